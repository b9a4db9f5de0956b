//! `solver { shift = on | off; }`: the model's choice of the real-time iteration's shift,
//! and the located errors of a wrong block.

use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};

const BASE: &str = "model m;\nstate x;\ncontrol u;\ndynamics ode rk4 { der(x) = u; }\n\
                    horizon N = 5, dt = 0.1;\ncost { Q = diag(1); R = diag(1); }\n";

fn shift_of(block: &str) -> Option<bool> {
    let src = format!("{BASE}{block}");
    let g = Graph::new();
    match parse(&g, &src, &ParseOptions::default()) {
        Ok(p) => p.ocp.solver.shift,
        Err(d) => panic!("{}", d.render("m.mpc", &src)),
    }
}

/// The first error's message and its 1-based line and column.
fn error_of(block: &str) -> (String, (usize, usize)) {
    let src = format!("{BASE}{block}");
    let g = Graph::new();
    let Err(d) = parse(&g, &src, &ParseOptions::default()) else {
        panic!("`{block}` was accepted");
    };
    let e = d.errors().next().expect("an error");
    (e.message.clone(), e.line_col(&src))
}

#[test]
fn the_block_sets_the_shift_and_its_absence_leaves_the_default() {
    assert_eq!(shift_of(""), None);
    assert_eq!(shift_of("solver { shift = off; }\n"), Some(false));
    assert_eq!(shift_of("solver { shift = on; }\n"), Some(true));
    assert_eq!(shift_of("solver { }\n"), None);
}

#[test]
fn a_wrong_block_is_a_located_error() {
    let (m, at) = error_of("solver { shfit = on; }\n");
    assert!(m.contains("unknown solver setting `shfit`"), "{m}");
    assert_eq!(at, (7, 10));
    let (m, at) = error_of("solver { shift = yes; }\n");
    assert!(m.contains("`shift` is `on` or `off`, not `yes`"), "{m}");
    assert_eq!(at, (7, 18));
    let (m, at) = error_of("solver { shift = on; }\nsolver { shift = off; }\n");
    assert!(m.contains("the shift is given twice"), "{m}");
    assert_eq!(at, (8, 10));
}
