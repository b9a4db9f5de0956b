//! Tests of the release planner against independent references: an RK4 ballistic
//! integration with Hermite crossing search, and brute-force searches over the angle with
//! speeds found by bisection on the range equation (not the planner's closed forms).

use mpc_sim::mission::G;
use mpc_sim::release::{
    ReleaseBounds, ReleaseError, ReleasePlan, flight_time, landing_point, max_range, plan, range,
};

/// Integrates a drag-free point (RK4, dt 1e-4, on the generic `x'' = a(x, v)` form) until it
/// crosses `z = 0`, then finds the crossing time by bisection on the cubic Hermite
/// interpolant of the step. Returns the landing position and the time.
fn integrate_landing(p: [f64; 3], v: [f64; 3], g: f64) -> ([f64; 3], f64) {
    let accel = |_p: [f64; 3], _v: [f64; 3]| [0.0, 0.0, -g];
    let dt = 1e-4;
    if p[2] <= 0.0 && v[2] <= 0.0 {
        return (p, 0.0);
    }
    let add =
        |a: [f64; 3], b: [f64; 3], s: f64| [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]];
    let (mut p, mut v, mut t) = (p, v, 0.0);
    for _ in 0..10_000_000 {
        let k1p = v;
        let k1v = accel(p, v);
        let k2p = add(v, k1v, dt / 2.0);
        let k2v = accel(add(p, k1p, dt / 2.0), k2p);
        let k3p = add(v, k2v, dt / 2.0);
        let k3v = accel(add(p, k2p, dt / 2.0), k3p);
        let k4p = add(v, k3v, dt);
        let k4v = accel(add(p, k3p, dt), k4p);
        let mut pn = p;
        let mut vn = v;
        for i in 0..3 {
            pn[i] += dt / 6.0 * (k1p[i] + 2.0 * k2p[i] + 2.0 * k3p[i] + k4p[i]);
            vn[i] += dt / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i]);
        }
        if pn[2] <= 0.0 {
            // Cubic Hermite on [0, dt] per coordinate; bisection for z(s) = 0.
            let herm = |i: usize, s: f64| {
                let u = s / dt;
                let (h00, h10) = (
                    2.0 * u.powi(3) - 3.0 * u * u + 1.0,
                    u.powi(3) - 2.0 * u * u + u,
                );
                let (h01, h11) = (-2.0 * u.powi(3) + 3.0 * u * u, u.powi(3) - u * u);
                h00 * p[i] + h10 * dt * v[i] + h01 * pn[i] + h11 * dt * vn[i]
            };
            let (mut lo, mut hi) = (0.0, dt);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if herm(2, mid) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let s = 0.5 * (lo + hi);
            return ([herm(0, s), herm(1, s), 0.0], t + s);
        }
        p = pn;
        v = vn;
        t += dt;
    }
    panic!("no landing");
}

fn grid(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f64> {
    (0..n).map(move |i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
}

/// The speed that reaches `target` at `theta` by bisection on the range equation (which is
/// increasing in the speed), or None if no speed below 1e4 m/s does.
fn speed_by_bisection(target: f64, theta: f64, h: f64, g: f64) -> Option<f64> {
    let mut hi = 1.0;
    while range(hi, theta, h, g) < target {
        hi *= 2.0;
        if hi > 1e4 {
            return None;
        }
    }
    let mut lo = 0.0;
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if range(mid, theta, h, g) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

/// Maximizes `f` over `[lo, hi]` by a dense grid refined around the best point (30 zooms of
/// 401 points); `f` returns None where infeasible. Returns `(f, x)` at the best point.
fn brute_max(lo: f64, hi: f64, f: impl Fn(f64) -> Option<f64>) -> Option<(f64, f64)> {
    let (mut a, mut b) = (lo, hi);
    let mut best: Option<(f64, f64)> = None;
    let n = 401;
    for level in 0..30 {
        let pts = if level == 0 { 5_001 } else { n };
        let step = (b - a) / (pts - 1) as f64;
        for x in grid(a, b, pts) {
            if let Some(y) = f(x)
                && best.is_none_or(|(by, _)| y > by)
            {
                best = Some((y, x));
            }
        }
        let (_, x) = best?;
        a = (x - step).max(lo);
        b = (x + step).min(hi);
    }
    best
}

/// The least feasible speed by brute force: maximize `-V(theta)` over the angle bounds with
/// `V(theta)` from bisection and the speed bounds as feasibility.
fn brute_min_speed(target: f64, h: f64, g: f64, b: &ReleaseBounds) -> Option<(f64, f64)> {
    brute_max(b.theta_min, b.theta_max, |theta| {
        let v = speed_by_bisection(target, theta, h, g)?;
        (v >= b.v_min && v <= b.v_max).then_some(-v)
    })
    .map(|(neg_v, theta)| (-neg_v, theta))
}

fn wide() -> ReleaseBounds {
    ReleaseBounds {
        v_min: 0.0,
        v_max: 100.0,
        theta_min: -1.5,
        theta_max: 1.5,
    }
}

fn check_plan(p: &ReleasePlan, target: f64, h: f64, b: &ReleaseBounds) {
    assert!(
        (range(p.speed, p.angle, h, G) - target).abs() < 1e-9,
        "{p:?}"
    );
    assert!((p.range - target).abs() < 1e-9, "{p:?}");
    assert!(p.speed >= b.v_min && p.speed <= b.v_max, "{p:?}");
    assert!(p.angle >= b.theta_min && p.angle <= b.theta_max, "{p:?}");
    assert_eq!(p.height, h);
    assert!((p.flight_time - flight_time(p.speed, p.angle, h, G)).abs() < 1e-12);
    assert!((p.velocity[0] - p.speed * p.angle.cos()).abs() < 1e-12);
    assert!((p.velocity[1] - p.speed * p.angle.sin()).abs() < 1e-12);
    let (v, _) = brute_min_speed(target, h, G, b).expect("brute force finds a feasible release");
    assert!((p.speed - v).abs() < 1e-6, "plan {} brute {v}", p.speed);
}

#[test]
fn release_range_equation_matches_integration() {
    let mut worst: f64 = 0.0;
    for v in grid(1.0, 20.0, 8) {
        for theta in grid(-0.5, 1.3, 10) {
            for h in grid(0.0, 10.0, 5) {
                let (land, t) =
                    integrate_landing([0.0, 0.0, h], [v * theta.cos(), 0.0, v * theta.sin()], G);
                let r = range(v, theta, h, G);
                let err = (r - land[0]).abs() / r.max(1.0);
                worst = worst.max(err);
                assert!(err < 1e-6, "v {v} theta {theta} h {h}: {r} vs {}", land[0]);
                assert!((flight_time(v, theta, h, G) - t).abs() < 1e-6 * t.max(1.0));
            }
        }
    }
    println!("range equation vs RK4: worst relative error {worst:.2e}");
}

#[test]
fn release_landing_point_matches_integration() {
    for px in [-3.0, 0.0, 2.5] {
        for pz in [0.0, 0.5, 3.0, 10.0] {
            for vx in [-4.0, 0.0, 7.0] {
                for vy in [-2.0, 1.5] {
                    for vz in [-9.0, -1.0, 0.0, 2.0, 12.0] {
                        let (p, v) = ([px, 1.0, pz], [vx, vy, vz]);
                        let got = landing_point(p, v, G).expect("lands under gravity");
                        let (want, _) = integrate_landing(p, v, G);
                        if pz == 0.0 && vz <= 0.0 {
                            // On the ground and not rising: landed where it is.
                            assert_eq!(got, p);
                            continue;
                        }
                        for i in 0..3 {
                            assert!(
                                (got[i] - want[i]).abs() < 1e-6 * want[i].abs().max(1.0),
                                "{p:?} {v:?}: {got:?} vs {want:?}"
                            );
                        }
                    }
                }
            }
        }
    }
    // Below the ground: landed where it is.
    assert_eq!(
        landing_point([1.0, 2.0, -0.1], [3.0, 0.0, 5.0], G),
        Some([1.0, 2.0, -0.1])
    );
    // Never lands: no gravity and not descending; non-finite inputs.
    assert_eq!(landing_point([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 0.0), None);
    assert_eq!(landing_point([0.0, 0.0, 1.0], [1.0, 0.0, 2.0], 0.0), None);
    assert_eq!(
        landing_point([0.0, 0.0, 1.0], [1.0, 0.0, -0.5], 0.0),
        Some([2.0, 0.0, 0.0])
    );
    assert_eq!(
        landing_point([f64::NAN, 0.0, 1.0], [1.0, 0.0, 0.0], G),
        None
    );
    assert_eq!(
        landing_point([0.0, 0.0, 1.0], [1.0, f64::INFINITY, 0.0], G),
        None
    );
    // Consistent with the range equation.
    let p = landing_point(
        [0.0, 0.0, 3.0],
        [13.0 * 0.7f64.cos(), 0.0, 13.0 * 0.7f64.sin()],
        G,
    )
    .unwrap();
    assert!((p[0] - range(13.0, 0.7, 3.0, G)).abs() < 1e-12);
}

#[test]
fn release_speed_curve_algebra() {
    // V^2(theta) = g R^2 / (2 cos^2(theta) (h + R tan(theta))) against bisection on R.
    for target in [1.0, 7.5, 20.0, 35.0] {
        for h in [0.0, 3.0, 10.0] {
            for theta in grid(-1.2, 1.4, 27) {
                let denom = 2.0 * theta.cos().powi(2) * (h + target * theta.tan());
                let closed = (denom > 0.0).then(|| (G * target * target / denom).sqrt());
                let bisect = speed_by_bisection(target, theta, h, G);
                match (closed, bisect) {
                    (Some(c), Some(b)) => {
                        assert!(
                            (c - b).abs() < 1e-9 * c,
                            "R {target} h {h} theta {theta}: {c} vs {b}"
                        );
                        assert!((range(c, theta, h, G) - target).abs() < 1e-9 * target);
                    }
                    (None, None) => {}
                    // Near the domain's edge the speed exceeds the bisection's ceiling.
                    (Some(c), None) => assert!(c > 1e4),
                    (None, Some(b)) => {
                        panic!("R {target} h {h} theta {theta}: bisection {b}, no closed form")
                    }
                }
            }
        }
    }
}

#[test]
fn release_plan_inactive_bounds_is_closed_form() {
    for (target, h) in [(5.0, 0.0), (20.0, 3.0), (12.0, 10.0), (0.5, 8.0)] {
        let b = wide();
        let p = plan(target, h, G, &b).unwrap();
        let rho = f64::hypot(target, h);
        let v_star = (G * (rho - h)).sqrt();
        let theta_star = ((rho - h) / target).atan();
        assert!((p.speed - v_star).abs() < 1e-9, "{p:?} vs {v_star}");
        assert!((p.angle - theta_star).abs() < 1e-9, "{p:?} vs {theta_star}");
        check_plan(&p, target, h, &b);
    }
}

#[test]
fn release_paper_case() {
    let p = plan(20.0, 3.0, G, &ReleaseBounds::default()).unwrap();
    println!(
        "paper case R = 20 m, h = 3 m: V = {:.4} m/s, theta = {:.4} rad ({:.2} deg), T = {:.4} s",
        p.speed,
        p.angle,
        p.angle.to_degrees(),
        p.flight_time
    );
    assert!((p.speed - 13.0).abs() < 0.05, "{p:?}");
    check_plan(&p, 20.0, 3.0, &ReleaseBounds::default());
}

#[test]
fn release_plan_active_bounds() {
    let (target, h) = (20.0, 3.0);
    let free = plan(target, h, G, &wide()).unwrap();

    // Angle bounds below theta*: the plan sits on theta_max.
    let b = ReleaseBounds {
        theta_max: 0.3,
        ..wide()
    };
    let p = plan(target, h, G, &b).unwrap();
    assert_eq!(p.angle, 0.3);
    check_plan(&p, target, h, &b);

    // Angle bounds above theta*: on theta_min.
    let b = ReleaseBounds {
        theta_min: 1.0,
        ..wide()
    };
    let p = plan(target, h, G, &b).unwrap();
    assert_eq!(p.angle, 1.0);
    check_plan(&p, target, h, &b);

    // v_min above V*: two feasible intervals; the plan is V = v_min, the lower crossing.
    let b = ReleaseBounds {
        v_min: 14.0,
        ..wide()
    };
    let p = plan(target, h, G, &b).unwrap();
    assert!(
        (p.speed - 14.0).abs() < 1e-12 && p.angle < free.angle,
        "{p:?}"
    );
    check_plan(&p, target, h, &b);
    let lower = p.angle;

    // The lower crossing cut off by theta_min: the upper crossing.
    let b = ReleaseBounds {
        v_min: 14.0,
        theta_min: lower + 0.05,
        ..wide()
    };
    let p = plan(target, h, G, &b).unwrap();
    assert!(
        (p.speed - 14.0).abs() < 1e-12 && p.angle > free.angle,
        "{p:?}"
    );
    check_plan(&p, target, h, &b);

    // v_min and theta_max together, theta_max between the lower crossing and theta*: the
    // slowest angle in bounds is too slow, V = v_min at the lower crossing.
    let b = ReleaseBounds {
        v_min: 14.0,
        theta_max: 0.5 * (lower + free.angle),
        ..wide()
    };
    let p = plan(target, h, G, &b).unwrap();
    assert!(
        (p.speed - 14.0).abs() < 1e-12 && (p.angle - lower).abs() < 1e-12,
        "{p:?}"
    );
    check_plan(&p, target, h, &b);

    // v_max active: the target at the maximum range is thrown at v_max from the max-range angle.
    let b = ReleaseBounds::default();
    let (r_max, theta_max_range) = max_range(h, G, &b).unwrap();
    let p = plan(r_max, h, G, &b).unwrap();
    assert!((p.speed - b.v_max).abs() < 1e-6, "{p:?}");
    assert!((p.angle - theta_max_range).abs() < 1e-4, "{p:?}");
    assert!((p.range - r_max).abs() < 1e-9);

    // A just-too-fast speed bound: the same target needs v_max a hair above V*.
    let b = ReleaseBounds {
        v_max: free.speed * (1.0 - 1e-9),
        ..wide()
    };
    assert!(matches!(
        plan(target, h, G, &b),
        Err(ReleaseError::Unreachable { .. })
    ));
    let b = ReleaseBounds {
        v_max: free.speed * (1.0 + 1e-9),
        ..wide()
    };
    // (Too narrow a feasible window, about 3e-5 rad, for the brute-force grid.)
    let p = plan(target, h, G, &b).unwrap();
    assert!((p.speed - free.speed).abs() < 1e-12 && (p.angle - free.angle).abs() < 1e-12);
    assert!((p.range - target).abs() < 1e-9);
}

#[test]
fn release_plan_matches_brute_force_over_cases() {
    // (planned, unreachable, too close): every outcome is exercised.
    let mut seen = [0usize; 3];
    for target in [2.0, 9.0, 20.0, 26.0] {
        for h in [0.0, 1.5, 6.0] {
            for b in [
                ReleaseBounds::default(),
                ReleaseBounds {
                    v_min: 11.0,
                    ..ReleaseBounds::default()
                },
                ReleaseBounds {
                    theta_min: -0.4,
                    theta_max: 0.4,
                    ..ReleaseBounds::default()
                },
                ReleaseBounds {
                    v_min: 6.0,
                    v_max: 20.0,
                    theta_min: 0.9,
                    theta_max: 1.3,
                },
            ] {
                match plan(target, h, G, &b) {
                    Ok(p) => {
                        seen[0] += 1;
                        check_plan(&p, target, h, &b);
                    }
                    Err(ReleaseError::Unreachable { max_range, .. }) => {
                        seen[1] += 1;
                        assert!(target > max_range);
                        assert!(
                            brute_min_speed(target, h, G, &b).is_none(),
                            "R {target} h {h} {b:?}"
                        );
                    }
                    Err(ReleaseError::TooClose { min_range, .. }) => {
                        seen[2] += 1;
                        assert!(target < min_range);
                        assert!(
                            brute_min_speed(target, h, G, &b).is_none(),
                            "R {target} h {h} {b:?}"
                        );
                    }
                    Err(e) => panic!("{e}"),
                }
            }
        }
    }
    println!("planned, unreachable, too close: {seen:?}");
    assert!(seen.iter().all(|&n| n > 0), "{seen:?}");
}

#[test]
fn release_unreachable_reports_the_max_range() {
    let b = ReleaseBounds::default();
    let err = plan(40.0, 3.0, G, &b).unwrap_err();
    let ReleaseError::Unreachable {
        range: r,
        max_range: m,
        v_max,
        ..
    } = err
    else {
        panic!("{err:?}");
    };
    assert_eq!((r, v_max), (40.0, 16.0));
    let (brute, theta) =
        brute_max(b.theta_min, b.theta_max, |t| Some(range(16.0, t, 3.0, G))).unwrap();
    assert!((m - brute).abs() < 1e-6, "{m} vs brute {brute} at {theta}");
    assert_eq!(max_range(3.0, G, &b).unwrap().0, m);
    let msg = err.to_string();
    println!("{msg}");
    assert!(msg.contains("v_max = 16.000"), "{msg}");
    assert!(msg.contains(&format!("{m:.3} m")), "{msg}");

    // Angle bounds that cut off the max-range angle: the clamp is the maximum.
    for (lo, hi) in [(0.0, 0.3), (1.0, 1.2), (-1.0, -0.2)] {
        let b = ReleaseBounds {
            theta_min: lo,
            theta_max: hi,
            ..b
        };
        for h in [0.0, 3.0] {
            let (m, t) = max_range(h, G, &b).unwrap();
            let (brute, _) = brute_max(lo, hi, |t| Some(range(16.0, t, h, G))).unwrap();
            assert!(
                (m - brute).abs() < 1e-6,
                "{lo} {hi} {h}: {m} at {t} vs {brute}"
            );
        }
    }
}

#[test]
fn release_too_close() {
    let b = ReleaseBounds {
        v_min: 10.0,
        theta_min: 0.2,
        theta_max: 1.0,
        ..ReleaseBounds::default()
    };
    let err = plan(2.0, 3.0, G, &b).unwrap_err();
    let ReleaseError::TooClose {
        min_range, v_min, ..
    } = err
    else {
        panic!("{err:?}");
    };
    assert_eq!(v_min, 10.0);
    let (neg_brute, _) = brute_max(0.2, 1.0, |t| Some(-range(10.0, t, 3.0, G))).unwrap();
    assert!((min_range + neg_brute).abs() < 1e-6);
    let msg = err.to_string();
    assert!(
        msg.contains("v_min = 10.000") && msg.contains(&format!("{min_range:.3} m")),
        "{msg}"
    );
    // At the minimum range itself: V = v_min on an angle bound.
    let p = plan(min_range, 3.0, G, &b).unwrap();
    assert!(
        (p.speed - 10.0).abs() < 1e-9 && (p.range - min_range).abs() < 1e-9,
        "{p:?}"
    );
}

#[test]
fn release_invalid_inputs() {
    let d = ReleaseBounds::default();
    let field_of = |r: Result<ReleasePlan, ReleaseError>| match r {
        Err(ReleaseError::InvalidInput { field, .. }) => field,
        other => panic!("{other:?}"),
    };
    assert_eq!(field_of(plan(f64::NAN, 3.0, G, &d)), "range");
    assert_eq!(field_of(plan(0.0, 3.0, G, &d)), "range");
    assert_eq!(field_of(plan(-5.0, 3.0, G, &d)), "range");
    assert_eq!(field_of(plan(f64::INFINITY, 3.0, G, &d)), "range");
    assert_eq!(field_of(plan(10.0, -1.0, G, &d)), "height");
    assert_eq!(field_of(plan(10.0, f64::NAN, G, &d)), "height");
    assert_eq!(field_of(plan(10.0, 3.0, 0.0, &d)), "g");
    assert_eq!(field_of(plan(10.0, 3.0, -G, &d)), "g");
    assert_eq!(field_of(plan(10.0, 3.0, f64::INFINITY, &d)), "g");
    let cases: [(ReleaseBounds, &str); 8] = [
        (ReleaseBounds { v_min: -1.0, ..d }, "v_min"),
        (
            ReleaseBounds {
                v_min: f64::NAN,
                ..d
            },
            "v_min",
        ),
        (
            ReleaseBounds {
                v_max: f64::INFINITY,
                ..d
            },
            "v_max",
        ),
        (
            ReleaseBounds {
                v_min: 10.0,
                v_max: 5.0,
                ..d
            },
            "v_max",
        ),
        (
            ReleaseBounds {
                theta_min: -2.0,
                ..d
            },
            "theta_min",
        ),
        (
            ReleaseBounds {
                theta_max: std::f64::consts::FRAC_PI_2,
                ..d
            },
            "theta_max",
        ),
        (
            ReleaseBounds {
                theta_min: 1.0,
                theta_max: 0.5,
                ..d
            },
            "theta_max",
        ),
        (
            ReleaseBounds {
                theta_max: f64::NAN,
                ..d
            },
            "theta_max",
        ),
    ];
    for (b, field) in cases {
        assert_eq!(field_of(plan(10.0, 3.0, G, &b)), field, "{b:?}");
        assert!(
            matches!(max_range(3.0, G, &b), Err(ReleaseError::InvalidInput { field: f, .. }) if f == field)
        );
        let msg = plan(10.0, 3.0, G, &b).unwrap_err().to_string();
        assert!(msg.contains(&format!("`{field}`")), "{msg}");
    }
}

#[test]
fn release_table_at_three_metres() {
    let b = ReleaseBounds::default();
    let (r_max, theta_r_max) = max_range(3.0, G, &b).unwrap();
    println!("h = 3 m, default bounds: max range {r_max:.4} m at theta {theta_r_max:.4} rad");
    println!(
        "{:>6} {:>9} {:>9} {:>8} {:>8}",
        "R m", "V m/s", "theta rad", "deg", "T s"
    );
    let mut last = 0.0;
    for target in [5.0, 10.0, 15.0, 20.0, 25.0] {
        let p = plan(target, 3.0, G, &b).expect("reachable with the defaults");
        println!(
            "{target:>6.1} {:>9.4} {:>9.4} {:>8.2} {:>8.4}",
            p.speed,
            p.angle,
            p.angle.to_degrees(),
            p.flight_time
        );
        assert!(p.speed > last);
        last = p.speed;
        check_plan(&p, target, 3.0, &b);
    }
}
