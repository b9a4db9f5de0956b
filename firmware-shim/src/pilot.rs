//! The controller loop: PX4's state in, the generated NMPC's body-rate + thrust setpoints out,
//! the simulator's mission state machine (`mpc_mission::mission`) in between, the offboard
//! [`Session`] with its failsafes around it. Clocked by the caller ([`Pilot::poll`] every
//! millisecond or so, [`Pilot::on_message`] for everything received); [`run`] is that loop on
//! a [`Link`].
//!
//! * State: ODOMETRY (preferred), or LOCAL_POSITION_NED + ATTITUDE_QUATERNION pairs less than
//!   [`PAIR_WINDOW_US`] apart when no ODOMETRY came for [`ODOMETRY_PREFERENCE_US`] of vehicle
//!   time. A state not newer than the last one (a duplicate, or overtaken on a lossy link) or
//!   not finite is dropped and counted. NED/FRD is converted to the models' ENU/FLU.
//! * Clock: the vehicle's, estimated from the states' timestamps and arrival times (the least
//!   delayed state sets the offset to the wall clock); it runs at the wall clock's rate
//!   between states, never backwards. The mission, the 20 Hz solver and the
//!   setpoint stream ([`PilotConfig::setpoint_rate`]) are scheduled on it, so a simulator that
//!   runs faster than real time still gets a setpoint per simulated period (PX4 scales its
//!   timeouts with its speed-up factor); the session's timeouts run on it too, so between
//!   states (and in a blackout) they are wall time.
//! * Latency: the estimate handed to the solver is the last state brought forward to the
//!   solve time (its age, at most [`MAX_PREDICTION_S`]) under the setpoints sent since
//!   ([`predict`]: rates and thrust as first-order lags, attitude, velocity, position), as
//!   PX4's own output predictor does with the IMU.
//! * Flight: when the session is flying (OFFBOARD and armed), the mission starts at its
//!   take-off from where the vehicle stands (the mission's positions are relative to that
//!   point). When the mission has landed, [`Session::finish`] asks for AUTO.LAND, and PX4
//!   disarms. The mission's own pose-loss return mode is not used: stale odometry is the
//!   session's failsafe (PX4's AUTO.RTL).
//! * Setpoints: the solver's first control, held between solves, through
//!   [`make_setpoint`] (never non-finite, always in range); before the flight, an idle
//!   setpoint (thrust 0: PX4 needs the stream before OFFBOARD, and arms on the ground). In a
//!   failsafe the controller keeps running on the newest state (or its prediction) until
//!   PX4's HEARTBEAT shows it out of OFFBOARD: the stream never pauses while PX4 may still be
//!   listening; then controller and stream stop, so PX4 cannot be switched back to OFFBOARD
//!   onto stale setpoints.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use mpc_mission::controller::{Controller, InnerCommand, NmpcController, OuterStats};
use mpc_mission::estimate::Estimate;
use mpc_mission::log::Sample;
use mpc_mission::mission::{
    G, Mission, MissionConfig, MissionInput, MissionKind, Phase as MissionPhase,
};
use mpc_mission::report::{self, Conditions, Outcome, Touchdown, TrialSummary};
use mpc_mission::vehicle::QuadState;
use nalgebra::{UnitQuaternion, Vector3};

use crate::clock::{RoundTrip, VehicleClock, Verdict};
use crate::frames::{frd_to_flu, ned_to_enu, quat_from_mavlink, quat_ned_frd_to_enu_flu};
use crate::link::{Failsafe, LinkConfig, LinkConfigError, Phase, Session};
use crate::messages::{self, Inbound, LandedState, Px4Mode};
use crate::profile::{FlipPlan, ProfileError, SIH_PARAMS, VehicleProfile, plan_flip};
use crate::setpoint::{Px4Setpoint, RateLimits, SetpointError, ThrustMap, make_setpoint};
use crate::transport::{Link, LinkStats};
use crate::watch::Watch;

/// LOCAL_POSITION_NED and ATTITUDE_QUATERNION closer than this make one state \[us\].
pub const PAIR_WINDOW_US: u64 = 25_000;
/// ODOMETRY is preferred: the pairs are used only when none came for this long \[us\].
pub const ODOMETRY_PREFERENCE_US: u64 = 500_000;
/// The estimate is brought forward by its age, at most this much \[s\].
pub const MAX_PREDICTION_S: f64 = 0.25;
/// The least bound on a state's delay that TIMESYNC's round trips set \[s\].
pub const MIN_DELAY_BOUND_S: f64 = 0.005;
/// After a failsafe PX4 flies the vehicle; the loop waits this long for it to disarm, then
/// ends (the flight has failed either way) \[s\].
pub const HANDOVER_WAIT_S: f64 = 30.0;
/// The landing's slow final descent starts at least this high above the start point \[m\]:
/// EKF2's height was up to 0.8 m high at touchdown on SIH, and from a flare at the
/// simulator's 0.3 m such a vehicle met the ground at 0.74-0.99 m/s, still in the faster
/// part of the descent.
pub const FLARE_HEIGHT_M: f64 = 1.0;
/// TIMESYNC requests go out this often \[s, wall clock\].
pub const TIMESYNC_PERIOD_S: f64 = 0.5;
/// Height above the start point and speed below which the vehicle counts as on the ground.
pub const GROUND_HEIGHT_M: f64 = 0.05;
/// See [`GROUND_HEIGHT_M`] [m/s].
pub const GROUND_SPEED_M_S: f64 = 0.2;

/// Settings of the controller loop.
#[derive(Clone, Debug, PartialEq)]
pub struct PilotConfig {
    /// The offboard session's timing and failsafes.
    pub link: LinkConfig,
    /// The mission; its positions are relative to where the vehicle stands at the start
    /// (`home` is that point, normally zero).
    pub mission: MissionConfig,
    /// Collective acceleration to PX4's normalized thrust (the vehicle's hover thrust);
    /// `None`: read PX4's `MPC_THR_HOVER` before starting.
    pub thrust_map: Option<ThrustMap>,
    /// Body-rate bounds of the setpoints.
    pub limits: RateLimits,
    /// SET_ATTITUDE_TARGET rate \[Hz\], 25..=250.
    pub setpoint_rate: f64,
    /// Bring the estimate forward by its age before each solve.
    pub predict: bool,
    /// The vehicle; `None`: read PX4 SIH's parameters before starting.
    pub vehicle: Option<VehicleProfile>,
    /// The flip's pitch rate asked for [rad/s]; `None`: the paper's 5*pi, or the fastest
    /// the vehicle can fly if slower ([`plan_flip`]).
    pub flip_rate: Option<f64>,
}

impl PilotConfig {
    /// The loop for `mission` with the default link, the hover thrust read from PX4, the
    /// models' rate bounds and setpoints at 100 Hz.
    pub fn new(mission: MissionConfig) -> Self {
        Self {
            link: LinkConfig::default(),
            mission,
            thrust_map: None,
            limits: RateLimits::default(),
            setpoint_rate: 100.0,
            predict: true,
            vehicle: None,
            flip_rate: None,
        }
    }

    /// Checks every setting.
    ///
    /// # Errors
    /// [`PilotError`] naming the first bad setting.
    pub fn validate(&self) -> Result<(), PilotError> {
        self.link.validate()?;
        if let Some(m) = &self.thrust_map {
            m.validate()?;
        }
        self.limits.validate()?;
        if !(self.setpoint_rate.is_finite() && (25.0..=250.0).contains(&self.setpoint_rate)) {
            return Err(PilotError::SetpointRate(self.setpoint_rate));
        }
        Ok(())
    }
}

/// A [`PilotConfig`] that cannot fly.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PilotError {
    /// A link setting.
    #[error(transparent)]
    Link(#[from] LinkConfigError),
    /// The thrust map or the rate bounds.
    #[error(transparent)]
    Setpoint(#[from] SetpointError),
    /// The vehicle's profile, or the maneuver beyond it.
    #[error(transparent)]
    Vehicle(#[from] ProfileError),
    /// The setpoint rate.
    #[error(
        "setpoint rate {0} Hz is out of range: use 25 to 250 Hz (PX4 needs at least 2 Hz, the solver runs at 20 Hz)"
    )]
    SetpointRate(f64),
}

/// The vehicle's state in the models' frames (ENU world, FLU body).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State {
    /// Vehicle time \[s\].
    pub t: f64,
    /// Position \[m\].
    pub p: Vector3<f64>,
    /// Velocity [m/s].
    pub v: Vector3<f64>,
    /// Attitude, body to world.
    pub q: UnitQuaternion<f64>,
    /// Body rates [rad/s].
    pub w: Vector3<f64>,
}

fn vec3(a: [f32; 3]) -> Vector3<f64> {
    Vector3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]))
}

fn state_from_ned(
    time_us: u64,
    position: [f32; 3],
    velocity: [f32; 3],
    q: [f32; 4],
    rates: [f32; 3],
) -> Option<State> {
    let q = quat_from_mavlink(q)?;
    let s = State {
        t: time_us as f64 * 1e-6,
        p: ned_to_enu(&vec3(position)),
        v: ned_to_enu(&vec3(velocity)),
        q: quat_ned_frd_to_enu_flu(&q),
        w: frd_to_flu(&vec3(rates)),
    };
    let finite =
        s.p.iter()
            .chain(s.v.iter())
            .chain(s.w.iter())
            .all(|x| x.is_finite());
    finite.then_some(s)
}

/// Turns what PX4 sends into [`State`]s: ODOMETRY, or LOCAL_POSITION_NED +
/// ATTITUDE_QUATERNION pairs; drops what is not newer than the last state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StateInput {
    last_us: Option<u64>,
    last_odometry_us: Option<u64>,
    first_us: Option<u64>,
    position: Option<(u64, [f32; 3], [f32; 3])>,
    attitude: Option<(u64, [f32; 4], [f32; 3])>,
    parsed_pair: bool,
    /// States dropped: duplicates, overtaken (older than the last), not finite.
    pub dropped: u64,
    /// States accepted.
    pub accepted: u64,
    /// Of those, made of LOCAL_POSITION_NED + ATTITUDE_QUATERNION.
    pub from_pairs: u64,
}

impl StateInput {
    /// A new state from `inbound`, if it makes one: [`StateInput::parse`], then
    /// [`StateInput::accept`].
    pub fn on_inbound(&mut self, inbound: &Inbound) -> Option<State> {
        let (time_us, s) = self.parse(inbound)?;
        self.accept(time_us, s)
    }

    /// The state `inbound` makes, with its vehicle time \[us\], not yet judged: `None` inside
    /// when it is not finite; nothing when `inbound` makes no state (not a state message, or
    /// half of a pair, or a pair while ODOMETRY comes).
    pub fn parse(&mut self, inbound: &Inbound) -> Option<(u64, Option<State>)> {
        self.parsed_pair = !matches!(inbound, Inbound::Odometry(_));
        match *inbound {
            Inbound::Odometry(o) => {
                self.last_odometry_us = Some(o.time_us);
                Some((
                    o.time_us,
                    state_from_ned(o.time_us, o.position, o.velocity, o.q, o.rates),
                ))
            }
            Inbound::LocalPosition {
                time_boot_ms,
                position,
                velocity,
            } => {
                let t = u64::from(time_boot_ms) * 1000;
                self.first_us.get_or_insert(t);
                self.position = Some((t, position, velocity));
                self.pair(t)
            }
            Inbound::Attitude {
                time_boot_ms,
                q,
                rates,
            } => {
                let t = u64::from(time_boot_ms) * 1000;
                self.first_us.get_or_insert(t);
                self.attitude = Some((t, q, rates));
                self.pair(t)
            }
            _ => None,
        }
    }

    /// Accepts a parsed state if it is finite and newer than the last one (else counts it
    /// dropped).
    pub fn accept(&mut self, time_us: u64, s: Option<State>) -> Option<State> {
        let newer = self.last_us.is_none_or(|last| time_us > last);
        let Some(s) = s.filter(|_| newer) else {
            self.dropped += 1;
            return None;
        };
        if self.parsed_pair {
            self.from_pairs += 1;
        }
        self.last_us = Some(time_us);
        self.accepted += 1;
        Some(s)
    }

    /// Forgets the vehicle's times seen (after a jump of its clock): the next state is
    /// accepted whatever its time.
    pub fn restart(&mut self) {
        *self = Self {
            dropped: self.dropped,
            accepted: self.accepted,
            from_pairs: self.from_pairs,
            ..Self::default()
        };
    }

    /// A state from the newest position and attitude, when they are close enough in time and
    /// ODOMETRY is not coming; stamped with the later of the two.
    fn pair(&self, now_us: u64) -> Option<(u64, Option<State>)> {
        // ODOMETRY is expected from the first state message on, until it has been missing
        // for ODOMETRY_PREFERENCE_US.
        let since = self.last_odometry_us.or(self.first_us).unwrap_or(now_us);
        if now_us.saturating_sub(since) < ODOMETRY_PREFERENCE_US {
            return None;
        }
        let (tp, position, velocity) = self.position?;
        let (ta, q, rates) = self.attitude?;
        if tp.abs_diff(ta) > PAIR_WINDOW_US {
            return None;
        }
        let t = tp.max(ta);
        Some((t, state_from_ned(t, position, velocity, q, rates)))
    }
}

/// The touchdown's speed is the fastest descent over this long \[s\] ...
pub const TOUCHDOWN_WINDOW_S: f64 = 0.3;
/// ... in the last this long before the vehicle was found down (the landing's stall takes
/// 0.6 s to judge) \[s\].
pub const TOUCHDOWN_LOOKBACK_S: f64 = 1.2;

/// The fastest descent [m/s, positive down] over any `window` \[s\] of `heights` (time,
/// height), from the heights themselves: EKF2's vertical speed was seen 0.45 m/s off the
/// truth in a landing while its height followed it.
pub fn fastest_descent(heights: &std::collections::VecDeque<(f64, f64)>, window: f64) -> f64 {
    let mut fastest: f64 = 0.0;
    let mut j = 0;
    for (i, &(t0, h0)) in heights.iter().enumerate() {
        j = j.max(i);
        while heights.get(j).is_some_and(|(t1, _)| t1 - t0 < window) {
            j += 1;
        }
        let Some(&(t1, h1)) = heights.get(j) else {
            break;
        };
        fastest = fastest.max((h0 - h1) / (t1 - t0));
    }
    fastest
}

/// Time constant of PX4's rate loop and rotors as the prediction models them \[s\]: the body
/// rates and the thrust follow the setpoint as first-order lags.
pub const RESPONSE_TIME_CONSTANT: f64 = 0.03;

/// `s` brought forward to `until` (at most [`MAX_PREDICTION_S`]) in 2.5 ms steps, under the
/// setpoints in `commands` (vehicle time each acts, collective acceleration, body rates; in
/// time order; the one in force at a time is the last before it, and before the first, the
/// first; none: zero thrust and rates): the body rates and
/// the collective thrust follow the setpoint with [`RESPONSE_TIME_CONSTANT`] from the
/// measured rates and the setpoint in force at `s.t`, the attitude turns by the rates,
/// velocity and position follow thrust and gravity.
pub fn predict(s: &State, commands: &[(f64, InnerCommand)], until: f64) -> State {
    predict_with(s, commands, until, &Response::default())
}

/// How the vehicle follows a setpoint, as [`predict_with`] models it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Response {
    /// The body rates' and the thrust's time constant \[s\].
    pub tau: f64,
    /// The most the body rates change per second [rad/s^2] (the pitch authority).
    pub max_accel: f64,
}

impl Default for Response {
    /// [`RESPONSE_TIME_CONSTANT`], no bound on the rates' change.
    fn default() -> Self {
        Self {
            tau: RESPONSE_TIME_CONSTANT,
            max_accel: f64::INFINITY,
        }
    }
}

impl Response {
    /// The response of `vehicle`: its rotors' time constant (at least
    /// [`RESPONSE_TIME_CONSTANT`]: PX4's rate loop), its pitch authority.
    pub fn of(vehicle: &VehicleProfile) -> Self {
        Self {
            tau: vehicle.rotor_tau_s.max(RESPONSE_TIME_CONSTANT),
            max_accel: vehicle.pitch_authority(),
        }
    }
}

/// [`predict`] with the vehicle's `response`: the rates follow the setpoint with its time
/// constant, changing by at most its angular acceleration.
pub fn predict_with(
    s: &State,
    commands: &[(f64, InnerCommand)],
    until: f64,
    response: &Response,
) -> State {
    let age = (until - s.t).clamp(0.0, MAX_PREDICTION_S);
    let steps = (age / 0.0025).ceil().max(1.0);
    let h = age / steps;
    let at = |t: f64| {
        commands
            .iter()
            .rev()
            .find(|(ts, _)| *ts <= t)
            .or(commands.first())
            .map_or(InnerCommand::default(), |(_, c)| *c)
    };
    let k = 1.0 - (-h / response.tau).exp();
    let max_step = if response.max_accel.is_finite() {
        response.max_accel * h
    } else {
        f64::INFINITY
    };
    let mut out = *s;
    let mut c = at(s.t).thrust_c;
    for i in 0..steps as usize {
        let cmd = at(s.t + i as f64 * h);
        out.w += ((cmd.rates - out.w) * k).map(|d| d.clamp(-max_step, max_step));
        c += (cmd.thrust_c - c) * k;
        let a = out.q * Vector3::new(0.0, 0.0, c) - Vector3::new(0.0, 0.0, G);
        out.p += out.v * h + a * (0.5 * h * h);
        out.v += a * h;
        out.q *= UnitQuaternion::from_scaled_axis(out.w * h);
    }
    out.t = s.t + age;
    out
}

/// What happened, with the vehicle time \[s\] it happened at.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// Vehicle time \[s\].
    pub t: f64,
    /// What, in words.
    pub what: String,
}

/// Mean, median, 99th percentile and maximum \[ms\].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PeriodStats {
    /// Number of intervals.
    pub count: usize,
    /// Mean \[ms\].
    pub mean_ms: f64,
    /// Median \[ms\].
    pub median_ms: f64,
    /// 99th percentile (nearest rank) \[ms\].
    pub p99_ms: f64,
    /// Maximum \[ms\].
    pub max_ms: f64,
}

impl PeriodStats {
    /// Statistics of `values` \[s\].
    pub fn of(values: &[f64]) -> Self {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f64::total_cmp);
        let rank = |p: f64| {
            let i = ((p * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
            v.get(i).copied().unwrap_or(f64::NAN) * 1e3
        };
        Self {
            count: v.len(),
            mean_ms: v.iter().sum::<f64>() / v.len() as f64 * 1e3,
            median_ms: rank(0.5),
            p99_ms: rank(0.99),
            max_ms: v.last().copied().unwrap_or(f64::NAN) * 1e3,
        }
    }
}

/// The figures of a flight as the controller saw it.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FlightReport {
    /// The mission's verdict on the telemetry (the simulator's criteria).
    pub summary: Option<TrialSummary>,
    /// How the session ended, in words.
    pub session: String,
    /// Failsafes engaged, with their vehicle time \[s\].
    pub failsafes: Vec<(String, f64)>,
    /// States accepted.
    pub states: u64,
    /// States dropped (duplicate, overtaken, not finite).
    pub states_dropped: u64,
    /// Setpoints sent.
    pub setpoints: u64,
    /// Setpoints clamped into range.
    pub setpoints_clamped: u64,
    /// Setpoints whose input was not finite (the previous one was sent).
    pub setpoints_replaced: u64,
    /// Wall-clock period of the setpoint stream (the loop's jitter).
    pub setpoint_period: PeriodStats,
    /// Wall-clock period of the solver steps.
    pub solver_period: PeriodStats,
    /// Solver time per step \[us\]: mean, p99, max.
    pub solver_us: report::TimeStats,
    /// Solver steps that fell back to the previous plan.
    pub fallbacks: u64,
    /// The vehicle flown, as PX4 reported it or as given.
    pub vehicle: Option<VehicleProfile>,
    /// The flip as planned for it.
    pub flip: Option<FlipPlan>,
    /// The vehicle's clock rate over the wall clock, as estimated.
    pub clock_rate: f64,
    /// Jumps of the vehicle's clock seen.
    pub clock_jumps: u32,
    /// TIMESYNC round trips \[ms\]: the shortest and the longest of the last ones.
    pub round_trip_ms: Option<(f64, f64)>,
    /// What the link took in and kept out (set by whoever owns the link: the pilot does
    /// not see it).
    pub link: Option<LinkStats>,
}

struct Flight {
    t0: f64,
    home: Vector3<f64>,
    mission: Mission,
    ctrl: NmpcController,
    next_outer: f64,
    cmd: InnerCommand,
    samples: Vec<Sample>,
    pitch_turned: f64,
    flip_started: bool,
    last_logged: Option<State>,
    touchdown: Option<Touchdown>,
    pending_stats: Option<OuterStats>,
    on_ground: bool,
    airborne: bool,
    /// The setpoints of the last [`MAX_PREDICTION_S`] (vehicle time sent, command).
    history: std::collections::VecDeque<(f64, InnerCommand)>,
    watch: Watch,
    /// The estimate's heights of the last [`TOUCHDOWN_LOOKBACK_S`] (vehicle time, z).
    heights: std::collections::VecDeque<(f64, f64)>,
}

/// The controller loop. See the [module documentation](self).
pub struct Pilot {
    cfg: PilotConfig,
    map: Option<ThrustMap>,
    param_requests: u32,
    last_param_request: Option<f64>,
    failure: Option<String>,
    session: Option<Session>,
    input: StateInput,
    clock: VehicleClock,
    state: Option<State>,
    flight: Option<Flight>,
    next_setpoint: f64,
    last_setpoint: Option<Px4Setpoint>,
    last_setpoint_wall: Option<f64>,
    last_solve_wall: Option<f64>,
    setpoint_periods: Vec<f64>,
    solver_periods: Vec<f64>,
    solver_us: Vec<f64>,
    setpoints: u64,
    clamped: u64,
    replaced: u64,
    fallbacks: u64,
    abort: bool,
    events: Vec<Event>,
    failsafes: Vec<(Failsafe, f64)>,
    link_delay: f64,
    round_trip: RoundTrip,
    last_timesync: Option<f64>,
    px4_landed: Option<LandedState>,
    autopilot: Option<u8>,
    vehicle: Option<VehicleProfile>,
    sih: [Option<f64>; 5],
    flip: Option<FlipPlan>,
    response: Response,
    finished_at: Option<f64>,
}

impl Pilot {
    /// A loop that waits for PX4's first state.
    ///
    /// # Errors
    /// [`PilotError`] if the configuration cannot fly ([`PilotConfig::validate`]).
    pub fn new(cfg: PilotConfig) -> Result<Self, PilotError> {
        cfg.validate()?;
        let given = cfg.vehicle.clone();
        let mut pilot = Self::waiting(cfg);
        if let Some(v) = given {
            pilot.set_vehicle(v, 0.0)?;
        }
        Ok(pilot)
    }

    fn waiting(cfg: PilotConfig) -> Self {
        Self {
            map: cfg.thrust_map,
            param_requests: 0,
            last_param_request: None,
            failure: None,
            cfg,
            session: None,
            input: StateInput::default(),
            clock: VehicleClock::default(),
            state: None,
            flight: None,
            next_setpoint: 0.0,
            last_setpoint: None,
            last_setpoint_wall: None,
            last_solve_wall: None,
            setpoint_periods: Vec::new(),
            solver_periods: Vec::new(),
            solver_us: Vec::new(),
            setpoints: 0,
            clamped: 0,
            replaced: 0,
            fallbacks: 0,
            abort: false,
            events: Vec::new(),
            failsafes: Vec::new(),
            link_delay: 0.0,
            round_trip: RoundTrip::default(),
            last_timesync: None,
            px4_landed: None,
            autopilot: None,
            vehicle: None,
            sih: [None; 5],
            flip: None,
            response: Response::default(),
            finished_at: None,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &PilotConfig {
        &self.cfg
    }

    /// The session, once the first state has come.
    pub fn session(&self) -> Option<&Session> {
        self.session.as_ref()
    }

    /// The mission phase, once flying.
    pub fn mission_phase(&self) -> Option<MissionPhase> {
        self.flight.as_ref().map(|f| f.mission.phase())
    }

    /// The newest state.
    pub fn state(&self) -> Option<&State> {
        self.state.as_ref()
    }

    /// Everything that happened so far.
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// The operator asks to stop: AUTO.LAND at the next poll.
    pub fn abort(&mut self) {
        self.abort = true;
    }

    /// Whether there is nothing more to do: the mission is over and PX4 disarmed, the session
    /// could not start, or a failsafe handed the vehicle to PX4 and it has disarmed (or was
    /// never armed).
    pub fn finished(&self) -> bool {
        if self.failure.is_some() {
            return true;
        }
        let Some(s) = &self.session else {
            return false;
        };
        match s.phase() {
            Phase::Done | Phase::Failed(_) => true,
            Phase::Failsafe(_) => {
                // Since the failsafe: PX4 flies; done once it has disarmed, or given up on
                // after HANDOVER_WAIT_S (a crashed vehicle PX4 never calls landed).
                let since = self
                    .failsafes
                    .last()
                    .and_then(|(_, t)| self.clock.last().map(|l| l - t));
                since.is_some_and(|d| (!s.armed() && d > 1.5) || d > HANDOVER_WAIT_S)
            }
            _ => false,
        }
    }

    fn event(&mut self, t: f64, what: String) {
        self.events.push(Event { t, what });
    }

    /// Handles a message received at wall time `wall` \[s\].
    pub fn on_message(&mut self, header: &MavHeader, msg: &MavMessage, wall: f64) {
        let Some(system) = self
            .autopilot
            .or_else(|| self.find_autopilot(header, msg, wall))
        else {
            return;
        };
        let inbound = messages::classify_from(header, msg, system);
        if let Inbound::Param { name, value } = inbound {
            self.on_param(&name, value, wall);
            return;
        }
        if let Some((time_us, s)) = self.input.parse(&inbound) {
            self.on_state(time_us, s, wall);
            return;
        }
        if let Inbound::Landed(l) = inbound {
            self.px4_landed = Some(l);
        }
        if let Inbound::Timesync { ts1, .. } = inbound {
            self.round_trip.on_answer(ts1 as f64 * 1e-9, wall);
            return;
        }
        if let (Some(session), Some(now)) = (self.session.as_mut(), self.clock.now(wall)) {
            let before = (session.px4_mode(), session.armed());
            session.on_inbound(&inbound, now);
            let after = (session.px4_mode(), session.armed());
            // Disarmed by PX4's land detector in the landing: the mission is over.
            if !after.1
                && self.flight.as_ref().map(|f| f.mission.phase()) == Some(MissionPhase::Land)
            {
                session.finish();
            }
            if before != after {
                let what = format!(
                    "PX4: {}, {}",
                    after.0.map_or("?".to_string(), |m| m.to_string()),
                    if after.1 { "armed" } else { "disarmed" }
                );
                self.event(now, what);
            }
        }
    }

    /// The autopilot is the sender of the first PX4 HEARTBEAT (system 1 on a vehicle;
    /// PX4 SITL's instance `i` is system `i + 1`); until it has come, nothing is used.
    fn find_autopilot(&mut self, header: &MavHeader, msg: &MavMessage, wall: f64) -> Option<u8> {
        let system = messages::px4_heartbeat_system(header, msg)?;
        self.autopilot = Some(system);
        let t = self.clock.now(wall).unwrap_or(0.0);
        self.event(t, format!("PX4's autopilot: system {system}"));
        Some(system)
    }

    /// A parameter PX4 sent: its hover thrust, or one of SIH's vehicle parameters.
    fn on_param(&mut self, name: &[u8; 16], value: f32, wall: f64) {
        if self.failure.is_some() {
            return;
        }
        let t = self.clock.now(wall).unwrap_or(0.0);
        if messages::param_name_is(name, messages::HOVER_THRUST_PARAM) && self.map.is_none() {
            let map = ThrustMap {
                hover_thrust: f64::from(value),
                g: G,
            };
            match map.validate() {
                Ok(()) => {
                    self.map = Some(map);
                    let what = format!("PX4: {} = {value}", messages::HOVER_THRUST_PARAM);
                    self.event(t, what);
                }
                Err(e) => {
                    self.failure = Some(format!(
                        "PX4's {} = {value} cannot be used ({e}); calibrate it (hover, read \
                         the hover-thrust estimate) or give the hover thrust",
                        messages::HOVER_THRUST_PARAM
                    ));
                }
            }
            return;
        }
        let Some(i) = SIH_PARAMS
            .iter()
            .position(|p| messages::param_name_is(name, p))
        else {
            return;
        };
        if self.vehicle.is_some() {
            return;
        }
        if let Some(v) = self.sih.get_mut(i) {
            *v = Some(f64::from(value));
        }
        if let [Some(a), Some(b), Some(c), Some(d), Some(e)] = self.sih {
            let v = VehicleProfile::from_sih([a, b, c, d, e]);
            if let Err(e) = self.set_vehicle(v, t) {
                self.failure = Some(e.to_string());
            }
        }
    }

    /// Flies `v`: the flip planned for it, the prediction with its response.
    fn set_vehicle(&mut self, v: VehicleProfile, t: f64) -> Result<(), ProfileError> {
        v.validate()?;
        // The NMPC's model takes the vehicle's collective thrust as its bound (at take-off).
        NmpcController::new()
            .set_thrust_limit(v.max_collective())
            .map_err(|_| ProfileError::Invalid {
                name: "collective thrust (4 rotors' most thrust over mass)",
                value: v.max_collective(),
                why: "the NMPC's thrust bound must be finite and at least 0",
            })?;
        let plan = plan_flip(&mut self.cfg.mission, &v, self.cfg.flip_rate)?;
        self.event(t, format!("vehicle: {}", v.describe()));
        if let Some(p) = plan {
            let what = format!(
                "flip planned at {:.1} rad/s (this vehicle: up to {:.1}), ramped at {:.0} \
                 rad/s^2, {:.2} s, climbing in at {:.1} m/s",
                p.rate, p.max_rate, p.accel, p.duration, p.ascend_speed
            );
            self.event(t, what);
        }
        self.response = Response::of(&v);
        self.flip = plan;
        self.vehicle = Some(v);
        Ok(())
    }

    /// Whether the hover thrust and the vehicle are known: the session may start.
    fn ready(&self) -> bool {
        self.map.is_some() && self.vehicle.is_some() && self.failure.is_none()
    }

    /// A state stamped `time_us` arrived at `wall`: judged by the vehicle's clock, then by
    /// its time (newer than the last), then used.
    fn on_state(&mut self, time_us: u64, s: Option<State>, wall: f64) {
        if let Some(st) = &s {
            match self.clock.observe(st.t, wall) {
                Verdict::Consistent => {}
                Verdict::Inconsistent => {
                    self.input.dropped += 1;
                    return;
                }
                Verdict::Jumped { by } => {
                    self.input.restart();
                    let now = self.clock.now(wall).unwrap_or(0.0);
                    self.event(now, format!("PX4's clock jumped by {by:+.3} s"));
                }
            }
        }
        let Some(mut s) = self.input.accept(time_us, s) else {
            return;
        };
        s.t = self.clock.local(s.t);
        self.state = Some(s);
        let now = self.clock.now(wall).unwrap_or(s.t);
        // Mean delay of the states over the least delayed one (~1 s memory), never more
        // than the link's round trip shows.
        let delay = (now - s.t).clamp(0.0, self.delay_bound());
        self.link_delay += 0.02 * (delay - self.link_delay);
        self.link_delay = self.link_delay.min(self.delay_bound());
        if self.ready() {
            let session = self
                .session
                .get_or_insert_with(|| Session::new(self.cfg.link, now));
            // The session's odometry clock: only accepted (newer) states count.
            session.on_odometry(now);
        }
        self.log_state(&s);
    }

    /// The most a state can be late: the link's longest recent round trip (TIMESYNC), at
    /// least [`MIN_DELAY_BOUND_S`]; without TIMESYNC answers, [`MAX_PREDICTION_S`].
    fn delay_bound(&self) -> f64 {
        self.round_trip.bound().map_or(MAX_PREDICTION_S, |b| {
            b.clamp(MIN_DELAY_BOUND_S, MAX_PREDICTION_S)
        })
    }

    fn log_state(&mut self, s: &State) {
        let Some(f) = self.flight.as_mut() else {
            return;
        };
        let t = s.t - f.t0;
        let phase = f.mission.phase();
        if phase == MissionPhase::Flip {
            f.flip_started = true;
        }
        if let Some(prev) = f.last_logged
            && f.flip_started
        {
            // Trapezoidal integral of the pitch rate between states.
            f.pitch_turned += 0.5 * (prev.w.y + s.w.y) * (s.t - prev.t);
        }
        let height = s.p.z - f.home.z;
        let r = f.mission.reference(t);
        let px4_on_ground = self.px4_landed == Some(LandedState::OnGround);
        let seen = f.watch.observe(t, phase, s, &r, height, px4_on_ground);
        let on_ground = seen.on_ground;
        f.airborne |= height > 0.3;
        if let Some(d) = seen.deviation
            && let Some(session) = self.session.as_mut()
            && session.phase() == Phase::Flying
        {
            session.trip(Failsafe::OffMission(d));
        }
        f.heights.push_back((s.t, s.p.z));
        while f
            .heights
            .front()
            .is_some_and(|(t0, _)| s.t - t0 > TOUCHDOWN_LOOKBACK_S)
        {
            f.heights.pop_front();
        }
        if on_ground && !f.on_ground && f.airborne {
            f.touchdown = Some(Touchdown {
                t,
                vertical_speed: -fastest_descent(&f.heights, TOUCHDOWN_WINDOW_S),
                p: s.p,
            });
        }
        f.on_ground = on_ground;
        f.last_logged = Some(*s);
        let truth = QuadState {
            p: s.p,
            v: s.v,
            q: s.q,
            w: s.w,
            omega: [0.0; 4],
        };
        f.samples.push(Sample {
            phase: phase.index(),
            failsafe: !self.failsafes.is_empty(),
            pose_valid: true,
            x_ref: r.p.x,
            y_ref: r.p.y,
            z_ref: r.p.z,
            pitch_turned: f.pitch_turned,
            wx_cmd: f.cmd.rates.x,
            wy_cmd: f.cmd.rates.y,
            wz_cmd: f.cmd.rates.z,
            wy_ref: r.rate.y,
            thrust_cmd: f.cmd.thrust_c,
            ..Sample::at(t, &truth, [0.0; 4], f.pending_stats.take())
        });
    }

    /// One step of the loop at wall time `wall` \[s\]: the messages to send now, addressed
    /// to the autopilot.
    pub fn poll(&mut self, wall: f64) -> Vec<MavMessage> {
        let mut out = self.step(wall);
        if let Some(system) = self.autopilot {
            for m in &mut out {
                messages::retarget(m, system);
            }
        }
        out
    }

    fn step(&mut self, wall: f64) -> Vec<MavMessage> {
        let mut out = Vec::new();
        if self.clock.started()
            && self
                .last_timesync
                .is_none_or(|t| wall - t >= TIMESYNC_PERIOD_S)
        {
            self.last_timesync = Some(wall);
            // Stamped with the wall clock in ns, 1 ns at least (tc1 = 0 asks).
            out.push(messages::timesync_request(((wall * 1e9) as i64).max(1)));
        }
        if !self.ready() && self.failure.is_none() && self.clock.started() {
            self.ask_params(wall, &mut out);
            return out;
        }
        let (Some(now), Some(session)) = (self.clock.now(wall), self.session.as_mut()) else {
            return out;
        };
        if self.abort {
            session.abort();
        }
        let tick = session.tick(now);
        out.extend(tick.send);
        let phase = session.phase();
        let px4_mode = session.px4_mode();
        if let Some(f) = tick.failsafe {
            self.failsafes.push((f, now));
            let what = format!("failsafe: {f:?} -> {}", failsafe_mode(f));
            self.event(now, what);
        }
        if tick.mpc_in_control && self.flight.is_none() {
            self.start_flight(now);
        }
        // After a failsafe request or the final landing, PX4 flies: once its HEARTBEAT shows
        // it out of OFFBOARD the controller stops and so does the stream (PX4 then refuses
        // OFFBOARD: nobody can switch it back onto stale setpoints). Until then the
        // controller goes on: PX4 may still be listening. A vehicle that PX4 disarmed gets
        // no setpoint either.
        let armed = self.session.as_ref().is_some_and(Session::armed);
        let handed_over = matches!(phase, Phase::Failsafe(_) | Phase::Finishing | Phase::Done)
            && (px4_mode != Some(Px4Mode::Offboard) || !armed);
        let active = self.flight.is_some()
            && matches!(phase, Phase::Flying | Phase::Failsafe(_))
            && !handed_over;
        if active {
            self.control(now, wall);
        }
        if now + 1e-9 >= self.next_setpoint && !handed_over {
            let period = 1.0 / self.cfg.setpoint_rate;
            self.next_setpoint = if self.next_setpoint + period < now {
                now + period
            } else {
                self.next_setpoint + period
            };
            let sp = match (&self.flight, active, &self.map) {
                (Some(f), true, Some(map)) => {
                    let s = make_setpoint(
                        f.cmd.thrust_c,
                        &f.cmd.rates,
                        map,
                        &self.cfg.limits,
                        self.last_setpoint.as_ref(),
                    );
                    self.clamped += u64::from(s.clamped);
                    self.replaced += u64::from(s.replaced_non_finite);
                    s.setpoint
                }
                _ => Px4Setpoint {
                    rates_frd: [0.0; 3],
                    thrust: 0.0,
                },
            };
            self.last_setpoint = Some(sp);
            out.push(messages::set_attitude_target(
                sp.rates_frd,
                sp.thrust,
                (now * 1e3) as u32,
            ));
            self.setpoints += 1;
            if let Some(w) = self.last_setpoint_wall {
                self.setpoint_periods.push(wall - w);
            }
            self.last_setpoint_wall = Some(wall);
        }
        if self.finished() && self.finished_at.is_none() {
            self.finished_at = Some(now);
            let what = match self.session.as_ref().map(|s| (s.phase(), s.armed())) {
                Some((Phase::Failed(e), _)) => format!("session failed: {e}"),
                Some((_, true)) => format!(
                    "given up: PX4 still armed in {} {HANDOVER_WAIT_S} s after the failsafe",
                    px4_mode.map_or("?".to_string(), |m| m.to_string())
                ),
                _ => "done: PX4 disarmed".to_string(),
            };
            self.event(now, what);
        }
        out
    }

    /// Asks PX4 for its hover thrust and SIH's vehicle parameters (what is still missing)
    /// once a second; gives up after five tries.
    fn ask_params(&mut self, wall: f64, out: &mut Vec<MavMessage>) {
        const TRIES: u32 = 5;
        if self.last_param_request.is_some_and(|t| wall - t < 1.0) {
            return;
        }
        if self.param_requests >= TRIES {
            self.no_answer(wall);
            return;
        }
        self.param_requests += 1;
        self.last_param_request = Some(wall);
        if self.map.is_none() {
            out.push(messages::param_request_read(messages::HOVER_THRUST_PARAM));
        }
        if self.vehicle.is_none() {
            for (name, v) in SIH_PARAMS.iter().zip(self.sih) {
                if v.is_none() {
                    out.push(messages::param_request_read(name));
                }
            }
        }
    }

    /// PX4 did not answer every request: no hover thrust is fatal; no vehicle is fatal for
    /// a flip (it must be planned for the vehicle), else the prediction's defaults fly.
    fn no_answer(&mut self, wall: f64) {
        const TRIES: u32 = 5;
        if self.map.is_none() {
            self.failure = Some(format!(
                "PX4 did not answer the request for {} ({TRIES} tries); give the hover \
                 thrust (normalized thrust of a hover, 0..1) instead",
                messages::HOVER_THRUST_PARAM
            ));
        } else if self.cfg.mission.kind == MissionKind::Flip {
            self.failure = Some(
                "PX4 did not report its vehicle (SIH_* parameters: only PX4's SIH simulation \
                 has them), and a flip is planned for the vehicle: give its profile with \
                 --vehicle FILE (docs/shim.md)"
                    .to_string(),
            );
        } else {
            let v = VehicleProfile {
                source: "not reported by PX4 and not given (--vehicle): the design vehicle's \
                         figures"
                    .to_string(),
                ..VehicleProfile::design()
            };
            let t = self.clock.now(wall).unwrap_or(0.0);
            if let Err(e) = self.set_vehicle(v, t) {
                self.failure = Some(e.to_string());
            }
        }
    }

    /// Why the loop could not fly, if it could not start (no hover thrust).
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// The thrust map in use (given, or read from PX4).
    pub fn thrust_map(&self) -> Option<ThrustMap> {
        self.map
    }

    fn start_flight(&mut self, now: f64) {
        let Some(s) = self.state else {
            return;
        };
        let mut m = self.cfg.mission.clone();
        let shift = s.p - m.home;
        m.home += shift;
        m.takeoff_point += shift;
        m.rally_point += shift;
        // Stale odometry is the session's failsafe (PX4's return mode), not the mission's.
        m.pose_timeout = f64::INFINITY;
        m.land_flare_height = m.land_flare_height.max(FLARE_HEIGHT_M);
        let mut ctrl = NmpcController::new();
        let c_max = self.vehicle.as_ref().map(VehicleProfile::max_collective);
        // Checked when the vehicle was set (`set_vehicle`): this cannot fail; if it did, the
        // model's own bound is kept and said so, rather than leaving PX4 without setpoints.
        let bounded = c_max.map(|c| ctrl.set_thrust_limit(c));
        let what = match bounded {
            Some(Err(e)) => {
                format!("NMPC: the vehicle's thrust refused ({e:?}); the model's bound")
            }
            Some(Ok(())) => "NMPC: collective thrust bounded by the vehicle's".to_string(),
            None => "NMPC: collective thrust bounded by the model (no vehicle profile)".to_string(),
        };
        self.event(now, format!("{what}, {:.1} m/s^2", ctrl.thrust_limit()));
        self.flight = Some(Flight {
            t0: now,
            home: s.p,
            mission: Mission::new(m),
            ctrl,
            next_outer: now,
            cmd: InnerCommand::default(),
            samples: Vec::new(),
            pitch_turned: 0.0,
            flip_started: false,
            last_logged: None,
            touchdown: None,
            pending_stats: None,
            on_ground: true,
            airborne: false,
            history: std::collections::VecDeque::new(),
            watch: Watch::default(),
            heights: std::collections::VecDeque::new(),
        });
        self.event(now, "flying: mission started".to_string());
    }

    fn control(&mut self, now: f64, wall: f64) {
        let (Some(f), Some(s)) = (self.flight.as_mut(), self.state) else {
            return;
        };
        if now + 1e-9 < f.next_outer {
            return;
        }
        let period = f.ctrl.period();
        f.next_outer = if f.next_outer + period < now {
            now + period
        } else {
            f.next_outer + period
        };
        // The setpoint computed now acts a link delay later: solve for that instant, from
        // the state brought forward to it.
        let acts_at = now + self.link_delay;
        let s = if self.cfg.predict {
            predict_with(&s, f.history.make_contiguous(), acts_at, &self.response)
        } else {
            s
        };
        let t = acts_at - f.t0;
        let est = Estimate {
            t,
            p: s.p,
            v: s.v,
            q: s.q,
            w: s.w,
            pose_valid: true,
        };
        let before = f.mission.phase();
        let phase = f.mission.update(&MissionInput {
            t,
            p: s.p,
            v: s.v,
            pose_valid: true,
            on_ground: f.on_ground,
        });
        if phase == MissionPhase::Landed {
            f.cmd = InnerCommand::default();
        } else {
            let stats = f.ctrl.outer(t, &est, &f.mission);
            f.cmd = f.ctrl.inner(t, &est, &f.mission);
            // The setpoint acts when it reaches PX4: a link delay later (taken to be the
            // mean delay of the states, relative to the least delayed one).
            f.history.push_back((now + self.link_delay, f.cmd));
            while f
                .history
                .get(1)
                .is_some_and(|(t1, _)| now - t1 > MAX_PREDICTION_S)
            {
                f.history.pop_front();
            }
            self.fallbacks += u64::from(stats.fallback);
            self.solver_us.push(stats.solver_us);
            f.pending_stats = Some(stats);
            if let Some(session) = self.session.as_mut() {
                session.on_solver(!stats.fallback);
            }
            if let Some(w) = self.last_solve_wall {
                self.solver_periods.push(wall - w);
            }
            self.last_solve_wall = Some(wall);
        }
        if phase != before {
            let what = format!("mission: {}", phase.name());
            self.event(now, what);
            if phase == MissionPhase::Landed
                && let Some(session) = self.session.as_mut()
            {
                session.finish();
            }
        }
    }

    /// The flight's figures and the mission's verdict on the telemetry.
    pub fn report(&self) -> FlightReport {
        let summary = self.flight.as_ref().map(|f| {
            let mut mission = f.mission.config().clone();
            mission.pose_timeout = MissionConfig::flip().pose_timeout;
            let lost = self
                .failsafes
                .iter()
                .find(|(k, _)| *k == Failsafe::OdometryLost)
                .map(|(_, t)| *t);
            let landed = matches!(self.session.as_ref().map(Session::phase), Some(Phase::Done))
                || (self.finished() && f.touchdown.is_some());
            let outcome = if landed {
                Outcome::Landed
            } else {
                Outcome::Timeout
            };
            let flight = report::Flight {
                mission: &mission,
                conditions: Conditions::nominal(),
                samples: &f.samples,
                outcome: &outcome,
                touchdown: f.touchdown,
                // The pose was lost when the last state before the failsafe came.
                pose_lost_at: lost.map(|t| t - self.cfg.link.odometry_timeout - f.t0),
                failsafe_at: self.failsafes.first().map(|(_, t)| t - f.t0),
            };
            report::summarize_flight(&flight, &report::Criteria::PX4)
        });
        FlightReport {
            summary,
            session: match (self.session.as_ref().map(Session::phase), &self.failure) {
                (_, Some(f)) => format!("failed: {f}"),
                (None, None) => "no state from PX4".to_string(),
                (Some(Phase::Failed(e)), None) => format!("failed: {e}"),
                (Some(p), None) => format!("{p:?}"),
            },
            failsafes: self
                .failsafes
                .iter()
                .map(|(f, t)| (format!("{f:?}"), *t))
                .collect(),
            states: self.input.accepted,
            states_dropped: self.input.dropped,
            setpoints: self.setpoints,
            setpoints_clamped: self.clamped,
            setpoints_replaced: self.replaced,
            setpoint_period: PeriodStats::of(&self.setpoint_periods),
            solver_period: PeriodStats::of(&self.solver_periods),
            solver_us: report::TimeStats::of(self.solver_us.iter().copied()),
            fallbacks: self.fallbacks,
            vehicle: self.vehicle.clone(),
            flip: self.flip,
            clock_rate: self.clock.rate(),
            clock_jumps: self.clock.jumps(),
            round_trip_ms: self
                .round_trip
                .min()
                .zip(self.round_trip.bound())
                .map(|(a, b)| (a * 1e3, b * 1e3)),
            link: None,
        }
    }

    /// The flight's log (telemetry rows, mission time), for the CSV and the plots.
    pub fn samples(&self) -> &[Sample] {
        self.flight.as_ref().map_or(&[], |f| &f.samples)
    }
}

fn failsafe_mode(f: Failsafe) -> String {
    f.mode()
        .map_or("PX4's own mode".to_string(), |m| m.to_string())
}

/// Runs `pilot` on `link` in real time, the wall clock being the time since `epoch` (the
/// same for every call on one pilot), until it has finished, the wall clock reads `until`
/// seconds, or `stop` is set: then it aborts (AUTO.LAND) and goes on until PX4 has landed
/// and disarmed (or `until`); with no state from PX4 yet it returns at once. Polls every
/// half millisecond. Call it again with a later `until` to go on (e.g. to print progress).
pub fn run(link: &Link, pilot: &mut Pilot, epoch: Instant, until: f64, stop: &AtomicBool) {
    loop {
        let wall = epoch.elapsed().as_secs_f64();
        if wall >= until || pilot.finished() {
            return;
        }
        if stop.load(Ordering::Relaxed) {
            if pilot.session().is_none() {
                return;
            }
            pilot.abort();
        }
        while let Some((h, m)) = link.try_recv() {
            pilot.on_message(&h, &m, epoch.elapsed().as_secs_f64());
        }
        for m in pilot.poll(epoch.elapsed().as_secs_f64()) {
            let _ = link.send(&m);
        }
        std::thread::sleep(Duration::from_micros(500));
    }
}
