//! The bare-metal C proof (`tests/embedded-c/`): generates the f32 QR-bench A solver with
//! `mpcc build --staticlib` (as `generated/quadrotor_rates_f32`), builds its bare-metal
//! static library for `thumbv7em-none-eabihf` (the crate's `bare-metal/` library crate, with
//! its firmware profile, through the crate's Makefile fragment), builds the C firmware with
//! arm-none-eabi-gcc and that fragment (no Rust in that build), and flies both it and the
//! Rust firmware (`tests/embedded/`) in qemu on the emulated Cortex-M4F (`mps2-an386`,
//! `-icount shift=0`). The C firmware must fly every step Ok with the Rust firmware's QP
//! iterations and end in the same final state, bit for bit; both firmwares must meet the
//! flash (64 KiB), RAM (32 KiB) and worst-step (1 M instructions) targets. Flash, RAM and
//! instructions per step of both are printed side by side (`docs/embedded-c.md`). Needs qemu-system-arm, arm-none-eabi-gcc (with binutils) and
//! make: without them the test fails, it never skips.
#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

mod common;

use common::{TempDir, run};

const TARGET: &str = "thumbv7em-none-eabihf";
const NAME: &str = "quadrotor_rates_f32";
const QEMU: &str = "qemu-system-arm";
const QEMU_TIMEOUT: Duration = Duration::from_secs(120);
const STEPS: usize = 100;
/// The flash target of the firmware (bytes of text + data).
const FLASH_TARGET: u32 = 64 * 1024;
/// The RAM target of the firmware (static data plus the deepest stack).
const RAM_TARGET: u32 = 32 * 1024;
/// The target for the instructions of any RTI step (prepare, `set_x0`, feedback).
const STEP_TARGET: u32 = 1_000_000;

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn tmpdir() -> &'static Path {
    Path::new(env!("CARGO_TARGET_TMPDIR"))
}

/// A cargo command for the thumb target, free of the host build's flags.
fn thumb_cargo() -> Command {
    without_host_flags(Command::new(env!("CARGO")))
}

/// `cmd` (cargo, or make running cargo) without the host build's flags.
fn without_host_flags(mut cmd: Command) -> Command {
    cmd.env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("CARGO_TARGET_DIR");
    cmd
}

/// Builds the Rust firmware where `tests/embedded/host_check.rs` builds it (shared cache).
fn rust_firmware() -> PathBuf {
    let dir = repo().join("tests/embedded");
    let target_dir = tmpdir().join("embedded-firmware");
    run(
        thumb_cargo()
            .current_dir(&dir)
            .args(["build", "--release", "--target", TARGET, "--manifest-path"])
            .arg(dir.join("Cargo.toml"))
            .arg("--target-dir")
            .arg(&target_dir),
        "building the Rust firmware",
    );
    target_dir.join(TARGET).join("release/embedded-qr-bench")
}

/// Generates the solver crate with its glue into `tmp`, with the Rust firmware's dependency
/// versions (its `Cargo.lock`) for the bare-metal library crate. Returns the crate directory.
fn solver_crate(tmp: &Path) -> PathBuf {
    let crate_dir = tmp.join(NAME);
    let out_dir = crate_dir.to_str().expect("UTF-8 temporary directory");
    let (code, stdout, stderr) = common::mpcc(&[
        "build",
        "models/quadrotor_rates.mpc",
        "--variant",
        "A",
        "--f32",
        "--qp-method",
        "condensed",
        "--name",
        NAME,
        "--staticlib",
        "-o",
        out_dir,
        // This checkout's runtime, as the Rust firmware's.
        "--runtime-path",
        &format!("{}/runtime", repo().display()),
    ]);
    assert_eq!(code, Some(0), "mpcc build failed:\n{stdout}\n{stderr}");
    std::fs::copy(
        repo().join("tests/embedded/Cargo.lock"),
        crate_dir.join("bare-metal/Cargo.lock"),
    )
    .expect("copy the Rust firmware's Cargo.lock");
    // The crate's target/ is a directory kept between runs (and shared with tests/c_glue.rs).
    let shared = tmpdir().join("generated-staticlibs");
    std::fs::create_dir_all(&shared).expect("create the shared target directory");
    std::os::unix::fs::symlink(&shared, crate_dir.join("target")).expect("link target/");
    crate_dir
}

/// Runs a firmware on the emulated Cortex-M4F; returns its semihosting output.
fn run_qemu(elf: &Path) -> String {
    let mut child = Command::new(QEMU)
        .args([
            "-M",
            "mps2-an386",
            "-cpu",
            "cortex-m4",
            "-icount",
            "shift=0",
        ])
        .args(["-display", "none", "-monitor", "none", "-serial", "null"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run {QEMU} ({e}); .ci/run installs it"));
    let done = common::wait_with_timeout(&mut child, QEMU_TIMEOUT);
    let Some(status) = done.status else {
        panic!("{QEMU} timed out on {}:\n{}", elf.display(), done.stdout);
    };
    assert!(
        status.success(),
        "{QEMU} on {} exited with {status}:\n{}\n{}",
        elf.display(),
        done.stdout,
        done.stderr
    );
    done.stdout
}

/// The value after `key=` up to the next space or comma.
fn field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    line.split([' ', ','])
        .find_map(|w| w.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
}

fn line_with<'a>(out: &'a str, prefix: &str, who: &str) -> &'a str {
    out.lines()
        .find_map(|l| l.strip_prefix(prefix))
        .unwrap_or_else(|| panic!("{who}: no {prefix:?} line:\n{out}"))
}

fn number(s: Option<&str>, what: &str) -> u32 {
    s.and_then(|v| v.trim_end_matches(';').parse().ok())
        .unwrap_or_else(|| panic!("no number for {what}"))
}

/// What one firmware printed: checked, and the figures compared.
struct Flight {
    iterations: Vec<u32>,
    x_final_bits: String,
    solver_bytes: u32,
    insns: [u32; 3],
    ram: [u32; 3],
}

fn parse(out: &str, who: &str) -> Flight {
    assert!(out.lines().any(|l| l == "DONE"), "{who}: no DONE:\n{out}");
    assert!(
        line_with(out, "fpu: ", who).ends_with("enabled=true"),
        "{who}: FPU off"
    );
    assert!(
        line_with(out, "calib: ", who).contains("= 100000 ticks"),
        "{who}: SysTick does not count 40 instructions per tick:\n{out}"
    );
    let solver = line_with(out, "solver: ", who);
    assert!(solver.ends_with(" in .bss"), "{who}: solver not in .bss");
    let solver_bytes = number(solver.split_whitespace().next(), "solver bytes");
    let mut iterations = Vec::new();
    for (k, l) in out.lines().filter(|l| l.starts_with("step ")).enumerate() {
        assert_eq!(
            l.split_whitespace().nth(1),
            Some(k.to_string().as_str()),
            "{who}: {l}"
        );
        assert_eq!(field(l, "status"), Some("Ok"), "{who}: {l}");
        iterations.push(number(field(l, "iters"), "iters"));
    }
    assert_eq!(iterations.len(), STEPS, "{who}: steps:\n{out}");
    let x_final_bits = line_with(out, "x_final_bits=", who).to_string();
    let insns = line_with(out, "insns/RTI step: ", who);
    let ram = line_with(out, "ram: ", who);
    let ram = ["static", "stack", "total"].map(|k| number(field(ram, k), k));
    assert_eq!(ram[2], ram[0] + ram[1], "{who}: ram");
    Flight {
        iterations,
        x_final_bits,
        solver_bytes,
        insns: ["mean", "min", "max"].map(|k| number(field(insns, k), k)),
        ram,
    }
}

/// Flash as `arm-none-eabi-size` (Berkeley) counts it: text (vector table, code, read-only
/// data) plus the initial image of .data.
fn flash(elf: &Path) -> u32 {
    let out = run(
        Command::new("arm-none-eabi-size").arg(elf),
        "arm-none-eabi-size",
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let row: Vec<u32> = text
        .lines()
        .nth(1)
        .unwrap_or_default()
        .split_whitespace()
        .take(2)
        .map(|v| v.parse().expect("size's text and data columns"))
        .collect();
    assert_eq!(row.len(), 2, "arm-none-eabi-size: {text}");
    row[0] + row[1]
}

#[test]
fn c_firmware_flies_qr_bench_like_the_rust_firmware() {
    for (tool, arg) in [(QEMU, "--version"), ("arm-none-eabi-gcc", "--version")] {
        run(
            Command::new(tool).arg(arg).stdout(Stdio::null()),
            &format!("{tool} (.ci/run installs it)"),
        );
    }
    let tmp = TempDir(std::env::temp_dir().join(format!("mpcc-embedded-c-{}", std::process::id())));
    std::fs::create_dir_all(&tmp.0).expect("create the temporary directory");

    let rust_elf = rust_firmware();
    let rust = parse(&run_qemu(&rust_elf), "Rust firmware");

    let crate_dir = solver_crate(&tmp.0);
    // The library through the fragment's rule (`<name>-staticlib` always asks cargo: the
    // target directory is kept between runs), then the C build: make and arm-none-eabi-gcc
    // only, the solver's memory as large as the Rust firmware's `Solver`.
    run(
        without_host_flags(Command::new("make"))
            .current_dir(repo().join("tests/embedded-c"))
            .arg(format!("CRATE={}", crate_dir.display()))
            .arg(format!("OUT={}", tmp.0.display()))
            .arg(format!("SOLVER_BYTES={}", rust.solver_bytes))
            .args([&format!("{NAME}-staticlib"), "firmware"]),
        "building the static library and the C firmware",
    );
    let c_elf = tmp.0.join("embedded-c-qr-bench");
    let c_out = run_qemu(&c_elf);
    for l in c_out.lines().filter(|l| !l.starts_with("step ")) {
        println!("[C firmware] {l}");
    }
    let c = parse(&c_out, "C firmware");

    assert_eq!(
        c.solver_bytes, rust.solver_bytes,
        "memsize() vs size_of::<Solver>()"
    );
    assert_eq!(c.iterations, rust.iterations, "QP iterations per step");
    assert_eq!(c.x_final_bits, rust.x_final_bits, "final state (f32 bits)");

    let (fc, fr) = (flash(&c_elf), flash(&rust_elf));
    for (who, flash, r) in [("C", fc, &c), ("Rust", fr, &rust)] {
        assert!(
            flash <= FLASH_TARGET,
            "{who} firmware flash {flash} B > {FLASH_TARGET} B"
        );
        assert!(
            r.ram[2] <= RAM_TARGET,
            "{who} firmware RAM {} B > {RAM_TARGET} B",
            r.ram[2]
        );
        assert!(
            r.insns[2] <= STEP_TARGET,
            "{who} firmware's worst step: {} instructions > {STEP_TARGET}",
            r.insns[2]
        );
    }
    println!("QR-bench A, f32, mps2-an386 (Cortex-M4F), 100 steps: C firmware | Rust firmware");
    println!("flash B:                    {fc} | {fr}");
    println!(
        "RAM B (static + stack):     {} + {} = {} | {} + {} = {}",
        c.ram[0], c.ram[1], c.ram[2], rust.ram[0], rust.ram[1], rust.ram[2]
    );
    println!(
        "instructions per RTI step:  mean {} min {} max {} | mean {} min {} max {}",
        c.insns[0], c.insns[1], c.insns[2], rust.insns[0], rust.insns[1], rust.insns[2]
    );
}
