//! Soft state and control bounds end to end: `mpcc build` generates the solvers of
//! `tests/soft-bounds/soft_box.mpc` (horizons 3 and 1) and of `soft_row.mpc` (the same problem
//! with the soft bounds written as general soft rows) into a temporary directory; a Rust
//! program (`tests/soft-bounds/program.rs`) solves with them and a C program (`main.c`) uses the
//! C ABI. The outcomes are compared with the optima computed here by hand:
//!
//! With N = 1, `x_1 = x_0 + u_0` and the cost `1/2 r u_0^2 + 1/2 p (x_1 - xr)^2` (r = 1,
//! p = 4, xr = 2), the soft bound `x_1 <= b` with penalties `l1 s + 1/2 l2 s^2` on the
//! violation `s`: where the optimum violates it, `x_1 = (r x_0 + p xr + l2 b - l1) /
//! (r + p + l2)`; the hard bound's multiplier is `lambda = r (x_0 - b) + p (xr - b)`, and
//! with `l1 >= lambda` the bound holds exactly. The control's bound `u_0 <= b` likewise, with
//! `u_0 = (p (xr - x_0) + l2 b - l1) / (r + p + l2)`.
//! Needs cc (the test fails without it).
#![cfg(unix)]

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

mod common;

use common::{TempDir, run};

const R: f64 = 1.0;
const P: f64 = 4.0;
const XR: f64 = 2.0;

/// The soft optimum of `x_1 <= b` from `x0` (N = 1), or `b` where `l1` exceeds the
/// multiplier.
fn x1_soft(x0: f64, b: f64, l1: f64, l2: f64) -> f64 {
    let free = (R * x0 + P * XR) / (R + P);
    if free <= b {
        return free;
    }
    let lambda = R * (x0 - b) + P * (XR - b);
    if l2 == 0.0 && l1 >= lambda {
        return b;
    }
    ((R * x0 + P * XR + l2 * b - l1) / (R + P + l2)).max(b)
}

/// The soft optimum of `u_0 <= b` from `x_0 = 0` (N = 1).
fn u0_soft(b: f64, l1: f64, l2: f64) -> f64 {
    let free = P * XR / (R + P);
    let lambda = R * b + P * (b - XR);
    if l2 == 0.0 && l1 >= -lambda {
        return b;
    }
    ((P * XR + l2 * b - l1) / (R + P + l2)).max(b).min(free)
}

/// Generates the crate of `model` (with `extra` options) into `dir/name`.
fn generate(dir: &Path, model: &str, name: &str, extra: &[&str]) {
    let out = dir.join(name);
    let runtime = format!("{}/runtime", env!("CARGO_MANIFEST_DIR"));
    let mut args = vec!["build", model, "-o", out.to_str().unwrap(), "--name", name];
    args.extend_from_slice(&["--runtime-path", &runtime]);
    args.extend_from_slice(extra);
    let (code, stdout, stderr) = common::mpcc(&args);
    assert_eq!(code, Some(0), "mpcc build {model}:\n{stdout}\n{stderr}");
}

/// `models/cartpole.mpc` with its rail `|s| <= 1.5` (which the closed loop never reaches:
/// its cart goes to 0.816 m, `docs/examples.md`) made the soft bound `|s| <= 0.5`, written
/// into `dir`.
fn cartpole_with_a_soft_rail(dir: &Path) -> std::path::PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("models/cartpole.mpc")).unwrap();
    let hard = "    s in [-1.5, 1.5];";
    assert!(text.contains(hard), "models/cartpole.mpc changed its rail");
    let soft = text.replace(hard, "    s in [-0.5, 0.5] soft l1 = 1000;");
    let path = dir.join("cartpole_soft.mpc");
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(&path, soft).unwrap();
    path
}

/// Builds and runs the Rust program against the three crates: its `name value` lines.
fn rust_program(dir: &Path, target: &Path) -> HashMap<String, f64> {
    let prog = dir.join("prog");
    std::fs::create_dir_all(prog.join("src")).unwrap();
    let manifest = "[package]\nname = \"soft_bounds_prog\"\nversion = \"0.1.0\"\nedition = \"2024\"\n\
        publish = false\n\n[workspace]\n\n[dependencies]\nsoft_box = { path = \"../soft_box\" }\n\
        soft_box_n1 = { path = \"../soft_box_n1\" }\nsoft_row = { path = \"../soft_row\" }\n\
        cartpole_soft = { path = \"../cartpole_soft\" }\n";
    std::fs::write(prog.join("Cargo.toml"), manifest).unwrap();
    let main = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/soft-bounds/program.rs");
    std::fs::copy(main, prog.join("src/main.rs")).unwrap();
    let out = run(
        Command::new(env!("CARGO"))
            .args(["run", "--quiet", "--release"])
            .current_dir(&prog)
            .env("CARGO_TARGET_DIR", target)
            .env("CARGO_NET_OFFLINE", "true"),
        "the Rust program",
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(text.contains("api ok"), "{text}");
    (text.lines())
        .filter_map(|l| l.split_once(' '))
        .filter_map(|(k, v)| Some((k.to_string(), v.parse().ok()?)))
        .collect()
}

#[test]
fn soft_bounds_match_their_closed_form_optima_and_the_soft_rows() {
    let tmp = TempDir(std::env::temp_dir().join(format!("mpcc-soft-{}", std::process::id())));
    let dir = &tmp.0;
    generate(
        dir,
        "tests/soft-bounds/soft_box.mpc",
        "soft_box",
        &["--staticlib"],
    );
    generate(
        dir,
        "tests/soft-bounds/soft_box.mpc",
        "soft_box_n1",
        &["--variant", "N1"],
    );
    generate(dir, "tests/soft-bounds/soft_row.mpc", "soft_row", &[]);
    let cartpole = cartpole_with_a_soft_rail(dir);
    generate(dir, cartpole.to_str().unwrap(), "cartpole_soft", &[]);
    // Kept between runs: the runtime's build is reused.
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).join("soft-bounds");
    let v = rust_program(dir, &target);
    let get = |k: &str| *v.get(k).unwrap_or_else(|| panic!("no {k} in {v:?}"));
    // (case, closed form, by hand, the bound's multiplier: l1 + l2 s where violated by s,
    // the hard bound's 3 where it holds).
    let cases = [
        ("x_l2", x1_soft(0.0, 1.0, 0.0, 10.0), 1.2, 2.0),
        ("x_l1_above", x1_soft(0.0, 1.0, 5.0, 0.0), 1.0, 3.0),
        ("x_l1_below", x1_soft(0.0, 1.0, 2.0, 0.0), 1.2, 2.0),
        (
            "x_l1_l2",
            x1_soft(0.0, 1.0, 2.0, 10.0),
            16.0 / 15.0,
            2.0 + 10.0 / 15.0,
        ),
        ("x_l2_outside", x1_soft(1.5, 1.0, 0.0, 10.0), 1.3, 3.0),
        ("u_l2", u0_soft(1.0, 0.0, 10.0), 1.2, 2.0),
        ("u_l1_above", u0_soft(1.0, 5.0, 0.0), 1.0, 3.0),
        ("u_l1_below", u0_soft(1.0, 2.0, 0.0), 1.2, 2.0),
    ];
    for (name, want, by_hand, mult) in cases {
        assert!(
            (want - by_hand).abs() < 1e-12,
            "{name}: {want} vs {by_hand}"
        );
        // The state's cases read x_1, the control's u_0.
        let what = if name.starts_with('x') { "x1" } else { "u0" };
        let got = get(&format!("{name}_{what}"));
        assert!(
            (got - want).abs() < 1e-6,
            "{name}: {what} = {got}, closed form {want}"
        );
        let m = get(&format!("{name}_mult"));
        assert!(
            (m - mult).abs() < 1e-5,
            "{name}: multiplier {m}, closed form {mult}"
        );
    }
    // The same QP as the explicit soft rows: the same closed loops.
    for name in ["loop_l2", "loop_l1"] {
        let d = get(&format!("{name}_diff"));
        assert!(d <= 1e-9, "{name}: soft bounds and soft rows differ by {d}");
    }
    // L1 above the multiplier: from 1.8, outside the bound 1, the state is brought inside
    // and stays there (the terminal cost pulls it toward 2; its plans approach 1 from below).
    let x = get("loop_l1_x");
    assert!(x <= 1.0 + 1e-6 && x > 0.99, "loop_l1: x = {x}");

    // IPOPT on the same problem with explicit slacks (benches/peers/soft_bounds_casadi.py).
    let csv =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/peers/soft_bounds/soft_box_ipopt.csv");
    let text = std::fs::read_to_string(csv).unwrap();
    let mut compared = 0;
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("case"))
    {
        let f: Vec<&str> = line.split(',').collect();
        let (case, k) = (f[0], f[1]);
        for (what, value) in [("x", f[2]), ("u", f[3])]
            .into_iter()
            .filter(|(_, v)| !v.is_empty())
        {
            let want: f64 = value.parse().unwrap();
            let got = get(&format!("ipopt_{case}_{what}{k}"));
            assert!(
                (got - want).abs() < 1e-6,
                "{case}: {what}_{k} = {got}, IPOPT {want}"
            );
            compared += 1;
        }
    }
    assert_eq!(compared, 4 * 7, "{text}");

    // The cart-pole with its rail a soft bound |s| <= 0.5: the bound's multiplier peaks at
    // about 135 during the swing-up, so L1 = 100 is below it and the cart passes the rail;
    // L1 = 1000 is above it and the rail holds (to the QP's tolerance), the swing-up intact.
    for (k, val) in v.iter().filter(|(k, _)| k.starts_with("cart_")) {
        println!("{k} {val}");
    }
    let m = get("cart_l1_1000_multiplier");
    assert!(m > 100.0 && m < 1000.0, "the rail's multiplier: {m}");
    assert!(
        get("cart_l1_100_multiplier") <= 100.0 + 1e-6,
        "L1 caps the multiplier"
    );
    assert!(
        get("cart_l1_100_s_max") > 0.5 + 1e-3,
        "L1 = 100 below the multiplier"
    );
    assert!(get("cart_l1_100_plan_max") > 0.5 + 1e-3);
    assert!(get("cart_l1_1000_s_max") <= 0.5 + 1e-6, "the rail holds");
    assert!(
        get("cart_l1_1000_plan_max") <= 0.5 + 1e-6,
        "the plans keep it"
    );
    // Without the shift the plans are linearized around the last plan unshifted: their QPs
    // cannot keep the rail, the multiplier rises to L1 whatever it is, and the cart passes
    // the rail by about as much with L1 = 1000 as with 10000 (the real-time iteration's
    // inexactness, not the weight).
    for (name, l1) in [
        ("cart_noshift_l1_1000", 1000.0),
        ("cart_noshift_l1_10000", 1e4),
    ] {
        let m = get(&format!("{name}_multiplier"));
        assert!((m - l1).abs() < 1e-6 * l1, "{name}: multiplier {m}");
        assert!(get(&format!("{name}_s_max")) > 0.9, "{name}");
    }
    let (a, b) = (
        get("cart_noshift_l1_1000_s_max"),
        get("cart_noshift_l1_10000_s_max"),
    );
    assert!(
        (a - b).abs() < 1e-2,
        "a larger L1 did not help: {a} and {b}"
    );
    for name in [
        "cart_l1_100",
        "cart_l1_1000",
        "cart_noshift_l1_1000",
        "cart_noshift_l1_10000",
    ] {
        assert_eq!(get(&format!("{name}_not_ok")), 0.0, "{name}: a step not Ok");
        assert!(
            get(&format!("{name}_upright_since")) <= 100.0,
            "{name}: no swing-up"
        );
        assert!(
            get(&format!("{name}_rest")) < 1e-3,
            "{name}: not at rest upright"
        );
    }

    // The C ABI: penalties set, read back and refused; the bound then holds exactly.
    let exe = dir.join("soft_c");
    let crate_dir = dir.join("soft_box");
    run(
        Command::new(env!("CARGO"))
            .args(["build", "--quiet", "--release"])
            .current_dir(&crate_dir)
            .env("CARGO_TARGET_DIR", &target)
            .env("CARGO_NET_OFFLINE", "true"),
        "the static library",
    );
    let lib = target.join("release/libsoft_box.a");
    let main_c = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/soft-bounds/main.c");
    common::build_c(&main_c, &crate_dir.join("include"), &lib, &exe);
    let out = run(&mut Command::new(&exe), "the C program");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let x3: f64 = (text.strip_prefix("x3 ").and_then(|t| t.trim().parse().ok()))
        .unwrap_or_else(|| panic!("{text}"));
    // The multiplier of x_3 <= 0.5 is 35/6 < 10: the bound holds.
    assert!((x3 - 0.5).abs() < 1e-6, "C: x_3 = {x3}");
}

#[test]
fn mpcc_check_counts_the_soft_bounds_and_locates_bad_penalties() {
    let (code, stdout, stderr) = common::mpcc(&["check", "tests/soft-bounds/soft_box.mpc"]);
    assert_eq!(code, Some(0), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("bounds      x: 1 of 1 entries (1 soft), u: 1 of 1 entries (1 soft)"),
        "{stdout}"
    );
    let tmp = TempDir(std::env::temp_dir().join(format!("mpcc-soft-check-{}", std::process::id())));
    std::fs::create_dir_all(&tmp.0).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("tests/soft-bounds/soft_box.mpc")).unwrap();
    let bad = tmp.0.join("bad.mpc");
    std::fs::write(&bad, text.replace("soft l2 = 10;", "soft l1 = 0, l2 = 0;")).unwrap();
    let (code, stdout, stderr) = common::mpcc(&["check", bad.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{stdout}\n{stderr}");
    let line = text
        .lines()
        .position(|l| l.contains("soft l2 = 10;"))
        .unwrap()
        + 1;
    assert!(stderr.contains(&format!("bad.mpc:{line}:5 ]")), "{stderr}");
    assert!(
        stderr.contains("soft state bound on `x`: soft with l1 = 0 and l2 = 0"),
        "{stderr}"
    );
}
