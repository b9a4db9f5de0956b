"""IPOPT reference for the soft-bounds test (tests/soft_bounds.rs): tests/soft-bounds/
soft_box.mpc's problem written independently in CasADi, with the soft bounds as explicit
slack variables, solved by IPOPT to 1e-12 (bounds not relaxed); the optimal trajectories are written to
benches/peers/soft_bounds/soft_box_ipopt.csv.

Usage (from the repository root; the Rust test reads the CSV and needs no Python):
    python3 -m pip install -r benches/peers/requirements.txt
    python3 benches/peers/soft_bounds_casadi.py

The problem (docs/mpc-language.md, "Constraints"): x_{k+1} = x_k + u_k, N = 3, the cost
sum_{k<N} 1/2 u_k^2 + 1/2 * 4 (x_N - xr)^2 with xr = 2, the soft bound u_k <= 5 on k < N
and the soft bound x_k <= 1 on 1 <= k <= N (x_0 is the measured state, not bounded), each
violation s >= 0 costing l1 s + 1/2 l2 s^2. Each case is a start x_0 and the state bound's
penalties (the control's: l1 = 5, l2 = 0, as in the model file).
"""
import os

import casadi as ca

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "soft_bounds", "soft_box_ipopt.csv")

N, XR, XB, UB, UL1, UL2 = 3, 2.0, 1.0, 5.0, 5.0, 0.0

# (name, x0, l1, l2) of the state's soft bound.
CASES = [
    ("l2_inside", 0.0, 0.0, 10.0),
    ("l2_outside", 1.8, 0.0, 10.0),
    ("l1_l2_outside", 1.8, 5.0, 1.0),
    ("l1_below", 0.0, 2.0, 0.0),
]


def solve(x0, l1, l2):
    opti = ca.Opti()
    x = opti.variable(N + 1)
    u = opti.variable(N)
    sx = opti.variable(N)  # violations of x_k <= 1, k = 1..N
    su = opti.variable(N)  # violations of u_k <= 5, k = 0..N-1
    cost = 0
    for k in range(N):
        opti.subject_to(x[k + 1] == x[k] + u[k])
        cost += 0.5 * u[k] ** 2
        cost += l1 * sx[k] + 0.5 * l2 * sx[k] ** 2 + UL1 * su[k] + 0.5 * UL2 * su[k] ** 2
        opti.subject_to(x[k + 1] <= XB + sx[k])
        opti.subject_to(u[k] <= UB + su[k])
        opti.subject_to(sx[k] >= 0)
        opti.subject_to(su[k] >= 0)
    cost += 0.5 * 4.0 * (x[N] - XR) ** 2
    opti.subject_to(x[0] == x0)
    opti.minimize(cost)
    ipopt = {"tol": 1e-12, "acceptable_tol": 1e-12, "constr_viol_tol": 1e-12}
    ipopt.update({"bound_relax_factor": 0.0, "print_level": 0})
    opti.solver("ipopt", {"print_time": False}, ipopt)
    sol = opti.solve()
    stats = sol.stats()
    return sol.value(x), sol.value(u), stats["iter_count"], sol.value(cost)


def main():
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    lines = []
    rows = ["case,k,x,u"]
    for name, x0, l1, l2 in CASES:
        x, u, iters, cost = solve(x0, l1, l2)
        lines.append(f"{name} {iters} iterations, cost {cost!r}")
        for k in range(N + 1):
            uk = f"{u[k]:.17g}" if k < N else ""
            rows.append(f"{name},{k},{x[k]:.17g},{uk}")
    head = (
        f"# soft_box: IPOPT (CasADi {ca.__version__}), tol 1e-12; "
        + "; ".join(lines)
        + "; benches/peers/soft_bounds_casadi.py"
    )
    with open(OUT, "w") as f:
        f.write(head + "\n" + "\n".join(rows) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
