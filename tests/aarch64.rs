//! The companion-computer proof: the paper's companion computer is an Odroid M1 (Cortex-A55,
//! aarch64 Linux). This test cross-builds the `mpcc` binary for `aarch64-unknown-linux-gnu`
//! (release, linked by Debian's `aarch64-linux-gnu-gcc`), runs it under `qemu-aarch64`
//! user-mode emulation and checks that it computes what the host `mpcc` computes: QR-bench A
//! (f64 and f32) and B with `mpcc bench`, and the flip mission with `mpcc sim`.
//!
//! Needs the Rust target (`rustup target add aarch64-unknown-linux-gnu`), the cross linker and
//! its C library (Debian: `apt-get install -y gcc-aarch64-linux-gnu libc6-dev-arm64-cross`) and
//! qemu's user-mode emulator (Debian: `apt-get install -y qemu-user`): without them the test
//! fails with what to install, it never skips. `.ci/run` installs them.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;

const TARGET: &str = "aarch64-unknown-linux-gnu";
const LINKER: &str = "aarch64-linux-gnu-gcc";
/// qemu's aarch64 user-mode emulator: Debian's `qemu-user` installs the first name,
/// `qemu-user-static` the second.
const QEMUS: [&str; 2] = ["qemu-aarch64", "qemu-aarch64-static"];
/// The nearest core qemu 7.2 models to the Odroid M1's Cortex-A55 (ARMv8.2; qemu has no A55):
/// its in-order predecessor, ARMv8.0, so the binary needs nothing past the baseline either.
const QEMU_CPU: &str = "cortex-a53";
const QEMU_TIMEOUT: Duration = Duration::from_secs(600);
const INSTALL: &str = "install them with `rustup target add aarch64-unknown-linux-gnu` and \
                       (Debian/Ubuntu) `apt-get install -y --no-install-recommends \
                       gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user`; .ci/run does";

/// Relative tolerance of the comparisons of final errors and states. Rust never contracts
/// `a * b + c` into an FMA, the solver's maths is IEEE-754 basic arithmetic and `sqrt` (exactly
/// rounded on both ISAs), so the two binaries are expected to agree to the bit; 1e-9 leaves
/// room only for a last-bit difference of a libm function (glibc's x86_64 and aarch64 builds).
const RTOL: f64 = 1e-9;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn tmp(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(name)
}

fn succeeds(cmd: &mut Command) -> bool {
    cmd.stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The sysroot the cross gcc links against (`/usr/aarch64-linux-gnu` on Debian): qemu's `-L`,
/// where it finds `lib/ld-linux-aarch64.so.1` and the target's glibc.
fn sysroot() -> Result<PathBuf, String> {
    let out = Command::new(LINKER)
        .arg("-print-file-name=ld-linux-aarch64.so.1")
        .output()
        .map_err(|e| format!("cannot run {LINKER} ({e}): {INSTALL}"))?;
    let printed = String::from_utf8_lossy(&out.stdout).trim().to_string();
    // gcc prints the bare name when it does not find the file.
    let loader = Path::new(&printed)
        .canonicalize()
        .map_err(|_| format!("{LINKER} finds no aarch64 glibc ({printed:?}): {INSTALL}"))?;
    let dir = loader
        .parent()
        .and_then(Path::parent)
        .ok_or_else(|| format!("odd loader path {}", loader.display()))?;
    Ok(dir.to_path_buf())
}

struct Tools {
    qemu: &'static str,
    sysroot: PathBuf,
}

/// Checks the tools before minutes of building.
fn preflight() -> Result<Tools, String> {
    let mut missing = Vec::new();
    let qemu = QEMUS
        .into_iter()
        .find(|q| succeeds(Command::new(q).arg("--version")));
    if qemu.is_none() {
        missing.push(QEMUS[0]);
    }
    if !succeeds(Command::new(LINKER).arg("--version")) {
        missing.push(LINKER);
    }
    // The target's standard library, in the sysroot of the rustc cargo runs.
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let std_installed = Command::new(rustc)
        .args(["--print", "sysroot"])
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .is_some_and(|s| Path::new(&s).join("lib/rustlib").join(TARGET).is_dir());
    if !std_installed {
        missing.push("the Rust target aarch64-unknown-linux-gnu");
    }
    if !missing.is_empty() {
        return Err(format!("missing {}: {INSTALL}", missing.join(", ")));
    }
    Ok(Tools {
        qemu: qemu.unwrap_or(QEMUS[0]),
        sysroot: sysroot()?,
    })
}

/// Cross-builds `mpcc` into its own target dir (the outer build holds the lock on its own).
fn build() -> Result<PathBuf, String> {
    let target_dir = tmp("aarch64-mpcc");
    let started = Instant::now();
    let out = Command::new(env!("CARGO"))
        .current_dir(root())
        .args(["build", "--release", "--bin", "mpcc", "--target", TARGET])
        .arg("--manifest-path")
        .arg(root().join("Cargo.toml"))
        .arg("--target-dir")
        .arg(&target_dir)
        .env("CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER", LINKER)
        // Host flags (e.g. -C target-cpu=native) must not reach the aarch64 build.
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("CARGO_TARGET_DIR")
        .output()
        .map_err(|e| format!("cargo does not run: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "cross-building mpcc for {TARGET} failed ({INSTALL}):\n{}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let bin = target_dir.join(TARGET).join("release/mpcc");
    // ELF, 64-bit, little-endian, e_machine EM_AARCH64 (183): not a host binary by mistake.
    let head = std::fs::read(&bin).map_err(|e| format!("{}: {e}", bin.display()))?;
    if head.len() < 20 || &head[..6] != b"\x7fELF\x02\x01" || head[18..20] != [183, 0] {
        return Err(format!("{} is not an aarch64 ELF", bin.display()));
    }
    eprintln!(
        "cross-built {} in {:.1} s",
        bin.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(bin)
}

/// The aarch64 `mpcc` and the tools to run it, built once for both tests.
fn aarch64_mpcc() -> &'static (PathBuf, Tools) {
    static BIN: OnceLock<Result<(PathBuf, Tools), String>> = OnceLock::new();
    match BIN.get_or_init(|| {
        let tools = preflight()?;
        Ok((build()?, tools))
    }) {
        Ok(b) => b,
        Err(e) => panic!("{e}"),
    }
}

struct Run {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// Runs `cmd` from the repository root with a timeout.
fn run(mut cmd: Command, what: &str) -> Run {
    let mut child = cmd
        .current_dir(root())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{what} does not start ({e}): {INSTALL}"));
    let done = common::wait_with_timeout(&mut child, QEMU_TIMEOUT);
    let Some(status) = done.status else {
        panic!("{what} timed out after {QEMU_TIMEOUT:?}");
    };
    Run {
        code: status.code(),
        stdout: done.stdout,
        stderr: done.stderr,
    }
}

fn host(args: &[&str]) -> Run {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mpcc"));
    cmd.args(args);
    run(cmd, &format!("host mpcc {args:?}"))
}

fn emulated(args: &[&str]) -> Run {
    let (bin, tools) = aarch64_mpcc();
    let mut cmd = Command::new(tools.qemu);
    cmd.args(["-cpu", QEMU_CPU, "-L"])
        .arg(&tools.sysroot)
        .arg(bin)
        .args(args);
    run(cmd, &format!("{} mpcc {args:?}", tools.qemu))
}

fn json(r: &Run, what: &str) -> Value {
    assert_eq!(r.code, Some(0), "{what}:\n{}\n{}", r.stdout, r.stderr);
    serde_json::from_str(r.stdout.trim())
        .unwrap_or_else(|e| panic!("{what}: not one JSON object ({e}):\n{}", r.stdout))
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} missing or not a number in {v}"))
}

/// |a - b| relative to the larger magnitude (absolute below 1).
fn rel(a: f64, b: f64) -> f64 {
    if a == b {
        0.0
    } else {
        (a - b).abs() / a.abs().max(b.abs()).max(1.0)
    }
}

/// The numbers of a closed-loop CSV (t, 10 states, 4 controls; the last row has no controls).
fn csv_rows(path: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    assert!(
        lines.next().is_some_and(|h| h.starts_with("t,px,py,pz,")),
        "{}: header",
        path.display()
    );
    lines
        .map(|l| {
            l.split(',')
                .filter(|f| !f.is_empty())
                .map(|f| f.parse().expect("a number"))
                .collect()
        })
        .collect()
}

/// Largest relative difference of two CSVs, and how many entries are not bit-identical.
fn csv_difference(a: &Path, b: &Path) -> (f64, usize) {
    let (ra, rb) = (csv_rows(a), csv_rows(b));
    assert_eq!(
        ra.len(),
        rb.len(),
        "row counts of {} and {}",
        a.display(),
        b.display()
    );
    let mut worst = 0.0f64;
    let mut differing = 0;
    for (k, (x, y)) in ra.iter().zip(&rb).enumerate() {
        assert_eq!(x.len(), y.len(), "row {k} widths");
        for (p, q) in x.iter().zip(y) {
            if p.to_bits() != q.to_bits() {
                differing += 1;
            }
            worst = worst.max(rel(*p, *q));
        }
    }
    (worst, differing)
}

fn stats(v: &Value, phase: &str) -> String {
    let s = &v[phase];
    format!(
        "{phase} mean {:.1} median {:.1} p99 {:.1} max {:.1} us",
        num(s, "mean"),
        num(s, "median"),
        num(s, "p99"),
        num(s, "max")
    )
}

/// QR-bench A (f64, f32) and B: same success, QP iterations, final error and closed loop.
#[test]
fn qr_bench_on_aarch64_matches_the_host() {
    aarch64_mpcc();
    for (name, extra) in [
        ("A_f64", &[][..]),
        ("A_f32", &["--f32"][..]),
        ("B_f64", &["--horizon", "20"][..]),
    ] {
        let mut csvs = Vec::new();
        let mut reports = Vec::new();
        for side in ["host", "aarch64"] {
            let csv = tmp(&format!("aarch64_bench_{name}_{side}.csv"));
            let _ = std::fs::remove_file(&csv);
            let mut args = vec!["bench", "--rounds", "1", "--json", "--csv"];
            args.push(csv.to_str().unwrap());
            args.extend(extra);
            let started = Instant::now();
            let r = if side == "host" {
                host(&args)
            } else {
                emulated(&args)
            };
            let v = json(&r, &format!("{name} on {side}"));
            println!(
                "[{name} {side}] {:.1} s; final error {:e} m, QP iterations mean {}, all_ok {}; \
                 {}; {}; {}",
                started.elapsed().as_secs_f64(),
                num(&v, "final_position_error_m"),
                num(&v, "qp_iterations_mean"),
                v["all_ok"],
                stats(&v, "prepare_us"),
                stats(&v, "feedback_us"),
                stats(&v, "total_us"),
            );
            csvs.push(csv);
            reports.push(v);
        }
        let (h, a) = (&reports[0], &reports[1]);
        assert_eq!(h["all_ok"], Value::Bool(true), "{name}: host {h}");
        assert_eq!(h["all_ok"], a["all_ok"], "{name}: all_ok");
        assert_eq!(h["steps"], a["steps"], "{name}: steps");
        for key in [
            "qp_iterations_mean",
            "qp_iterations_max",
            "qp_interior_point_steps",
            "qp_active_set_solves_mean",
        ] {
            assert_eq!(h[key], a[key], "{name}: {key}");
        }
        let (eh, ea) = (
            num(h, "final_position_error_m"),
            num(a, "final_position_error_m"),
        );
        assert!(
            rel(eh, ea) <= RTOL,
            "{name}: final position error {ea:e} m on aarch64, {eh:e} m on the host"
        );
        let (d, differing) = csv_difference(&csvs[0], &csvs[1]);
        println!(
            "[{name}] closed loop: max relative difference {d:e}, {differing} entries not \
             bit-identical"
        );
        assert!(d <= RTOL, "{name}: closed loops differ by {d:e} (relative)");
    }
}

/// Drops the wall-clock fields (solver timing) of the sim summary.
fn without_timing(v: &Value) -> Value {
    match v {
        Value::Object(m) => Value::Object(
            m.iter()
                .filter(|(k, _)| !k.contains("time_us") && !k.ends_with("_ms"))
                .map(|(k, x)| (k.clone(), without_timing(x)))
                .collect(),
        ),
        Value::Array(a) => Value::Array(a.iter().map(without_timing).collect()),
        x => x.clone(),
    }
}

/// Largest relative difference of the numbers of two JSON values of the same shape.
fn json_difference(a: &Value, b: &Value, path: &str) -> f64 {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => rel(x.as_f64().unwrap(), y.as_f64().unwrap()),
        (Value::Object(x), Value::Object(y)) => {
            let (kx, ky): (Vec<_>, Vec<_>) = (x.keys().collect(), y.keys().collect());
            assert_eq!(kx, ky, "keys of {path}");
            x.iter()
                .map(|(k, v)| json_difference(v, &y[k], &format!("{path}.{k}")))
                .fold(0.0, f64::max)
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "length of {path}");
            x.iter()
                .zip(y)
                .enumerate()
                .map(|(i, (p, q))| json_difference(p, q, &format!("{path}[{i}]")))
                .fold(0.0, f64::max)
        }
        (x, y) => {
            assert_eq!(x, y, "{path}");
            0.0
        }
    }
}

/// The flip mission (the paper's architecture, `mpcc sim`) succeeds on both, with the same
/// summary up to the solver timings.
#[test]
fn flip_mission_on_aarch64_matches_the_host() {
    aarch64_mpcc();
    let args = ["sim", "--json", "--no-plots"];
    let started = Instant::now();
    let h = json(&host(&args), "sim on host");
    let host_s = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let a = json(&emulated(&args), "sim on aarch64");
    let emulated_s = started.elapsed().as_secs_f64();
    for (side, v) in [("host", &h), ("aarch64", &a)] {
        assert_eq!(v["success"], Value::Bool(true), "{side}: {v}");
        assert_eq!(num(v, "trials"), 1.0, "{side}: {v}");
        assert_eq!(num(v, "successes"), 1.0, "{side}: {v}");
    }
    let d = json_difference(&without_timing(&h), &without_timing(&a), "sim");
    println!(
        "[sim] host {host_s:.1} s, aarch64 (qemu) {emulated_s:.1} s; summaries differ by {d:e}"
    );
    assert!(d <= RTOL, "sim summaries differ by {d:e} (relative)");
}
