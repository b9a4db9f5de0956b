//! The paper's point-mass MPC (`mpc_models::paper_pointmass`, the code of
//! `generated/paper_pointmass`) tracking a 1 m step in x for 100 control steps, with the exact
//! triple-integrator plant (the closed loop of `cargo bench --bench generated -- pointmass`),
//! once: for instruction counts,
//!
//! ```sh
//! cargo build --release --example pointmass_loop
//! valgrind --tool=callgrind target/release/examples/pointmass_loop
//! callgrind_annotate --inclusive=yes callgrind.out.<pid> | grep -E "Solver::(prepare|feedback) "
//! ```
//!
//! (divide by the 100 steps). Prints the QP iterations and the final state.

use mpc_models::paper_pointmass as m;

fn main() {
    let mut s = Box::new(m::Solver::new());
    let mut xref = [0.0; 9];
    xref[0] = 1.0;
    if let Err(e) = s.set_xref_all(&xref) {
        eprintln!("reference refused: {e:?}");
        std::process::exit(1);
    }
    let mut x = [0.0f64; 9];
    let mut iterations = 0;
    for _ in 0..100 {
        s.prepare();
        if let Err(e) = s.set_x0(&x) {
            eprintln!("state refused: {e:?}");
            std::process::exit(1);
        }
        iterations += s.feedback().qp.iterations;
        x = mpc_sim::pointmass::plant(&x, &s.u0(), m::DT);
    }
    println!("QP iterations: {iterations} in 100 steps; final state {x:?}");
}
