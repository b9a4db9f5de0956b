//! General cost terms end to end: `tests/data/pendulum_cost.mpc` (least squares, an energy
//! term, a log barrier, a nonlinear output, a terminal term) through `mpcc build
//! --exact-hessian --staticlib` into a crate in a temporary directory (this checkout's
//! runtime), then solved to convergence by `solve_sqp` from a Rust program on the crate and
//! from a C program on its C ABI (`tests/general-cost/main.c`). Both must match IPOPT's
//! solution of the same problem written independently in CasADi
//! (`benches/peers/general_cost/pendulum_cost_ipopt.csv`) to 1e-6 over the whole trajectory,
//! and their cost read-outs (which include the general terms) IPOPT's optimal cost; and the
//! model generated in f32 builds for `thumbv7em-none-eabihf`. Needs cc and that target (the
//! test fails without them).
#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

use common::{TempDir, run};

const NAME: &str = "pendulum_cost";

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The Rust program on the generated crate: the same solve and print-out as the C one.
const RUST_MAIN: &str = r#"
use pendulum_cost::Solver;

fn main() {
    let mut s = Box::new(Solver::new());
    let st = s.settings_mut();
    st.sqp_max_iter = 200;
    st.sqp_tol = 1e-11;
    st.sqp_kkt_tol = 1e-10;
    s.set_x0(&[1.0, 0.0]).unwrap();
    let info = s.solve_sqp();
    assert_eq!(format!("{:?}", info.status), "Ok");
    println!("cost {:.17e} iterations {}", s.cost(), info.sqp_iterations);
    for k in 0..=30 {
        let x = s.state(k).unwrap();
        match s.control(k) {
            Some(u) => println!("{:.17e} {:.17e} {:.17e}", x[0], x[1], u[0]),
            None => println!("{:.17e} {:.17e}", x[0], x[1]),
        }
    }
}
"#;

/// IPOPT's trajectory (rows `th om [tau]`) and optimal cost.
fn ipopt() -> (Vec<Vec<f64>>, f64) {
    let path = repo().join("benches/peers/general_cost/pendulum_cost_ipopt.csv");
    let text = std::fs::read_to_string(path).unwrap();
    let first = text.lines().next().unwrap();
    let cost = first
        .rsplit("cost ")
        .next()
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let rows = (text.lines().filter(|l| !l.starts_with('#')).skip(1))
        .map(|l| l.split(',').skip(1).map(|s| s.parse().unwrap()).collect())
        .collect();
    (rows, cost)
}

/// Checks a program's print-out against IPOPT; returns its SQP iterations.
fn check(out: &str, what: &str) -> u32 {
    let mut lines = out.lines();
    let head: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
    assert_eq!((head[0], head[2]), ("cost", "iterations"), "{what}: {out}");
    let cost: f64 = head[1].parse().unwrap();
    let (want, want_cost) = ipopt();
    assert!(
        (cost - want_cost).abs() <= 1e-8 * want_cost,
        "{what}: cost {cost} vs IPOPT {want_cost}"
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split_whitespace().map(|w| w.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), want.len(), "{what}: {out}");
    let mut worst: f64 = 0.0;
    for (got, w) in rows.iter().zip(&want) {
        assert_eq!(got.len(), w.len(), "{what}");
        for (a, b) in got.iter().zip(w) {
            worst = worst.max((a - b).abs());
        }
    }
    println!("{what}: deviation from IPOPT {worst:.1e}, cost {cost}");
    assert!(worst <= 1e-6, "{what}: deviation {worst}");
    head[3].parse().unwrap()
}

#[test]
fn a_general_cost_model_solves_from_rust_and_c() {
    // Outside the repository: a crate under it would be taken for a workspace member.
    let tmp =
        TempDir(std::env::temp_dir().join(format!("mpcc-general-cost-{}", std::process::id())));
    let crate_dir = tmp.0.join(NAME);
    let out_dir = crate_dir.to_str().expect("UTF-8 temporary directory");
    let runtime = format!("{}/runtime", env!("CARGO_MANIFEST_DIR"));
    let (code, stdout, stderr) = common::mpcc(&[
        "build",
        "tests/data/pendulum_cost.mpc",
        "-o",
        out_dir,
        "--exact-hessian",
        "--staticlib",
        "--runtime-path",
        &runtime,
    ]);
    assert_eq!(code, Some(0), "mpcc build failed:\n{stdout}\n{stderr}");
    let lib = std::fs::read_to_string(crate_dir.join("src/lib.rs")).unwrap();
    assert!(lib.contains("const GENERAL_COST: bool = true;"));
    assert!(lib.contains("pub const NH: usize = 30;"));

    // One target directory kept between runs: the runtime's build is reused.
    let target = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("general-cost");
    let cargo = |args: &[&str]| {
        run(
            Command::new(env!("CARGO"))
                .args(args)
                .arg("--offline")
                .current_dir(&crate_dir)
                .env("CARGO_TARGET_DIR", &target)
                .env_remove("RUSTFLAGS"),
            &format!("cargo {args:?}"),
        )
    };

    // Rust.
    std::fs::create_dir_all(crate_dir.join("examples")).unwrap();
    std::fs::write(crate_dir.join("examples/solve.rs"), RUST_MAIN).unwrap();
    let out = cargo(&["run", "--release", "--example", "solve"]);
    let rust_iters = check(&String::from_utf8_lossy(&out.stdout), "Rust");

    // C, on the static library.
    cargo(&["build", "--release"]);
    let exe = tmp.0.join("solve_c");
    common::build_c(
        &repo().join("tests/general-cost/main.c"),
        &crate_dir.join("include"),
        &target.join(format!("release/lib{NAME}.a")),
        &exe,
    );
    let out = run(&mut Command::new(&exe), "the C program");
    let c_iters = check(&String::from_utf8_lossy(&out.stdout), "C");
    assert_eq!(rust_iters, c_iters);
}

/// The same model generated in f32 builds for a Cortex-M4F (`no_std`, no heap).
#[test]
fn a_general_cost_model_builds_in_f32_for_a_bare_metal_target() {
    let tmp =
        TempDir(std::env::temp_dir().join(format!("mpcc-general-cost-f32-{}", std::process::id())));
    let crate_dir = tmp.0.join(NAME);
    let out_dir = crate_dir.to_str().expect("UTF-8 temporary directory");
    let runtime = format!("{}/runtime", env!("CARGO_MANIFEST_DIR"));
    let (code, stdout, stderr) = common::mpcc(&[
        "build",
        "tests/data/pendulum_cost.mpc",
        "-o",
        out_dir,
        "--f32",
        "--exact-hessian",
        "--runtime-path",
        &runtime,
    ]);
    assert_eq!(code, Some(0), "mpcc build failed:\n{stdout}\n{stderr}");
    let target = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("general-cost");
    run(
        Command::new(env!("CARGO"))
            .args(["build", "--offline", "--target", "thumbv7em-none-eabihf"])
            .current_dir(&crate_dir)
            .env("CARGO_TARGET_DIR", &target)
            .env_remove("RUSTFLAGS"),
        "cargo build --target thumbv7em-none-eabihf",
    );
}
