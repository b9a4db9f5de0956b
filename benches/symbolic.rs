//! Criterion benchmarks of the symbolic core (`mpc-dsl`).
//!
//! - `qr_rk4_jacobian_ssa/{1,4}_substeps`: the whole code-generation front end for the
//!   quadrotor rate model, timed end to end from an empty graph: build the ODE, discretize it
//!   with RK4 (0.04 s, 1 or 4 substeps), take the 10 x 14 Jacobian with respect to `(x, u)`
//!   and lower it to SSA with [`Graph::compile`]. Every iteration uses a brand-new graph: the
//!   graph hash-conses, so rebuilding into a reused one would only time lookups.
//! - `gradient_100k`: reverse-mode gradient of a scalar over a random 100,000-node DAG with
//!   heavy sharing (50 inputs). Only [`Graph::gradient`] is timed; each iteration builds its
//!   own graph outside the timed region.
//!
//! Run with `cargo bench --bench symbolic` (add `-- --quick` for a fast pass).

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use mpc_dsl::models::{quadrotor_rates, quadrotor_rates_rhs, rk4};
use mpc_dsl::{Graph, Program};

#[path = "common/random_dag.rs"]
mod random_dag;

/// Nodes in the random DAG of `gradient_100k`.
const DAG_NODES: usize = 100_000;

/// Build, discretize, differentiate and lower the quadrotor model in a fresh graph.
fn qr_rk4_jacobian_program(substeps: usize) -> Program {
    let g = Graph::new();
    let model = quadrotor_rates(&g).expect("quadrotor model");
    let xnext = rk4(&model.x, 0.04, substeps, |x| {
        quadrotor_rates_rhs(x, &model.u)
    })
    .expect("rk4 discretization");
    let wrt: Vec<_> = model.x.iter().chain(model.u.iter()).copied().collect();
    let jac = g.jacobian(&xnext, &wrt).expect("jacobian");
    g.compile(jac.values(), &wrt).expect("lowering to SSA")
}

fn bench_qr_rk4(c: &mut Criterion) {
    let mut group = c.benchmark_group("qr_rk4_jacobian_ssa");
    for substeps in [1usize, 4] {
        group.bench_function(format!("{substeps}_substeps"), |b| {
            b.iter(|| black_box(qr_rk4_jacobian_program(black_box(substeps))));
        });
    }
    group.finish();
}

fn bench_gradient(c: &mut Criterion) {
    let mut group = c.benchmark_group("gradient_100k");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5));
    group.bench_function("reverse_sweep", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                // `Expr` borrows the graph, so set-up and measurement share this scope; only
                // the gradient itself is inside the stopwatch.
                let g = Graph::new();
                let (f, inputs) = random_dag::random_dag(&g, DAG_NODES, random_dag::SEED);
                let start = Instant::now();
                let grad = g.gradient(f, &inputs).expect("gradient");
                total += start.elapsed();
                black_box(grad);
            }
            total
        });
    });
    group.finish();
}

criterion_group!(benches, bench_qr_rk4, bench_gradient);
criterion_main!(benches);
