//! The bicycle's closed loop of `tests/examples.rs` (`models/bicycle.mpc`: a reference along
//! x at 3 m/s through a circular obstacle, kept out by the soft row `clearance`), with the
//! row as built, made hard or switched off at run time; shared by the `soft_rows` example
//! (the benchmark) and `tests/soft_rows.rs`.

use std::time::Instant;

use mpc_runtime::{RtiSettings, RtiStatus};

/// Closed-loop steps (as `tests/examples.rs`).
pub const STEPS: usize = 300;
const SPEED: f64 = 3.0;
const GOAL: f64 = 20.0;
const PLANT_SUBSTEPS: usize = 10;

/// The obstacle row as the loop uses it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Row {
    /// Soft, as built (`l1 = 100`, `l2 = 1000`).
    Soft,
    /// Hard: `set_soft_penalties` with zeros.
    Hard,
    /// Switched off: `set_constraint_bounds` with `-inf..inf`.
    Off,
}

/// What a closed loop did, per step.
pub struct Run {
    /// The plant's states, from the start.
    pub xs: Vec<[f64; 4]>,
    /// Interior-point iterations and active-set solves of each step's QP.
    pub iterations: Vec<u32>,
    pub active_set_solves: Vec<u32>,
    /// Wall time of `prepare` + `feedback`, seconds.
    pub seconds: Vec<f64>,
    /// Steps whose status was not `Ok`.
    pub not_ok: usize,
}

/// The reference: along the x axis at 3 m/s to the goal, then at rest there.
fn reference(t: f64) -> [f64; 4] {
    if SPEED * t < GOAL {
        [SPEED * t, 0.0, 0.0, SPEED]
    } else {
        [GOAL, 0.0, 0.0, 0.0]
    }
}

/// `models/bicycle.mpc`'s ODE, `x = [px, py, psi, v]`, `u = [a, delta]`.
fn ode(x: &[f64; 4], u: &[f64; 2]) -> [f64; 4] {
    let l = 2.5;
    [
        x[3] * x[2].cos(),
        x[3] * x[2].sin(),
        x[3] * u[1].tan() / l,
        u[0],
    ]
}

/// Classical RK4 over `dt` in `PLANT_SUBSTEPS` steps (the plant).
fn plant(x: &[f64; 4], u: &[f64; 2], dt: f64) -> [f64; 4] {
    let h = dt / PLANT_SUBSTEPS as f64;
    let add = |x: &[f64; 4], k: &[f64; 4], c: f64| std::array::from_fn(|i| x[i] + c * k[i]);
    let mut x = *x;
    for _ in 0..PLANT_SUBSTEPS {
        let k1 = ode(&x, u);
        let k2 = ode(&add(&x, &k1, h / 2.0), u);
        let k3 = ode(&add(&x, &k2, h / 2.0), u);
        let k4 = ode(&add(&x, &k3, h), u);
        x = std::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
    }
    x
}

/// The closed loop with `settings` and the obstacle row as `row` says.
pub fn run(settings: RtiSettings<f64>, row: Row) -> Run {
    let mut s = Box::new(bicycle::Solver::new());
    *s.settings_mut() = settings;
    match row {
        Row::Soft => {}
        Row::Hard => s.set_soft_penalties(&[0.0], &[0.0]).unwrap(),
        Row::Off => s
            .set_constraint_bounds(&[f64::NEG_INFINITY], &[f64::INFINITY])
            .unwrap(),
    }
    let mut x = [0.0, 0.0, 0.0, SPEED];
    let mut out = Run {
        xs: vec![x],
        iterations: Vec::new(),
        active_set_solves: Vec::new(),
        seconds: Vec::new(),
        not_ok: 0,
    };
    for step in 0..STEPS {
        let t = step as f64 * bicycle::DT;
        for k in 0..=bicycle::N {
            s.set_xref(k, &reference(t + k as f64 * bicycle::DT))
                .unwrap();
        }
        let start = Instant::now();
        s.prepare();
        s.set_x0(&x).unwrap();
        let info = s.feedback();
        out.seconds.push(start.elapsed().as_secs_f64());
        out.not_ok += usize::from(info.status != RtiStatus::Ok);
        out.iterations.push(info.qp.iterations);
        out.active_set_solves.push(info.qp.active_set_solves);
        x = plant(&x, &s.u0(), bicycle::DT);
        out.xs.push(x);
    }
    out
}
