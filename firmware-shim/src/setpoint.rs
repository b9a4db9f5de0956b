//! The setpoint PX4 takes in offboard body-rate mode, made safe.
//!
//! PX4's SET_ATTITUDE_TARGET with `type_mask = 128` (ignore the attitude) carries body rates
//! in FRD, rad/s, and a normalized collective thrust in `[0, 1]`. The models command body
//! rates in FLU and a mass-normalized collective acceleration `c` (m/s^2, along body +z).
//! [`make_setpoint`] converts one to the other and guarantees the result is finite and in
//! range, whatever the solver produced.
//!
//! # Thrust mapping
//!
//! `thrust = hover_thrust * c / g` ([`ThrustMap`]): PX4's own linear hover-thrust model, in
//! which the normalized thrust `hover_thrust` holds the vehicle (`c = g`) and thrust is
//! proportional to collective acceleration. `hover_thrust` depends on the vehicle (mass,
//! motors, propellers, battery) and must be calibrated:
//!
//! * hover in POSCTL (or ALTCTL) more than 1 m above the ground for some tens of seconds and
//!   read PX4's hover-thrust estimate: the `hover_thrust_estimate` uORB topic (`listener
//!   hover_thrust_estimate` in the PX4 shell, or the flight log), field `hover_thrust`, once
//!   its `valid` flag is set. The estimator (module `mc_hover_thrust_estimator`) starts from
//!   `MPC_THR_HOVER` and only runs while PX4's position controller does (POSCTL, ALTCTL, the
//!   AUTO modes), not in offboard body-rate mode. PX4 uses the estimate in place of
//!   `MPC_THR_HOVER` when `MPC_USE_HTE` is set, but does not write it back to the parameter:
//!   copy it to `hover_thrust` (and, if wanted, to `MPC_THR_HOVER`) yourself;
//! * or log the normalized thrust PX4 applies in a steady hover (`vehicle_thrust_setpoint`,
//!   body z, negated) and average it.
//!
//! PX4's default `MPC_THR_HOVER` is 0.5 ([`ThrustMap::default`]); PX4 v1.16's SIH quadrotor
//! was measured at 0.495. Recalibrate after changing the payload or the battery.
//!
//! # Safety
//!
//! * A non-finite input (any component of `c` or of the rates) yields the previous setpoint
//!   if there is one, else a hover setpoint ([`Px4Setpoint::hover`]);
//! * values out of range are clamped: each rate to `+-max` of its axis ([`RateLimits`]), the
//!   thrust to `[0, 1]`; clamping is repeated after the `f64 -> f32` cast, so the `f32` values
//!   sent are within `+-(max as f32)` and `[0, 1]`;
//! * [`Sanitized`] reports whether either happened, so the caller can count and log them;
//!   repeating the previous setpoint is a bridge over a bad solve, not a failsafe: the caller
//!   must act (hold, land) when replacements persist.
//!
//! [`make_setpoint`] never fails and never panics. It does not validate its parameters (call
//! [`ThrustMap::validate`] and [`RateLimits::validate`] once, at configuration); even with
//! invalid ones its output is finite and in range: a non-finite or non-positive rate limit
//! allows only a zero rate on its axis, a limit beyond `f32::MAX` is capped at `f32::MAX`,
//! and a thrust map giving a NaN thrust is treated like a non-finite input (with a
//! non-finite `hover_thrust`, hover uses PX4's default 0.5).

use nalgebra::Vector3;

use crate::frames::flu_to_frd;

/// A thrust map or rate limits that cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum SetpointError {
    /// [`ThrustMap::hover_thrust`] is not a finite number strictly between 0 and 1.
    #[error(
        "hover thrust {0} is not strictly between 0 and 1: set `hover_thrust` to the normalized \
         thrust that holds the vehicle in a hover (PX4's hover-thrust estimate or MPC_THR_HOVER, \
         default 0.5)"
    )]
    HoverThrust(f64),
    /// [`ThrustMap::g`] is not a finite positive number.
    #[error(
        "gravity g = {0} m/s^2 is not finite and positive: set `g` to 9.81 (or the local value)"
    )]
    Gravity(f64),
    /// A component of [`RateLimits::max`] is not a finite positive number.
    #[error(
        "maximum {axis} rate {value} rad/s is not finite and positive: set `RateLimits::max` to \
         the model's body-rate bounds (default 20, 20, 6 rad/s)"
    )]
    RateLimit {
        /// The axis: `"roll (x)"`, `"pitch (y)"` or `"yaw (z)"`.
        axis: &'static str,
        /// The offending limit, rad/s.
        value: f64,
    },
}

/// The map from the models' mass-normalized collective acceleration `c` (m/s^2) to PX4's
/// normalized collective thrust: `thrust = hover_thrust * c / g` (see the
/// [module documentation](self) for the calibration).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThrustMap {
    /// The normalized thrust that holds the vehicle in a hover, in `(0, 1)`.
    pub hover_thrust: f64,
    /// Gravity, m/s^2: the collective acceleration of a hover.
    pub g: f64,
}

impl Default for ThrustMap {
    /// PX4's default `MPC_THR_HOVER` (0.5) and `g = 9.81` m/s^2.
    fn default() -> Self {
        Self {
            hover_thrust: 0.5,
            g: 9.81,
        }
    }
}

impl ThrustMap {
    /// Checks that `hover_thrust` is in `(0, 1)` and `g` is finite and positive.
    ///
    /// # Errors
    ///
    /// [`SetpointError::HoverThrust`] or [`SetpointError::Gravity`], saying what to fix.
    pub fn validate(&self) -> Result<(), SetpointError> {
        if !(self.hover_thrust > 0.0 && self.hover_thrust < 1.0) {
            return Err(SetpointError::HoverThrust(self.hover_thrust));
        }
        if !(self.g.is_finite() && self.g > 0.0) {
            return Err(SetpointError::Gravity(self.g));
        }
        Ok(())
    }

    /// The normalized thrust of collective acceleration `c` (m/s^2), not clamped:
    /// `hover_thrust * c / g`.
    #[must_use]
    pub fn thrust(&self, c: f64) -> f64 {
        self.hover_thrust * c / self.g
    }

    /// The collective acceleration (m/s^2) of a normalized thrust, the inverse of
    /// [`ThrustMap::thrust`]: `thrust * g / hover_thrust`.
    #[must_use]
    pub fn acceleration(&self, thrust: f64) -> f64 {
        thrust * self.g / self.hover_thrust
    }
}

/// Per-axis body-rate bounds, rad/s (roll, pitch, yaw; the same in FRD and FLU).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateLimits {
    /// The largest magnitude of each body rate, rad/s.
    pub max: Vector3<f64>,
}

impl Default for RateLimits {
    /// The models' bounds: 20, 20 and 6 rad/s.
    fn default() -> Self {
        Self {
            max: Vector3::new(20.0, 20.0, 6.0),
        }
    }
}

impl RateLimits {
    /// Checks that every limit is finite and positive.
    ///
    /// # Errors
    ///
    /// [`SetpointError::RateLimit`] for the first bad axis.
    pub fn validate(&self) -> Result<(), SetpointError> {
        for (axis, value) in [
            ("roll (x)", self.max.x),
            ("pitch (y)", self.max.y),
            ("yaw (z)", self.max.z),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(SetpointError::RateLimit { axis, value });
            }
        }
        Ok(())
    }
}

/// What goes into SET_ATTITUDE_TARGET (`type_mask = 128`): body rates and normalized thrust.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Px4Setpoint {
    /// Body rates in FRD (roll, pitch, yaw), rad/s.
    pub rates_frd: [f32; 3],
    /// Normalized collective thrust in `[0, 1]`.
    pub thrust: f32,
}

impl Px4Setpoint {
    /// Zero rates and the hover thrust of `map` (clamped to `[0, 1]`; PX4's default 0.5 when
    /// `hover_thrust` is not finite).
    #[must_use]
    pub fn hover(map: &ThrustMap) -> Self {
        let hover = if map.hover_thrust.is_finite() {
            map.hover_thrust
        } else {
            ThrustMap::default().hover_thrust
        };
        Self {
            rates_frd: [0.0; 3],
            thrust: clamp(hover as f32, 0.0, 1.0).0,
        }
    }

    fn is_finite(&self) -> bool {
        self.thrust.is_finite() && self.rates_frd.iter().all(|r| r.is_finite())
    }
}

/// The result of [`make_setpoint`]: the setpoint to send and what was done to get it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sanitized {
    /// The setpoint to send: always finite, rates within the limits, thrust in `[0, 1]`.
    pub setpoint: Px4Setpoint,
    /// The input (or its thrust mapping) was not finite: the previous setpoint or a hover was
    /// sent instead.
    pub replaced_non_finite: bool,
    /// At least one value was out of range and was clamped.
    pub clamped: bool,
}

/// `x` limited to `[lo, hi]` (with `lo <= hi`, both non-NaN), and whether it was changed.
/// A NaN `x` becomes `lo`.
fn clamp<T: PartialOrd + Copy>(x: T, lo: T, hi: T) -> (T, bool) {
    if x > hi {
        (hi, true)
    } else if x >= lo {
        (x, false)
    } else {
        (lo, true)
    }
}

/// A usable bound from a rate limit: the limit if finite and positive, capped at `f32::MAX`
/// (so that it survives the cast); `f32::MAX` for `+inf`; 0 otherwise (NaN, zero, negative).
fn rate_bound(max: f64) -> f64 {
    if max > 0.0 {
        max.min(f64::from(f32::MAX))
    } else {
        0.0
    }
}

/// The setpoint for the models' collective acceleration `c` (m/s^2) and body rates in FLU
/// (rad/s): rates converted to FRD, thrust mapped with `map`, made safe.
///
/// A non-finite input (any component) gives `previous` if there is one (and it is finite),
/// else [`Px4Setpoint::hover`]. Out-of-range values are clamped, rates to `+-limits.max` per
/// axis, thrust to `[0, 1]`, both in `f64` and again after the cast to `f32`. The result is
/// always finite and in range (see the [module documentation](self) for invalid parameters);
/// for finite in-range inputs it is the exact mapping rounded to `f32`.
#[must_use]
pub fn make_setpoint(
    c: f64,
    rates_flu: &Vector3<f64>,
    map: &ThrustMap,
    limits: &RateLimits,
    previous: Option<&Px4Setpoint>,
) -> Sanitized {
    let bounds = [
        rate_bound(limits.max.x),
        rate_bound(limits.max.y),
        rate_bound(limits.max.z),
    ];
    let mut clamped = false;

    let input_finite = c.is_finite() && rates_flu.iter().all(|r| r.is_finite());
    let thrust = map.thrust(c);
    let raw = if input_finite && !thrust.is_nan() {
        let frd = flu_to_frd(rates_flu);
        let mut rates = [0.0_f32; 3];
        for ((out, value), bound) in rates.iter_mut().zip([frd.x, frd.y, frd.z]).zip(bounds) {
            let (r, hit) = clamp(value, -bound, bound);
            clamped |= hit;
            *out = r as f32;
        }
        // thrust may be +-inf (finite c, tiny g): clamping handles it.
        let (t, hit) = clamp(thrust, 0.0, 1.0);
        clamped |= hit;
        Some(Px4Setpoint {
            rates_frd: rates,
            thrust: t as f32,
        })
    } else {
        None
    };
    let replaced_non_finite = raw.is_none();
    let candidate = raw.unwrap_or_else(|| match previous {
        Some(p) if p.is_finite() => *p,
        _ => Px4Setpoint::hover(map),
    });

    // The f32 pass: the bounds as sent, applied to the cast values and to the fallback.
    let mut setpoint = candidate;
    for (r, bound) in setpoint.rates_frd.iter_mut().zip(bounds) {
        let b = bound as f32;
        let (v, hit) = clamp(*r, -b, b);
        clamped |= hit;
        *r = v;
    }
    let (t, hit) = clamp(setpoint.thrust, 0.0, 1.0);
    clamped |= hit;
    setpoint.thrust = t;

    Sanitized {
        setpoint,
        replaced_non_finite,
        clamped,
    }
}
