//! Lowering facts the emitter relies on.

use mpc_codegen::lower;
use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};

fn lowered<R>(src: &str, f: impl FnOnce(&mpc_codegen::Lowered) -> R) -> R {
    let g = Graph::new();
    let parsed = match parse(&g, src, &ParseOptions::default()) {
        Ok(p) => p,
        Err(d) => panic!("{}", d.render("test.mpc", src)),
    };
    f(&lower(&parsed.ocp).unwrap())
}

fn weights_use_u_prev(src: &str) -> bool {
    lowered(src, |l| l.weights_use_u_prev)
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

const RESIDUAL_MODEL: &str = "
model residual_test;
state x[2];
control u;
param xr[2] stage default [0, 0];
dynamics ode rk4(1) { der(x) = [x[1], u]; }
horizon N = 5, dt = 0.1;
cost {
    Q = diag(1, 1) ref xr;
    R = diag(1);
    RESIDUAL
}
";

/// The RTI keeps `J'WJ` between linearizations only for models whose residual Jacobians are
/// constants: tracking residuals with references from parameters (QR-bench, the point mass)
/// are; a residual nonlinear in a state (stage or terminal), or the probe model's terminal
/// velocity residual, is not.
#[test]
fn constant_residual_jacobians_are_recognized() {
    let constant = |src: &str| lowered(src, |l| l.constant_residual_jacobians);
    assert!(constant(include_str!("../../models/quadrotor_rates.mpc")));
    assert!(constant(include_str!("../../models/paper_pointmass.mpc")));
    assert!(!constant(include_str!("../../models/quadrotor_probe.mpc")));
    assert!(constant(&RESIDUAL_MODEL.replace("RESIDUAL", "")));
    assert!(constant(&RESIDUAL_MODEL.replace(
        "RESIDUAL",
        "residual lin = 2 * x[0] - 3 * u + xr[1] * xr[0] weight eye(1);"
    )));
    assert!(!constant(&RESIDUAL_MODEL.replace(
        "RESIDUAL",
        "residual sq = x[0] * x[1] weight eye(1);"
    )));
    assert!(!constant(&RESIDUAL_MODEL.replace(
        "RESIDUAL",
        "terminal residual s = sin(x[0]) weight eye(1);"
    )));
}

/// The stages alone may have constant residual Jacobians while the terminal one does not
/// (the probe model's terminal velocity residual): then every stage shares one `J'WJ`
/// (`NH = 1`) and only the terminal one is computed again at each linearization.
#[test]
fn constant_stage_residual_jacobians_are_recognized() {
    let both = |src: &str| {
        lowered(src, |l| {
            (
                l.constant_stage_residual_jacobians,
                l.constant_residual_jacobians,
            )
        })
    };
    assert_eq!(
        both(include_str!("../../models/quadrotor_rates.mpc")),
        (true, true)
    );
    assert_eq!(
        both(include_str!("../../models/quadrotor_probe.mpc")),
        (true, false)
    );
    assert_eq!(both(&RESIDUAL_MODEL.replace("RESIDUAL", "")), (true, true));
    assert_eq!(
        both(&RESIDUAL_MODEL.replace("RESIDUAL", "terminal residual s = sin(x[0]) weight eye(1);")),
        (true, false)
    );
    assert_eq!(
        both(&RESIDUAL_MODEL.replace("RESIDUAL", "residual sq = x[0] * x[1] weight eye(1);")),
        (false, false)
    );
}
