//! A pendulum driven through a torque that weakens with the angle (`cos(theta) u`, as a
//! cart-pole's), explicit Euler: nonlinear in the state and bilinear in state and control, with
//! its dynamics' Lagrangian Hessian written out by hand for the exact-Hessian full SQP.

use mpc_runtime::Model;
use nalgebra::{SMatrix, SVector};

/// Gravity over length `A`, actuation gain `B`, damping `C`.
pub const A: f64 = 9.81;
pub const B: f64 = 4.0;
pub const C: f64 = 0.2;

/// `x = (theta, omega)`, `u = (torque)`, `y = (theta, omega, u)` (the reference sets the
/// target angle), terminal `y_N = x`.
#[derive(Clone, Copy, Debug)]
pub struct Pendulum {
    pub dt: f64,
    /// Add [`dynamics_hessian`](Model::dynamics_hessian) times this (1 = exact; a negative
    /// factor makes every curved QP non-convex).
    pub hessian_scale: f64,
}

impl Pendulum {
    /// `omega' = -A sin(theta) - C omega + B cos(theta) u`.
    pub fn accel(theta: f64, omega: f64, u: f64) -> f64 {
        -A * theta.sin() - C * omega + B * theta.cos() * u
    }
}

impl Model<f64, 2, 1, 0, 3, 2, 0, 0> for Pendulum {
    const EXACT_HESSIAN: bool = true;

    fn dynamics(
        &self,
        x: &SVector<f64, 2>,
        u: &SVector<f64, 1>,
        _p: &SVector<f64, 0>,
        a: &mut SMatrix<f64, 2, 2>,
        b: &mut SMatrix<f64, 2, 1>,
    ) -> SVector<f64, 2> {
        let h = self.dt;
        let (th, om, uu) = (x[0], x[1], u[0]);
        let dacc_dth = -A * th.cos() - B * th.sin() * uu;
        *a = SMatrix::from_row_slice(&[1.0, h, h * dacc_dth, 1.0 - h * C]);
        *b = SMatrix::from_column_slice(&[0.0, h * B * th.cos()]);
        SVector::from([th + h * om, om + h * Self::accel(th, om, uu)])
    }

    fn dynamics_hessian(
        &self,
        x: &SVector<f64, 2>,
        u: &SVector<f64, 1>,
        _p: &SVector<f64, 0>,
        pi: &SVector<f64, 2>,
        hxx: &mut SMatrix<f64, 2, 2>,
        hux: &mut SMatrix<f64, 1, 2>,
        huu: &mut SMatrix<f64, 1, 1>,
    ) {
        // Only F_2 is nonlinear: d2/dth2 = h (A sin th - B cos th u), d2/(du dth) =
        // -h B sin th, d2/du2 = 0.
        let (th, uu) = (x[0], u[0]);
        let s = self.hessian_scale * pi[1] * self.dt;
        *hxx = SMatrix::from_row_slice(&[s * (A * th.sin() - B * th.cos() * uu), 0.0, 0.0, 0.0]);
        *hux = SMatrix::from_row_slice(&[-s * B * th.sin(), 0.0]);
        *huu = SMatrix::zeros();
    }

    fn residual(
        &self,
        x: &SVector<f64, 2>,
        u: &SVector<f64, 1>,
        _p: &SVector<f64, 0>,
        jx: &mut SMatrix<f64, 3, 2>,
        ju: &mut SMatrix<f64, 3, 1>,
    ) -> SVector<f64, 3> {
        *jx = SMatrix::from_row_slice(&[1.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        *ju = SMatrix::from_column_slice(&[0.0, 0.0, 1.0]);
        SVector::from([x[0], x[1], u[0]])
    }

    fn terminal_residual(
        &self,
        x: &SVector<f64, 2>,
        _p: &SVector<f64, 0>,
        jx: &mut SMatrix<f64, 2, 2>,
    ) -> SVector<f64, 2> {
        *jx = SMatrix::identity();
        *x
    }
}
