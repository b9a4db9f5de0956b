//! Frame conversions: hand-computed attitudes, the body-rate sign convention, and property
//! tests over random quaternions and vectors (seeded).

use std::f64::consts::{FRAC_PI_2, PI};

use firmware_shim::frames::{
    MIN_MAVLINK_QUAT_NORM, enu_to_ned, flu_to_frd, frd_to_flu, ned_to_enu, quat_enu_flu_to_ned_frd,
    quat_from_mavlink, quat_ned_frd_to_enu_flu, quat_to_mavlink,
};
use nalgebra::{Quaternion, Unit, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Hand-computed cases: a few roundings of `sin`, `cos` and `1/sqrt 2`.
const HAND_TOL: f64 = 1e-15;
/// Property tests (vectors of norm up to 100 through two rotations).
const PROP_TOL: f64 = 1e-12;
const SAMPLES: usize = 20_000;

fn deg(d: f64) -> f64 {
    d.to_radians()
}

fn axis_angle(axis: Vector3<f64>, angle: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), angle)
}

fn assert_vec_close(got: &Vector3<f64>, want: &Vector3<f64>, tol: f64, what: &str) {
    let err = (got - want).amax();
    assert!(
        err <= tol,
        "{what}: got {got:?}, want {want:?} (error {err:e} > {tol:e})"
    );
}

/// The same rotation: rotation matrices equal entry by entry (q and -q are the same rotation).
fn assert_same_rotation(
    got: &UnitQuaternion<f64>,
    want: &UnitQuaternion<f64>,
    tol: f64,
    what: &str,
) {
    let err = (got.to_rotation_matrix().matrix() - want.to_rotation_matrix().matrix()).amax();
    assert!(
        err <= tol,
        "{what}: got {got:?}, want {want:?} (matrix error {err:e} > {tol:e})"
    );
}

/// Components `[w, x, y, z]`, exactly as documented (sign included).
fn assert_components(got: &UnitQuaternion<f64>, want: [f64; 4], tol: f64, what: &str) {
    let g = [got.w, got.i, got.j, got.k];
    let err = g
        .iter()
        .zip(want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        err <= tol,
        "{what}: got {g:?}, want {want:?} (error {err:e} > {tol:e})"
    );
}

fn random_quat(rng: &mut StdRng) -> UnitQuaternion<f64> {
    loop {
        let q = Quaternion::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let n = q.norm();
        if n > 0.1 && n <= 1.0 {
            return UnitQuaternion::new_normalize(q);
        }
    }
}

fn random_vec(rng: &mut StdRng, scale: f64) -> Vector3<f64> {
    Vector3::new(
        rng.random_range(-scale..scale),
        rng.random_range(-scale..scale),
        rng.random_range(-scale..scale),
    )
}

#[test]
fn vector_maps_hand_cases() {
    let v = Vector3::new(1.0, 2.0, 3.0);
    assert_eq!(ned_to_enu(&v), Vector3::new(2.0, 1.0, -3.0));
    assert_eq!(enu_to_ned(&Vector3::new(2.0, 1.0, -3.0)), v);
    assert_eq!(frd_to_flu(&v), Vector3::new(1.0, -2.0, -3.0));
    assert_eq!(flu_to_frd(&Vector3::new(1.0, -2.0, -3.0)), v);
    // North, east, down in NED are north (+y), east (+x), down (-z) in ENU.
    assert_eq!(ned_to_enu(&Vector3::x()), Vector3::y());
    assert_eq!(ned_to_enu(&Vector3::y()), Vector3::x());
    assert_eq!(ned_to_enu(&Vector3::z()), -Vector3::z());
    // Right and down in FRD are -left and -up in FLU.
    assert_eq!(frd_to_flu(&Vector3::y()), -Vector3::y());
    assert_eq!(frd_to_flu(&Vector3::z()), -Vector3::z());
}

#[test]
fn level_nose_north_is_enu_yaw_90() {
    let q_enu = quat_ned_frd_to_enu_flu(&UnitQuaternion::identity());
    let h = deg(45.0);
    assert_components(
        &q_enu,
        [h.cos(), 0.0, 0.0, h.sin()],
        HAND_TOL,
        "NED identity",
    );
    assert_same_rotation(
        &q_enu,
        &axis_angle(Vector3::z(), FRAC_PI_2),
        HAND_TOL,
        "yaw +90 ENU",
    );
    // The nose points north: +y in ENU.
    assert_vec_close(&(q_enu * Vector3::x()), &Vector3::y(), HAND_TOL, "nose");
    // The thrust axis (FLU +z) points up.
    assert_vec_close(
        &(q_enu * Vector3::z()),
        &Vector3::z(),
        HAND_TOL,
        "thrust axis",
    );
    // And back.
    let back = quat_enu_flu_to_ned_frd(&q_enu);
    assert_same_rotation(&back, &UnitQuaternion::identity(), HAND_TOL, "back to NED");
}

#[test]
fn nose_east_is_enu_identity() {
    let q_ned = axis_angle(Vector3::z(), deg(90.0));
    // Yaw +90 deg in NED: the nose (FRD x) points east (NED y).
    assert_vec_close(
        &(q_ned * Vector3::x()),
        &Vector3::y(),
        HAND_TOL,
        "NED nose east",
    );
    let q_enu = quat_ned_frd_to_enu_flu(&q_ned);
    assert_components(&q_enu, [1.0, 0.0, 0.0, 0.0], HAND_TOL, "ENU identity");
    assert_vec_close(
        &(q_enu * Vector3::x()),
        &Vector3::x(),
        HAND_TOL,
        "ENU nose east",
    );
    // The ENU identity goes back to yaw 90 deg in NED.
    let back = quat_enu_flu_to_ned_frd(&UnitQuaternion::identity());
    assert_same_rotation(&back, &q_ned, HAND_TOL, "ENU identity to NED");
}

#[test]
fn pitch_up_30_heading_north() {
    let (s, c) = deg(30.0).sin_cos();
    // Positive pitch about FRD +y (right) is nose up.
    let q_ned = axis_angle(Vector3::y(), deg(30.0));
    assert_vec_close(
        &(q_ned * Vector3::x()),
        &Vector3::new(c, 0.0, -s),
        HAND_TOL,
        "NED nose",
    );
    let q_enu = quat_ned_frd_to_enu_flu(&q_ned);
    assert_vec_close(
        &(q_enu * Vector3::x()),
        &Vector3::new(0.0, c, s),
        HAND_TOL,
        "ENU nose (north and up)",
    );
    // Thrust (FLU +z) tilts backwards, to the south: (0, -sin 30, cos 30).
    assert_vec_close(
        &(q_enu * Vector3::z()),
        &Vector3::new(0.0, -s, c),
        HAND_TOL,
        "ENU thrust axis",
    );
    // In ENU/FLU: yaw +90 deg, then pitch -30 deg (about FLU +y, which tips the nose up when
    // negative).
    let want = axis_angle(Vector3::z(), deg(90.0)) * axis_angle(Vector3::y(), deg(-30.0));
    assert_same_rotation(&q_enu, &want, HAND_TOL, "ENU attitude");
    assert_same_rotation(
        &quat_enu_flu_to_ned_frd(&want),
        &q_ned,
        HAND_TOL,
        "back to NED",
    );
}

#[test]
fn roll_right_wing_down_20() {
    let (s, c) = deg(20.0).sin_cos();
    // Positive roll about FRD +x: the right wing (FRD +y) goes down (NED +z).
    let q_ned = axis_angle(Vector3::x(), deg(20.0));
    assert_vec_close(
        &(q_ned * Vector3::y()),
        &Vector3::new(0.0, c, s),
        HAND_TOL,
        "NED right wing",
    );
    let q_enu = quat_ned_frd_to_enu_flu(&q_ned);
    // The left wing (FLU +y) points west and up.
    assert_vec_close(
        &(q_enu * Vector3::y()),
        &Vector3::new(-c, 0.0, s),
        HAND_TOL,
        "ENU left wing",
    );
    // The nose still points north.
    assert_vec_close(&(q_enu * Vector3::x()), &Vector3::y(), HAND_TOL, "ENU nose");
    // The thrust axis leans to the right of a north heading, i.e. east: (sin 20, 0, cos 20).
    assert_vec_close(
        &(q_enu * Vector3::z()),
        &Vector3::new(s, 0.0, c),
        HAND_TOL,
        "ENU thrust axis",
    );
    // A roll keeps its sign: yaw +90 deg, then roll +20 deg about FLU +x.
    let want = axis_angle(Vector3::z(), deg(90.0)) * axis_angle(Vector3::x(), deg(20.0));
    assert_same_rotation(&q_enu, &want, HAND_TOL, "ENU attitude");
}

#[test]
fn body_rate_signs() {
    // FRD (p, q, r) -> FLU (p, -q, -r).
    let q_rate = 0.7;
    assert_eq!(
        frd_to_flu(&Vector3::new(0.0, q_rate, 0.0)),
        Vector3::new(0.0, -q_rate, 0.0)
    );
    assert_eq!(
        frd_to_flu(&Vector3::new(0.3, 0.0, 0.0)),
        Vector3::new(0.3, 0.0, 0.0)
    );
    assert_eq!(
        frd_to_flu(&Vector3::new(0.0, 0.0, 0.5)),
        Vector3::new(0.0, 0.0, -0.5)
    );

    // The simulator's convention: in FLU a positive rate about +y tips the nose down.
    let t = 0.1;
    let flu_step = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 1.0, 0.0) * t);
    assert!(
        (flu_step * Vector3::x()).z < 0.0,
        "FLU +y rate tips the nose down"
    );
    // In FRD a positive pitch rate is nose up: NED z of the nose decreases (goes up).
    let frd_step = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 1.0, 0.0) * t);
    assert!(
        (frd_step * Vector3::x()).z < 0.0,
        "FRD +y rate: NED z < 0 is up"
    );

    // Flying a positive FRD pitch rate for t seconds from level, nose north...
    let w_frd = Vector3::new(0.0, q_rate, 0.0);
    let q_ned = UnitQuaternion::from_scaled_axis(w_frd * t);
    let q_enu = quat_ned_frd_to_enu_flu(&q_ned);
    // ...raises the nose in ENU...
    let nose = q_enu * Vector3::x();
    assert!(nose.z > 0.0, "nose up in ENU: {nose:?}");
    assert_vec_close(
        &nose,
        &Vector3::new(0.0, (q_rate * t).cos(), (q_rate * t).sin()),
        HAND_TOL,
        "ENU nose after the pitch-up",
    );
    // ...which is the converted (negative) FLU rate integrated from the converted start.
    let w_flu = frd_to_flu(&w_frd);
    assert!(w_flu.y < 0.0);
    let start = quat_ned_frd_to_enu_flu(&UnitQuaternion::identity());
    let flown = start * UnitQuaternion::from_scaled_axis(w_flu * t);
    assert_same_rotation(&q_enu, &flown, HAND_TOL, "FLU integration");
}

#[test]
fn kinematics_commute_with_the_conversion() {
    // q' = q exp(w t) in NED/FRD is q'_enu = q_enu exp(frd_to_flu(w) t) in ENU/FLU.
    let mut rng = StdRng::seed_from_u64(11);
    for _ in 0..SAMPLES {
        let q = random_quat(&mut rng);
        let w = random_vec(&mut rng, 20.0);
        let t = rng.random_range(0.0..0.2);
        let ned_after = q * UnitQuaternion::from_scaled_axis(w * t);
        let enu_after =
            quat_ned_frd_to_enu_flu(&q) * UnitQuaternion::from_scaled_axis(frd_to_flu(&w) * t);
        assert_same_rotation(
            &quat_ned_frd_to_enu_flu(&ned_after),
            &enu_after,
            PROP_TOL,
            "rate integration",
        );
    }
}

#[test]
fn matches_the_documented_product() {
    // q_enu_flu = Q(NED->ENU) * q_ned_frd * Q(FLU->FRD), built independently with nalgebra.
    let q_ned_enu = axis_angle(Vector3::new(1.0, 1.0, 0.0), PI);
    let q_flu_frd = axis_angle(Vector3::x(), PI);
    // The two constants are the vector maps.
    let mut rng = StdRng::seed_from_u64(5);
    for _ in 0..100 {
        let v = random_vec(&mut rng, 10.0);
        assert_vec_close(
            &(q_ned_enu * v),
            &ned_to_enu(&v),
            HAND_TOL * 100.0,
            "Q(NED->ENU)",
        );
        assert_vec_close(
            &(q_flu_frd * v),
            &flu_to_frd(&v),
            HAND_TOL * 100.0,
            "Q(FLU->FRD)",
        );
    }
    // With the documented signs, the product is the result component by component.
    let s = std::f64::consts::FRAC_1_SQRT_2;
    let q_ne = UnitQuaternion::new_unchecked(Quaternion::new(0.0, s, s, 0.0));
    let q_ff = UnitQuaternion::new_unchecked(Quaternion::new(0.0, -1.0, 0.0, 0.0));
    assert_same_rotation(&q_ne, &q_ned_enu, HAND_TOL, "documented Q(NED->ENU)");
    assert_same_rotation(&q_ff, &q_flu_frd, HAND_TOL, "documented Q(FLU->FRD)");
    for _ in 0..SAMPLES {
        let q = random_quat(&mut rng);
        let p = q_ne * q * q_ff;
        assert_components(
            &quat_ned_frd_to_enu_flu(&q),
            [p.w, p.i, p.j, p.k],
            1e-15,
            "documented product, components",
        );
        let product = q_ned_enu * q * q_flu_frd;
        assert_same_rotation(&quat_ned_frd_to_enu_flu(&q), &product, PROP_TOL, "to ENU");
        let inverse = q_ned_enu.inverse() * q * q_flu_frd.inverse();
        assert_same_rotation(&quat_enu_flu_to_ned_frd(&q), &inverse, PROP_TOL, "to NED");
    }
}

#[test]
fn property_euler_angles() {
    // roll_enu = roll_ned, pitch_enu = -pitch_ned, yaw_enu = 90 deg - yaw_ned.
    let mut rng = StdRng::seed_from_u64(4);
    for _ in 0..SAMPLES {
        let roll = rng.random_range(-PI..PI);
        let pitch = rng.random_range(-FRAC_PI_2..FRAC_PI_2);
        let yaw = rng.random_range(-PI..PI);
        let q_ned = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        let want = UnitQuaternion::from_euler_angles(roll, -pitch, FRAC_PI_2 - yaw);
        assert_same_rotation(&quat_ned_frd_to_enu_flu(&q_ned), &want, PROP_TOL, "Euler");
    }
}

#[test]
fn property_vectors_through_attitudes() {
    let mut rng = StdRng::seed_from_u64(1);
    for _ in 0..SAMPLES {
        let q_ned = random_quat(&mut rng);
        let q_enu = quat_ned_frd_to_enu_flu(&q_ned);
        // A body vector to the world: R_enu(q') flu(v) == ned_to_enu(R_ned(q) v).
        let v_frd = random_vec(&mut rng, 100.0);
        assert_vec_close(
            &(q_enu * frd_to_flu(&v_frd)),
            &ned_to_enu(&(q_ned * v_frd)),
            PROP_TOL,
            "body to world",
        );
        // A world vector to the body: R_enu^T enu(w) == flu(R_ned^T w).
        let w_ned = random_vec(&mut rng, 100.0);
        assert_vec_close(
            &(q_enu.inverse() * ned_to_enu(&w_ned)),
            &frd_to_flu(&(q_ned.inverse() * w_ned)),
            PROP_TOL,
            "world to body",
        );
        // The ENU -> NED direction.
        let q_back = quat_enu_flu_to_ned_frd(&q_enu);
        let v_flu = random_vec(&mut rng, 100.0);
        assert_vec_close(
            &(q_back * flu_to_frd(&v_flu)),
            &enu_to_ned(&(q_enu * v_flu)),
            PROP_TOL,
            "ENU to NED",
        );
    }
}

#[test]
fn property_round_trips_and_norms() {
    let mut rng = StdRng::seed_from_u64(2);
    for _ in 0..SAMPLES {
        // Vector maps are swaps and negations: exact.
        let v = random_vec(&mut rng, 1e6);
        assert_eq!(enu_to_ned(&ned_to_enu(&v)), v);
        assert_eq!(ned_to_enu(&enu_to_ned(&v)), v);
        assert_eq!(flu_to_frd(&frd_to_flu(&v)), v);
        assert_eq!(frd_to_flu(&flu_to_frd(&v)), v);
        let n = v.norm();
        for (m, what) in [
            (ned_to_enu(&v).norm(), "ned_to_enu"),
            (frd_to_flu(&v).norm(), "frd_to_flu"),
        ] {
            assert!(
                (m - n).abs() <= 1e-15 * n,
                "{what} changed the norm: {n} -> {m}"
            );
        }

        // Attitude round trips: the same quaternion (components, not only the rotation).
        let q = random_quat(&mut rng);
        for (back, what) in [
            (
                quat_enu_flu_to_ned_frd(&quat_ned_frd_to_enu_flu(&q)),
                "NED -> ENU -> NED",
            ),
            (
                quat_ned_frd_to_enu_flu(&quat_enu_flu_to_ned_frd(&q)),
                "ENU -> NED -> ENU",
            ),
        ] {
            assert_components(&back, [q.w, q.i, q.j, q.k], 1e-15, what);
        }
        // Unit norms.
        for (p, what) in [
            (quat_ned_frd_to_enu_flu(&q), "to ENU"),
            (quat_enu_flu_to_ned_frd(&q), "to NED"),
        ] {
            let err = (p.quaternion().norm() - 1.0).abs();
            assert!(err <= 1e-15, "{what}: norm off by {err:e}");
        }
    }
}

#[test]
fn mavlink_order_is_w_x_y_z() {
    let q = axis_angle(Vector3::z(), FRAC_PI_2);
    let h = deg(45.0);
    assert_eq!(
        quat_to_mavlink(&q),
        [h.cos() as f32, 0.0, 0.0, h.sin() as f32]
    );
    // [w, x, y, z] = [0, 0, 0, 1]: a half turn about z.
    let Some(half_turn_z) = quat_from_mavlink([0.0, 0.0, 0.0, 1.0]) else {
        panic!("rejected");
    };
    assert_components(&half_turn_z, [0.0, 0.0, 0.0, 1.0], 0.0, "[0, 0, 0, 1]");
    assert_same_rotation(
        &half_turn_z,
        &axis_angle(Vector3::z(), PI),
        HAND_TOL,
        "half turn z",
    );
    // [0, 1, 0, 0]: a half turn about x.
    let Some(half_turn_x) = quat_from_mavlink([0.0, 1.0, 0.0, 0.0]) else {
        panic!("rejected");
    };
    assert_components(&half_turn_x, [0.0, 1.0, 0.0, 0.0], 0.0, "[0, 1, 0, 0]");
}

#[test]
fn mavlink_round_trip() {
    let mut rng = StdRng::seed_from_u64(3);
    for _ in 0..SAMPLES {
        let q = random_quat(&mut rng);
        let back = quat_from_mavlink(quat_to_mavlink(&q));
        let Some(back) = back else {
            panic!("a unit quaternion was rejected: {q:?}");
        };
        // f32 rounding of the components (6e-8 relative), then normalization.
        assert_components(&back, [q.w, q.i, q.j, q.k], 2e-7, "through f32");
    }
}

#[test]
fn mavlink_rejects_and_normalizes() {
    for slot in 0..4 {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut q = [0.5_f32; 4];
            q[slot] = bad;
            assert_eq!(quat_from_mavlink(q), None, "{q:?}");
        }
    }
    assert_eq!(quat_from_mavlink([0.0; 4]), None);
    assert_eq!(quat_from_mavlink([-0.0; 4]), None);
    assert_eq!(quat_from_mavlink([f32::MIN_POSITIVE; 4]), None);
    let tiny = (MIN_MAVLINK_QUAT_NORM / 4.0) as f32;
    assert_eq!(quat_from_mavlink([tiny, tiny, tiny, tiny]), None);

    let normalized = |q: [f32; 4], want: [f64; 4]| {
        let Some(got) = quat_from_mavlink(q) else {
            panic!("{q:?} was rejected");
        };
        assert_components(&got, want, HAND_TOL, "normalized");
    };
    normalized([2.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
    normalized([0.0, 0.0, 0.0, -3.0], [0.0, 0.0, 0.0, -1.0]);
    normalized([f32::MAX; 4], [0.5; 4]);
    normalized([0.01, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
    normalized([1.0, 1.0, 1.0, 1.0], [0.5; 4]);
}
