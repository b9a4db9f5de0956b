//! The estimation model: what the controllers see of the true state.
//!
//! Two sources, as on the paper's vehicle: a pose source (motion capture: position, attitude,
//! and the velocity the flight controller's filter derives from them) with noise and a
//! latency, which can drop out; and the IMU (gyro and accelerometer), always available and
//! without latency, which the rate loop uses. While the pose is lost the estimate is dead
//! reckoning: the position and velocity drift as a random walk that grows with the time
//! since the loss (the attitude stays good: the gyro carries it), and
//! [`Estimate::pose_valid`] is false so the mission's failsafe can react.

use std::collections::VecDeque;

use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use crate::plant::QuadState;

/// Noise, latency and dropouts of the estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct EstimatorConfig {
    /// Latency of the pose source \[s\] (the paper's motion capture: a few ms).
    pub latency: f64,
    /// Standard deviation of the position noise, per axis \[m\].
    pub pos_noise: f64,
    /// Standard deviation of the velocity noise, per axis [m/s].
    pub vel_noise: f64,
    /// Standard deviation of the attitude noise, per axis (small rotation vector) \[rad\].
    pub att_noise: f64,
    /// Standard deviation of the gyro noise, per axis [rad/s].
    pub gyro_noise: f64,
    /// Windows `[start, end)` \[s\] in which the pose is lost.
    pub dropouts: Vec<(f64, f64)>,
    /// Dead-reckoning drift while the pose is lost: random-walk intensity of the velocity
    /// error [m/s per sqrt(s)] (the position error is its integral).
    pub drift: f64,
    /// Correlation time of the pose noise \[s\]: the flight controller's filter smooths the
    /// motion-capture samples, so the error is coloured (first-order Gauss-Markov with the
    /// standard deviations above), not white at the simulation rate. 0: white.
    pub noise_correlation: f64,
}

impl EstimatorConfig {
    /// The true state, undelayed, without noise or dropouts.
    pub fn perfect() -> Self {
        Self {
            latency: 0.0,
            pos_noise: 0.0,
            vel_noise: 0.0,
            att_noise: 0.0,
            gyro_noise: 0.0,
            dropouts: Vec::new(),
            drift: 0.0,
            noise_correlation: 0.0,
        }
    }

    /// Motion-capture-like noise: 5 mm position, 0.02 m/s velocity, 0.005 rad attitude
    /// (correlated over 20 ms), 0.02 rad/s gyro (white), 5 ms latency.
    pub fn noisy() -> Self {
        Self {
            latency: 0.005,
            pos_noise: 0.005,
            vel_noise: 0.02,
            att_noise: 0.005,
            gyro_noise: 0.02,
            dropouts: Vec::new(),
            drift: 0.01,
            noise_correlation: 0.02,
        }
    }

    /// Whether the pose is lost at time `t`.
    pub fn pose_lost(&self, t: f64) -> bool {
        self.dropouts.iter().any(|&(a, b)| t >= a && t < b)
    }
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self::noisy()
    }
}

/// What the controllers see at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Time of the estimate \[s\].
    pub t: f64,
    /// Position \[m\].
    pub p: Vector3<f64>,
    /// Velocity [m/s].
    pub v: Vector3<f64>,
    /// Attitude body to world.
    pub q: UnitQuaternion<f64>,
    /// Gyro: body rates [rad/s] (no latency).
    pub w: Vector3<f64>,
    /// Whether the pose source delivered this estimate (false: dead reckoning).
    pub pose_valid: bool,
}

/// The estimator: a delay line of true states plus noise and dropouts.
#[derive(Clone, Debug)]
pub struct Estimator {
    cfg: EstimatorConfig,
    history: VecDeque<(f64, QuadState)>,
    rng: StdRng,
    drift_v: Vector3<f64>,
    drift_p: Vector3<f64>,
    last_t: Option<f64>,
    /// Coloured pose noise: position, velocity, attitude.
    colored: [Vector3<f64>; 3],
}

fn clean_std(std: f64) -> f64 {
    // A non-finite or negative deviation is treated as zero noise.
    if std.is_finite() && std > 0.0 {
        std
    } else {
        0.0
    }
}

impl Estimator {
    /// An estimator with its own random stream (`seed`).
    pub fn new(cfg: EstimatorConfig, seed: u64) -> Self {
        Self {
            cfg,
            history: VecDeque::new(),
            rng: StdRng::seed_from_u64(seed),
            drift_v: Vector3::zeros(),
            drift_p: Vector3::zeros(),
            last_t: None,
            colored: [Vector3::zeros(); 3],
        }
    }

    /// The configuration.
    pub fn config(&self) -> &EstimatorConfig {
        &self.cfg
    }

    fn vec_noise(&mut self, std: f64) -> Vector3<f64> {
        let s = clean_std(std);
        if s == 0.0 {
            return Vector3::zeros();
        }
        let mut g = || -> f64 { StandardNormal.sample(&mut self.rng) };
        Vector3::new(g(), g(), g()) * s
    }

    /// Records the true state at time `t` and returns the estimate the controllers see now.
    /// Call once per simulation step, with increasing `t`.
    pub fn update(&mut self, t: f64, truth: &QuadState) -> Estimate {
        let dt = self.last_t.map_or(0.0, |l| (t - l).max(0.0));
        self.last_t = Some(t);
        self.history.push_back((t, truth.clone()));
        // Keep only what the latency needs (plus one older entry).
        let horizon = t - self.cfg.latency.max(0.0);
        while self.history.len() > 1 && self.history.get(1).is_some_and(|e| e.0 <= horizon) {
            self.history.pop_front();
        }
        let delayed = self
            .history
            .front()
            .map_or_else(|| truth.clone(), |e| e.1.clone());
        let lost = self.cfg.pose_lost(t);
        if lost {
            let dv = self.vec_noise(self.cfg.drift * dt.sqrt());
            self.drift_v += dv;
            self.drift_p += self.drift_v * dt;
        } else {
            self.drift_v = Vector3::zeros();
            self.drift_p = Vector3::zeros();
        }
        // First-order Gauss-Markov: x+ = a x + sqrt(1 - a^2) sigma n keeps the variance.
        let tc = self.cfg.noise_correlation;
        let a = if tc > 0.0 && dt > 0.0 {
            (-dt / tc).exp()
        } else {
            0.0
        };
        let b = (1.0 - a * a).sqrt();
        let stds = [self.cfg.pos_noise, self.cfg.vel_noise, self.cfg.att_noise];
        for (i, std) in stds.into_iter().enumerate() {
            let n = self.vec_noise(std);
            if let Some(c) = self.colored.get_mut(i) {
                *c = *c * a + n * b;
            }
        }
        let [np, nv, na] = self.colored;
        let p = delayed.p + np + self.drift_p;
        let v = delayed.v + nv + self.drift_v;
        let dq = UnitQuaternion::from_scaled_axis(na);
        let q = delayed.q * dq;
        let w = truth.w + self.vec_noise(self.cfg.gyro_noise);
        Estimate {
            t,
            p,
            v,
            q,
            w,
            pose_valid: !lost,
        }
    }
}
