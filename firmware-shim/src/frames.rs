//! Frame conversions between PX4 (world NED, body FRD) and the models (world ENU, body FLU).
//!
//! # Conventions
//!
//! | frame | used by          | x       | y     | z    |
//! |-------|------------------|---------|-------|------|
//! | NED   | PX4 world        | north   | east  | down |
//! | FRD   | PX4 body         | forward | right | down |
//! | ENU   | models' world    | east    | north | up   |
//! | FLU   | models' body     | forward | left  | up   |
//!
//! | quantity     | PX4 -> model                | model -> PX4                | map            |
//! |--------------|-----------------------------|-----------------------------|----------------|
//! | world vector | [`ned_to_enu`]              | [`enu_to_ned`]              | `(y, x, -z)`   |
//! | body vector  | [`frd_to_flu`]              | [`flu_to_frd`]              | `(x, -y, -z)`  |
//! | attitude     | [`quat_ned_frd_to_enu_flu`] | [`quat_enu_flu_to_ned_frd`] | see below      |
//! | MAVLink `q`  | [`quat_from_mavlink`]       | [`quat_to_mavlink`]         | `[w, x, y, z]` |
//!
//! World vectors are positions, velocities and accelerations in the world frame (PX4's
//! LOCAL_POSITION_NED, ODOMETRY with frame LOCAL_NED); body vectors are body rates (ODOMETRY
//! rollspeed/pitchspeed/yawspeed, the rates of SET_ATTITUDE_TARGET), body velocities and
//! accelerations.
//!
//! Both vector maps are their own inverses (a swap and a sign change, exact in floating point).
//!
//! Quaternions are Hamilton, scalar first, and rotate **body to world**:
//! `v_world = q * v_body`. This is the convention of PX4 (ATTITUDE_QUATERNION, ODOMETRY) and of
//! the simulator (`mpc-sim`).
//!
//! # Attitude
//!
//! ```text
//! q_enu_flu = Q(NED->ENU) * q_ned_frd * Q(FLU->FRD)
//! Q(NED->ENU) = rotation of pi about (1, 1, 0)/sqrt(2) = (0, 1/sqrt2, 1/sqrt2, 0)
//! Q(FLU->FRD) = rotation of pi about x                 = (0, -1, 0, 0)
//! ```
//!
//! Read right to left: a FLU body vector is first expressed in FRD (`Q(FLU->FRD)`, i.e.
//! `(x, -y, -z)`), rotated to NED by PX4's attitude, then expressed in ENU (`Q(NED->ENU)`, i.e.
//! `(y, x, -z)`). A rotation of pi is represented by `(0, n)` and by `(0, -n)`; the sign chosen
//! for `Q(FLU->FRD)` makes PX4's level, nose-north attitude (the NED identity) come out as
//! `(cos 45deg, 0, 0, sin 45deg)` (yaw +90 deg in ENU) with a positive scalar part. Written out,
//! with `s = 1/sqrt(2)` and `q = (w, x, y, z)`:
//!
//! ```text
//! q_enu_flu = s * (w + z, x + y, x - y, w - z)
//! ```
//!
//! This map is its own inverse, so [`quat_enu_flu_to_ned_frd`] is the same formula.
//!
//! In Euler angles (yaw-pitch-roll, `R = Rz(yaw) Ry(pitch) Rx(roll)` in both conventions):
//! `roll_enu = roll_ned`, `pitch_enu = -pitch_ned`, `yaw_enu = 90 deg - yaw_ned`. Heading north
//! (NED yaw 0) is ENU yaw +90 deg, heading east (NED yaw 90 deg) is ENU yaw 0. The roll rate
//! keeps its sign, the pitch and yaw rates change sign: a positive FRD pitch rate (nose up) is
//! a negative FLU pitch rate, since in FLU a positive rate about +y (left) tips the nose down.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Norm below which a MAVLink quaternion is rejected by [`quat_from_mavlink`].
///
/// A unit quaternion sent as `f32` has a norm of `1 +- 1e-7`; a norm this small is a zeroed or
/// uninitialized field, not an attitude.
pub const MIN_MAVLINK_QUAT_NORM: f64 = 1e-3;

/// A world vector from NED (x north, y east, z down) to ENU (x east, y north, z up):
/// `(y, x, -z)`.
#[must_use]
pub fn ned_to_enu(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.y, v.x, -v.z)
}

/// A world vector from ENU to NED: `(y, x, -z)` (the same map as [`ned_to_enu`]).
#[must_use]
pub fn enu_to_ned(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.y, v.x, -v.z)
}

/// A body vector (body rates, body velocity, acceleration) from FRD (x forward, y right,
/// z down) to FLU (x forward, y left, z up): `(x, -y, -z)`.
#[must_use]
pub fn frd_to_flu(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.x, -v.y, -v.z)
}

/// A body vector from FLU to FRD: `(x, -y, -z)` (the same map as [`frd_to_flu`]).
#[must_use]
pub fn flu_to_frd(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.x, -v.y, -v.z)
}

/// `s * (w + z, x + y, x - y, w - z)`: both attitude conversions (the map is an involution).
fn swap_attitude(q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    let s = core::f64::consts::FRAC_1_SQRT_2;
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    UnitQuaternion::new_normalize(Quaternion::new(
        s * (w + z),
        s * (x + y),
        s * (x - y),
        s * (w - z),
    ))
}

/// PX4's attitude (FRD body to NED world) as the models' attitude (FLU body to ENU world):
/// `Q(NED->ENU) * q * Q(FLU->FRD)` (see the [module documentation](self)).
///
/// The NED identity (level, nose north) becomes `(cos 45deg, 0, 0, sin 45deg)`, yaw +90 deg
/// in ENU; yaw 90 deg in NED (nose east) becomes the ENU identity.
#[must_use]
pub fn quat_ned_frd_to_enu_flu(q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    swap_attitude(q)
}

/// The models' attitude (FLU body to ENU world) as PX4's (FRD body to NED world):
/// `Q(NED->ENU)^-1 * q * Q(FLU->FRD)^-1`, the inverse of [`quat_ned_frd_to_enu_flu`] (and the
/// same formula).
#[must_use]
pub fn quat_enu_flu_to_ned_frd(q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    swap_attitude(q)
}

/// A quaternion from a MAVLink `q` field (`[w, x, y, z]`), normalized.
///
/// `None` when a component is not finite or the norm is below [`MIN_MAVLINK_QUAT_NORM`]. The
/// frame is unchanged (PX4 sends FRD body to NED world; convert with
/// [`quat_ned_frd_to_enu_flu`]).
#[must_use]
pub fn quat_from_mavlink(q: [f32; 4]) -> Option<UnitQuaternion<f64>> {
    let [w, x, y, z] = q.map(f64::from);
    if !(w.is_finite() && x.is_finite() && y.is_finite() && z.is_finite()) {
        return None;
    }
    UnitQuaternion::try_new(Quaternion::new(w, x, y, z), MIN_MAVLINK_QUAT_NORM)
}

/// A quaternion as a MAVLink `q` field (`[w, x, y, z]`, `f32`). The frame is unchanged (PX4
/// expects FRD body to NED world; convert with [`quat_enu_flu_to_ned_frd`]).
#[must_use]
pub fn quat_to_mavlink(q: &UnitQuaternion<f64>) -> [f32; 4] {
    [q.w as f32, q.i as f32, q.j as f32, q.k as f32]
}
