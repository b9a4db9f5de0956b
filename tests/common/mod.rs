//! Helpers shared by the workspace's integration tests.

use std::process::Command;

/// Runs the `mpcc` binary of this build from the repository root: exit code, stdout, stderr.
#[allow(dead_code)] // not every test binary that includes this module runs mpcc
pub fn mpcc(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_mpcc"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the mpcc binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// What a child printed and how it ended, or `None` for `status` if it was killed after the
/// timeout.
#[allow(dead_code)] // not every test binary that includes this module waits for children
pub struct Finished {
    /// The exit status (`None`: timed out and killed).
    pub status: Option<std::process::ExitStatus>,
    /// Standard output (what was printed until the end or the kill).
    pub stdout: String,
    /// Standard error.
    pub stderr: String,
}

/// Waits for `child` (spawned with piped stdout and stderr, read on threads so a full pipe
/// cannot stall it) at most `timeout`, killing it then.
#[allow(dead_code)]
pub fn wait_with_timeout(
    child: &mut std::process::Child,
    timeout: std::time::Duration,
) -> Finished {
    use std::io::Read;
    fn drain(r: Option<impl Read + Send + 'static>) -> std::thread::JoinHandle<String> {
        std::thread::spawn(move || {
            let mut s = String::new();
            if let Some(mut r) = r {
                let _ = r.read_to_string(&mut s);
            }
            s
        })
    }
    let out = drain(child.stdout.take());
    let err = drain(child.stderr.take());
    let start = std::time::Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Some(status),
            Ok(None) if start.elapsed() <= timeout => {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
        }
    };
    Finished {
        status,
        stdout: out.join().unwrap_or_default(),
        stderr: err.join().unwrap_or_default(),
    }
}

/// The number `key` of a JSON object (panics naming the key if it is missing).
#[allow(dead_code)] // not every test binary that includes this module reads JSON
pub fn num(v: &serde_json::Value, key: &str) -> f64 {
    v.get(key)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or_else(|| panic!("{key} missing or not a number in {v}"))
}

/// Runs `cmd` and returns its output; panics with what it printed if it cannot start or
/// fails (`.ci/run` installs the tools the tests run).
#[allow(dead_code)] // not every test binary that includes this module runs tools
pub fn run(cmd: &mut Command, what: &str) -> std::process::Output {
    let out = cmd.output().unwrap_or_else(|e| {
        panic!(
            "{what}: cannot run {:?} ({e}); .ci/run installs the tools",
            cmd.get_program()
        )
    });
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The warnings every C program of the tests is compiled with (C11, warnings as errors).
#[allow(dead_code)] // not every test binary that includes this module compiles C
pub const C_FLAGS: [&str; 6] = [
    "-std=c11",
    "-Wall",
    "-Wextra",
    "-Werror",
    "-pedantic",
    "-O2",
];

/// Compiles `main_c` with the compile and link line `mpcc build --staticlib` printed (its
/// `main.c` replaced by `main_c`) and [`C_FLAGS`], into `exe`.
#[allow(dead_code)] // not every test binary that includes this module compiles C
pub fn build_with_printed_line(link_line: &str, main_c: &std::path::Path, exe: &std::path::Path) {
    let mut words = link_line.split_whitespace();
    let mut cmd = Command::new(words.next().expect("a compiler"));
    for w in words {
        if w == "main.c" {
            cmd.arg(main_c);
        } else {
            cmd.arg(w);
        }
    }
    cmd.args(C_FLAGS).arg("-o").arg(exe);
    run(&mut cmd, "the printed compile and link line");
}

/// Compiles `main_c` against the generated header in `include` and links the static library
/// `lib` (with the system libraries a Rust static library needs) and [`C_FLAGS`], into `exe`.
#[allow(dead_code)] // not every test binary that includes this module compiles C
pub fn build_c(
    main_c: &std::path::Path,
    include: &std::path::Path,
    lib: &std::path::Path,
    exe: &std::path::Path,
) {
    run(
        Command::new("cc")
            .args(C_FLAGS)
            .arg(main_c)
            .arg(format!("-I{}", include.display()))
            .arg(lib)
            .args(["-lpthread", "-ldl", "-lm", "-o"])
            .arg(exe),
        "cc",
    );
}

/// A directory removed when dropped (also when the test fails).
#[allow(dead_code)] // not every test binary that includes this module makes one
pub struct TempDir(pub std::path::PathBuf);

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
