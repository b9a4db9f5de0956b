//! General (not least-squares) cost terms: `stage NAME = l;` and `terminal NAME = l;` in a
//! `cost` block, the builder's `general_cost`, and their validation with spans.

use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, Place, parse};
use mpc_dsl::ocp::{Decl, Integrator, Ocp, OcpError, Stage};

const SRC: &str = "model m;
state x[2];
control u;
param w global default 2;
dynamics ode rk4 { der(x) = [x[1], u]; }
horizon N = 10, dt = 0.1;
cost {
    R = diag(0.1);
    stage energy = w * u^2;
    stage barrier = -log(4 - x[0]^2);
    terminal stop = x[1]^4;
    terminal residual end = x weight eye(2);
}
";

fn diag_of(src: &str) -> Vec<(usize, usize, String)> {
    let g = Graph::new();
    let e = parse(&g, src, &ParseOptions::default()).unwrap_err();
    e.items
        .iter()
        .map(|d| {
            let (l, c) = d.line_col(src);
            (l, c, d.message.clone())
        })
        .collect()
}

/// The parsed problem equals the builder's, node for node.
#[test]
fn parsed_terms_equal_the_builders() {
    let g = Graph::new();
    let parsed = parse(&g, SRC, &ParseOptions::default()).unwrap();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::vector("x", 2));
    let u = b.control(Decl::scalar("u"));
    let w = b.global_param(Decl::scalar("w").start(&[2.0]));
    b.ode(&[x[1], u[0]], Integrator::Rk4 { steps: 1 });
    b.horizon(10, 0.1);
    let r = mpc_dsl::Matrix::diag(&g, &mpc_dsl::Vector::constants(&g, &[0.1]));
    b.control_cost(r, &mpc_dsl::Vector::zeros(&g, 1));
    b.general_cost("energy", Stage::Path, w[0] * u[0].powi(2));
    b.general_cost("barrier", Stage::Path, -(4.0 - x[0].powi(2)).ln());
    b.general_cost("stop", Stage::Terminal, x[1].powi(4));
    b.residual("end", Stage::Terminal, &x, mpc_dsl::Matrix::identity(&g, 2));
    let built = b.build().unwrap();
    assert_eq!(parsed.ocp.cost.general, built.cost.general);
    assert_eq!(parsed.ocp.cost.residuals, built.cost.residuals);
    let names: Vec<_> = built.cost.general.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ["energy", "barrier", "stop"]);
    // The sum at each stage, and the source place of a term.
    let stage = built.cost.general_sum(Stage::Path).unwrap();
    assert_eq!(stage, w[0] * u[0].powi(2) + -(4.0 - x[0].powi(2)).ln());
    assert_eq!(built.cost.general_sum(Stage::Terminal), Some(x[1].powi(4)));
    let at = parsed
        .source
        .span(&Place::GeneralCost("barrier".into()))
        .unwrap();
    assert_eq!(&SRC[at], "-log(4 - x[0]^2)");
}

#[test]
fn a_control_in_a_terminal_term_is_an_error_at_its_name() {
    let src = SRC.replace("terminal stop = x[1]^4;", "terminal stop = x[1]^4 + u;");
    let list = diag_of(&src);
    assert_eq!(list.len(), 1, "{list:?}");
    assert_eq!((list[0].0, list[0].1), (11, 14), "{list:?}");
    assert!(
        list[0].2.contains("cost term `stop` depends on `u`")
            && list[0]
                .2
                .contains("terminal term sees x_N and parameters only"),
        "{}",
        list[0].2
    );
}

#[test]
fn a_vector_term_is_refused_with_its_span() {
    let src = SRC.replace("stage energy = w * u^2;", "stage energy = [u, u];");
    let list = diag_of(&src);
    assert_eq!(list.len(), 1, "{list:?}");
    assert_eq!((list[0].0, list[0].1), (9, 20));
    assert!(list[0].2.contains("must be a scalar"), "{}", list[0].2);
}

#[test]
fn a_duplicate_term_name_is_refused() {
    let src = SRC.replace("stage barrier", "stage energy");
    let list = diag_of(&src);
    assert_eq!(list.len(), 1, "{list:?}");
    assert_eq!((list[0].0, list[0].1), (10, 11));
    assert!(
        list[0].2.contains("`energy` is given twice"),
        "{}",
        list[0].2
    );
    // A term named like a residual or a declaration: the builder's validation.
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("x"));
    let u = b.control(Decl::scalar("u"));
    b.ode(&[u[0]], Integrator::Euler);
    b.horizon(3, 0.1);
    b.general_cost("x", Stage::Path, x[0] * u[0]);
    let e = b.build().unwrap_err();
    assert_eq!(e.errors, [OcpError::DuplicateName { name: "x".into() }]);
}

#[test]
fn an_unknown_symbol_in_a_term_is_named() {
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("x"));
    let u = b.control(Decl::scalar("u"));
    b.ode(&[u[0]], Integrator::Euler);
    b.horizon(3, 0.1);
    let ghost = g.symbol("ghost");
    b.general_cost("t", Stage::Path, x[0] * ghost);
    let e = b.build().unwrap_err();
    assert_eq!(e.errors.len(), 1, "{e}");
    let msg = e.errors[0].to_string();
    assert!(
        msg.contains("`ghost`") && msg.contains("cost term `t`"),
        "{msg}"
    );
}

/// `terminal residual` still starts a residual; `terminal residual = ...` is a general term
/// named `residual`.
#[test]
fn terminal_residual_keeps_its_meaning() {
    let src = SRC.replace("terminal stop = x[1]^4;", "terminal residual = x[1]^4;");
    let g = Graph::new();
    let p = parse(&g, &src, &ParseOptions::default()).unwrap();
    assert_eq!(p.ocp.cost.residuals.len(), 1);
    assert_eq!(p.ocp.cost.general[2].name, "residual");
    assert_eq!(p.ocp.cost.general[2].stage, Stage::Terminal);
}

/// The example of `docs/mpc-language.md` ("General cost terms") is the cost block of
/// `tests/data/pendulum_cost.mpc`, with comments: both parse to the same terms.
#[test]
fn the_documented_example_is_the_test_models() {
    let doc = include_str!("../../docs/mpc-language.md");
    let block = doc
        .split("```")
        .find(|b| b.contains("stage energy"))
        .expect("the documented example")
        .trim();
    let model = include_str!("../../tests/data/pendulum_cost.mpc");
    let start = model.find("cost {").unwrap();
    let end = start + model[start..].find('}').unwrap() + 1;
    let spliced = format!("{}{block}{}", &model[..start], &model[end..]);
    let g = Graph::new();
    let a = parse(&g, model, &ParseOptions::default()).unwrap();
    let b = parse(&g, &spliced, &ParseOptions::default()).unwrap();
    assert_eq!(a.ocp.cost.general.len(), 4);
    assert_eq!(a.ocp.cost.general, b.ocp.cost.general);
}
