//! Soft state and control bounds: the `.mpc` syntax (`v in [0, 6] soft l1 = 100, l2 = 10;`)
//! gives the builder's problem, and every malformed soft bound is an error naming the entry,
//! with line and column from `.mpc` text.

use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};
use mpc_dsl::ocp::{Decl, Integrator, Ocp, OcpError, Slack};

const SRC: &str = "model m;
state x[3];
control u;
dynamics ode rk4 { der(x) = [x[1], x[2], u]; }
horizon N = 10, dt = 0.1;
cost { Q = diag(1, 1, 1); R = diag(0.1); }
constraints {
  u in [-2, 2] soft l2 = 10;
  x[0:2] in [-1, 1] soft l1 = [50, 60], l2 = 1;
  x[2] in [-inf, 3];
}
";

fn slack(l1: f64, l2: f64) -> Option<Slack> {
    Some(Slack { l1, l2 })
}

#[test]
fn soft_bounds_parse_to_the_builders_problem() {
    let g = Graph::new();
    let parsed = parse(&g, SRC, &ParseOptions::default()).unwrap().ocp;
    assert_eq!(parsed.control_bounds.soft, vec![slack(0.0, 10.0)]);
    assert_eq!(
        parsed.state_bounds.soft,
        vec![slack(50.0, 1.0), slack(60.0, 1.0), None]
    );
    assert_eq!(parsed.state_bounds.soft_entries(), vec![0, 1]);
    assert_eq!(parsed.state_bounds.upper, vec![1.0, 1.0, 3.0]);

    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::vector("x", 3));
    let u = b.control(Decl::scalar("u"));
    b.ode(&[x[1], x[2], u[0]], Integrator::Rk4 { steps: 1 });
    b.horizon(10, 0.1);
    b.state_cost(
        mpc_dsl::Matrix::diag(&g, &mpc_dsl::Vector::constants(&g, &[1.0, 1.0, 1.0])),
        &mpc_dsl::Vector::zeros(&g, 3),
    );
    b.control_cost(
        mpc_dsl::Matrix::diag(&g, &mpc_dsl::Vector::constants(&g, &[0.1])),
        &mpc_dsl::Vector::zeros(&g, 1),
    );
    b.soft_bound(&u, -2.0, 2.0, Slack { l1: 0.0, l2: 10.0 });
    b.soft_bound_each(
        &x[0..2],
        &[-1.0, -1.0],
        &[1.0, 1.0],
        &[Slack { l1: 50.0, l2: 1.0 }, Slack { l1: 60.0, l2: 1.0 }],
    );
    b.bound(&x[2..3], f64::NEG_INFINITY, 3.0);
    let built = b.build().unwrap();
    assert_eq!(built.state_bounds, parsed.state_bounds);
    assert_eq!(built.control_bounds, parsed.control_bounds);
}

/// The errors of `src` as (line, column, message).
fn diags(src: &str) -> Vec<(usize, usize, String)> {
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

/// `SRC` with the control's soft bound (line 8) replaced by `line`.
fn with_u_bound(line: &str) -> String {
    SRC.replace("u in [-2, 2] soft l2 = 10;", line)
}

#[test]
fn bad_penalties_are_errors_at_the_bound() {
    let cases = [
        (
            "u in [-2, 2] soft l1 = -1;",
            "soft control bound on `u`: slack penalty -1 is negative",
        ),
        (
            "u in [-2, 2] soft l1 = inf;",
            "slack penalty of soft control bound on `u`: constant inf is not finite",
        ),
        (
            "u in [-2, 2] soft l1 = 0, l2 = 0;",
            "soft control bound on `u`: soft with l1 = 0 and l2 = 0",
        ),
        (
            "u in [-inf, inf] soft l1 = 1;",
            "soft control bound on `u`: soft on an entry without a finite bound",
        ),
    ];
    for (line, want) in cases {
        let list = diags(&with_u_bound(line));
        assert_eq!(list.len(), 1, "{line}: {list:?}");
        assert_eq!((list[0].0, list[0].1), (8, 3), "{line}: {list:?}");
        assert!(list[0].2.contains(want), "{line}: {list:?}");
    }
    // One error per soft entry.
    let list = diags(&SRC.replace("l1 = [50, 60]", "l1 = [-50, 60]"));
    assert_eq!(list.len(), 1, "{list:?}");
    assert_eq!((list[0].0, list[0].1), (9, 3));
    assert!(list[0].2.contains("soft state bound on `x[0]`"), "{list:?}");
}

#[test]
fn malformed_soft_clauses_are_syntax_or_shape_errors() {
    let list = diags(&SRC.replace("l1 = [50, 60]", "l1 = [50, 60, 70]"));
    assert_eq!(list.len(), 1, "{list:?}");
    assert_eq!((list[0].0, list[0].1), (9, 31));
    assert_eq!(list[0].2, "the L1 penalty has 3 entries but `x` selects 2");
    let list = diags(&with_u_bound("u in [-2, 2] soft l3 = 1;"));
    assert_eq!((list[0].0, list[0].1), (8, 21));
    assert!(
        list[0].2.contains("expected `l1 = ...` or `l2 = ...`"),
        "{list:?}"
    );
    let list = diags(&with_u_bound("u in [-2, 2] soft l1 = u;"));
    assert!(
        list[0].2.contains("the L1 penalty must be a constant"),
        "{list:?}"
    );
    let list = diags(&with_u_bound("u in [-2, 2] l1 = 1;"));
    assert!(list[0].2.contains("`;` (or `soft`)"), "{list:?}");
}

#[test]
fn builder_soft_bounds_check_their_lengths_and_targets() {
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "m");
    let x = b.state(Decl::scalar("x"));
    let u = b.control(Decl::scalar("u"));
    let p = b.global_param(Decl::scalar("p"));
    b.ode(&[u[0]], Integrator::Euler);
    b.horizon(5, 0.1);
    b.soft_bound_each(&x, &[-1.0], &[1.0], &[]);
    b.soft_bound(&p, -1.0, 1.0, Slack { l1: 1.0, l2: 0.0 });
    let e = b.build().unwrap_err();
    assert_eq!(e.errors.len(), 2, "{e}");
    assert!(e.errors[0].to_string().contains("0 slack penalties"), "{e}");
    assert!(matches!(e.errors[1], OcpError::NotAVariable { .. }), "{e}");

    // A later hard bound on the same entry replaces the soft one.
    let mut b = Ocp::builder(&g, "m2");
    let x = b.state(Decl::scalar("y"));
    let u = b.control(Decl::scalar("v"));
    b.ode(&[u[0]], Integrator::Euler);
    b.horizon(5, 0.1);
    b.soft_bound(&x, -1.0, 1.0, Slack { l1: 1.0, l2: 0.0 });
    b.bound(&x, -2.0, 2.0);
    let ocp = b.build().unwrap();
    assert_eq!(ocp.state_bounds.soft, vec![None]);
    assert_eq!(ocp.state_bounds.lower, vec![-2.0]);
}
