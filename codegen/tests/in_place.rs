//! Construction in place for a long horizon: a tiny model generated with `N = 4096`, built
//! as a crate with its `alloc` feature, whose test builds the solver with `Solver::boxed()`
//! in a thread with a 2 MiB stack (smaller than the solver) and runs a control step.

mod support;

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

#[test]
fn boxed_solver_with_thousands_of_stages_runs_in_a_2_mib_thread() {
    let dir = support::write_crate("in-place-test/tiny_long", TINY);
    std::fs::create_dir_all(dir.join("tests")).unwrap();
    std::fs::write(dir.join("tests/step.rs"), STEP_TEST).unwrap();
    let args = ["test", "--features", "alloc", "--test", "step"];
    support::cargo(&dir, &args, "in-place-test/target");
}
