//! The `.mpc` parser never panics: random bytes, random token soups, mutated models, deep
//! nesting. Every failure comes back as diagnostics that render with a caret.

use mpc_dsl::lang::check_source;
use proptest::prelude::*;

const MODELS: [&str; 3] = [
    include_str!("../../models/quadrotor_rates.mpc"),
    include_str!("../../models/paper_pointmass.mpc"),
    include_str!("../../models/quadrotor_probe.mpc"),
];

const TOKENS: &[&str] = &[
    "model",
    "state",
    "control",
    "param",
    "let",
    "dynamics",
    "ode",
    "discrete",
    "rk4",
    "euler",
    "der",
    "next",
    "horizon",
    "N",
    "dt",
    "cost",
    "constraints",
    "variant",
    "Q",
    "R",
    "P",
    "ref",
    "residual",
    "terminal",
    "rate",
    "prev",
    "weight",
    "in",
    "soft",
    "l1",
    "l2",
    "stage",
    "global",
    "default",
    "guess",
    "unit",
    "doc",
    "x",
    "u",
    "p",
    "diag",
    "eye",
    "mat",
    "quat_mul",
    "quat_rotate",
    "norm",
    "sin",
    "inf",
    "pi",
    "0",
    "1",
    "2.5",
    "1e308",
    "4096",
    "\"m\"",
    "(",
    ")",
    "[",
    "]",
    "{",
    "}",
    ",",
    ";",
    ":",
    "=",
    "<=",
    "+",
    "-",
    "*",
    "/",
    "^",
    "#",
    "\n",
    "é",
    "@",
];

/// Parses and renders; the point is that neither panics.
fn exercise(src: &str) {
    if let Err(d) = check_source(src) {
        assert!(!d.items.is_empty());
        let text = d.render("fuzz.mpc", src);
        assert!(text.contains("fuzz.mpc"), "{text}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        exercise(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn token_soup_never_panics(idx in proptest::collection::vec(0..TOKENS.len(), 0..120)) {
        let src: Vec<&str> = idx.iter().map(|&i| TOKENS[i]).collect();
        exercise(&src.join(" "));
    }

    #[test]
    fn mutated_models_never_panic(
        which in 0..MODELS.len(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), 0..TOKENS.len(), any::<bool>()), 1..6),
    ) {
        let mut src = MODELS[which].to_owned();
        for (at, tok, delete) in edits {
            let mut i = at.index(src.len() + 1);
            while !src.is_char_boundary(i) {
                i -= 1;
            }
            if delete {
                let mut j = (i + 5).min(src.len());
                while !src.is_char_boundary(j) {
                    j -= 1;
                }
                src.replace_range(i..j, "");
            } else {
                src.insert_str(i, TOKENS[tok]);
            }
        }
        exercise(&src);
    }
}

#[test]
fn deep_nesting_is_an_error_not_a_stack_overflow() {
    for open in ["(", "[", "-", "sin(", "2^"] {
        let src = format!(
            "model m; state x; dynamics ode rk4 {{ der(x) = {}x; }}",
            open.repeat(100_000)
        );
        let err = check_source(&src).unwrap_err();
        assert!(err.to_string().contains("nested deeper"), "{open}: {err}");
    }
}

#[test]
fn huge_sizes_are_refused() {
    for src in [
        "model m; state x[1e12];",
        "model m; state x; let W = eye(100000);",
        "model m; state x; let W = diag(zeros(5000));",
        "model m; state x; horizon N = 1e30, dt = 1;",
    ] {
        assert!(check_source(src).is_err(), "{src}");
    }
}

#[test]
fn the_models_pass() {
    for m in MODELS {
        check_source(m).unwrap();
    }
}
