//! `mpc-sim`: the closed-loop simulator of mpcc.
//!
//! A 6-DoF quadrotor plant with first-order rotor dynamics ([`plant`]) and a tethered probe
//! ([`probe`]), a PX4-like body-rate loop and mixer ([`rate_loop`]), an estimation model with
//! noise, latency and dropouts ([`estimator`]), the closed-loop runner ([`run`]), the
//! flip-and-throw mission ([`throw`], [`release`]) and plots ([`plot`]). The paper's missions
//! ([`mission`]), the outer-loop controllers ([`controller`]), the log ([`log`]) and the
//! summaries ([`report`]) are `mpc-mission`'s, shared with the PX4 shim, and re-exported here.
//!
//! Frames: world ENU (x east/forward, y north/left, z up), body FLU (x forward, y left,
//! z up); quaternions are Hamilton, scalar first, body to world.

pub mod estimator;
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

pub use mpc_mission::{controller, log, mission};

/// The linear-algebra crate of this crate's API (positions, quaternions).
pub use nalgebra;
