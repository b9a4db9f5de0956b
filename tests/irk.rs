//! The implicit integrator (`dynamics ode irk(...)`) on the stiff example
//! `models/stiff_actuator.mpc` and its checked-in crate `generated/stiff_actuator`:
//!
//! - the generated step against scipy's Radau at `rtol = atol = 1e-12`
//!   (`benches/peers/examples/stiff_actuator_radau.csv`, written by
//!   `benches/peers/irk_radau.py`), one interval and a 30-interval trajectory; RK4 at the same
//!   interval and substeps, from the same file with `irk(...)` replaced by `rk4(4)`, diverges;
//! - the order of Gauss-Legendre collocation with 1, 2 and 3 stages (the error ratio when the
//!   step is halved) against the same reference, through the runtime's step on this test's
//!   own copy of the ODE;
//! - Radau IIA at one substep damping the actuator's transient more than Gauss-Legendre;
//! - the step's sensitivities `A`, `B` against central finite differences of the generated
//!   step itself;
//! - a converged `solve_sqp` and an RTI closed loop on the generated solver, with the plant
//!   integrated by the runtime's step at 3 stages and 20 substeps;
//! - the f32 crate: the same step to 1e-3, and the closed loop;
//! - the exact Hessian refused with a typed error (no second-order sensitivities);
//! - the checked-in crates are what the generator writes now.

use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};
use mpc_runtime::RtiStatus;
use mpc_runtime::implicit::{GAUSS_LEGENDRE, Irk, RADAU_IIA, Tableau, irk_step};
use mpc_runtime::nalgebra::{SMatrix, SVector};
use stiff_actuator::{NP, NU, NX, Solver, functions};

const SRC: &str = include_str!("../models/stiff_actuator.mpc");
const CSV: &str = include_str!("../benches/peers/examples/stiff_actuator_radau.csv");
const DT: f64 = 0.05;

/// One row of the Radau reference.
struct Row {
    kind: String,
    x0: [f64; 3],
    u: f64,
    x1: [f64; 3],
}

fn reference() -> Vec<Row> {
    let mut rows = Vec::new();
    for line in CSV.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let v: Vec<f64> = f[2..].iter().map(|s| s.parse().unwrap()).collect();
        assert_eq!(v[4], DT, "{line}");
        rows.push(Row {
            kind: f[0].to_string(),
            x0: [v[0], v[1], v[2]],
            u: v[3],
            x1: [v[5], v[6], v[7]],
        });
    }
    assert_eq!(rows.len(), 34);
    rows
}

/// The model's ODE, written again (as in `benches/peers/irk_radau.py`), with its Jacobians.
fn ode(
    x: &SVector<f64, 3>,
    u: f64,
    fx: &mut SMatrix<f64, 3, 3>,
    fu: &mut SMatrix<f64, 3, 1>,
) -> SVector<f64, 3> {
    let (m, k, k3, c, tau) = (1.0, 4.0, 2.0, 0.4, 0.004);
    let (s, v, f) = (x[0], x[1], x[2]);
    *fx = SMatrix::<f64, 3, 3>::new(
        0.0,
        1.0,
        0.0,
        (-k - 3.0 * k3 * s * s) / m,
        -c / m,
        1.0 / m,
        0.0,
        0.0,
        -1.0 / tau,
    );
    *fu = SMatrix::<f64, 3, 1>::new(0.0, 0.0, 1.0 / tau);
    SVector::<f64, 3>::new(v, (f - k * s - k3 * s * s * s - c * v) / m, (u - f) / tau)
}

/// The runtime's implicit step on [`ode`] with `stages` and `steps` (Newton to convergence).
fn runtime_step(stages: usize, steps: usize, x: [f64; 3], u: f64) -> [f64; 3] {
    runtime_step_with(&GAUSS_LEGENDRE, stages, steps, x, u)
}

/// [`runtime_step`] with the given family of tableaus.
fn runtime_step_with(
    tables: &'static [Tableau; 3],
    stages: usize,
    steps: usize,
    x: [f64; 3],
    u: f64,
) -> [f64; 3] {
    let irk = Irk {
        tableau: &tables[stages - 1],
        steps,
        newton: 8,
        dt: DT,
    };
    let mut f = |x: &SVector<f64, 3>, fx: &mut SMatrix<f64, 3, 3>, fu: &mut SMatrix<f64, 3, 1>| {
        ode(x, u, fx, fu)
    };
    let x = SVector::from(x);
    let xn = match stages {
        1 => irk_step::<f64, 3, 1, 3, _>(&irk, &x, &mut f, None),
        2 => irk_step::<f64, 3, 1, 6, _>(&irk, &x, &mut f, None),
        _ => irk_step::<f64, 3, 1, 9, _>(&irk, &x, &mut f, None),
    };
    xn.expect("the step succeeds").into()
}

fn max_err(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

const P: [f64; NP] = [1.0];

fn generated_value(x: [f64; 3], u: f64) -> [f64; 3] {
    let v = functions::dynamics_value(&SVector::from(x), &SVector::from([u]), &SVector::from(P));
    v.into()
}

#[test]
fn the_generated_step_matches_radau_and_rk4_diverges() {
    let rows = reference();
    let mut worst_step = 0.0_f64;
    for r in rows.iter().filter(|r| r.kind == "step") {
        worst_step = worst_step.max(max_err(&generated_value(r.x0, r.u), &r.x1));
    }
    // The trajectory: the generated step chained from rest under the reference's controls.
    let (mut x, mut worst_traj) = ([0.0; 3], 0.0_f64);
    for r in rows.iter().filter(|r| r.kind == "traj") {
        x = generated_value(x, r.u);
        worst_traj = worst_traj.max(max_err(&x, &r.x1));
    }
    // RK4 with the same substeps, from the same model text: the interpreter on the
    // expanded map, chained the same way.
    let rk4_src = SRC.replace("irk(stages = 2, steps = 4, newton = 3)", "rk4(4)");
    assert_ne!(rk4_src, SRC);
    let g = Graph::new();
    let ocp = parse(&g, &rk4_src, &ParseOptions::default()).unwrap().ocp;
    let map = ocp.discrete_map().unwrap();
    let syms: Vec<_> = ocp
        .x()
        .iter()
        .chain(ocp.u().iter())
        .chain(ocp.p().iter())
        .copied()
        .collect();
    let (mut xr, mut rk4_max) = ([0.0; 3], 0.0_f64);
    for r in rows.iter().filter(|r| r.kind == "traj") {
        let vals = [xr[0], xr[1], xr[2], r.u, P[0]];
        let b: Vec<_> = syms.iter().copied().zip(vals).collect();
        let next = g.eval(&map, &b).unwrap();
        xr = [next[0], next[1], next[2]];
        rk4_max = rk4_max.max(max_err(&xr, &r.x1));
    }
    println!(
        "max |irk - Radau|: one step {worst_step:.3e}, 30 steps {worst_traj:.3e}; \
         rk4(4): {rk4_max:.3e}"
    );
    assert!(worst_step < 1e-3, "{worst_step}");
    assert!(worst_traj < 1e-3, "{worst_traj}");
    let blown_up = rk4_max > 1e3 || xr.iter().any(|v| !v.is_finite());
    assert!(blown_up, "RK4 did not diverge: {rk4_max}, {xr:?}");
}

#[test]
fn gauss_legendre_has_order_two_s() {
    // One interval from each `step` row, 32 to 256 substeps (h |lambda| from 0.39 down, the
    // asymptotic range): the error must fall by about 2^(2s) per halving.
    let rows = reference();
    for stages in 1..=3 {
        let mut ratios = Vec::new();
        let err = |steps: usize| {
            rows.iter()
                .filter(|r| r.kind == "step")
                .map(|r| max_err(&runtime_step(stages, steps, r.x0, r.u), &r.x1))
                .fold(0.0, f64::max)
        };
        let range: &[usize] = if stages == 3 {
            &[4, 8, 16]
        } else {
            &[32, 64, 128]
        };
        let mut prev = err(range[0]);
        for &steps in &range[1..] {
            let e = err(steps);
            ratios.push(prev / e);
            prev = e;
        }
        println!("stages {stages}: error ratios per halving {ratios:.2?} (last error {prev:.2e})");
        let expect = f64::powi(2.0, 2 * stages as i32);
        for r in ratios {
            assert!(
                r > 0.8 * expect && r < 1.25 * expect,
                "stages {stages}: {r} vs {expect}"
            );
        }
    }
}

#[test]
fn radau_iia_damps_the_actuator_transient_in_one_substep() {
    // One substep per interval (dt / tau = 12.5): what is left of the actuator's transient
    // after a step is the stability function at -12.5 (the flow: 4e-6). Gauss-Legendre's
    // tends to (-1)^s (1, 2, 3 stages: -0.72, 0.38, -0.15), Radau IIA's (L-stable) to 0
    // (0.074, -0.090, 0.059).
    let rows = reference();
    for stages in 1..=3 {
        let err = |tables| {
            (rows.iter().filter(|r| r.kind == "step"))
                .map(|r| max_err(&runtime_step_with(tables, stages, 1, r.x0, r.u), &r.x1))
                .fold(0.0, f64::max)
        };
        let (radau, gauss) = (err(&RADAU_IIA), err(&GAUSS_LEGENDRE));
        println!(
            "{stages} stage(s), 1 substep: max |step - Radau|: Radau IIA {radau:.2e}, Gauss-Legendre {gauss:.2e}"
        );
        assert!(radau < 0.5 * gauss, "{stages}: {radau} against {gauss}");
    }
}

#[test]
fn the_sensitivities_match_central_differences_of_the_step() {
    let x0 = [0.7, -0.4, 5.0];
    let u0 = [12.0];
    let (mut a, mut b) = (
        SMatrix::<f64, NX, NX>::zeros(),
        SMatrix::<f64, NX, NU>::zeros(),
    );
    let p = SVector::from(P);
    let f0 = functions::dynamics(&SVector::from(x0), &SVector::from(u0), &p, &mut a, &mut b);
    assert_eq!(
        f0,
        functions::dynamics_value(&SVector::from(x0), &SVector::from(u0), &p)
    );
    let mut worst = 0.0_f64;
    for j in 0..NX + NU {
        let h = 1e-6 * (1.0 + if j < NX { x0[j].abs() } else { u0[0].abs() });
        let (mut xp, mut xm, mut up, mut um) = (x0, x0, u0, u0);
        if j < NX {
            xp[j] += h;
            xm[j] -= h;
        } else {
            up[0] += h;
            um[0] -= h;
        }
        let fp = functions::dynamics_value(&SVector::from(xp), &SVector::from(up), &p);
        let fm = functions::dynamics_value(&SVector::from(xm), &SVector::from(um), &p);
        for i in 0..NX {
            let fd = (fp[i] - fm[i]) / (2.0 * h);
            let exact = if j < NX { a[(i, j)] } else { b[(i, j - NX)] };
            let rel = (fd - exact).abs() / (1.0 + exact.abs());
            worst = worst.max(rel);
        }
    }
    println!("max relative |[A B] - central differences|: {worst:.2e}");
    assert!(worst < 1e-6, "{worst}");
}

/// The plant: the runtime's step with 3 stages and 20 substeps (Radau-accurate to 1e-9 here).
fn plant(x: [f64; 3], u: f64) -> [f64; 3] {
    runtime_step(3, 20, x, u)
}

#[test]
fn solve_sqp_converges_and_the_closed_loop_reaches_the_target() {
    let mut s = Solver::new();
    s.set_x0(&[0.0, 0.0, 0.0]).unwrap();
    let info = s.solve_sqp();
    println!(
        "solve_sqp: {:?} after {} iterations",
        info.status, info.sqp_iterations
    );
    assert_eq!(info.status, RtiStatus::Ok);
    // The converged plan is dynamically consistent: each state the plant's from the last.
    for k in 0..stiff_actuator::N {
        let (x, u) = (s.state(k).unwrap(), s.control(k).unwrap());
        let next = s.state(k + 1).unwrap();
        assert!(max_err(&plant(x, u[0]), &next) < 1e-3, "stage {k}");
    }
    let mut s = Solver::new();
    let mut x = [0.0; 3];
    for _ in 0..60 {
        s.set_x0(&x).unwrap();
        s.prepare();
        let info = s.feedback();
        assert_eq!(info.status, RtiStatus::Ok);
        x = plant(x, s.u0()[0]);
    }
    println!("closed loop after 3 s: {x:?}");
    assert!((x[0] - 1.0).abs() < 1e-2 && x[1].abs() < 1e-2, "{x:?}");
}

#[test]
fn the_f32_crate_steps_like_the_f64_one_and_flies() {
    // f32 rounding (about 1e-7 relative) through the Newton iterations and the stiff
    // actuator's 250 1/s: the same step to 1e-4 of the reference's scale.
    let mut worst = 0.0_f64;
    for r in reference().iter().filter(|r| r.kind == "step") {
        let x = SVector::<f32, 3>::from(r.x0.map(|v| v as f32));
        let u = SVector::<f32, 1>::from([r.u as f32]);
        let v = stiff_actuator_f32::functions::dynamics_value(&x, &u, &SVector::from([1.0f32]));
        let v64 = [f64::from(v[0]), f64::from(v[1]), f64::from(v[2])];
        worst = worst.max(max_err(&v64, &r.x1));
    }
    println!("f32: max |irk - Radau| over one step {worst:.3e}");
    assert!(worst < 1e-3, "{worst}");
    let mut s = stiff_actuator_f32::Solver::new();
    let mut x = [0.0; 3];
    for _ in 0..60 {
        s.set_x0(&x.map(|v| v as f32)).unwrap();
        s.prepare();
        assert_eq!(s.feedback().status, RtiStatus::Ok);
        x = plant(x, f64::from(s.u0()[0]));
    }
    println!("f32 closed loop after 3 s: {x:?}");
    assert!((x[0] - 1.0).abs() < 1e-2 && x[1].abs() < 1e-2, "{x:?}");
}

#[test]
fn the_exact_hessian_is_refused_with_a_typed_error() {
    let g = Graph::new();
    let ocp = parse(&g, SRC, &ParseOptions::default()).unwrap().ocp;
    let opts = mpc_codegen::Options {
        exact_hessian: true,
        ..mpc_codegen::Options::new()
    };
    let e = mpc_codegen::generate(&ocp, &opts).expect_err("refused");
    assert!(
        matches!(e, mpc_codegen::CodegenError::ExactHessianWithIrk),
        "{e}"
    );
    assert!(e.to_string().contains("integrate with `rk4(k)`"), "{e}");
    // The same from the command line, with nothing written.
    let dir = std::env::temp_dir().join(format!("mpcc-irk-exact-{}", std::process::id()));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mpcc"))
        .args([
            "build",
            "models/stiff_actuator.mpc",
            "--exact-hessian",
            "-o",
        ])
        .arg(&dir)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("exact Hessian"),
        "{err}"
    );
    assert!(!dir.exists());
}

#[test]
fn the_stiff_crate_is_current() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let opts = mpc_codegen::Options {
        runtime: mpc_codegen::RuntimeDep::Path("../../runtime".into()),
        ..mpc_codegen::Options::new()
    };
    let model = root.join("models/stiff_actuator.mpc");
    let generated = mpc_codegen::generate_file(&model, None, &opts).unwrap();
    let stale = generated.check(&root.join("generated/stiff_actuator"));
    assert!(
        stale.is_empty(),
        "generated/stiff_actuator: {stale:?} differ"
    );
    let f32_opts = mpc_codegen::Options {
        scalar: mpc_codegen::Scalar::F32,
        crate_name: Some("stiff_actuator_f32".into()),
        ..opts
    };
    let generated = mpc_codegen::generate_file(&model, None, &f32_opts).unwrap();
    let stale = generated.check(&root.join("generated/stiff_actuator_f32"));
    // Regenerate with the commands of generated/README.md.
    assert!(
        stale.is_empty(),
        "generated/stiff_actuator_f32: {stale:?} differ"
    );
}
