//! How the full SQP (`Solver::solve_sqp`, Gauss-Newton with a merit line search) converges on
//! QR-bench A (`mpc_models::quadrotor_rates_a`, the code of `generated/quadrotor_rates_a`): the
//! SQP iterations of every step of the closed loop (`mpcc bench --sqp` reports their mean),
//! then, at two steps, the largest difference of the controls after `k` iterations from the
//! step's solution converged to 1e-12:
//!
//! ```sh
//! cargo run --release --example sqp_convergence
//! ```

use mpc_models::quadrotor_rates_a as m;
use mpc_sim::qrbench::{X0, plant};

/// The largest difference between two plans' controls.
fn plan_difference(a: &m::Solver, b: &m::Solver) -> f64 {
    (0..m::N)
        .filter_map(|k| Some((a.control(k)?, b.control(k)?)))
        .flat_map(|(ua, ub)| (0..m::NU).map(move |i| (ua[i] - ub[i]).abs()))
        .fold(0.0, f64::max)
}

fn main() {
    let mut s = Box::new(m::Solver::new());
    let _ = s.set_guess(&X0, &[0.0; 4]);
    let mut x = X0;
    let mut iterations = Vec::new();
    for step in 0..100 {
        s.prepare();
        if s.set_x0(&x).is_err() {
            eprintln!("step {step}: state refused");
            std::process::exit(1);
        }
        if step == 4 || step == 60 {
            let mut converged = s.clone();
            converged.settings_mut().sqp_max_iter = 500;
            converged.settings_mut().sqp_tol = 1e-12;
            let done = converged.solve_sqp().sqp_iterations;
            print!("step {step} (converged to 1e-12 in {done} iterations), after k iterations:");
            for k in [1u32, 2, 3, 4, 6, 8, 10, 15, 20, 30, 40] {
                let mut t = s.clone();
                t.settings_mut().sqp_max_iter = k;
                t.solve_sqp();
                print!(" {k}: {:.1e}", plan_difference(&t, &converged));
            }
            println!();
        }
        iterations.push(s.solve_sqp().sqp_iterations);
        x = plant(&x, &s.u0(), m::DT, 10);
    }
    let mean = f64::from(iterations.iter().sum::<u32>()) / iterations.len() as f64;
    println!("SQP iterations per step (mean {mean:.2}): {iterations:?}");
}
