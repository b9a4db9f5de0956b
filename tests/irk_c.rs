//! The C ABI of a solver whose dynamics are the implicit `irk` step: `mpcc build
//! models/stiff_actuator.mpc --staticlib` into a temporary directory, its static library
//! built by cargo (offline), and `tests/c-irk/main.c` (`-Wall -Wextra -Werror`) compiled and
//! linked with the line `mpcc build` printed. The C program flies the stiff model against its
//! own fine RK4 integration of the ODE; every step must be OK and the cart at the target.
//! Needs cc (the test fails without it). And the same model with an input-rate cost (the
//! augmented state of the emitted step) and Radau IIA collocation as a Rust crate in a
//! temporary directory: its sensitivities against central differences, `solve_sqp`, a
//! closed loop.
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
    common::build_with_printed_line(link_line, &main_c, &exe);
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

/// The stiff model with an input-rate cost on `F_cmd`, integrated by 3-stage Radau IIA.
fn rate_model() -> String {
    let src = include_str!("../models/stiff_actuator.mpc")
        .replace("model stiff_actuator;", "model stiff_rate;")
        .replace(
            "param s_ref global",
            "param F_prev global unit \"N\" default 0;\nparam s_ref global",
        )
        .replace(
            "    R = diag(0.01)",
            "    rate = diag(0.001) prev F_prev;\n    R = diag(0.01)",
        )
        .replace(
            "irk(stages = 2, steps = 4, newton = 3)",
            "irk(stages = 3, steps = 2, newton = 3, collocation = radau_iia)",
        );
    assert!(src.contains("rate = ") && src.contains("F_prev global") && src.contains("radau"));
    src
}

#[test]
fn a_rust_crate_with_an_input_rate_cost_solves_from_a_temporary_directory() {
    let tmp = TempDir(std::env::temp_dir().join(format!("mpcc-rs-irk-{}", std::process::id())));
    std::fs::create_dir_all(&tmp.0).unwrap();
    let model = tmp.0.join("stiff_rate.mpc");
    std::fs::write(&model, rate_model()).unwrap();
    let crate_dir = tmp.0.join("stiff_rate");
    let runtime = format!("{}/runtime", env!("CARGO_MANIFEST_DIR"));
    let (code, stdout, stderr) = common::mpcc(&[
        "build",
        model.to_str().unwrap(),
        "-o",
        crate_dir.to_str().unwrap(),
        "--runtime-path",
        &runtime,
    ]);
    assert_eq!(code, Some(0), "mpcc build failed:\n{stdout}\n{stderr}");
    // A binary crate beside it that uses it.
    let app = tmp.0.join("app");
    std::fs::create_dir_all(app.join("src")).unwrap();
    std::fs::write(
        app.join("Cargo.toml"),
        format!(
            "[package]\nname = \"app\"\nversion = \"0.1.0\"\nedition = \"2024\"\n\n\
             [dependencies]\nstiff_rate = {{ path = \"../stiff_rate\" }}\n\
             mpc-runtime = {{ path = \"{runtime}\" }}\n\n[workspace]\n"
        ),
    )
    .unwrap();
    let main_rs = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/c-irk/rate_main.rs");
    std::fs::copy(main_rs, app.join("src/main.rs")).unwrap();
    let shared = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generated-staticlibs");
    std::fs::create_dir_all(&shared).expect("create the shared target directory");
    let out = run(
        Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
            .args(["run", "--release", "--offline", "--target-dir"])
            .arg(&shared)
            .current_dir(&app)
            .env_remove("RUSTFLAGS")
            .env_remove("CARGO_TARGET_DIR"),
        "cargo run of the app",
    );
    let line = String::from_utf8_lossy(&out.stdout).trim().to_string();
    println!("input-rate irk (fd status iterations s v F): {line}");
    let w: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(w.len(), 6, "{line}");
    let fd: f64 = w[0].parse().unwrap();
    assert!(fd < 1e-6, "[A B] against central differences: {fd}");
    assert_eq!(w[1], "Ok", "solve_sqp: {line}");
    let (s, v): (f64, f64) = (w[3].parse().unwrap(), w[4].parse().unwrap());
    assert!(
        (s - 1.0).abs() < 1e-2 && v.abs() < 1e-2,
        "not at the target: {line}"
    );
}
