//! Lowering facts the emitter relies on.

use mpc_codegen::lower;
use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};

fn weights_use_u_prev(src: &str) -> bool {
    let g = Graph::new();
    let parsed = match parse(&g, src, &ParseOptions::default()) {
        Ok(p) => p,
        Err(d) => panic!("{}", d.render("test.mpc", src)),
    };
    lower(&parsed.ocp).unwrap().weights_use_u_prev
}

const RATE_MODEL: &str = "
model rate_test;
state x[2];
control u;
param up global default 0;
param w global default 1;
dynamics ode rk4(1) { der(x) = [x[1], u]; }
horizon N = 5, dt = 0.1;
cost {
    Q = diag(1, 1);
    rate = WEIGHT prev [up];
}
";

/// The automatic u_prev update after each feedback re-evaluates the weights only when they
/// read u_prev: the paper's point-mass model (weights from other global parameters) does
/// not, a weight made of u_prev itself does.
#[test]
fn the_weights_are_known_to_read_u_prev_or_not() {
    let pointmass = include_str!("../../models/paper_pointmass.mpc");
    assert!(!weights_use_u_prev(pointmass));
    assert!(!weights_use_u_prev(
        &RATE_MODEL.replace("WEIGHT", "diag(w)")
    ));
    assert!(weights_use_u_prev(
        &RATE_MODEL.replace("WEIGHT", "diag(1 + up^2)")
    ));
}
