//! Every validation error, from a malformed problem, with a message naming the culprit; the
//! `.mpc` front end's diagnostics with line, column and caret.

use mpc_dsl::lang::{DiagnosticKind, ParseOptions, parse};
use mpc_dsl::linalg::{Matrix, Vector};
use mpc_dsl::ocp::{Decl, Integrator, Ocp, OcpBuilder, OcpError, OcpWarning, Slack, Stage};
use mpc_dsl::{Graph, ValidationErrors};

/// A valid two-state, one-control problem to break in one place.
fn base(g: &Graph) -> OcpBuilder<'_> {
    let mut b = Ocp::builder(g, "base");
    let x = b.state(Decl::vector("x", 2));
    let u = b.control(Decl::scalar("u"));
    b.ode(&[x[1], u[0]], Integrator::Rk4 { steps: 1 });
    b.horizon(10, 0.1);
    b
}

fn errors(b: OcpBuilder<'_>) -> ValidationErrors {
    match b.build() {
        Ok(_) => panic!("the malformed problem was accepted"),
        Err(e) => e,
    }
}

fn one_error(b: OcpBuilder<'_>) -> OcpError {
    let e = errors(b);
    assert_eq!(e.errors.len(), 1, "{e}");
    e.errors[0].clone()
}

#[test]
fn the_base_problem_is_valid() {
    let g = Graph::new();
    let ocp = base(&g).build().unwrap();
    assert_eq!((ocp.nx(), ocp.nu(), ocp.np()), (2, 1, 0));
}

#[test]
fn unknown_symbol_is_named() {
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("x"));
    let _u = b.control(Decl::scalar("u"));
    let ghost = g.symbol("ghost");
    b.ode(&[x[0] * ghost], Integrator::Euler);
    b.horizon(5, 0.1);
    let e = errors(b);
    let msg = e.errors[0].to_string();
    assert!(matches!(e.errors[0], OcpError::UnknownSymbol { .. }), "{e}");
    assert!(msg.contains("`ghost`") && msg.contains("dynamics"), "{msg}");
}

#[test]
fn duplicate_name_is_named() {
    let g = Graph::new();
    let mut b = base(&g);
    b.global_param(Decl::scalar("x"));
    let e = one_error(b);
    assert!(e.to_string().contains("duplicate name `x`"), "{e}");
    // Residuals and constraints share the namespace.
    let mut b = base(&g);
    let x = g.symbols("x", 2);
    b.constraint("c1", Stage::Path, &x[0..1], &[0.0], &[1.0]);
    b.constraint("c1", Stage::Path, &x[1..2], &[0.0], &[1.0]);
    assert!(one_error(b).to_string().contains("`c1`"));
}

#[test]
fn dimension_mismatch_names_the_weight() {
    // The issue's example: Q is 9x9 but the state has 10 entries.
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::vector("x", 10));
    let u = b.control(Decl::scalar("u"));
    let mut xdot = x[1..].to_vec();
    xdot.push(u[0]);
    b.ode(&xdot, Integrator::Rk4 { steps: 2 });
    b.horizon(10, 0.1);
    b.state_cost(Matrix::identity(&g, 9), &Vector::zeros(&g, 10));
    let e = one_error(b);
    assert_eq!(e.to_string(), "Q is 9x9 but the state has 10 entries");
    // Dynamics of the wrong length.
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::vector("x", 2));
    b.discrete(&x[0..1]);
    b.horizon(10, 0.1);
    assert!(
        one_error(b)
            .to_string()
            .contains("the dynamics is of length 1 but the state has 2")
    );
    // A residual weight of the wrong size.
    let mut b = base(&g);
    let x = g.symbols("x", 2);
    b.residual("r", Stage::Path, &x, Matrix::identity(&g, 3));
    assert!(
        one_error(b)
            .to_string()
            .contains("weight of residual `r` is 3x3 but the residual has 2")
    );
}

#[test]
fn non_symmetric_weight_is_named() {
    let g = Graph::new();
    let mut b = base(&g);
    let w = Matrix::constants(&g, &[[1.0, 2.0], [3.0, 1.0]]).unwrap();
    b.state_cost(w, &Vector::zeros(&g, 2));
    let e = one_error(b);
    assert!(
        matches!(e, OcpError::NotSymmetric { i: 0, j: 1, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("weight Q is not symmetric"), "{e}");
}

#[test]
fn indefinite_weight_is_named_with_its_eigenvalue() {
    let g = Graph::new();
    let mut b = base(&g);
    // [[1, 2], [2, 1]] has eigenvalues 3 and -1 (closed form 1 ± 2).
    let w = Matrix::constants(&g, &[[1.0, 2.0], [2.0, 1.0]]).unwrap();
    b.terminal_cost(w, &Vector::zeros(&g, 2));
    match one_error(b) {
        e @ OcpError::NotPsd { .. } => {
            let OcpError::NotPsd { eigenvalue, .. } = &e else {
                unreachable!()
            };
            assert!((eigenvalue + 1.0).abs() < 1e-12);
            assert!(
                e.to_string()
                    .contains("weight P is not positive semidefinite"),
                "{e}"
            );
        }
        e => panic!("{e}"),
    }
    // A PSD but singular weight is fine.
    let mut b = base(&g);
    let w = Matrix::constants(&g, &[[1.0, 1.0], [1.0, 1.0]]).unwrap();
    b.terminal_cost(w, &Vector::zeros(&g, 2));
    assert!(b.build().is_ok());
}

#[test]
fn jacobi_eigenvalues_match_nalgebra() {
    let mut seed = 7u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    for n in 1..8 {
        let a = nalgebra::DMatrix::<f64>::from_fn(n, n, |_, _| next());
        let s = &a + a.transpose();
        let data: Vec<f64> = (0..n * n).map(|k| s[(k / n, k % n)]).collect();
        let got = mpc_dsl::ocp::symmetric_eigenvalues(&data, n);
        let mut want: Vec<f64> = s.symmetric_eigen().eigenvalues.iter().copied().collect();
        want.sort_by(f64::total_cmp);
        for (a, b) in got.iter().zip(&want) {
            assert!((a - b).abs() < 1e-10, "{got:?} vs {want:?}");
        }
    }
}

#[test]
fn crossed_bounds_are_named() {
    let g = Graph::new();
    let mut b = base(&g);
    let u = g.symbol("u");
    b.bound(&[u], 5.0, 1.0);
    let e = one_error(b);
    assert_eq!(
        e.to_string(),
        "control bound on `u`: lower bound 5 is above upper bound 1"
    );
    let mut b = base(&g);
    let x = g.symbols("x", 2);
    b.constraint("corridor", Stage::Terminal, &x[0..1], &[2.0], &[-2.0]);
    assert!(
        one_error(b)
            .to_string()
            .contains("constraint `corridor` entry 0")
    );
}

#[test]
fn infinite_bounds_are_allowed_but_nan_is_not() {
    let g = Graph::new();
    let mut b = base(&g);
    let x = g.symbols("x", 2);
    b.bound(&x, f64::NEG_INFINITY, 3.0);
    let ocp = b.build().unwrap();
    assert_eq!(ocp.state_bounds.active(), vec![0, 1]);
    let mut b = base(&g);
    b.bound(&x[0..1], f64::NAN, 3.0);
    let e = one_error(b);
    assert!(
        e.to_string()
            .contains("state bound on `x[0]` (lower): constant NaN"),
        "{e}"
    );
}

#[test]
fn non_finite_constants_are_named() {
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("x"));
    let u = b.control(Decl::scalar("u"));
    b.ode(&[x[0] * f64::NAN + u[0]], Integrator::Euler);
    b.horizon(5, 0.1);
    let e = one_error(b);
    assert!(
        e.to_string().starts_with("the dynamics: constant NaN"),
        "{e}"
    );
    // In a weight, a guess and a reference.
    let mut b = base(&g);
    b.control_cost(
        Matrix::diag(&g, &[g.constant_unchecked(f64::INFINITY)]),
        &Vector::zeros(&g, 1),
    );
    assert!(one_error(b).to_string().starts_with("R: constant inf"));
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("y").start(&[f64::INFINITY]));
    b.discrete(&x);
    b.horizon(1, 1.0);
    assert!(
        one_error(b)
            .to_string()
            .contains("initial guess of `y`: constant inf")
    );
}

#[test]
fn zero_horizon_and_bad_dt() {
    let g = Graph::new();
    for (n, dt, want) in [
        (0, 0.1, "horizon N = 0"),
        (5, 0.0, "horizon dt = 0"),
        (5, -0.5, "horizon dt = -0.5"),
        (5, f64::NAN, "horizon dt = NaN"),
    ] {
        let mut b = base(&g);
        b.horizon(n, dt);
        let e = one_error(b);
        assert!(e.to_string().starts_with(want), "{e}");
    }
}

#[test]
fn all_errors_are_collected() {
    let g = Graph::new();
    let mut b = base(&g);
    b.horizon(0, -1.0);
    b.state_cost(Matrix::identity(&g, 3), &Vector::zeros(&g, 2));
    b.bound(&[g.symbol("u")], 1.0, 0.0);
    let e = errors(b);
    assert_eq!(e.errors.len(), 4, "{e}");
    let text = e.to_string();
    for s in ["N = 0", "dt = -1", "Q is 3x3", "control bound on `u`"] {
        assert!(text.contains(s), "{text}");
    }
}

#[test]
fn unused_control_is_a_warning() {
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("x"));
    let u = b.control(Decl::vector("u", 2));
    b.ode(&[x[0] + u[0]], Integrator::Euler);
    b.horizon(5, 0.1);
    let (_, w) = b.build_with_warnings().unwrap();
    assert_eq!(
        w,
        vec![OcpWarning::UnusedControl {
            name: "u[1]".into()
        }]
    );
    assert!(w[0].to_string().contains("control `u[1]`"));
}

#[test]
fn other_structural_errors_are_named() {
    let g = Graph::new();
    // Terminal terms cannot see controls.
    let mut b = base(&g);
    let u = g.symbol("u");
    b.residual("final_u", Stage::Terminal, &[u], Matrix::identity(&g, 1));
    let e = one_error(b);
    assert!(
        e.to_string().contains("residual `final_u` depends on `u`"),
        "{e}"
    );
    // Weights may depend on global parameters only.
    let mut b = base(&g);
    let x = g.symbols("x", 2);
    b.state_cost(Matrix::diag(&g, &x), &Vector::zeros(&g, 2));
    let e = errors(b);
    assert_eq!(e.errors.len(), 2, "one error per offending symbol: {e}");
    assert!(e.errors[0].to_string().contains("Q depends on `x[0]`"));
    // Runtime weights from a global parameter are accepted.
    let mut b = base(&g);
    let qd = b.global_param(Decl::vector("qdiag", 2).start(&[1.0]));
    b.state_cost(Matrix::diag(&g, &qd), &Vector::zeros(&g, 2));
    assert!(b.build().is_ok());
    // RK4 with no substeps.
    let mut b = base(&g);
    b.ode(&[x[1], u], Integrator::Rk4 { steps: 0 });
    let e = errors(b);
    assert!(e.to_string().contains("rk4 with 0 substeps"), "{e}");
    // Missing dynamics; bound on a parameter; negative slack penalty.
    let mut b = Ocp::builder(&g, "m");
    b.state(Decl::scalar("z"));
    b.horizon(3, 0.1);
    assert!(one_error(b).to_string().contains("no dynamics"));
    let mut b = base(&g);
    let m = b.global_param(Decl::scalar("mass"));
    b.bound(&m, 0.0, 1.0);
    assert!(
        one_error(b)
            .to_string()
            .contains("`mass` is not a state or control")
    );
    let mut b = base(&g);
    b.soft_constraint(
        "s",
        Stage::Path,
        &x[0..1],
        &[0.0],
        &[1.0],
        Slack { l1: -1.0, l2: 0.0 },
    );
    assert!(
        one_error(b)
            .to_string()
            .contains("constraint `s`: slack penalty -1")
    );
}

// ------------------------------------------------------------------ .mpc diagnostics

const GOOD: &str = "model m;
state x[2];
control u;
dynamics ode rk4 { der(x) = [x[1], u]; }
horizon N = 10, dt = 0.1;
cost { Q = diag(1, 1); R = diag(0.1); }
constraints { u in [-1, 1]; }
";

fn diag_of(src: &str) -> (String, Vec<(usize, usize, String)>) {
    let g = Graph::new();
    let e = parse(&g, src, &ParseOptions::default()).unwrap_err();
    let rendered = e.render("m.mpc", src);
    let list = e
        .items
        .iter()
        .map(|d| {
            let (l, c) = d.line_col(src);
            (l, c, d.message.clone())
        })
        .collect();
    (rendered, list)
}

#[test]
fn good_source_parses() {
    let g = Graph::new();
    let p = parse(&g, GOOD, &ParseOptions::default()).unwrap();
    assert_eq!(p.ocp.control_bounds.lower, vec![-1.0]);
}

#[test]
fn syntax_error_has_line_column_and_caret() {
    let src = GOOD.replace("horizon N = 10, dt = 0.1;", "horizon N = 10 dt = 0.1;");
    let (text, list) = diag_of(&src);
    assert_eq!(list.len(), 1, "{text}");
    assert_eq!((list[0].0, list[0].1), (5, 16));
    assert!(list[0].2.contains("expected `,`"), "{text}");
    assert!(text.contains("m.mpc:5:16"), "{text}");
    assert!(text.contains("horizon N = 10 dt = 0.1;"), "{text}");
    assert!(text.contains('^'), "{text}");
}

#[test]
fn unknown_name_points_at_the_use() {
    let src = GOOD.replace("[x[1], u]", "[x[1], thrust]");
    let (text, list) = diag_of(&src);
    assert_eq!(list.len(), 1, "{text}");
    assert_eq!((list[0].0, list[0].1), (4, 36));
    assert!(list[0].2.contains("unknown name `thrust`"));
}

#[test]
fn several_errors_are_all_reported() {
    let src = GOOD
        .replace("[x[1], u]", "[x[1], ghost]")
        .replace("R = diag(0.1);", "R = diag(0.1) ref;")
        .replace("u in [-1, 1]", "u in [-1 1]");
    let (text, list) = diag_of(&src);
    assert_eq!(list.len(), 3, "{text}");
    assert_eq!(list.iter().map(|d| d.0).collect::<Vec<_>>(), vec![4, 6, 7]);
}

#[test]
fn validation_errors_point_at_their_item() {
    let src = GOOD.replace("Q = diag(1, 1)", "Q = diag(1, 1, 1)");
    let (text, list) = diag_of(&src);
    assert_eq!(list.len(), 1, "{text}");
    assert_eq!(list[0].2, "Q is 3x3 but the state has 2 entries");
    assert_eq!((list[0].0, list[0].1), (6, 8));
    let src = GOOD.replace("u in [-1, 1]", "u in [1, -1]");
    let (_, list) = diag_of(&src);
    assert_eq!(list[0].0, 7);
    assert!(list[0].2.contains("control bound on `u`"));
    let src = GOOD.replace("N = 10", "N = 0");
    let (_, list) = diag_of(&src);
    assert_eq!(
        (list[0].0, list[0].2.starts_with("horizon N = 0")),
        (5, true)
    );
    let src = GOOD.replace("state x[2];", "state x[2];\nparam x global;");
    let (_, list) = diag_of(&src);
    assert!(list[0].2.contains("duplicate name `x`"), "{list:?}");
    assert_eq!((list[0].0, list[0].1), (3, 7));
    let src = GOOD.replace("R = diag(0.1)", "R = mat([1, 2], [2, 1])");
    let (text, _) = diag_of(&src);
    assert!(text.contains("R is 2x2"), "{text}");
    let src = GOOD.replace("Q = diag(1, 1)", "Q = mat([1, 2], [2, 1])");
    let (text, _) = diag_of(&src);
    assert!(
        text.contains("weight Q is not positive semidefinite"),
        "{text}"
    );
    let src = GOOD.replace("[x[1], u]", "[x[1] * inf, u]");
    let (text, _) = diag_of(&src);
    assert!(text.contains("the dynamics: constant inf"), "{text}");
    let src = GOOD.replace("dt = 0.1", "dt = -0.1");
    let (text, _) = diag_of(&src);
    assert!(text.contains("horizon dt = -0.1"), "{text}");
}

#[test]
fn unused_control_warning_from_source() {
    let src = GOOD
        .replace("control u;", "control u;\ncontrol spare;")
        .replace("R = diag(0.1)", "R = diag(0.1, 0.1)");
    let g = Graph::new();
    let p = parse(&g, &src, &ParseOptions::default()).unwrap();
    assert_eq!(p.warnings.len(), 1);
    assert!(matches!(p.warnings[0].kind, DiagnosticKind::Warning(_)));
    assert_eq!(p.warnings[0].line_col(&src), (4, 9));
}

#[test]
fn shape_errors_in_expressions() {
    let src = GOOD.replace("[x[1], u]", "[x[1], u] + [1, 2, 3]");
    let (text, list) = diag_of(&src);
    assert!(list[0].2.contains("same shape"), "{text}");
    let src = GOOD.replace("[x[1], u]", "[x[5], u]");
    let (text, _) = diag_of(&src);
    assert!(text.contains("index 5 is out of range"), "{text}");
    let src = GOOD.replace("[x[1], u]", "[x[1], frob(u)]");
    let (text, _) = diag_of(&src);
    assert!(text.contains("unknown function `frob`"), "{text}");
}

#[test]
fn missing_state_equation_is_named() {
    let src = GOOD.replace("state x[2];", "state x[2];\nstate extra;");
    let (text, _) = diag_of(&src);
    assert!(text.contains("no equation for state(s) `extra`"), "{text}");
}

#[test]
fn general_and_soft_constraints_parse() {
    let src = GOOD.replace(
        "u in [-1, 1];",
        "u in [-1, 1];\n  speed: -inf <= x[1]^2 <= 4 soft l1 = 100, l2 = 10;\n  terminal stop: 0 <= x <= [0, 0];",
    );
    let g = Graph::new();
    let p = parse(&g, &src, &ParseOptions::default()).unwrap().ocp;
    assert_eq!(p.constraints.len(), 2);
    assert_eq!(p.constraints[0].lower, vec![f64::NEG_INFINITY]);
    assert_eq!(
        p.constraints[0].soft,
        Some(Slack {
            l1: 100.0,
            l2: 10.0
        })
    );
    assert_eq!(p.constraints[1].stage, Stage::Terminal);
    assert_eq!(p.constraints[1].expr.len(), 2);
    // A terminal constraint that uses the control is rejected, naming it.
    let bad = src.replace("terminal stop: 0 <= x", "terminal stop: 0 <= x + u");
    let (text, _) = diag_of(&bad);
    assert!(text.contains("constraint `stop` depends on `u`"), "{text}");
}
