//! `mpcc build`: writes a complete crate, `--check` detects drift, errors name the place.

mod common;

use std::path::Path;

/// `mpcc ARGS` from the repository root: whether it succeeded, stdout, stderr.
fn mpcc(args: &[&str]) -> (bool, String, String) {
    let (code, stdout, stderr) = common::mpcc(args);
    (code == Some(0), stdout, stderr)
}

#[test]
fn build_writes_a_crate_and_check_detects_drift() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_build_pointmass");
    let _ = std::fs::remove_dir_all(&dir);
    let out = dir.to_str().unwrap();
    let (ok, stdout, err) = mpcc(&["build", "models/paper_pointmass.mpc", "-o", out, "--f32"]);
    assert!(ok, "{err}");
    for f in ["Cargo.toml", "src/lib.rs", "include/paper_pointmass.h"] {
        assert!(dir.join(f).is_file(), "{f} missing; {stdout}");
    }
    let lib = std::fs::read_to_string(dir.join("src/lib.rs")).unwrap();
    assert!(lib.contains("#![no_std]") && lib.contains("pub type Real = f32;"));
    let header = std::fs::read_to_string(dir.join("include/paper_pointmass.h")).unwrap();
    assert!(header.contains("typedef float paper_pointmass_real;"));
    let toml = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    // The runtime dependency is by version (the runtime's), naming no path of this machine.
    assert!(
        toml.contains(&format!(
            "mpc-runtime = {{ version = \"{}\", default-features = false }}",
            mpc_codegen::vendor::RUNTIME_VERSION
        )),
        "{toml}"
    );
    assert!(!toml.contains("path ="), "{toml}");

    let (ok, stdout, _) = mpcc(&[
        "build",
        "models/paper_pointmass.mpc",
        "-o",
        out,
        "--f32",
        "--check",
    ]);
    assert!(ok && stdout.contains("up to date"), "{stdout}");
    // f64 output differs from the f32 crate on disk.
    let (ok, _, err) = mpcc(&["build", "models/paper_pointmass.mpc", "-o", out, "--check"]);
    assert!(!ok);
    assert!(err.contains("src/lib.rs: differs"), "{err}");
    // A hand edit is detected, and a rebuild restores the file.
    std::fs::write(dir.join("src/lib.rs"), format!("{lib}\n// edited\n")).unwrap();
    let (ok, _, err) = mpcc(&[
        "build",
        "models/paper_pointmass.mpc",
        "-o",
        out,
        "--f32",
        "--check",
    ]);
    assert!(!ok && err.contains("regenerate with"), "{err}");
    let (ok, _, _) = mpcc(&["build", "models/paper_pointmass.mpc", "-o", out, "--f32"]);
    assert!(ok);
    assert_eq!(
        std::fs::read_to_string(dir.join("src/lib.rs")).unwrap(),
        lib
    );
}

#[test]
fn build_reports_errors_with_file_line_and_column() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let bad = dir.join("bad_build.mpc");
    std::fs::write(
        &bad,
        "model wstage;\nstate x;\ncontrol u;\nparam w stage default 1;\n\
         dynamics ode euler { der(x) = u; }\nhorizon N = 5, dt = 0.1;\n\
         cost { Q = diag(w) ref [0]; }\n",
    )
    .unwrap();
    let out = dir.join("bad_build_out");
    let _ = std::fs::remove_dir_all(&out);
    let (ok, _, err) = mpcc(&["build", bad.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("bad_build.mpc:7:8"), "{err}");
    assert!(err.contains("global parameters only"), "{err}");
    assert!(!out.exists(), "nothing is written on error");

    let (ok, _, err) = mpcc(&[
        "build",
        "models/paper_pointmass.mpc",
        "-o",
        out.to_str().unwrap(),
        "--name",
        "loop",
    ]);
    assert!(!ok);
    assert!(err.contains("`loop` is not usable"), "{err}");
    let (ok, _, err) = mpcc(&["build", "no/such.mpc", "-o", out.to_str().unwrap()]);
    assert!(!ok && err.contains("no/such.mpc"), "{err}");
}

/// `--qp-method` reaches the generated solver: `condensed` gives QR-bench B and A condensing
/// storage and asks for it, `riccati` gives none and asks for the recursion; a bad value is
/// refused with the choices.
#[test]
fn build_qp_method_option() {
    let base = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let cases = [
        (None, "condensed", "20"),
        (Some("A"), "condensed", "10"),
        (Some("A"), "riccati", "0"),
    ];
    for (i, (variant, method, nc)) in cases.into_iter().enumerate() {
        let dir = base.join(format!("cli_build_qp_method_{i}_{method}"));
        let _ = std::fs::remove_dir_all(&dir);
        let out = dir.to_str().unwrap();
        let mut args = vec![
            "build",
            "models/quadrotor_rates.mpc",
            "-o",
            out,
            "--qp-method",
            method,
        ];
        if let Some(v) = variant {
            args.extend(["--variant", v]);
        }
        let (ok, _, err) = mpcc(&args);
        assert!(ok, "{err}");
        let lib = std::fs::read_to_string(dir.join("src/lib.rs")).unwrap();
        assert!(
            lib.contains(&format!("pub const NC: usize = {nc};")),
            "{method}"
        );
        let name = if method == "condensed" {
            "Condensed"
        } else {
            "Riccati"
        };
        assert!(lib.contains(&format!("s.qp.method = mpc_runtime::QpMethod::{name};")));
    }
    let dir = base.join("cli_build_qp_method_bad");
    let (ok, _, err) = mpcc(&[
        "build",
        "models/quadrotor_rates.mpc",
        "-o",
        dir.to_str().unwrap(),
        "--qp-method",
        "dense",
    ]);
    assert!(!ok);
    assert!(
        err.contains("--qp-method") && err.contains("condensed"),
        "{err}"
    );
}

#[test]
fn build_takes_the_shift_and_refuses_a_bad_value() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_build_shift");
    let _ = std::fs::remove_dir_all(&dir);
    let out = dir.to_str().unwrap();
    let (ok, _, err) = mpcc(&[
        "build",
        "models/paper_pointmass.mpc",
        "-o",
        out,
        "--shift",
        "off",
    ]);
    assert!(ok, "{err}");
    let lib = std::fs::read_to_string(dir.join("src/lib.rs")).unwrap();
    assert!(
        lib.contains("s.shift = false;"),
        "the shift is off in default_settings()"
    );
    let (ok, _, err) = mpcc(&[
        "build",
        "models/paper_pointmass.mpc",
        "-o",
        out,
        "--shift",
        "maybe",
    ]);
    assert!(!ok);
    assert!(
        err.contains("--shift") && err.contains("on") && err.contains("off"),
        "{err}"
    );
}
