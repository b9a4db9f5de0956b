//! Runs the QR-bench closed loop (config A: N = 10, dt = 0.04, 100 steps; `CONFIG=B`: N = 20,
//! dt = 0.05, 80 steps) with the hand-written quadrotor model, for instruction counts per RTI
//! step:
//!
//! `valgrind --tool=callgrind target/release/examples/qrbench_loop`
//!
//! It prints the number of steps, the mean QP iterations and the final position error.
//! Environment: `COLD=1` starts every QP cold, `TOL=1e-6` loosens the QP tolerances,
//! `POLISH=1` polishes every QP's solution (`QpSettings::polish`), `WARM_SET=0` turns off
//! the warm active set (`QpSettings::warm_active_set`: every QP by the interior point),
//! `METHOD=riccati` or `METHOD=condensed` forces how the QPs are solved (default: the solver's
//! automatic choice, with storage for condensing).

#[allow(dead_code)]
#[path = "../tests/support/quadrotor.rs"]
mod quadrotor;

use mpc_runtime::{QpMethod, RtiStatus};
use nalgebra::SVector;
use quadrotor::{X0, plant, qrbench_in};

fn main() {
    // CONFIG=B: N = 20, dt = 0.05, 80 steps (default A: N = 10, dt = 0.04, 100 steps).
    if std::env::var("CONFIG").as_deref() == Ok("B") {
        run::<20>(0.05, 80);
    } else {
        run::<10>(0.04, 100);
    }
}

fn run<const N: usize>(dt: f64, steps: usize) {
    let mut s = qrbench_in::<f64, N, N>(dt);
    s.settings.qp.method = match std::env::var("METHOD").as_deref() {
        Ok("riccati") => QpMethod::Riccati,
        Ok("condensed") => QpMethod::Condensed,
        Ok(other) => panic!("METHOD={other}: expected riccati or condensed"),
        Err(_) => QpMethod::Auto,
    };
    // Multipliers of the previous control step's QP as the start of the next (the default;
    // COLD=1 turns it off). TOL=1e-6 sets the QP tolerances (complementarity 100x tighter).
    s.settings.qp.warm_start_dual = std::env::var_os("COLD").is_none();
    if let Some(t) = std::env::var("TOL")
        .ok()
        .and_then(|v| v.parse::<f64>().ok())
    {
        s.settings.qp.tol_stat = t;
        s.settings.qp.tol_eq = t;
        s.settings.qp.tol_ineq = t;
        s.settings.qp.tol_comp = t * 1e-2;
    }
    // POLISH=1: the active-set polish after every QP (off by default in f64).
    s.settings.qp.polish = std::env::var_os("POLISH").is_some();
    // WARM_SET=0: no warm active set (on by default in a real-time iteration).
    s.settings.qp.warm_active_set = std::env::var("WARM_SET").as_deref() != Ok("0");
    let mut x = SVector::from(X0);
    let (mut iterations, mut solves, mut interior) = (0u32, 0u32, 0u32);
    for _ in 0..steps {
        s.prepare();
        let (u, info) = s.feedback(&x);
        assert_eq!(info.status, RtiStatus::Ok);
        iterations += info.qp.iterations;
        solves += info.qp.active_set_solves;
        interior += u32::from(info.qp.iterations > 0);
        x = plant(&x, &u, dt, 10);
    }
    let err = ((x[0] - 4.0).powi(2) + x[1].powi(2) + (x[2] - 2.0).powi(2)).sqrt();
    println!(
        "steps {steps}, mean QP iterations {:.2}, mean active-set solves {:.2}, \
         interior point in {interior} steps, final position error {err:.3e} m",
        f64::from(iterations) / steps as f64,
        f64::from(solves) / steps as f64
    );
}
