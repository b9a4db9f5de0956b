//! The PX4-like body-rate loop and mixer.
//!
//! Frames and rotor numbering are those of [`crate::plant`] (body FLU; rotors front-right,
//! rear-left, front-left, rear-right).
//!
//! # Rate law
//!
//! With `e = rate_sp - w_meas` and the controller's *nominal* inertia `J` (diagonal):
//!
//! ```text
//! tau = J . (kp . e + I - kd . d(w_meas)/dt) + kff . J . d(rate_sp)/dt + w_meas x J w_meas
//! I' = ki . e . max(0, 1 - (e / I_ERROR_SCALE)^2),   |I| <= i_limit  (per axis, rad/s^2)
//! ```
//!
//! `.` is the component-wise product. The integrator `I` is frozen on the roll/pitch axes
//! while the mixer had to scale roll/pitch down, and on the yaw axis while it reduced yaw
//! (anti-windup). Derivatives are backward differences (zero on the first update after
//! [`RateController::reset`]).
//!
//! # Mixer
//!
//! [`mix`] solves `A f = [T, tau]` ([`allocation_matrix`]) and, if a rotor thrust leaves
//! `[f_min, f_max]`, applies PX4 airmode priorities: roll/pitch first (scaled down only if
//! their spread alone does not fit), then the collective thrust (all four rotors shifted
//! equally, up or down, as little as possible), then yaw (scaled down to what fits).
//! Rotor thrusts become speed commands through the nominal thrust curve,
//! `omega = sqrt(f / k_thrust)`.

use crate::plant::QuadParams;
use nalgebra::{Matrix4, Vector3, Vector4};

/// Rate error (rad/s, 400 deg/s as in PX4) beyond which the integrator stops; below it the
/// integration rate is scaled by `1 - (e / I_ERROR_SCALE)^2`, which keeps flips from
/// winding the integrator up.
pub const I_ERROR_SCALE: f64 = 400.0 * std::f64::consts::PI / 180.0;

/// Gains of the rate loop, per body axis (x, y, z). Units are such that the terms are
/// angular accelerations (multiplied by the nominal inertia to give torques).
#[derive(Clone, Debug, PartialEq)]
pub struct RateGains {
    /// Proportional gain on the rate error, 1/s.
    pub kp: Vector3<f64>,
    /// Integral gain on the rate error, 1/s^2.
    pub ki: Vector3<f64>,
    /// Derivative gain on the measured rate (not the error), dimensionless.
    pub kd: Vector3<f64>,
    /// Feed-forward gain on the derivative of the rate setpoint, dimensionless
    /// (1 = the nominal inertia times the setpoint's angular acceleration).
    pub kff: Vector3<f64>,
    /// Bound on the integral term `I` (an angular acceleration), rad/s^2.
    pub i_limit: Vector3<f64>,
}

impl Default for RateGains {
    /// Tuned on the plant with [`QuadParams::default`] (rotor time constant 0.03 s), at 1 kHz
    /// and 250 Hz: `kp` (35, 35, 12) 1/s, `ki` (60, 60, 20) 1/s^2, `kd` (0.8, 0.8, 0),
    /// `kff` (0, 0, 0), `i_limit` (40, 40, 20) rad/s^2 (0.24 N m on roll/pitch).
    ///
    /// A 5*pi rad/s pitch-rate step reaches 90 % in about 0.10 s with about 1.5 %
    /// overshoot, at hover thrust and at 0.3 of it (airmode); with the inertia 30 % off and
    /// the rotor time constant 50 % off it still reaches 90 % within 0.12 s, overshoot
    /// below 6 %.
    fn default() -> Self {
        Self {
            kp: Vector3::new(35.0, 35.0, 12.0),
            ki: Vector3::new(60.0, 60.0, 20.0),
            kd: Vector3::new(0.8, 0.8, 0.0),
            kff: Vector3::zeros(),
            i_limit: Vector3::new(40.0, 40.0, 20.0),
        }
    }
}

/// PX4's default multicopter rate-controller parameters (mc_rate_control): the P, I and D
/// gains (MC_ROLLRATE_P/I/D = MC_PITCHRATE_P/I/D, MC_YAWRATE_P/I/D) and the integrator limits
/// (MC_RR_INT_LIM, MC_PR_INT_LIM, MC_YR_INT_LIM), on PX4's normalized torque, roll, pitch,
/// yaw.
pub const PX4_RATE_P: [f64; 3] = [0.15, 0.15, 0.2];
/// See [`PX4_RATE_P`].
pub const PX4_RATE_I: [f64; 3] = [0.2, 0.2, 0.1];
/// See [`PX4_RATE_P`].
pub const PX4_RATE_D: [f64; 3] = [0.003, 0.003, 0.0];
/// See [`PX4_RATE_P`].
pub const PX4_RATE_INT_LIM: [f64; 3] = [0.3, 0.3, 0.3];

/// The torque (N m) a unit normalized torque command of PX4's rate controller gives on
/// vehicle `params` (a quad X), per axis: PX4's control allocation normalizes the roll and
/// pitch columns of its mixer to `1/sqrt(2)` of a rotor's thrust range per rotor, and the
/// yaw column to its largest entry, 1; so roll and pitch give
/// `4 * T_max / sqrt(2) * arm / sqrt(2) = 2 T_max arm` and yaw `4 k_torque T_max`.
pub fn px4_torque_per_command(params: &QuadParams) -> Vector3<f64> {
    let t_max = params.rotor_thrust_max();
    let rp = 2.0 * t_max * params.arm;
    Vector3::new(rp, rp, 4.0 * params.k_torque * t_max)
}

impl RateGains {
    /// PX4's default rate gains ([`PX4_RATE_P`], ...) on vehicle `params`, in this loop's
    /// units: PX4 commands a normalized torque `P e + I + D d(w)/dt`; times
    /// [`px4_torque_per_command`] over the inertia, that is `kp`, `ki`, `kd` and `i_limit`
    /// here. No feed-forward (MC_*RATE_FF 0). On PX4's SIH quadrotor
    /// ([`QuadParams::px4_sih`]): `kp` (17.0, 17.0, 2.67) 1/s, saturating the rotors beyond
    /// about 4.7 rad/s of roll or pitch-rate error.
    pub fn px4_default(params: &QuadParams) -> Self {
        let k = px4_torque_per_command(params).component_div(&params.inertia);
        let scale = |g: [f64; 3]| Vector3::from(g).component_mul(&k);
        Self {
            kp: scale(PX4_RATE_P),
            ki: scale(PX4_RATE_I),
            kd: scale(PX4_RATE_D),
            kff: Vector3::zeros(),
            i_limit: scale(PX4_RATE_INT_LIM),
        }
    }
}

/// Output of one rate-loop update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateOutput {
    /// Demanded body torque, N m (before the mixer's saturation handling).
    pub torque_sp: Vector3<f64>,
    /// Per-rotor thrust setpoints after the mixer, N.
    pub rotor_thrust_sp: [f64; 4],
    /// Rotor speed commands, rad/s, for [`crate::plant::Plant::step`].
    pub rotor_cmd: [f64; 4],
    /// Whether the mixer could not deliver the demand exactly (see [`MixResult`]).
    pub saturated: bool,
}

/// Detailed result of [`mix_detailed`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MixResult {
    /// Per-rotor thrusts, N, within `[f_min, f_max]`.
    pub thrusts: [f64; 4],
    /// What those thrusts deliver: `[T, tau_x, tau_y, tau_z] = A f`.
    pub achieved: Vector4<f64>,
    /// Roll/pitch torque was scaled down.
    pub roll_pitch_saturated: bool,
    /// The collective thrust was shifted (airmode).
    pub thrust_saturated: bool,
    /// Yaw torque was reduced.
    pub yaw_saturated: bool,
}

impl MixResult {
    /// Whether any part of the demand was not met.
    pub fn saturated(&self) -> bool {
        self.roll_pitch_saturated || self.thrust_saturated || self.yaw_saturated
    }
}

/// The allocation matrix `A`: `[T, tau_x, tau_y, tau_z] = A f` for rotor thrusts `f`
/// (columns in rotor order). Row 0 is all ones, rows 1 and 2 are `r_i x e_z` (`y_i` and
/// `-x_i`), row 3 is `spin_i * k_torque`.
pub fn allocation_matrix(params: &QuadParams) -> Matrix4<f64> {
    let pos = params.rotor_positions();
    let spin = params.rotor_spin();
    let mut a = Matrix4::zeros();
    for (i, (r, s)) in pos.iter().zip(spin.iter()).enumerate() {
        a[(0, i)] = 1.0;
        a[(1, i)] = r.y;
        a[(2, i)] = -r.x;
        a[(3, i)] = s * params.k_torque;
    }
    a
}

/// Per-rotor thrusts for collective thrust `thrust` (N) and body torque `torque` (N m),
/// with airmode saturation priorities; returns the thrusts and whether the demand was
/// not met exactly. See [`mix_detailed`].
pub fn mix(params: &QuadParams, thrust: f64, torque: &Vector3<f64>) -> ([f64; 4], bool) {
    let r = mix_detailed(params, thrust, torque);
    (r.thrusts, r.saturated())
}

/// [`mix`] with the detail of which priorities were applied.
///
/// Never panics; a singular allocation or non-finite demand gives thrusts at `f_min` and
/// all saturation flags set.
pub fn mix_detailed(params: &QuadParams, thrust: f64, torque: &Vector3<f64>) -> MixResult {
    let f_min = params.rotor_thrust_min();
    let f_max = params.rotor_thrust_max().max(f_min);
    let a = allocation_matrix(params);
    let fail = MixResult {
        thrusts: [f_min; 4],
        achieved: a * Vector4::repeat(f_min),
        roll_pitch_saturated: true,
        thrust_saturated: true,
        yaw_saturated: true,
    };
    let demand_finite = thrust.is_finite() && torque.iter().all(|x| x.is_finite());
    let Some(b) = a.try_inverse() else {
        return fail;
    };
    if !demand_finite {
        return fail;
    }
    let c_t: Vector4<f64> = b.column(0).into_owned();
    let c_rp: Vector4<f64> = b.column(1) * torque.x + b.column(2) * torque.y;
    let c_yaw: Vector4<f64> = b.column(3) * torque.z;
    let range = f_max - f_min;
    let eps = 1e-9 * f_max.max(1.0);

    // 1. Roll/pitch: scale down only if their spread alone does not fit.
    let spread = c_rp.max() - c_rp.min();
    let mut rp_sat = false;
    let u_rp = if spread > range + eps {
        rp_sat = true;
        c_rp * (range / spread)
    } else {
        c_rp
    };

    // 2. Collective: shift along c_t as little as possible to fit roll/pitch.
    let f0 = c_t * thrust + u_rp;
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for i in 0..4 {
        let c = c_t[i];
        if c.abs() < 1e-12 {
            continue;
        }
        let (d1, d2) = ((f_min - f0[i]) / c, (f_max - f0[i]) / c);
        lo = lo.max(d1.min(d2));
        hi = hi.min(d1.max(d2));
    }
    let delta = if lo > hi {
        0.5 * (lo + hi)
    } else {
        0.0_f64.clamp(lo, hi)
    };
    let delta = if delta.is_finite() { delta } else { 0.0 };
    let thrust_sat = delta.abs() > eps;
    let f1 = f0 + c_t * delta;

    // 3. Yaw: the largest fraction in [0, 1] that fits.
    let mut s_yaw: f64 = 1.0;
    for i in 0..4 {
        let c = c_yaw[i];
        if c > 1e-12 {
            s_yaw = s_yaw.min((f_max - f1[i]) / c);
        } else if c < -1e-12 {
            s_yaw = s_yaw.min((f_min - f1[i]) / c);
        }
    }
    let s_yaw = s_yaw.clamp(0.0, 1.0);
    let yaw_sat = s_yaw < 1.0 - 1e-9;
    let f = f1 + c_yaw * s_yaw;

    let thrusts = [
        f[0].clamp(f_min, f_max),
        f[1].clamp(f_min, f_max),
        f[2].clamp(f_min, f_max),
        f[3].clamp(f_min, f_max),
    ];
    MixResult {
        thrusts,
        achieved: a * Vector4::from(thrusts),
        roll_pitch_saturated: rp_sat,
        thrust_saturated: thrust_sat,
        yaw_saturated: yaw_sat,
    }
}

/// Rotor speed command for thrust `f` through the nominal thrust curve, clamped to
/// `[omega_min, omega_max]`.
pub fn thrust_to_speed(params: &QuadParams, f: f64) -> f64 {
    let lo = params.omega_min;
    let hi = params.omega_max.max(lo);
    if params.k_thrust.is_nan() || params.k_thrust <= 0.0 || !f.is_finite() {
        return lo;
    }
    (f.max(0.0) / params.k_thrust).sqrt().clamp(lo, hi)
}

/// The PX4-like body-rate controller with its mixer.
#[derive(Clone, Debug)]
pub struct RateController {
    nominal: QuadParams,
    /// The gains (may be changed between updates).
    pub gains: RateGains,
    integral: Vector3<f64>,
    prev_meas: Option<Vector3<f64>>,
    prev_sp: Option<Vector3<f64>>,
    last_mix: Option<MixResult>,
}

impl RateController {
    /// A controller that believes the vehicle is `nominal` (mass, inertia, geometry, thrust
    /// curve); the true plant may differ.
    pub fn new(nominal: &QuadParams, gains: RateGains) -> Self {
        Self {
            nominal: nominal.clone(),
            gains,
            integral: Vector3::zeros(),
            prev_meas: None,
            prev_sp: None,
            last_mix: None,
        }
    }

    /// The nominal parameters the controller uses.
    pub fn nominal(&self) -> &QuadParams {
        &self.nominal
    }

    /// Current integral term (angular acceleration), rad/s^2.
    pub fn integral(&self) -> Vector3<f64> {
        self.integral
    }

    /// The detailed mixer result of the last update.
    pub fn last_mix(&self) -> Option<MixResult> {
        self.last_mix
    }

    /// Clears the integrator and the derivative memories.
    pub fn reset(&mut self) {
        self.integral = Vector3::zeros();
        self.prev_meas = None;
        self.prev_sp = None;
        self.last_mix = None;
    }

    /// One update: body-rate setpoint `rate_sp` (rad/s), collective thrust setpoint
    /// `thrust_sp` (N), measured body rate `rate_meas` (rad/s), time since the last
    /// update `dt` (s). A non-positive or non-finite `dt` skips the integrator and the
    /// derivative terms.
    pub fn update(
        &mut self,
        rate_sp: &Vector3<f64>,
        thrust_sp: f64,
        rate_meas: &Vector3<f64>,
        dt: f64,
    ) -> RateOutput {
        let g = &self.gains;
        let j = self.nominal.inertia;
        let dt_ok = dt.is_finite() && dt > 0.0;
        let e = rate_sp - rate_meas;

        // Integrator with anti-windup (frozen on axes the mixer saturated last time).
        if dt_ok && e.iter().all(|x| x.is_finite()) {
            let (rp_sat, yaw_sat) = self.last_mix.map_or((false, false), |m| {
                (m.roll_pitch_saturated, m.yaw_saturated)
            });
            // PX4: integrate less at large rate errors (zero beyond I_ERROR_SCALE).
            let factor = e.map(|x| (1.0 - (x / I_ERROR_SCALE).powi(2)).max(0.0));
            let mut inc = g.ki.component_mul(&e).component_mul(&factor) * dt;
            if rp_sat {
                inc.x = 0.0;
                inc.y = 0.0;
            }
            if yaw_sat {
                inc.z = 0.0;
            }
            let lim = g.i_limit.abs();
            self.integral = (self.integral + inc).zip_map(&lim, |x, l| x.clamp(-l, l));
        }

        let d_meas = match (self.prev_meas, dt_ok) {
            (Some(p), true) => (rate_meas - p) / dt,
            _ => Vector3::zeros(),
        };
        let d_sp = match (self.prev_sp, dt_ok) {
            (Some(p), true) => (rate_sp - p) / dt,
            _ => Vector3::zeros(),
        };
        self.prev_meas = Some(*rate_meas);
        self.prev_sp = Some(*rate_sp);

        let acc = g.kp.component_mul(&e) + self.integral - g.kd.component_mul(&d_meas);
        let torque_sp = j.component_mul(&acc)
            + g.kff.component_mul(&j).component_mul(&d_sp)
            + rate_meas.cross(&j.component_mul(rate_meas));

        let m = mix_detailed(&self.nominal, thrust_sp, &torque_sp);
        self.last_mix = Some(m);
        let rotor_cmd = m.thrusts.map(|f| thrust_to_speed(&self.nominal, f));
        RateOutput {
            torque_sp,
            rotor_thrust_sp: m.thrusts,
            rotor_cmd,
            saturated: m.saturated(),
        }
    }
}
