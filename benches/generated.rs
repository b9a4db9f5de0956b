//! Criterion benchmarks of the generated solvers (`mpc-models`, the code of `generated/`),
//! each in its closed loop:
//!
//! - `qrbench/<case>/{prepare,feedback,step}` for QR-bench with N = 10, 20, 40 in f64 and f32
//!   (`quadrotor_rates_a`, `quadrotor_rates`, `quadrotor_rates_n40` and their `_f32`
//!   siblings): the closed loop of `mpcc bench` (x0 = (0,0,2, 1,0,0,0, 0,0,0), hover at
//!   (4, 0, 2), RK4 plant with 10 substeps), restarted after 4 s; each timed iteration is one
//!   control step.
//! - `pointmass/{prepare,feedback,step}`: the paper's point-mass MPC tracking a 1 m step, the
//!   exact triple-integrator plant.
//! - `probe/{prepare,feedback,step}`: the probe model, with its own prediction as the plant.
//!
//! The QP alone against clarabel on the identical QP is `cargo bench --bench runtime`
//! (`qp/{mpcc,clarabel}/N{10,20}`). Run with `cargo bench --bench generated`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use mpc_sim::qrbench::{X0, plant};

/// Times one phase of the closed loop of solver crate `$m`; `$reset` builds a fresh solver
/// and state, `$step` flies one step given the solver and the state (returns the new state).
macro_rules! closed_loop_group {
    ($c:expr, $name:expr, $steps:expr, $new:expr, $plant:expr) => {{
        let mut group = $c.benchmark_group($name);
        for phase in ["prepare", "feedback", "step"] {
            let (mut s, mut x) = $new;
            let mut k = 0usize;
            group.bench_function(phase, |b| {
                b.iter_custom(|iters| {
                    let mut total = Duration::ZERO;
                    for _ in 0..iters {
                        if k == $steps {
                            (s, x) = $new;
                            k = 0;
                        }
                        let t0 = Instant::now();
                        s.prepare();
                        let t1 = Instant::now();
                        let _ = s.set_x0(&x);
                        let info = s.feedback();
                        let t2 = Instant::now();
                        black_box(info);
                        total += match phase {
                            "prepare" => t1 - t0,
                            "feedback" => t2 - t1,
                            _ => t2 - t0,
                        };
                        x = $plant(&s, &x);
                        k += 1;
                    }
                    total
                })
            });
        }
        group.finish();
    }};
}

macro_rules! qrbench {
    ($c:expr, $m:ident, $name:expr) => {{
        use mpc_models::$m as m;
        let new = || {
            let mut s = Box::new(m::Solver::new());
            let x0: [m::Real; 10] = X0.map(|v| v as m::Real);
            let _ = s.set_guess(&x0, &[0.0; 4]);
            (s, x0)
        };
        let steps = (4.0 / f64::from(m::DT)).round() as usize;
        let plant = |s: &m::Solver, x: &[m::Real; 10]| -> [m::Real; 10] {
            let u = s.u0().map(f64::from);
            plant(&x.map(f64::from), &u, f64::from(m::DT), 10).map(|v| v as m::Real)
        };
        closed_loop_group!($c, $name, steps, new(), plant);
    }};
}

fn benches(c: &mut Criterion) {
    qrbench!(c, quadrotor_rates_a, "qrbench/N10_f64");
    qrbench!(c, quadrotor_rates, "qrbench/N20_f64");
    qrbench!(c, quadrotor_rates_n40, "qrbench/N40_f64");
    qrbench!(c, quadrotor_rates_f32, "qrbench/N10_f32");
    qrbench!(c, quadrotor_rates_b_f32, "qrbench/N20_f32");
    qrbench!(c, quadrotor_rates_n40_f32, "qrbench/N40_f32");

    {
        use mpc_models::paper_pointmass as m;
        let new = || {
            let mut s = Box::new(m::Solver::new());
            let mut xref = [0.0; 9];
            xref[0] = 1.0;
            let _ = s.set_xref_all(&xref);
            (s, [0.0; 9])
        };
        // The exact plant: the triple integrator over dt with the applied jerk.
        let plant = |s: &m::Solver, x: &[f64; 9]| -> [f64; 9] {
            mpc_sim::pointmass::plant(x, &s.u0(), m::DT)
        };
        closed_loop_group!(c, "pointmass", 100, new(), plant);
    }

    {
        use mpc_models::quadrotor_probe as m;
        let new = || {
            let s = Box::new(m::Solver::new());
            let x0 = s.state(0).unwrap_or([0.0; m::NX_MODEL]);
            (s, x0)
        };
        // The solver's own prediction one interval ahead as the plant.
        let plant = |s: &m::Solver, x: &[f64; m::NX_MODEL]| s.state(1).unwrap_or(*x);
        closed_loop_group!(c, "probe", 80, new(), plant);
    }
}

criterion_group! {
    name = generated;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2));
    targets = benches
}
criterion_main!(generated);
