//! Constant expressions whose value is not finite (`0/0`, `1/0`, `sqrt(-1)`, `log(0)`, ...)
//! are refused where they are written, with the line and column of the offending expression,
//! instead of being folded to a finite value.

use mpc_dsl::lang::{DiagnosticKind, ParseOptions, parse};
use mpc_dsl::ocp::{Decl, Integrator, Ocp};
use mpc_dsl::{Graph, OcpError};

/// A model whose dynamics are `der(x) = EXPR + x + u` (EXPR on line 4, column 29).
fn model(expr: &str) -> String {
    format!(
        "model m;\nstate x;\ncontrol u;\n\
         dynamics ode rk4 {{ der(x) = {expr} + x + u; }}\nhorizon N = 5, dt = 0.1;\n\
         cost {{ Q = diag(1); R = diag(1); }}\n"
    )
}

/// The single error of `src`: its message, line and column.
fn error_of(src: &str) -> (String, usize, usize) {
    let g = Graph::new();
    let d = parse(&g, src, &ParseOptions::default()).expect_err("must be refused");
    let errors: Vec<_> = d.errors().collect();
    assert_eq!(errors.len(), 1, "{}", d.render("m.mpc", src));
    assert_eq!(errors[0].kind, DiagnosticKind::Semantic);
    let (line, col) = errors[0].line_col(src);
    (errors[0].message.clone(), line, col)
}

#[test]
fn non_finite_constant_expressions_are_located_errors() {
    let cases = [
        ("0/0", "NaN", 29),
        ("0*(1/0)", "inf", 32),
        ("1/0", "inf", 29),
        ("sqrt(-1)", "NaN", 29),
        ("log(0)", "-inf", 29),
        ("log(-1)", "NaN", 29),
        ("(-8)^(1/3)", "NaN", 29),
        ("pow(-8, 0.5)", "NaN", 29),
        ("0^-1", "inf", 29),
        ("inf - inf", "NaN", 29),
        ("0 * inf", "NaN", 29),
        ("1e308 * 10", "inf", 29),
        ("2 + asin(2)", "NaN", 33),
    ];
    for (expr, value, col) in cases {
        let (msg, line, c) = error_of(&model(expr));
        assert!(
            msg.contains(&format!("evaluates to {value}")) && msg.contains("fix the numbers"),
            "{expr}: {msg}"
        );
        assert_eq!((line, c), (4, col), "{expr}: {msg}");
    }
}

#[test]
fn the_innermost_offending_expression_is_pointed_at() {
    let src = model("1 + 2 * (3 - 1/0)");
    let g = Graph::new();
    let d = parse(&g, &src, &ParseOptions::default()).unwrap_err();
    let text = d.render("m.mpc", &src);
    assert!(text.contains("m.mpc:4:42"), "{text}");
    // The caret spans `1/0`, not the whole right-hand side.
    let e = d.errors().next().unwrap();
    assert_eq!(&src[e.span.clone()], "1/0");
}

#[test]
fn finite_constants_and_infinite_bounds_still_pass() {
    for expr in ["0/1", "sqrt(4)", "log(1)", "0 * 5", "2^-1", "(-8)^3"] {
        let g = Graph::new();
        assert!(
            parse(&g, &model(expr), &ParseOptions::default()).is_ok(),
            "{expr}"
        );
    }
    let src = model("1").replace(
        "cost {",
        "constraints { u in [-inf, 2 * inf]; k: -inf <= x <= inf; }\ncost {",
    );
    let g = Graph::new();
    assert!(parse(&g, &src, &ParseOptions::default()).is_ok());
}

#[test]
fn the_builder_refuses_a_non_finite_constant_expression_in_a_function() {
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("x"));
    let u = b.control(Decl::scalar("u"));
    // 0 * (1/0) is NaN, not 0: it must reach validation, not vanish.
    let bad = g.zero() * (1.0 / g.zero());
    b.ode(&[x[0] + u[0] + bad], Integrator::Euler);
    b.horizon(5, 0.1);
    let errors = b.build().unwrap_err().errors;
    assert!(
        errors.iter().any(|e| matches!(
            e,
            OcpError::NonFinite { item, value } if item == "the dynamics" && value.is_nan()
        )),
        "{errors:?}"
    );
}
