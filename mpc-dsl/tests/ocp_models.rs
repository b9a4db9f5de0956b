//! The paper's models: `.mpc` files against the Rust builder (same `Ocp`), and their ODEs
//! against independent hand-written nalgebra implementations at random states.

use mpc_dsl::lang::{ParseOptions, parse};
use mpc_dsl::linalg::{Matrix, Vector, quat_mul, quat_rotate};
use mpc_dsl::ocp::{Decl, Dynamics, Integrator, Ocp, ParamKind};
use mpc_dsl::{Expr, Graph};
use nalgebra::{Quaternion, Vector3};

const QR: &str = include_str!("../../models/quadrotor_rates.mpc");
const PM: &str = include_str!("../../models/paper_pointmass.mpc");

mod common;
use common::Rng;

fn parse_ok<'g>(g: &'g Graph, src: &str, variant: Option<&str>) -> Ocp<'g> {
    let opts = ParseOptions {
        variant: variant.map(str::to_owned),
    };
    match parse(g, src, &opts) {
        Ok(p) => {
            assert!(
                p.warnings.is_empty(),
                "unexpected warnings: {:?}",
                p.warnings
            );
            p.ocp
        }
        Err(e) => panic!("{}", e.render("model.mpc", src)),
    }
}

/// QR-bench through the Rust builder, written from its definition in `docs/bench.md`.
fn quadrotor_rates_builder(g: &Graph) -> Ocp<'_> {
    let mut b = Ocp::builder(g, "quadrotor_rates");
    let p = b.state(
        Decl::vector("p", 3)
            .unit("m")
            .describe("position, world frame, z up"),
    );
    let q = b.state(
        Decl::vector("q", 4)
            .describe("attitude quaternion body->world (w, x, y, z)")
            .start(&[1.0, 0.0, 0.0, 0.0]),
    );
    let v = b.state(
        Decl::vector("v", 3)
            .unit("m/s")
            .describe("velocity, world frame"),
    );
    let c = b.control(
        Decl::scalar("c")
            .unit("m/s^2")
            .describe("mass-normalized collective thrust along body z"),
    );
    let w = b.control(
        Decl::vector("w", 3)
            .unit("rad/s")
            .describe("body rates (x, y, z)"),
    );
    let xref = b.param(
        Decl::vector("xref", 10)
            .describe("state reference")
            .start(&[4.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        ParamKind::Stage,
    );
    let uref = b.stage_param(
        Decl::vector("uref", 4)
            .describe("control reference")
            .start(&[9.81, 0.0, 0.0, 0.0]),
    );
    let z = g.zero();
    let q_dot = quat_mul(&q, &[z, w[0], w[1], w[2]]).unwrap().scale(0.5);
    let thrust = quat_rotate(&q, &[z, z, c[0]]).unwrap();
    let v_dot = [thrust[0], thrust[1], thrust[2] - 9.81];
    let xdot: Vec<Expr<'_>> = v
        .iter()
        .chain(q_dot.iter())
        .chain(&v_dot)
        .copied()
        .collect();
    b.ode(&xdot, Integrator::Rk4 { steps: 1 });
    b.horizon(20, 0.05);
    let qw = Matrix::diag(
        g,
        &Vector::constants(
            g,
            &[100.0, 100.0, 100.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0, 1.0],
        ),
    );
    b.state_cost(qw.clone(), &xref);
    b.control_cost(
        Matrix::diag(g, &Vector::constants(g, &[0.5, 1.0, 1.0, 1.0])),
        &uref,
    );
    b.terminal_cost(qw.scale(5.0), &xref);
    b.bound(&c, 0.0, 20.0);
    b.bound(&w[0..2], -20.0, 20.0);
    b.bound(&w[2..3], -6.0, 6.0);
    let _ = p;
    b.build().unwrap()
}

/// The paper's point-mass MPC through the Rust builder, written from SEED_PAPER.md.
fn paper_pointmass_builder(g: &Graph) -> Ocp<'_> {
    let mut b = Ocp::builder(g, "paper_pointmass");
    let _pos = b.state(Decl::vector("pos", 3).unit("m").describe("position P"));
    let vel = b.state(Decl::vector("vel", 3).unit("m/s").describe("velocity P'"));
    let acc = b.state(
        Decl::vector("acc", 3)
            .unit("m/s^2")
            .describe("acceleration P''"),
    );
    let jerk = b.control(
        Decl::vector("jerk", 3)
            .unit("m/s^3")
            .describe("jerk (ours: the paper's input f, differentiated)"),
    );
    let xref = b.stage_param(Decl::vector("xref", 9).describe("state reference"));
    let u_prev = b.global_param(
        Decl::vector("u_prev", 3).describe("jerk applied at the previous control step (u_{-1})"),
    );
    let q_w = b.global_param(
        Decl::vector("q_w", 9)
            .describe("diagonal of Q (default: the paper's)")
            .start(&[50.0, 10.0, 20.0, 10.0, 20.0, 10.0, 10.0, 10.0, 10.0]),
    );
    let p_w = b.global_param(
        Decl::vector("p_w", 9)
            .describe("diagonal of P (default: the paper's)")
            .start(&[100.0, 100.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0]),
    );
    let r_w = b.global_param(
        Decl::vector("r_w", 3)
            .describe("diagonal of R on the jerk change (default: identity)")
            .start(&[1.0]),
    );
    let xdot: Vec<Expr<'_>> = vel.iter().chain(&acc).chain(&jerk).copied().collect();
    b.ode(&xdot, Integrator::Rk4 { steps: 1 });
    b.horizon(10, 0.04);
    b.state_cost(Matrix::diag(g, &q_w), &xref);
    b.terminal_cost(Matrix::diag(g, &p_w), &xref);
    b.input_rate(Matrix::diag(g, &r_w), &u_prev);
    b.bound(&jerk, -50.0, 50.0);
    b.bound(&acc, -20.0, 20.0);
    b.build().unwrap()
}

#[test]
fn quadrotor_rates_file_equals_builder() {
    let g = Graph::new();
    let parsed = parse_ok(&g, QR, None);
    let built = quadrotor_rates_builder(&g);
    assert_eq!(parsed, built);
    assert_eq!((parsed.nx(), parsed.nu(), parsed.np()), (10, 4, 14));
    assert_eq!((parsed.horizon.n, parsed.horizon.dt), (20, 0.05));
    assert_eq!(parsed.control_bounds.lower, vec![0.0, -20.0, -20.0, -6.0]);
    assert_eq!(parsed.control_bounds.upper, vec![20.0, 20.0, 20.0, 6.0]);
    assert!(parsed.state_bounds.active().is_empty());
    // P = 5 Q, entry by entry.
    let (q, p) = (
        &parsed.cost.state.as_ref().unwrap().weight,
        &parsed.cost.terminal.as_ref().unwrap().weight,
    );
    let qd = [100.0, 100.0, 100.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0, 1.0];
    for i in 0..10 {
        for j in 0..10 {
            let want = if i == j { qd[i] } else { 0.0 };
            assert_eq!(q[(i, j)].as_constant(), Some(want));
            assert_eq!(p[(i, j)].as_constant(), Some(5.0 * want));
        }
    }
}

#[test]
fn quadrotor_rates_variant_a() {
    let g = Graph::new();
    let a = parse_ok(&g, QR, Some("A"));
    assert_eq!((a.horizon.n, a.horizon.dt), (10, 0.04));
    assert_eq!(a.name, "quadrotor_rates_A");
    let mut b = quadrotor_rates_builder(&g);
    b.horizon.n = 10;
    b.horizon.dt = 0.04;
    b.name = "quadrotor_rates_A".into();
    assert_eq!(a, b);
    let err = parse(
        &g,
        QR,
        &ParseOptions {
            variant: Some("C".into()),
        },
    )
    .unwrap_err();
    assert!(err.to_string().contains("variant C"), "{err}");
}

#[test]
fn paper_pointmass_file_equals_builder() {
    let g = Graph::new();
    let parsed = parse_ok(&g, PM, None);
    let built = paper_pointmass_builder(&g);
    assert_eq!(parsed, built);
    assert_eq!((parsed.nx(), parsed.nu(), parsed.np()), (9, 3, 33));
    assert_eq!((parsed.horizon.n, parsed.horizon.dt), (10, 0.04));
    assert!(parsed.cost.input_rate.is_some());
    assert!(parsed.cost.control.is_none());
}

/// QR-bench ODE, hand-written with nalgebra's quaternion product and the rotation formula
/// of `models/quadrotor_rates.mpc`.
fn qr_ode(x: &[f64], u: &[f64]) -> Vec<f64> {
    let q = Quaternion::new(x[3], x[4], x[5], x[6]);
    let omega = Quaternion::new(0.0, u[1], u[2], u[3]);
    let qd = (q * omega) * 0.5;
    let (qw, qx, qy, qz) = (x[3], x[4], x[5], x[6]);
    let c = u[0];
    let acc = Vector3::new(
        2.0 * (qw * qy + qx * qz) * c,
        2.0 * (qy * qz - qw * qx) * c,
        (1.0 - 2.0 * (qx * qx + qy * qy)) * c - 9.81,
    );
    vec![
        x[7], x[8], x[9], qd.w, qd.i, qd.j, qd.k, acc.x, acc.y, acc.z,
    ]
}

fn eval_dynamics(ocp: &Ocp<'_>, g: &Graph, x: &[f64], u: &[f64]) -> Vec<f64> {
    let mut bind: Vec<(Expr<'_>, f64)> = ocp.x().iter().copied().zip(x.iter().copied()).collect();
    bind.extend(ocp.u().iter().copied().zip(u.iter().copied()));
    g.eval(ocp.dynamics_exprs(), &bind).unwrap()
}

#[test]
fn quadrotor_rates_ode_matches_nalgebra() {
    let g = Graph::new();
    let ocp = parse_ok(&g, QR, None);
    assert!(matches!(
        ocp.dynamics,
        Dynamics::Continuous {
            integrator: Integrator::Rk4 { steps: 1 },
            ..
        }
    ));
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for _ in 0..200 {
        // Quaternions deliberately not normalized: the model does not renormalize.
        let x: Vec<f64> = (0..10).map(|_| rng.uniform(-2.0, 2.0)).collect();
        let u: Vec<f64> = (0..4).map(|_| rng.uniform(-10.0, 20.0)).collect();
        let got = eval_dynamics(&ocp, &g, &x, &u);
        let want = qr_ode(&x, &u);
        for (a, b) in got.iter().zip(&want) {
            assert!(
                (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                "{got:?} vs {want:?}"
            );
        }
    }
}

#[test]
fn paper_pointmass_ode_matches_nalgebra() {
    let g = Graph::new();
    let ocp = parse_ok(&g, PM, None);
    let mut rng = Rng(12345);
    for _ in 0..100 {
        let x: Vec<f64> = (0..9).map(|_| rng.uniform(-5.0, 5.0)).collect();
        let u: Vec<f64> = (0..3).map(|_| rng.uniform(-50.0, 50.0)).collect();
        // Triple integrator: d/dt [p; v; a] = [0 I 0; 0 0 I; 0 0 0] [p; v; a] + [0; 0; I] j.
        let mut a = nalgebra::DMatrix::<f64>::zeros(9, 9);
        let mut bm = nalgebra::DMatrix::<f64>::zeros(9, 3);
        for i in 0..3 {
            a[(i, 3 + i)] = 1.0;
            a[(3 + i, 6 + i)] = 1.0;
            bm[(6 + i, i)] = 1.0;
        }
        let want = &a * nalgebra::DVector::from_column_slice(&x)
            + &bm * nalgebra::DVector::from_column_slice(&u);
        let got = eval_dynamics(&ocp, &g, &x, &u);
        assert_eq!(got, want.as_slice());
    }
}

#[test]
fn builder_doc_and_metadata_survive() {
    let g = Graph::new();
    let ocp = parse_ok(&g, QR, None);
    let p = ocp.variable("p").unwrap();
    assert_eq!(p.unit.as_deref(), Some("m"));
    assert_eq!(ocp.x_guess()[3..7], [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(ocp.p_default()[10], 9.81);
    assert_eq!(ocp.u_guess(), vec![0.0; 4]);
}

/// The fenced code blocks of `docs/mpc-language.md` after "## Complete example".
fn doc_examples() -> Vec<String> {
    let doc = include_str!("../../docs/mpc-language.md");
    let part = doc.split("## Complete example").nth(1).unwrap();
    part.split("```")
        .skip(1)
        .step_by(2)
        .map(|b| b.trim_start_matches('\n').to_owned())
        .collect()
}

#[test]
fn documented_examples_parse() {
    let blocks = doc_examples();
    let g = Graph::new();
    // The complete example is the model file without its header comment.
    let body: String = QR
        .lines()
        .skip_while(|l| l.starts_with('#') || l.is_empty())
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(blocks[0], body);
    let full = format!("{}\n{}", blocks[0], blocks[1]);
    let ocp = parse_ok(&g, &full, None);
    assert_eq!(ocp.cost.residuals.len(), 2);
    assert_eq!(ocp.constraints.len(), 2);
    assert!(ocp.cost.input_rate.is_some());
    assert!(ocp.constraints[0].soft.is_some());
}
