//! Instantiates the runtime's QP and RTI solvers and the generated solvers of `generated/`
//! in `f32` and `f64` for a QR-bench-sized problem with no standard library, so that
//! `cargo build -p no-std-check --target thumbv7em-none-eabihf` proves they build bare-metal.
#![no_std]
#![forbid(unsafe_code)]

use mpc_runtime::nalgebra::{SMatrix, SVector};
use mpc_runtime::{Model, OcpQp, QpInfo, QpSolver, Real, Rti, RtiInfo};

/// A linear model, enough to monomorphize every solver path.
#[derive(Clone, Copy, Debug, Default)]
pub struct Linear;

impl<T: Real> Model<T, 10, 4, 0, 14, 10, 0, 0> for Linear {
    fn dynamics(
        &self,
        x: &SVector<T, 10>,
        u: &SVector<T, 4>,
        _p: &SVector<T, 0>,
        a: &mut SMatrix<T, 10, 10>,
        b: &mut SMatrix<T, 10, 4>,
    ) -> SVector<T, 10> {
        *a = SMatrix::identity();
        *b = SMatrix::from_fn(|i, j| if i == j { T::ONE } else { T::ZERO });
        *a * x + *b * u
    }
    fn residual(
        &self,
        x: &SVector<T, 10>,
        u: &SVector<T, 4>,
        _p: &SVector<T, 0>,
        jx: &mut SMatrix<T, 14, 10>,
        ju: &mut SMatrix<T, 14, 4>,
    ) -> SVector<T, 14> {
        *jx = SMatrix::from_fn(|i, j| if i == j { T::ONE } else { T::ZERO });
        *ju = SMatrix::from_fn(|i, j| if i == 10 + j { T::ONE } else { T::ZERO });
        SVector::from_fn(|i, _| if i < 10 { x[i] } else { u[i - 10] })
    }
    fn terminal_residual(
        &self,
        x: &SVector<T, 10>,
        _p: &SVector<T, 0>,
        jx: &mut SMatrix<T, 10, 10>,
    ) -> SVector<T, 10> {
        *jx = SMatrix::identity();
        *x
    }
}

/// A QP solver in a `static`-compatible form.
pub static QP_F32: QpSolver<f32, 10, 4, 0, 0, 10> = QpSolver::NEW;

/// Solves a QR-bench-sized QP in `f32`.
pub fn solve_qp_f32(
    s: &mut QpSolver<f32, 10, 4, 0, 0, 10>,
    qp: &OcpQp<f32, 10, 4, 0, 0, 10>,
) -> QpInfo<f32> {
    s.solve(qp)
}

/// Solves a QR-bench-sized QP in `f64`.
pub fn solve_qp_f64(
    s: &mut QpSolver<f64, 10, 4, 0, 0, 20>,
    qp: &OcpQp<f64, 10, 4, 0, 0, 20>,
) -> QpInfo<f64> {
    s.solve(qp)
}

/// Solves a QP with state-bound rows for 3 states and a general row (`NBX = 3 < NX`).
pub fn solve_qp_state_slots_f64(
    s: &mut QpSolver<f64, 10, 4, 1, 0, 20, 0, 3>,
    qp: &OcpQp<f64, 10, 4, 1, 0, 20>,
) -> QpInfo<f64> {
    s.solve(qp)
}

/// Solves a QP with one stage Hessian (`NH = 1`) condensed, without Riccati storage
/// (`NBX = 0`, `NR = 0`).
pub fn solve_qp_dense_f32(
    s: &mut QpSolver<f32, 10, 4, 0, 0, 10, 10, 0, 0>,
    qp: &OcpQp<f32, 10, 4, 0, 0, 10, 1>,
) -> QpInfo<f32> {
    s.solve(qp)
}

/// One RTI step in `f32`.
pub fn rti_step_f32(
    s: &mut Rti<f32, Linear, 10, 4, 0, 14, 10, 0, 0, 10>,
    x0: &SVector<f32, 10>,
) -> (SVector<f32, 4>, RtiInfo<f32>) {
    s.prepare();
    s.feedback(x0)
}

/// One RTI step in `f64`, and a full SQP.
pub fn rti_step_f64(
    s: &mut Rti<f64, Linear, 10, 4, 0, 14, 10, 0, 0, 20>,
    x0: &SVector<f64, 10>,
) -> (SVector<f64, 4>, RtiInfo<f64>) {
    s.prepare();
    let r = s.feedback(x0);
    let _ = s.solve_sqp(x0);
    r
}

/// The generated QR-bench solver (f32, variant A), as a bare-metal application holds it: a
/// `static` built by the `const fn`.
pub static GENERATED_F32: quadrotor_rates_f32::Solver = quadrotor_rates_f32::Solver::unconfigured();

/// One control step of the generated f32 solver (every generated path monomorphized).
pub fn generated_step_f32(
    s: &mut quadrotor_rates_f32::Solver,
    x0: &[f32; quadrotor_rates_f32::NX_MODEL],
) -> Option<[f32; quadrotor_rates_f32::NU]> {
    s.prepare();
    s.set_x0(x0).ok()?;
    let info = s.feedback();
    (info.status == quadrotor_rates_f32::RtiStatus::Ok).then(|| s.u0())
}

/// One control step of the generated f64 solver.
pub fn generated_step_f64(
    s: &mut quadrotor_rates::Solver,
    x0: &[f64; quadrotor_rates::NX_MODEL],
) -> Option<[f64; quadrotor_rates::NU]> {
    s.prepare();
    s.set_x0(x0).ok()?;
    let info = s.feedback();
    (info.status == quadrotor_rates::RtiStatus::Ok).then(|| s.u0())
}

/// One control step and a full SQP of the generated stiff model, whose dynamics are the
/// implicit `irk` step (`mpc_runtime::implicit`), in `f32`.
pub fn stiff_step_f32(
    s: &mut stiff_actuator_f32::Solver,
    x0: &[f32; stiff_actuator_f32::NX_MODEL],
) -> Option<[f32; stiff_actuator_f32::NU]> {
    s.prepare();
    s.set_x0(x0).ok()?;
    let info = s.feedback();
    let _ = s.solve_sqp();
    (info.status == stiff_actuator_f32::RtiStatus::Ok).then(|| s.u0())
}

/// The same in `f64`.
pub fn stiff_step_f64(
    s: &mut stiff_actuator::Solver,
    x0: &[f64; stiff_actuator::NX_MODEL],
) -> Option<[f64; stiff_actuator::NU]> {
    s.prepare();
    s.set_x0(x0).ok()?;
    let info = s.feedback();
    let _ = s.solve_sqp();
    (info.status == stiff_actuator::RtiStatus::Ok).then(|| s.u0())
}
