//! What the controllers see of the vehicle: the [`Estimate`] at one instant, and how good
//! it is ([`EstimatorConfig`]: noise, latency, dropouts). The simulator's estimation model
//! (`mpc_sim::estimator`) makes estimates of its plant's true state; the PX4 shim makes them
//! from PX4's telemetry.

use nalgebra::{UnitQuaternion, Vector3};

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
