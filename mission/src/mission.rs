//! The paper's missions as a state machine over reference segments.
//!
//! A mission is a sequence of [`Phase`]s. Entering a phase builds the reference *plan* from
//! there on: time-stamped [`Segment`]s (smooth quintic legs, holds, the flip, the landing
//! descent), so a controller can read the reference anywhere in its horizon, across phase
//! boundaries (the NMPC sees the flip coming during the ascent). Transitions that depend on
//! the vehicle (settled at a waypoint, touchdown, pose lost) are taken in [`Mission::update`].
//!
//! The flip (the paper's "ascend, flip, recover"): an ascent that ends with upward speed,
//! then a full pitch rotation at the reference rate (5*pi rad/s, 0.4 s) about body y with a
//! low constant thrust; the position reference in the flip is the trajectory that rotation
//! and thrust produce (ballistic plus the rotating thrust, integrated in closed form), so the
//! references never contradict each other; then a smooth recovery leg back to the rally
//! point and a hold. A positive pitch rate tips the nose down (body FLU): a forward flip.
//!
//! Failsafe (the paper's trial 9): when the pose is lost for longer than
//! [`MissionConfig::pose_timeout`], the mission switches to return mode from wherever it is:
//! level out and climb, fly home at the return altitude, land.

use core::f64::consts::PI;

use nalgebra::{UnitQuaternion, Vector3};

/// Gravity [m/s^2] (the models' value).
pub const G: f64 = 9.81;

/// Mission phases, in the order of the flip mission.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Phase {
    /// On the ground, then climbing to the take-off point.
    Takeoff,
    /// Flying to the rally point and settling there.
    Rally,
    /// Accelerating upwards before the flip.
    Ascend,
    /// The pitch rotation.
    Flip,
    /// Back to the rally point after the flip.
    Recover,
    /// Holding a point.
    Hold,
    /// A position step (the `step` mission).
    Step,
    /// Flying home (also the failsafe's climb and return).
    ReturnHome,
    /// Descending to touchdown.
    Land,
    /// On the ground, motors off.
    Landed,
}

impl Phase {
    /// Every phase, indexed by [`Phase::index`].
    pub const ALL: [Phase; 10] = [
        Phase::Takeoff,
        Phase::Rally,
        Phase::Ascend,
        Phase::Flip,
        Phase::Recover,
        Phase::Hold,
        Phase::Step,
        Phase::ReturnHome,
        Phase::Land,
        Phase::Landed,
    ];

    /// Position in [`Phase::ALL`] (the `phase` column of the log).
    pub fn index(self) -> u8 {
        self as u8
    }

    /// Lower-case name, as in the summary and the plots.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Takeoff => "takeoff",
            Phase::Rally => "rally",
            Phase::Ascend => "ascend",
            Phase::Flip => "flip",
            Phase::Recover => "recover",
            Phase::Hold => "hold",
            Phase::Step => "step",
            Phase::ReturnHome => "return",
            Phase::Land => "land",
            Phase::Landed => "landed",
        }
    }

    /// The names of [`Phase::ALL`].
    pub fn names() -> [&'static str; 10] {
        Self::ALL.map(Phase::name)
    }
}

/// Which mission to fly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MissionKind {
    /// Take off, rally point, ascend, flip, recover, hold, return, land (the paper's).
    Flip,
    /// Take off, hold, land.
    Hover,
    /// Take off, hold, a position step, hold, land.
    Step,
}

/// References and timing of the missions. Positions in m (world ENU), times in s.
#[derive(Clone, Debug, PartialEq)]
pub struct MissionConfig {
    /// Which mission.
    pub kind: MissionKind,
    /// Home: where the vehicle starts on the ground and lands again.
    pub home: Vector3<f64>,
    /// Take-off point (the paper: (0, 0, 2)).
    pub takeoff_point: Vector3<f64>,
    /// Rally point, where the flip happens and which is held after it (the paper: (4, 0, 2)).
    pub rally_point: Vector3<f64>,
    /// Heading \[rad\] (0: body x along world x).
    pub yaw: f64,
    /// Duration of the take-off leg.
    pub takeoff_time: f64,
    /// Duration of the leg to the rally point.
    pub rally_time: f64,
    /// Minimum settling time at the end of a leg before the next phase.
    pub settle_time: f64,
    /// Position error below which the vehicle counts as settled \[m\].
    pub settle_tol: f64,
    /// Longest wait for settling; the mission goes on after it (the summary judges).
    pub settle_timeout: f64,
    /// Duration of the ascent before the flip.
    pub ascend_time: f64,
    /// Upward speed at the end of the ascent [m/s].
    pub ascend_speed: f64,
    /// Pitch-rate reference of the flip [rad/s] (the paper: 5*pi).
    pub flip_rate: f64,
    /// Rotation of the flip \[rad\] (2*pi: one full turn).
    pub flip_angle: f64,
    /// Angular acceleration of the flip's rate reference [rad/s^2]: the rate ramps up to
    /// `flip_rate` and down to zero at the end of the turn at this rate (infinite: a step
    /// of the rate, the paper's flip).
    pub flip_accel: f64,
    /// Mass-normalized collective thrust during the flip [m/s^2].
    pub flip_thrust: f64,
    /// Duration of the recovery leg from the flip's end back to the rally point.
    pub recover_time: f64,
    /// Duration of the hold at the rally point after the recovery leg.
    pub hold_time: f64,
    /// Duration of the hold of the `hover` mission.
    pub hover_time: f64,
    /// Position step of the `step` mission \[m\].
    pub step: Vector3<f64>,
    /// Duration of the return leg.
    pub return_time: f64,
    /// Duration of the smooth part of the landing, down to `land_flare_height`.
    pub land_time: f64,
    /// Height where the smooth descent hands over to the constant final descent \[m\].
    pub land_flare_height: f64,
    /// Final descent speed until touchdown [m/s].
    pub land_speed: f64,
    /// Pose loss longer than this triggers return mode \[s\].
    pub pose_timeout: f64,
    /// Return mode: climb by this much above the current height first \[m\].
    pub failsafe_climb: f64,
    /// Return mode: duration of the climb (and level-out).
    pub failsafe_climb_time: f64,
}

impl MissionConfig {
    /// The paper's flip mission with our timing.
    pub fn flip() -> Self {
        Self {
            kind: MissionKind::Flip,
            home: Vector3::zeros(),
            takeoff_point: Vector3::new(0.0, 0.0, 2.0),
            rally_point: Vector3::new(4.0, 0.0, 2.0),
            yaw: 0.0,
            takeoff_time: 3.0,
            rally_time: 3.0,
            settle_time: 1.0,
            settle_tol: 0.1,
            settle_timeout: 10.0,
            ascend_time: 0.6,
            ascend_speed: 2.5,
            flip_rate: 5.0 * PI,
            flip_angle: 2.0 * PI,
            flip_accel: f64::INFINITY,
            flip_thrust: 5.0,
            recover_time: 1.5,
            hold_time: 2.5,
            hover_time: 5.0,
            step: Vector3::new(1.0, 0.0, 0.0),
            return_time: 3.5,
            land_time: 3.0,
            land_flare_height: 0.3,
            land_speed: 0.3,
            pose_timeout: 0.05,
            failsafe_climb: 1.0,
            failsafe_climb_time: 1.5,
        }
    }

    /// The same timing for another mission.
    pub fn for_kind(kind: MissionKind) -> Self {
        Self {
            kind,
            ..Self::flip()
        }
    }

    /// Duration of the flip rotation \[s\].
    pub fn flip_time(&self) -> f64 {
        self.flip_profile().duration()
    }

    /// The flip's rate profile.
    pub fn flip_profile(&self) -> FlipProfile {
        FlipProfile {
            rate: self.flip_rate,
            accel: self.flip_accel,
            angle: self.flip_angle,
        }
    }
}

/// The flip's pitch-rate reference: up to `rate` at `accel`, on, then down to zero at `accel`
/// where the rotation reaches `angle` (a triangle if `angle` is too short for `rate`); with
/// an infinite `accel`, a step of `rate` for `angle / rate`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlipProfile {
    /// Top pitch rate [rad/s].
    pub rate: f64,
    /// Angular acceleration [rad/s^2].
    pub accel: f64,
    /// Rotation \[rad\].
    pub angle: f64,
}

impl FlipProfile {
    fn ramped(&self) -> bool {
        self.accel.is_finite() && self.accel > 0.0 && self.rate.abs() > 1e-9
    }

    /// The top rate reached [rad/s] (signed as `rate`).
    fn top(&self) -> f64 {
        if !self.ramped() {
            return self.rate;
        }
        let triangle = (self.angle.abs() * self.accel).sqrt();
        self.rate.signum() * self.rate.abs().min(triangle)
    }

    /// Duration of the turn \[s\].
    pub fn duration(&self) -> f64 {
        let w = self.top().abs();
        if w <= 1e-9 {
            return 0.0;
        }
        if !self.ramped() {
            return (self.angle / self.rate).abs();
        }
        self.angle.abs() / w + w / self.accel
    }

    /// Rotation and rate `tau` seconds in.
    pub fn at(&self, tau: f64) -> (f64, f64) {
        if !self.ramped() {
            return (self.rate * tau, self.rate);
        }
        let w = self.top();
        let s = w.signum();
        let ta = w.abs() / self.accel;
        let total = self.duration();
        let tau = tau.clamp(0.0, total);
        if tau < ta {
            (0.5 * s * self.accel * tau * tau, s * self.accel * tau)
        } else if tau <= total - ta {
            (0.5 * w * ta + w * (tau - ta), w)
        } else {
            let r = total - tau;
            (
                self.angle - 0.5 * s * self.accel * r * r,
                s * self.accel * r,
            )
        }
    }
}

impl Default for MissionConfig {
    fn default() -> Self {
        Self::flip()
    }
}

/// The reference at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefPoint {
    /// Phase this instant belongs to.
    pub phase: Phase,
    /// Position \[m\].
    pub p: Vector3<f64>,
    /// Velocity [m/s].
    pub v: Vector3<f64>,
    /// Acceleration [m/s^2].
    pub a: Vector3<f64>,
    /// Heading \[rad\].
    pub yaw: f64,
    /// Attitude reference where the mission prescribes one (the flip); otherwise the
    /// attitude follows from `a` and `yaw`.
    pub attitude: Option<UnitQuaternion<f64>>,
    /// Body-rate reference [rad/s] (the flip's pitch rate, else zero).
    pub rate: Vector3<f64>,
    /// Mass-normalized collective thrust reference where prescribed (the flip) [m/s^2].
    pub thrust: Option<f64>,
}

impl RefPoint {
    /// Mass-normalized collective thrust this reference needs [m/s^2].
    pub fn thrust_c(&self) -> f64 {
        self.thrust
            .unwrap_or_else(|| (self.a + Vector3::z() * G).norm())
    }

    /// The attitude reference: the prescribed one, or the one that points the thrust along
    /// `a + g e3` with heading `yaw`.
    pub fn attitude_ref(&self) -> UnitQuaternion<f64> {
        self.attitude
            .unwrap_or_else(|| attitude_from_thrust(&(self.a + Vector3::z() * G), self.yaw))
    }
}

/// The attitude whose body z points along `f` with heading `yaw` (Lee's construction:
/// b3 = f/|f|, b2 = b3 x b1c / |.|, b1 = b2 x b3 with b1c = (cos yaw, sin yaw, 0)).
/// Level at `yaw` when `f` is zero or along b1c.
pub fn attitude_from_thrust(f: &Vector3<f64>, yaw: f64) -> UnitQuaternion<f64> {
    let rot = rotation_from_thrust(f, yaw);
    UnitQuaternion::from_rotation_matrix(&rot)
}

/// [`attitude_from_thrust`] as a rotation (columns b1, b2, b3).
pub fn rotation_from_thrust(f: &Vector3<f64>, yaw: f64) -> nalgebra::Rotation3<f64> {
    let n = f.norm();
    let b3 = if n > 1e-9 && n.is_finite() {
        f / n
    } else {
        Vector3::z()
    };
    let b1c = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
    let c = b3.cross(&b1c);
    let b2 = if c.norm() > 1e-6 {
        c.normalize()
    } else {
        Vector3::new(-yaw.sin(), yaw.cos(), 0.0)
    };
    let b1 = b2.cross(&b3);
    nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[b1, b2, b3]))
}

/// A piece of reference trajectory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Segment {
    /// Stay at a point.
    Hold(Vector3<f64>),
    /// A quintic from (p0, v0, a0) to (p1, v1, a1) in `duration` (per axis, minimum-jerk
    /// shape for rest-to-rest legs); held at (p1, v1 = 0, a1 = 0) after its end.
    Quintic {
        /// Start position, velocity, acceleration.
        start: [Vector3<f64>; 3],
        /// End position, velocity, acceleration.
        end: [Vector3<f64>; 3],
        /// Duration \[s\].
        duration: f64,
    },
    /// The flip rotation from position `p0` and velocity `v0`.
    Flip {
        /// Start position.
        p0: Vector3<f64>,
        /// Start velocity.
        v0: Vector3<f64>,
        /// Pitch rate [rad/s].
        rate: f64,
        /// The rate profile (a step of `rate` when not ramped).
        profile: FlipProfile,
        /// Mass-normalized thrust [m/s^2].
        thrust: f64,
        /// Heading \[rad\].
        yaw: f64,
    },
    /// Constant-speed vertical descent from `p0`.
    Descend {
        /// Start position.
        p0: Vector3<f64>,
        /// Speed [m/s] (positive: down).
        speed: f64,
    },
}

impl Segment {
    /// The reference `tau` seconds into this segment, labelled `phase`, with heading `yaw`.
    pub fn reference(&self, phase: Phase, yaw: f64, tau: f64) -> RefPoint {
        let (p, v, a, attitude, rate, thrust) = eval_segment(self, tau);
        RefPoint {
            phase,
            p,
            v,
            a,
            yaw,
            attitude,
            rate,
            thrust,
        }
    }
}

/// One axis of a quintic: `start` and `end` are (position, velocity, acceleration), `t` the
/// time into it, `tt` its duration.
fn quintic_1d(start: [f64; 3], end: [f64; 3], t: f64, tt: f64) -> [f64; 3] {
    let [p0, v0, a0] = start;
    let [p1, v1, a1] = end;
    if tt <= 0.0 {
        return [p1, v1, a1];
    }
    let s = (t / tt).clamp(0.0, 1.0);
    let d = p1 - p0;
    let c0 = p0;
    let c1 = v0 * tt;
    let c2 = 0.5 * a0 * tt * tt;
    let c3 = 10.0 * d - (6.0 * v0 + 4.0 * v1) * tt - (1.5 * a0 - 0.5 * a1) * tt * tt;
    let c4 = -15.0 * d + (8.0 * v0 + 7.0 * v1) * tt + (1.5 * a0 - a1) * tt * tt;
    let c5 = 6.0 * d - 3.0 * (v0 + v1) * tt - (0.5 * a0 - 0.5 * a1) * tt * tt;
    let p = c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * c5))));
    let dp = c1 + s * (2.0 * c2 + s * (3.0 * c3 + s * (4.0 * c4 + s * 5.0 * c5)));
    let ddp = 2.0 * c2 + s * (6.0 * c3 + s * (12.0 * c4 + s * 20.0 * c5));
    [p, dp / tt, ddp / (tt * tt)]
}

/// Position, velocity, acceleration, attitude, rate and thrust of a segment `tau` seconds
/// after its start.
#[allow(clippy::type_complexity)]
fn eval_segment(
    seg: &Segment,
    tau: f64,
) -> (
    Vector3<f64>,
    Vector3<f64>,
    Vector3<f64>,
    Option<UnitQuaternion<f64>>,
    Vector3<f64>,
    Option<f64>,
) {
    let z = Vector3::zeros();
    match *seg {
        Segment::Hold(p) => (p, z, z, None, z, None),
        Segment::Quintic {
            start,
            end,
            duration,
        } => {
            if tau >= duration {
                return (end[0], z, z, None, z, None);
            }
            let mut out = [Vector3::zeros(); 3];
            for i in 0..3 {
                let r = quintic_1d(
                    [start[0][i], start[1][i], start[2][i]],
                    [end[0][i], end[1][i], end[2][i]],
                    tau,
                    duration,
                );
                out[0][i] = r[0];
                out[1][i] = r[1];
                out[2][i] = r[2];
            }
            (out[0], out[1], out[2], None, z, None)
        }
        Segment::Flip {
            p0,
            v0,
            rate,
            profile,
            thrust,
            yaw,
        } => {
            if profile.ramped() {
                let (p, v, a, q, w) = ramped_flip_state(&p0, &v0, &profile, thrust, yaw, tau);
                return (p, v, a, Some(q), Vector3::new(0.0, w, 0.0), Some(thrust));
            }
            let (p, v, a, q) = flip_state(&p0, &v0, rate, thrust, yaw, tau);
            (p, v, a, Some(q), Vector3::new(0.0, rate, 0.0), Some(thrust))
        }
        Segment::Descend { p0, speed } => (
            p0 - Vector3::z() * (speed * tau),
            -Vector3::z() * speed,
            z,
            None,
            z,
            None,
        ),
    }
}

/// Closed-form state of the flip `tau` seconds in: rotation theta = rate * tau about body y
/// (after the heading), constant mass-normalized thrust `c` along body z, gravity.
/// Returns position, velocity, acceleration, attitude.
pub fn flip_state(
    p0: &Vector3<f64>,
    v0: &Vector3<f64>,
    rate: f64,
    c: f64,
    yaw: f64,
    tau: f64,
) -> (
    Vector3<f64>,
    Vector3<f64>,
    Vector3<f64>,
    UnitQuaternion<f64>,
) {
    let th = rate * tau;
    let heading = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    let q = heading * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), th);
    let g = Vector3::z() * G;
    // In the heading frame, body z = (sin th, 0, cos th).
    let (a_loc, v_loc, p_loc) = if rate.abs() > 1e-9 {
        let w = rate;
        (
            Vector3::new(th.sin(), 0.0, th.cos()) * c,
            Vector3::new(1.0 - th.cos(), 0.0, th.sin()) * (c / w),
            Vector3::new(tau - th.sin() / w, 0.0, (1.0 - th.cos()) / w) * (c / w),
        )
    } else {
        (
            Vector3::new(0.0, 0.0, c),
            Vector3::new(0.0, 0.0, c * tau),
            Vector3::new(0.0, 0.0, 0.5 * c * tau * tau),
        )
    };
    let a = heading * a_loc - g;
    let v = v0 + heading * v_loc - g * tau;
    let p = p0 + v0 * tau + heading * p_loc - g * (0.5 * tau * tau);
    (p, v, a, q)
}

/// [`flip_state`] for a ramped rate profile, integrated numerically (1 ms steps, the
/// midpoint of each step's rotation): position, velocity, acceleration, attitude, rate.
pub fn ramped_flip_state(
    p0: &Vector3<f64>,
    v0: &Vector3<f64>,
    profile: &FlipProfile,
    c: f64,
    yaw: f64,
    tau: f64,
) -> (
    Vector3<f64>,
    Vector3<f64>,
    Vector3<f64>,
    UnitQuaternion<f64>,
    f64,
) {
    let heading = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    let g = Vector3::z() * G;
    let thrust = |th: f64| heading * Vector3::new(th.sin(), 0.0, th.cos()) * c - g;
    let tau = tau.max(0.0);
    let steps = (tau / 1e-3).ceil().max(1.0);
    let h = tau / steps;
    let (mut p, mut v) = (*p0, *v0);
    for i in 0..steps as usize {
        let (th, _) = profile.at((i as f64 + 0.5) * h);
        let a = thrust(th);
        p += v * h + a * (0.5 * h * h);
        v += a * h;
    }
    let (th, w) = profile.at(tau);
    let q = heading * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), th);
    (p, v, thrust(th), q, w)
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct PlanSeg {
    phase: Phase,
    t0: f64,
    seg: Segment,
}

/// What the mission needs to know of the vehicle at each step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MissionInput {
    /// Time \[s\].
    pub t: f64,
    /// Estimated position \[m\].
    pub p: Vector3<f64>,
    /// Estimated velocity [m/s].
    pub v: Vector3<f64>,
    /// Whether the pose source is delivering.
    pub pose_valid: bool,
    /// Whether the vehicle is on the ground (after having flown: touchdown).
    pub on_ground: bool,
}

/// A phase change, for the log and the summary.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transition {
    /// Time \[s\].
    pub t: f64,
    /// The phase entered.
    pub phase: Phase,
    /// Whether it was entered by the failsafe.
    pub failsafe: bool,
}

/// The mission state machine.
#[derive(Clone, Debug)]
pub struct Mission {
    cfg: MissionConfig,
    phase: Phase,
    phase_start: f64,
    plan: Vec<PlanSeg>,
    failsafe: Option<f64>,
    pose_lost_since: Option<f64>,
    airborne: bool,
    transitions: Vec<Transition>,
}

impl Mission {
    /// A mission at time 0, on the ground at home, phase [`Phase::Takeoff`].
    pub fn new(cfg: MissionConfig) -> Self {
        let mut m = Self {
            phase: Phase::Takeoff,
            phase_start: 0.0,
            plan: Vec::new(),
            failsafe: None,
            pose_lost_since: None,
            airborne: false,
            transitions: Vec::new(),
            cfg,
        };
        let home = m.cfg.home;
        let to = m.cfg.takeoff_point;
        let dur = m.cfg.takeoff_time;
        m.plan = vec![PlanSeg {
            phase: Phase::Takeoff,
            t0: 0.0,
            seg: Segment::Quintic {
                start: [home, Vector3::zeros(), Vector3::zeros()],
                end: [to, Vector3::zeros(), Vector3::zeros()],
                duration: dur,
            },
        }];
        m.transitions.push(Transition {
            t: 0.0,
            phase: Phase::Takeoff,
            failsafe: false,
        });
        m
    }

    /// The configuration.
    pub fn config(&self) -> &MissionConfig {
        &self.cfg
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// When the current phase began \[s\].
    pub fn phase_start(&self) -> f64 {
        self.phase_start
    }

    /// When return mode engaged, if it did \[s\].
    pub fn failsafe_since(&self) -> Option<f64> {
        self.failsafe
    }

    /// Every phase change so far (the first is the take-off at t = 0).
    pub fn transitions(&self) -> &[Transition] {
        &self.transitions
    }

    /// Whether the mission is over (landed).
    pub fn done(&self) -> bool {
        self.phase == Phase::Landed
    }

    /// The reference at time `t` (any time: the current plan is extended by its last
    /// segment; before the plan's start, its first point).
    pub fn reference(&self, t: f64) -> RefPoint {
        let idx = self
            .plan
            .iter()
            .rposition(|s| s.t0 <= t)
            .unwrap_or_default();
        let Some(ps) = self.plan.get(idx) else {
            let p = self.cfg.home;
            return RefPoint {
                phase: self.phase,
                p,
                v: Vector3::zeros(),
                a: Vector3::zeros(),
                yaw: self.cfg.yaw,
                attitude: None,
                rate: Vector3::zeros(),
                thrust: None,
            };
        };
        let (p, v, a, attitude, rate, thrust) = eval_segment(&ps.seg, (t - ps.t0).max(0.0));
        RefPoint {
            phase: ps.phase,
            p,
            v,
            a,
            yaw: self.cfg.yaw,
            attitude,
            rate,
            thrust,
        }
    }

    fn enter(&mut self, t: f64, phase: Phase) {
        self.phase = phase;
        self.phase_start = t;
        self.transitions.push(Transition {
            t,
            phase,
            failsafe: self.failsafe.is_some(),
        });
    }

    fn replan(&mut self, segs: Vec<PlanSeg>) {
        self.plan = segs;
    }

    fn quintic_rest(from: Vector3<f64>, to: Vector3<f64>, duration: f64) -> Segment {
        Segment::Quintic {
            start: [from, Vector3::zeros(), Vector3::zeros()],
            end: [to, Vector3::zeros(), Vector3::zeros()],
            duration,
        }
    }

    fn landing(&self, t0: f64, from: Vector3<f64>) -> Vec<PlanSeg> {
        let flare = Vector3::new(from.x, from.y, self.cfg.home.z + self.cfg.land_flare_height);
        let speed = self.cfg.land_speed;
        vec![
            PlanSeg {
                phase: Phase::Land,
                t0,
                seg: Segment::Quintic {
                    start: [from, Vector3::zeros(), Vector3::zeros()],
                    end: [flare, -Vector3::z() * speed, Vector3::zeros()],
                    duration: self.cfg.land_time,
                },
            },
            PlanSeg {
                phase: Phase::Land,
                t0: t0 + self.cfg.land_time,
                seg: Segment::Descend { p0: flare, speed },
            },
        ]
    }

    fn settled(&self, inp: &MissionInput, target: &Vector3<f64>, elapsed: f64, leg: f64) -> bool {
        let ok = (inp.p - target).norm() < self.cfg.settle_tol && inp.v.norm() < 0.3;
        elapsed >= leg + self.cfg.settle_time && (ok || elapsed >= leg + self.cfg.settle_timeout)
    }

    /// Advances the state machine to time `inp.t`; returns the phase after the update.
    pub fn update(&mut self, inp: &MissionInput) -> Phase {
        let t = inp.t;
        if !inp.on_ground {
            self.airborne = true;
        }
        if inp.pose_valid {
            self.pose_lost_since = None;
        } else if self.pose_lost_since.is_none() {
            self.pose_lost_since = Some(t);
        }
        if self.pose_failsafe_due(t) {
            self.start_failsafe_return(inp);
            return self.phase;
        }
        let elapsed = t - self.phase_start;
        let here = self.reference(t);
        match self.phase {
            Phase::Takeoff => self.after_takeoff(inp, elapsed),
            Phase::Rally => {
                let rp = self.cfg.rally_point;
                if self.settled(inp, &rp, elapsed, self.cfg.rally_time) {
                    self.enter(t, Phase::Ascend);
                    self.replan(self.flip_plan(t, rp));
                }
            }
            Phase::Ascend | Phase::Flip | Phase::Recover => {
                // Time-driven: the plan labels its segments.
                if here.phase != self.phase {
                    self.enter(t, here.phase);
                }
            }
            Phase::Hold => self.after_hold(t, elapsed, here.p),
            Phase::Step => {
                if elapsed >= 4.0 {
                    self.start_landing(t, here.p);
                }
            }
            Phase::ReturnHome => self.after_return(inp, elapsed, here.phase),
            Phase::Land => {
                if inp.on_ground && self.airborne {
                    self.enter(t, Phase::Landed);
                    let p = Vector3::new(inp.p.x, inp.p.y, self.cfg.home.z);
                    self.hold_at(t, Phase::Landed, p);
                }
            }
            Phase::Landed => {}
        }
        self.phase
    }

    /// Whether the failsafe engages at `t`: the pose lost for longer than the timeout while
    /// flying, outside the landing, and not engaged before.
    fn pose_failsafe_due(&self, t: f64) -> bool {
        self.failsafe.is_none()
            && self.airborne
            && !matches!(self.phase, Phase::Land | Phase::Landed)
            && self
                .pose_lost_since
                .is_some_and(|t0| t - t0 >= self.cfg.pose_timeout)
    }

    /// The failsafe's return: climb from where the vehicle is, fly home at that height,
    /// land.
    fn start_failsafe_return(&mut self, inp: &MissionInput) {
        let t = inp.t;
        self.failsafe = Some(t);
        self.enter(t, Phase::ReturnHome);
        let alt = inp.p.z.max(self.cfg.takeoff_point.z) + self.cfg.failsafe_climb;
        let climb = Vector3::new(inp.p.x, inp.p.y, alt);
        let home_hi = Vector3::new(self.cfg.home.x, self.cfg.home.y, alt);
        let dist = (home_hi - climb).norm();
        let ret = self.cfg.return_time.max(dist / 1.5);
        let t1 = t + self.cfg.failsafe_climb_time;
        let t2 = t1 + ret;
        let mut plan = vec![
            PlanSeg {
                phase: Phase::ReturnHome,
                t0: t,
                seg: Segment::Quintic {
                    start: [inp.p, inp.v, Vector3::zeros()],
                    end: [climb, Vector3::zeros(), Vector3::zeros()],
                    duration: self.cfg.failsafe_climb_time,
                },
            },
            PlanSeg {
                phase: Phase::ReturnHome,
                t0: t1,
                seg: Self::quintic_rest(climb, home_hi, ret),
            },
        ];
        plan.extend(self.landing(t2 + self.cfg.settle_time, home_hi));
        self.replan(plan);
    }

    /// Settled at the take-off point: to the rally point (flip), or hold there.
    fn after_takeoff(&mut self, inp: &MissionInput, elapsed: f64) {
        let t = inp.t;
        let target = self.cfg.takeoff_point;
        if !self.settled(inp, &target, elapsed, self.cfg.takeoff_time) {
            return;
        }
        match self.cfg.kind {
            MissionKind::Flip => {
                self.enter(t, Phase::Rally);
                let rp = self.cfg.rally_point;
                let seg = Self::quintic_rest(target, rp, self.cfg.rally_time);
                self.replan(vec![PlanSeg {
                    phase: Phase::Rally,
                    t0: t,
                    seg,
                }]);
            }
            MissionKind::Hover | MissionKind::Step => {
                self.enter(t, Phase::Hold);
                self.hold_at(t, Phase::Hold, target);
            }
        }
    }

    /// At the end of the hold (at `p`): return home (flip), land (hover), or step.
    fn after_hold(&mut self, t: f64, elapsed: f64, p: Vector3<f64>) {
        let hold = match self.cfg.kind {
            MissionKind::Flip => self.cfg.hold_time,
            MissionKind::Hover => self.cfg.hover_time,
            MissionKind::Step => self.cfg.settle_time,
        };
        if elapsed < hold {
            return;
        }
        match self.cfg.kind {
            MissionKind::Flip => self.start_return(t, p),
            MissionKind::Hover => self.start_landing(t, p),
            MissionKind::Step => {
                self.enter(t, Phase::Step);
                self.hold_at(t, Phase::Step, p + self.cfg.step);
            }
        }
    }

    /// In the return: land when the plan says so (the failsafe's), or once settled above
    /// home (the mission's).
    fn after_return(&mut self, inp: &MissionInput, elapsed: f64, planned: Phase) {
        let t = inp.t;
        if planned == Phase::Land {
            self.enter(t, Phase::Land);
        } else if self.failsafe.is_none() {
            let home_hi = Vector3::new(self.cfg.home.x, self.cfg.home.y, self.cfg.takeoff_point.z);
            if self.settled(inp, &home_hi, elapsed, self.cfg.return_time) {
                self.start_landing(t, home_hi);
            }
        }
    }

    /// Enters the landing at `t` from `from`.
    fn start_landing(&mut self, t: f64, from: Vector3<f64>) {
        self.enter(t, Phase::Land);
        let plan = self.landing(t, from);
        self.replan(plan);
    }

    /// Plans a hold at `p` from `t`, labelled `phase`.
    fn hold_at(&mut self, t: f64, phase: Phase, p: Vector3<f64>) {
        self.replan(vec![PlanSeg {
            phase,
            t0: t,
            seg: Segment::Hold(p),
        }]);
    }

    fn start_return(&mut self, t: f64, from: Vector3<f64>) {
        self.enter(t, Phase::ReturnHome);
        let home_hi = Vector3::new(self.cfg.home.x, self.cfg.home.y, self.cfg.takeoff_point.z);
        let seg = Self::quintic_rest(from, home_hi, self.cfg.return_time);
        self.replan(vec![PlanSeg {
            phase: Phase::ReturnHome,
            t0: t,
            seg,
        }]);
    }

    /// Ascend, flip, recover, hold: one plan, so the horizon sees across the phases.
    fn flip_plan(&self, t: f64, rp: Vector3<f64>) -> Vec<PlanSeg> {
        let c = &self.cfg;
        let vz = c.ascend_speed;
        let ta = c.ascend_time;
        // Constant acceleration vz/ta would climb vz*ta/2; the quintic with these boundary
        // values stays close to it.
        let top = rp + Vector3::z() * (0.5 * vz * ta);
        let ascend = Segment::Quintic {
            start: [rp, Vector3::zeros(), Vector3::zeros()],
            end: [top, Vector3::z() * vz, Vector3::zeros()],
            duration: ta,
        };
        let t_flip = t + ta;
        let flip = Segment::Flip {
            p0: top,
            v0: Vector3::z() * vz,
            rate: c.flip_rate,
            profile: c.flip_profile(),
            thrust: c.flip_thrust,
            yaw: c.yaw,
        };
        let tf = c.flip_time();
        let (p1, v1, a1, ..) = eval_segment(&flip, tf);
        let t_rec = t_flip + tf;
        let recover = Segment::Quintic {
            start: [p1, v1, a1],
            end: [rp, Vector3::zeros(), Vector3::zeros()],
            duration: c.recover_time,
        };
        vec![
            PlanSeg {
                phase: Phase::Ascend,
                t0: t,
                seg: ascend,
            },
            PlanSeg {
                phase: Phase::Flip,
                t0: t_flip,
                seg: flip,
            },
            PlanSeg {
                phase: Phase::Recover,
                t0: t_rec,
                seg: recover,
            },
            PlanSeg {
                phase: Phase::Hold,
                t0: t_rec + c.recover_time,
                seg: Segment::Hold(rp),
            },
        ]
    }
}
