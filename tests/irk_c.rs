//! The C ABI of a solver whose dynamics are the implicit `irk` step: `mpcc build
//! models/stiff_actuator.mpc --staticlib` into a temporary directory, its static library
//! built by cargo (offline), and `tests/c-irk/main.c` (`-Wall -Wextra -Werror`) compiled and
//! linked with the line `mpcc build` printed. The C program flies the stiff model against its
//! own fine RK4 integration of the ODE; every step must be OK and the cart at the target.
//! Needs cc (the test fails without it).
#![cfg(unix)]

use std::path::Path;
use std::process::Command;

mod common;

use common::{TempDir, run};

const NAME: &str = "stiff_actuator";

#[test]
fn a_c_program_flies_the_irk_solver() {
    let tmp = TempDir(std::env::temp_dir().join(format!("mpcc-c-irk-{}", std::process::id())));
    let crate_dir = tmp.0.join(NAME);
    let out_dir = crate_dir.to_str().expect("UTF-8 temporary directory");
    let runtime = format!("{}/runtime", env!("CARGO_MANIFEST_DIR"));
    let (code, stdout, stderr) = common::mpcc(&[
        "build",
        "models/stiff_actuator.mpc",
        "-o",
        out_dir,
        "--staticlib",
        "--runtime-path",
        &runtime,
    ]);
    assert_eq!(code, Some(0), "mpcc build failed:\n{stdout}\n{stderr}");
    let link_line = stdout
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("cc main.c"))
        .unwrap_or_else(|| panic!("no compile and link line printed:\n{stdout}"));
    // A target directory kept between runs (the runtime's build is reused).
    let shared = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generated-staticlibs");
    std::fs::create_dir_all(&shared).expect("create the shared target directory");
    std::os::unix::fs::symlink(&shared, crate_dir.join("target")).expect("link target/");
    run(
        Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
            .args(["build", "--release", "--offline"])
            .current_dir(&crate_dir)
            .env_remove("RUSTFLAGS")
            .env_remove("CARGO_TARGET_DIR"),
        "cargo build of the static library",
    );
    let main_c = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/c-irk/main.c");
    let exe = tmp.0.join("irk_loop");
    let mut words = link_line.split_whitespace();
    let mut cmd = Command::new(words.next().expect("a compiler"));
    for w in words {
        if w == "main.c" {
            cmd.arg(&main_c);
        } else {
            cmd.arg(w);
        }
    }
    cmd.args([
        "-std=c11",
        "-Wall",
        "-Wextra",
        "-Werror",
        "-pedantic",
        "-O2",
        "-o",
    ])
    .arg(&exe);
    run(&mut cmd, "the printed compile and link line");
    let out = run(&mut Command::new(&exe), "the C closed loop");
    let line = String::from_utf8_lossy(&out.stdout).trim().to_string();
    println!("C closed loop (s v F ok): {line}");
    let v: Vec<f64> = line
        .split_whitespace()
        .map(|w| w.parse().unwrap())
        .collect();
    assert_eq!(v.len(), 4, "{line}");
    assert_eq!(v[3], 60.0, "not every step was OK: {line}");
    assert!(
        (v[0] - 1.0).abs() < 1e-2 && v[1].abs() < 1e-2,
        "not at the target: {line}"
    );
}
