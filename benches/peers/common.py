"""QR-bench model for the CasADi peer (benches/peers/run.py).

Copied from the scripts of the CasADi reference runs (`common.py`, run with casadi 3.8.2;
docs/benchmarks.md, "Reference data") and trimmed. Changes against that copy:
  - kept only the QR-bench model, the NLP builder and the statistics helper; dropped the
    Gauss-Newton Hessian diagonal, JSON/machine helpers and the file helpers;
  - `initial_guess(N, hover=False)` also offers QR-bench's first guess u_k = 0 (the one
    `mpcc bench` uses); the default stays the reference runs' u_k = uref (hover), because CasADi's
    exact-Hessian sqpmethod diverges from u_k = 0 (measured with benches/peers/run.py).

QR-bench model:
  x = [px,py,pz, qw,qx,qy,qz, vx,vy,vz]  (z up, q unit quaternion body->world)
  u = [c, wx, wy, wz]  (mass-normalised collective thrust along body z, body rates)
  pdot = v ; qdot = 0.5 * q (x) (0,w)  (Hamilton) ; vdot = R(q) (0,0,c) - (0,0,9.81)
"""
import os

# single-threaded BLAS etc. (must be set before casadi/numpy load their libs)
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

G = 9.81
NX, NU = 10, 4

Q_DIAG = [100, 100, 100, 10, 10, 10, 10, 1, 1, 1]
R_DIAG = [0.5, 1, 1, 1]
P_FACTOR = 5.0
UREF = [G, 0.0, 0.0, 0.0]
XREF = [4, 0, 2, 1, 0, 0, 0, 0, 0, 0]
X0 = [0, 0, 2, 1, 0, 0, 0, 0, 0, 0]
U_LB = [0.0, -20.0, -20.0, -6.0]
U_UB = [20.0, 20.0, 20.0, 6.0]
T_SIM = 4.0
PLANT_SUBSTEPS = 10
CONFIGS = {"A": dict(N=10, dt=0.04), "B": dict(N=20, dt=0.05)}


def quad_ode_expr(x, u):
    """Continuous-time QR-bench dynamics as a CasADi expression (SX or MX)."""
    qw, qx, qy, qz = x[3], x[4], x[5], x[6]
    v = x[7:10]
    c, wx, wy, wz = u[0], u[1], u[2], u[3]
    # q (x) (0, w), Hamilton convention
    qdot = 0.5 * ca.vertcat(
        -qx * wx - qy * wy - qz * wz,
        qw * wx + qy * wz - qz * wy,
        qw * wy + qz * wx - qx * wz,
        qw * wz + qx * wy - qy * wx,
    )
    # R(q) * (0,0,c): third column of the unit-quaternion rotation matrix
    acc = ca.vertcat(
        2 * (qw * qy + qx * qz) * c,
        2 * (qy * qz - qw * qx) * c,
        (1 - 2 * (qx * qx + qy * qy)) * c - G,
    )
    return ca.vertcat(v, qdot, acc)


def rk4_expr(f, x, u, h, steps=1):
    for _ in range(steps):
        k1 = f(x, u)
        k2 = f(x + h / 2 * k1, u)
        k3 = f(x + h / 2 * k2, u)
        k4 = f(x + h * k3, u)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def quad_functions(dt):
    """Returns (F_mpc, F_plant): one RK4 step of dt, and 10 RK4 substeps over dt."""
    x = ca.SX.sym("x", NX)
    u = ca.SX.sym("u", NU)
    f = ca.Function("f", [x, u], [quad_ode_expr(x, u)])
    F = ca.Function("F", [x, u], [rk4_expr(f, x, u, dt, 1)], ["x", "u"], ["xn"])
    Fp = ca.Function("Fplant", [x, u],
                     [rk4_expr(f, x, u, dt / PLANT_SUBSTEPS, PLANT_SUBSTEPS)],
                     ["x", "u"], ["xn"])
    return F, Fp


def build_qrbench_nlp(N, dt):
    """Multiple-shooting NLP on SX graphs.

    w = [x_0, u_0, x_1, u_1, ..., x_{N-1}, u_{N-1}, x_N]
    p = measured state (x0 equality as g_0 = x_0 - p)
    g = [x_0 - p ; x_{k+1} - F(x_k, u_k)]  (all == 0)
    """
    F, Fp = quad_functions(dt)
    Q = ca.diag(ca.DM(Q_DIAG))
    R = ca.diag(ca.DM(R_DIAG))
    P = P_FACTOR * Q
    xref = ca.DM(XREF)
    uref = ca.DM(UREF)
    p = ca.SX.sym("x0", NX)
    X = [ca.SX.sym(f"x{k}", NX) for k in range(N + 1)]
    U = [ca.SX.sym(f"u{k}", NU) for k in range(N)]
    w, lbw, ubw = [], [], []
    J = 0
    g = [X[0] - p]
    for k in range(N):
        w += [X[k], U[k]]
        lbw += [-np.inf] * NX + U_LB
        ubw += [np.inf] * NX + U_UB
        dx = X[k] - xref
        du = U[k] - uref
        J += 0.5 * ca.mtimes([dx.T, Q, dx]) + 0.5 * ca.mtimes([du.T, R, du])
        g.append(X[k + 1] - F(X[k], U[k]))
    w.append(X[N])
    lbw += [-np.inf] * NX
    ubw += [np.inf] * NX
    dx = X[N] - xref
    J += 0.5 * ca.mtimes([dx.T, P, dx])
    nlp = {"x": ca.vertcat(*w), "p": p, "f": J, "g": ca.vertcat(*g)}
    ng = NX * (N + 1)
    bounds = dict(lbx=np.array(lbw), ubx=np.array(ubw),
                  lbg=np.zeros(ng), ubg=np.zeros(ng))
    return nlp, bounds, F, Fp


def initial_guess(N, hover=True):
    """First guess: x_k = X0, u_k = uref if hover (the reference runs'), else u_k = 0 (QR-bench)."""
    u = UREF if hover else [0.0] * NU
    w = []
    for _ in range(N):
        w += X0 + u
    w += X0
    return np.array(w, dtype=float)
