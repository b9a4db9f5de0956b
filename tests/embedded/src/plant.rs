//! The plant of the bare-metal closed loop, shared by the firmware (`main.rs`) and the host
//! test (`host_check.rs`, which includes this file) so both fly exactly the same f32 loop.

use quadrotor_rates_f32::{NU, NX_MODEL, Real};

/// The plant: the same rate model, 10 RK4 substeps per control interval (as in
/// `examples/build-rs/src/main.rs`).
pub fn plant(x: &[Real; NX_MODEL], u: &[Real; NU], dt: Real) -> [Real; NX_MODEL] {
    let f = |x: &[Real; NX_MODEL]| -> [Real; NX_MODEL] {
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
    };
    let axpy = |x: &[Real; NX_MODEL], k: &[Real; NX_MODEL], h: Real| {
        core::array::from_fn(|i| x[i] + h * k[i])
    };
    let h = dt / 10.0;
    let mut x = *x;
    for _ in 0..10 {
        let k1 = f(&x);
        let k2 = f(&axpy(&x, &k1, h / 2.0));
        let k3 = f(&axpy(&x, &k2, h / 2.0));
        let k4 = f(&axpy(&x, &k3, h));
        x = core::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
    }
    x
}
