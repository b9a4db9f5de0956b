//! `mpc-sim`: the closed-loop simulator of mpcc.
//!
//! A 6-DoF quadrotor plant with first-order rotor dynamics ([`plant`]), a PX4-like body-rate
//! loop and mixer ([`rate_loop`]), an estimation model with noise, latency and dropouts
//! ([`estimator`]), the two outer-loop controllers built on generated solvers
//! ([`controller`]), the paper's missions ([`mission`]), the closed-loop runner ([`run`]) and
//! its logs ([`log`]), summaries and plots ([`report`], [`plot`]).
//!
//! Frames: world ENU (x east/forward, y north/left, z up), body FLU (x forward, y left,
//! z up); quaternions are Hamilton, scalar first, body to world.

pub mod controller;
pub mod estimator;
pub mod log;
pub mod mission;
pub mod plant;
pub mod plot;
pub mod pointmass;
pub mod probe;
pub mod qrbench;
pub mod rate_loop;
pub mod release;
pub mod report;
pub mod run;
pub mod throw;

/// The linear-algebra crate of this crate's API (positions, quaternions).
pub use nalgebra;
