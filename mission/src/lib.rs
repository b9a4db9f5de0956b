//! `mpc-mission`: what mpcc's simulator (`mpc-sim`) and its PX4 shim (`firmware-shim`) both
//! fly with, and nothing of the simulated world (plant, rate loop, probe, noise, plots).
//!
//! * [`vehicle`]: the quadrotor's parameters and state;
//! * [`estimate`]: what the controllers see of it, and how good that is;
//! * [`mission`]: the paper's missions (flip, hover, step): phases, references, failsafe;
//! * [`controller`]: the two outer-loop controllers on generated solvers (the paper's
//!   point-mass MPC and the full NMPC) and the mass estimator;
//! * [`log`]: one row of the flight log;
//! * [`report`]: a flight's summary and verdict, the table and the JSON of many.
//!
//! Frames: world ENU (x east/forward, y north/left, z up), body FLU (x forward, y left,
//! z up); quaternions are Hamilton, scalar first, body to world.

pub mod controller;
pub mod estimate;
pub mod log;
pub mod mission;
pub mod report;
pub mod vehicle;

/// The linear-algebra crate of this crate's API (positions, quaternions).
pub use nalgebra;
