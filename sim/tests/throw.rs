//! The flip-and-throw mission against the acceptance criteria: the probe lands within
//! 0.5 m of the target in 10 of 10 noisy trials at 20 m, the other ranges of the table work,
//! the vehicle recovers (0.15 m of the hold point within 3 s of release, never below 1 m, no
//! fallbacks), and an unreachable range is an error that names the reachable maximum.

use mpc_sim::release::{self, ReleaseError};
use mpc_sim::throw::{
    LANDING_TOL_M, MODEL_SWING_LIMIT, ThrowConfig, ThrowError, ThrowSimConfig, ThrowSummary,
    plan_throw, run_throw_trial, summarize_throw,
};

const G: f64 = 9.81;

fn fly(range: f64, seeds: std::ops::Range<u64>) -> Vec<ThrowSummary> {
    fly_heading(range, 0.0, seeds)
}

fn fly_heading(range: f64, yaw: f64, seeds: std::ops::Range<u64>) -> Vec<ThrowSummary> {
    let seeds: Vec<u64> = seeds.collect();
    let mut out: Vec<(u64, ThrowSummary)> = std::thread::scope(|s| {
        let handles: Vec<_> = seeds
            .chunks(seeds.len().div_ceil(2).max(1))
            .map(|chunk| {
                s.spawn(move || {
                    chunk
                        .iter()
                        .map(|&seed| {
                            let mut cfg = ThrowSimConfig::new(ThrowConfig {
                                range,
                                yaw,
                                ..ThrowConfig::default()
                            });
                            cfg.seed = seed;
                            let tr = run_throw_trial(&cfg).expect("the throw is planned");
                            (seed, summarize_throw(&tr))
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("a trial thread"))
            .collect()
    });
    out.sort_by_key(|(s, _)| *s);
    out.into_iter().map(|(_, s)| s).collect()
}

fn check(s: &ThrowSummary) {
    println!(
        "range {:>4} seed {:>2}: landed at ({:.3}, {:.3}), error {:.3} m; released at {:.2} m/s, \
         {:.1} deg; recovery {:.2} s; lowest {:.2} m; fallbacks {}",
        s.range_m,
        s.seed,
        s.probe_landing_x_m.unwrap_or(f64::NAN),
        s.probe_landing_y_m.unwrap_or(f64::NAN),
        s.probe_landing_error_m.unwrap_or(f64::NAN),
        s.release_speed_m_s.unwrap_or(f64::NAN),
        s.release_angle_rad.unwrap_or(f64::NAN).to_degrees(),
        s.recovery_time_s.unwrap_or(f64::NAN),
        s.min_altitude_m,
        s.fallbacks
    );
    assert!(s.success, "seed {}: {:?}", s.seed, s.failures);
    assert!(s.release_triggered);
    let err = s.probe_landing_error_m.expect("the probe landed");
    assert!(err < LANDING_TOL_M, "seed {}: {err} m", s.seed);
    // Independent of the summary's own arithmetic: the landing point against the target.
    let (x, y) = (
        s.probe_landing_x_m.unwrap_or(f64::NAN),
        s.probe_landing_y_m.unwrap_or(f64::NAN),
    );
    let d = ((x - s.target_m[0]).powi(2) + (y - s.target_m[1]).powi(2)).sqrt();
    assert!((d - err).abs() < 1e-9);
    assert!(s.recovery_time_s.is_some_and(|t| t <= 3.0), "{s:?}");
    assert!(s.min_altitude_m >= 1.0, "{s:?}");
    assert_eq!(s.fallbacks, 0, "seed {}", s.seed);
    // The swing stays in the throw's plane, far from the model's singularity at pi/2.
    assert!(s.max_out_of_plane_rad < 0.2, "seed {}: {s:?}", s.seed);
}

#[test]
fn range_20_lands_within_half_a_metre_in_ten_noisy_trials() {
    let runs = fly(20.0, 0..10);
    assert_eq!(runs.len(), 10);
    for s in &runs {
        check(s);
        // The trigger released at the velocity the range equation asks for: from the
        // recorded release state the drag-free range equation reaches the target.
        let v = s.release_speed_m_s.unwrap_or(f64::NAN);
        let th = s.release_angle_rad.unwrap_or(f64::NAN);
        let h = s.release_height_m.unwrap_or(f64::NAN);
        let r = release::range(v, th, h, G);
        assert!(r > 15.0 && r < 25.0, "{r}");
    }
}

#[test]
fn the_other_ranges_of_the_table_land_too() {
    for range in [5.0, 10.0, 15.0, 25.0] {
        for s in fly(range, 0..2) {
            check(&s);
        }
    }
}

/// The solver works in the throw frame, so a throw at any heading flies as at heading 0 and
/// its swing stays in the model's x-z plane: the two-angle model's singularity at
/// |beta| = pi/2 is never near (without the frame, a throw towards +y swung the probe through
/// it and crashed).
#[test]
fn throws_at_any_heading_land_on_target_with_the_swing_in_plane() {
    use std::f64::consts::{FRAC_PI_2, PI};
    for yaw in [FRAC_PI_2, -2.4, PI] {
        for s in fly_heading(15.0, yaw, 0..2) {
            println!(
                "heading {yaw:.2} rad: out of plane {:.4} rad",
                s.max_out_of_plane_rad
            );
            check(&s);
            let t = s.target_m;
            let along = (
                t[0] * yaw.cos() + t[1] * yaw.sin(),
                t[1] * yaw.cos() - t[0] * yaw.sin(),
            );
            assert!(
                (along.0 - 15.0).abs() < 1e-9 && along.1.abs() < 1e-9,
                "{t:?}"
            );
        }
    }
}

/// A measured swing beyond the model's range (|beta| > 1.4 rad, towards the angles'
/// singularity at pi/2) ends the trial as a failure that says so, instead of flying the
/// solver where its model no longer holds. An encoder with 3 rad of noise reads such angles
/// at once.
#[test]
fn a_swing_out_of_the_models_range_ends_the_trial_as_a_failure() {
    let mut cfg = ThrowSimConfig::new(ThrowConfig {
        range: 10.0,
        angle_noise: 3.0,
        ..ThrowConfig::default()
    });
    cfg.seed = 3;
    let tr = run_throw_trial(&cfg).expect("the throw is planned");
    let s = summarize_throw(&tr);
    assert!(
        tr.outcome.starts_with("ended: the probe swung"),
        "{}",
        tr.outcome
    );
    assert!(
        tr.outcome.contains(&format!("{MODEL_SWING_LIMIT} rad")),
        "{}",
        tr.outcome
    );
    assert!(!s.success);
    assert!(
        s.failures
            .iter()
            .any(|f| f.contains("out of the throw's plane")),
        "{:?}",
        s.failures
    );
    assert!(tr.release.is_none() && tr.probe_landing.is_none());
}

/// With air drag on the free probe the trigger predicts the landing point with the drag
/// (the plant integrates the same law at 1 kHz, the predictor at 5 ms): still on target.
/// Without the drag-aware prediction this throw lands about 2 m short.
#[test]
fn with_probe_drag_the_trigger_still_lands_on_target() {
    let mut tc = ThrowConfig::default();
    tc.probe.drag = 0.002;
    let mut cfg = ThrowSimConfig::new(tc);
    cfg.seed = 3;
    let s = summarize_throw(&run_throw_trial(&cfg).unwrap());
    check(&s);
}

#[test]
fn an_unreachable_range_is_an_error_that_names_the_maximum() {
    let cfg = ThrowConfig {
        range: 40.0,
        ..ThrowConfig::default()
    };
    let err = plan_throw(&cfg, 1.0).expect_err("40 m is beyond 16 m/s");
    let msg = err.to_string();
    match err {
        ThrowError::Release {
            source: ReleaseError::Unreachable { max_range, .. },
            ..
        } => {
            assert!(max_range > 25.0 && max_range < 40.0, "{max_range}");
            assert!(msg.contains("maximum range"), "{msg}");
            assert!(msg.contains("v_max"), "{msg}");
        }
        e => panic!("not Unreachable: {e}"),
    }
    // A faster bound makes it reachable in the planner's eyes.
    let mut fast = cfg.clone();
    fast.bounds.v_max = 30.0;
    match plan_throw(&fast, 1.0) {
        Ok(_) | Err(ThrowError::Unachievable { .. }) => {}
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn the_plan_releases_at_the_asked_velocity_and_lands_past_the_target() {
    let cfg = ThrowConfig::default();
    let plan = plan_throw(&cfg, 1.0).unwrap();
    // The plan's terminal probe velocity is the asked one (planned release velocity plus the
    // speed margin) to 5 %.
    let miss = (plan.release_velocity - plan.asked_velocity).norm();
    assert!(miss < 0.05 * plan.asked_velocity.norm(), "{miss}");
    // The planned release (V, theta) reaches the target from the release point.
    let along = plan.target.x - plan.release_point.x;
    let r = release::range(
        plan.release.speed,
        plan.release.angle,
        plan.release_point.z,
        G,
    );
    assert!((r - along).abs() < 0.05, "{r} vs {along}");
    // With the margin the planned swing throws past the target, so the trigger fires before
    // the plan's end.
    assert!(
        plan.planned_landing.x > plan.target.x,
        "{:?}",
        plan.planned_landing
    );
    assert_eq!(plan.states.len(), 2 * mpc_models::quadrotor_probe::N + 1);
}

#[test]
fn bad_settings_are_rejected_with_the_field_named() {
    let bad = [
        (
            ThrowConfig {
                range: -1.0,
                ..ThrowConfig::default()
            },
            "range",
        ),
        (
            ThrowConfig {
                probe: mpc_sim::probe::ProbeParams {
                    length: 0.7,
                    ..Default::default()
                },
                ..ThrowConfig::default()
            },
            "probe length",
        ),
        (
            ThrowConfig {
                recover_time: 0.0,
                ..ThrowConfig::default()
            },
            "recover_time",
        ),
    ];
    for (cfg, what) in bad {
        let e = plan_throw(&cfg, 1.0).expect_err(what);
        assert!(matches!(e, ThrowError::Invalid(_)), "{e}");
        assert!(e.to_string().contains(what), "{e}");
    }
}
