"""CasADi references for mpcc's general (not least-squares) cost terms, written to
benches/peers/general_cost/*.csv and read by codegen/tests/general_cost.rs (which needs no
Python):

  - derivatives.csv: the value, gradient and Hessian over (x, u) of a few general costs
    (a log barrier, a cost on a nonlinear output, an energy term, a terminal term) at
    random points, by CasADi's symbolic AD;
  - pendulum_cost_ipopt.csv: IPOPT's converged solution of the optimal control problem of
    tests/data/pendulum_cost.mpc.

Usage (from the repository root):
    python3 -m pip install -r benches/peers/requirements.txt
    python3 benches/peers/general_cost_casadi.py [--out DIR]

The problem is the one mpcc builds from the model file (docs/mpc-language.md, "Cost"): the
dynamics discretized by classical RK4 with 2 equal substeps over dt, the control and the
parameters constant over an interval; the objective sum_k 1/2 |r_k|^2_W over the least-
squares terms (Q on x_k, R on u_k, k < N) plus the general terms as they are (no factor
1/2): sum_{k<N} l(x_k, u_k, p) + l_N(x_N, p). The model functions below are written from the
model's description, not from the generated code.
"""
import argparse
import os

import casadi as ca
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "general_cost")
SEED = 20261205
POINTS = 6
TOL = 1e-12


def fmt(v):
    return repr(float(v)) if np.isfinite(v) else str(v)


# ---------------------------------------------------------------------------------------
# Derivatives of general costs at random points: x in R^3, u in R^2, p = (a,) in R^1.

def cost_cases(x, u, a):
    """The costs of codegen/tests/general_cost.rs, by name: (expression, terminal?)."""
    return {
        "barrier": (-ca.log(1 - x[0] ** 2 - 0.5 * u[0] ** 2 - 0.2 * x[1] * u[1]), False),
        "output": ((ca.sin(x[0]) * x[1] + ca.exp(0.3 * x[2]) * u[1] - a) ** 2, False),
        "energy": (a * (u[0] ** 2 + u[1] ** 2) * (1 + x[1] ** 2) + u[0] * x[2], False),
        "terminal": (x[0] ** 4 + ca.cos(x[1]) * x[2] ** 2 + a * x[2], True),
    }


def derivatives(out_dir):
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    a = ca.SX.sym("a")
    z = ca.vertcat(x, u)
    rng = np.random.default_rng(SEED)
    rows = []
    for name, (l, terminal) in cost_cases(x, u, a).items():
        g = ca.gradient(l, z)
        h = ca.hessian(l, z)[0]
        fn = ca.Function(name, [x, u, a], [l, g, h])
        for i in range(POINTS):
            xv = rng.uniform(-0.5, 0.5, 3)
            uv = rng.uniform(-0.5, 0.5, 2)
            av = rng.uniform(0.5, 1.5)
            if terminal:
                uv = np.zeros(2)
            lv, gv, hv = fn(xv, uv, av)
            gv = np.array(gv).ravel()
            hv = np.array(hv)
            vals = [name, str(i)] + [fmt(v) for v in list(xv) + list(uv) + [av, float(lv)]]
            vals += [fmt(v) for v in gv] + [fmt(v) for v in hv.ravel()]
            rows.append(",".join(vals))
    header = ["case", "point", "x0", "x1", "x2", "u0", "u1", "a", "value"]
    header += [f"g{i}" for i in range(5)] + [f"h{i}{j}" for i in range(5) for j in range(5)]
    path = os.path.join(out_dir, "derivatives.csv")
    with open(path, "w") as f:
        f.write(f"# CasADi {ca.__version__} symbolic AD (SX), seed {SEED}, "
                f"x, u uniform in [-0.5, 0.5], a in [0.5, 1.5]; terminal: u = 0\n")
        f.write(",".join(header) + "\n")
        f.write("\n".join(rows) + "\n")
    print(f"wrote {path} ({len(rows)} rows)")


# ---------------------------------------------------------------------------------------
# The pendulum of tests/data/pendulum_cost.mpc, solved by IPOPT.

def rk4(f, x, u, dt, substeps):
    h = dt / substeps
    for _ in range(substeps):
        k1 = f(x, u)
        k2 = f(x + h / 2 * k1, u)
        k3 = f(x + h / 2 * k2, u)
        k4 = f(x + h * k3, u)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def pendulum(out_dir):
    n, dt, substeps = 30, 0.05, 2
    umax, w = 2.0, 0.5
    x0 = np.array([1.0, 0.0])

    def f(x, u):
        th, om = x[0], x[1]
        return ca.vertcat(om, -9.81 * ca.sin(th) - 0.2 * om + u[0])

    def stage(x, u):
        th, om, tau = x[0], x[1], u[0]
        lsq = 0.5 * (0.5 * th ** 2 + 0.05 * om ** 2) + 0.5 * 0.01 * tau ** 2
        energy = w * tau ** 2 * (1 + 0.5 * om ** 2)
        barrier = -0.05 * ca.log(umax ** 2 - tau ** 2)
        height = 2 * (1 - ca.cos(th)) ** 2
        return lsq + energy + barrier + height

    def terminal(x):
        return 5 * (1 - ca.cos(x[0])) + 2 * x[1] ** 2

    X = [ca.MX.sym(f"x{k}", 2) for k in range(n + 1)]
    U = [ca.MX.sym(f"u{k}", 1) for k in range(n)]
    J = sum(stage(X[k], U[k]) for k in range(n)) + terminal(X[n])
    g = [X[0] - x0] + [rk4(f, X[k], U[k], dt, substeps) - X[k + 1] for k in range(n)]
    w0 = []
    for k in range(n):
        w0 += [x0 if k == 0 else np.zeros(2), np.zeros(1)]
    w0.append(np.zeros(2))
    z = ca.vertcat(*[v for k in range(n) for v in (X[k], U[k])], X[n])
    nlp = {"x": z, "f": J, "g": ca.vertcat(*g)}
    opts = {"ipopt.tol": TOL, "ipopt.print_level": 0, "print_time": False}
    solver = ca.nlpsol("s", "ipopt", nlp, opts)
    sol = solver(x0=np.concatenate(w0), lbg=0, ubg=0)
    stats = solver.stats()
    zs = np.array(sol["x"]).ravel()
    path = os.path.join(out_dir, "pendulum_cost_ipopt.csv")
    with open(path, "w") as fh:
        fh.write(f"# CasADi {ca.__version__} IPOPT tol {TOL}, {stats['return_status']}, "
                 f"{stats['iter_count']} iterations, cost {float(sol['f'])!r}\n")
        fh.write("k,th,om,tau\n")
        for k in range(n + 1):
            xs = zs[3 * k:3 * k + 2]
            us = zs[3 * k + 2:3 * k + 3] if k < n else []
            fh.write(",".join([str(k)] + [fmt(v) for v in list(xs) + list(us)]) + "\n")
    print(f"wrote {path}: {stats['return_status']}, cost {float(sol['f'])}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=OUT)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    derivatives(args.out)
    pendulum(args.out)


if __name__ == "__main__":
    main()
