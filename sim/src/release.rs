//! The release planner of the flip-and-throw mission: the release speed and angle that put a
//! drag-free point on a target at range `R` on flat ground, with the least release speed.
//!
//! # The range equation
//!
//! A point released at height `h >= 0` with speed `V` at angle `theta` above the horizontal
//! (gravity `g > 0`, no drag) flies `x(t) = V cos(theta) t`, `z(t) = h + V sin(theta) t -
//! g t^2 / 2`. It reaches `z = 0` at the flight time
//! `T = (V sin(theta) + sqrt((V sin(theta))^2 + 2 g h)) / g` and lands at the paper's range
//!
//! ```text
//! R(V, theta) = V cos(theta) (V sin(theta) + sqrt((V sin(theta))^2 + 2 g h)) / g.
//! ```
//!
//! For a descending release (`sin(theta) < 0`) the sum `V sin(theta) + sqrt(..)` cancels; it
//! is evaluated as `2 g h / (sqrt(..) - V sin(theta))` ([`range`], [`flight_time`],
//! [`landing_point`]). For fixed `theta`, `R` is strictly increasing in `V` (write it as
//! `2 h cos(theta) / (sqrt(sin^2(theta) + 2 g h / V^2) - sin(theta))` when `h > 0`, and
//! `V^2 sin(2 theta) / g` when `h = 0`); the one exception is `h = 0`, `theta <= 0`, where
//! the point lands where it is released and `R = 0` for every `V`.
//!
//! # The planning problem
//!
//! [`plan`] solves: minimize `V` subject to `R(V, theta) = R`, `v_min <= V <= v_max` and
//! `theta_min <= theta <= theta_max` (the [`ReleaseBounds`]). The least speed is the least
//! release energy the vehicle must pump into the probe and the smallest reaction at release.
//! The problem has two variables and one equality; it is solved exactly by reduction, not
//! by a generic NLP solver.
//!
//! **Eliminate `V`.** Substituting `t = R / (V cos(theta))` into `z(t) = 0` gives
//! `0 = h + R tan(theta) - g R^2 / (2 V^2 cos^2(theta))`, so on the target
//!
//! ```text
//! V^2(theta) = g R^2 / (2 cos^2(theta) (h + R tan(theta)))      where h + R tan(theta) > 0,
//! ```
//!
//! and no speed reaches `R` where `h + R tan(theta) <= 0` (the release points at or below
//! the target). `R` is the only positive root of `z(x) = 0` when `h > 0` (the roots' product
//! is negative), and the descending root when `h = 0`, so this `V` is the one of the range
//! equation; since `R` is increasing in `V` it is the only one.
//!
//! **The speed curve is a cosine.** With `rho = sqrt(R^2 + h^2)` and `phi = atan2(R, h)`,
//! `2 cos^2(theta) (h + R tan(theta)) = h (1 + cos 2 theta) + R sin 2 theta
//! = h + rho cos(2 theta - phi)`, so
//!
//! ```text
//! V^2(theta) = g R^2 / (h + rho cos(2 (theta - theta*))),   theta* = phi / 2.
//! ```
//!
//! It is symmetric about `theta*` and strictly unimodal on its domain `|theta - theta*| <
//! (pi - phi) / 2` (where the denominator is positive; the domain's ends are `theta = pi/2`
//! and `tan(theta) = -h / R`), with the minimum at `tan(theta*) = tan(phi / 2) =
//! (rho - h) / R` and `V*^2 = g R^2 / (h + rho) = g (rho - h)`. The level set `V(theta) =
//! v >= V*` is the pair `theta* +- delta(v)`, in closed form: `h + rho cos(2 delta) =
//! g R^2 / v^2` gives
//!
//! ```text
//! sin^2(delta(v)) = (rho + h) (1 - V*^2 / v^2) / (2 rho).
//! ```
//!
//! **The feasible set and its best point.** In `theta` the feasible set is `[theta_min,
//! theta_max]` intersected with `{V(theta) <= v_max}` (the interval `theta* +- delta(v_max)`
//! if `v_max >= V*`, else empty) and with `{V(theta) >= v_min}` (everything if `v_min <= V*`,
//! else everything but the open interval `theta* +- delta(v_min)`): one interval or two.
//! On `[theta_min, theta_max]` alone the slowest angle is `theta_c = clamp(theta*,
//! theta_min, theta_max)` (unimodality). If `v_min <= V(theta_c) <= v_max` it is the answer.
//! If `V(theta_c) > v_max` nothing is feasible. If `V(theta_c) < v_min`, every feasible
//! point has `V >= v_min`, and by continuity some angle between `theta_c` and a feasible
//! point has `V = v_min` exactly: the answer is `V = v_min` at the crossing `theta* -
//! delta(v_min)` if it lies in the angle bounds (the lower, shorter flight on a tie), else
//! `theta* + delta(v_min)`. The crossings are closed form, so no root finder and no
//! tolerance is involved; the plan's range matches the target to rounding.
//!
//! **Reachable ranges.** The reachable set is the image of the connected box of bounds, an
//! interval `[R_min, R_max]`. As `R` grows with `V`, `R_max` is the maximum over the angle
//! bounds of `R(v_max, theta)` and `R_min` the minimum of `R(v_min, theta)`. `R(v, theta)`
//! is unimodal in `theta`: by the monotonicity in `V`, `R(v, theta) >= X > 0` exactly where
//! `V(theta; X) <= v`, an interval by the above. So `R_min` is attained at an angle bound,
//! and `R_max` at `tan(theta) = v_max / sqrt(v_max^2 + 2 g h)` clamped into the bounds
//! ([`max_range`]). Outside `[R_min, R_max]`, [`plan`] returns
//! [`ReleaseError::Unreachable`] or [`ReleaseError::TooClose`] with the limit and the bound
//! to relax.

use std::f64::consts::FRAC_PI_2;

/// The bounds of the release speed and angle.
///
/// The [`Default`] is `v_min = 0`, `v_max = 16` m/s (what the vehicle can throw in the flip)
/// and `theta` in `[0, 1.2]` rad (level to about 69 degrees above the horizontal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReleaseBounds {
    /// Least release speed, m/s (`>= 0`).
    pub v_min: f64,
    /// Greatest release speed, m/s (`>= v_min`).
    pub v_max: f64,
    /// Least release angle above the horizontal, rad (in `(-pi/2, pi/2)`).
    pub theta_min: f64,
    /// Greatest release angle above the horizontal, rad (in `[theta_min, pi/2)`).
    pub theta_max: f64,
}

impl Default for ReleaseBounds {
    fn default() -> Self {
        Self {
            v_min: 0.0,
            v_max: 16.0,
            theta_min: 0.0,
            theta_max: 1.2,
        }
    }
}

/// A planned release: the speed and angle of least speed that reach the target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReleasePlan {
    /// Release speed, m/s.
    pub speed: f64,
    /// Release angle above the horizontal, rad.
    pub angle: f64,
    /// The range the plan achieves, m, recomputed by [`range`] (the target to rounding).
    pub range: f64,
    /// Release height above the ground, m.
    pub height: f64,
    /// Time from release to the ground, s.
    pub flight_time: f64,
    /// Release velocity `(horizontal toward the target, vertical up)`, m/s.
    pub velocity: [f64; 2],
}

/// Why no release plan exists, and what to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReleaseError {
    /// The target is beyond the longest throw the bounds allow.
    #[error(
        "range {range:.3} m is unreachable from height {height:.3} m with v_max = {v_max:.3} m/s \
         and theta in [{theta_min:.3}, {theta_max:.3}] rad: the maximum range is \
         {max_range:.3} m (at theta = {max_range_angle:.3} rad); raise v_max, widen the angle \
         bounds, release higher or move closer"
    )]
    Unreachable {
        /// The requested range, m.
        range: f64,
        /// The longest range under the bounds, m.
        max_range: f64,
        /// The angle of the longest range, rad.
        max_range_angle: f64,
        /// The speed bound that limits the range, m/s.
        v_max: f64,
        /// The release height, m.
        height: f64,
        /// The least angle, rad.
        theta_min: f64,
        /// The greatest angle, rad.
        theta_max: f64,
    },
    /// The target is nearer than the shortest throw at the least speed.
    #[error(
        "range {range:.3} m is too close from height {height:.3} m with v_min = {v_min:.3} m/s \
         and theta in [{theta_min:.3}, {theta_max:.3}] rad: the minimum range is \
         {min_range:.3} m; lower v_min, widen the angle bounds or move farther"
    )]
    TooClose {
        /// The requested range, m.
        range: f64,
        /// The shortest range under the bounds, m.
        min_range: f64,
        /// The speed bound that limits the range, m/s.
        v_min: f64,
        /// The release height, m.
        height: f64,
        /// The least angle, rad.
        theta_min: f64,
        /// The greatest angle, rad.
        theta_max: f64,
    },
    /// An input is out of its domain.
    #[error("invalid release input: `{field}` = {value} must be {requirement}")]
    InvalidInput {
        /// The offending field or argument.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        requirement: &'static str,
    },
}

/// Time for a point at height `z >= 0` with vertical velocity `vz` to reach `z = 0` under
/// gravity `g` (the later root of `z + vz t - g t^2 / 2 = 0`), cancellation-free.
fn time_to_ground(z: f64, vz: f64, g: f64) -> f64 {
    if z <= 0.0 && vz <= 0.0 {
        return 0.0;
    }
    let root = (vz * vz + 2.0 * g * z).sqrt();
    if vz >= 0.0 {
        (vz + root) / g
    } else {
        2.0 * z / (root - vz)
    }
}

/// The drag-free range on flat ground of a point released at height `h >= 0` with speed
/// `v` at angle `theta` above the horizontal, gravity `g > 0`: the range equation
/// `v cos(theta) (v sin(theta) + sqrt((v sin(theta))^2 + 2 g h)) / g`.
///
/// Returns NaN for `h < 0`.
#[must_use]
pub fn range(v: f64, theta: f64, h: f64, g: f64) -> f64 {
    v * theta.cos() * flight_time(v, theta, h, g)
}

/// The drag-free flight time from release (height `h >= 0`, speed `v`, angle `theta` above
/// the horizontal) to the ground, gravity `g > 0`:
/// `(v sin(theta) + sqrt((v sin(theta))^2 + 2 g h)) / g`; zero for `h = 0`, `theta <= 0`.
///
/// Returns NaN for `h < 0`.
#[must_use]
pub fn flight_time(v: f64, theta: f64, h: f64, g: f64) -> f64 {
    if h < 0.0 {
        return f64::NAN;
    }
    time_to_ground(h, v * theta.sin(), g)
}

/// The exact drag-free landing point on the ground `z = 0` of a point at position `p` with
/// velocity `v`, gravity `g > 0` along `-z`.
///
/// A point below the ground (`p[2] < 0`), or on it and not rising (`p[2] = 0`, `v[2] <= 0`),
/// counts as landed at `p`; on the ground and rising, it lands where it comes down. Returns
/// `None` if the point never reaches `z <= 0` (with `g = 0` and `v[2] >= 0`) or an input is
/// not finite. One square root and one division: cheap enough to call at every control tick
/// to decide the release instant.
#[must_use]
pub fn landing_point(p: [f64; 3], v: [f64; 3], g: f64) -> Option<[f64; 3]> {
    if !(p.iter().chain(&v).all(|x| x.is_finite()) && g.is_finite()) {
        return None;
    }
    if p[2] < 0.0 || (p[2] == 0.0 && v[2] <= 0.0) {
        return Some(p);
    }
    let t = time_to_ground(p[2], v[2], g);
    (t.is_finite() && t >= 0.0).then(|| [p[0] + v[0] * t, p[1] + v[1] * t, 0.0])
}

fn invalid(field: &'static str, value: f64, requirement: &'static str) -> ReleaseError {
    ReleaseError::InvalidInput {
        field,
        value,
        requirement,
    }
}

fn check_height_gravity(height: f64, g: f64) -> Result<(), ReleaseError> {
    if !(height.is_finite() && height >= 0.0) {
        return Err(invalid("height", height, "finite and >= 0"));
    }
    if !(g.is_finite() && g > 0.0) {
        return Err(invalid("g", g, "finite and > 0"));
    }
    Ok(())
}

impl ReleaseBounds {
    /// Checks the bounds: finite, `0 <= v_min <= v_max`, `-pi/2 < theta_min <= theta_max <
    /// pi/2`.
    ///
    /// # Errors
    ///
    /// [`ReleaseError::InvalidInput`] naming the first offending field.
    pub fn validate(&self) -> Result<(), ReleaseError> {
        let b = self;
        if !(b.v_min.is_finite() && b.v_min >= 0.0) {
            return Err(invalid("v_min", b.v_min, "finite and >= 0"));
        }
        if !b.v_max.is_finite() {
            return Err(invalid("v_max", b.v_max, "finite"));
        }
        if b.v_max < b.v_min {
            return Err(invalid("v_max", b.v_max, ">= v_min (empty speed bounds)"));
        }
        let in_range = |x: f64| x.is_finite() && x > -FRAC_PI_2 && x < FRAC_PI_2;
        if !in_range(b.theta_min) {
            return Err(invalid(
                "theta_min",
                b.theta_min,
                "finite and in (-pi/2, pi/2)",
            ));
        }
        if !in_range(b.theta_max) {
            return Err(invalid(
                "theta_max",
                b.theta_max,
                "finite and in (-pi/2, pi/2)",
            ));
        }
        if b.theta_max < b.theta_min {
            return Err(invalid(
                "theta_max",
                b.theta_max,
                ">= theta_min (empty angle bounds)",
            ));
        }
        Ok(())
    }
}

/// The longest range under the bounds from height `height`, and its angle: the maximum over
/// `[theta_min, theta_max]` of `R(v_max, theta)`, attained at `tan(theta) = v_max /
/// sqrt(v_max^2 + 2 g h)` clamped into the bounds (`R` is unimodal in `theta`).
///
/// # Errors
///
/// [`ReleaseError::InvalidInput`] for a negative or non-finite height, a non-positive or
/// non-finite `g`, or invalid bounds.
pub fn max_range(height: f64, g: f64, bounds: &ReleaseBounds) -> Result<(f64, f64), ReleaseError> {
    check_height_gravity(height, g)?;
    bounds.validate()?;
    let v = bounds.v_max;
    let theta = v
        .atan2((v * v + 2.0 * g * height).sqrt())
        .clamp(bounds.theta_min, bounds.theta_max);
    Ok((range(v, theta, height, g), theta))
}

/// The release of least speed that lands a drag-free point released at height `height` on
/// flat ground at `range` (gravity `g`), under `bounds`; see the [module docs](self) for the
/// exact reduction.
///
/// # Errors
///
/// * [`ReleaseError::InvalidInput`] for a non-positive or non-finite range, a negative or
///   non-finite height, a non-positive or non-finite `g`, or invalid bounds.
/// * [`ReleaseError::Unreachable`] if `range` exceeds [`max_range`].
/// * [`ReleaseError::TooClose`] if `range` is below the shortest range at `v_min`.
pub fn plan(
    range: f64,
    height: f64,
    g: f64,
    bounds: &ReleaseBounds,
) -> Result<ReleasePlan, ReleaseError> {
    let target = range;
    if !(target.is_finite() && target > 0.0) {
        return Err(invalid("range", target, "finite and > 0"));
    }
    let (r_max, theta_r_max) = max_range(height, g, bounds)?;
    let (h, b) = (height, bounds);
    let unreachable = || ReleaseError::Unreachable {
        range: target,
        max_range: r_max,
        max_range_angle: theta_r_max,
        v_max: b.v_max,
        height: h,
        theta_min: b.theta_min,
        theta_max: b.theta_max,
    };
    if target > r_max {
        return Err(unreachable());
    }
    let r_min =
        self::range(b.v_min, b.theta_min, h, g).min(self::range(b.v_min, b.theta_max, h, g));
    if target < r_min {
        return Err(ReleaseError::TooClose {
            range: target,
            min_range: r_min,
            v_min: b.v_min,
            height: h,
            theta_min: b.theta_min,
            theta_max: b.theta_max,
        });
    }

    // The speed curve V^2(theta) = g R^2 / (h + rho cos(2 (theta - theta*))).
    let rho = target.hypot(h);
    let theta_star = (target / (rho + h)).atan();
    let v_star_sq = g * target * target / (rho + h);
    let speed_at = |theta: f64| {
        let c = theta.cos();
        let denom = 2.0 * c * (h * c + target * theta.sin());
        if denom > 0.0 {
            (g * target * target / denom).sqrt()
        } else {
            f64::INFINITY
        }
    };

    let theta_c = theta_star.clamp(b.theta_min, b.theta_max);
    let v_c = speed_at(theta_c);
    let angle = if v_c >= b.v_min {
        theta_c
    } else {
        // V(theta_c) < v_min: the optimum is V = v_min at a crossing theta* -+ delta.
        let v_min_sq = b.v_min * b.v_min;
        let sin_sq = ((rho + h) * (1.0 - v_star_sq / v_min_sq) / (2.0 * rho)).clamp(0.0, 1.0);
        let delta = sin_sq.sqrt().asin();
        let (lower, upper) = (theta_star - delta, theta_star + delta);
        if lower >= b.theta_min {
            lower
        } else if upper <= b.theta_max {
            upper
        } else if b.theta_min - lower <= upper - b.theta_max {
            // Rounding at R = R_min: the crossing sits on an angle bound.
            b.theta_min
        } else {
            b.theta_max
        }
    };
    let v = speed_at(angle);
    if !v.is_finite() {
        return Err(unreachable());
    }
    let speed = v.clamp(b.v_min, b.v_max);
    Ok(ReleasePlan {
        speed,
        angle,
        range: self::range(speed, angle, h, g),
        height: h,
        flight_time: flight_time(speed, angle, h, g),
        velocity: [speed * angle.cos(), speed * angle.sin()],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn release_crossings_are_on_the_level_set() {
        // sin^2(delta) = (rho + h)(1 - V*^2 / v^2) / (2 rho) puts V(theta* +- delta) = v.
        let (g, h, r) = (9.81, 3.0, 20.0);
        let rho = f64::hypot(r, h);
        let theta_star = (r / (rho + h)).atan();
        let v_star_sq = g * (rho - h);
        for v in [13.5, 15.0, 20.0, 40.0] {
            let sin_sq = (rho + h) * (1.0 - v_star_sq / (v * v)) / (2.0 * rho);
            let delta = sin_sq.sqrt().asin();
            for theta in [theta_star - delta, theta_star + delta] {
                assert!(
                    (range(v, theta, h, g) - r).abs() < 1e-11 * r,
                    "v {v} theta {theta}"
                );
            }
        }
    }

    #[test]
    fn release_descending_branch_has_no_cancellation() {
        // h = 0, theta < 0 lands at once; tiny h, steep descent: the rationalized form.
        assert_eq!(range(10.0, -0.3, 0.0, 9.81), 0.0);
        assert_eq!(flight_time(0.0, 0.0, 0.0, 9.81), 0.0);
        let (v, theta, h, g) = (1e4, -1.0, 1e-6, 9.81);
        let vz = v * f64::sin(theta);
        let expect_t = -h / vz; // g t^2 is negligible at this scale
        assert!((flight_time(v, theta, h, g) / expect_t - 1.0).abs() < 1e-9);
        assert!(flight_time(1.0, 0.0, -1.0, 9.81).is_nan());
    }
}
