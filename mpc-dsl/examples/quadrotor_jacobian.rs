//! Builds the quadrotor rate model, discretizes it with one RK4 step, differentiates it and
//! lowers the Jacobian to straight-line code.
//!
//! `cargo run -p mpc-dsl --example quadrotor_jacobian`

use mpc_dsl::models::{quadrotor_rates, quadrotor_rates_rhs, rk4};
use mpc_dsl::{DslError, Graph};

fn main() -> Result<(), DslError> {
    let g = Graph::new();
    let m = quadrotor_rates(&g)?; // x = (p, q, v), u = (c, wx, wy, wz)
    let x_next = rk4(&m.x, 0.04, 1, |x| quadrotor_rates_rhs(x, &m.u))?;
    let wrt: Vec<_> = m.x.iter().chain(m.u.iter()).copied().collect();
    let jac = g.jacobian(&x_next, &wrt)?; // [A B], sparse
    let program = g.compile(jac.values(), &wrt)?; // straight-line SSA
    println!(
        "[A B] is {}x{} with {} structural nonzeros; {} SSA instructions, at most {} temporaries live",
        jac.nrows(),
        jac.ncols(),
        jac.nnz(),
        program.instrs().len(),
        program.max_live()
    );
    let hover = [
        0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 9.81, 0.0, 0.0, 0.0,
    ];
    let values = program.eval(&hover)?;
    let dvz_dc = jac.sparsity().position(9, 10).map(|k| values[k]);
    println!("at hover, d vz+ / d c = {dvz_dc:?} (dt = 0.04 s)");
    Ok(())
}
