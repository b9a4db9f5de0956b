//! `mpcc check` on good and bad `.mpc` files: output, exit status and caret diagnostics.

mod common;

/// `mpcc ARGS` from the repository root: whether it succeeded, stdout, stderr.
fn mpcc(args: &[&str]) -> (bool, String, String) {
    let (code, stdout, stderr) = common::mpcc(args);
    (code == Some(0), stdout, stderr)
}

#[test]
fn check_accepts_the_models() {
    let (ok, out, err) = mpcc(&["check", "models/quadrotor_rates.mpc"]);
    assert!(ok, "{err}");
    assert!(out.contains("nx = 10"), "{out}");
    assert!(out.contains("nu = 4"), "{out}");
    assert!(out.contains("N = 20, dt = 0.05"), "{out}");
    assert!(out.contains("instructions after CSE"), "{out}");
    assert!(out.contains("jacobian df/d(x,u): 10x14"), "{out}");
    // pdot = v: the first row of the Jacobian has exactly one entry, at v[0] (column 7).
    assert!(out.contains("p[0]  .......*......"), "{out}");
    let (ok, out, _) = mpcc(&["check", "models/quadrotor_rates.mpc", "--variant", "A"]);
    assert!(ok);
    assert!(out.contains("N = 10, dt = 0.04"), "{out}");
    let (ok, out, err) = mpcc(&["check", "models/paper_pointmass.mpc"]);
    assert!(ok, "{err}");
    assert!(
        out.contains("nx = 9") && out.contains("input rate"),
        "{out}"
    );
}

#[test]
fn check_rejects_a_bad_file_with_a_caret() {
    let dir = env!("CARGO_TARGET_TMPDIR");
    let path = format!("{dir}/bad_check.mpc");
    std::fs::write(
        &path,
        "model bad;\nstate x;\ncontrol u;\ndynamics ode euler { der(x) = u * speed; }\nhorizon N = 5, dt = 0.1;\n",
    )
    .unwrap();
    let (ok, out, err) = mpcc(&["check", &path]);
    assert!(!ok, "{out}");
    assert!(err.contains("unknown name `speed`"), "{err}");
    assert!(err.contains("bad_check.mpc:4:35"), "{err}");
    assert!(
        err.contains("dynamics ode euler { der(x) = u * speed; }"),
        "{err}"
    );
    assert!(err.contains('^'), "{err}");
    let (ok, _, err) = mpcc(&["check", "no/such/file.mpc"]);
    assert!(!ok);
    assert!(err.contains("cannot read"), "{err}");
}

#[test]
fn check_describes_an_implicit_integrator_and_locates_its_errors() {
    let (ok, out, err) = mpcc(&["check", "models/stiff_actuator.mpc"]);
    assert!(ok, "{err}");
    assert!(
        out.contains("irk (Gauss-Legendre) with 2 stage(s), 4 substep(s), 3 Newton iteration(s)"),
        "{out}"
    );
    assert!(
        out.contains("discrete map F(x,u,p) over dt: implicit (irk)"),
        "{out}"
    );
    assert!(out.contains("jacobian df/d(x,u): 3x4"), "{out}");
    let dir = env!("CARGO_TARGET_TMPDIR");
    let path = format!("{dir}/bad_irk.mpc");
    std::fs::write(
        &path,
        "model bad;\nstate x;\ncontrol u;\ndynamics ode irk(stages = 5) { der(x) = u; }\n\
         horizon N = 5, dt = 0.1;\ncost { Q = diag(1); R = diag(1); }\n",
    )
    .unwrap();
    let (ok, out, err) = mpcc(&["check", &path]);
    assert!(!ok, "{out}");
    assert!(err.contains("irk with 5 stages"), "{err}");
    assert!(err.contains("bad_irk.mpc:4:14"), "{err}");
}
