//! The controllers' attitude helpers, the mass estimator and the NMPC's thrust limit.

use mpc_mission::controller::{MassEstimator, NmpcController, aligned, attitude_rates};
use nalgebra::{UnitQuaternion, Vector3};

/// Integrating the geometric law's rates turns the attitude to the desired one, from small
/// and from large errors (but not exactly inverted, where eR vanishes).
#[test]
fn attitude_law_converges_with_its_time_constant() {
    let qd = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.5);
    for start in [
        UnitQuaternion::from_euler_angles(0.0, 0.05, 0.5),
        UnitQuaternion::from_euler_angles(1.0, -1.0, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 2.5),
    ] {
        let tau = 0.12;
        let mut q = start;
        let e0 = q.angle_to(&qd);
        let dt = 1e-4;
        for _ in 0..(tau / dt) as usize {
            let w = attitude_rates(&q, &qd, tau);
            q *= UnitQuaternion::from_scaled_axis(w * dt);
        }
        let e1 = q.angle_to(&qd);
        assert!(e1 < e0 * 0.5, "error {e0} -> {e1} after one time constant");
        for _ in 0..(5.0 * tau / dt) as usize {
            let w = attitude_rates(&q, &qd, tau);
            q *= UnitQuaternion::from_scaled_axis(w * dt);
        }
        assert!(q.angle_to(&qd) < 1e-3, "{}", q.angle_to(&qd));
    }
    // Small errors: the rate is (2/tau) times the error angle, directed to reduce it
    // (eR ~ the rotation vector from qd to q, for small angles).
    let q = qd * UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.01, 0.0));
    let w = attitude_rates(&q, &qd, 0.1);
    assert!((w - Vector3::new(0.0, -0.2, 0.0)).norm() < 1e-4, "{w}");
}

#[test]
fn quaternion_hemisphere_alignment() {
    let q = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.3);
    let a = aligned(&q, &[1.0, 0.0, 0.0, 0.0]);
    assert!(a[0] > 0.0);
    let b = aligned(&q, &[-1.0, 0.0, 0.0, 0.0]);
    assert_eq!(b, a.map(|e| -e));
}

#[test]
fn mass_estimator_finds_the_true_mass_in_hover() {
    let mut m = MassEstimator::new(1.0);
    // True mass 1.2 kg hovering: thrust 1.2 g gives specific force g along body z.
    for _ in 0..5000 {
        m.update(1.2 * 9.81, 9.81, 1.0, 0.0, 0.001);
    }
    assert!((m.mass - 1.2).abs() < 1e-3, "{}", m.mass);
    // Not updated while flipping or tilted.
    let before = m.mass;
    m.update(5.0, 4.0, -1.0, 15.0, 0.001);
    m.update(5.0, 4.0, 1.0, 15.0, 0.001);
    assert_eq!(m.mass, before);
}

#[test]
fn the_nmpcs_thrust_limit_is_validated_and_kept() {
    let mut c = NmpcController::new();
    assert_eq!(c.thrust_limit(), 20.0, "the model's bound");
    c.set_thrust_limit(14.5).unwrap();
    assert_eq!(c.thrust_limit(), 14.5);
    for bad in [f64::NAN, f64::INFINITY, -1.0] {
        assert!(c.set_thrust_limit(bad).is_err(), "{bad}");
        assert_eq!(c.thrust_limit(), 14.5, "unchanged after {bad}");
    }
}
