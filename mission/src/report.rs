//! Trial and run summaries: the figures the acceptance criteria are judged on, the table the
//! CLI prints and the JSON object of `mpcc sim --json`.
//!
//! Definitions (per phase, from the 1 kHz log of the true state):
//! - tracking error: |p - p_ref| (m); `tracking_error_pct` is its RMS over the phase
//!   relative to the length of the phase's reference path (at least 1 m), in percent. For the
//!   flip, `rate_tracking_error_pct` is the mean |wy - wy_ref| over the flip relative to the
//!   reference rate (the paper's "tracking error under 10 %" reads naturally as either).
//! - recovery time (recover phase): from the flip's end until the vehicle is within
//!   [`RECOVERY_TOL_M`] of the rally point and stays there for the rest of the hold.
//! - altitude loss: height at the phase's start minus the lowest height in it.
//! - solver time: wall-clock time of each outer-loop step (references, prepare, feedback).

use core::f64::consts::PI;
use std::fmt::Write as _;

use nalgebra::Vector3;
use serde::Serialize;

use crate::estimate::EstimatorConfig;
use crate::log::Sample;
use crate::mission::{MissionConfig, MissionKind, Phase};
use crate::vehicle::QuadParams;

/// Distance to the rally point that counts as recovered \[m\].
pub const RECOVERY_TOL_M: f64 = 0.10;
/// Longest acceptable recovery after the flip \[s\].
pub const RECOVERY_LIMIT_S: f64 = 3.0;
/// Lowest acceptable height from the ascent to the end of the hold \[m\].
pub const MIN_FLIGHT_ALTITUDE_M: f64 = 1.0;
/// Fastest acceptable touchdown [m/s].
pub const MAX_TOUCHDOWN_SPEED: f64 = 0.5;
/// Fraction of the flip's rate reference that must be reached.
pub const MIN_RATE_FRACTION: f64 = 0.9;
/// Return mode must engage this soon after the pose is lost \[s\].
pub const FAILSAFE_DELAY_LIMIT_S: f64 = 0.2;
/// Touchdown this close to the landing point counts as landed there \[m\] (0.5 m in return
/// mode, which flies on dead reckoning).
pub const LANDING_TOL_M: f64 = 0.25;

/// The thresholds a trial is judged by.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Criteria {
    /// Distance to the rally point that counts as recovered \[m\].
    pub recovery_tol_m: f64,
    /// Longest acceptable recovery after the flip \[s\].
    pub recovery_limit_s: f64,
    /// Lowest acceptable height from the ascent to the end of the hold \[m\].
    pub min_flight_altitude_m: f64,
    /// Fastest acceptable touchdown [m/s].
    pub max_touchdown_speed: f64,
    /// Fraction of the flip's rate reference that must be reached.
    pub min_rate_fraction: f64,
    /// Return mode must engage this soon after the pose is lost \[s\].
    pub failsafe_delay_limit_s: f64,
    /// Touchdown this close to the landing point counts as landed there \[m\].
    pub landing_tol_m: f64,
    /// The same after a failsafe's return \[m\].
    pub failsafe_landing_tol_m: f64,
}

impl Criteria {
    /// The simulator's criteria, judged on the true state: the constants of this module.
    pub const SIMULATOR: Criteria = Criteria {
        recovery_tol_m: RECOVERY_TOL_M,
        recovery_limit_s: RECOVERY_LIMIT_S,
        min_flight_altitude_m: MIN_FLIGHT_ALTITUDE_M,
        max_touchdown_speed: MAX_TOUCHDOWN_SPEED,
        min_rate_fraction: MIN_RATE_FRACTION,
        failsafe_delay_limit_s: FAILSAFE_DELAY_LIMIT_S,
        landing_tol_m: LANDING_TOL_M,
        failsafe_landing_tol_m: 0.5,
    };

    /// A flight through PX4, judged on PX4's estimate (EKF2 on GNSS: decimetres of noise
    /// and drift, so the position criteria are wider): recovered within 0.5 m, landed within
    /// 1 m of home, touchdown at most 0.7 m/s; the rest as [`Criteria::SIMULATOR`].
    pub const PX4: Criteria = Criteria {
        recovery_tol_m: 0.5,
        max_touchdown_speed: 0.7,
        landing_tol_m: 1.0,
        failsafe_landing_tol_m: 1.5,
        ..Criteria::SIMULATOR
    };
}

/// Mean, 99th percentile and maximum.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TimeStats {
    /// Mean.
    pub mean: f64,
    /// 99th percentile (nearest rank).
    pub p99: f64,
    /// Maximum.
    pub max: f64,
    /// Number of values.
    pub count: usize,
}

impl TimeStats {
    /// Statistics of `values` (NaN ignored); zeros when empty.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Self {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let rank = ((0.99 * n as f64).ceil() as usize).clamp(1, n) - 1;
        Self {
            mean: v.iter().sum::<f64>() / n as f64,
            p99: v.get(rank).copied().unwrap_or_default(),
            max: v.last().copied().unwrap_or_default(),
            count: n,
        }
    }
}

/// The figures of one phase of one trial.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PhaseSummary {
    /// Phase name.
    pub phase: String,
    /// Start \[s\].
    pub start_s: f64,
    /// Duration \[s\].
    pub duration_s: f64,
    /// Largest position error \[m\].
    pub max_tracking_error_m: f64,
    /// RMS position error \[m\].
    pub rms_tracking_error_m: f64,
    /// RMS position error relative to the reference path length (at least 1 m) [%].
    pub tracking_error_pct: f64,
    /// Mean pitch-rate error relative to the reference rate [%] (phases with a rate
    /// reference only).
    pub rate_tracking_error_pct: Option<f64>,
    /// Recovery time after the flip \[s\] (the recover phase; `None` if never recovered).
    pub recovery_time_s: Option<f64>,
    /// Lowest height \[m\].
    pub min_altitude_m: f64,
    /// Height lost in the phase \[m\].
    pub altitude_loss_m: f64,
    /// Largest |pitch rate| [rad/s].
    pub peak_pitch_rate_rad_s: f64,
    /// Solver time per outer step \[us\].
    pub solver_time_us: TimeStats,
    /// Outer steps that fell back to the previous plan.
    pub fallbacks: u32,
}

/// The figures of one trial.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrialSummary {
    /// Seed of the trial.
    pub seed: u64,
    /// Whether every criterion held.
    pub success: bool,
    /// The criteria that failed, in words.
    pub failures: Vec<String>,
    /// How it ended: landed, crashed (why), timeout.
    pub outcome: String,
    /// Per phase, in the order flown.
    pub phases: Vec<PhaseSummary>,
    /// Total pitch rotation of the flip (largest accumulated) \[rad\].
    pub flip_rotation_rad: Option<f64>,
    /// Largest |pitch rate| in the flip [rad/s].
    pub peak_pitch_rate_rad_s: Option<f64>,
    /// Recovery time after the flip \[s\].
    pub recovery_time_s: Option<f64>,
    /// Lowest height from the ascent to the end of the hold \[m\].
    pub min_flight_altitude_m: Option<f64>,
    /// Vertical speed at touchdown [m/s].
    pub touchdown_speed_m_s: Option<f64>,
    /// Distance of the touchdown from the landing point \[m\].
    pub landing_error_m: Option<f64>,
    /// Delay from pose loss to return mode \[s\].
    pub failsafe_delay_s: Option<f64>,
    /// Solver time over the whole trial \[us\].
    pub solver_time_us: TimeStats,
    /// QP iterations per outer step, mean.
    pub qp_iterations_mean: f64,
    /// Fallbacks over the whole trial.
    pub fallbacks: u32,
    /// True mass \[kg\] (Monte Carlo draws differ).
    pub mass_kg: f64,
    /// True inertia diagonal [kg m^2].
    pub inertia: [f64; 3],
    /// True rotor time constant \[s\].
    pub rotor_tau_s: f64,
    /// Pose latency \[s\].
    pub latency_s: f64,
    /// Peak gust speed [m/s].
    pub gust_m_s: f64,
}

fn pos(s: &Sample) -> Vector3<f64> {
    Vector3::new(s.x, s.y, s.z)
}

fn pos_ref(s: &Sample) -> Vector3<f64> {
    Vector3::new(s.x_ref, s.y_ref, s.z_ref)
}

fn phase_of(i: u8) -> Phase {
    Phase::ALL
        .get(usize::from(i))
        .copied()
        .unwrap_or(Phase::Landed)
}

fn summarize_phase(rows: &[Sample]) -> PhaseSummary {
    let first = rows.first().copied().unwrap_or_default();
    let last = rows.last().copied().unwrap_or_default();
    let phase = phase_of(first.phase);
    let errs: Vec<f64> = rows.iter().map(|s| (pos(s) - pos_ref(s)).norm()).collect();
    let max_err = errs.iter().copied().fold(0.0, f64::max);
    let rms = if errs.is_empty() {
        0.0
    } else {
        (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt()
    };
    let path: f64 = rows
        .windows(2)
        .map(|w| match w {
            [a, b] => (pos_ref(b) - pos_ref(a)).norm(),
            _ => 0.0,
        })
        .sum();
    let min_alt = rows.iter().map(|s| s.z).fold(f64::INFINITY, f64::min);
    let rate_rows: Vec<&Sample> = rows.iter().filter(|s| s.wy_ref != 0.0).collect();
    let rate_pct = (!rate_rows.is_empty()).then(|| {
        let m = rate_rows
            .iter()
            .map(|s| ((s.wy - s.wy_ref) / s.wy_ref).abs())
            .sum::<f64>()
            / rate_rows.len() as f64;
        100.0 * m
    });
    PhaseSummary {
        phase: phase.name().to_string(),
        start_s: first.t,
        duration_s: last.t - first.t,
        max_tracking_error_m: max_err,
        rms_tracking_error_m: rms,
        tracking_error_pct: 100.0 * rms / path.max(1.0),
        rate_tracking_error_pct: rate_pct,
        recovery_time_s: None,
        min_altitude_m: if min_alt.is_finite() { min_alt } else { 0.0 },
        altitude_loss_m: (first.z - min_alt).max(0.0),
        peak_pitch_rate_rad_s: rows.iter().map(|s| s.wy.abs()).fold(0.0, f64::max),
        solver_time_us: TimeStats::of(rows.iter().map(|s| s.solver_us)),
        fallbacks: rows.iter().filter(|s| s.fallback).count() as u32,
    }
}

/// Recovery time: from `t0` (the flip's end) until the vehicle is within
/// [`RECOVERY_TOL_M`] of `target` for good, judged on `rows` up to `until`.
pub fn recovery_time(rows: &[Sample], target: &Vector3<f64>, t0: f64, until: f64) -> Option<f64> {
    recovery_time_within(rows, target, t0, until, RECOVERY_TOL_M)
}

/// [`recovery_time`] with another distance `tol` \[m\].
pub fn recovery_time_within(
    rows: &[Sample],
    target: &Vector3<f64>,
    t0: f64,
    until: f64,
    tol: f64,
) -> Option<f64> {
    let window: Vec<&Sample> = rows.iter().filter(|s| s.t >= t0 && s.t <= until).collect();
    let last = window.last()?;
    if (pos(last) - target).norm() >= tol {
        return None;
    }
    let last_out = window
        .iter()
        .rev()
        .find(|s| (pos(s) - target).norm() >= tol)
        .map_or(t0, |s| s.t);
    Some(last_out - t0)
}

/// How a trial ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Landed (touchdown, motors off).
    Landed,
    /// Crashed.
    Crashed(String),
    /// `t_max` reached in the air.
    Timeout,
}

/// A touchdown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Touchdown {
    /// Time \[s\].
    pub t: f64,
    /// Vertical speed at contact [m/s].
    pub vertical_speed: f64,
    /// Where \[m\].
    pub p: Vector3<f64>,
}

/// The vehicle and conditions a trial flew in, as its summary reports them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conditions {
    /// Seed of the noise.
    pub seed: u64,
    /// True mass \[kg\].
    pub mass_kg: f64,
    /// True inertia diagonal [kg m^2].
    pub inertia: [f64; 3],
    /// True rotor time constant \[s\].
    pub rotor_tau_s: f64,
    /// Pose latency \[s\].
    pub latency_s: f64,
    /// Peak gust speed [m/s].
    pub gust_m_s: f64,
}

impl Conditions {
    /// The simulator's nominal trial (`mpc_sim::run::SimConfig::new`): the design vehicle
    /// ([`QuadParams::default`]), motion-capture latency ([`EstimatorConfig::noisy`]), seed 0,
    /// no gust. A flight through PX4 is reported with these.
    pub fn nominal() -> Self {
        let p = QuadParams::default();
        Self {
            seed: 0,
            mass_kg: p.mass,
            inertia: [p.inertia.x, p.inertia.y, p.inertia.z],
            rotor_tau_s: p.rotor_tau,
            latency_s: EstimatorConfig::noisy().latency,
            gust_m_s: 0.0,
        }
    }
}

/// One flight as its summary reads it: the mission flown, the conditions, the log and how
/// it ended. The simulator makes one of each trial (`mpc_sim::run::TrialResult::flight`),
/// the PX4 shim of each flight from PX4's telemetry.
#[derive(Clone, Copy, Debug)]
pub struct Flight<'a> {
    /// The mission flown.
    pub mission: &'a MissionConfig,
    /// The vehicle and conditions.
    pub conditions: Conditions,
    /// The log, one row per step.
    pub samples: &'a [Sample],
    /// How it ended.
    pub outcome: &'a Outcome,
    /// The last touchdown (after having flown).
    pub touchdown: Option<Touchdown>,
    /// When the pose was first lost, if it was \[s\].
    pub pose_lost_at: Option<f64>,
    /// When return mode engaged, if it did \[s\].
    pub failsafe_at: Option<f64>,
}

/// Summarizes one flight and judges it by the criteria `c`.
pub fn summarize_flight(res: &Flight<'_>, c: &Criteria) -> TrialSummary {
    let rows = res.samples;
    let fig = measure(res, c);
    let failures = judge(res, &fig, c);
    let outer: Vec<&Sample> = rows.iter().filter(|s| s.solver_us.is_finite()).collect();
    let qp_mean = if outer.is_empty() {
        0.0
    } else {
        outer.iter().map(|s| s.qp_iterations).sum::<f64>() / outer.len() as f64
    };
    let k = &res.conditions;
    TrialSummary {
        seed: k.seed,
        success: failures.is_empty(),
        failures,
        outcome: match res.outcome {
            Outcome::Landed => "landed".to_string(),
            Outcome::Crashed(w) => format!("crashed ({w})"),
            Outcome::Timeout => "timeout".to_string(),
        },
        phases: fig.phases,
        flip_rotation_rad: fig.rotation,
        peak_pitch_rate_rad_s: fig.peak_rate,
        recovery_time_s: fig.recovery,
        min_flight_altitude_m: fig.min_flight_alt,
        touchdown_speed_m_s: res.touchdown.map(|t| t.vertical_speed.abs()),
        landing_error_m: fig.landing_error,
        failsafe_delay_s: fig.failsafe_delay,
        solver_time_us: TimeStats::of(rows.iter().map(|s| s.solver_us)),
        qp_iterations_mean: qp_mean,
        fallbacks: rows.iter().filter(|s| s.fallback).count() as u32,
        mass_kg: k.mass_kg,
        inertia: k.inertia,
        rotor_tau_s: k.rotor_tau_s,
        latency_s: k.latency_s,
        gust_m_s: k.gust_m_s,
    }
}

/// The figures a flight is judged on.
struct Figures {
    /// Per phase, in the order flown.
    phases: Vec<PhaseSummary>,
    /// Whether the flip was flown.
    flip_flown: bool,
    recovery: Option<f64>,
    min_flight_alt: Option<f64>,
    rotation: Option<f64>,
    peak_rate: Option<f64>,
    landing_error: Option<f64>,
    failsafe_delay: Option<f64>,
}

/// One pass over the log's phases: the figures of each phase and of the flight.
fn measure(res: &Flight<'_>, c: &Criteria) -> Figures {
    let rows = res.samples;
    let phases = phase_runs(rows);
    let flip = first_run(&phases, Phase::Flip);
    let recover = first_run(&phases, Phase::Recover);
    let flip_end = recover.and_then(|r| r.first().map(|s| s.t));
    let recovery = recovery_after_flip(
        rows,
        &phases,
        recover,
        &res.mission.rally_point,
        c.recovery_tol_m,
    );
    let mut summaries: Vec<PhaseSummary> = phases.iter().map(|r| summarize_phase(r)).collect();
    for s in &mut summaries {
        if s.phase == Phase::Recover.name() {
            s.recovery_time_s = recovery;
        }
    }
    let rotation = flip.map(|_| rows.iter().map(|s| s.pitch_turned).fold(0.0, f64::max));
    let peak_rate = flip.map(|_| {
        rows.iter()
            .filter(|s| matches!(phase_of(s.phase), Phase::Flip | Phase::Recover))
            .map(|s| s.wy.abs())
            .fold(0.0, f64::max)
    });
    Figures {
        phases: summaries,
        flip_flown: flip.is_some(),
        recovery,
        min_flight_alt: lowest_in_flight(rows, flip_end),
        rotation,
        peak_rate,
        landing_error: landing_error(res),
        failsafe_delay: match (res.pose_lost_at, res.failsafe_at) {
            (Some(a), Some(b)) => Some(b - a),
            _ => None,
        },
    }
}

/// The log split into runs of one phase, in the order flown.
fn phase_runs(rows: &[Sample]) -> Vec<&[Sample]> {
    let mut phases = Vec::new();
    let mut start = 0;
    for i in 1..=rows.len() {
        let boundary =
            i == rows.len() || rows.get(i).map(|s| s.phase) != rows.get(start).map(|s| s.phase);
        if boundary {
            if let Some(run) = rows.get(start..i) {
                phases.push(run);
            }
            start = i;
        }
    }
    phases
}

/// The first run of phase `p`.
fn first_run<'a>(phases: &[&'a [Sample]], p: Phase) -> Option<&'a [Sample]> {
    phases
        .iter()
        .find(|r| r.first().is_some_and(|s| s.phase == p.index()))
        .copied()
}

/// The recovery time after the flip (from the flip's end, the start of `recover`), judged
/// up to the end of the hold after the flip (or of the recovery, without a hold).
fn recovery_after_flip(
    rows: &[Sample],
    phases: &[&[Sample]],
    recover: Option<&[Sample]>,
    rally_point: &Vector3<f64>,
    tol: f64,
) -> Option<f64> {
    let hold_after_flip = recover.and_then(|r| {
        let end = r.last()?.t;
        phases
            .iter()
            .find(|h| {
                h.first()
                    .is_some_and(|s| s.phase == Phase::Hold.index() && s.t >= end)
            })
            .copied()
    });
    let flip_end = recover.and_then(|r| r.first().map(|s| s.t));
    let until = hold_after_flip
        .and_then(|h| h.last().map(|s| s.t))
        .or_else(|| recover.and_then(|r| r.last().map(|s| s.t)));
    match (flip_end, until) {
        (Some(t0), Some(t1)) => recovery_time_within(rows, rally_point, t0, t1, tol),
        _ => None,
    }
}

/// The lowest height from the ascent to the end of the hold after the flip (which ends at
/// `flip_end`); `None` without such rows.
fn lowest_in_flight(rows: &[Sample], flip_end: Option<f64>) -> Option<f64> {
    let flight_rows: Vec<&Sample> = rows
        .iter()
        .filter(|s| {
            let p = phase_of(s.phase);
            matches!(p, Phase::Ascend | Phase::Flip | Phase::Recover)
                || (p == Phase::Hold && flip_end.is_some_and(|t| s.t >= t))
        })
        .collect();
    (!flight_rows.is_empty()).then(|| {
        flight_rows
            .iter()
            .map(|s| s.z)
            .fold(f64::INFINITY, f64::min)
    })
}

/// The horizontal distance of the touchdown from the mission's landing point.
fn landing_error(res: &Flight<'_>) -> Option<f64> {
    let m = res.mission;
    let landing_point = match m.kind {
        MissionKind::Step => m.takeoff_point + m.step,
        MissionKind::Flip | MissionKind::Hover => m.home,
    };
    res.touchdown.map(|td| {
        let d = td.p - landing_point;
        (d.x * d.x + d.y * d.y).sqrt()
    })
}

/// The criteria `fig` fails, in words: the landing's, then the failsafe's after a pose
/// loss or the flip's.
fn judge(res: &Flight<'_>, fig: &Figures, c: &Criteria) -> Vec<String> {
    let mut failures = landing_failures(res, fig, c);
    if res.pose_lost_at.is_some() {
        match fig.failsafe_delay {
            Some(d) if d <= c.failsafe_delay_limit_s => {}
            Some(d) => failures.push(format!("return mode engaged {d:.3} s after the pose loss")),
            None => failures.push("pose lost but return mode never engaged".to_string()),
        }
    } else if res.mission.kind == MissionKind::Flip {
        failures.extend(flip_failures(res.mission, fig, c));
    }
    failures
}

/// How it ended, the touchdown's speed and place.
fn landing_failures(res: &Flight<'_>, fig: &Figures, c: &Criteria) -> Vec<String> {
    let mut failures = Vec::new();
    match res.outcome {
        Outcome::Landed => {}
        Outcome::Crashed(why) => failures.push(format!("crashed: {why}")),
        Outcome::Timeout => failures.push("did not land before the time limit".to_string()),
    }
    if let Some(v) = res.touchdown.map(|t| t.vertical_speed)
        && v.abs() >= c.max_touchdown_speed
    {
        failures.push(format!(
            "touchdown at {v:.2} m/s (limit {})",
            c.max_touchdown_speed
        ));
    }
    let landing_tol = if res.failsafe_at.is_some() {
        c.failsafe_landing_tol_m
    } else {
        c.landing_tol_m
    };
    if let Some(e) = fig.landing_error
        && e > landing_tol
    {
        failures.push(format!(
            "landed {e:.2} m from the landing point (limit {landing_tol})"
        ));
    }
    failures
}

/// The flip's full turn, its rate, the height around it and the recovery.
fn flip_failures(m: &MissionConfig, fig: &Figures, c: &Criteria) -> Vec<String> {
    let mut failures = Vec::new();
    match fig.rotation {
        Some(r) if r >= 2.0 * PI => {}
        Some(r) => failures.push(format!("flip turned only {:.0} deg", r.to_degrees())),
        None => failures.push("the flip never started".to_string()),
    }
    if let Some(p) = fig.peak_rate
        && p < c.min_rate_fraction * m.flip_rate
    {
        failures.push(format!(
            "peak pitch rate {p:.1} rad/s < {:.0} % of {:.1}",
            c.min_rate_fraction * 100.0,
            m.flip_rate
        ));
    }
    if let Some(z) = fig.min_flight_alt
        && z < c.min_flight_altitude_m
    {
        failures.push(format!("went down to {z:.2} m around the flip"));
    }
    match fig.recovery {
        Some(r) if r <= c.recovery_limit_s => {}
        Some(r) => failures.push(format!("recovered only after {r:.2} s")),
        None if fig.flip_flown => failures.push(format!(
            "not back within {} m of the rally point by the end of the hold",
            c.recovery_tol_m
        )),
        None => {}
    }
    failures
}

/// Per-phase figures over several trials: the worst of each.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PhaseAggregate {
    /// Phase name.
    pub phase: String,
    /// Largest position error over the trials \[m\].
    pub max_tracking_error_m: f64,
    /// Largest relative RMS error [%].
    pub tracking_error_pct: f64,
    /// Largest relative pitch-rate error [%].
    pub rate_tracking_error_pct: Option<f64>,
    /// Longest recovery \[s\] (`None`: some trial never recovered, or no recovery phase).
    pub recovery_time_s: Option<f64>,
    /// Lowest height \[m\].
    pub min_altitude_m: f64,
    /// Largest altitude loss \[m\].
    pub altitude_loss_m: f64,
    /// Smallest peak pitch rate over the trials [rad/s] (the weakest flip).
    pub peak_pitch_rate_rad_s: f64,
    /// Solver time per step over all trials \[us\].
    pub solver_time_us: TimeStats,
    /// Fallbacks over all trials.
    pub fallbacks: u32,
}

/// The summary of a run of one or more trials (the JSON of `mpcc sim --json`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunSummary {
    /// Mission name.
    pub mission: String,
    /// Controller name.
    pub controller: String,
    /// Whether every trial succeeded.
    pub success: bool,
    /// Trials flown.
    pub trials: usize,
    /// Trials that met every criterion.
    pub successes: usize,
    /// successes / trials.
    pub success_rate: f64,
    /// Per phase, worst over the trials.
    pub phases: Vec<PhaseAggregate>,
    /// Solver time per step over all trials \[us\].
    pub solver_time_us: TimeStats,
    /// Fallbacks over all trials.
    pub fallbacks: u32,
    /// The failed trials (all of them), then the worst successful ones by recovery time, at
    /// most 5 in all.
    pub worst: Vec<TrialSummary>,
    /// The first trial in full.
    pub first: Option<TrialSummary>,
}

/// Aggregates trial summaries.
pub fn aggregate(mission: &str, controller: &str, trials: &[TrialSummary]) -> RunSummary {
    let successes = trials.iter().filter(|t| t.success).count();
    let mut order: Vec<String> = Vec::new();
    for t in trials {
        for p in &t.phases {
            if !order.contains(&p.phase) {
                order.push(p.phase.clone());
            }
        }
    }
    let phases = order
        .iter()
        .map(|name| {
            let ps: Vec<&PhaseSummary> = trials
                .iter()
                .flat_map(|t| t.phases.iter().filter(|p| &p.phase == name))
                .collect();
            let rate: Vec<f64> = ps
                .iter()
                .filter_map(|p| p.rate_tracking_error_pct)
                .collect();
            let is_recover = name == Phase::Recover.name();
            let rec: Vec<Option<f64>> = ps.iter().map(|p| p.recovery_time_s).collect();
            PhaseAggregate {
                phase: name.clone(),
                max_tracking_error_m: ps
                    .iter()
                    .map(|p| p.max_tracking_error_m)
                    .fold(0.0, f64::max),
                tracking_error_pct: ps.iter().map(|p| p.tracking_error_pct).fold(0.0, f64::max),
                rate_tracking_error_pct: (!rate.is_empty())
                    .then(|| rate.iter().copied().fold(0.0, f64::max)),
                recovery_time_s: if is_recover && rec.iter().all(Option::is_some) {
                    rec.iter().flatten().copied().reduce(f64::max)
                } else {
                    None
                },
                min_altitude_m: ps
                    .iter()
                    .map(|p| p.min_altitude_m)
                    .fold(f64::INFINITY, f64::min),
                altitude_loss_m: ps.iter().map(|p| p.altitude_loss_m).fold(0.0, f64::max),
                peak_pitch_rate_rad_s: ps
                    .iter()
                    .map(|p| p.peak_pitch_rate_rad_s)
                    .fold(f64::INFINITY, f64::min),
                solver_time_us: pooled(ps.iter().map(|p| p.solver_time_us)),
                fallbacks: ps.iter().map(|p| p.fallbacks).sum(),
            }
        })
        .collect();
    let mut worst: Vec<TrialSummary> = trials.iter().filter(|t| !t.success).cloned().collect();
    let mut ok: Vec<&TrialSummary> = trials.iter().filter(|t| t.success).collect();
    ok.sort_by(|a, b| {
        b.recovery_time_s
            .unwrap_or_default()
            .total_cmp(&a.recovery_time_s.unwrap_or_default())
    });
    for t in ok {
        if worst.len() >= 5 {
            break;
        }
        worst.push(t.clone());
    }
    RunSummary {
        mission: mission.to_string(),
        controller: controller.to_string(),
        success: successes == trials.len() && !trials.is_empty(),
        trials: trials.len(),
        successes,
        success_rate: if trials.is_empty() {
            0.0
        } else {
            successes as f64 / trials.len() as f64
        },
        phases,
        solver_time_us: pooled(trials.iter().map(|t| t.solver_time_us)),
        fallbacks: trials.iter().map(|t| t.fallbacks).sum(),
        worst,
        first: trials.first().cloned(),
    }
}

/// Pools statistics: mean weighted by count, p99 and max as the largest (an upper bound for
/// the pooled p99).
fn pooled(stats: impl IntoIterator<Item = TimeStats>) -> TimeStats {
    let mut out = TimeStats::default();
    let mut sum = 0.0;
    for s in stats {
        sum += s.mean * s.count as f64;
        out.count += s.count;
        out.p99 = out.p99.max(s.p99);
        out.max = out.max.max(s.max);
    }
    if out.count > 0 {
        out.mean = sum / out.count as f64;
    }
    out
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_string(), |x| format!("{x:.digits$}"))
}

/// The summary as the table the CLI prints.
pub fn table(run: &RunSummary) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "mission {} · controller {} · {} of {} trials succeeded ({:.1} %)",
        run.mission,
        run.controller,
        run.successes,
        run.trials,
        100.0 * run.success_rate
    );
    let _ = writeln!(
        s,
        "{:<9} {:>9} {:>7} {:>9} {:>9} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>5}",
        "phase",
        "max err",
        "err",
        "rate err",
        "recovery",
        "min z",
        "alt loss",
        "peak wy",
        "solver",
        "p99",
        "max",
        "fall"
    );
    let _ = writeln!(
        s,
        "{:<9} {:>9} {:>7} {:>9} {:>9} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>5}",
        "", "m", "%", "%", "s", "m", "m", "rad/s", "mean us", "us", "us", "backs"
    );
    for p in &run.phases {
        let _ = writeln!(
            s,
            "{:<9} {:>9.3} {:>7.1} {:>9} {:>9} {:>8.2} {:>9.2} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>5}",
            p.phase,
            p.max_tracking_error_m,
            p.tracking_error_pct,
            opt(p.rate_tracking_error_pct, 1),
            opt(p.recovery_time_s, 2),
            p.min_altitude_m,
            p.altitude_loss_m,
            p.peak_pitch_rate_rad_s,
            p.solver_time_us.mean,
            p.solver_time_us.p99,
            p.solver_time_us.max,
            p.fallbacks
        );
    }
    if let Some(f) = &run.first {
        let mut line = format!("trial seed {}: {}", f.seed, f.outcome);
        if let Some(r) = f.flip_rotation_rad {
            let _ = write!(
                line,
                "; flip {:.0} deg, peak pitch rate {} rad/s, recovered in {} s, lowest {} m \
                 around the flip",
                r.to_degrees(),
                opt(f.peak_pitch_rate_rad_s, 1),
                opt(f.recovery_time_s, 2),
                opt(f.min_flight_altitude_m, 2)
            );
        }
        let _ = writeln!(
            s,
            "{line}; touchdown {} m/s, {} m from the landing point",
            opt(f.touchdown_speed_m_s, 2),
            opt(f.landing_error_m, 2)
        );
        if let Some(d) = f.failsafe_delay_s {
            let _ = writeln!(s, "pose lost: return mode engaged after {d:.3} s");
        }
    }
    if run.trials > 1 && !run.worst.is_empty() {
        let _ = writeln!(
            s,
            "worst cases (failed first, then the slowest recoveries):"
        );
    }
    for w in run.worst.iter().filter(|w| run.trials > 1 || !w.success) {
        let verdict = if w.success {
            format!("ok, recovered in {} s", opt(w.recovery_time_s, 2))
        } else {
            w.failures.join("; ")
        };
        let _ = writeln!(
            s,
            "{} seed {} (mass {:.2} kg, rotor tau {:.0} ms, latency {:.1} ms, gust {:.1} m/s): {}",
            if w.success { "  " } else { "FAILED" },
            w.seed,
            w.mass_kg,
            w.rotor_tau_s * 1e3,
            w.latency_s * 1e3,
            w.gust_m_s,
            verdict
        );
    }
    s
}
