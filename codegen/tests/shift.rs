//! Where the generated solver's default shift comes from: the runtime's default (on), the
//! model's `solver { shift = ...; }`, and the generator's option, which wins.

use mpc_codegen::{Options, generate};
use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};

const BASE: &str = "model m;\nstate x;\ncontrol u;\ndynamics ode rk4 { der(x) = u; }\n\
                    horizon N = 5, dt = 0.1;\ncost { Q = diag(1); R = diag(1); }\n";

/// The body of the generated `default_settings()`.
fn default_settings(block: &str, shift: Option<bool>) -> String {
    let src = format!("{BASE}{block}");
    let g = Graph::new();
    let ocp = parse(&g, &src, &ParseOptions::default()).unwrap().ocp;
    let opts = Options {
        shift,
        ..Options::new()
    };
    let lib = generate(&ocp, &opts).unwrap();
    let lib = lib.file("src/lib.rs").unwrap();
    let start = lib
        .find("pub fn default_settings()")
        .expect("default_settings");
    let end = start + lib[start..].find("\n}").expect("its end");
    lib[start..end].to_string()
}

#[test]
fn the_model_chooses_the_shift_and_the_generator_option_wins() {
    // Nothing said: the runtime's default, which is on.
    let none = default_settings("", None);
    assert!(!none.contains("shift"), "{none}");
    const { assert!(mpc_runtime::RtiSettings::<f64>::DEFAULT.shift) };
    let off = default_settings("solver { shift = off; }\n", None);
    assert!(off.contains("s.shift = false;"), "{off}");
    let on = default_settings("solver { shift = off; }\n", Some(true));
    assert!(
        on.contains("s.shift = true;") && !on.contains("false"),
        "{on}"
    );
    let off = default_settings("", Some(false));
    assert!(off.contains("s.shift = false;"), "{off}");
}
