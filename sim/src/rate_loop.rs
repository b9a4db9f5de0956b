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
//!
//! With [`Airmode::Disabled`] the mixer is PX4's default instead (MC_AIRMODE 0,
//! [`mix_airmode_disabled`]): the collective is never raised to make room for a torque, so
//! roll and pitch are cut where they do not fit. With a [`GyroFilter`] the controller sees
//! the measured rate as PX4's rate controller does: low-pass filtered, its derivative taken
//! of the filtered rate and filtered again.

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

/// How the mixer gives up a demand the rotors cannot deliver (PX4's MC_AIRMODE).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Airmode {
    /// This loop's own mixer ([`mix_detailed`]): roll/pitch first, the collective shifted up
    /// or down as needed to fit them, then yaw (like PX4's MC_AIRMODE 1).
    #[default]
    RollPitch,
    /// PX4's default, MC_AIRMODE 0 ([`mix_airmode_disabled`]): the collective may only be
    /// lowered; roll and pitch are cut to what fits.
    Disabled,
}

/// PX4's gyro filtering ahead of its rate controller (sensors' `VehicleAngularVelocity`):
/// at the gyro's rate, a second-order Butterworth low-pass on the rate (IMU_GYRO_CUTOFF);
/// the angular acceleration of the D term is the difference of the filtered rate over the
/// sample interval, low-pass filtered again (IMU_DGYRO_CUTOFF). The rate controller runs on
/// every gyro sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroFilter {
    /// Gyro (and rate-loop) rate, Hz.
    pub sample_rate: f64,
    /// Cutoff of the rate's low-pass, Hz (IMU_GYRO_CUTOFF).
    pub rate_cutoff: f64,
    /// Cutoff of the angular acceleration's low-pass, Hz (IMU_DGYRO_CUTOFF).
    pub accel_cutoff: f64,
}

impl GyroFilter {
    /// PX4 SITL with SIH: the gyro at 250 Hz (SIH steps at the lesser of IMU_GYRO_RATEMAX
    /// and IMU_INTEG_RATE, 800 and 250 Hz), IMU_GYRO_CUTOFF 40 Hz, IMU_DGYRO_CUTOFF 30 Hz.
    pub fn px4_sih() -> Self {
        Self {
            sample_rate: 250.0,
            rate_cutoff: 40.0,
            accel_cutoff: 30.0,
        }
    }

    /// The sample interval, s.
    pub fn period(&self) -> f64 {
        1.0 / self.sample_rate
    }
}

/// PX4's `LowPassFilter2p`: a second-order Butterworth low-pass (bilinear transform), per
/// axis; a cutoff not below half the sample rate, or not positive, passes the signal.
#[derive(Clone, Debug)]
struct LowPass2p {
    b: [f64; 3],
    a: [f64; 2],
    delay: [Vector3<f64>; 2],
}

impl LowPass2p {
    fn new(sample_rate: f64, cutoff: f64) -> Self {
        if !(cutoff > 0.0 && cutoff < 0.5 * sample_rate) {
            return Self {
                b: [1.0, 0.0, 0.0],
                a: [0.0, 0.0],
                delay: [Vector3::zeros(); 2],
            };
        }
        let ohm = (std::f64::consts::PI * cutoff / sample_rate).tan();
        let k = 2.0 * std::f64::consts::FRAC_PI_4.cos() * ohm;
        let c = 1.0 + k + ohm * ohm;
        let b0 = ohm * ohm / c;
        Self {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (ohm * ohm - 1.0) / c, (1.0 - k + ohm * ohm) / c],
            delay: [Vector3::zeros(); 2],
        }
    }

    /// Settles the filter at `x` (its output is `x` from now on while the input stays).
    fn reset(&mut self, x: &Vector3<f64>) {
        let d = x / (self.b[0] + self.b[1] + self.b[2]);
        self.delay = [d, d];
    }

    fn apply(&mut self, x: &Vector3<f64>) -> Vector3<f64> {
        let d0 = x - self.delay[0] * self.a[0] - self.delay[1] * self.a[1];
        let y = d0 * self.b[0] + self.delay[0] * self.b[1] + self.delay[1] * self.b[2];
        self.delay = [d0, self.delay[0]];
        y
    }
}

/// The state of a [`GyroFilter`].
#[derive(Clone, Debug)]
struct GyroFilterState {
    rate: LowPass2p,
    accel: LowPass2p,
    /// The last filtered rate; `None` until the first sample after a reset.
    prev: Option<Vector3<f64>>,
}

impl GyroFilterState {
    fn new(f: &GyroFilter) -> Self {
        Self {
            rate: LowPass2p::new(f.sample_rate, f.rate_cutoff),
            accel: LowPass2p::new(f.sample_rate, f.accel_cutoff),
            prev: None,
        }
    }

    /// The filtered rate and angular acceleration for gyro sample `w`, `dt` after the last
    /// (the first sample after a reset settles the filters at `w` and zero acceleration).
    fn apply(&mut self, w: &Vector3<f64>, dt: f64) -> (Vector3<f64>, Vector3<f64>) {
        let Some(prev) = self.prev else {
            self.rate.reset(w);
            self.accel.reset(&Vector3::zeros());
            self.prev = Some(*w);
            return (*w, Vector3::zeros());
        };
        let rate = self.rate.apply(w);
        let raw = if dt.is_finite() && dt > 0.0 {
            (rate - prev) / dt
        } else {
            Vector3::zeros()
        };
        self.prev = Some(rate);
        (rate, self.accel.apply(&raw))
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

/// Per-rotor thrusts for collective thrust `thrust` (N) and body torque `torque` (N m) as
/// PX4's control allocator with its default MC_AIRMODE 0 (`ControlAllocationSequentialDesaturation::
/// mixAirmodeDisabled`), in newtons instead of PX4's normalized commands:
///
/// 1. mix thrust, roll and pitch; desaturate along the thrust direction, lowering it only;
/// 2. desaturate along the roll direction, then along the pitch direction;
/// 3. add yaw; desaturate along yaw with the upper bound 15 % of the range higher; lower the
///    thrust again if needed; clip to `[f_min, f_max]`.
///
/// Each desaturation moves the thrusts along its direction `v` by `k_min + k_max` (the most
/// negative and most positive of the moves that would bring each rotor out of its bounds back
/// to the bound), then by half of that again; PX4 skips rotors whose entry of `v` is below
/// 0.2 (never on a quad X: all entries of a direction have the same size). The flags tell
/// which parts of the demand the clipped thrusts do not deliver.
///
/// Never panics; a singular allocation or non-finite demand gives thrusts at `f_min` and
/// all saturation flags set.
pub fn mix_airmode_disabled(params: &QuadParams, thrust: f64, torque: &Vector3<f64>) -> MixResult {
    let f_min = params.rotor_thrust_min();
    let f_max = params.rotor_thrust_max().max(f_min);
    let a = allocation_matrix(params);
    let demand_finite = thrust.is_finite() && torque.iter().all(|x| x.is_finite());
    let (Some(b), true) = (a.try_inverse(), demand_finite) else {
        return MixResult {
            thrusts: [f_min; 4],
            achieved: a * Vector4::repeat(f_min),
            roll_pitch_saturated: true,
            thrust_saturated: true,
            yaw_saturated: true,
        };
    };
    let col = |i: usize| -> Vector4<f64> { b.column(i).into_owned() };
    let (c_t, c_roll, c_pitch, c_yaw) = (col(0), col(1), col(2), col(3));
    let bounds = (f_min, f_max);
    let mut f = c_t * thrust + c_roll * torque.x + c_pitch * torque.y;
    desaturate(&mut f, &-c_t, bounds, true);
    desaturate(&mut f, &c_roll, bounds, false);
    desaturate(&mut f, &c_pitch, bounds, false);
    f += c_yaw * torque.z;
    desaturate(
        &mut f,
        &c_yaw,
        (f_min, f_max + 0.15 * (f_max - f_min)),
        false,
    );
    desaturate(&mut f, &-c_t, bounds, true);
    let thrusts = f.map(|x| x.clamp(f_min, f_max));
    let achieved = a * thrusts;
    let eps = 1e-9 * f_max.max(1.0);
    MixResult {
        thrusts: [thrusts[0], thrusts[1], thrusts[2], thrusts[3]],
        achieved,
        roll_pitch_saturated: (achieved.fixed_rows::<2>(1) - torque.xy()).amax() > eps,
        thrust_saturated: (achieved[0] - thrust).abs() > eps,
        yaw_saturated: (achieved[3] - torque.z).abs() > eps,
    }
}

/// PX4's `desaturateActuators`: moves `f` along `v` by [`desaturation_gain`], then by half
/// the gain left; with `increase_only`, not at all if the first gain is negative.
fn desaturate(f: &mut Vector4<f64>, v: &Vector4<f64>, bounds: (f64, f64), increase_only: bool) {
    let gain = desaturation_gain(f, v, bounds);
    if increase_only && gain < 0.0 {
        return;
    }
    *f += v * gain;
    let gain = 0.5 * desaturation_gain(f, v, bounds);
    *f += v * gain;
}

/// PX4's `computeDesaturationGain`: of the moves along `v` that would bring each rotor
/// outside `bounds` back to its bound, the most negative (or 0) plus the most positive (or
/// 0); rotors whose entry of `v` is below 0.2 of the largest are skipped.
fn desaturation_gain(f: &Vector4<f64>, v: &Vector4<f64>, (lo, hi): (f64, f64)) -> f64 {
    let floor = 0.2 * v.amax();
    let (mut k_min, mut k_max) = (0.0_f64, 0.0_f64);
    for (x, d) in f.iter().zip(v.iter()) {
        if d.abs() < floor || d.abs() < 1e-12 {
            continue;
        }
        let bound = if *x < lo {
            lo
        } else if *x > hi {
            hi
        } else {
            continue;
        };
        let k = (bound - x) / d;
        k_min = k_min.min(k);
        k_max = k_max.max(k);
    }
    k_min + k_max
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
    airmode: Airmode,
    gyro_filter: Option<(GyroFilter, GyroFilterState)>,
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
            airmode: Airmode::default(),
            gyro_filter: None,
        }
    }

    /// This controller with mixer `airmode`.
    pub fn with_airmode(self, airmode: Airmode) -> Self {
        Self { airmode, ..self }
    }

    /// This controller on a gyro filtered as PX4's (`None`: the rate as measured, its
    /// derivative the backward difference). Call [`RateController::update`] at the filter's
    /// sample rate.
    pub fn with_gyro_filter(self, filter: Option<GyroFilter>) -> Self {
        Self {
            gyro_filter: filter.map(|f| (f, GyroFilterState::new(&f))),
            ..self
        }
    }

    /// The mixer's airmode.
    pub fn airmode(&self) -> Airmode {
        self.airmode
    }

    /// The gyro filter, if any.
    pub fn gyro_filter(&self) -> Option<GyroFilter> {
        self.gyro_filter.as_ref().map(|(f, _)| *f)
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

    /// Clears the integrator, the derivative memories and the gyro filter.
    pub fn reset(&mut self) {
        self.integral = Vector3::zeros();
        self.prev_meas = None;
        self.prev_sp = None;
        self.last_mix = None;
        if let Some((f, state)) = self.gyro_filter.as_mut() {
            *state = GyroFilterState::new(f);
        }
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
        let dt_ok = dt.is_finite() && dt > 0.0;
        let filtered = self
            .gyro_filter
            .as_mut()
            .map(|(_, s)| s.apply(rate_meas, dt));
        let (rate_meas, d_filtered) = match &filtered {
            Some((w, d)) => (w, Some(*d)),
            None => (rate_meas, None),
        };
        let g = &self.gains;
        let j = self.nominal.inertia;
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

        let d_meas = match (d_filtered, self.prev_meas, dt_ok) {
            (Some(d), _, _) => d,
            (None, Some(p), true) => (rate_meas - p) / dt,
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

        let m = match self.airmode {
            Airmode::RollPitch => mix_detailed(&self.nominal, thrust_sp, &torque_sp),
            Airmode::Disabled => mix_airmode_disabled(&self.nominal, thrust_sp, &torque_sp),
        };
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
