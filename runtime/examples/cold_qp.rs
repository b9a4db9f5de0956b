//! Solves one QP of the QR-bench closed loop cold, ten times, each by a new solver with the
//! warm active set (its first QP starts from the empty set: the unconstrained solution, then
//! active-set moves), for instruction counts per whole solve (`prepare` + `solve_prepared`):
//!
//! `valgrind --tool=callgrind target/release/examples/cold_qp N10-step2`, then
//! `callgrind_annotate --inclusive=yes callgrind.out.<pid> | grep cold_qp::measured`
//! (the total over the ten solves).
//!
//! The QPs are those of `benches/runtime.rs`'s `qp/` group: `N10` and `N20` (prepared at step
//! 10 of configs A and B), `N10-step2` and `N20-step2` (at step 2, with the most bounds active
//! of the loop). It prints the active-set solves and interior-point iterations of the ten.

#[allow(dead_code)]
#[path = "../tests/support/quadrotor.rs"]
mod quadrotor;

use mpc_runtime::{OcpQp, QpMethod, QpSolver, QpStatus};
use quadrotor::{NU, NX, closed_loop_qp};

fn main() {
    match std::env::args().nth(1).as_deref() {
        Some("N10") => run::<10>(0.04, 10),
        Some("N20") => run::<20>(0.05, 10),
        Some("N10-step2") => run::<10>(0.04, 2),
        Some("N20-step2") => run::<20>(0.05, 2),
        _ => eprintln!("usage: cold_qp N10 | N20 | N10-step2 | N20-step2"),
    }
}

/// One whole solve: the function whose inclusive count callgrind gives.
#[inline(never)]
fn measured<const N: usize>(
    s: &mut QpSolver<f64, NX, NU, 0, 0, N, N>,
    qp: &OcpQp<f64, NX, NU, 0, 0, N>,
) -> (u32, u32) {
    let info = s.solve(qp);
    assert_eq!(info.status, QpStatus::Solved);
    (info.active_set_solves, info.iterations)
}

fn run<const N: usize>(dt: f64, step: usize) {
    let qp = closed_loop_qp::<N>(dt, step);
    let mut fresh = Box::new(QpSolver::<f64, NX, NU, 0, 0, N, N>::NEW);
    fresh.settings.method = QpMethod::Riccati;
    fresh.settings.warm_active_set = true;
    let (mut solves, mut iterations) = (0, 0);
    for _ in 0..10 {
        let mut s = fresh.clone();
        let (a, i) = std::hint::black_box(measured(&mut s, &qp));
        (solves, iterations) = (solves + a, iterations + i);
    }
    println!(
        "N = {N}, step {step}: 10 cold solves, {solves} active-set solves, {iterations} interior-point iterations"
    );
}
