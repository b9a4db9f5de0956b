//! `mpcc check` and `mpcc build` refuse what cannot compile or evaluate (reserved and
//! clashing names, non-finite constants, functions that are not finite at the guess), with
//! the file, line and column; `mpcc build` says which files it wrote and which it left.

use std::path::{Path, PathBuf};
use std::process::Command;

fn mpcc(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_mpcc"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the mpcc binary runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
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
