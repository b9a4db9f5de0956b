//! Vehicle profiles and the flip planned for them: the figures against hand computation from
//! PX4 SIH's parameters, the refusals, the file round trip, and the planned rate profile
//! (it turns exactly once, within the planned angular acceleration).

use std::f64::consts::PI;

use firmware_shim::profile::{FlipPlan, MAX_BRAKE_ANGLE, ProfileError, VehicleProfile, plan_flip};
use mpc_mission::mission::{G, MissionConfig, MissionKind};

/// PX4 v1.16's stock SIH quadrotor: 1 kg, 5 N rotors, 0.2 m lever, Iyy 0.025, 50 ms.
fn stock() -> VehicleProfile {
    VehicleProfile::from_sih([1.0, 5.0, 0.2, 0.025, 0.05])
}

#[test]
fn the_stock_sih_vehicle_has_thrust_to_weight_two_and_80_rad_s2() {
    let v = stock();
    v.validate().unwrap();
    assert!((v.thrust_to_weight() - 20.0 / G).abs() < 1e-12);
    // 2 rotors x 5 N x 0.2 m / 0.025 kg m^2.
    assert!((v.pitch_authority() - 80.0).abs() < 1e-12);
    // Braking from the fastest flip at half the authority, plus a rotor time constant,
    // takes a quarter turn.
    let w = v.max_flip_rate();
    assert!(
        (v.braking_angle(w, 0.5) - MAX_BRAKE_ANGLE).abs() < 1e-9,
        "{w}"
    );
    assert!((9.0..10.0).contains(&w), "{w}");
    // The design vehicle flies the paper's 5*pi.
    let d = VehicleProfile::design();
    assert!((d.thrust_to_weight() - 4.0).abs() < 0.01);
    assert!(
        (d.pitch_authority() - 392.0).abs() < 2.0,
        "{}",
        d.pitch_authority()
    );
    assert!(d.max_flip_rate() > 5.0 * PI);
}

#[test]
fn a_flip_beyond_the_vehicle_is_refused_before_take_off_with_what_it_can_do() {
    let mut m = MissionConfig::flip();
    let err = plan_flip(&mut m, &stock(), Some(5.0 * PI)).unwrap_err();
    let ProfileError::FlipTooFast { asked, max, .. } = &err else {
        panic!("{err:?}");
    };
    assert!((*asked - 5.0 * PI).abs() < 1e-12 && *max < 10.0);
    let text = err.to_string();
    assert!(
        text.contains("--flip-rate") && text.contains("80 rad/s^2"),
        "{text}"
    );
    assert_eq!(m, MissionConfig::flip(), "the mission is left as it was");
    // Too little thrust for any flip.
    let weak = VehicleProfile::from_sih([1.0, 4.0, 0.2, 0.025, 0.05]);
    let err = plan_flip(&mut MissionConfig::flip(), &weak, None).unwrap_err();
    assert!(matches!(err, ProfileError::NoFlip { .. }), "{err:?}");
    // A hover is not planned.
    let mut h = MissionConfig::for_kind(MissionKind::Hover);
    assert_eq!(plan_flip(&mut h, &weak, None), Ok(None));
}

#[test]
fn the_planned_flip_turns_once_within_its_ramps() {
    for (v, asked) in [
        (stock(), None),
        (VehicleProfile::design(), None),
        (stock(), Some(6.0)),
    ] {
        let mut m = MissionConfig::flip();
        let plan: FlipPlan = plan_flip(&mut m, &v, asked).unwrap().unwrap();
        let expected = asked.unwrap_or((5.0 * PI).min(v.max_flip_rate()));
        assert!((plan.rate - expected).abs() < 1e-12);
        assert!((plan.accel - 0.5 * v.pitch_authority()).abs() < 1e-9);
        assert!((plan.thrust - 0.5 * v.max_collective()).abs() < 1e-9);
        let profile = m.flip_profile();
        let total = m.flip_time();
        assert!((total - plan.duration).abs() < 1e-12);
        assert!((plan.ascend_speed - (0.5 * G * total).max(2.5)).abs() < 1e-9);
        // The turn: from rest to rest, one full turn, the rate never over the top, changing
        // no faster than planned.
        let n = 2000;
        let mut last = profile.at(0.0);
        assert_eq!(last, (0.0, 0.0));
        for i in 1..=n {
            let (th, w) = profile.at(total * f64::from(i) / f64::from(n));
            let dt = total / f64::from(n);
            assert!(w <= plan.rate + 1e-9 && w >= -1e-9, "{w}");
            assert!((w - last.1).abs() <= plan.accel * dt + 1e-9);
            // The rotation is the rate's integral (trapezoid rule).
            // (exact but where the rate has a kink in the step)
            assert!((th - last.0 - 0.5 * (w + last.1) * dt).abs() <= plan.accel * dt * dt);
            last = (th, w);
        }
        assert!(
            (last.0 - 2.0 * PI).abs() < 1e-9 && last.1.abs() < 1e-9,
            "{last:?}"
        );
    }
}

#[test]
fn a_profile_file_round_trips_and_bad_ones_are_refused_by_field() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("profile_files");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("stock.json");
    stock().save(&path).unwrap();
    assert_eq!(VehicleProfile::load(&path).unwrap(), stock());
    let bad = dir.join("bad.json");
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("0.025", "-1.0");
    std::fs::write(&bad, text).unwrap();
    let err = VehicleProfile::load(&bad).unwrap_err();
    assert!(
        matches!(
            err,
            ProfileError::Invalid {
                name: "iyy_kg_m2",
                ..
            }
        ),
        "{err:?}"
    );
    let err = VehicleProfile::load(&dir.join("missing.json")).unwrap_err();
    assert!(matches!(err, ProfileError::File { .. }) && err.to_string().contains("missing.json"));
    std::fs::write(&bad, "{\"mass_kg\": 1.0}").unwrap();
    assert!(matches!(
        VehicleProfile::load(&bad).unwrap_err(),
        ProfileError::File { .. }
    ));
}

#[test]
fn the_ramped_flip_reference_tends_to_the_papers_closed_form_as_its_ramps_shorten() {
    use mpc_mission::mission::{FlipProfile, flip_state, ramped_flip_state};
    use nalgebra::Vector3;
    let (p0, v0) = (Vector3::new(4.0, 0.0, 2.5), Vector3::new(0.0, 0.0, 2.5));
    let rate = 5.0 * PI;
    let profile = FlipProfile {
        rate,
        accel: 1e7,
        angle: 2.0 * PI,
    };
    for tau in [0.05, 0.2, 0.4] {
        let (p, v, a, q) = flip_state(&p0, &v0, rate, 5.0, 0.3, tau);
        let (pr, vr, ar, qr, w) = ramped_flip_state(&p0, &v0, &profile, 5.0, 0.3, tau);
        assert!((p - pr).norm() < 1e-4, "{tau}: {p} {pr}");
        assert!((v - vr).norm() < 1e-3, "{tau}: {v} {vr}");
        if tau < 0.39 {
            assert!((a - ar).norm() < 1e-2 && q.angle_to(&qr) < 1e-3 && (w - rate).abs() < 1e-9);
        }
    }
}
