//! `dynamics ode irk(stages = s, steps = k, newton = n, collocation = c)`: what it parses
//! to, its defaults,
//! the Rust builder's equivalent, and the located errors of wrong options (from the parser)
//! and out-of-range values (from validation, located at the integrator).

use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};
use mpc_dsl::ocp::{Collocation, Decl, Dynamics, Integrator, Ocp, OcpError};

/// A model whose integrator is `integ`; the integrator starts on line 4, column 14.
fn model(integ: &str) -> String {
    format!(
        "model m;\nstate x;\ncontrol u;\ndynamics ode {integ} {{ der(x) = -x + u; }}\n\
         horizon N = 5, dt = 0.1;\ncost {{ Q = diag(1); R = diag(1); }}\n"
    )
}

fn integrator_of(integ: &str) -> Integrator {
    let src = model(integ);
    let g = Graph::new();
    match parse(&g, &src, &ParseOptions::default()) {
        Ok(p) => match p.ocp.dynamics {
            Dynamics::Continuous { integrator, .. } => integrator,
            Dynamics::Discrete { .. } => panic!("not an ode"),
        },
        Err(d) => panic!("{}", d.render("m.mpc", &src)),
    }
}

/// The first error's message and its 1-based line and column.
fn error_of(integ: &str) -> (String, (usize, usize)) {
    let src = model(integ);
    let g = Graph::new();
    let Err(d) = parse(&g, &src, &ParseOptions::default()) else {
        panic!("`{integ}` was accepted");
    };
    let e = d.errors().next().expect("an error");
    (e.message.clone(), e.line_col(&src))
}

fn irk(stages: usize, steps: usize, newton: usize) -> Integrator {
    Integrator::Irk {
        stages,
        steps,
        newton,
        collocation: Collocation::GaussLegendre,
    }
}

#[test]
fn the_options_parse_in_any_order_with_defaults() {
    assert_eq!(
        integrator_of("irk(stages = 3, steps = 2, newton = 5)"),
        irk(3, 2, 5)
    );
    assert_eq!(integrator_of("irk(newton = 1, stages = 1)"), irk(1, 1, 1));
    assert_eq!(integrator_of("irk(steps = 4)"), irk(2, 4, 3));
    assert_eq!(integrator_of("irk"), irk(2, 1, 3));
    assert_eq!(integrator_of("irk"), Integrator::gauss_legendre(2));
    // The options are constant expressions, as rk4's substeps are.
    assert_eq!(integrator_of("irk(stages = 1 + 2)"), irk(3, 1, 3));
    let radau = Integrator::Irk {
        stages: 3,
        steps: 2,
        newton: 3,
        collocation: Collocation::RadauIia,
    };
    assert_eq!(
        integrator_of("irk(collocation = radau_iia, stages = 3, steps = 2)"),
        radau
    );
    assert_eq!(
        integrator_of("irk(collocation = gauss_legendre)"),
        irk(2, 1, 3)
    );
}

#[test]
fn the_builder_makes_the_same_problem() {
    let src = model("irk(stages = 3, steps = 2, newton = 4)");
    let g = Graph::new();
    let parsed = parse(&g, &src, &ParseOptions::default()).unwrap().ocp;
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("x"));
    let u = b.control(Decl::scalar("u"));
    b.ode(&[-x[0] + u[0]], irk(3, 2, 4));
    b.horizon(5, 0.1);
    b.state_cost(
        mpc_dsl::Matrix::identity(&g, 1),
        &mpc_dsl::Vector::zeros(&g, 1),
    );
    b.control_cost(
        mpc_dsl::Matrix::identity(&g, 1),
        &mpc_dsl::Vector::zeros(&g, 1),
    );
    let built = b.build().unwrap();
    assert_eq!(built.dynamics, parsed.dynamics);
    // No closed-form map: a typed error, not a panic.
    assert!(matches!(
        built.discrete_map(),
        Err(mpc_dsl::DslError::NoClosedForm { .. })
    ));
}

#[test]
fn the_builder_refuses_out_of_range_settings() {
    let g = Graph::new();
    for (integ, want) in [
        (irk(0, 1, 3), OcpError::IrkStages { stages: 0 }),
        (irk(4, 1, 3), OcpError::IrkStages { stages: 4 }),
        (irk(2, 0, 3), OcpError::IrkZero { what: "substeps" }),
        (
            irk(2, 1, 0),
            OcpError::IrkZero {
                what: "Newton iterations",
            },
        ),
    ] {
        let mut b = Ocp::builder(&g, "m");
        let x = b.state(Decl::scalar("x"));
        let u = b.control(Decl::scalar("u"));
        b.ode(&[-x[0] + u[0]], integ);
        b.horizon(5, 0.1);
        b.state_cost(
            mpc_dsl::Matrix::identity(&g, 1),
            &mpc_dsl::Vector::zeros(&g, 1),
        );
        let e = b.build().expect_err("refused");
        assert_eq!(e.errors, vec![want], "{integ:?}");
    }
}

#[test]
fn wrong_options_are_located_errors() {
    // Validation errors point at the integrator (line 4, column 14).
    let (m, at) = error_of("irk(stages = 4)");
    assert!(
        m.contains("irk with 4 stages") && m.contains("1, 2 or 3"),
        "{m}"
    );
    assert_eq!(at, (4, 14));
    let (m, at) = error_of("irk(newton = 0)");
    assert!(
        m.contains("irk with 0 Newton iterations: use at least 1"),
        "{m}"
    );
    assert_eq!(at, (4, 14));
    let (m, at) = error_of("irk(steps = 0)");
    assert!(m.contains("irk with 0 substeps"), "{m}");
    assert_eq!(at, (4, 14));
    // Parse errors point at the option.
    let (m, at) = error_of("irk(stage = 2)");
    assert!(m.contains("unknown irk option `stage`"), "{m}");
    assert_eq!(at, (4, 18));
    let (m, at) = error_of("irk(steps = 2, steps = 3)");
    assert!(m.contains("irk option `steps` given twice"), "{m}");
    assert_eq!(at, (4, 29));
    let (m, at) = error_of("irk(stages = 1.5)");
    assert!(m.contains("whole number"), "{m}");
    assert_eq!(at, (4, 27));
    let (m, at) = error_of("irk(collocation = lobatto)");
    assert!(m.contains("unknown collocation `lobatto`"), "{m}");
    assert_eq!(at, (4, 32));
    let (m, _) = error_of("gl(2)");
    assert!(
        m.contains("`irk(stages = s, steps = k, newton = n)`"),
        "{m}"
    );
}
