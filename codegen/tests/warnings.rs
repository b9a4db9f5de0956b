//! Generated crates are warning-free for any legal name: a model with a control `F`, a
//! stage parameter `G` and a global parameter `H_` (names rustc's `non_snake_case` lint
//! flags once prefixed: `u0_F`, `set_G_all`, `quad_set_H_`), and a model `Bare` (a crate
//! name that is not snake case) without parameters (whose C ABI once compared `NP > 0` with
//! `NP = 0`). Each is generated into its own crate and checked by `cargo clippy -- -D
//! warnings`, the rules the repository's own crates meet.

mod support;

const NAMES: &str = r#"
model quad;
state x;
control F;
param G stage;
param H_ global default 1;
dynamics ode rk4(1) { der(x) = F + G + H_; }
horizon N = 3, dt = 0.1;
cost {
    Q = diag(1);
    R = diag(1);
}
"#;

const BARE: &str = r#"
model Bare;
state x;
control u;
dynamics ode rk4(1) { der(x) = u; }
horizon N = 3, dt = 0.1;
cost {
    Q = diag(1);
    R = diag(1);
}
"#;

/// Generates `src` into its own crate and runs clippy on it with warnings denied.
fn clippy_clean(dir: &str, src: &str) {
    let dir = support::write_crate(&format!("warnings-test/{dir}"), src);
    let args = ["clippy", "--all-targets", "--", "-D", "warnings"];
    support::cargo(&dir, &args, "warnings-test/target");
}

#[test]
fn names_that_are_not_snake_case_generate_no_warning() {
    clippy_clean("names", NAMES);
}

#[test]
fn a_model_without_parameters_generates_no_warning() {
    clippy_clean("bare", BARE);
}
