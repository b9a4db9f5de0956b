//! Construction in place for a long horizon: a tiny model generated with `N = 4096`, built
//! as a crate with its `alloc` feature, whose test builds the solver with `Solver::boxed()`
//! in a thread with a 2 MiB stack (smaller than the solver) and runs a control step.

use std::path::PathBuf;
use std::process::Command;

use mpc_codegen::{Options, RuntimeDep, generate};
use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};

const TINY: &str = r#"
model tiny_long;
state x[2];
control u;
dynamics ode rk4(1) { der(x) = [x[1], u]; }
horizon N = 4096, dt = 0.01;
cost {
    Q = diag(1, 1);
    R = diag(1);
}
"#;

const STEP_TEST: &str = r#"
#[test]
fn boxed_in_a_small_thread() {
    let size = core::mem::size_of::<tiny_long::Solver>();
    assert!(size > 2 << 20, "the solver ({size} B) must not fit the thread's stack");
    let h = std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(|| {
            let mut s = tiny_long::Solver::boxed();
            s.set_x0(&[1.0, 0.0]).unwrap();
            s.prepare();
            let info = s.feedback();
            (info.status, s.u0()[0])
        })
        .unwrap();
    let (status, u) = h.join().unwrap();
    assert_eq!(status, tiny_long::RtiStatus::Ok);
    assert!(u < 0.0, "the plan pushes back to the origin: {u}");
}
"#;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn boxed_solver_with_thousands_of_stages_runs_in_a_2_mib_thread() {
    let g = Graph::new();
    let parsed = match parse(&g, TINY, &ParseOptions::default()) {
        Ok(p) => p,
        Err(d) => panic!("{}", d.render("tiny.mpc", TINY)),
    };
    let mut opts = Options::new();
    let runtime = root().join("runtime").canonicalize().unwrap();
    opts.runtime = RuntimeDep::Path(runtime.display().to_string());
    let krate = generate(&parsed.ocp, &opts).unwrap();
    let dir = root().join("target/in-place-test/tiny_long");
    krate.write(&dir).unwrap();
    std::fs::create_dir_all(dir.join("tests")).unwrap();
    std::fs::write(dir.join("tests/step.rs"), STEP_TEST).unwrap();
    // Its own workspace (the repository's does not list it), the repository's target
    // directory (the runtime and its dependencies are built there already).
    let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    if !manifest.contains("[workspace]") {
        std::fs::write(dir.join("Cargo.toml"), format!("{manifest}\n[workspace]\n")).unwrap();
    }
    let out = Command::new(env!("CARGO"))
        .args(["test", "--offline", "--features", "alloc", "--test", "step"])
        .current_dir(&dir)
        .env(
            "CARGO_TARGET_DIR",
            root().join("target/in-place-test/target"),
        )
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
