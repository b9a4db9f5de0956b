//! Generated crates are warning-free for any legal name: a model with a control `F`, a
//! stage parameter `G` and a global parameter `H_` (names rustc's `non_snake_case` lint
//! flags once prefixed: `u0_F`, `set_G_all`, `quad_set_H_`), and a model `Bare` (a crate
//! name that is not snake case) without parameters (whose C ABI once compared `NP > 0` with
//! `NP = 0`). Each is generated into its own crate
//! and checked by `cargo clippy -- -D warnings`, the rules the repository's own crates meet.

use std::path::PathBuf;
use std::process::Command;

use mpc_codegen::{Options, RuntimeDep, generate};
use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};

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

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Generates `src` into `target/warnings-test/<dir>` as a crate of its own workspace and
/// runs clippy on it with warnings denied; panics with clippy's output if it fails.
fn clippy_clean(dir: &str, src: &str) {
    let g = Graph::new();
    let parsed = match parse(&g, src, &ParseOptions::default()) {
        Ok(p) => p,
        Err(d) => panic!("{}", d.render("model.mpc", src)),
    };
    let mut opts = Options::new();
    let runtime = root().join("runtime").canonicalize().unwrap();
    opts.runtime = RuntimeDep::Path(runtime.display().to_string());
    let krate = generate(&parsed.ocp, &opts).unwrap();
    let dir = root().join("target/warnings-test").join(dir);
    krate.write(&dir).unwrap();
    let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    if !manifest.contains("[workspace]") {
        std::fs::write(dir.join("Cargo.toml"), format!("{manifest}\n[workspace]\n")).unwrap();
    }
    let out = Command::new(env!("CARGO"))
        .args([
            "clippy",
            "--offline",
            "--all-targets",
            "--",
            "-D",
            "warnings",
        ])
        .current_dir(&dir)
        .env(
            "CARGO_TARGET_DIR",
            root().join("target/warnings-test/target"),
        )
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn names_that_are_not_snake_case_generate_no_warning() {
    clippy_clean("names", NAMES);
}

#[test]
fn a_model_without_parameters_generates_no_warning() {
    clippy_clean("bare", BARE);
}
