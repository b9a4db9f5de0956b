"""Reference solutions of models/stiff_actuator.mpc for tests/irk.rs, by scipy's Radau.

Writes benches/peers/examples/stiff_actuator_radau.csv (from the repository root:
`python3 benches/peers/irk_radau.py`). Every row is the state reached from `x0` after `t`
seconds with the control `F_cmd` held constant, integrated by
`solve_ivp(method="Radau", rtol=1e-12, atol=1e-12)` with the analytic Jacobian:

- kind `step`: one shooting interval (dt = 0.05 s) from a few states away from equilibrium
  (the actuator's transient is in the step);
- kind `traj`: 30 intervals from rest with F_cmd = 10 cos(0.3 k) on interval k, each row
  the state after interval k (integrated interval by interval, as a zero-order hold).

The ODE is the model's, written again here:
  der(s) = v, der(v) = (F - k s - k3 s^3 - c v) / m, der(F) = (F_cmd - F) / tau.
"""

import csv
import math
import os

import numpy as np
import scipy
from scipy.integrate import solve_ivp

M, K, K3, C, TAU, DT = 1.0, 4.0, 2.0, 0.4, 0.004, 0.05


def rhs(_t, x, u):
    s, v, f = x
    return [v, (f - K * s - K3 * s**3 - C * v) / M, (u - f) / TAU]


def jac(_t, x, _u):
    s = x[0]
    return [[0, 1, 0], [(-K - 3 * K3 * s**2) / M, -C / M, 1 / M], [0, 0, -1 / TAU]]


def flow(x0, u, t):
    sol = solve_ivp(rhs, (0.0, t), x0, method="Radau", rtol=1e-12, atol=1e-12,
                    args=(u,), jac=jac)
    assert sol.success, sol.message
    return sol.y[:, -1]


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    out = os.path.join(here, "examples", "stiff_actuator_radau.csv")
    rows = []
    steps = [
        ([0.0, 0.0, 0.0], 10.0),
        ([0.5, -1.0, 3.0], -5.0),
        ([1.2, 0.3, 8.0], 20.0),
        ([-0.8, 2.0, -15.0], 0.0),
    ]
    for i, (x0, u) in enumerate(steps):
        rows.append(["step", i, *x0, u, DT, *flow(x0, u, DT)])
    x = np.zeros(3)
    for k in range(30):
        u = 10.0 * math.cos(0.3 * k)
        x1 = flow(x, u, DT)
        rows.append(["traj", k, *x, u, DT, *x1])
        x = x1
    with open(out, "w", newline="") as f:
        f.write(f"# scipy {scipy.__version__}, numpy {np.__version__}: solve_ivp Radau, "
                "rtol = atol = 1e-12, analytic Jacobian (benches/peers/irk_radau.py)\n")
        w = csv.writer(f)
        w.writerow(["kind", "index", "s0", "v0", "F0", "F_cmd", "t", "s", "v", "F"])
        for r in rows:
            w.writerow([r[0], r[1]] + [repr(float(v)) for v in r[2:]])
    print(f"wrote {out} ({len(rows)} rows)")


if __name__ == "__main__":
    main()
