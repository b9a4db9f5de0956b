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

pub use mpc_mission::estimate::{Estimate, EstimatorConfig};
use mpc_mission::vehicle::QuadState;

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
