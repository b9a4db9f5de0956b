//! The bare-metal proof (`tests/embedded/`): builds the firmware for
//! `thumbv7em-none-eabihf`, runs it in qemu on an emulated Cortex-M4F (`mps2-an386`) and
//! Cortex-M7 (`mps2-an500`) under `-icount shift=0`, and checks that it flies the 100 steps of
//! the f32 QR-bench closed loop with every status Ok, that its SysTick counts instructions
//! at the expected scale, and that its final state matches the same loop flown here on the
//! host with `quadrotor_rates_f32`. Needs `qemu-system-arm` (Debian: `apt-get install -y
//! qemu-system-arm`) and the target (`rustup target add thumbv7em-none-eabihf`): without
//! them the test fails, it never skips.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use quadrotor_rates_f32::{DT, NX_MODEL, Real, RtiStatus, Solver};

#[path = "../common/mod.rs"]
mod common;
#[path = "src/plant.rs"]
mod plant;
use plant::plant;

const STEPS: usize = 100;
const TARGET: &str = "thumbv7em-none-eabihf";
const QEMU: &str = "qemu-system-arm";
const QEMU_TIMEOUT: Duration = Duration::from_secs(120);

/// The closed loop on the host: final state and QP iterations per step.
fn host_run() -> ([Real; NX_MODEL], Vec<u32>) {
    let mut solver = Box::new(Solver::new());
    let mut x: [Real; NX_MODEL] = [0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut iterations = Vec::with_capacity(STEPS);
    for k in 0..STEPS {
        solver.prepare();
        solver.set_x0(&x).expect("finite state");
        let info = solver.feedback();
        assert_eq!(info.status, RtiStatus::Ok, "host step {k}");
        iterations.push(info.qp.iterations);
        x = plant(&x, &solver.u0(), DT);
    }
    (x, iterations)
}

fn firmware_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/embedded")
}

/// Builds the firmware into its own target dir (the outer build holds the lock on its own).
fn build_firmware() -> PathBuf {
    let dir = firmware_dir();
    let target_dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("embedded-firmware");
    let out = Command::new(env!("CARGO"))
        .current_dir(&dir)
        .args(["build", "--release", "--target", TARGET, "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .arg("--target-dir")
        .arg(&target_dir)
        // Host flags (e.g. -C target-cpu=native) must not reach the thumb build.
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("CARGO_TARGET_DIR")
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "building the firmware failed (is the target installed? `rustup target add {TARGET}`):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    target_dir.join(TARGET).join("release/embedded-qr-bench")
}

/// Runs the firmware in qemu with a timeout; returns its semihosting output.
fn run_qemu(elf: &Path, machine: &str, cpu: &str) -> String {
    let mut child = Command::new(QEMU)
        .args(["-M", machine, "-cpu", cpu, "-icount", "shift=0"])
        .args(["-display", "none", "-monitor", "none", "-serial", "null"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run {QEMU} ({e}): install it (Debian/Ubuntu: `apt-get install -y \
                 qemu-system-arm`); .ci/run installs it"
            )
        });
    let done = common::wait_with_timeout(&mut child, QEMU_TIMEOUT);
    let (out, err) = (done.stdout, done.stderr);
    let Some(status) = done.status else {
        panic!("{QEMU} -M {machine} timed out after {QEMU_TIMEOUT:?}; output so far:\n{out}");
    };
    assert!(
        status.success(),
        "{QEMU} -M {machine} exited with {status}:\n{out}\n{err}"
    );
    out
}

/// The value after `key=` up to the next space, in `line`.
fn field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
}

struct Report {
    iterations: Vec<u32>,
    x_final: [Real; NX_MODEL],
}

/// Checks the firmware's output and extracts what the host compares.
fn parse(out: &str, machine: &str) -> Report {
    assert!(
        out.lines().any(|l| l == "DONE"),
        "{machine}: no DONE line:\n{out}"
    );
    assert!(
        out.lines()
            .any(|l| l.starts_with("fpu:") && l.ends_with("enabled=true")),
        "{machine}: FPU not enabled:\n{out}"
    );
    // The counter: 4000002 instructions must read as 100000 SysTick ticks (40 per tick).
    let calib = out
        .lines()
        .find(|l| l.starts_with("calib:"))
        .unwrap_or_else(|| panic!("{machine}: no calib line:\n{out}"));
    assert!(
        calib.contains("= 100000 ticks"),
        "{machine}: SysTick does not count 40 instructions per tick: {calib}"
    );
    // The solver's static is zero-filled memory, not an image in flash.
    assert!(
        out.lines()
            .any(|l| l.starts_with("solver:") && l.ends_with(" in .bss")),
        "{machine}: the solver is not in .bss:\n{out}"
    );
    // RAM: the static sections hold the solver; the total is statics plus the stack mark.
    let ram = out
        .lines()
        .find(|l| l.starts_with("ram:"))
        .unwrap_or_else(|| panic!("{machine}: no ram line:\n{out}"));
    let bytes = |key: &str| -> usize {
        field(ram, key)
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{machine}: no {key} in {ram}"))
    };
    let solver: usize = out
        .lines()
        .find_map(|l| l.strip_prefix("solver: "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{machine}: no solver size:\n{out}"));
    assert!(
        bytes("static") >= solver,
        "{machine}: the static RAM is smaller than the {solver}-byte solver: {ram}"
    );
    assert_eq!(
        bytes("total"),
        bytes("static") + bytes("stack"),
        "{machine}: {ram}"
    );
    // The stack counted is the deepest of the marks printed (setup, the loop, step 0's
    // prepare and feedback alone).
    let marks = out
        .lines()
        .find_map(|l| l.strip_prefix("stack high-water: "))
        .unwrap_or_else(|| panic!("{machine}: no stack high-water line:\n{out}"));
    let mark = |key: &str| -> usize {
        marks
            .split(key)
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{machine}: no {key:?} mark in {marks}"))
    };
    let deepest = ["setup=", "loop=", "(prepare ", "set_x0+feedback "]
        .map(mark)
        .into_iter()
        .max()
        .unwrap_or(0);
    assert_eq!(
        bytes("stack"),
        deepest,
        "{machine}: the RAM figure's stack is not the deepest mark: {marks} / {ram}"
    );
    let mut iterations = Vec::new();
    for (k, line) in out.lines().filter(|l| l.starts_with("step ")).enumerate() {
        assert_eq!(
            line.split_whitespace().nth(1),
            Some(k.to_string().as_str()),
            "{machine}: steps out of order: {line}"
        );
        assert_eq!(field(line, "status"), Some("Ok"), "{machine}: {line}");
        for key in ["prepare_ticks", "feedback_ticks"] {
            let ticks: u32 = field(line, key)
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{machine}: no {key} in {line}"));
            assert!(ticks > 0, "{machine}: {key} is 0 in {line}");
        }
        let it: u32 = field(line, "iters")
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{machine}: no iters in {line}"));
        iterations.push(it);
    }
    assert_eq!(iterations.len(), STEPS, "{machine}: step count:\n{out}");
    // The final state as the hex bits of each f32 (the firmware has no float formatting).
    let xs = out
        .lines()
        .find_map(|l| l.strip_prefix("x_final_bits=["))
        .and_then(|l| l.strip_suffix(']'))
        .unwrap_or_else(|| panic!("{machine}: no x_final_bits line:\n{out}"));
    let v: Vec<Real> = xs
        .split(',')
        .map(|e| {
            u32::from_str_radix(e.trim(), 16)
                .map(Real::from_bits)
                .expect("x_final_bits entry is hexadecimal")
        })
        .collect();
    let x_final: [Real; NX_MODEL] = v.try_into().expect("x_final has 10 entries");
    Report {
        iterations,
        x_final,
    }
}

#[test]
fn firmware_flies_qr_bench_in_qemu_like_the_host() {
    // Fail early and clearly when qemu is missing (before a minute of building).
    assert!(
        Command::new(QEMU)
            .arg("--version")
            .stdout(Stdio::null())
            .status()
            .is_ok_and(|s| s.success()),
        "{QEMU} not found: install it (Debian/Ubuntu: `apt-get install -y qemu-system-arm`); \
         .ci/run installs it"
    );
    let started = Instant::now();
    let elf = build_firmware();
    let built = started.elapsed();
    let (x_host, it_host) = host_run();
    let mut finals = Vec::new();
    for (machine, cpu) in [("mps2-an386", "cortex-m4"), ("mps2-an500", "cortex-m7")] {
        let out = run_qemu(&elf, machine, cpu);
        for line in out.lines().filter(|l| !l.starts_with("step ")) {
            println!("[{machine}] {line}");
        }
        let r = parse(&out, machine);
        let diff = r
            .x_final
            .iter()
            .zip(&x_host)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, Real::max);
        println!("[{machine}] max |x_qemu - x_host| = {diff:e}");
        assert!(
            diff <= 1e-3,
            "{machine}: final state {:?} vs host {x_host:?}",
            r.x_final
        );
        let (sq, sh) = (
            r.iterations.iter().sum::<u32>(),
            it_host.iter().sum::<u32>(),
        );
        assert!(
            sq.abs_diff(sh) <= 5,
            "{machine}: QP iterations {sq} vs host {sh}"
        );
        finals.push(r.x_final);
    }
    // The same binary on both cores computes the same numbers.
    assert_eq!(finals[0], finals[1], "Cortex-M4F and Cortex-M7 differ");
    println!(
        "build {:.1} s, total {:.1} s",
        built.as_secs_f64(),
        started.elapsed().as_secs_f64()
    );
}
