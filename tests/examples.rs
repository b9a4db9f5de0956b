//! The example models beyond the paper's (`docs/examples.md`): the cart-pole swing-up
//! (`models/cartpole.mpc`), the kinematic bicycle passing an obstacle (`models/bicycle.mpc`)
//! and the planar quadrotor (`models/planar_quadrotor.mpc`), through their checked-in
//! generated crates.
//!
//! - Converged solutions: `solve_sqp` from the models' start and first guess against IPOPT's
//!   solution of the same problem written independently in CasADi
//!   (`benches/peers/examples_casadi.py`, which wrote `benches/peers/examples/*.csv`), to
//!   1e-6 over every state and control of the horizon. The offline solve raises the SQP's
//!   iteration limit and tightens its stopping tolerances (`sqp_settings`); nothing else.
//! - Closed loops with the generated defaults (`Solver::new()`, settings untouched): the
//!   plant is the model's ODE integrated by RK4 with 10 substeps per interval, here in the
//!   test; every step's status must be `Ok` and the maneuver must succeed. The same loops
//!   with the shift off are the evidence for its default (on): the cart-pole then fails,
//!   the other two fly either way.
//! - The checked-in crates are what the generator makes of the model files.
//!
//! `cargo test --test examples -- --nocapture` prints the deviations from IPOPT and the
//! closed loops' figures.

use std::path::{Path, PathBuf};

use mpc_runtime::{RtiSettings, RtiStatus};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// IPOPT's converged trajectory: row `k` holds `x_k` and (for `k < N`) `u_k`.
struct Reference {
    x: Vec<Vec<f64>>,
    u: Vec<Vec<f64>>,
}

fn reference(name: &str, nx: usize, nu: usize) -> Reference {
    let path = root()
        .join("benches/peers/examples")
        .join(format!("{name}_ipopt.csv"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    assert_eq!(header.len(), 1 + nx + nu, "{name}: columns {header:?}");
    let (mut x, mut u) = (Vec::new(), Vec::new());
    for (k, line) in lines.enumerate() {
        let v: Vec<f64> = line
            .split(',')
            .map(|s| s.parse().expect("a number"))
            .collect();
        assert_eq!(v[0], k as f64, "{name}: row {k}");
        x.push(v[1..=nx].to_vec());
        if v.len() == 1 + nx + nu {
            u.push(v[1 + nx..].to_vec());
        } else {
            assert_eq!(v.len(), 1 + nx, "{name}: row {k}");
        }
    }
    assert_eq!(x.len(), u.len() + 1, "{name}: the last row holds x_N only");
    Reference { x, u }
}

/// The largest deviation of a solver's plan from IPOPT's, over every `x_k` and `u_k`.
fn max_deviation(
    r: &Reference,
    state: impl Fn(usize) -> Option<Vec<f64>>,
    control: impl Fn(usize) -> Option<Vec<f64>>,
) -> f64 {
    let mut worst = 0.0_f64;
    for (k, xr) in r.x.iter().enumerate() {
        let x = state(k).expect("a state");
        worst = xr
            .iter()
            .zip(&x)
            .fold(worst, |m, (a, b)| m.max((a - b).abs()));
    }
    for (k, ur) in r.u.iter().enumerate() {
        let u = control(k).expect("a control");
        worst = ur
            .iter()
            .zip(&u)
            .fold(worst, |m, (a, b)| m.max((a - b).abs()));
    }
    worst
}

/// Settings of the offline solve: the defaults, with room for Gauss-Newton's linear
/// convergence on these nonlinear problems and a stop well below the 1e-6 compared.
fn sqp_settings(s: &mut RtiSettings<f64>) {
    s.sqp_max_iter = 1000;
    s.sqp_tol = 1e-11;
    s.sqp_kkt_tol = 1e-10;
}

/// Classical RK4 of `f` over `dt` in `substeps` equal steps (the plant).
fn rk4<const NX: usize>(
    f: impl Fn(&[f64; NX]) -> [f64; NX],
    x: &[f64; NX],
    dt: f64,
    substeps: usize,
) -> [f64; NX] {
    let h = dt / substeps as f64;
    let add = |x: &[f64; NX], k: &[f64; NX], c: f64| std::array::from_fn(|i| x[i] + c * k[i]);
    let mut x = *x;
    for _ in 0..substeps {
        let k1 = f(&x);
        let k2 = f(&add(&x, &k1, h / 2.0));
        let k3 = f(&add(&x, &k2, h / 2.0));
        let k4 = f(&add(&x, &k3, h));
        x = std::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
    }
    x
}

const PLANT_SUBSTEPS: usize = 10;
const CLOSED_LOOP_STEPS: usize = 300;

// ---------------------------------------------------------------------------------------
// Cart-pole

/// `models/cartpole.mpc`'s ODE, `x = [s, theta, ds, dtheta]`.
fn cartpole_ode(x: &[f64; 4], force: f64) -> [f64; 4] {
    let (g, mc, mp, l) = (9.81, 0.5, 0.2, 0.5);
    let (st, ct) = x[1].sin_cos();
    let d = mc + mp * st * st;
    let dds = (force + mp * st * (l * x[3] * x[3] + g * ct)) / d;
    let ddth = (-force * ct - mp * l * x[3] * x[3] * st * ct - (mc + mp) * g * st) / (l * d);
    [x[2], x[3], dds, ddth]
}

#[test]
fn cartpole_converges_to_ipopt() {
    let r = reference("cartpole", 4, 1);
    let mut s = Box::new(cartpole::Solver::new());
    sqp_settings(s.settings_mut());
    s.set_x0(&[0.0; 4]).unwrap();
    let info = s.solve_sqp();
    let dev = max_deviation(
        &r,
        |k| s.state(k).map(|x| x.to_vec()),
        |k| s.control(k).map(|u| u.to_vec()),
    );
    let s_min = (0..=cartpole::N)
        .map(|k| s.state(k).unwrap()[0])
        .fold(f64::INFINITY, f64::min);
    println!(
        "cartpole: solve_sqp {:?} after {} iterations, max |mpcc - IPOPT| over x_k, u_k = \
         {dev:.2e}; smallest cart position {s_min:.9} m",
        info.status, info.sqp_iterations
    );
    assert_eq!(info.status, RtiStatus::Ok);
    assert!(dev < 1e-6, "{dev:e}");
    // The rail's bound is active: the plan runs into it.
    assert!((s_min + 1.5).abs() < 1e-8, "{s_min}");
}

/// What a closed loop did.
#[derive(Debug)]
struct Outcome {
    /// Steps whose feedback was not `Ok`, and the first of them.
    not_ok: usize,
    first_not_ok: Option<usize>,
    /// The plant's states, `x_0` to `x_STEPS`.
    xs: Vec<Vec<f64>>,
}

fn cartpole_loop(settings: RtiSettings<f64>, sqp_first: bool) -> Outcome {
    let mut s = Box::new(cartpole::Solver::new());
    *s.settings_mut() = settings;
    let mut x = [0.0; 4];
    if sqp_first {
        s.set_x0(&x).unwrap();
        // The default 50 iterations leave it short of convergence: a plan to start from.
        let info = s.solve_sqp();
        assert!(
            matches!(info.status, RtiStatus::Ok | RtiStatus::MaxIterations),
            "{info:?}"
        );
    }
    let mut out = Outcome {
        not_ok: 0,
        first_not_ok: None,
        xs: vec![x.to_vec()],
    };
    for step in 0..CLOSED_LOOP_STEPS {
        s.prepare();
        s.set_x0(&x).unwrap();
        let info = s.feedback();
        if info.status != RtiStatus::Ok {
            out.not_ok += 1;
            out.first_not_ok.get_or_insert(step);
        }
        let force = s.u0()[0];
        assert!(force.abs() <= 10.0 + 1e-9, "step {step}: force {force}");
        x = rk4(|x| cartpole_ode(x, force), &x, cartpole::DT, PLANT_SUBSTEPS);
        out.xs.push(x.to_vec());
    }
    out
}

/// The cart-pole's maneuver: the first step from which the pole stays within 0.05 rad of
/// upright (modulo full turns), and the largest |s| on the way.
fn cartpole_summary(o: &Outcome) -> (Option<usize>, f64) {
    let mut since = None;
    for (k, x) in o.xs.iter().enumerate() {
        let off = x[1].rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        if off.abs() < 0.05 {
            since.get_or_insert(k);
        } else {
            since = None;
        }
    }
    let s_max = o.xs.iter().fold(0.0_f64, |m, x| m.max(x[0].abs()));
    (since, s_max)
}

// ---------------------------------------------------------------------------------------
// Bicycle

const BIKE_SPEED: f64 = 3.0;
const BIKE_GOAL: f64 = 20.0;

/// The reference the bicycle follows (also `benches/peers/examples_casadi.py`'s): along the
/// x axis at 3 m/s to the goal, then at rest there.
fn bicycle_ref(t: f64) -> [f64; 4] {
    if BIKE_SPEED * t < BIKE_GOAL {
        [BIKE_SPEED * t, 0.0, 0.0, BIKE_SPEED]
    } else {
        [BIKE_GOAL, 0.0, 0.0, 0.0]
    }
}

/// `models/bicycle.mpc`'s ODE, `x = [px, py, psi, v]`, `u = [a, delta]`.
fn bicycle_ode(x: &[f64; 4], u: &[f64; 2]) -> [f64; 4] {
    let l = 2.5;
    [
        x[3] * x[2].cos(),
        x[3] * x[2].sin(),
        x[3] * u[1].tan() / l,
        u[0],
    ]
}

/// The bicycle's references for the horizon starting at `t`.
fn set_bicycle_refs(s: &mut bicycle::Solver, t: f64) {
    for k in 0..=bicycle::N {
        s.set_xref(k, &bicycle_ref(t + k as f64 * bicycle::DT))
            .unwrap();
    }
}

/// The default obstacle (`models/bicycle.mpc`): centre and radius.
const OBSTACLE: ([f64; 2], f64) = ([6.0, -0.3], 1.0);

fn clearance(x: &[f64]) -> f64 {
    let ([ox, oy], r) = OBSTACLE;
    (x[0] - ox).hypot(x[1] - oy) - r
}

fn bicycle_loop(settings: RtiSettings<f64>) -> Outcome {
    let mut s = Box::new(bicycle::Solver::new());
    *s.settings_mut() = settings;
    let mut x = [0.0, 0.0, 0.0, BIKE_SPEED];
    let mut out = Outcome {
        not_ok: 0,
        first_not_ok: None,
        xs: vec![x.to_vec()],
    };
    for step in 0..CLOSED_LOOP_STEPS {
        set_bicycle_refs(&mut s, step as f64 * bicycle::DT);
        s.prepare();
        s.set_x0(&x).unwrap();
        let info = s.feedback();
        if info.status != RtiStatus::Ok {
            out.not_ok += 1;
            out.first_not_ok.get_or_insert(step);
        }
        let u = s.u0();
        assert!(
            u[0].abs() <= 3.0 + 1e-9 && u[1].abs() <= 0.5 + 1e-9,
            "step {step}: {u:?}"
        );
        x = rk4(|x| bicycle_ode(x, &u), &x, bicycle::DT, PLANT_SUBSTEPS);
        out.xs.push(x.to_vec());
    }
    out
}

// ---------------------------------------------------------------------------------------
// Planar quadrotor

const QUAD_TARGET: [f64; 2] = [2.0, 1.0];

/// `models/planar_quadrotor.mpc`'s ODE, `x = [y, z, phi, vy, vz, omega]`, `u = [f1, f2]`.
fn quad_ode(x: &[f64; 6], u: &[f64; 2]) -> [f64; 6] {
    let (g, m, l, j) = (9.81, 1.0, 0.2, 0.01);
    let thrust = u[0] + u[1];
    [
        x[3],
        x[4],
        x[5],
        -thrust * x[2].sin() / m,
        thrust * x[2].cos() / m - g,
        (u[1] - u[0]) * l / j,
    ]
}

fn target_distance(x: &[f64]) -> f64 {
    (x[0] - QUAD_TARGET[0]).hypot(x[1] - QUAD_TARGET[1])
}

/// A closed loop of the planar quadrotor, and each step's distance of the plan's last state
/// from the target (the terminal constraint: at most 0.01 m).
fn quad_loop(settings: RtiSettings<f64>) -> (Outcome, Vec<f64>) {
    let mut s = Box::new(planar_quadrotor::Solver::new());
    *s.settings_mut() = settings;
    let mut x = [0.0; 6];
    let mut out = Outcome {
        not_ok: 0,
        first_not_ok: None,
        xs: vec![x.to_vec()],
    };
    let mut terminal = Vec::new();
    for step in 0..CLOSED_LOOP_STEPS {
        s.prepare();
        s.set_x0(&x).unwrap();
        let info = s.feedback();
        if info.status != RtiStatus::Ok {
            out.not_ok += 1;
            out.first_not_ok.get_or_insert(step);
        }
        terminal.push(target_distance(&s.state(planar_quadrotor::N).unwrap()));
        let u = s.u0();
        assert!(
            u.iter().all(|f| (-1e-9..=8.0 + 1e-9).contains(f)),
            "step {step}: {u:?}"
        );
        x = rk4(
            |x| quad_ode(x, &u),
            &x,
            planar_quadrotor::DT,
            PLANT_SUBSTEPS,
        );
        out.xs.push(x.to_vec());
    }
    (out, terminal)
}

// ---------------------------------------------------------------------------------------
// Converged solutions against IPOPT

#[test]
fn bicycle_converges_to_ipopt() {
    let r = reference("bicycle", 4, 2);
    let mut s = Box::new(bicycle::Solver::new());
    sqp_settings(s.settings_mut());
    set_bicycle_refs(&mut s, 0.0);
    s.set_x0(&[0.0, 0.0, 0.0, BIKE_SPEED]).unwrap();
    let info = s.solve_sqp();
    let dev = max_deviation(
        &r,
        |k| s.state(k).map(|x| x.to_vec()),
        |k| s.control(k).map(|u| u.to_vec()),
    );
    let min_clearance = (0..bicycle::N)
        .map(|k| clearance(&s.state(k).unwrap()))
        .fold(f64::INFINITY, f64::min);
    println!(
        "bicycle: solve_sqp {:?} after {} iterations, max |mpcc - IPOPT| over x_k, u_k = \
         {dev:.2e}; smallest clearance of the plan {min_clearance:.2e} m",
        info.status, info.sqp_iterations
    );
    assert_eq!(info.status, RtiStatus::Ok);
    assert!(dev < 1e-6, "{dev:e}");
    // The soft constraint is active (the plan touches the circle) and met: l1 is exact.
    assert!(min_clearance.abs() < 1e-6, "{min_clearance:e}");
}

#[test]
fn planar_quadrotor_converges_to_ipopt() {
    let r = reference("planar_quadrotor", 6, 2);
    let mut s = Box::new(planar_quadrotor::Solver::new());
    sqp_settings(s.settings_mut());
    s.set_x0(&[0.0; 6]).unwrap();
    let info = s.solve_sqp();
    let dev = max_deviation(
        &r,
        |k| s.state(k).map(|x| x.to_vec()),
        |k| s.control(k).map(|u| u.to_vec()),
    );
    let terminal = target_distance(&s.state(planar_quadrotor::N).unwrap());
    println!(
        "planar_quadrotor: solve_sqp {:?} after {} iterations, max |mpcc - IPOPT| over x_k, \
         u_k = {dev:.2e}; |p_N - target| = {terminal:.6} m",
        info.status, info.sqp_iterations
    );
    assert_eq!(info.status, RtiStatus::Ok);
    assert!(dev < 1e-6, "{dev:e}");
    // The terminal constraint is active: the plan ends on the 1 cm ball.
    assert!((terminal - 0.01).abs() < 1e-8, "{terminal}");
}

// ---------------------------------------------------------------------------------------
// Closed loops

/// The pure real-time iteration from the model's first guess, with the generated settings
/// (the shift on, the runtime's default).
#[test]
fn cartpole_closed_loop_with_default_settings() {
    let o = cartpole_loop(cartpole::default_settings(), false);
    check_cartpole(&o, "default settings");
}

/// Why the shift is on by default: without it the swing-up's QPs become infeasible and the
/// pole spins (the other examples fly either way, below).
#[test]
fn cartpole_closed_loop_without_the_shift_fails() {
    let settings = RtiSettings {
        shift: false,
        ..cartpole::default_settings()
    };
    let o = cartpole_loop(settings, false);
    let (since, s_max) = cartpole_summary(&o);
    println!(
        "cartpole closed loop (shift off): {} of {CLOSED_LOOP_STEPS} steps not Ok (first: \
         {:?}); upright from step {since:?}; max |s| = {s_max:.3} m",
        o.not_ok, o.first_not_ok
    );
    assert!(
        o.not_ok > 0 && s_max > 1.5,
        "the shift no longer matters here"
    );
}

/// Default settings, the real-time iteration started from a plan of `solve_sqp` (its
/// default 50 iterations) instead of the first guess.
#[test]
fn cartpole_closed_loop_from_a_plan_with_default_settings() {
    let o = cartpole_loop(cartpole::default_settings(), true);
    check_cartpole(&o, "default settings, started from solve_sqp");
}

fn check_cartpole(o: &Outcome, what: &str) {
    let (since, s_max) = cartpole_summary(o);
    let x = o.xs.last().unwrap();
    println!(
        "cartpole closed loop ({what}): {} of {CLOSED_LOOP_STEPS} steps not Ok (first: \
         {:?}); upright (|theta - pi| < 0.05) from step {since:?} on; max |s| = {s_max:.3} m; \
         final x = {x:?}",
        o.not_ok, o.first_not_ok
    );
    assert_eq!(o.not_ok, 0, "first at step {:?}", o.first_not_ok);
    let since = since.expect("the pole ends upright");
    assert!(since <= 100, "upright only from step {since}");
    assert!(s_max <= 1.5 + 1e-2, "the cart left the rail: {s_max}");
    assert!(
        x.iter()
            .all(|e| e.abs() < 1e-3 || (e - std::f64::consts::PI).abs() < 1e-3)
    );
}

#[test]
fn bicycle_closed_loop_with_default_settings() {
    check_bicycle(
        &bicycle_loop(bicycle::default_settings()),
        "default settings",
    );
}

#[test]
fn bicycle_closed_loop_without_the_shift() {
    let settings = RtiSettings {
        shift: false,
        ..bicycle::default_settings()
    };
    check_bicycle(&bicycle_loop(settings), "shift off");
}

fn check_bicycle(o: &Outcome, what: &str) {
    let min_clearance =
        o.xs.iter()
            .map(|x| clearance(x))
            .fold(f64::INFINITY, f64::min);
    let x = o.xs.last().unwrap();
    let passed = o.xs.iter().position(|x| x[0] > OBSTACLE.0[0]);
    println!(
        "bicycle closed loop ({what}): {} of {CLOSED_LOOP_STEPS} steps not Ok; \
         smallest clearance {min_clearance:.4} m; past the obstacle's centre at step \
         {passed:?}; final x = {x:.4?}",
        o.not_ok
    );
    assert_eq!(o.not_ok, 0, "first at step {:?}", o.first_not_ok);
    // The soft constraint may be entered by what the plant and the real-time iteration's
    // one step per sample leave: 1 cm.
    assert!(min_clearance > -0.01, "{min_clearance}");
    assert!(passed.is_some_and(|k| k < 40), "{passed:?}");
    assert!((x[0] - BIKE_GOAL).abs() < 0.1 && x[1].abs() < 0.01, "{x:?}");
    assert!(x[2].abs() < 0.01 && x[3].abs() < 1e-3, "{x:?}");
}

#[test]
fn planar_quadrotor_closed_loop_with_default_settings() {
    let (o, terminal) = quad_loop(planar_quadrotor::default_settings());
    check_quad(&o, &terminal, "default settings");
}

#[test]
fn planar_quadrotor_closed_loop_without_the_shift() {
    let settings = RtiSettings {
        shift: false,
        ..planar_quadrotor::default_settings()
    };
    let (o, terminal) = quad_loop(settings);
    check_quad(&o, &terminal, "shift off");
}

fn check_quad(o: &Outcome, terminal: &[f64], what: &str) {
    let x = o.xs.last().unwrap();
    let arrived = o.xs.iter().position(|x| target_distance(x) < 0.01);
    let late = terminal[5..].iter().fold(0.0_f64, |m, &d| m.max(d));
    println!(
        "planar_quadrotor closed loop ({what}): {} of {CLOSED_LOOP_STEPS} steps not \
         Ok; within 1 cm of the target from step {arrived:?}; plans' |p_N - target| at most \
         {:.4} m (first step), {late:.5} m from step 5; final x = {x:?}",
        o.not_ok, terminal[0]
    );
    assert_eq!(o.not_ok, 0, "first at step {:?}", o.first_not_ok);
    assert!(arrived.is_some_and(|k| k <= 60), "{arrived:?}");
    assert!(late <= 0.01 + 1e-3, "{late}");
    assert!(
        target_distance(x) < 1e-4 && x[2..].iter().all(|e| e.abs() < 1e-3),
        "{x:?}"
    );
}

/// The checked-in crates are what the generator makes of the model files
/// (`generated/README.md` has the commands).
#[test]
fn the_example_crates_are_current() {
    let opts = mpc_codegen::Options {
        runtime: mpc_codegen::RuntimeDep::Path("../../runtime".into()),
        ..mpc_codegen::Options::new()
    };
    for name in ["cartpole", "bicycle", "planar_quadrotor"] {
        let model = root().join("models").join(format!("{name}.mpc"));
        let generated = mpc_codegen::generate_file(&model, None, &opts)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let stale = generated.check(&root().join("generated").join(name));
        assert!(
            stale.is_empty(),
            "generated/{name}: {stale:?} differ; regenerate with \
             `cargo run -- build models/{name}.mpc --runtime-path ../../runtime -o generated/{name}`"
        );
    }
}
