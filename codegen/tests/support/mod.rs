//! Generated crates built as a user would build them: written into the repository's target
//! directory as crates of their own workspace, then run through cargo.

use std::path::{Path, PathBuf};
use std::process::Command;

use mpc_codegen::{Options, RuntimeDep, generate};
use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};

/// The repository's root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Generates the model `src` (default options, this checkout's runtime) into
/// `target/<dir>` as a crate of its own workspace and returns its folder.
pub fn write_crate(dir: &str, src: &str) -> PathBuf {
    let g = Graph::new();
    let parsed = match parse(&g, src, &ParseOptions::default()) {
        Ok(p) => p,
        Err(d) => panic!("{}", d.render("model.mpc", src)),
    };
    let mut opts = Options::new();
    let runtime = root().join("runtime").canonicalize().unwrap();
    opts.runtime = RuntimeDep::Path(runtime.display().to_string());
    let krate = generate(&parsed.ocp, &opts).unwrap();
    let dir = root().join("target").join(dir);
    krate.write(&dir).unwrap();
    // Its own workspace: the repository's does not list it.
    let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    if !manifest.contains("[workspace]") {
        std::fs::write(dir.join("Cargo.toml"), format!("{manifest}\n[workspace]\n")).unwrap();
    }
    dir
}

/// Runs `cargo COMMAND --offline REST` (`args` = COMMAND, REST...) in `dir` with target
/// directory `target/<target>`; panics with cargo's output if it fails.
pub fn cargo(dir: &Path, args: &[&str], target: &str) {
    let (command, rest) = args.split_first().expect("a cargo command");
    let out = Command::new(env!("CARGO"))
        .arg(command)
        .arg("--offline")
        .args(rest)
        .current_dir(dir)
        .env("CARGO_TARGET_DIR", root().join("target").join(target))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
