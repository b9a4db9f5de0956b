//! The estimation model.

use mpc_sim::estimator::{Estimator, EstimatorConfig};
use mpc_sim::plant::QuadState;
use nalgebra::{UnitQuaternion, Vector3};

fn state_at(t: f64) -> QuadState {
    let mut s = QuadState::at_rest(Vector3::new(t, 2.0 * t, 3.0));
    s.v = Vector3::new(1.0, 2.0, 0.0);
    s.w = Vector3::new(0.1, -0.2, 0.3 * t);
    s.q = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), t);
    s
}

#[test]
fn latency_delays_the_pose_but_not_the_gyro() {
    let cfg = EstimatorConfig {
        latency: 0.007,
        ..EstimatorConfig::perfect()
    };
    let mut e = Estimator::new(cfg, 0);
    let dt = 0.001;
    let mut last = None;
    for i in 0..100 {
        let t = i as f64 * dt;
        last = Some((t, e.update(t, &state_at(t))));
    }
    let (t, est) = last.unwrap();
    let delayed = state_at(t - 0.007);
    assert!(
        (est.p - delayed.p).norm() < 1e-9,
        "{} vs {}",
        est.p,
        delayed.p
    );
    assert!(est.q.angle_to(&delayed.q) < 1e-9);
    assert!(
        (est.w - state_at(t).w).norm() < 1e-12,
        "the gyro has no latency"
    );
    assert!(est.pose_valid);
}

#[test]
fn noise_has_the_configured_spread() {
    let cfg = EstimatorConfig {
        pos_noise: 0.01,
        gyro_noise: 0.05,
        noise_correlation: 0.0,
        ..EstimatorConfig::perfect()
    };
    let mut e = Estimator::new(cfg, 42);
    let truth = state_at(0.0);
    let n = 20_000;
    let (mut sp, mut sw, mut mean) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let est = e.update(i as f64 * 1e-3, &truth);
        let d = est.p - truth.p;
        mean += d.x;
        sp += d.norm_squared();
        sw += (est.w - truth.w).norm_squared();
    }
    let std_p = (sp / (3.0 * n as f64)).sqrt();
    let std_w = (sw / (3.0 * n as f64)).sqrt();
    assert!((std_p - 0.01).abs() < 0.0005, "{std_p}");
    assert!((std_w - 0.05).abs() < 0.002, "{std_w}");
    assert!((mean / n as f64).abs() < 0.0005);
}

#[test]
fn coloured_noise_keeps_its_variance_and_is_correlated() {
    let cfg = EstimatorConfig {
        pos_noise: 0.01,
        noise_correlation: 0.02,
        ..EstimatorConfig::perfect()
    };
    let mut e = Estimator::new(cfg, 7);
    let truth = state_at(0.0);
    let xs: Vec<f64> = (0..100_000)
        .map(|i| e.update(i as f64 * 1e-3, &truth).p.x - truth.p.x)
        .collect();
    let var = xs.iter().map(|x| x * x).sum::<f64>() / xs.len() as f64;
    assert!((var.sqrt() - 0.01).abs() < 0.001, "{}", var.sqrt());
    // Lag-1 autocorrelation of a Gauss-Markov process: exp(-dt/tc) = exp(-0.05) = 0.951.
    let c1 = xs.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (xs.len() - 1) as f64 / var;
    assert!((c1 - (-0.05f64).exp()).abs() < 0.01, "{c1}");
}

#[test]
fn dropouts_flag_the_pose_and_drift() {
    let cfg = EstimatorConfig {
        dropouts: vec![(0.5, 1.5)],
        drift: 0.05,
        ..EstimatorConfig::perfect()
    };
    let mut e = Estimator::new(cfg, 3);
    let truth = state_at(0.0);
    let mut errs = Vec::new();
    for i in 0..2000 {
        let t = i as f64 * 1e-3;
        let est = e.update(t, &truth);
        assert_eq!(est.pose_valid, !(0.5..1.5).contains(&t), "at {t}");
        errs.push((t, (est.p - truth.p).norm()));
    }
    let before = errs
        .iter()
        .filter(|e| e.0 < 0.5)
        .map(|e| e.1)
        .fold(0.0, f64::max);
    let during = errs
        .iter()
        .filter(|e| e.0 > 1.4 && e.0 < 1.5)
        .map(|e| e.1)
        .fold(0.0, f64::max);
    let after = errs
        .iter()
        .filter(|e| e.0 > 1.5)
        .map(|e| e.1)
        .fold(0.0, f64::max);
    assert_eq!(before, 0.0);
    assert!(during > 0.0, "no dead-reckoning drift");
    assert_eq!(after, 0.0, "the drift must reset when the pose returns");
}
