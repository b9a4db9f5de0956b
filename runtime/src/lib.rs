//! # mpc-runtime
//!
//! The engine every mpcc-generated solver runs on: a structured OCP-QP interior-point solver
//! with a Riccati recursion ([`qp`]) and, on top, the real-time-iteration SQP loop ([`rti`])
//! over a [`Model`] that generated code implements.
//!
//! General constraints are hard by default; each row can be made soft with an L1 (exact) and
//! an L2 penalty on its slacks ([`QpStage::soft_l1`], [`QpStage::soft_l2`] in the QP,
//! [`Rti::set_soft_penalties`] in the RTI solver). The slacks are eliminated inside the
//! interior-point iteration row by row, so the Riccati structure is kept; see [`qp`] for the
//! formulation. Box bounds on states and controls are always hard.
//!
//! `#![no_std]`, no heap, no `unsafe`: every workspace is a struct of fixed-size arrays whose
//! sizes are const generics, with a `const NEW` so it can live in a `static`. Linear algebra on
//! the small fixed-size blocks is nalgebra's (`SMatrix`, Cholesky), math goes through `libm`.
//!
//! Panics: the public API does not panic on any input. Indexing inside the crate is over
//! arrays whose length is the const generic the loop runs to, so it cannot go out of bounds;
//! `clippy::indexing_slicing` is not enabled for that reason, while `unwrap`, `expect` and
//! `panic!` are denied.
#![no_std]
#![forbid(unsafe_code)]
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use nalgebra::{ArrayStorage, SMatrix};

pub mod convexify;
pub mod implicit;
mod kernels;
pub mod model;
pub mod qp;
pub mod real;
mod rows;
pub mod rti;

/// The math library generated code calls (`mpc_runtime::libm::sin`), so that a crate using a
/// generated solver needs no dependency of its own on it.
pub use libm;
pub use model::Model;
pub use nalgebra;
pub use qp::{
    OcpQp, QpHessian, QpInfo, QpMethod, QpSettings, QpSolution, QpSolver, QpStage, QpStatus,
    QpTerminal, condensing_pays,
};
pub use real::Real;
pub use rti::{Rti, RtiInfo, RtiSettings, RtiStatus, SetError};

/// A zero matrix, usable in constants.
pub(crate) const fn zeros<T: Real, const R: usize, const C: usize>() -> SMatrix<T, R, C> {
    SMatrix::from_array_storage(ArrayStorage([[T::ZERO; R]; C]))
}

/// A matrix with every entry `v`, usable in constants.
pub(crate) const fn filled<T: Real, const R: usize, const C: usize>(v: T) -> SMatrix<T, R, C> {
    SMatrix::from_array_storage(ArrayStorage([[v; R]; C]))
}

/// Includes a solver module that `mpc_codegen::Builder` generated into `OUT_DIR` from a build
/// script: `mpc_runtime::include_solver!("quadrotor");` then `quadrotor::Solver::new()`.
#[macro_export]
macro_rules! include_solver {
    ($module:literal) => {
        include!(concat!(env!("OUT_DIR"), "/", $module, ".rs"));
    };
}
