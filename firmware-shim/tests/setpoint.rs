//! Setpoint safety: the exact mapping, clamping, non-finite handling, parameter validation,
//! and a seeded property test over 200,000 hostile inputs.

use firmware_shim::setpoint::{
    Px4Setpoint, RateLimits, Sanitized, SetpointError, ThrustMap, make_setpoint,
};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

fn sp(rates_frd: [f32; 3], thrust: f32) -> Px4Setpoint {
    Px4Setpoint { rates_frd, thrust }
}

fn run(c: f64, rates_flu: Vector3<f64>, previous: Option<&Px4Setpoint>) -> Sanitized {
    make_setpoint(
        c,
        &rates_flu,
        &ThrustMap::default(),
        &RateLimits::default(),
        previous,
    )
}

/// Finite, rates within `+-(max as f32)`, thrust in `[0, 1]`.
fn assert_safe(s: &Px4Setpoint, limits: &RateLimits, what: &str) {
    let max = [limits.max.x, limits.max.y, limits.max.z];
    for (r, m) in s.rates_frd.iter().zip(max) {
        assert!(r.is_finite(), "{what}: non-finite rate in {s:?}");
        assert!(
            r.abs() <= m as f32,
            "{what}: rate {r} beyond +-{m} in {s:?}"
        );
    }
    assert!(s.thrust.is_finite(), "{what}: non-finite thrust in {s:?}");
    assert!(
        (0.0..=1.0).contains(&s.thrust),
        "{what}: thrust out of [0, 1] in {s:?}"
    );
}

#[test]
fn defaults() {
    let map = ThrustMap::default();
    assert_eq!(map.hover_thrust, 0.5);
    assert_eq!(map.g, 9.81);
    assert_eq!(map.validate(), Ok(()));
    let limits = RateLimits::default();
    assert_eq!(limits.max, v(20.0, 20.0, 6.0));
    assert_eq!(limits.validate(), Ok(()));
    assert_eq!(
        Px4Setpoint::hover(&map),
        sp([0.0; 3], 0.5),
        "hover: zero rates, hover thrust"
    );
    let sih = ThrustMap {
        hover_thrust: 0.495,
        g: 9.81,
    };
    assert_eq!(Px4Setpoint::hover(&sih), sp([0.0; 3], 0.495));
}

#[test]
fn exact_mapping_in_range() {
    // Hover: c = g gives the hover thrust, whatever the map.
    for (hover_thrust, g) in [(0.5, 9.81), (0.495, 9.81), (0.3, 9.80665), (0.72, 3.71)] {
        let map = ThrustMap { hover_thrust, g };
        let s = make_setpoint(g, &Vector3::zeros(), &map, &RateLimits::default(), None);
        assert_eq!(
            s.setpoint,
            sp([0.0; 3], hover_thrust as f32),
            "hover with {map:?}"
        );
        assert!(!s.clamped && !s.replaced_non_finite);
    }
    // Rates FLU (1, 2, 3) -> FRD (1, -2, -3).
    let s = run(9.81, v(1.0, 2.0, 3.0), None);
    assert_eq!(s.setpoint.rates_frd, [1.0, -2.0, -3.0]);
    assert!(!s.clamped && !s.replaced_non_finite);
    // Linear in c: twice the hover acceleration is twice the hover thrust; zero is zero.
    assert_eq!(run(2.0 * 9.81, Vector3::zeros(), None).setpoint.thrust, 1.0);
    assert_eq!(run(0.0, Vector3::zeros(), None).setpoint.thrust, 0.0);
    assert_eq!(
        run(4.905, Vector3::zeros(), None).setpoint.thrust,
        0.25,
        "half the hover acceleration"
    );
    // Exactly at the limits is not clamping (g = 8, hover 0.5: c = 16 is thrust 1 exactly).
    let map = ThrustMap {
        hover_thrust: 0.5,
        g: 8.0,
    };
    let s = make_setpoint(
        16.0,
        &v(20.0, -20.0, 6.0),
        &map,
        &RateLimits::default(),
        None,
    );
    assert_eq!(s.setpoint, sp([20.0, 20.0, -6.0], 1.0));
    assert!(!s.clamped && !s.replaced_non_finite);
    // The inverse map.
    assert_eq!(ThrustMap::default().acceleration(0.5), 9.81);
    assert_eq!(map.thrust(4.0), 0.25);
}

#[test]
fn clamping() {
    // FLU (25, -30, 7) is FRD (25, 30, -7): clamped to (20, 20, -6).
    let s = run(9.81, v(25.0, -30.0, 7.0), None);
    assert_eq!(s.setpoint, sp([20.0, 20.0, -6.0], 0.5));
    assert!(s.clamped && !s.replaced_non_finite);
    let s = run(9.81, v(-25.0, 30.0, -7.0), None);
    assert_eq!(s.setpoint.rates_frd, [-20.0, -20.0, 6.0]);
    assert!(s.clamped);
    // One axis is enough.
    let s = run(9.81, v(0.0, 0.0, 6.5), None);
    assert_eq!(s.setpoint.rates_frd, [0.0, 0.0, -6.0]);
    assert!(s.clamped);
    // Thrust above 1 and below 0.
    let s = run(100.0, Vector3::zeros(), None);
    assert_eq!(s.setpoint.thrust, 1.0);
    assert!(s.clamped && !s.replaced_non_finite);
    let s = run(-5.0, Vector3::zeros(), None);
    assert_eq!(s.setpoint.thrust, 0.0);
    assert!(s.clamped && !s.replaced_non_finite);
    // Huge finite values are clamped, not replaced.
    let s = run(1e300, v(-1e300, f64::MAX, -f64::MAX), None);
    assert_eq!(s.setpoint, sp([-20.0, -20.0, 6.0], 1.0));
    assert!(s.clamped && !s.replaced_non_finite);
    // Just past a bound.
    let s = run(9.81, v(20f64.next_up(), 0.0, 0.0), None);
    assert_eq!(s.setpoint.rates_frd[0], 20.0);
    assert!(s.clamped);
    let map = ThrustMap {
        hover_thrust: 0.5,
        g: 8.0,
    };
    let s = make_setpoint(
        16f64.next_up(),
        &Vector3::zeros(),
        &map,
        &RateLimits::default(),
        None,
    );
    assert_eq!(s.setpoint.thrust, 1.0);
    assert!(s.clamped);
    // A thrust that is a negative subnormal is below 0.
    let s = run(-f64::MIN_POSITIVE, Vector3::zeros(), None);
    assert_eq!(s.setpoint.thrust, 0.0);
    assert!(s.clamped);
}

#[test]
fn tiny_values_are_not_clamping() {
    // Subnormals and -0.0 are in range: they round to (signed) zero in f32.
    let sub = f64::from_bits(1);
    let s = run(sub, v(sub, -sub, -0.0), None);
    assert_eq!(s.setpoint, sp([0.0; 3], 0.0));
    assert!(!s.clamped && !s.replaced_non_finite);
    let s = run(-0.0, v(-0.0, -0.0, -0.0), None);
    assert_eq!(s.setpoint, sp([0.0; 3], 0.0));
    assert!(!s.clamped && !s.replaced_non_finite);
}

#[test]
fn non_finite_without_previous_is_hover() {
    let hover = Px4Setpoint::hover(&ThrustMap::default());
    let finite = v(1.0, 2.0, 3.0);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut cases = vec![(bad, finite)];
        for axis in 0..3 {
            let mut rates = finite;
            rates[axis] = bad;
            cases.push((9.81, rates));
        }
        cases.push((bad, v(bad, bad, bad)));
        for (c, rates) in cases {
            let s = run(c, rates, None);
            assert_eq!(s.setpoint, hover, "c = {c}, rates = {rates:?}");
            assert!(
                s.replaced_non_finite && !s.clamped,
                "c = {c}, rates = {rates:?}"
            );
        }
    }
    // The hover of the map in use.
    let sih = ThrustMap {
        hover_thrust: 0.495,
        g: 9.81,
    };
    let s = make_setpoint(f64::NAN, &finite, &sih, &RateLimits::default(), None);
    assert_eq!(s.setpoint, sp([0.0; 3], 0.495));
}

#[test]
fn non_finite_with_previous_repeats_it() {
    let previous = run(12.0, v(0.5, -1.0, 2.0), None).setpoint;
    assert_ne!(previous, Px4Setpoint::hover(&ThrustMap::default()));
    for (c, rates) in [
        (f64::NAN, v(0.0, 0.0, 0.0)),
        (9.81, v(0.0, f64::INFINITY, 0.0)),
        (9.81, v(0.0, 0.0, f64::NEG_INFINITY)),
        (f64::INFINITY, v(f64::NAN, 0.0, 0.0)),
    ] {
        let s = run(c, rates, Some(&previous));
        assert_eq!(s.setpoint, previous, "c = {c}, rates = {rates:?}");
        assert!(s.replaced_non_finite && !s.clamped);
    }
    // A finite input ignores the previous setpoint.
    let s = run(9.81, Vector3::zeros(), Some(&previous));
    assert_eq!(s.setpoint, sp([0.0; 3], 0.5));
    assert!(!s.replaced_non_finite);
}

#[test]
fn a_bad_previous_is_not_repeated_blindly() {
    // Out of the current limits (e.g. the limits were lowered): clamped.
    let previous = sp([100.0, -100.0, 7.0], 2.0);
    let s = run(f64::NAN, Vector3::zeros(), Some(&previous));
    assert_eq!(s.setpoint, sp([20.0, -20.0, 6.0], 1.0));
    assert!(s.replaced_non_finite && s.clamped);
    // Not finite: hover instead.
    let hover = Px4Setpoint::hover(&ThrustMap::default());
    for previous in [sp([f32::NAN, 0.0, 0.0], 0.5), sp([0.0; 3], f32::INFINITY)] {
        let s = run(f64::NAN, Vector3::zeros(), Some(&previous));
        assert_eq!(s.setpoint, hover, "previous {previous:?}");
        assert!(s.replaced_non_finite);
    }
}

#[test]
fn f32_bounds() {
    // 0.1 rounds up in f32, 0.7 rounds down: a rate at the f64 bound is the f32 bound.
    let limits = RateLimits {
        max: v(0.1, 0.7, 6.0),
    };
    let map = ThrustMap::default();
    assert!(f64::from(0.1_f32) > 0.1 && f64::from(0.7_f32) < 0.7);
    let s = make_setpoint(9.81, &v(0.1, -0.7, 0.0), &map, &limits, None);
    assert_eq!(s.setpoint.rates_frd, [0.1_f32, 0.7_f32, 0.0]);
    assert!(!s.clamped);
    assert_safe(&s.setpoint, &limits, "at the bounds");
    let s = make_setpoint(
        9.81,
        &v(0.1f64.next_up(), -(0.7f64.next_up()), 0.0),
        &map,
        &limits,
        None,
    );
    assert_eq!(s.setpoint.rates_frd, [0.1_f32, 0.7_f32, 0.0]);
    assert!(s.clamped);
    assert_safe(&s.setpoint, &limits, "past the bounds");

    // A limit beyond f32::MAX (valid: finite and positive): values that are in range in f64
    // but overflow f32 are clamped to f32::MAX, never sent as infinity.
    let limits = RateLimits {
        max: v(1e39, 1e39, 1e39),
    };
    assert_eq!(limits.validate(), Ok(()));
    let big = 3.5e38; // > f32::MAX, < 1e39
    let s = make_setpoint(9.81, &v(big, big, -1e300), &map, &limits, None);
    assert_eq!(s.setpoint.rates_frd, [f32::MAX, -f32::MAX, f32::MAX]);
    assert!(s.clamped);
    assert_safe(&s.setpoint, &limits, "huge limits");
    // f32::MAX itself is in range and exact.
    let s = make_setpoint(9.81, &v(f64::from(f32::MAX), 0.0, 0.0), &map, &limits, None);
    assert_eq!(s.setpoint.rates_frd[0], f32::MAX);
    assert!(!s.clamped);
}

#[test]
fn invalid_parameters_still_give_safe_setpoints() {
    let inputs = [
        (9.81, v(1.0, 2.0, 3.0)),
        (0.0, Vector3::zeros()),
        (1e300, v(1e300, -1e300, 1e300)),
        (-1.0, v(-1.0, 1.0, -1.0)),
        (f64::NAN, Vector3::zeros()),
    ];
    let maps = [
        ThrustMap {
            hover_thrust: f64::NAN,
            g: 9.81,
        },
        ThrustMap {
            hover_thrust: f64::INFINITY,
            g: 9.81,
        },
        ThrustMap {
            hover_thrust: -0.5,
            g: 9.81,
        },
        ThrustMap {
            hover_thrust: 2.0,
            g: 9.81,
        },
        ThrustMap {
            hover_thrust: 0.5,
            g: 0.0,
        },
        ThrustMap {
            hover_thrust: 0.5,
            g: f64::NAN,
        },
        ThrustMap {
            hover_thrust: 0.5,
            g: -9.81,
        },
    ];
    let limits = [
        RateLimits {
            max: v(f64::NAN, 20.0, 6.0),
        },
        RateLimits {
            max: v(20.0, -1.0, 6.0),
        },
        RateLimits {
            max: v(20.0, 20.0, 0.0),
        },
        RateLimits {
            max: v(f64::INFINITY, f64::INFINITY, f64::INFINITY),
        },
        RateLimits::default(),
    ];
    for map in &maps {
        assert!(map.validate().is_err(), "{map:?} should not validate");
        for lim in &limits {
            for prev in [None, Some(sp([1.0, 1.0, 1.0], 0.4))] {
                for (c, rates) in &inputs {
                    let s = make_setpoint(*c, rates, map, lim, prev.as_ref());
                    // The f32 bound of a NaN/negative limit is checked against 0 below.
                    let shown = RateLimits {
                        max: lim.max.map(|m| if m > 0.0 { m } else { 0.0 }),
                    };
                    assert_safe(
                        &s.setpoint,
                        &shown,
                        &format!("{map:?} {lim:?} {c} {rates:?}"),
                    );
                }
            }
        }
    }
    // A NaN limit allows only zero on its axis; an infinite one caps at f32::MAX.
    let s = make_setpoint(
        9.81,
        &v(5.0, 5.0, 5.0),
        &ThrustMap::default(),
        &RateLimits {
            max: v(f64::NAN, f64::INFINITY, -1.0),
        },
        None,
    );
    assert_eq!(s.setpoint.rates_frd, [0.0, -5.0, 0.0]);
    assert!(s.clamped);
    // A NaN hover thrust: the mapping is NaN, treated as non-finite; hover falls back to 0.5.
    // Hover itself stays in [0, 1] with a hover thrust out of range.
    let high = ThrustMap {
        hover_thrust: 2.0,
        g: 9.81,
    };
    assert_eq!(Px4Setpoint::hover(&high), sp([0.0; 3], 1.0));
    let negative = ThrustMap {
        hover_thrust: -0.5,
        g: 9.81,
    };
    assert_eq!(Px4Setpoint::hover(&negative), sp([0.0; 3], 0.0));
    let nan_map = ThrustMap {
        hover_thrust: f64::NAN,
        g: 9.81,
    };
    assert_eq!(Px4Setpoint::hover(&nan_map), sp([0.0; 3], 0.5));
    let s = make_setpoint(
        9.81,
        &Vector3::zeros(),
        &nan_map,
        &RateLimits::default(),
        None,
    );
    assert!(s.replaced_non_finite);
    assert_eq!(s.setpoint, sp([0.0; 3], 0.5));
    // A tiny g overflows the thrust to +inf for a finite c: clamped to 1, not replaced.
    let tiny_g = ThrustMap {
        hover_thrust: 0.5,
        g: 1e-320,
    };
    let s = make_setpoint(
        1e10,
        &Vector3::zeros(),
        &tiny_g,
        &RateLimits::default(),
        None,
    );
    assert_eq!(s.setpoint.thrust, 1.0);
    assert!(s.clamped && !s.replaced_non_finite);
}

#[test]
fn validation_errors() {
    for hover_thrust in [
        0.0,
        1.0,
        -0.1,
        1.5,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ] {
        let map = ThrustMap {
            hover_thrust,
            g: 9.81,
        };
        let err = map.validate();
        let same = |h: f64| h.to_bits() == hover_thrust.to_bits();
        assert!(
            matches!(err, Err(SetpointError::HoverThrust(h)) if same(h)),
            "{map:?}: {err:?}"
        );
        let msg = err.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(
            msg.contains("hover_thrust") && msg.contains("between 0 and 1"),
            "{msg}"
        );
    }
    for g in [0.0, -9.81, f64::NAN, f64::INFINITY] {
        let map = ThrustMap {
            hover_thrust: 0.5,
            g,
        };
        let err = map.validate();
        assert!(
            matches!(err, Err(SetpointError::Gravity(_))),
            "{map:?}: {err:?}"
        );
        let msg = err.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(msg.contains("`g`") && msg.contains("9.81"), "{msg}");
    }
    // Both wrong: the hover thrust is reported first.
    let both = ThrustMap {
        hover_thrust: 2.0,
        g: 0.0,
    };
    assert!(matches!(
        both.validate(),
        Err(SetpointError::HoverThrust(_))
    ));
    assert_eq!(
        ThrustMap {
            hover_thrust: 0.495,
            g: 9.81
        }
        .validate(),
        Ok(())
    );

    for (max, axis) in [
        (v(0.0, 20.0, 6.0), "roll (x)"),
        (v(-1.0, 20.0, 6.0), "roll (x)"),
        (v(20.0, f64::NAN, 6.0), "pitch (y)"),
        (v(20.0, f64::INFINITY, 6.0), "pitch (y)"),
        (v(20.0, 20.0, -6.0), "yaw (z)"),
        (v(20.0, 20.0, f64::NEG_INFINITY), "yaw (z)"),
    ] {
        let err = RateLimits { max }.validate();
        assert!(
            matches!(err, Err(SetpointError::RateLimit { axis: a, .. }) if a == axis),
            "{max:?}: {err:?}"
        );
        let msg = err.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(
            msg.contains(axis) && msg.contains("RateLimits::max"),
            "{msg}"
        );
    }
    assert_eq!(
        RateLimits {
            max: v(1e-3, 100.0, 0.5)
        }
        .validate(),
        Ok(())
    );
}

/// One hostile value: the special values, values at and just past the bound `m` (and at and
/// just past 0 when `zero_is_bound`), and ordinary values.
fn hostile(rng: &mut StdRng, m: f64, zero_is_bound: bool) -> f64 {
    let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    match rng.random_range(0..24) {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => f64::NEG_INFINITY,
        3 => sign * 1e300,
        4 => sign * f64::MAX,
        5 => sign * f64::from_bits(rng.random_range(1..(1_u64 << 52))), // subnormal
        6 => sign * 0.0,
        7 => sign * m,
        8 => sign * m.next_up(),
        9 => sign * m.next_down(),
        10 => sign * m * (1.0 + 1e-12),
        11 => sign * 3.5e38, // past f32::MAX
        12 if zero_is_bound => -f64::from_bits(rng.random_range(1..1000)),
        13 => sign * f64::from(m as f32), // the f32 bound, maybe just past the f64 one
        14..=15 => rng.random_range(-1.5 * m..1.5 * m),
        _ if zero_is_bound => rng.random_range(0.0..m),
        _ => rng.random_range(-m..m),
    }
}

#[test]
fn property_200k_hostile_inputs() {
    let maps = [
        ThrustMap::default(),
        ThrustMap {
            hover_thrust: 0.495,
            g: 9.81,
        },
        ThrustMap {
            hover_thrust: 0.3,
            g: 9.80665,
        },
    ];
    let limits = [
        RateLimits::default(),
        RateLimits {
            max: v(0.1, 0.7, 1e-3),
        },
        RateLimits {
            max: v(7.3, 1e39, 2.0f64.sqrt()),
        },
    ];
    let mut rng = StdRng::seed_from_u64(0x5e7_9017);
    let mut previous: Option<Px4Setpoint> = None;
    let (mut exact, mut clamped, mut replaced_prev, mut replaced_hover) = (0, 0, 0, 0);

    for i in 0..200_000 {
        let map = &maps[i % maps.len()];
        let lim = &limits[(i / maps.len()) % limits.len()];
        let c_top = map.g / map.hover_thrust; // the c of thrust 1
        let c = hostile(&mut rng, c_top, true);
        let rates = v(
            hostile(&mut rng, lim.max.x, false),
            hostile(&mut rng, lim.max.y, false),
            hostile(&mut rng, lim.max.z, false),
        );
        let prev = if rng.random_bool(0.5) { previous } else { None };

        let s = make_setpoint(c, &rates, map, lim, prev.as_ref());
        let what = format!("#{i}: c = {c:e}, rates = {rates:?}, {map:?}, {lim:?}, {prev:?}");
        assert_safe(&s.setpoint, lim, &what);

        let finite = c.is_finite() && rates.iter().all(|r| r.is_finite());
        if finite {
            assert!(!s.replaced_non_finite, "{what}");
            // The exact mapping, in f64.
            let thrust = map.hover_thrust * c / map.g;
            let frd = [rates.x, -rates.y, -rates.z];
            let max = [lim.max.x, lim.max.y, lim.max.z];
            let f32_max = f64::from(f32::MAX);
            let in_range = (0.0..=1.0).contains(&thrust)
                && frd
                    .iter()
                    .zip(max)
                    .all(|(r, m)| r.abs() <= m && r.abs() <= f32_max);
            if in_range {
                exact += 1;
                let want = sp(frd.map(|r| r as f32), thrust as f32);
                assert_eq!(s.setpoint, want, "{what}");
                assert!(!s.clamped, "{what}");
            } else {
                clamped += 1;
                assert!(s.clamped, "{what}");
                // Clamped to the bound (capped at f32::MAX), then rounded.
                let clamp = |x: f64, lo: f64, hi: f64| x.max(lo).min(hi);
                let want_rates: [f32; 3] = std::array::from_fn(|k| {
                    let b = max[k].min(f32_max);
                    clamp(frd[k], -b, b) as f32
                });
                assert_eq!(s.setpoint.rates_frd, want_rates, "{what}");
                assert_eq!(s.setpoint.thrust, clamp(thrust, 0.0, 1.0) as f32, "{what}");
            }
        } else {
            assert!(s.replaced_non_finite, "{what}");
            assert!(!s.clamped, "{what}: the fallbacks here are in range");
            match prev {
                Some(p) => {
                    replaced_prev += 1;
                    assert_eq!(s.setpoint, p, "{what}");
                }
                None => {
                    replaced_hover += 1;
                    assert_eq!(s.setpoint, Px4Setpoint::hover(map), "{what}");
                }
            }
        }
        // Only previous setpoints made under the same limits are reused (the limits change
        // every few steps: restart the chain then).
        previous = if i % maps.len() == maps.len() - 1 {
            None
        } else {
            Some(s.setpoint)
        };
    }
    // Every branch was exercised many times.
    for (count, what) in [
        (exact, "exact"),
        (clamped, "clamped"),
        (replaced_prev, "replaced by the previous setpoint"),
        (replaced_hover, "replaced by hover"),
    ] {
        assert!(count > 10_000, "only {count} cases {what}");
    }
}
