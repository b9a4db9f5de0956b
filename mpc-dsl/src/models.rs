//! Reference models and a fixed-step integrator, shared by tests, benchmarks and examples.
//!
//! The OCP layer describes models in full (`models/*.mpc`); what is here is the bare ODE of
//! the quadrotor rate model, the problem every NMPC peer is measured on (QR-bench, defined in
//! `docs/bench.md`; the peers' reference data: `docs/benchmarks.md`).

use crate::error::Result;
use crate::graph::{Expr, Graph};
use crate::linalg::{Vector, quat_mul, quat_rotate};

/// An explicit ODE `xdot = f(x, u)` over symbolic states and controls.
#[derive(Clone, Debug)]
pub struct OdeModel<'g> {
    /// State symbols.
    pub x: Vector<'g>,
    /// Control symbols.
    pub u: Vector<'g>,
    /// Right-hand side, one expression per state.
    pub xdot: Vector<'g>,
}

/// Standard gravity used by the reference models, m/s^2.
pub const GRAVITY: f64 = 9.81;

/// Right-hand side of the quadrotor rate model for given state and control expressions.
///
/// State `x = (p, q, v)`: position (m, world, z up), unit quaternion body to world (Hamilton,
/// scalar first, not renormalized), velocity (m/s). Control `u = (c, wx, wy, wz)`:
/// mass-normalized collective thrust along body z (m/s^2) and body rates (rad/s).
///
/// `pdot = v`, `qdot = 1/2 q ⊗ (0, w)`, `vdot = R(q) (0, 0, c) - (0, 0, g)`.
///
/// # Errors
/// [`DslError::DimensionMismatch`](crate::DslError::DimensionMismatch) unless `x` has 10 and
/// `u` 4 entries.
pub fn quadrotor_rates_rhs<'g>(x: &[Expr<'g>], u: &[Expr<'g>]) -> Result<Vector<'g>> {
    if x.len() != 10 || u.len() != 4 {
        return Err(crate::DslError::DimensionMismatch {
            op: "quadrotor_rates_rhs",
            expected: "10 states and 4 controls".into(),
            found: format!("{} states and {} controls", x.len(), u.len()),
        });
    }
    let g = u[0].graph();
    let (p_dot, q) = (&x[7..10], &x[3..7]);
    let omega = [g.zero(), u[1], u[2], u[3]];
    let q_dot = quat_mul(q, &omega)?.scale(0.5);
    let thrust = quat_rotate(q, &[g.zero(), g.zero(), u[0]])?;
    let v_dot = [thrust[0], thrust[1], thrust[2] - GRAVITY];
    Ok(p_dot
        .iter()
        .chain(q_dot.iter())
        .chain(v_dot.iter())
        .copied()
        .collect())
}

/// The quadrotor rate model with symbols `px, py, pz, qw, qx, qy, qz, vx, vy, vz` and
/// `c, wx, wy, wz`.
pub fn quadrotor_rates(g: &Graph) -> Result<OdeModel<'_>> {
    let x: Vector<'_> = ["px", "py", "pz", "qw", "qx", "qy", "qz", "vx", "vy", "vz"]
        .iter()
        .map(|n| g.symbol(n))
        .collect();
    let u: Vector<'_> = ["c", "wx", "wy", "wz"]
        .iter()
        .map(|n| g.symbol(n))
        .collect();
    let xdot = quadrotor_rates_rhs(&x, &u)?;
    Ok(OdeModel { x, u, xdot })
}

/// `steps` classical Runge-Kutta 4 steps of total length `h` for `xdot = f(x)`.
///
/// The result is one expression per state, fully expanded; hash-consing keeps the shared
/// stage values shared.
///
/// # Errors
/// Whatever `f` returns.
pub fn rk4<'g>(
    x: &[Expr<'g>],
    h: f64,
    steps: usize,
    f: impl Fn(&[Expr<'g>]) -> Result<Vector<'g>>,
) -> Result<Vector<'g>> {
    let dt = h / steps.max(1) as f64;
    let mut x: Vector<'g> = x.iter().copied().collect();
    for _ in 0..steps.max(1) {
        let k1 = f(&x)?;
        let k2 = f(&x.add(&k1.scale(dt / 2.0))?)?;
        let k3 = f(&x.add(&k2.scale(dt / 2.0))?)?;
        let k4 = f(&x.add(&k3.scale(dt))?)?;
        let incr = k1.add(&k2.scale(2.0))?.add(&k3.scale(2.0))?.add(&k4)?;
        x = x.add(&incr.scale(dt / 6.0))?;
    }
    Ok(x)
}
