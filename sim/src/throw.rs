//! The flip-and-throw mission: pump the tethered probe with a pitch-over manoeuvre planned by
//! the `quadrotor_probe` solver, release it when its ballistic landing point reaches the
//! target, recover, hold, return and land.
//!
//! # How it works
//!
//! 1. **Release velocity** ([`crate::release::plan`]): the least release speed `V` and its
//!    angle `theta_t` that reach the target from the release point with the paper's range
//!    equation, within the bounds on `V` and `theta_t`; a range out of reach is an error that
//!    says the largest reachable range.
//! 2. **Throw plan** ([`plan_throw`]): the generated `quadrotor_probe` solver in full-SQP mode
//!    over its 1 s horizon, from hover at the throw point with the probe hanging, with small
//!    tracking weights and the terminal residual `throw` (the probe's velocity
//!    `v + l (n_a alpha' + n_b beta')` minus the wanted release velocity). The release point
//!    (probe position at the end of the plan) moves the range and the height the release
//!    velocity is planned for, so steps 1 and 2 alternate until the release point settles
//!    (to 1 cm; a few rounds). The release velocity asked of the plan is
//!    `1 + speed_margin` times the planned one, so that on the real vehicle the probe's
//!    predicted landing point passes the target during the swing rather than stopping short.
//! 3. **Closed loop** ([`run_throw_trial`]): the same solver in RTI mode at 20 Hz tracks the
//!    plan (states, including the swing angles and rates, and controls as references, with the
//!    probe mass parameter at 0.2 kg); the body-rate and thrust setpoints go through the
//!    PX4-like rate loop to the coupled vehicle-and-probe plant. The model carries the rate
//!    loop's and the rotors' first-order lags as states (the delivered rates come from the
//!    gyro, the delivered thrust from the model's own lag of the commands), and the estimate
//!    is brought forward by the pose latency with the gyro and the accelerometer.
//! 4. **Release instant**: at every 1 kHz step of the throw, the drag-free landing point of the
//!    probe is predicted from the (latency-compensated) estimate and the link-angle encoder;
//!    the probe is released at the step nearest to the predicted range crossing the target
//!    (now, if the range is past the target or closer to it than the next step will be).
//!    Because of the speed margin the plan's last stage throws past the target (at 20 m it
//!    asks 13.5 m/s at the planner's 38.2 deg, 1.1 times the planner's 12.24 m/s), so the
//!    crossing comes earlier in the swing, while the probe still climbs more steeply: the
//!    flown release is not the planner's `(V, theta_t)` (at 20 m, 12.4-12.5 m/s at 44-45 deg
//!    in the noisy trials) but whatever velocity lands the probe on the target from where it
//!    is. If the range is not reached within the release window, the probe is released at
//!    the window's end and the trial fails.
//! 5. **Recovery**: at release the probe mass parameter is set to zero (no regeneration: with
//!    `mp = 0` the swing states are frozen and the model's vehicle part is the plain rate
//!    model QR-bench uses, plus the lags; checked in `mpc-dsl/tests/probe_model.rs`), the
//!    swing states lose their weights, the solver restarts from the measured state with one
//!    converged solve (a few SQP iterations: the plan's trajectory no longer fits), and the
//!    reference becomes a quintic from the vehicle's state at release to the hold point, then
//!    hold, return home, land.
//!
//! The thrust command in newtons is `(mq + mp) c` with the nominal masses; the mass estimator
//! of the flip mission is not used (the link force would bias it).
//!
//! # The throw frame
//!
//! The model's swing angles are singular at `|beta| = pi/2` (the link along the model's y
//! axis: `models/quadrotor_probe.mpc`). A throw pumps the swing in the vertical plane of its
//! heading, so the solver works in the throw frame: the world turned by the heading
//! ([`ThrowConfig::yaw`]) about the vertical, where that plane is the model's x-z plane, the
//! swing is `alpha` and `beta` is only the out-of-plane wobble. The model is invariant under
//! turns about the vertical (gravity is vertical, the weights are equal over x and y), so this
//! changes nothing at heading 0 and makes every heading fly alike. The plan's model states
//! ([`ThrowPlan::states`]) are in the throw frame; everything else (estimates, references,
//! the plan's points and velocities) is in the world frame. The encoder reads the swing angles
//! in the throw frame, and a measured `|beta|` above [`MODEL_SWING_LIMIT`] ends the trial with
//! that reason (the model's equations lose accuracy towards the singularity), as a failure.

use std::time::Instant;

use mpc_models::quadrotor_probe as pm;
use nalgebra::{SVector, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde::Serialize;

use crate::controller::{OuterStats, aligned};
use crate::estimator::{Estimate, Estimator, EstimatorConfig};
use crate::log::Sample;
use crate::mission::{G, Phase, RefPoint, Segment};
use crate::plant::{Contact, Disturbance, Plant, QuadParams, QuadState};
use crate::probe::{ProbeParams, link_direction, link_rate, swing_angles, swing_rates};
use crate::rate_loop::{RateController, RateGains};
use crate::release::{self, ReleaseBounds, ReleaseError, ReleasePlan};
use crate::report::TimeStats;

/// Link length of the `quadrotor_probe` model \[m\] (a constant of the model file).
pub const MODEL_LINK_LENGTH: f64 = 0.5;

/// Largest out-of-plane swing angle `|beta|` \[rad\] the controller flies with: the model's
/// swing equation divides by `cos^2 beta` (30 times the hanging value at 1.4 rad) and is
/// singular at `pi/2`. A measured `|beta|` above it ends a throw trial as a failure.
pub const MODEL_SWING_LIMIT: f64 = 1.4;

/// Recovery tolerance after release \[m\] (issue: back within 0.15 m of the hold point).
pub const THROW_RECOVERY_TOL_M: f64 = 0.15;
/// Longest acceptable recovery after release \[s\].
pub const THROW_RECOVERY_MAX_S: f64 = 3.0;
/// Lowest acceptable height of the vehicle from the throw to the end of the hold \[m\].
pub const THROW_MIN_ALTITUDE_M: f64 = 1.0;
/// Largest acceptable distance of the probe's landing point from the target \[m\].
pub const LANDING_TOL_M: f64 = 0.5;

/// Tracking weights (diagonal of Q) of the swing-aware controller before release.
const Q_TRACK: [f64; pm::NX_MODEL] = [
    50.0, 50.0, 50.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 20.0, 20.0, 2.0, 2.0, 0.0, 0.0, 0.0, 0.0,
];
/// Control weights before release.
const R_TRACK: [f64; 4] = [0.1, 0.5, 0.5, 0.5];
/// Weights after release: QR-bench's, the swing states unweighted (the probe is gone).
const Q_FREE: [f64; pm::NX_MODEL] = [
    100.0, 100.0, 100.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    0.0,
];
const R_FREE: [f64; 4] = [0.5, 1.0, 1.0, 1.0];

/// SQP iterations of the one converged solve at release.
const RELEASE_SQP_ITERATIONS: u32 = 3;

/// Weight of the release-velocity residual, in the plan and in flight.
const W_THROW: f64 = 100.0;

/// Most rounds of release velocity <-> throw trajectory in [`plan_throw`].
const MAX_ROUNDS: u32 = 12;

/// Everything the flip-and-throw mission needs. Positions in m (world ENU), times in s.
#[derive(Clone, Debug, PartialEq)]
pub struct ThrowConfig {
    /// Wanted range: horizontal distance from the probe's start to its landing point \[m\].
    pub range: f64,
    /// Bounds on the release speed and angle.
    pub bounds: ReleaseBounds,
    /// Heading of the throw \[rad\] (0: towards +x).
    pub yaw: f64,
    /// Where the vehicle lands at the end.
    pub home: Vector3<f64>,
    /// Where the trial starts: hovering, the probe hanging at rest below.
    pub start: Vector3<f64>,
    /// Where the throw begins (in hover): the end of the ascent.
    pub throw_point: Vector3<f64>,
    /// Duration of the climb from `start` to `throw_point`.
    pub ascend_time: f64,
    /// Hover at the throw point before the throw (the swing settles).
    pub settle_time: f64,
    /// Relative extra speed asked of the throw plan (see the module documentation).
    pub speed_margin: f64,
    /// The probe may be released from this long before the plan's release instant...
    pub window_before: f64,
    /// ... until this long after it; then it is released anyway (and the trial fails).
    pub window_after: f64,
    /// Hold point after release; `None`: the vehicle's planned position at release plus
    /// `hold_lead` seconds of its planned velocity, at least 1.5 m high.
    pub hold: Option<Vector3<f64>>,
    /// See `hold`.
    pub hold_lead: f64,
    /// Duration of the leg from the release state to the hold point.
    pub recover_time: f64,
    /// Hold after the recovery leg.
    pub hold_time: f64,
    /// Duration of the return leg to above home.
    pub return_time: f64,
    /// Height above home the return leg ends at.
    pub return_height: f64,
    /// Duration of the smooth descent down to `land_flare_height`.
    pub land_time: f64,
    /// Height where the final constant-speed descent begins.
    pub land_flare_height: f64,
    /// Final descent speed [m/s].
    pub land_speed: f64,
    /// The probe.
    pub probe: ProbeParams,
    /// Link-angle encoder noise, per angle \[rad\] (white).
    pub angle_noise: f64,
    /// Link-rate noise, per angle [rad/s] (white).
    pub rate_noise: f64,
}

impl Default for ThrowConfig {
    /// Range 20 m (the paper's), default bounds, start hovering at (0, 0, 2), throw from
    /// (0, 0, 3) after a 2 s climb and 1.5 s of hover, the paper's probe (0.2 kg, 0.5 m, no
    /// drag), encoder noise 0.002 rad and 0.02 rad/s.
    fn default() -> Self {
        Self {
            range: 20.0,
            bounds: ReleaseBounds::default(),
            yaw: 0.0,
            home: Vector3::zeros(),
            start: Vector3::new(0.0, 0.0, 2.0),
            throw_point: Vector3::new(0.0, 0.0, 3.0),
            ascend_time: 2.0,
            settle_time: 1.5,
            speed_margin: 0.10,
            window_before: 0.3,
            window_after: 0.15,
            hold: None,
            hold_lead: 0.35,
            recover_time: 1.5,
            hold_time: 2.0,
            return_time: 4.0,
            return_height: 2.0,
            land_time: 3.0,
            land_flare_height: 0.3,
            land_speed: 0.3,
            probe: ProbeParams::default(),
            angle_noise: 0.002,
            rate_noise: 0.02,
        }
    }
}

/// Why a throw cannot be planned or flown.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ThrowError {
    /// The release planner's verdict (unreachable range, bad bounds).
    #[error(
        "range {range} m from the probe's start ({along:.2} m from the release point, \
         {height:.2} m high): {source}"
    )]
    Release {
        /// The range asked for \[m\].
        range: f64,
        /// The distance from the release point to the target \[m\].
        along: f64,
        /// The release height \[m\].
        height: f64,
        /// The planner's error.
        source: ReleaseError,
    },
    /// The throw planner could not make the probe reach the release velocity.
    #[error(
        "the throw plan reaches a probe speed of {reached:.2} m/s at {angle_deg:.1} deg, but the \
         release needs {wanted:.2} m/s at {wanted_deg:.1} deg ({why}); lower --range or raise \
         the release-speed bound"
    )]
    Unachievable {
        /// Probe speed at the end of the plan [m/s].
        reached: f64,
        /// Its angle above the horizontal \[deg\].
        angle_deg: f64,
        /// Planned release speed [m/s].
        wanted: f64,
        /// Planned release angle \[deg\].
        wanted_deg: f64,
        /// The solver's status or the size of the miss.
        why: String,
    },
    /// A setting out of its range; the message names it.
    #[error("invalid flip-throw setting: {0}")]
    Invalid(String),
}

impl ThrowConfig {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`ThrowError::Invalid`] naming the first bad setting.
    pub fn validate(&self) -> Result<(), ThrowError> {
        let bad = |m: &str| Err(ThrowError::Invalid(m.to_string()));
        if !(self.range.is_finite() && self.range > 0.0) {
            return bad("range must be a positive number of metres");
        }
        if (self.probe.length - MODEL_LINK_LENGTH).abs() > 1e-12 {
            return Err(ThrowError::Invalid(format!(
                "probe length must be the model's {MODEL_LINK_LENGTH} m (models/quadrotor_probe.mpc)"
            )));
        }
        if !(self.probe.mass.is_finite() && self.probe.mass > 0.0 && self.probe.mass < 1.0) {
            return bad("probe mass must be in (0, 1) kg");
        }
        if !(self.probe.drag.is_finite() && self.probe.drag >= 0.0) {
            return bad("probe drag must be finite and >= 0");
        }
        if !(self.throw_point.z >= 2.0 && self.start.z >= 1.5) {
            return bad("the start must be at least 1.5 m and the throw point 2 m high");
        }
        for (name, v) in [
            ("ascend_time", self.ascend_time),
            ("recover_time", self.recover_time),
            ("return_time", self.return_time),
            ("land_time", self.land_time),
            ("land_speed", self.land_speed),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ThrowError::Invalid(format!("{name} must be positive")));
            }
        }
        for (name, v) in [
            ("settle_time", self.settle_time),
            ("hold_time", self.hold_time),
            ("speed_margin", self.speed_margin),
            ("window_before", self.window_before),
            ("window_after", self.window_after),
            ("angle_noise", self.angle_noise),
            ("rate_noise", self.rate_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ThrowError::Invalid(format!("{name} must be >= 0")));
            }
        }
        Ok(())
    }

    /// The throw direction (unit, horizontal).
    pub fn direction(&self) -> Vector3<f64> {
        Vector3::new(self.yaw.cos(), self.yaw.sin(), 0.0)
    }

    /// The probe's start: where it hangs at the beginning of the trial.
    pub fn probe_start(&self) -> Vector3<f64> {
        self.start - Vector3::z() * self.probe.length
    }

    /// The target on the ground: the probe's start projected on the ground plus `range`
    /// along the throw direction.
    pub fn target(&self) -> Vector3<f64> {
        let s = self.probe_start();
        Vector3::new(s.x, s.y, 0.0) + self.direction() * self.range
    }

    /// When the throw begins \[s\] (a multiple of the controller period).
    pub fn throw_start(&self) -> f64 {
        let t = self.ascend_time + self.settle_time;
        (t / pm::DT).ceil() * pm::DT
    }
}

/// The planned throw.
#[derive(Clone, Debug, PartialEq)]
pub struct ThrowPlan {
    /// The release velocity the plan was made for.
    pub release: ReleasePlan,
    /// Where the probe should land.
    pub target: Vector3<f64>,
    /// Planned probe position at release.
    pub release_point: Vector3<f64>,
    /// Planned probe velocity at release.
    pub release_velocity: Vector3<f64>,
    /// The release velocity asked of the plan and of the controller (the planned one plus
    /// the speed margin).
    pub asked_velocity: Vector3<f64>,
    /// Where the planned release state lands the probe (drag-free).
    pub planned_landing: Vector3<f64>,
    /// Planned vehicle position and velocity at release.
    pub vehicle_at_release: (Vector3<f64>, Vector3<f64>),
    /// Model states at `k * dt` from the throw's start, `k = 0..=2N` (the plan's `N` stages,
    /// then `N` more with the last control held: a continuation the tracking horizon can
    /// look into), in the throw frame (module documentation).
    pub states: Vec<[f64; pm::NX_MODEL]>,
    /// Controls of the plan, `k = 0..2N`.
    pub controls: Vec<[f64; 4]>,
    /// Stage of the planned release (`N`).
    pub release_stage: usize,
    /// SQP iterations of the last round.
    pub sqp_iterations: u32,
    /// Planning rounds (release velocity <-> trajectory).
    pub rounds: u32,
}

impl ThrowPlan {
    /// The plan made in the throw frame `frame` with its points and velocities in the world
    /// frame (the model states stay in the throw frame).
    fn out_of(self, frame: &ThrowFrame) -> Self {
        let (p, v) = self.vehicle_at_release;
        Self {
            target: frame.vec_out(&self.target),
            release_point: frame.vec_out(&self.release_point),
            release_velocity: frame.vec_out(&self.release_velocity),
            asked_velocity: frame.vec_out(&self.asked_velocity),
            planned_landing: frame.vec_out(&self.planned_landing),
            vehicle_at_release: (frame.vec_out(&p), frame.vec_out(&v)),
            ..self
        }
    }

    /// Planned release time after the throw's start \[s\].
    pub fn release_time(&self) -> f64 {
        self.release_stage as f64 * pm::DT
    }

    fn state(&self, k: usize) -> [f64; pm::NX_MODEL] {
        self.states
            .get(k)
            .or(self.states.last())
            .copied()
            .unwrap_or([0.0; pm::NX_MODEL])
    }

    fn control(&self, k: usize) -> [f64; 4] {
        self.controls
            .get(k)
            .or(self.controls.last())
            .copied()
            .unwrap_or([G, 0.0, 0.0, 0.0])
    }
}

/// Probe position and velocity of a model state (in the state's frame).
pub fn probe_of_state(x: &[f64; pm::NX_MODEL], l: f64) -> (Vector3<f64>, Vector3<f64>) {
    let p = Vector3::new(x[0], x[1], x[2]);
    let v = Vector3::new(x[7], x[8], x[9]);
    let ang = [x[10], x[11]];
    (
        p + link_direction(ang) * l,
        v + link_rate(ang, [x[12], x[13]]) * l,
    )
}

/// The throw frame: the world turned by the throw's heading about the vertical (module
/// documentation). At heading 0 every conversion is exact (the identity rotation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThrowFrame {
    /// World from throw frame: the turn by the heading.
    turn: UnitQuaternion<f64>,
}

impl ThrowFrame {
    /// The frame of a throw heading `yaw` \[rad\] (0: towards +x).
    pub fn new(yaw: f64) -> Self {
        Self {
            turn: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        }
    }

    /// A world vector (or point) in the throw frame.
    pub fn vec_in(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.turn.inverse_transform_vector(v)
    }

    /// A throw-frame vector (or point) in the world frame.
    pub fn vec_out(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.turn.transform_vector(v)
    }

    /// A world attitude (body to world) as body to throw frame.
    pub fn attitude_in(&self, q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        self.turn.inverse() * q
    }

    /// A model state's vehicle part (position, attitude, velocity) turned by `rot`; the
    /// swing, the body rates and the thrust are kept.
    fn turn_state(rot: &UnitQuaternion<f64>, x: &[f64; pm::NX_MODEL]) -> [f64; pm::NX_MODEL] {
        let mut y = *x;
        let p = rot.transform_vector(&Vector3::new(x[0], x[1], x[2]));
        let v = rot.transform_vector(&Vector3::new(x[7], x[8], x[9]));
        let q = rot.quaternion() * nalgebra::Quaternion::new(x[3], x[4], x[5], x[6]);
        y[..3].copy_from_slice(p.as_slice());
        y[3..7].copy_from_slice(&[q.w, q.i, q.j, q.k]);
        y[7..10].copy_from_slice(v.as_slice());
        y
    }

    /// A model state with a world-frame vehicle part in the throw frame (the swing angles are
    /// the caller's, already in the throw frame).
    pub fn state_in(&self, x: &[f64; pm::NX_MODEL]) -> [f64; pm::NX_MODEL] {
        Self::turn_state(&self.turn.inverse(), x)
    }

    /// A throw-frame quaternion `[w, x, y, z]` in the world frame.
    fn quat_out(&self, q: &[f64; 4]) -> [f64; 4] {
        let r = self.turn.quaternion() * nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]);
        [r.w, r.i, r.j, r.k]
    }

    /// The swing of a world link direction `n` and rate `nd` as the model's angles and rates
    /// in the throw frame.
    pub fn swing_in(&self, n: &Vector3<f64>, nd: &Vector3<f64>) -> ([f64; 2], [f64; 2]) {
        let ang = swing_angles(&self.vec_in(n));
        (ang, swing_rates(ang, &self.vec_in(nd)))
    }
}

/// Hover at `p` with the probe hanging, heading 0.
fn hover_state(p: &Vector3<f64>) -> [f64; pm::NX_MODEL] {
    [
        p.x, p.y, p.z, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, G,
    ]
}

fn landing(p: &Vector3<f64>, v: &Vector3<f64>) -> Option<Vector3<f64>> {
    release::landing_point([p.x, p.y, p.z], [v.x, v.y, v.z], G).map(Vector3::from)
}

/// Plans the throw for a vehicle of mass `mq` (see the module documentation).
///
/// # Errors
/// [`ThrowError::Release`] when the range is out of reach under the bounds (or the bounds
/// are invalid),
/// [`ThrowError::Unachievable`] when the vehicle cannot pump the probe to the release
/// velocity, [`ThrowError::Invalid`] for bad settings.
pub fn plan_throw(cfg: &ThrowConfig, mq: f64) -> Result<ThrowPlan, ThrowError> {
    cfg.validate()?;
    if !(mq.is_finite() && mq > 0.0) {
        return Err(ThrowError::Invalid("vehicle mass must be positive".into()));
    }
    let frame = ThrowFrame::new(cfg.yaw);
    let local = ThrowConfig {
        yaw: 0.0,
        start: frame.vec_in(&cfg.start),
        throw_point: frame.vec_in(&cfg.throw_point),
        ..cfg.clone()
    };
    plan_in_frame(&local, mq).map(|plan| plan.out_of(&frame))
}

/// [`plan_throw`] for a throw at heading 0 (in its throw frame).
fn plan_in_frame(cfg: &ThrowConfig, mq: f64) -> Result<ThrowPlan, ThrowError> {
    let l = cfg.probe.length;
    let dir = cfg.direction();
    let target = cfg.target();
    let x0 = hover_state(&cfg.throw_point);
    let mut s = planning_solver(cfg, mq, &x0)?;

    // First guess of the release point: above and ahead of the throw point.
    let mut rel_p = cfg.throw_point + dir * 0.5 + Vector3::z() * 1.4;
    let mut rounds = 0;
    loop {
        rounds += 1;
        let along = (target - rel_p).dot(&dir);
        let plan = release::plan(along, rel_p.z, G, &cfg.bounds).map_err(|source| {
            ThrowError::Release {
                range: cfg.range,
                along,
                height: rel_p.z,
                source,
            }
        })?;
        let vwant = dir * plan.velocity[0] + Vector3::z() * plan.velocity[1];
        let vask = vwant * (1.0 + cfg.speed_margin);
        setting(s.set_vthrow(&[vask.x, vask.y, vask.z]))?;
        if rounds == 1 {
            setting(s.set_guess(&x0, &[G, 0.0, 0.0, 0.0]))?;
        }
        setting(s.set_x0(&x0))?;
        let info = s.solve_sqp();
        let xn = s.state(pm::N).unwrap_or(x0);
        let (pp, pv) = probe_of_state(&xn, l);
        let miss = (pv - vask).norm();
        let unachievable = |why: String| ThrowError::Unachievable {
            reached: pv.norm(),
            angle_deg: pv.z.atan2(pv.xy().norm()).to_degrees(),
            wanted: plan.speed,
            wanted_deg: plan.angle.to_degrees(),
            why,
        };
        if !matches!(
            info.status,
            pm::RtiStatus::Ok | pm::RtiStatus::MaxIterations
        ) {
            return Err(unachievable(format!("solver status {:?}", info.status)));
        }
        if miss > 0.05 * vask.norm().max(1.0) {
            return Err(unachievable(format!("missed by {miss:.2} m/s")));
        }
        let moved = (pp - rel_p).norm();
        // Damped: the release point and the release velocity pull on each other.
        rel_p = if rounds < 3 { pp } else { (rel_p + pp) * 0.5 };
        if moved < 0.01 || rounds >= MAX_ROUNDS {
            if moved >= 0.01 {
                return Err(unachievable(format!(
                    "the release point did not settle in {MAX_ROUNDS} rounds"
                )));
            }
            let (states, controls) = planned_trajectory(&s, &x0, xn);
            let planned_landing = landing(&pp, &pv).unwrap_or(pp);
            return Ok(ThrowPlan {
                release: plan,
                target,
                release_point: pp,
                release_velocity: pv,
                asked_velocity: vask,
                planned_landing,
                vehicle_at_release: (
                    Vector3::new(xn[0], xn[1], xn[2]),
                    Vector3::new(xn[7], xn[8], xn[9]),
                ),
                states,
                controls,
                release_stage: pm::N,
                sqp_iterations: info.sqp_iterations,
                rounds,
            });
        }
    }
}

/// A setting the planning solver refused, as a [`ThrowError::Invalid`].
fn setting(r: Result<(), pm::SetError>) -> Result<(), ThrowError> {
    r.map_err(|e| ThrowError::Invalid(format!("solver rejected a setting: {e:?}")))
}

/// The probe solver set up for planning a throw from hover at `x0`: the masses, and weights
/// that keep near the throw point with smooth controls and make the terminal probe velocity
/// dominant; full SQP, at most 60 iterations.
fn planning_solver(
    cfg: &ThrowConfig,
    mq: f64,
    x0: &[f64; pm::NX_MODEL],
) -> Result<Box<pm::Solver>, ThrowError> {
    let mut s = Box::new(pm::Solver::new());
    setting(s.set_mq(mq))?;
    setting(s.set_mp(cfg.probe.mass))?;
    let mut qw = [0.0; pm::NX_MODEL];
    qw[..3].copy_from_slice(&[1.0, 1.0, 1.0]);
    let mut pw = [0.0; pm::NX_MODEL];
    pw[1] = 1.0;
    setting(s.set_q_w(&qw))?;
    setting(s.set_p_w(&pw))?;
    setting(s.set_r_w(&[0.01; 4]))?;
    setting(s.set_w_throw(W_THROW))?;
    setting(s.set_xref_all(x0))?;
    setting(s.set_uref_all(&[G, 0.0, 0.0, 0.0]))?;
    s.settings_mut().sqp_max_iter = 60;
    Ok(s)
}

/// The planned trajectory: the solver's states and controls to the release (stage `N`,
/// state `xn`), then as many stages more with the last control held, on the model's own
/// discretization.
fn planned_trajectory(
    s: &pm::Solver,
    x0: &[f64; pm::NX_MODEL],
    xn: [f64; pm::NX_MODEL],
) -> (Vec<[f64; pm::NX_MODEL]>, Vec<[f64; 4]>) {
    let mut states = Vec::with_capacity(2 * pm::N + 1);
    let mut controls = Vec::with_capacity(2 * pm::N);
    for k in 0..=pm::N {
        states.push(s.state(k).unwrap_or(*x0));
    }
    for k in 0..pm::N {
        controls.push(s.control(k).unwrap_or([G, 0.0, 0.0, 0.0]));
    }
    let p = SVector::from(s.param(pm::N - 1).unwrap_or(pm::P_DEFAULT));
    let ulast = controls.last().copied().unwrap_or([G, 0.0, 0.0, 0.0]);
    let mut x = xn;
    for _ in 0..pm::N {
        let (mut a, mut b) = (nalgebra::SMatrix::zeros(), nalgebra::SMatrix::zeros());
        let xs =
            pm::functions::dynamics(&SVector::from(x), &SVector::from(ulast), &p, &mut a, &mut b);
        x = xs.into();
        states.push(x);
        controls.push(ulast);
    }
    (states, controls)
}

/// One flip-and-throw trial.
#[derive(Clone, Debug)]
pub struct ThrowSimConfig {
    /// The mission.
    pub throw: ThrowConfig,
    /// The true vehicle.
    pub plant: QuadParams,
    /// The vehicle the controllers believe in.
    pub nominal: QuadParams,
    /// Rate-loop gains.
    pub gains: RateGains,
    /// Estimation model.
    pub estimator: EstimatorConfig,
    /// Seed of the noise.
    pub seed: u64,
    /// Plant and rate-loop step \[s\].
    pub dt: f64,
    /// Longest trial \[s\].
    pub t_max: f64,
}

impl ThrowSimConfig {
    /// A trial of `throw` with the default vehicle and motion-capture noise.
    pub fn new(throw: ThrowConfig) -> Self {
        Self {
            throw,
            plant: QuadParams::default(),
            nominal: QuadParams::default(),
            gains: RateGains::default(),
            estimator: EstimatorConfig::noisy(),
            seed: 0,
            dt: 0.001,
            t_max: 40.0,
        }
    }
}

/// What happened at release.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ReleaseRecord {
    /// Time \[s\].
    pub t: f64,
    /// Whether the trigger fired (false: released at the end of the window).
    pub triggered: bool,
    /// True probe speed [m/s].
    pub speed_m_s: f64,
    /// True angle of the probe velocity above the horizontal \[rad\].
    pub angle_rad: f64,
    /// True probe height \[m\].
    pub height_m: f64,
    /// True vehicle velocity [m/s].
    pub vehicle_velocity: [f64; 3],
    /// The landing point predicted from the estimate at the trigger \[m\].
    pub predicted_landing: [f64; 3],
}

/// One trial of the flip-and-throw mission.
#[derive(Clone, Debug)]
pub struct ThrowTrial {
    /// Its configuration.
    pub config: ThrowSimConfig,
    /// The plan it flew.
    pub plan: ThrowPlan,
    /// The vehicle's log (as the flip mission's).
    pub samples: Vec<Sample>,
    /// The probe's path: (t, x, y, z) every 10 ms and at release and landing.
    pub probe_track: Vec<[f64; 4]>,
    /// Phase changes (time, phase).
    pub transitions: Vec<(f64, Phase)>,
    /// The release.
    pub release: Option<ReleaseRecord>,
    /// Where the probe came down, and when.
    pub probe_landing: Option<(f64, Vector3<f64>)>,
    /// When the probe hit the ground while still attached.
    pub probe_struck: Option<f64>,
    /// How it ended ("landed", "crashed: ...", "timeout", "ended: ..." when the swing left
    /// the model's range).
    pub outcome: String,
    /// The hold point after release.
    pub hold_point: Vector3<f64>,
    /// The largest out-of-plane swing `|beta|` (throw frame, true value) while the probe was
    /// attached \[rad\]; the model is singular at `pi/2` ([`MODEL_SWING_LIMIT`]).
    pub max_out_of_plane_rad: f64,
}

/// The reference schedule after release.
#[derive(Clone, Copy, Debug)]
struct AfterRelease {
    t0: f64,
    recover: Segment,
    hold: Vector3<f64>,
}

struct Schedule<'a> {
    cfg: &'a ThrowConfig,
    t_throw: f64,
    plan: &'a ThrowPlan,
    after: Option<AfterRelease>,
    /// Touchdown seen: motors off.
    landed: bool,
}

enum Ref {
    /// A position reference (hover, legs).
    Point(RefPoint),
    /// A stage of the throw plan.
    Plan(usize),
}

impl AfterRelease {
    /// The schedule after a release at `t`: recover from the estimated state `e` to `hold`
    /// in `recover_time`, then hold there.
    fn from(t: f64, e: &Estimate, hold: Vector3<f64>, recover_time: f64) -> Self {
        let z = Vector3::zeros();
        Self {
            t0: t,
            recover: Segment::Quintic {
                start: [e.p, e.v, z],
                end: [hold, z, z],
                duration: recover_time,
            },
            hold,
        }
    }
}

impl Schedule<'_> {
    /// The throw frame (module documentation).
    fn frame(&self) -> ThrowFrame {
        ThrowFrame::new(self.cfg.yaw)
    }

    /// The position reference at `t`, for the log.
    fn logged_reference(&self, t: f64) -> Vector3<f64> {
        match self.reference(t).1 {
            Ref::Plan(j) => {
                let x = self.plan.state(j);
                self.frame().vec_out(&Vector3::new(x[0], x[1], x[2]))
            }
            Ref::Point(p) => p.p,
        }
    }

    fn ascend(&self) -> Segment {
        let z = Vector3::zeros();
        Segment::Quintic {
            start: [self.cfg.start, z, z],
            end: [self.cfg.throw_point, z, z],
            duration: self.cfg.ascend_time,
        }
    }

    fn land_start(&self, a: &AfterRelease) -> f64 {
        a.t0 + self.cfg.recover_time + self.cfg.hold_time + self.cfg.return_time
    }

    fn above_home(&self) -> Vector3<f64> {
        self.cfg.home + Vector3::z() * self.cfg.return_height
    }

    fn flare(&self) -> Vector3<f64> {
        self.cfg.home + Vector3::z() * self.cfg.land_flare_height
    }

    fn reference(&self, t: f64) -> (Phase, Ref) {
        let z = Vector3::zeros();
        let yaw = self.cfg.yaw;
        let Some(a) = self.after else {
            if t < self.t_throw {
                return (
                    Phase::Ascend,
                    Ref::Point(self.ascend().reference(Phase::Ascend, yaw, t)),
                );
            }
            let k = ((t - self.t_throw) / pm::DT + 1e-6).floor() as usize;
            return (Phase::Flip, Ref::Plan(k));
        };
        let tr = t - a.t0;
        if tr < self.cfg.recover_time {
            return (
                Phase::Recover,
                Ref::Point(a.recover.reference(Phase::Recover, yaw, tr)),
            );
        }
        let t_hold_end = self.cfg.recover_time + self.cfg.hold_time;
        if tr < t_hold_end {
            return (
                Phase::Hold,
                Ref::Point(Segment::Hold(a.hold).reference(Phase::Hold, yaw, 0.0)),
            );
        }
        let t_ret_end = t_hold_end + self.cfg.return_time;
        if tr < t_ret_end {
            let seg = Segment::Quintic {
                start: [a.hold, z, z],
                end: [self.above_home(), z, z],
                duration: self.cfg.return_time,
            };
            return (
                Phase::ReturnHome,
                Ref::Point(seg.reference(Phase::ReturnHome, yaw, tr - t_hold_end)),
            );
        }
        if self.landed {
            return (
                Phase::Landed,
                Ref::Point(Segment::Hold(self.cfg.home).reference(Phase::Landed, yaw, 0.0)),
            );
        }
        let tl = t - self.land_start(&a);
        let seg = if tl < self.cfg.land_time {
            Segment::Quintic {
                start: [self.above_home(), z, z],
                end: [self.flare(), z, z],
                duration: self.cfg.land_time,
            }
        } else {
            Segment::Descend {
                p0: self.flare(),
                speed: self.cfg.land_speed,
            }
        };
        let tau = if tl < self.cfg.land_time {
            tl
        } else {
            tl - self.cfg.land_time
        };
        (
            Phase::Land,
            Ref::Point(seg.reference(Phase::Land, yaw, tau)),
        )
    }
}

/// The swing-aware NMPC: the `quadrotor_probe` solver in RTI mode.
struct ThrowController {
    solver: Box<pm::Solver>,
    u: [f64; 4],
    released: bool,
    started: bool,
    reinit: bool,
    /// The thrust the rotors deliver, by the model's first-order lag of the commands.
    thrust: f64,
}

fn point_state(r: &RefPoint, near: &[f64; 4]) -> ([f64; pm::NX_MODEL], [f64; 4]) {
    let q = aligned(&r.attitude_ref(), near);
    (
        [
            r.p.x,
            r.p.y,
            r.p.z,
            q[0],
            q[1],
            q[2],
            q[3],
            r.v.x,
            r.v.y,
            r.v.z,
            0.0,
            0.0,
            0.0,
            0.0,
            r.rate.x,
            r.rate.y,
            r.rate.z,
            r.thrust_c(),
        ],
        [r.thrust_c(), r.rate.x, r.rate.y, r.rate.z],
    )
}

impl ThrowController {
    fn new(mq: f64, mp: f64) -> Self {
        let mut solver = Box::new(pm::Solver::new());
        solver.settings_mut().shift = true;
        let _ = solver.set_mq(mq);
        let _ = solver.set_mp(mp);
        let _ = solver.set_q_w(&Q_TRACK);
        let _ = solver.set_p_w(&Q_TRACK.map(|w| 5.0 * w));
        let _ = solver.set_r_w(&R_TRACK);
        let _ = solver.set_w_throw(0.0);
        Self {
            solver,
            u: [G, 0.0, 0.0, 0.0],
            released: false,
            started: false,
            reinit: false,
            thrust: G,
        }
    }

    fn release(&mut self) {
        self.released = true;
        self.reinit = true;
        let _ = self.solver.set_mp(0.0);
        let _ = self.solver.set_w_throw(0.0);
        let _ = self.solver.set_q_w(&Q_FREE);
        let _ = self.solver.set_p_w(&Q_FREE.map(|w| 5.0 * w));
        let _ = self.solver.set_r_w(&R_FREE);
    }

    /// One step of the rate loop on the last command: the rotor commands and the
    /// collective thrust \[N\] for the carried mass `mass`; the thrust the rotors deliver
    /// follows the command by the model's lag.
    fn rate_loop_step(
        &mut self,
        rate: &mut RateController,
        mass: f64,
        gyro: &Vector3<f64>,
        dt: f64,
    ) -> ([f64; 4], f64) {
        let thrust = (mass * self.u[0]).max(0.0);
        self.thrust += (dt / pm::P_DEFAULT[pm::PARAM_TAU_C.start]) * (self.u[0] - self.thrust);
        let rates = Vector3::new(self.u[1], self.u[2], self.u[3]);
        let out = rate.update(&rates, thrust, gyro, dt);
        (out.rotor_cmd, thrust)
    }

    fn plan_q(&self, k: usize) -> [f64; 4] {
        self.solver
            .state(k.min(pm::N))
            .map_or([1.0, 0.0, 0.0, 0.0], |x| [x[3], x[4], x[5], x[6]])
    }

    fn outer(
        &mut self,
        t: f64,
        est: &Estimate,
        swing: ([f64; 2], [f64; 2]),
        sched: &Schedule<'_>,
    ) -> OuterStats {
        let start = Instant::now();
        let frame = sched.frame();
        let q = aligned(
            &frame.attitude_in(&est.q),
            &self.plan_q(usize::from(self.started)),
        );
        let (p, v) = (frame.vec_in(&est.p), frame.vec_in(&est.v));
        let (ang, dang) = if self.released {
            ([0.0; 2], [0.0; 2])
        } else {
            swing
        };
        let x0 = [
            p.x,
            p.y,
            p.z,
            q[0],
            q[1],
            q[2],
            q[3],
            v.x,
            v.y,
            v.z,
            ang[0],
            ang[1],
            dang[0],
            dang[1],
            est.w.x,
            est.w.y,
            est.w.z,
            self.thrust,
        ];
        // At release the plan's trajectory no longer fits (mass, swing states): start
        // afresh from the measured state and converge once (full SQP, at most 10
        // iterations), then go on with one RTI iteration per step.
        let converge = self.reinit;
        if !self.started || self.reinit {
            let _ = self.solver.set_guess(&x0, &[G, 0.0, 0.0, 0.0]);
        }
        self.reinit = false;
        // The soft floor (1 m) holds until the landing begins.
        let landing = sched.reference(t).0 == Phase::Land;
        let _ = self.solver.set_z_floor(if landing { -1.0 } else { 1.0 });
        for k in 0..=pm::N {
            let (_, r) = sched.reference(t + k as f64 * pm::DT);
            let (xr, ur) = match r {
                Ref::Plan(j) => (sched.plan.state(j), sched.plan.control(j)),
                Ref::Point(p) => {
                    let (x, u) = point_state(&p, &frame.quat_out(&self.plan_q(k + 1)));
                    (frame.state_in(&x), u)
                }
            };
            let _ = self.solver.set_xref(k, &xr);
            let _ = self.solver.set_uref(k, &ur);
        }
        let info = if converge {
            let _ = self.solver.set_x0(&x0);
            self.solver.settings_mut().sqp_max_iter = RELEASE_SQP_ITERATIONS;
            self.solver.solve_sqp()
        } else {
            self.solver.prepare();
            let _ = self.solver.set_x0(&x0);
            self.solver.feedback()
        };
        self.u = self.solver.u0();
        self.started = true;
        OuterStats {
            solver_us: start.elapsed().as_secs_f64() * 1e6,
            qp_iterations: info.qp.iterations,
            fallback: matches!(
                info.status,
                pm::RtiStatus::UsedPreviousPlan | pm::RtiStatus::PlanExhausted
            ),
        }
    }
}

/// The estimate brought forward by the pose latency with the IMU (as PX4's EKF output
/// predictor does): the attitude by the gyro, velocity and position by the accelerometer.
fn compensated(e: &Estimate, acc_world: &Vector3<f64>, latency: f64) -> Estimate {
    let mut c = *e;
    c.q = e.q * UnitQuaternion::from_scaled_axis(e.w * latency);
    c.v = e.v + acc_world * latency;
    c.p = e.p + e.v * latency + acc_world * (0.5 * latency * latency);
    c
}

/// Landing point of a point mass with quadratic drag (acceleration `-k |v| v - g e3`,
/// `k = drag / mass`): RK4 at 5 ms until `z <= 0`, the crossing interpolated linearly inside
/// the last step (the drag-free case is [`release::landing_point`], exact). `None` if it has
/// not come down within 60 s.
fn landing_with_drag(p: &Vector3<f64>, v: &Vector3<f64>, k: f64) -> Option<Vector3<f64>> {
    const H: f64 = 0.005;
    let acc = |v: &Vector3<f64>| -v * (k * v.norm()) - Vector3::z() * G;
    let (mut p, mut v) = (*p, *v);
    if p.z <= 0.0 {
        return Some(Vector3::new(p.x, p.y, 0.0));
    }
    for _ in 0..12_000 {
        let (k1p, k1v) = (v, acc(&v));
        let v2 = v + k1v * (0.5 * H);
        let (k2p, k2v) = (v2, acc(&v2));
        let v3 = v + k2v * (0.5 * H);
        let (k3p, k3v) = (v3, acc(&v3));
        let v4 = v + k3v * H;
        let (k4p, k4v) = (v4, acc(&v4));
        let pn = p + (k1p + k2p * 2.0 + k3p * 2.0 + k4p) * (H / 6.0);
        let vn = v + (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (H / 6.0);
        if pn.z <= 0.0 {
            let s = p.z / (p.z - pn.z);
            let l = p + (pn - p) * s;
            return Some(Vector3::new(l.x, l.y, 0.0));
        }
        (p, v) = (pn, vn);
    }
    None
}

/// A predicted landing: the landing point, and the probe's position and velocity it was
/// predicted from.
type Prediction = (Vector3<f64>, Vector3<f64>, Vector3<f64>);

/// The probe's landing point predicted from the (latency-compensated) estimate and the
/// encoder, with the probe's drag if it has any; also the probe's position and velocity.
fn predicted_landing(
    est: &Estimate,
    swing: ([f64; 2], [f64; 2]),
    probe: &ProbeParams,
    frame: &ThrowFrame,
) -> Option<Prediction> {
    let (p, v) = (est.p, est.v);
    let (ang, dang) = swing;
    let l = probe.length;
    let pp = p + frame.vec_out(&link_direction(ang)) * l;
    let pv = v + frame.vec_out(&link_rate(ang, dang)) * l;
    let lp = if probe.drag > 0.0 {
        landing_with_drag(&pp, &pv, probe.drag / probe.mass)
    } else {
        landing(&pp, &pv)
    };
    lp.map(|lp| (lp, pp, pv))
}

/// Runs one flip-and-throw trial (planning included).
///
/// # Errors
/// [`ThrowError`] if the settings are invalid or the throw cannot be planned.
// The loop is one simulation step in its order (estimate, release, outer loop, rate loop,
// log, plant), on state every step shares; its parts are the functions below.
pub fn run_throw_trial(cfg: &ThrowSimConfig) -> Result<ThrowTrial, ThrowError> {
    validate_trial(cfg)?;
    let tc = &cfg.throw;
    let lat = cfg.estimator.latency;
    let mq = cfg.nominal.mass;
    let mp = tc.probe.mass;
    let plan = plan_throw(tc, mq)?;
    let dt = cfg.dt;

    let mut plant = hanging_at_start(cfg);
    let mut est = Estimator::new(cfg.estimator.clone(), cfg.seed);
    let mut encoder = Encoder::new(tc, cfg.seed);
    let mut rate = RateController::new(&cfg.nominal, cfg.gains.clone());
    let mut ctrl = ThrowController::new(mq, mp);

    let hold_point = hold_point(tc, &plan);
    let mut sched = Schedule {
        cfg: tc,
        t_throw: tc.throw_start(),
        plan: &plan,
        after: None,
        landed: false,
    };
    let mut trigger = Trigger::new(tc, &plan, sched.t_throw);

    let mut samples = Vec::with_capacity((cfg.t_max / dt) as usize / 2);
    let mut probe_track = Vec::new();
    let mut transitions: Vec<(f64, Phase)> = Vec::new();
    let mut next_outer = 0.0;
    let mut pending = None;
    let mut release_rec = None;
    let mut outcome = "timeout".to_string();
    let mut on_ground = false;
    let mut landed_at: Option<f64> = None;
    let mut pitch_turned = 0.0;
    let steps = (cfg.t_max / dt).ceil() as usize;
    for i in 0..=steps {
        let t = i as f64 * dt;
        let truth = plant.state().clone();
        let e_raw = est.update(t, &truth);
        let acc_world = e_raw.q * plant.specific_acceleration() - Vector3::z() * G;
        let e = compensated(&e_raw, &acc_world, lat);
        let swing = encoder.read(&plant);
        if let Some(why) = swing_out_of_model(&swing, release_rec.is_none()) {
            outcome = why;
            break;
        }
        let (mut phase, _) = sched.reference(t);
        if transitions.last().map(|x| x.1) != Some(phase) {
            transitions.push((t, phase));
        }

        // Release decision (1 kHz).
        if phase == Phase::Flip
            && release_rec.is_none()
            && let Some((triggered, pred)) = trigger.check(t, &e, swing, &tc.probe)
        {
            let (rec, pp_true) = release(&mut plant, &truth, t, triggered, pred);
            release_rec = Some(rec);
            ctrl.release();
            probe_track.push([t, pp_true.x, pp_true.y, pp_true.z]);
            // Recovery from the vehicle's estimated state now.
            sched.after = Some(AfterRelease::from(t, &e, hold_point, tc.recover_time));
            // The next outer step at once: the plan must change with the mass.
            next_outer = t;
            phase = sched.reference(t).0;
            transitions.push((t, phase));
        }
        if on_ground && phase == Phase::Land {
            sched.landed = true;
            phase = Phase::Landed;
            transitions.push((t, phase));
        }
        if phase == Phase::Landed {
            landed_at.get_or_insert(t);
        }
        if t + 1e-9 >= next_outer && phase != Phase::Landed {
            pending = Some(ctrl.outer(t, &e, swing, &sched));
            next_outer = t + pm::DT;
        }
        let mp_now = if release_rec.is_some() { 0.0 } else { mp };
        let (rotor_cmd, thrust_cmd) = if phase == Phase::Landed {
            rate.reset();
            ([0.0; 4], 0.0)
        } else {
            ctrl.rate_loop_step(&mut rate, mq + mp_now, &e.w, dt)
        };
        if phase == Phase::Flip || release_rec.is_some() {
            pitch_turned += truth.w.y * dt;
        }
        let rp = sched.logged_reference(t);
        let stats = pending.take();
        let fs = plant.rotor_thrusts();
        samples.push(Sample {
            phase: phase.index(),
            pose_valid: e.pose_valid,
            x_ref: rp.x,
            y_ref: rp.y,
            z_ref: rp.z,
            pitch_turned,
            wx_cmd: ctrl.u[1],
            wy_cmd: ctrl.u[2],
            wz_cmd: ctrl.u[3],
            thrust_cmd,
            ..Sample::at(t, &truth, fs, stats)
        });
        if i % 10 == 0
            && let Some(p) = plant.probe()
            && p.landing().is_none()
        {
            let pp = p.position(&truth);
            probe_track.push([t, pp.x, pp.y, pp.z]);
        }
        let probe_down = plant.probe().is_none_or(|p| p.landing().is_some());
        if landed_at.is_some_and(|tl| t - tl > 0.5) && probe_down {
            outcome = "landed".to_string();
            break;
        }
        match plant.step(&rotor_cmd, &Disturbance::default(), dt) {
            Contact::Crash { reason, .. } => {
                outcome = format!("crashed: {reason:?} at t = {:.3} s", t + dt);
                break;
            }
            Contact::Touchdown { .. } | Contact::OnGround => on_ground = true,
            Contact::Airborne => on_ground = false,
        }
    }
    let probe_landing = plant
        .probe()
        .and_then(|p| p.landing())
        .map(|l| (l.time, l.position));
    if let Some((t, p)) = probe_landing {
        probe_track.push([t, p.x, p.y, p.z]);
    }
    Ok(ThrowTrial {
        config: cfg.clone(),
        samples,
        probe_track,
        transitions,
        release: release_rec,
        probe_landing,
        probe_struck: plant.probe().and_then(|p| p.struck_ground_attached()),
        outcome,
        hold_point,
        plan,
        max_out_of_plane_rad: encoder.max_out_of_plane,
    })
}

/// The hold point after the release: the configured one, or where the vehicle will be
/// `hold_lead` seconds after the planned release at its velocity then (at least 1.5 m up).
fn hold_point(tc: &ThrowConfig, plan: &ThrowPlan) -> Vector3<f64> {
    tc.hold.unwrap_or_else(|| {
        let (p, v) = plan.vehicle_at_release;
        let mut h = p + v * tc.hold_lead;
        h.z = h.z.max(1.5);
        h
    })
}

/// Checks the settings a throw trial depends on.
fn validate_trial(cfg: &ThrowSimConfig) -> Result<(), ThrowError> {
    cfg.throw.validate()?;
    if !(cfg.dt.is_finite() && cfg.dt > 0.0 && cfg.dt <= 0.002) {
        return Err(ThrowError::Invalid("dt must be in (0, 0.002] s".into()));
    }
    if !(cfg.t_max.is_finite() && cfg.t_max > 0.0 && cfg.t_max <= 3600.0) {
        return Err(ThrowError::Invalid("t_max must be in (0, 3600] s".into()));
    }
    let lat = cfg.estimator.latency;
    if !(lat.is_finite() && (0.0..=0.1).contains(&lat)) {
        return Err(ThrowError::Invalid(
            "estimator latency must be in [0, 0.1] s for the throw".into(),
        ));
    }
    Ok(())
}

/// The plant at the start: hovering at the start point with the rotor speeds for the total
/// weight, at the throw's heading, the probe hanging at rest.
fn hanging_at_start(cfg: &ThrowSimConfig) -> Plant {
    let tc = &cfg.throw;
    let mut s0 = QuadState::hovering(tc.start, &cfg.plant);
    let hover_omega =
        ((cfg.plant.mass + tc.probe.mass) * cfg.plant.g / (4.0 * cfg.plant.k_thrust)).sqrt();
    s0.omega = [hover_omega; 4];
    s0.q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), tc.yaw);
    let mut plant = Plant::new(cfg.plant.clone(), s0);
    plant.attach_probe(tc.probe, [0.0; 2], [0.0; 2]);
    plant
}

/// The link's encoder: the true swing angles and rates with the configured noise, from its
/// own random stream.
struct Encoder {
    rng: StdRng,
    angle: Option<Normal<f64>>,
    rate: Option<Normal<f64>>,
    frame: ThrowFrame,
    /// The largest true `|beta|` read while the probe was attached \[rad\].
    max_out_of_plane: f64,
}

impl Encoder {
    fn new(tc: &ThrowConfig, seed: u64) -> Self {
        let noise = |std: f64| Normal::new(0.0, std.max(0.0)).ok();
        Self {
            rng: StdRng::seed_from_u64(seed ^ 0x7e57_ab1e),
            angle: noise(tc.angle_noise),
            rate: noise(tc.rate_noise),
            frame: ThrowFrame::new(tc.yaw),
            max_out_of_plane: 0.0,
        }
    }

    /// The measured swing (angles, rates) in the throw frame; zero once the probe is gone.
    fn read(&mut self, plant: &Plant) -> ([f64; 2], [f64; 2]) {
        let (ang_true, dang_true) = plant.probe().map_or(([0.0; 2], [0.0; 2]), |p| {
            self.frame.swing_in(&p.link_direction(), &p.link_rate())
        });
        if plant.probe().is_some_and(|p| p.is_attached()) {
            self.max_out_of_plane = self.max_out_of_plane.max(ang_true[1].abs());
        }
        let rng = &mut self.rng;
        let mut meas = |std: &Option<Normal<f64>>| std.map_or(0.0, |d| d.sample(rng));
        let (n_ang, n_rate) = (self.angle, self.rate);
        (
            [ang_true[0] + meas(&n_ang), ang_true[1] + meas(&n_ang)],
            [dang_true[0] + meas(&n_rate), dang_true[1] + meas(&n_rate)],
        )
    }
}

/// Why a trial must end at a measured swing `swing` of the attached probe: `|beta|` beyond
/// [`MODEL_SWING_LIMIT`], where the model no longer holds (module documentation).
fn swing_out_of_model(swing: &([f64; 2], [f64; 2]), attached: bool) -> Option<String> {
    let beta = swing.0[1];
    let outside = beta.is_nan() || beta.abs() > MODEL_SWING_LIMIT;
    (attached && outside).then(|| {
        format!(
            "ended: the probe swung {beta:.2} rad out of the throw's plane, beyond the model's \
             {MODEL_SWING_LIMIT} rad (its swing angles are singular at pi/2)"
        )
    })
}

/// The release trigger: within the window around the planned release, fire at the step
/// nearest to the crossing of the target by the predicted landing point, or at the end of
/// the window.
struct Trigger {
    window: (f64, f64),
    target: Vector3<f64>,
    dir: Vector3<f64>,
    /// The encoder's frame.
    frame: ThrowFrame,
    /// The predicted landing's distance past the target at the last step \[m\].
    prev_along: Option<f64>,
}

impl Trigger {
    fn new(tc: &ThrowConfig, plan: &ThrowPlan, t_throw: f64) -> Self {
        let t_rel_plan = t_throw + plan.release_time();
        Self {
            window: (t_rel_plan - tc.window_before, t_rel_plan + tc.window_after),
            target: plan.target,
            dir: tc.direction(),
            frame: ThrowFrame::new(tc.yaw),
            prev_along: None,
        }
    }

    /// At time `t` in the flip, with the probe attached: `Some` (whether the trigger fired
    /// rather than the window ended, the prediction) when the probe is to be released now.
    fn check(
        &mut self,
        t: f64,
        e: &Estimate,
        swing: ([f64; 2], [f64; 2]),
        probe: &ProbeParams,
    ) -> Option<(bool, Option<Prediction>)> {
        if t < self.window.0 {
            return None;
        }
        let pred = predicted_landing(e, swing, probe, &self.frame);
        // Release at the step nearest to the crossing: now, if the predicted range is
        // past the target or closer to it than the next step will be.
        let along = pred.map(|(lp, _, _)| (lp - self.target).dot(&self.dir));
        let step = match (along, self.prev_along) {
            (Some(a), Some(b)) => (a - b).max(0.0),
            _ => 0.0,
        };
        let reached = along.is_some_and(|a| a + 0.5 * step >= 0.0);
        self.prev_along = along;
        let forced = t >= self.window.1;
        (reached || forced).then_some((reached, pred))
    }
}

/// Releases the probe at `t`: the record (the true probe's speed, angle and height, the
/// vehicle's velocity, the landing predicted) and the probe's true position.
fn release(
    plant: &mut Plant,
    truth: &QuadState,
    t: f64,
    triggered: bool,
    pred: Option<Prediction>,
) -> (ReleaseRecord, Vector3<f64>) {
    let pv_true = plant
        .probe()
        .map_or(Vector3::zeros(), |p| p.velocity(truth));
    let pp_true = plant
        .probe()
        .map_or(Vector3::zeros(), |p| p.position(truth));
    let _ = plant.release_probe();
    let rec = ReleaseRecord {
        t,
        triggered,
        speed_m_s: pv_true.norm(),
        angle_rad: pv_true.z.atan2(pv_true.xy().norm()),
        height_m: pp_true.z,
        vehicle_velocity: [truth.v.x, truth.v.y, truth.v.z],
        predicted_landing: pred.map_or([f64::NAN; 3], |(lp, _, _)| [lp.x, lp.y, lp.z]),
    };
    (rec, pp_true)
}

/// The figures of one flip-and-throw trial.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ThrowSummary {
    /// Seed.
    pub seed: u64,
    /// Whether every criterion held.
    pub success: bool,
    /// The criteria that failed, in words.
    pub failures: Vec<String>,
    /// How it ended.
    pub outcome: String,
    /// Wanted range \[m\].
    pub range_m: f64,
    /// Target x, y \[m\].
    pub target_m: [f64; 2],
    /// Planned release speed and angle.
    pub planned_speed_m_s: f64,
    /// Planned release angle \[rad\].
    pub planned_angle_rad: f64,
    /// Release speed of the probe (true) [m/s].
    pub release_speed_m_s: Option<f64>,
    /// Release angle above the horizontal (true) \[rad\].
    pub release_angle_rad: Option<f64>,
    /// Release height (true) \[m\].
    pub release_height_m: Option<f64>,
    /// Release time \[s\].
    pub release_time_s: Option<f64>,
    /// Whether the trigger fired (false: released at the end of the window).
    pub release_triggered: bool,
    /// Probe landing x \[m\].
    pub probe_landing_x_m: Option<f64>,
    /// Probe landing y \[m\].
    pub probe_landing_y_m: Option<f64>,
    /// Distance of the landing point from the target \[m\].
    pub probe_landing_error_m: Option<f64>,
    /// Achieved range from the probe's start \[m\].
    pub achieved_range_m: Option<f64>,
    /// Hold point after release.
    pub hold_point_m: [f64; 3],
    /// Time from release until within 0.15 m of the hold point for good \[s\].
    pub recovery_time_s: Option<f64>,
    /// Lowest vehicle height from the throw's start to the end of the hold \[m\].
    pub min_altitude_m: f64,
    /// Largest pitch rate [rad/s] in the throw and recovery.
    pub peak_pitch_rate_rad_s: f64,
    /// Largest tilt (body z from world z) during the throw and recovery \[rad\].
    pub max_tilt_rad: f64,
    /// Largest out-of-plane swing `|beta|` while attached \[rad\] (the model's limit:
    /// [`MODEL_SWING_LIMIT`]).
    pub max_out_of_plane_rad: f64,
    /// Solver fallbacks over the trial (and from the throw to the end of the hold).
    pub fallbacks: u32,
    /// Fallbacks from the throw's start to the end of the hold.
    pub fallbacks_throw: u32,
    /// Solver time \[us\].
    pub solver_time_us: TimeStats,
    /// QP iterations per step, mean.
    pub qp_iterations_mean: f64,
}

/// Summarizes and judges one trial.
pub fn summarize_throw(tr: &ThrowTrial) -> ThrowSummary {
    let tc = &tr.config.throw;
    let start = tc.probe_start();
    let target = tr.plan.target;
    let rel = tr.release;
    let t_throw = tc.throw_start();
    let t_hold_end = rel.map_or(f64::INFINITY, |r| r.t + tc.recover_time + tc.hold_time);
    let window: Vec<&Sample> = tr
        .samples
        .iter()
        .filter(|s| s.t >= t_throw && s.t <= t_hold_end)
        .collect();
    let min_alt = window.iter().map(|s| s.z).fold(f64::INFINITY, f64::min);
    let recovery = rel.and_then(|r| throw_recovery(tr, r.t, t_hold_end));
    let landing = tr.probe_landing.map(|(_, p)| p);
    let err = landing.map(|p| (p - target).xy().norm());
    let achieved = landing.map(|p| (p - start).xy().norm());
    let max_rot = window
        .iter()
        .map(|s| {
            let q =
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(s.qw, s.qx, s.qy, s.qz));
            (q * Vector3::z()).z.clamp(-1.0, 1.0).acos()
        })
        .fold(0.0, f64::max);
    let failures = judge_throw(tr, err, recovery, min_alt);
    let solver = TimeStats::of(tr.samples.iter().map(|s| s.solver_us));
    let iters: Vec<f64> = tr
        .samples
        .iter()
        .map(|s| s.qp_iterations)
        .filter(|v| v.is_finite())
        .collect();
    ThrowSummary {
        seed: tr.config.seed,
        success: failures.is_empty(),
        failures,
        outcome: tr.outcome.clone(),
        range_m: tc.range,
        target_m: [target.x, target.y],
        planned_speed_m_s: tr.plan.release.speed,
        planned_angle_rad: tr.plan.release.angle,
        release_speed_m_s: rel.map(|r| r.speed_m_s),
        release_angle_rad: rel.map(|r| r.angle_rad),
        release_height_m: rel.map(|r| r.height_m),
        release_time_s: rel.map(|r| r.t),
        release_triggered: rel.is_some_and(|r| r.triggered),
        probe_landing_x_m: landing.map(|p| p.x),
        probe_landing_y_m: landing.map(|p| p.y),
        probe_landing_error_m: err,
        achieved_range_m: achieved,
        hold_point_m: [tr.hold_point.x, tr.hold_point.y, tr.hold_point.z],
        recovery_time_s: recovery,
        min_altitude_m: if min_alt.is_finite() { min_alt } else { 0.0 },
        peak_pitch_rate_rad_s: window.iter().map(|s| s.wy.abs()).fold(0.0, f64::max),
        max_tilt_rad: max_rot,
        max_out_of_plane_rad: tr.max_out_of_plane_rad,
        fallbacks: tr.samples.iter().filter(|s| s.fallback).count() as u32,
        fallbacks_throw: window.iter().filter(|s| s.fallback).count() as u32,
        solver_time_us: solver,
        qp_iterations_mean: if iters.is_empty() {
            0.0
        } else {
            iters.iter().sum::<f64>() / iters.len() as f64
        },
    }
}

/// The time from the release at `t_rel` until the vehicle is within
/// [`THROW_RECOVERY_TOL_M`] of the hold point for good, judged up to `t_hold_end`.
fn throw_recovery(tr: &ThrowTrial, t_rel: f64, t_hold_end: f64) -> Option<f64> {
    let rows: Vec<&Sample> = tr
        .samples
        .iter()
        .filter(|s| s.t >= t_rel && s.t <= t_hold_end)
        .collect();
    let pos = |s: &Sample| Vector3::new(s.x, s.y, s.z);
    let last = rows.last()?;
    if (pos(last) - tr.hold_point).norm() >= THROW_RECOVERY_TOL_M {
        return None;
    }
    let last_out = rows
        .iter()
        .rev()
        .find(|s| (pos(s) - tr.hold_point).norm() >= THROW_RECOVERY_TOL_M)
        .map_or(t_rel, |s| s.t);
    Some(last_out - t_rel)
}

/// The criteria a throw trial fails, in words: the vehicle's landing, the release, the
/// probe's landing error `err`, the recovery and the lowest height `min_alt`.
fn judge_throw(
    tr: &ThrowTrial,
    err: Option<f64>,
    recovery: Option<f64>,
    min_alt: f64,
) -> Vec<String> {
    let mut failures = Vec::new();
    if tr.outcome != "landed" {
        failures.push(format!("the vehicle did not land: {}", tr.outcome));
    }
    match tr.release {
        None => failures.push("the probe was not released".into()),
        Some(r) if !r.triggered => failures.push(format!(
            "the predicted range never reached the target; released at the window's end \
             (t = {:.3} s)",
            r.t
        )),
        Some(_) => {}
    }
    match err {
        None => failures.push("the probe did not land".into()),
        Some(e) if e > LANDING_TOL_M => failures.push(format!(
            "the probe landed {e:.2} m from the target (limit {LANDING_TOL_M} m)"
        )),
        Some(_) => {}
    }
    if let Some(t) = tr.probe_struck {
        failures.push(format!(
            "the probe hit the ground while attached at t = {t:.2} s"
        ));
    }
    match recovery {
        None => failures.push(format!(
            "the vehicle did not settle within {THROW_RECOVERY_TOL_M} m of the hold point"
        )),
        Some(t) if t > THROW_RECOVERY_MAX_S => failures.push(format!(
            "recovery took {t:.2} s (limit {THROW_RECOVERY_MAX_S} s)"
        )),
        Some(_) => {}
    }
    if min_alt < THROW_MIN_ALTITUDE_M {
        failures.push(format!(
            "the vehicle went down to {min_alt:.2} m (limit {THROW_MIN_ALTITUDE_M} m)"
        ));
    }
    failures
}

/// The landing errors of a run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LandingErrors {
    /// Per trial, in seed order (`None`: the probe did not land).
    pub per_trial: Vec<Option<f64>>,
    /// The largest (`None` if a probe did not land).
    pub worst: Option<f64>,
    /// The mean over the trials that landed.
    pub mean: Option<f64>,
}

/// The figures of all trials at one range.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ThrowRunSummary {
    /// Always `"flip-throw"`.
    pub mission: String,
    /// Wanted range \[m\].
    pub range_m: f64,
    /// Whether every trial met every criterion.
    pub success: bool,
    /// Trials flown.
    pub trials: usize,
    /// Trials that met every criterion.
    pub successes: usize,
    /// `successes / trials`.
    pub success_rate: f64,
    /// Planned release speed [m/s] (the same for every trial: the plan is deterministic).
    pub planned_speed_m_s: f64,
    /// Planned release angle \[rad\].
    pub planned_angle_rad: f64,
    /// Landing x of the probe per trial \[m\].
    pub probe_landing_x_m: Vec<Option<f64>>,
    /// Landing y of the probe per trial \[m\].
    pub probe_landing_y_m: Vec<Option<f64>>,
    /// Distance of each landing from the target \[m\].
    pub probe_landing_error_m: LandingErrors,
    /// Release speed per trial [m/s].
    pub release_speed_m_s: Vec<Option<f64>>,
    /// Release angle per trial \[rad\].
    pub release_angle_rad: Vec<Option<f64>>,
    /// Longest recovery \[s\] (`None` if a trial did not recover).
    pub recovery_time_s_worst: Option<f64>,
    /// Lowest vehicle height from the throw to the end of the hold over all trials \[m\].
    pub min_altitude_m: f64,
    /// Solver fallbacks over all trials.
    pub fallbacks: u32,
    /// Solver time over all trials: the mean of the means, the largest p99 and max \[us\].
    pub solver_time_us: TimeStats,
    /// Every trial.
    pub trial_summaries: Vec<ThrowSummary>,
}

/// Aggregates the trials of one range.
pub fn aggregate_throw(range: f64, trials: &[ThrowSummary]) -> ThrowRunSummary {
    let successes = trials.iter().filter(|t| t.success).count();
    let errs: Vec<Option<f64>> = trials.iter().map(|t| t.probe_landing_error_m).collect();
    let landed: Vec<f64> = errs.iter().flatten().copied().collect();
    let worst = if landed.len() == errs.len() {
        landed.iter().copied().reduce(f64::max)
    } else {
        None
    };
    let rec: Vec<Option<f64>> = trials.iter().map(|t| t.recovery_time_s).collect();
    let n = trials.len().max(1) as f64;
    ThrowRunSummary {
        mission: "flip-throw".into(),
        range_m: range,
        success: !trials.is_empty() && successes == trials.len(),
        trials: trials.len(),
        successes,
        success_rate: successes as f64 / n,
        planned_speed_m_s: trials.first().map_or(f64::NAN, |t| t.planned_speed_m_s),
        planned_angle_rad: trials.first().map_or(f64::NAN, |t| t.planned_angle_rad),
        probe_landing_x_m: trials.iter().map(|t| t.probe_landing_x_m).collect(),
        probe_landing_y_m: trials.iter().map(|t| t.probe_landing_y_m).collect(),
        probe_landing_error_m: LandingErrors {
            worst,
            mean: (!landed.is_empty()).then(|| landed.iter().sum::<f64>() / landed.len() as f64),
            per_trial: errs,
        },
        release_speed_m_s: trials.iter().map(|t| t.release_speed_m_s).collect(),
        release_angle_rad: trials.iter().map(|t| t.release_angle_rad).collect(),
        recovery_time_s_worst: if rec.iter().all(Option::is_some) {
            rec.iter().flatten().copied().reduce(f64::max)
        } else {
            None
        },
        min_altitude_m: trials
            .iter()
            .map(|t| t.min_altitude_m)
            .fold(f64::INFINITY, f64::min),
        fallbacks: trials.iter().map(|t| t.fallbacks).sum(),
        solver_time_us: TimeStats {
            mean: trials.iter().map(|t| t.solver_time_us.mean).sum::<f64>() / n,
            p99: trials
                .iter()
                .map(|t| t.solver_time_us.p99)
                .fold(0.0, f64::max),
            max: trials
                .iter()
                .map(|t| t.solver_time_us.max)
                .fold(0.0, f64::max),
            count: trials.iter().map(|t| t.solver_time_us.count).sum(),
        },
        trial_summaries: trials.to_vec(),
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_string(), |x| format!("{x:.digits$}"))
}

/// The table of one or more ranges: a row per range (an unreachable range shows the
/// planner's reason), then each range's landing points.
pub fn throw_table(rows: &[(f64, Result<ThrowRunSummary, String>)]) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:>7} {:>7} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9} {:>8} {:>9}  verdict",
        "range",
        "trials",
        "V plan",
        "θ plan",
        "V rel",
        "err mean",
        "err max",
        "recovery",
        "min z",
        "fallback"
    );
    let _ = writeln!(
        out,
        "{:>7} {:>7} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9} {:>8} {:>9}",
        "[m]", "", "[m/s]", "[deg]", "[m/s]", "[m]", "[m]", "[s]", "[m]", ""
    );
    for (range, row) in rows {
        match row {
            Err(e) => {
                let _ = writeln!(out, "{range:>7.1}  unreachable: {e}");
            }
            Ok(r) => {
                let vrel: Vec<f64> = r.release_speed_m_s.iter().flatten().copied().collect();
                let vmean =
                    (!vrel.is_empty()).then(|| vrel.iter().sum::<f64>() / vrel.len() as f64);
                let _ = writeln!(
                    out,
                    "{:>7.1} {:>7} {:>8.2} {:>8.1} {:>8} {:>9} {:>9} {:>9} {:>8.2} {:>9}  {}",
                    r.range_m,
                    format!("{}/{}", r.successes, r.trials),
                    r.planned_speed_m_s,
                    r.planned_angle_rad.to_degrees(),
                    opt(vmean, 2),
                    opt(r.probe_landing_error_m.mean, 3),
                    opt(r.probe_landing_error_m.worst, 3),
                    opt(r.recovery_time_s_worst, 2),
                    r.min_altitude_m,
                    r.fallbacks,
                    if r.success { "ok" } else { "FAILED" }
                );
            }
        }
    }
    for (_, row) in rows {
        let Ok(r) = row else { continue };
        let _ = writeln!(
            out,
            "range {:.1} m, target x = {:.2} m: landing points (seed: x, y, error)",
            r.range_m,
            r.trial_summaries
                .first()
                .map_or(f64::NAN, |t| t.target_m[0])
        );
        for t in &r.trial_summaries {
            let _ = writeln!(
                out,
                "  {:>4}: {:>8} {:>7} {:>7}{}",
                t.seed,
                opt(t.probe_landing_x_m, 3),
                opt(t.probe_landing_y_m, 3),
                opt(t.probe_landing_error_m, 3),
                if t.success {
                    String::new()
                } else {
                    format!("  FAILED: {}", t.failures.join("; "))
                }
            );
        }
    }
    out
}

/// The side view of a trial for [`crate::plot::write_throw_plot`]: distances along the throw
/// from the probe's start.
pub fn side_view(tr: &ThrowTrial) -> crate::plot::ThrowView {
    let tc = &tr.config.throw;
    let dir = tc.direction();
    let s = tc.probe_start();
    let along = |x: f64, y: f64| (Vector3::new(x, y, 0.0) - Vector3::new(s.x, s.y, 0.0)).dot(&dir);
    crate::plot::ThrowView {
        probe: tr
            .probe_track
            .iter()
            .map(|p| (along(p[1], p[2]), p[3]))
            .collect(),
        vehicle: tr
            .samples
            .iter()
            .step_by(10)
            .map(|v| (along(v.x, v.y), v.z))
            .collect(),
        release: tr.release.and_then(|r| {
            tr.probe_track
                .iter()
                .find(|p| (p[0] - r.t).abs() < 1e-9)
                .map(|p| (along(p[1], p[2]), p[3]))
        }),
        landing: tr.probe_landing.map(|(_, p)| along(p.x, p.y)),
        target: tc.range,
        tolerance: LANDING_TOL_M,
    }
}
