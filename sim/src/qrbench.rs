//! QR-bench's plant (the problem every peer is measured on, `docs/bench.md`): the quadrotor
//! rate model integrated with RK4, in f64, as `mpcc bench` and the criterion benches fly it.

/// The initial state of QR-bench: (p, q, v) = ((0, 0, 2), (1, 0, 0, 0), 0).
pub const X0: [f64; 10] = [0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];

/// `xdot = f(x, u)`: pdot = v, qdot = 1/2 q ⊗ (0, w), vdot = R(q)(0, 0, c) - (0, 0, 9.81)
/// (QR-bench's formula, `docs/bench.md`; u = (c, wx, wy, wz)).
pub fn ode(x: &[f64; 10], u: &[f64; 4]) -> [f64; 10] {
    let (qw, qx, qy, qz) = (x[3], x[4], x[5], x[6]);
    let (c, wx, wy, wz) = (u[0], u[1], u[2], u[3]);
    [
        x[7],
        x[8],
        x[9],
        0.5 * (-qx * wx - qy * wy - qz * wz),
        0.5 * (qw * wx + qy * wz - qz * wy),
        0.5 * (qw * wy - qx * wz + qz * wx),
        0.5 * (qw * wz + qx * wy - qy * wx),
        2.0 * (qw * qy + qx * qz) * c,
        2.0 * (qy * qz - qw * qx) * c,
        (1.0 - 2.0 * (qx * qx + qy * qy)) * c - 9.81,
    ]
}

/// The plant: `substeps` classical RK4 steps over `dt` with the control held.
pub fn plant(x: &[f64; 10], u: &[f64; 4], dt: f64, substeps: usize) -> [f64; 10] {
    let h = dt / substeps.max(1) as f64;
    let axpy = |a: &[f64; 10], s: f64, b: &[f64; 10]| -> [f64; 10] {
        core::array::from_fn(|i| a[i] + s * b[i])
    };
    let mut x = *x;
    for _ in 0..substeps.max(1) {
        let k1 = ode(&x, u);
        let k2 = ode(&axpy(&x, 0.5 * h, &k1), u);
        let k3 = ode(&axpy(&x, 0.5 * h, &k2), u);
        let k4 = ode(&axpy(&x, h, &k3), u);
        x = core::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
    }
    x
}
