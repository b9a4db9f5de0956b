//! The closed loop: plant, estimator, mission, outer loop, rate loop, at a fixed step.

use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::controller::{self, ControllerKind, InnerCommand, MassEstimator, OuterStats};
use crate::estimator::{Estimator, EstimatorConfig};
use crate::log::Sample;
use crate::mission::{G, Mission, MissionConfig, MissionInput, Phase, Transition};
use crate::plant::{Contact, Disturbance, Plant, QuadParams, QuadState};
use crate::rate_loop::{RateController, RateGains};
use crate::report::{Conditions, Flight};

pub use mpc_mission::report::{Outcome, Touchdown};

/// A wind gust: the air velocity rises and falls as 1 - cos over `duration`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gust {
    /// Start \[s\].
    pub start: f64,
    /// Duration \[s\].
    pub duration: f64,
    /// Peak air velocity [m/s] (world).
    pub peak: Vector3<f64>,
}

impl Gust {
    /// Air velocity at time `t`.
    pub fn wind(&self, t: f64) -> Vector3<f64> {
        if self.duration <= 0.0 || t < self.start || t > self.start + self.duration {
            return Vector3::zeros();
        }
        let s = (t - self.start) / self.duration;
        self.peak * (0.5 * (1.0 - (2.0 * core::f64::consts::PI * s).cos()))
    }
}

/// Everything one closed-loop trial needs.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// The mission.
    pub mission: MissionConfig,
    /// The outer-loop architecture.
    pub controller: ControllerKind,
    /// The true vehicle.
    pub plant: QuadParams,
    /// What the controllers believe the vehicle is (the rate loop's mixer, the thrust map).
    pub nominal: QuadParams,
    /// Rate-loop gains.
    pub gains: RateGains,
    /// Estimation model.
    pub estimator: EstimatorConfig,
    /// Optional wind gust.
    pub gust: Option<Gust>,
    /// Seed of the noise.
    pub seed: u64,
    /// Plant and rate-loop step \[s\] (1 kHz).
    pub dt: f64,
    /// The trial ends at this time at the latest \[s\].
    pub t_max: f64,
}

impl SimConfig {
    /// The default flip trial: nominal vehicle, motion-capture noise, no gust.
    pub fn new(mission: MissionConfig, controller: ControllerKind) -> Self {
        Self {
            mission,
            controller,
            plant: QuadParams::default(),
            nominal: QuadParams::default(),
            gains: RateGains::default(),
            estimator: EstimatorConfig::noisy(),
            gust: None,
            seed: 0,
            dt: 0.001,
            t_max: 60.0,
        }
    }

    /// The paper's trial 9: the pose is lost at the middle of the flip (inverted) and does
    /// not come back.
    pub fn with_pose_loss_in_flip(mut self, from: f64) -> Self {
        self.estimator.dropouts.push((from, f64::INFINITY));
        self
    }

    /// The vehicle and conditions of this configuration, as a trial's summary reports them.
    pub fn conditions(&self) -> Conditions {
        Conditions {
            seed: self.seed,
            mass_kg: self.plant.mass,
            inertia: [
                self.plant.inertia.x,
                self.plant.inertia.y,
                self.plant.inertia.z,
            ],
            rotor_tau_s: self.plant.rotor_tau,
            latency_s: self.estimator.latency,
            gust_m_s: self.gust.map_or(0.0, |g| g.peak.norm()),
        }
    }

    /// A Monte Carlo draw around this configuration: true mass +-20 %, inertia +-30 % per
    /// axis, rotor time constant 20..40 ms, pose latency 0..10 ms, motion-capture noise, and a
    /// horizontal gust of up to 3 m/s lasting 1..2 s somewhere in the mission.
    pub fn randomized(&self, seed: u64) -> Self {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed_cafe_f00d_d00d);
        let mut c = self.clone();
        c.seed = seed;
        c.plant.mass *= rng.random_range(0.8..=1.2);
        for i in 0..3 {
            c.plant.inertia[i] *= rng.random_range(0.7..=1.3);
        }
        c.plant.rotor_tau = rng.random_range(0.02..=0.04);
        c.estimator = EstimatorConfig {
            latency: rng.random_range(0.0..=0.01),
            dropouts: self.estimator.dropouts.clone(),
            ..EstimatorConfig::noisy()
        };
        let dir = rng.random_range(0.0..core::f64::consts::TAU);
        let speed = rng.random_range(0.0..=3.0);
        c.gust = Some(Gust {
            start: rng.random_range(4.0..=20.0),
            duration: rng.random_range(1.0..=2.0),
            peak: Vector3::new(dir.cos(), dir.sin(), 0.0) * speed,
        });
        c
    }
}

/// Everything one trial produced.
#[derive(Clone, Debug)]
pub struct TrialResult {
    /// The configuration it ran with.
    pub config: SimConfig,
    /// The log, one row per step.
    pub samples: Vec<Sample>,
    /// Phase changes.
    pub transitions: Vec<Transition>,
    /// How it ended.
    pub outcome: Outcome,
    /// The last touchdown (after having flown).
    pub touchdown: Option<Touchdown>,
    /// When the pose was first lost, if it was \[s\].
    pub pose_lost_at: Option<f64>,
    /// When return mode engaged, if it did \[s\].
    pub failsafe_at: Option<f64>,
}

impl TrialResult {
    /// The trial as its summary reads it ([`crate::report::summarize_flight`]).
    pub fn flight(&self) -> Flight<'_> {
        Flight {
            mission: &self.config.mission,
            conditions: self.config.conditions(),
            samples: &self.samples,
            outcome: &self.outcome,
            touchdown: self.touchdown,
            pose_lost_at: self.pose_lost_at,
            failsafe_at: self.failsafe_at,
        }
    }
}

/// A configuration the simulator cannot fly.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SimError {
    /// A parameter is out of its range; the message names it and the range.
    #[error("invalid simulation setting: {0}")]
    Invalid(String),
}

impl SimConfig {
    /// Checks the settings a trial depends on.
    ///
    /// # Errors
    /// [`SimError::Invalid`] naming the first bad setting.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |what: &str| Err(SimError::Invalid(what.to_string()));
        if !(self.dt.is_finite() && self.dt > 0.0 && self.dt <= 0.004) {
            return bad("dt must be in (0, 0.004] s (the rate loop runs at 250 Hz or faster)");
        }
        if !(self.t_max.is_finite() && self.t_max > 0.0 && self.t_max <= 3600.0) {
            return bad("t_max must be in (0, 3600] s");
        }
        for (name, p) in [("plant", &self.plant), ("nominal", &self.nominal)] {
            let inertia_ok = p.inertia.iter().all(|v| v.is_finite() && *v > 0.0);
            if !(p.mass.is_finite() && p.mass > 0.0 && inertia_ok) {
                return Err(SimError::Invalid(format!(
                    "{name}: mass and inertia must be finite and positive"
                )));
            }
            if !(p.rotor_tau.is_finite() && p.rotor_tau > 0.0) {
                return Err(SimError::Invalid(format!(
                    "{name}: rotor_tau must be finite and positive"
                )));
            }
        }
        if !(self.estimator.latency.is_finite() && (0.0..=0.5).contains(&self.estimator.latency)) {
            return bad("estimator latency must be in [0, 0.5] s");
        }
        Ok(())
    }
}

/// Runs one closed-loop trial.
///
/// # Errors
/// [`SimError`] if the configuration is invalid ([`SimConfig::validate`]).
pub fn run_trial(cfg: &SimConfig) -> Result<TrialResult, SimError> {
    cfg.validate()?;
    let dt = cfg.dt;
    let mut plant = Plant::new(cfg.plant.clone(), QuadState::at_rest(cfg.mission.home));
    let mut est = Estimator::new(cfg.estimator.clone(), cfg.seed);
    let mut mission = Mission::new(cfg.mission.clone());
    let mut ctrl = controller::make(cfg.controller);
    let mut rate = RateController::new(&cfg.nominal, cfg.gains.clone());
    let mut mass = MassEstimator::new(cfg.nominal.mass);
    let mut samples = Vec::with_capacity((cfg.t_max / dt) as usize / 2);
    let mut next_outer = 0.0;
    let mut pending: Option<OuterStats> = None;
    let mut touchdown = None;
    let mut pose_lost_at = None;
    let mut outcome = Outcome::Timeout;
    let mut on_ground = true;
    let mut pitch_turned = 0.0;
    let mut flip_started = false;
    let mut v_prev = plant.state().v;
    let mut landed_at: Option<f64> = None;
    let steps = (cfg.t_max / dt).ceil() as usize;
    for i in 0..=steps {
        let t = i as f64 * dt;
        let truth = plant.state().clone();
        let e = est.update(t, &truth);
        if !e.pose_valid && pose_lost_at.is_none() {
            pose_lost_at = Some(t);
        }
        let phase = mission.update(&MissionInput {
            t,
            p: e.p,
            v: e.v,
            pose_valid: e.pose_valid,
            on_ground,
        });
        if phase == Phase::Landed {
            landed_at.get_or_insert(t);
        }
        if t + 1e-9 >= next_outer && phase != Phase::Landed {
            pending = Some(ctrl.outer(t, &e, &mission));
            next_outer += ctrl.period();
        }
        let cmd = ctrl.inner(t, &e, &mission);
        let (rotor_cmd, thrust_cmd) = if phase == Phase::Landed {
            rate.reset();
            ([0.0; 4], 0.0)
        } else {
            rate_loop_step(&mut rate, &cmd, mass.mass, &e.w, on_ground, dt)
        };
        if !on_ground && i > 0 {
            update_mass(&mut mass, &truth, &v_prev, thrust_cmd, &e.w, dt);
        }
        v_prev = truth.v;
        let wind = cfg.gust.map_or_else(Vector3::zeros, |g| g.wind(t));
        let dist = Disturbance {
            wind,
            ..Disturbance::default()
        };
        if phase == Phase::Flip {
            flip_started = true;
        }
        if flip_started {
            // The rotation about body y since the flip began.
            pitch_turned += truth.w.y * dt;
        }
        let r = mission.reference(t);
        let stats = pending.take();
        let fs = plant.rotor_thrusts();
        samples.push(Sample {
            phase: phase.index(),
            failsafe: mission.failsafe_since().is_some(),
            pose_valid: e.pose_valid,
            x_ref: r.p.x,
            y_ref: r.p.y,
            z_ref: r.p.z,
            pitch_turned,
            wx_cmd: cmd.rates.x,
            wy_cmd: cmd.rates.y,
            wz_cmd: cmd.rates.z,
            wy_ref: r.rate.y,
            thrust_cmd,
            ..Sample::at(t, &truth, fs, stats)
        });
        if landed_at.is_some_and(|tl| t - tl > 0.5) {
            outcome = Outcome::Landed;
            break;
        }
        match plant.step(&rotor_cmd, &dist, dt) {
            Contact::Crash { reason, .. } => {
                outcome = Outcome::Crashed(format!("{reason:?} at t = {:.3} s", t + dt));
                break;
            }
            Contact::Touchdown { vertical_speed, .. } => {
                on_ground = true;
                touchdown = Some(Touchdown {
                    t: t + dt,
                    vertical_speed,
                    p: plant.state().p,
                });
            }
            Contact::OnGround => on_ground = true,
            Contact::Airborne => on_ground = false,
        }
    }
    Ok(TrialResult {
        config: cfg.clone(),
        samples,
        transitions: mission.transitions().to_vec(),
        outcome,
        touchdown,
        pose_lost_at,
        failsafe_at: mission.failsafe_since(),
    })
}

/// One step of the rate loop on the outer loop's command: the rotor commands and the
/// collective thrust \[N\] (the estimated mass times the commanded acceleration). On the
/// ground the integrator is reset: no wind-up against the ground.
fn rate_loop_step(
    rate: &mut RateController,
    cmd: &InnerCommand,
    mass: f64,
    gyro: &Vector3<f64>,
    on_ground: bool,
    dt: f64,
) -> ([f64; 4], f64) {
    let thrust = (mass * cmd.thrust_c).max(0.0);
    let out = rate.update(&cmd.rates, thrust, gyro, dt);
    if on_ground {
        rate.reset();
    }
    (out.rotor_cmd, thrust)
}

/// Feeds the mass estimator the accelerometer (the specific force along body z, from the
/// true motion since the last step's velocity `v_prev`) and the commanded thrust.
fn update_mass(
    mass: &mut MassEstimator,
    truth: &QuadState,
    v_prev: &Vector3<f64>,
    thrust: f64,
    gyro: &Vector3<f64>,
    dt: f64,
) {
    let a_true = (truth.v - v_prev) / dt;
    let b3 = truth.q * Vector3::z();
    let sf = (a_true + Vector3::z() * G).dot(&b3);
    mass.update(thrust, sf, b3.z, gyro.norm(), dt);
}
