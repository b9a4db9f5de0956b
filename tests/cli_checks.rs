//! `mpcc check` and `mpcc build` refuse what cannot compile or evaluate (reserved and
//! clashing names, non-finite constants, functions that are not finite at the guess), with
//! the file, line and column; `mpcc build` says which files it wrote and which it left.

mod common;

use std::path::{Path, PathBuf};

/// `mpcc ARGS` from the repository root: whether it succeeded, stdout, stderr.
fn mpcc(args: &[&str]) -> (bool, String, String) {
    let (code, stdout, stderr) = common::mpcc(args);
    (code == Some(0), stdout, stderr)
}

/// A small valid model.
const TINY: &str = "model tiny;\nstate x guess 1;\ncontrol u;\nparam xref stage default 0;\n\
    dynamics ode rk4 { der(x) = -x + u; }\nhorizon N = 5, dt = 0.1;\n\
    cost { Q = diag(1) ref [xref]; R = diag(0.1); }\n";

/// Writes `src` to a fresh file under the test directory.
fn model_file(name: &str, src: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}.mpc"));
    std::fs::write(&path, src).unwrap();
    path
}

#[test]
fn build_says_unchanged_for_files_it_did_not_write() {
    let file = model_file("cli_checks_tiny", TINY);
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_checks_tiny");
    let _ = std::fs::remove_dir_all(&dir);
    let (file, out) = (file.to_str().unwrap(), dir.to_str().unwrap());
    let lines = |stdout: &str, word: &str| stdout.lines().filter(|l| l.starts_with(word)).count();
    let (ok, stdout, err) = mpcc(&["build", file, "-o", out]);
    assert!(ok, "{err}");
    assert_eq!(
        (lines(&stdout, "wrote "), lines(&stdout, "unchanged ")),
        (3, 0),
        "{stdout}"
    );
    let (ok, stdout, err) = mpcc(&["build", file, "-o", out]);
    assert!(ok, "{err}");
    assert_eq!(
        (lines(&stdout, "wrote "), lines(&stdout, "unchanged ")),
        (0, 3),
        "{stdout}"
    );
    // One file edited by hand: that one is written again, the others are left.
    let lib = dir.join("src/lib.rs");
    let text = std::fs::read_to_string(&lib).unwrap();
    std::fs::write(&lib, format!("{text}// edited\n")).unwrap();
    let (ok, stdout, err) = mpcc(&["build", file, "-o", out]);
    assert!(ok, "{err}");
    assert_eq!(
        (lines(&stdout, "wrote "), lines(&stdout, "unchanged ")),
        (1, 2),
        "{stdout}"
    );
    assert!(
        stdout
            .lines()
            .any(|l| l.starts_with("wrote ") && l.contains("lib.rs")),
        "{stdout}"
    );
    assert_eq!(std::fs::read_to_string(&lib).unwrap(), text);
}

/// `mpcc check` and `mpcc build` both refuse `src`, each with every `needle` in its errors.
fn refused_by_check_and_build(name: &str, src: &str, needles: &[&str]) {
    let file = model_file(name, src);
    let file = file.to_str().unwrap();
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&out);
    for args in [
        vec!["check", file],
        vec!["build", file, "-o", out.to_str().unwrap()],
    ] {
        let (ok, stdout, err) = mpcc(&args);
        assert!(!ok, "{args:?} must fail: {stdout}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: `{n}` not in\n{err}");
        }
    }
    assert!(!out.exists(), "build wrote files for a refused model");
}

#[test]
fn reserved_names_are_refused_by_check_and_build() {
    let src = TINY.replace("param xref stage default 0;", "param x0 global;");
    let src = src.replace(" ref [xref]", "");
    refused_by_check_and_build(
        "cli_checks_x0",
        &src,
        &[
            "would generate `set_x0`",
            "cli_checks_x0.mpc:4:7",
            "param x0 global;",
        ],
    );
}

#[test]
fn non_finite_constants_are_refused_by_check_and_build() {
    let src = TINY.replace("-x + u", "-x + u + 0 * (1/0)");
    refused_by_check_and_build(
        "cli_checks_constant",
        &src,
        &["evaluates to inf", "cli_checks_constant.mpc:5:43"],
    );
}

#[test]
fn functions_not_finite_at_the_guess_are_refused_by_check_and_build() {
    let src = TINY.replace("state x guess 1;", "state x;");
    let cases = [
        ("cli_checks_div", "F / x + u", "der(x) = inf"),
        ("cli_checks_sqrt", "sqrt(x - 1) + u", "der(x) = NaN"),
    ];
    for (name, rhs, value) in cases {
        let src = src
            .replace("param xref", "param F global default 1;\nparam xref")
            .replace("-x + u", rhs);
        let at = format!("{name}.mpc:6:29");
        refused_by_check_and_build(name, &src, &["the dynamics", value, &at, "x = 0"]);
    }
    let src = src.replace("cost {", "constraints { pos: 0 <= log(x) <= 1; }\ncost {");
    refused_by_check_and_build(
        "cli_checks_log",
        &src,
        &[
            "constraint `pos` is not finite",
            "row 0 = -inf",
            "cli_checks_log.mpc:7:25",
        ],
    );
}

#[test]
fn the_models_pass_check() {
    for m in ["quadrotor_rates", "paper_pointmass", "quadrotor_probe"] {
        let (ok, _, err) = mpcc(&["check", &format!("models/{m}.mpc")]);
        assert!(ok, "{m}: {err}");
    }
}
