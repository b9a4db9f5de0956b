//! The two outer-loop architectures, both on solvers generated from the paper's models
//! (`mpc-models`).
//!
//! - [`PaperController`] ("paper"): the paper's point-mass MPC (`paper_pointmass`: position,
//!   velocity, acceleration, jerk input, N = 10, dt = 0.04) plans an acceleration; the inner
//!   attitude loop turns it into a thrust vector f = m (a + g e3), the desired attitude Rd from
//!   b3d = f/|f| and the heading (Lee's construction), and a body-rate command
//!   Omega = -(2/tau) eR + Omega_ref with eR = 1/2 (Rd' R - R' Rd)^vee (the paper prints
//!   Omega = (2/tau) eR; with this definition of eR the stabilizing sign is negative). In the
//!   flip the body-rate reference drives the vehicle directly (5*pi rad/s pitch) with the
//!   flip's collective thrust, as in the paper; the MPC keeps running on the flip's reference
//!   so it is warm when the recovery starts.
//! - [`NmpcController`] ("nmpc"): the full quaternion NMPC (`quadrotor_rates`: position,
//!   attitude quaternion, velocity; collective thrust and body rates; N = 20, dt = 0.05) flies
//!   everything, including the flip, as a reference of attitude, rates and thrust it tracks
//!   itself. Quaternion references and the measured quaternion are put in the hemisphere of
//!   the solver's own trajectory (q and -q are the same attitude; after a full turn the
//!   trajectory ends near -1).
//!
//! Both run a real-time iteration (prepare + feedback) once per model step (1/dt) and hold the
//! result in between (the model's zero-order hold). The collective thrust in newtons is
//! m_hat * c with m_hat from [`MassEstimator`] (PX4's hover-thrust estimator in another form),
//! so a heavier or lighter vehicle than nominal does not leave a steady altitude error.

use std::time::Instant;

use mpc_models::{paper_pointmass, quadrotor_rates};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::estimate::Estimate;
use crate::mission::{G, Mission, RefPoint};

/// What the outer loop hands to the rate loop at each inner step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InnerCommand {
    /// Mass-normalized collective thrust [m/s^2].
    pub thrust_c: f64,
    /// Body-rate command [rad/s].
    pub rates: Vector3<f64>,
}

/// Statistics of one outer-loop step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OuterStats {
    /// Wall-clock time of the solver (set references, prepare, feedback) \[us\].
    pub solver_us: f64,
    /// QP iterations.
    pub qp_iterations: u32,
    /// Whether the solver fell back to the previous plan.
    pub fallback: bool,
}

/// Which architecture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControllerKind {
    /// Point-mass MPC + geometric attitude + rate command.
    Paper,
    /// Full quaternion NMPC.
    Nmpc,
}

impl ControllerKind {
    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ControllerKind::Paper => "paper",
            ControllerKind::Nmpc => "nmpc",
        }
    }
}

/// An outer loop: a solver step every [`period`](Controller::period), an inner command at
/// every rate-loop step.
pub trait Controller {
    /// Outer-loop period \[s\].
    fn period(&self) -> f64;
    /// One solver step at time `t` from the estimate; the reference comes from `mission`.
    fn outer(&mut self, t: f64, est: &Estimate, mission: &Mission) -> OuterStats;
    /// The command for the rate loop at time `t` (called at the inner rate).
    fn inner(&mut self, t: f64, est: &Estimate, mission: &Mission) -> InnerCommand;
}

/// Estimates the vehicle's mass from the accelerometer (specific force along body z) and the
/// commanded collective thrust: m = T / a_z, low-pass filtered, updated only in near-level
/// flight with a clear thrust. This is the thrust mapping's integral action.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassEstimator {
    /// Current estimate \[kg\].
    pub mass: f64,
    /// Filter time constant \[s\].
    pub tau: f64,
    nominal: f64,
}

impl MassEstimator {
    /// Starts at the nominal mass.
    pub fn new(nominal: f64) -> Self {
        Self {
            mass: nominal,
            tau: 0.5,
            nominal,
        }
    }

    /// One update: `thrust` the commanded collective \[N\], `specific_z` the accelerometer's
    /// body-z specific force [m/s^2], `tilt_cos` body z . world z, `rate` the body-rate norm.
    pub fn update(&mut self, thrust: f64, specific_z: f64, tilt_cos: f64, rate: f64, dt: f64) {
        if specific_z > 3.0 && thrust > 0.0 && tilt_cos > 0.8 && rate < 1.5 && thrust.is_finite() {
            let m = (thrust / specific_z).clamp(0.5 * self.nominal, 2.0 * self.nominal);
            let k = (dt / self.tau).clamp(0.0, 1.0);
            self.mass += k * (m - self.mass);
        }
    }
}

fn quat_arr(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

fn dot4(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `q` as (w, x, y, z) with the sign that puts it nearest to `near`.
pub fn aligned(q: &UnitQuaternion<f64>, near: &[f64; 4]) -> [f64; 4] {
    let a = quat_arr(q);
    if dot4(&a, near) < 0.0 {
        a.map(|e| -e)
    } else {
        a
    }
}

fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

/// The geometric attitude law of the paper: body rates that turn `q` towards `qd` with time
/// constant `tau`: -(2/tau) eR with eR = 1/2 (Rd' R - R' Rd)^vee.
pub fn attitude_rates(q: &UnitQuaternion<f64>, qd: &UnitQuaternion<f64>, tau: f64) -> Vector3<f64> {
    let r = q.to_rotation_matrix().into_inner();
    let rd = qd.to_rotation_matrix().into_inner();
    let e = vee(&(rd.transpose() * r - r.transpose() * rd)) * 0.5;
    -e * (2.0 / tau)
}

/// Weights of the paper's point-mass MPC (diagonals of Q, P and R).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointMassWeights {
    /// Q on (position, velocity, acceleration).
    pub q: [f64; 9],
    /// P (terminal) on (position, velocity, acceleration).
    pub p: [f64; 9],
    /// R on the jerk change.
    pub r: [f64; 3],
}

impl PointMassWeights {
    /// The paper's values (the model's defaults).
    pub const PAPER: Self = Self {
        q: [50.0, 10.0, 20.0, 10.0, 20.0, 10.0, 10.0, 10.0, 10.0],
        p: [100.0, 100.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0],
        r: [1.0, 1.0, 1.0],
    };
    /// Ours, for the simulator: the paper's shape with position and velocity weighed up
    /// against acceleration, so the loop closes in well under a second.
    pub const TUNED: Self = Self {
        q: [2000.0, 2000.0, 2000.0, 200.0, 200.0, 200.0, 2.0, 2.0, 2.0],
        p: [4000.0, 4000.0, 4000.0, 400.0, 400.0, 400.0, 4.0, 4.0, 4.0],
        r: [0.01, 0.01, 0.01],
    };
}

/// The paper's architecture.
pub struct PaperController {
    solver: Box<paper_pointmass::Solver>,
    /// Attitude time constant tau \[s\].
    pub tau: f64,
    /// Collective-thrust and rate limits of the inner command.
    pub max_rate: f64,
    t_plan: f64,
    acc0: Vector3<f64>,
    jerk: Vector3<f64>,
    started: bool,
}

impl PaperController {
    /// A controller with [`PointMassWeights::TUNED`], tau = 0.12 s.
    pub fn new() -> Self {
        Self::with_weights(PointMassWeights::TUNED)
    }

    /// A controller with the given MPC weights.
    pub fn with_weights(w: PointMassWeights) -> Self {
        let mut solver = Box::new(paper_pointmass::Solver::new());
        solver.settings_mut().shift = true;
        let _ = solver.set_q_w(&w.q);
        let _ = solver.set_p_w(&w.p);
        let _ = solver.set_r_w(&w.r);
        Self {
            solver,
            tau: 0.12,
            max_rate: 20.0,
            t_plan: 0.0,
            acc0: Vector3::zeros(),
            jerk: Vector3::zeros(),
            started: false,
        }
    }

    fn xref(r: &RefPoint) -> [f64; 9] {
        [
            r.p.x, r.p.y, r.p.z, r.v.x, r.v.y, r.v.z, r.a.x, r.a.y, r.a.z,
        ]
    }
}

impl Default for PaperController {
    fn default() -> Self {
        Self::new()
    }
}

impl Controller for PaperController {
    fn period(&self) -> f64 {
        paper_pointmass::DT
    }

    fn outer(&mut self, t: f64, est: &Estimate, mission: &Mission) -> OuterStats {
        let start = Instant::now();
        let dt = paper_pointmass::DT;
        // The acceleration state: the plan's acceleration now (the commanded one); in the
        // flip the flip's own acceleration.
        let r_now = mission.reference(t);
        let acc = if r_now.attitude.is_some() {
            r_now.a
        } else if self.started {
            self.acc0 + self.jerk * (t - self.t_plan)
        } else {
            Vector3::zeros()
        };
        for k in 0..=paper_pointmass::N {
            let r = mission.reference(t + k as f64 * dt);
            let _ = self.solver.set_xref(k, &Self::xref(&r));
        }
        if !self.started {
            let x = [est.p.x, est.p.y, est.p.z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
            let _ = self.solver.set_guess(&x, &[0.0; 3]);
        }
        self.solver.prepare();
        let x0 = [
            est.p.x, est.p.y, est.p.z, est.v.x, est.v.y, est.v.z, acc.x, acc.y, acc.z,
        ];
        let _ = self.solver.set_x0(&x0);
        let info = self.solver.feedback();
        let j = self.solver.u0_jerk();
        self.jerk = Vector3::new(j[0], j[1], j[2]);
        self.acc0 = acc;
        self.t_plan = t;
        self.started = true;
        OuterStats {
            solver_us: start.elapsed().as_secs_f64() * 1e6,
            qp_iterations: info.qp.iterations,
            fallback: matches!(
                info.status,
                paper_pointmass::RtiStatus::UsedPreviousPlan
                    | paper_pointmass::RtiStatus::PlanExhausted
            ),
        }
    }

    fn inner(&mut self, t: f64, est: &Estimate, mission: &Mission) -> InnerCommand {
        let r = mission.reference(t);
        if let (Some(_), Some(c)) = (r.attitude, r.thrust) {
            // The flip: the body-rate reference drives the vehicle.
            return InnerCommand {
                thrust_c: c,
                rates: r.rate,
            };
        }
        let a = self.acc0 + self.jerk * (t - self.t_plan).clamp(0.0, 2.0 * self.period());
        let f = a + Vector3::z() * G;
        let qd = crate::mission::attitude_from_thrust(&f, r.yaw);
        let b3 = est.q * Vector3::z();
        let rates = attitude_rates(&est.q, &qd, self.tau);
        let n = rates.norm();
        let rates = if n > self.max_rate {
            rates * (self.max_rate / n)
        } else {
            rates
        };
        InnerCommand {
            thrust_c: f.dot(&b3).max(0.0),
            rates,
        }
    }
}

/// The full-NMPC architecture.
pub struct NmpcController {
    solver: Box<quadrotor_rates::Solver>,
    started: bool,
    u: [f64; 4],
}

impl NmpcController {
    /// A controller with the generated defaults (QR-bench weights and bounds).
    pub fn new() -> Self {
        let mut solver = Box::new(quadrotor_rates::Solver::new());
        solver.settings_mut().shift = true;
        Self {
            solver,
            started: false,
            u: [0.0; 4],
        }
    }

    /// Bounds the collective thrust `c` by `c_max` \[m/s^2\] (mass-normalized: the vehicle's
    /// rotors' most thrust over its mass) at every stage, in place of the model's bound.
    ///
    /// # Errors
    /// The solver's [`SetError`](quadrotor_rates::SetError) for a `c_max` that is not
    /// finite or below the lower bound (0); nothing changes then.
    pub fn set_thrust_limit(&mut self, c_max: f64) -> Result<(), quadrotor_rates::SetError> {
        if !c_max.is_finite() {
            return Err(quadrotor_rates::SetError::NonFinite);
        }
        let (lb, mut ub) = self.solver.control_bounds();
        ub[0] = c_max;
        self.solver.set_control_bounds(&lb, &ub)
    }

    /// The collective thrust's upper bound \[m/s^2\].
    pub fn thrust_limit(&self) -> f64 {
        self.solver.control_bounds().1[0]
    }

    fn plan_q(&self, k: usize) -> [f64; 4] {
        let k = k.min(quadrotor_rates::N);
        self.solver
            .state(k)
            .map_or([1.0, 0.0, 0.0, 0.0], |x| [x[3], x[4], x[5], x[6]])
    }
}

impl Default for NmpcController {
    fn default() -> Self {
        Self::new()
    }
}

impl Controller for NmpcController {
    fn period(&self) -> f64 {
        quadrotor_rates::DT
    }

    fn outer(&mut self, t: f64, est: &Estimate, mission: &Mission) -> OuterStats {
        let start = Instant::now();
        let dt = quadrotor_rates::DT;
        if !self.started {
            let q = aligned(&est.q, &[1.0, 0.0, 0.0, 0.0]);
            let x = [
                est.p.x, est.p.y, est.p.z, q[0], q[1], q[2], q[3], 0.0, 0.0, 0.0,
            ];
            let _ = self.solver.set_guess(&x, &[G, 0.0, 0.0, 0.0]);
        }
        for k in 0..=quadrotor_rates::N {
            let r = mission.reference(t + k as f64 * dt);
            // After the shift, stage k is today's stage k + 1 of the plan.
            let q = aligned(&r.attitude_ref(), &self.plan_q(k + 1));
            let xr = [
                r.p.x, r.p.y, r.p.z, q[0], q[1], q[2], q[3], r.v.x, r.v.y, r.v.z,
            ];
            let ur = [r.thrust_c(), r.rate.x, r.rate.y, r.rate.z];
            let _ = self.solver.set_xref(k, &xr);
            let _ = self.solver.set_uref(k, &ur);
        }
        self.solver.prepare();
        let q = aligned(&est.q, &self.plan_q(0));
        let x0 = [
            est.p.x, est.p.y, est.p.z, q[0], q[1], q[2], q[3], est.v.x, est.v.y, est.v.z,
        ];
        let _ = self.solver.set_x0(&x0);
        let info = self.solver.feedback();
        self.u = self.solver.u0();
        self.started = true;
        OuterStats {
            solver_us: start.elapsed().as_secs_f64() * 1e6,
            qp_iterations: info.qp.iterations,
            fallback: matches!(
                info.status,
                quadrotor_rates::RtiStatus::UsedPreviousPlan
                    | quadrotor_rates::RtiStatus::PlanExhausted
            ),
        }
    }

    fn inner(&mut self, _t: f64, _est: &Estimate, _mission: &Mission) -> InnerCommand {
        InnerCommand {
            thrust_c: self.u[0],
            rates: Vector3::new(self.u[1], self.u[2], self.u[3]),
        }
    }
}

/// A boxed controller of the given kind.
pub fn make(kind: ControllerKind) -> Box<dyn Controller> {
    match kind {
        ControllerKind::Paper => Box::new(PaperController::new()),
        ControllerKind::Nmpc => Box::new(NmpcController::new()),
    }
}
