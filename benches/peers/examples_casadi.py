"""IPOPT references for the example models (models/cartpole.mpc, bicycle.mpc,
planar_quadrotor.mpc): the same optimal control problems written independently in CasADi,
solved by IPOPT to 1e-12, converged trajectories written to benches/peers/examples/*.csv.

Usage (from the repository root; the Rust tests read the CSVs and need no Python):
    python3 -m venv .venv && .venv/bin/pip install -r benches/peers/requirements.txt
    .venv/bin/python benches/peers/examples_casadi.py [--out DIR] [--only NAME,...]

Each problem is the one mpcc builds from the model file (docs/mpc-language.md):
  - the dynamics discretized by classical RK4 with the model's number of equal substeps
    over dt, the control and the parameters constant over an interval;
  - the cost sum_k 1/2 |r_k|^2_W over every least-squares term (the factor 1/2 as mpcc's):
    Q and R on stages k < N, P on stage N, the input rate u_k - u_{k-1} on k < N with
    u_{-1} = the parameter u_prev;
  - control bounds on k < N, state bounds on 1 <= k <= N (x_0 is fixed to the measured
    state), general constraints on k < N, terminal ones on N;
  - a soft row lo <= h <= hi with penalties l1, l2: a slack s >= 0 per finite side,
    lo - s <= h (or h <= hi + s), and l1 s + 1/2 l2 s^2 in the cost, as the runtime's QP
    (docs/runtime.md, "Soft constraints"); at the optimum s is the violation, the penalty
    the runtime's merit adds.
The first guess is mpcc's: x_0 = the start, x_k = the model's state guess for k >= 1, u_k
= its control guess; the parameters are the model's defaults, with the per-stage references
the Rust tests set (bicycle: along the x axis at 3 m/s from t = 0).

The model functions below are written from the models' header comments, not from the
.mpc files or the generated code.
"""
import argparse
import math
import os
import sys

import casadi as ca
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "examples")


def rk4(f, x, u, p, dt, substeps):
    h = dt / substeps
    for _ in range(substeps):
        k1 = f(x, u, p)
        k2 = f(x + h / 2 * k1, u, p)
        k3 = f(x + h / 2 * k2, u, p)
        k4 = f(x + h * k3, u, p)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


# ---------------------------------------------------------------------------------------
# Cart-pole swing-up (models/cartpole.mpc)

def cartpole():
    g, M, m, l = 9.81, 0.5, 0.2, 0.5

    def f(x, u, p):
        th, ds, dth = x[1], x[2], x[3]
        F = u[0]
        D = M + m * ca.sin(th) ** 2
        dds = (F + m * ca.sin(th) * (l * dth ** 2 + g * ca.cos(th))) / D
        ddth = (-F * ca.cos(th) - m * l * dth ** 2 * ca.sin(th) * ca.cos(th)
                - (M + m) * g * ca.sin(th)) / (l * D)
        return ca.vertcat(ds, dth, dds, ddth)

    N = 50

    def xr(p):  # p = [s_ref]
        return ca.vertcat(p[0], math.pi, 0, 0)

    return dict(
        name="cartpole", nx=4, nu=1, N=N, dt=0.05, substeps=2, f=f,
        states=["s", "theta", "ds", "dtheta"], controls=["force"],
        x0=[0, 0, 0, 0], x_guess=[0, 0, 0, 0], u_guess=[0],
        params=[[0.0] for _ in range(N + 1)],
        stage=[(lambda x, u, p: x - xr(p), [2, 5, 0.1, 0.1]),
               (lambda x, u, p: u, [0.05])],
        terminal=[(lambda x, p: x - xr(p), [20, 50, 2, 2])],
        rate=None,
        lbu=[-10], ubu=[10],
        lbx=[-1.5, -np.inf, -np.inf, -np.inf], ubx=[1.5, np.inf, np.inf, np.inf],
        g_stage=[], g_terminal=[],
    )


# ---------------------------------------------------------------------------------------
# Kinematic bicycle passing an obstacle (models/bicycle.mpc)

BIKE_SPEED, BIKE_GOAL = 3.0, 20.0


def bicycle_ref(t):
    """The reference the Rust tests set: along the x axis at 3 m/s to the goal, then at
    rest there."""
    if BIKE_SPEED * t < BIKE_GOAL:
        return [BIKE_SPEED * t, 0.0, 0.0, BIKE_SPEED]
    return [BIKE_GOAL, 0.0, 0.0, 0.0]


def bicycle():
    L = 2.5
    ox, oy, r = 6.0, -0.3, 1.0
    N, dt = 40, 0.1

    def f(x, u, p):
        psi, v = x[2], x[3]
        a, delta = u[0], u[1]
        return ca.vertcat(v * ca.cos(psi), v * ca.sin(psi), v * ca.tan(delta) / L, a)

    # p = [xref (4), ox, oy, r_obs]
    params = [bicycle_ref(k * dt) + [ox, oy, r] for k in range(N + 1)]

    def clearance(x, u, p):
        return ca.sqrt((x[0] - p[4]) ** 2 + (x[1] - p[5]) ** 2) - p[6]

    return dict(
        name="bicycle", nx=4, nu=2, N=N, dt=dt, substeps=1, f=f,
        states=["px", "py", "psi", "v"], controls=["a", "delta"],
        x0=[0, 0, 0, 3], x_guess=[0, 0, 0, 3], u_guess=[0, 0],
        params=params,
        stage=[(lambda x, u, p: x - p[0:4], [1, 1, 0.5, 0.5]),
               (lambda x, u, p: u, [0.5, 5])],
        terminal=[(lambda x, p: x - p[0:4], [10, 10, 5, 5])],
        rate=None,
        lbu=[-3, -0.5], ubu=[3, 0.5],
        lbx=[-np.inf, -np.inf, -np.inf, 0], ubx=[np.inf, np.inf, np.inf, 6],
        g_stage=[(clearance, 0.0, np.inf, (100.0, 1000.0))], g_terminal=[],
    )


# ---------------------------------------------------------------------------------------
# Planar quadrotor (models/planar_quadrotor.mpc)

def planar_quadrotor():
    g, m, l, J = 9.81, 1.0, 0.2, 0.01
    hover = m * g / 2
    yt, zt = 2.0, 1.0
    N = 40

    def f(x, u, p):
        phi, vy, vz, om = x[2], x[3], x[4], x[5]
        T = u[0] + u[1]
        return ca.vertcat(vy, vz, om, -T * ca.sin(phi) / m, T * ca.cos(phi) / m - g,
                          (u[1] - u[0]) * l / J)

    target = ca.DM([yt, zt, 0, 0, 0, 0])

    def arrive(x, p):
        return (x[0] - yt) ** 2 + (x[1] - zt) ** 2

    return dict(
        name="planar_quadrotor", nx=6, nu=2, N=N, dt=0.05, substeps=1, f=f,
        states=["y", "z", "phi", "vy", "vz", "omega"], controls=["f1", "f2"],
        x0=[0] * 6, x_guess=[0] * 6, u_guess=[hover, hover],
        params=[[] for _ in range(N + 1)],
        stage=[(lambda x, u, p: x - target, [5, 5, 1, 0.5, 0.5, 0.1]),
               (lambda x, u, p: u - ca.DM([hover, hover]), [0.1, 0.1])],
        terminal=[(lambda x, p: x - target, [10, 10, 2, 1, 1, 0.2])],
        rate=([1, 1], [hover, hover]),
        lbu=[0, 0], ubu=[8, 8],
        lbx=[-np.inf] * 6, ubx=[np.inf] * 6,
        g_stage=[], g_terminal=[(arrive, -np.inf, 0.01 ** 2, None)],
    )


# ---------------------------------------------------------------------------------------

def quad(r, w):
    return 0.5 * ca.dot(r, ca.DM(w) * r)


def soft_rows(h, lo, hi, soft, w, lbw, ubw, w0, g, lbg, ubg):
    """Appends the constraint lo <= h <= hi (soft: a slack per finite side) and returns its
    penalty."""
    if soft is None:
        g.append(h)
        lbg.append(lo)
        ubg.append(hi)
        return 0
    l1, l2 = soft
    pen = 0
    for side, bound in (("lo", lo), ("hi", hi)):
        if not np.isfinite(bound):
            continue
        s = ca.SX.sym("s_" + side)
        w.append(s)
        lbw.append(0.0)
        ubw.append(np.inf)
        w0.append(0.0)
        if side == "lo":
            g.append(h + s)
            lbg.append(bound)
            ubg.append(np.inf)
        else:
            g.append(h - s)
            lbg.append(-np.inf)
            ubg.append(bound)
        pen += l1 * s + 0.5 * l2 * s ** 2
    return pen


def solve(spec):
    nx, nu, N = spec["nx"], spec["nu"], spec["N"]
    xs, us = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    npar = len(spec["params"][0])
    ps = ca.SX.sym("p", npar)
    F = ca.Function("F", [xs, us, ps],
                    [rk4(spec["f"], xs, us, ps, spec["dt"], spec["substeps"])])
    X = [ca.SX.sym(f"x{k}", nx) for k in range(N + 1)]
    U = [ca.SX.sym(f"u{k}", nu) for k in range(N)]
    P = [ca.DM(p) for p in spec["params"]]
    w, lbw, ubw, w0 = [], [], [], []
    g, lbg, ubg = [], [], []
    J = 0
    for k in range(N + 1):
        w.append(X[k])
        if k == 0:
            lbw += list(spec["x0"])
            ubw += list(spec["x0"])
            w0 += list(spec["x0"])
        else:
            lbw += list(spec["lbx"])
            ubw += list(spec["ubx"])
            w0 += list(spec["x_guess"])
        if k == N:
            break
        w.append(U[k])
        lbw += list(spec["lbu"])
        ubw += list(spec["ubu"])
        w0 += list(spec["u_guess"])
        for r, wt in spec["stage"]:
            J += quad(r(X[k], U[k], P[k]), wt)
        if spec["rate"] is not None:
            wt, uprev = spec["rate"]
            du = U[k] - (U[k - 1] if k > 0 else ca.DM(uprev))
            J += quad(du, wt)
        for h, lo, hi, soft in spec["g_stage"]:
            J += soft_rows(h(X[k], U[k], P[k]), lo, hi, soft, w, lbw, ubw, w0, g, lbg, ubg)
        g.append(X[k + 1] - F(X[k], U[k], P[k]))
        lbg += [0.0] * nx
        ubg += [0.0] * nx
    for r, wt in spec["terminal"]:
        J += quad(r(X[N], P[N]), wt)
    for h, lo, hi, soft in spec["g_terminal"]:
        J += soft_rows(h(X[N], P[N]), lo, hi, soft, w, lbw, ubw, w0, g, lbg, ubg)
    nlp = {"x": ca.vertcat(*w), "f": J, "g": ca.vertcat(*g)}
    opts = {
        "ipopt.tol": 1e-12,
        "ipopt.acceptable_tol": 1e-12,
        "ipopt.constr_viol_tol": 1e-12,
        "ipopt.bound_relax_factor": 0.0,
        "ipopt.max_iter": 3000,
        "ipopt.print_level": 0,
        "print_time": False,
    }
    S = ca.nlpsol("S", "ipopt", nlp, opts)
    sol = S(x0=np.array(w0, dtype=float), lbx=lbw, ubx=ubw, lbg=lbg, ubg=ubg)
    st = S.stats()
    if not st["success"]:
        sys.exit(f"{spec['name']}: IPOPT did not converge: {st['return_status']}")
    # Pick the states and controls out of w (the slacks sit between them).
    get = ca.Function("get", [nlp["x"]], [ca.horzcat(*X), ca.horzcat(*U)])
    xo, uo = (a.full() for a in get(sol["x"]))
    return xo, uo, float(sol["f"]), int(st["iter_count"])


def write_csv(spec, xo, uo, cost, iters, out):
    path = os.path.join(out, spec["name"] + "_ipopt.csv")
    N = spec["N"]
    with open(path, "w") as fh:
        fh.write(f"# {spec['name']}: IPOPT (CasADi {ca.__version__}), tol 1e-12, "
                 f"{iters} iterations, cost {cost:.17g}; benches/peers/examples_casadi.py\n")
        fh.write(",".join(["k"] + spec["states"] + spec["controls"]) + "\n")
        for k in range(N + 1):
            row = [str(k)] + [repr(float(v)) for v in xo[:, k]]
            if k < N:
                row += [repr(float(v)) for v in uo[:, k]]
            fh.write(",".join(row) + "\n")
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=OUT)
    ap.add_argument("--only", default="")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    only = {s for s in args.only.split(",") if s}
    for make in (cartpole, bicycle, planar_quadrotor):
        spec = make()
        if only and spec["name"] not in only:
            continue
        xo, uo, cost, iters = solve(spec)
        path = write_csv(spec, xo, uo, cost, iters, args.out)
        print(f"{spec['name']}: cost {cost:.12g}, {iters} IPOPT iterations -> "
              f"{os.path.relpath(path)}")


if __name__ == "__main__":
    main()
