//! Criterion benchmarks of the runtime solver on QR-bench (`docs/bench.md`).
//!
//! - `qp/{mpcc,clarabel}/N{10,20}[-step2]`: one QP of the QR-bench closed loop (the one
//!   prepared at step 10, with 1 control bound active in its solution at N = 10 and none at
//!   N = 20; `-step2`: at step 2, with 7 and 5, the most of the loop), solved by our Riccati
//!   interior-point method and by clarabel on the identical QP written out in sparse form.
//!   Both to their default tolerances; clarabel's setup (KKT assembly and symbolic
//!   factorization) is outside the timed region, so the comparison is solve against solve.
//!   `mpcc-condensed`: the same QP condensed (condensing in the timed region),
//!   `mpcc-condensed-prepared` and `mpcc-prepared`: condensed and by the Riccati recursion
//!   after a `QpSolver::prepare` outside the timed region (condensing, the first Newton
//!   system), as in a real-time iteration's feedback. `mpcc-condensed-polished[-prepared]`:
//!   condensed, the interior point to 1e-3 and then the active-set polish, whose solution is
//!   the exact one (checked against the default solve before timing).
//!   `mpcc-[condensed-]active-set[-prepared]`: a new solver with the warm active set
//!   (`QpSettings::warm_active_set`), whose first QP starts from the empty set (the
//!   unconstrained solution, then active-set moves; exact, checked against the default
//!   solve), whole or after `prepare` (a new copy per solve, made outside the timed region).
//! - `rti/{A,B}/{prepare,feedback,step}`: the closed loop of configs A (N = 10, dt = 0.04) and
//!   B (N = 20, dt = 0.05); each timed iteration is one control step of the loop, which restarts
//!   after 4 s.
//!
//! Run with `cargo bench --bench runtime`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettingsBuilder, DefaultSolver, IPSolver, SupportedConeT};
use criterion::{Criterion, criterion_group, criterion_main};
use mpc_runtime::{OcpQp, QpMethod, QpSolver, RtiStatus};
use nalgebra::SVector;

#[allow(unused_imports)]
#[path = "../runtime/tests/support/mod.rs"]
mod support;

use support::quadrotor::{NU, NX, X0, closed_loop_qp, plant, qrbench};

/// How many control bounds are active (within 1e-7) in `sol`.
fn active_bounds<const N: usize>(
    qp: &OcpQp<f64, NX, NU, 0, 0, N>,
    sol: &mpc_runtime::QpSolution<f64, NX, NU, N>,
) -> usize {
    let mut n = 0;
    for (s, u) in qp.stages.iter().zip(&sol.u) {
        for i in 0..NU {
            n += usize::from((u[i] - s.lbu[i]).abs() < 1e-7 || (s.ubu[i] - u[i]).abs() < 1e-7);
        }
    }
    n
}

fn bench_qp<const N: usize>(c: &mut Criterion, dt: f64, step: usize) {
    let qp = closed_loop_qp::<N>(dt, step);
    // Step 10 (the first figures' QP) has 1 active bound at N = 10 and none at N = 20; step
    // 2 has the most of the loop (7 and 5).
    let tag = if step == 10 {
        format!("N{N}")
    } else {
        format!("N{N}-step{step}")
    };
    let mut group = c.benchmark_group("qp");
    let mut ours = Box::new(QpSolver::<f64, NX, NU, 0, 0, N>::NEW);
    group.bench_function(format!("mpcc/{tag}"), |b| {
        b.iter(|| black_box(ours.solve(black_box(&qp))))
    });
    // Condensed: the whole solve (condensing included), and the part after `prepare` (what
    // a real-time iteration's feedback phase runs).
    let mut dense = Box::new(QpSolver::<f64, NX, NU, 0, 0, N, N>::NEW);
    dense.settings.method = QpMethod::Condensed;
    group.bench_function(format!("mpcc-condensed/{tag}"), |b| {
        b.iter(|| black_box(dense.solve(black_box(&qp))))
    });
    dense.prepare(&qp);
    assert!(dense.condensed());
    // `prepare` outside the timed region before every solve: what the feedback phase runs
    // (the first Newton system is factorized in `prepare`, and used by one solve).
    group.bench_function(format!("mpcc-condensed-prepared/{tag}"), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                dense.prepare(black_box(&qp));
                let start = Instant::now();
                black_box(dense.solve_prepared(black_box(&qp)));
                total += start.elapsed();
            }
            total
        })
    });
    // The interior point to 1e-3 only, then the polish (active-set iterations from it; on in
    // f32, off by default in f64): the exact solution (checked here against the solve to the
    // default tolerances) from fewer interior-point iterations.
    let mut loose = Box::new(QpSolver::<f64, NX, NU, 0, 0, N, N>::NEW);
    loose.settings.method = QpMethod::Condensed;
    loose.settings.tol_stat = 1e-3;
    loose.settings.tol_eq = 1e-3;
    loose.settings.tol_ineq = 1e-3;
    loose.settings.tol_comp = 1e-3;
    loose.settings.polish = true;
    let info = loose.solve(&qp);
    assert!(info.status == mpc_runtime::QpStatus::Solved && loose.polished());
    let tight = dense.solve(&qp);
    assert_eq!(tight.status, mpc_runtime::QpStatus::Solved);
    let gap = (loose.solution().u.iter())
        .zip(&dense.solution().u)
        .map(|(a, b)| (a - b).amax())
        .fold(0.0f64, f64::max);
    assert!(
        gap <= 1e-6,
        "polished solution {gap:e} from the default one"
    );
    eprintln!(
        "qp/{tag}: interior-point iterations {} to 1e-3 (then the polish), {} to the defaults",
        info.iterations, tight.iterations
    );
    group.bench_function(format!("mpcc-condensed-polished/{tag}"), |b| {
        b.iter(|| black_box(loose.solve(black_box(&qp))))
    });
    group.bench_function(format!("mpcc-condensed-polished-prepared/{tag}"), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                loose.prepare(black_box(&qp));
                let start = Instant::now();
                black_box(loose.solve_prepared(black_box(&qp)));
                total += start.elapsed();
            }
            total
        })
    });
    // The same for the Riccati recursion, whose `prepare` factorizes the first Newton system.
    group.bench_function(format!("mpcc-prepared/{tag}"), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                ours.prepare(black_box(&qp));
                let start = Instant::now();
                black_box(ours.solve_prepared(black_box(&qp)));
                total += start.elapsed();
            }
            total
        })
    });
    // A new solver with the warm active set: its first QP starts from the empty set (the
    // unconstrained solution, then active-set moves; the interior point only where they
    // miss), whose solution is the exact one (checked here against the default solve). A
    // new copy for every solve, made and prepared outside the timed region.
    for (name, method) in [
        ("mpcc-condensed-active-set-prepared", QpMethod::Condensed),
        ("mpcc-active-set-prepared", QpMethod::Riccati),
    ] {
        let mut fresh = Box::new(QpSolver::<f64, NX, NU, 0, 0, N, N>::NEW);
        fresh.settings.method = method;
        fresh.settings.warm_active_set = true;
        let mut first = fresh.clone();
        let info = first.solve(&qp);
        assert_eq!(info.status, mpc_runtime::QpStatus::Solved);
        assert_eq!(first.condensed(), method == QpMethod::Condensed);
        let gap = (first.solution().u.iter())
            .zip(&dense.solution().u)
            .map(|(a, b)| (a - b).amax())
            .fold(0.0f64, f64::max);
        assert!(gap <= 1e-6, "{name}: {gap:e} from the default solve");
        eprintln!(
            "qp/{tag}: {name}: {} active-set solves, {} interior-point iterations",
            info.active_set_solves, info.iterations
        );
        group.bench_function(format!("{name}/{tag}"), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let mut s = fresh.clone();
                    s.prepare(black_box(&qp));
                    let start = Instant::now();
                    black_box(s.solve_prepared(black_box(&qp)));
                    total += start.elapsed();
                }
                total
            })
        });
        // The whole solve: `prepare` (condensing, the factorization on the empty set) timed.
        let whole = name.trim_end_matches("-prepared");
        group.bench_function(format!("{whole}/{tag}"), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let mut s = fresh.clone();
                    let start = Instant::now();
                    black_box(s.solve(black_box(&qp)));
                    total += start.elapsed();
                }
                total
            })
        });
    }
    let d = support::dense(&qp);
    let p = CscMatrix::from(&d.p).to_triu();
    let a = CscMatrix::from(&d.a);
    let cones = [
        SupportedConeT::ZeroConeT(d.n_eq),
        SupportedConeT::NonnegativeConeT(d.n_ineq),
    ];
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .build()
        .expect("settings");
    let mut once =
        DefaultSolver::new(&p, &d.q, &a, &d.b, &cones, settings.clone()).expect("clarabel setup");
    once.solve();
    eprintln!(
        "qp/{tag}: clarabel iterations {}; {} control bounds active",
        once.info.iterations,
        active_bounds(&qp, dense.solution())
    );
    group.bench_function(format!("clarabel/{tag}"), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let mut solver = DefaultSolver::new(&p, &d.q, &a, &d.b, &cones, settings.clone())
                    .expect("clarabel setup");
                let start = Instant::now();
                solver.solve();
                total += start.elapsed();
                black_box(&solver.solution.x);
            }
            total
        })
    });
    group.finish();
}

fn bench_rti<const N: usize>(c: &mut Criterion, name: &str, dt: f64, steps: usize) {
    let mut group = c.benchmark_group(format!("rti/{name}"));
    for phase in ["prepare", "feedback", "step"] {
        let mut s = qrbench::<N>(dt);
        let mut x = SVector::from(X0);
        let mut k = 0;
        group.bench_function(phase, |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    if k == steps {
                        s = qrbench::<N>(dt);
                        x = SVector::from(X0);
                        k = 0;
                    }
                    let t0 = Instant::now();
                    s.prepare();
                    let t1 = Instant::now();
                    let (u, info) = s.feedback(&x);
                    let t2 = Instant::now();
                    debug_assert_eq!(info.status, RtiStatus::Ok);
                    total += match phase {
                        "prepare" => t1 - t0,
                        "feedback" => t2 - t1,
                        _ => t2 - t0,
                    };
                    x = plant(&x, &black_box(u), dt, 10);
                    k += 1;
                }
                total
            })
        });
    }
    group.finish();
}

fn benches(c: &mut Criterion) {
    for step in [10, 2] {
        bench_qp::<10>(c, 0.04, step);
        bench_qp::<20>(c, 0.05, step);
    }
    bench_rti::<10>(c, "A", 0.04, 100);
    bench_rti::<20>(c, "B", 0.05, 80);
}

criterion_group!(runtime, benches);
criterion_main!(runtime);
