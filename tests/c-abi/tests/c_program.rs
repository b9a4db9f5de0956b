//! Drives the generated `quadrotor_rates` solver through its C ABI: compiles `qrbench.c`
//! (C99, AddressSanitizer + UndefinedBehaviorSanitizer) and `qrbench.cpp` (C++17) against
//! the generated header, links them with this package's static library, runs them, and
//! checks the C closed loop against the same loop run here in Rust.
//!
//! gcc and g++ are required: without them these tests fail (they are not skipped).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use nalgebra::SVector;

#[allow(dead_code)]
#[path = "../../../runtime/tests/support/quadrotor.rs"]
mod quadrotor;

/// Closed-loop steps of `qrbench.c`.
const STEPS: usize = 100;
/// RK4 substeps of the plant per control interval.
const SUBSTEPS: usize = 10;

fn manifest_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn header_dir() -> PathBuf {
    manifest_dir().join("../../generated/quadrotor_rates/include")
}

/// The static library of this package that cargo built for this test run.
///
/// The test binary is `<target>/<profile>/deps/c_program-<hash>`. `cargo test` builds the
/// lib target (crate types staticlib + rlib) into the same `deps/` directory as
/// `libc_abi_test-<hash>.a`, but copies it to `<target>/<profile>/libc_abi_test.a` only
/// when the lib itself is a requested target (`cargo build`), so that copy may be missing
/// or stale. The archive built last is the one of this run: cargo has just (re)built it
/// or found it fresh, and an older hash would only be left over from a different
/// dependency graph.
fn staticlib() -> PathBuf {
    let exe = std::env::current_exe().expect("path of the test binary");
    let deps = exe
        .parent()
        .expect("test binary in <target>/<profile>/deps");
    let entries =
        std::fs::read_dir(deps).unwrap_or_else(|e| panic!("cannot list {}: {e}", deps.display()));
    let newest = entries
        .filter_map(Result::ok)
        .filter(|e| {
            let name = e.file_name();
            let name = name.to_string_lossy();
            name.starts_with("libc_abi_test-") && name.ends_with(".a")
        })
        .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
        .max();
    match newest {
        Some((_, lib)) => lib,
        None => panic!(
            "no libc_abi_test-*.a in {}: the static library of c-abi-test is built with \
             its lib target (crate-type staticlib); run the tests with `cargo test` in \
             tests/c-abi",
            deps.display()
        ),
    }
}

/// Runs `cmd`, failing the test with a clear message if the tool is missing.
fn run(cmd: &mut Command, what: &str) -> Output {
    match cmd.output() {
        Ok(out) => out,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => panic!(
            "{what}: `{}` not found ({e}); gcc and g++ are required for the C ABI tests",
            cmd.get_program().to_string_lossy()
        ),
        Err(e) => panic!("{what}: cannot run {cmd:?}: {e}"),
    }
}

fn assert_success(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed ({}):\n--- stdout\n{}\n--- stderr\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Compiles and links `source` with `compiler` and `flags` into `exe`.
fn build(compiler: &str, flags: &[&str], source: &str, exe: &Path) {
    let mut cmd = Command::new(compiler);
    cmd.args(flags)
        .arg("-I")
        .arg(header_dir())
        .arg(manifest_dir().join(source))
        .arg(staticlib())
        .args(["-lpthread", "-ldl", "-lm", "-o"])
        .arg(exe);
    let out = run(&mut cmd, &format!("compiling {source}"));
    assert_success(&out, &format!("{compiler} {source}"));
}

/// Runs `exe` with leak detection on and every UB report fatal.
fn run_sanitized(exe: &Path) -> Output {
    let mut cmd = Command::new(exe);
    cmd.env("ASAN_OPTIONS", "detect_leaks=1:abort_on_error=0")
        .env("UBSAN_OPTIONS", "halt_on_error=1:print_stacktrace=1");
    let out = run(&mut cmd, "running the compiled program");
    assert_success(&out, &exe.display().to_string());
    out
}

const SANITIZE: [&str; 3] = [
    "-O1",
    "-fsanitize=address,undefined",
    "-fno-omit-frame-pointer",
];

/// The QR-bench closed loop of `qrbench.c`, in Rust through the same generated crate.
fn rust_closed_loop() -> [f64; 10] {
    use quadrotor_rates as m;
    let mut s = Box::new(m::Solver::new());
    let x0 = quadrotor::X0;
    s.set_guess(&x0, &[0.0; 4]).unwrap();
    let mut x = SVector::from(x0);
    for k in 0..STEPS {
        s.prepare();
        s.set_x0(&x.into()).unwrap();
        let info = s.feedback();
        assert_eq!(info.status, m::RtiStatus::Ok, "step {k}: {info:?}");
        let u = SVector::from(s.u0());
        x = quadrotor::plant(&x, &u, m::DT, SUBSTEPS);
    }
    x.into()
}

#[test]
fn c_closed_loop_matches_rust() {
    let exe = Path::new(env!("CARGO_TARGET_TMPDIR")).join("qrbench_c");
    let flags = [
        &["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"][..],
        &SANITIZE[..],
    ]
    .concat();
    build("gcc", &flags, "qrbench.c", &exe);
    let out = run_sanitized(&exe);

    let stdout = String::from_utf8(out.stdout).expect("UTF-8 output");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(
        lines.len(),
        1,
        "expected one line of output, got:\n{stdout}"
    );
    let c: Vec<f64> = lines[0]
        .split_whitespace()
        .map(|t| {
            t.parse()
                .unwrap_or_else(|e| panic!("bad number {t:?}: {e}"))
        })
        .collect();
    assert_eq!(c.len(), 10, "expected 10 numbers, got {:?}", lines[0]);

    let rust = rust_closed_loop();
    let max_diff = c
        .iter()
        .zip(rust)
        .map(|(c, r)| (c - r).abs())
        .fold(0.0, f64::max);
    println!("C final state: {}", lines[0]);
    println!("Rust final state: {rust:?}");
    println!("max |C - Rust| = {max_diff:e}");
    for (i, (c, r)) in c.iter().zip(rust).enumerate() {
        assert!(
            (c - r).abs() <= 1e-9,
            "final state entry {i}: C {c:e} vs Rust {r:e}\nC:    {c_all:?}\nRust: {rust:?}",
            c_all = lines[0]
        );
    }
}

#[test]
fn header_compiles_and_links_as_cpp17() {
    let exe = Path::new(env!("CARGO_TARGET_TMPDIR")).join("qrbench_cpp");
    let flags = [
        &["-std=c++17", "-Wall", "-Wextra", "-Werror", "-pedantic"][..],
        &SANITIZE[..],
    ]
    .concat();
    build("g++", &flags, "qrbench.cpp", &exe);
    let out = run_sanitized(&exe);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.starts_with("u0 = "), "unexpected output: {stdout}");
}
