//! The simulated PX4 vehicle: the [`crate::commander::Commander`] around the simulator's plant
//! and PX4-like rate loop (`mpc-sim`), speaking MAVLink messages in PX4's frames; `mpcc sitl`
//! serves it on a link with [`serve`].
//!
//! * OFFBOARD: the last SET_ATTITUDE_TARGET flies it: FRD rates -> FLU, normalized thrust ->
//!   collective acceleration with the [`ThrustMap`] (the vehicle's hover thrust), through the
//!   rate loop (every 1 ms; the stock vehicle's as PX4's on SIH, at 250 Hz on the filtered
//!   gyro, see [`VehicleConfig::gyro_filter`]).
//! * POSCTL (hold), AUTO.LAND, AUTO.RTL: a PX4-like position controller (PD on position and
//!   velocity, tilt limited as MPC_TILTMAX_AIR) gives a thrust vector; the attitude it needs
//!   (the heading held from the moment the mode began) goes through PX4's quaternion attitude
//!   controller ([`attitude_control`], mc_att_control's `AttitudeControl` with PX4's default
//!   gains and rate limits, [`AttitudeGains`]) to body rates for the same rate loop. It holds
//!   the point where the mode began, descends at [`VehicleConfig::land_speed`], or flies
//!   home at the current height (at least 2 m above home) and lands there. The attitude law
//!   has no singularity: it recovers from any attitude, inverted included, turning the short
//!   way at PX4's maximum rates.
//! * Thrust in those modes: the thrust vector's component along the current body z axis,
//!   never negative. PX4 itself commands the full magnitude whatever the attitude; while the
//!   vehicle is inverted (a flip interrupted by RTL) that would push it towards the ground,
//!   so this vehicle idles the collective until the thrust axis points up again (the mixer
//!   keeps the torque, as PX4's airmode).
//! * Out: PX4's HEARTBEAT (1 Hz) and what PX4 streams on its onboard link, at PX4's default
//!   rates unless the companion changes them with MAV_CMD_SET_MESSAGE_INTERVAL
//!   ([`crate::commander`]): ODOMETRY (30 Hz, LOCAL_NED / LOCAL_NED), LOCAL_POSITION_NED (30 Hz),
//!   ATTITUDE_QUATERNION (50 Hz, NED -> FRD, FRD rates), EXTENDED_SYS_STATE (5 Hz, the
//!   land detector's verdict), and the commander's COMMAND_ACKs. The defaults are
//!   [`VehicleConfig`] fields. Answers: TIMESYNC (a request, `tc1` = 0, gets the vehicle's
//!   time in `tc1` and its `ts1` back, as PX4's `mavlink_timesync.cpp`) and
//!   PARAM_REQUEST_READ for the parameters of [`SimVehicle::parameters`].
//! * The clock: every timestamp (ODOMETRY's `time_usec`, the others' `time_boot_ms`,
//!   TIMESYNC's `tc1`) is the simulated time, shifted after a [`ClockJump`]; [`serve`] runs
//!   the simulation at [`VehicleConfig::clock_rate`] simulated seconds per wall-clock second
//!   (PX4's SIH in lockstep ran 1.0-1.5 % slow: default 0.988). PX4's own timeouts (offboard
//!   loss, land detector, auto-disarm) run on the simulated time, as in PX4.
//! * The estimate: the estimator's noise and latency, plus EKF2's height error with GNSS
//!   height, ramping from 0 at the first arming to [`VehicleConfig::height_bias`] over
//!   [`HEIGHT_BIAS_RAMP`] s; PX4's own modes fly on it; the record stays true.
//! * PX4's land detector ([`crate::commander::LandDetector`]) on the estimate and the commanded
//!   thrust: its verdict is EXTENDED_SYS_STATE's landed state, the commander's arming and
//!   disarming checks and its automatic disarm 2 s after landing, in any mode.
//! * The airframe ([`Airframe`]): the simulator's agile design vehicle (default) or PX4's
//!   stock SIH quadrotor ([`VehicleConfig::stock`]).
//! * [`SimVehicle::record`]: the true flight (crash, heights, touchdowns, mode changes,
//!   arming, the pitch rotation flown in OFFBOARD), kept at every 1 ms step, for the
//!   summary of `mpcc sitl`.

use firmware_shim::frames::{
    enu_to_ned, flu_to_frd, frd_to_flu, quat_enu_flu_to_ned_frd, quat_to_mavlink,
};
use firmware_shim::messages::Px4Mode;
use firmware_shim::setpoint::ThrustMap;
use mavlink::MessageData;
use mavlink::dialects::common::{self as mc, MavFrame, MavLandedState, MavMessage, MavVtolState};
use mpc_mission::estimate::{Estimate, EstimatorConfig};
use mpc_mission::mission::attitude_from_thrust;
use mpc_mission::vehicle::{QuadParams, QuadState};
use mpc_sim::estimator::Estimator;
use mpc_sim::plant::{Contact, Disturbance, Plant};
use mpc_sim::rate_loop::{Airmode, GyroFilter, RateController, RateGains, px4_torque_per_command};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::commander::{
    Commander, CommanderConfig, Control, LandDetector, LandDetectorConfig, LandDetectorInput,
    MessageInterval, STREAMED_MESSAGES, VehicleStatus,
};

/// The height error of the estimate grows from 0 at the first arming to its final value
/// over this long \[s\] (EKF2 on GNSS height drifted 0.2-0.7 m over a flight).
pub const HEIGHT_BIAS_RAMP: f64 = 20.0;

/// The slowest and the fastest vehicle clock, relative to the wall clock.
pub const CLOCK_RATE_RANGE: (f64, f64) = (0.5, 2.0);

/// The largest height bias [`VehicleConfig::validate`] accepts \[m\].
pub const MAX_HEIGHT_BIAS: f64 = 5.0;

/// A bad setting of the simulated vehicle, saying what to give instead.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VehicleConfigError {
    /// The clock rate is out of range.
    #[error(
        "clock rate {0}: give 0.5 to 2.0 vehicle seconds per wall-clock second (PX4 SITL in \
         lockstep: about 0.988)"
    )]
    ClockRate(f64),
    /// A clock jump that is not `AT:BY`.
    #[error(
        "clock jump `{0}`: give AT:BY in seconds, e.g. 30:-5 (at vehicle time AT >= 0, every \
         timestamp from then on is shifted by BY, either sign)"
    )]
    ClockJump(String),
    /// The height bias is not finite or too large.
    #[error("height bias {0} m: give a bias within -5 to 5 m (PX4's EKF2 on GNSS: 0.2-0.7 m)")]
    HeightBias(f64),
    /// An unknown airframe name.
    #[error(
        "vehicle `{0}`: unknown; use agile (the simulator's design vehicle) or stock (PX4's \
         SIH quadrotor)"
    )]
    Airframe(String),
}

/// A jump of the vehicle's clock (a PX4 reboot, a restarted lockstep simulation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockJump {
    /// When, in simulated time \[s\].
    pub at: f64,
    /// By how much every timestamp from then on is shifted \[s\] (either sign).
    pub by: f64,
}

impl std::str::FromStr for ClockJump {
    type Err = VehicleConfigError;

    /// `AT:BY` in seconds, e.g. `30:-5`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || VehicleConfigError::ClockJump(s.to_string());
        let (at, by) = s.split_once(':').ok_or_else(bad)?;
        let at: f64 = at.trim().parse().map_err(|_| bad())?;
        let by: f64 = by.trim().parse().map_err(|_| bad())?;
        let jump = Self { at, by };
        jump.is_valid().then_some(jump).ok_or_else(bad)
    }
}

impl ClockJump {
    fn is_valid(&self) -> bool {
        self.at.is_finite() && self.at >= 0.0 && self.by.is_finite()
    }
}

/// The vehicle PX4 flies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Airframe {
    /// The simulator's design vehicle ([`QuadParams::default`]): thrust-to-weight 4, about
    /// 390 rad/s^2 of pitch authority, 30 ms rotors.
    #[default]
    Agile,
    /// PX4's stock SIH quadrotor ([`VehicleConfig::stock`]): 1 kg, 4 x 5 N, about
    /// 80 rad/s^2 of pitch authority with PX4's default rate gains.
    Stock,
}

impl std::str::FromStr for Airframe {
    type Err = VehicleConfigError;

    /// `agile` or `stock`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "agile" => Ok(Self::Agile),
            "stock" => Ok(Self::Stock),
            _ => Err(VehicleConfigError::Airframe(s.to_string())),
        }
    }
}

impl Airframe {
    /// The vehicle's settings, with the other settings at their defaults.
    pub fn config(self) -> VehicleConfig {
        match self {
            Self::Agile => VehicleConfig::default(),
            Self::Stock => VehicleConfig::stock(),
        }
    }
}

/// Settings of the simulated vehicle.
#[derive(Clone, Debug, PartialEq)]
pub struct VehicleConfig {
    /// The commander's timing.
    pub commander: CommanderConfig,
    /// The vehicle (true and as the rate loop believes it).
    pub params: QuadParams,
    /// The rate loop's gains.
    pub rate_gains: RateGains,
    /// The rate loop's mixer: this simulator's airmode, or PX4's default MC_AIRMODE 0.
    pub airmode: Airmode,
    /// The gyro as PX4's rate controller sees it, filtered at the gyro's rate, the rate loop
    /// running on every sample; `None`: the raw gyro every 1 ms step.
    pub gyro_filter: Option<GyroFilter>,
    /// Angular damping, a torque of `-angular_damping * w` (SIH_KDW) [N m s/rad].
    pub angular_damping: f64,
    /// What PX4 answers for MPC_THR_HOVER (and its land detector uses); `None`: the true
    /// hover thrust of [`VehicleConfig::params`], as a calibrated airframe.
    pub hover_thrust_param: Option<f64>,
    /// PX4's land detector.
    pub land_detector: LandDetectorConfig,
    /// Simulated seconds per wall-clock second when served ([`serve`]); within
    /// [`CLOCK_RATE_RANGE`]. PX4's SIH in lockstep ran 1.0-1.5 % slower than the wall clock.
    pub clock_rate: f64,
    /// A jump of the vehicle's timestamps, if any.
    pub clock_jump: Option<ClockJump>,
    /// The estimate's final height error (reported minus true, ENU z) \[m\]; `None`: drawn
    /// from the seed, 0.2 to 0.7 m either way, as EKF2 on GNSS height.
    pub height_bias: Option<f64>,
    /// Estimation noise and latency of the odometry.
    pub estimator: EstimatorConfig,
    /// Noise seed.
    pub seed: u64,
    /// Where it starts, on the ground (ENU) \[m\]; also home for AUTO.RTL.
    pub home: Vector3<f64>,
    /// Default ODOMETRY period \[s\]: PX4 streams it at 30 Hz on the onboard link until asked
    /// otherwise (up to ~100 Hz seen). Not positive or not finite: not streamed by default.
    pub odometry_period: f64,
    /// Default LOCAL_POSITION_NED period \[s\] (PX4: 30 Hz); not positive or not finite: off.
    pub local_position_period: f64,
    /// Default ATTITUDE_QUATERNION period \[s\] (PX4: 50 Hz); not positive or not finite: off.
    pub attitude_quaternion_period: f64,
    /// Default EXTENDED_SYS_STATE period \[s\] (PX4's onboard link: 5 Hz); not positive or
    /// not finite: off.
    pub sys_state_period: f64,
    /// AUTO.LAND descent speed [m/s].
    pub land_speed: f64,
    /// The attitude controller of PX4's own modes.
    pub attitude: AttitudeGains,
}

impl Default for VehicleConfig {
    /// The simulator's default quadrotor ([`Airframe::Agile`]) at the origin, its rate gains
    /// and airmode mixer on the raw gyro every 1 ms, no angular damping, MPC_THR_HOVER its true hover thrust, PX4's land detector,
    /// motion-capture-like noise plus a height bias drawn from the seed, a clock 0.988 of
    /// the wall clock's rate (PX4 SITL in lockstep) without jumps, PX4's default rates on
    /// the onboard link (ODOMETRY and LOCAL_POSITION_NED 30 Hz, ATTITUDE_QUATERNION 50 Hz,
    /// EXTENDED_SYS_STATE 5 Hz), landing at 0.5 m/s, PX4's default attitude gains.
    fn default() -> Self {
        Self {
            commander: CommanderConfig::default(),
            params: QuadParams::default(),
            rate_gains: RateGains::default(),
            airmode: Airmode::RollPitch,
            gyro_filter: None,
            angular_damping: 0.0,
            hover_thrust_param: None,
            land_detector: LandDetectorConfig::default(),
            clock_rate: 0.988,
            clock_jump: None,
            height_bias: None,
            estimator: EstimatorConfig::noisy(),
            seed: 0,
            home: Vector3::zeros(),
            odometry_period: 1.0 / 30.0,
            local_position_period: 1.0 / 30.0,
            attitude_quaternion_period: 1.0 / 50.0,
            sys_state_period: 1.0 / 5.0,
            land_speed: 0.5,
            attitude: AttitudeGains::default(),
        }
    }
}

impl VehicleConfig {
    /// PX4's stock SIH quadrotor (`make px4_sitl sihsim_quadx`, PX4's default parameters):
    /// [`QuadParams::px4_sih`] (1 kg, SIH_IXX/IYY/IZZ 0.025/0.025/0.030, 4 x 5 N, lever
    /// SIH_L_ROLL = SIH_L_PITCH = 0.2 m, SIH_T_TAU 0.05 s on the thrust, SIH_KDV 1),
    /// SIH_KDW 0.025 N m s of angular damping, PX4's default rate gains
    /// ([`RateGains::px4_default`]) and mixer (MC_AIRMODE 0, [`Airmode::Disabled`]) on the
    /// gyro as PX4 filters it at SIH's 250 Hz ([`GyroFilter::px4_sih`]), MPC_THR_HOVER 0.5
    /// (PX4's default; the true hover thrust is 0.4905, PX4 SITL measured 0.495), and the
    /// estimate without the default's 5 ms pose latency (EKF2's output predictor: in a PX4
    /// SITL flip its attitude and velocity lag SIH's truth by no measurable time). The rest
    /// as [`VehicleConfig::default`].
    pub fn stock() -> Self {
        let params = QuadParams::px4_sih();
        Self {
            rate_gains: RateGains::px4_default(&params),
            airmode: Airmode::Disabled,
            gyro_filter: Some(GyroFilter::px4_sih()),
            estimator: EstimatorConfig {
                latency: 0.0,
                ..EstimatorConfig::noisy()
            },
            angular_damping: 0.025,
            hover_thrust_param: Some(0.5),
            params,
            ..Self::default()
        }
    }

    /// Checks the clock rate (within [`CLOCK_RATE_RANGE`]), the clock jump (`at` >= 0,
    /// finite) and the height bias (within [`MAX_HEIGHT_BIAS`]).
    ///
    /// # Errors
    ///
    /// The first bad setting, saying what to give instead.
    pub fn validate(&self) -> Result<(), VehicleConfigError> {
        let (lo, hi) = CLOCK_RATE_RANGE;
        if !(lo..=hi).contains(&self.clock_rate) {
            return Err(VehicleConfigError::ClockRate(self.clock_rate));
        }
        if let Some(j) = self.clock_jump
            && !j.is_valid()
        {
            return Err(VehicleConfigError::ClockJump(format!("{}:{}", j.at, j.by)));
        }
        match self.height_bias {
            Some(b) if !(-MAX_HEIGHT_BIAS..=MAX_HEIGHT_BIAS).contains(&b) => {
                Err(VehicleConfigError::HeightBias(b))
            }
            _ => Ok(()),
        }
    }

    /// The final height bias: [`VehicleConfig::height_bias`], or drawn from the seed
    /// (magnitude uniform in 0.2..0.7 m, either sign).
    pub fn final_height_bias(&self) -> f64 {
        self.height_bias
            .unwrap_or_else(|| seeded_height_bias(self.seed))
    }
}

/// A height bias drawn from `seed`: magnitude uniform in 0.2..0.7 m, random sign
/// (SplitMix64, so that the estimator's noise stream is not disturbed).
fn seeded_height_bias(seed: u64) -> f64 {
    let mut z = seed ^ 0x5EED_B1A5_u64;
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    let u = (z >> 11) as f64 / (1u64 << 53) as f64;
    let magnitude = 0.2 + 0.5 * u;
    if z & 1 == 0 { magnitude } else { -magnitude }
}

/// PX4's multicopter attitude controller parameters (mc_att_control).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttitudeGains {
    /// P gains roll, pitch, yaw [1/s] (MC_ROLL_P, MC_PITCH_P, MC_YAW_P).
    pub p: Vector3<f64>,
    /// Yaw weight in [0, 1] (MC_YAW_WEIGHT): how much of the yaw error is corrected
    /// together with the tilt (PX4 de-prioritizes yaw).
    pub yaw_weight: f64,
    /// Rate limits roll, pitch, yaw [rad/s] (MC_ROLLRATE_MAX, MC_PITCHRATE_MAX,
    /// MC_YAWRATE_MAX).
    pub max_rates: Vector3<f64>,
}

impl Default for AttitudeGains {
    /// PX4's defaults: P (6.5, 6.5, 2.8), yaw weight 0.4, rate limits 220, 220, 200 deg/s.
    fn default() -> Self {
        Self {
            p: Vector3::new(6.5, 6.5, 2.8),
            yaw_weight: 0.4,
            max_rates: Vector3::new(220.0, 220.0, 200.0).map(f64::to_radians),
        }
    }
}

/// PX4's `Quaternion(src, dst)`: the shortest rotation taking `src` to `dst`, with PX4's
/// choice of axis when they are opposite.
fn rotation_between(src: &Vector3<f64>, dst: &Vector3<f64>) -> Quaternion<f64> {
    let cr = src.cross(dst);
    let dt = src.dot(dst);
    let (w, axis) = if cr.norm() < 1e-5 && dt < 0.0 {
        let a = src.abs();
        let pick = if a.x < a.y {
            if a.x < a.z {
                Vector3::x()
            } else {
                Vector3::z()
            }
        } else if a.y < a.z {
            Vector3::y()
        } else {
            Vector3::z()
        };
        (0.0, src.cross(&pick))
    } else {
        (dt + (src.norm_squared() * dst.norm_squared()).sqrt(), cr)
    };
    let q = Quaternion::new(w, axis.x, axis.y, axis.z);
    let n = q.norm();
    if n > 0.0 && n.is_finite() {
        q / n
    } else {
        Quaternion::identity()
    }
}

/// PX4's `canonical()`: the sign that makes the first non-negligible component positive.
fn canonical(q: Quaternion<f64>) -> Quaternion<f64> {
    let eps = f64::from(f32::EPSILON);
    for c in [q.w, q.i, q.j, q.k] {
        if c.abs() > eps {
            return if c < 0.0 { -q } else { q };
        }
    }
    q
}

/// PX4's attitude controller (mc_att_control `AttitudeControl::update`), in PX4's frames:
/// body rates FRD [rad/s] that turn attitude `q` towards `qd` (both FRD body to NED world).
///
/// The tilt is corrected first: `qd_red` is the shortest rotation of the thrust axis onto
/// the desired one, and only `yaw_weight` of the remaining yaw error is mixed in (the yaw
/// gain is divided by the weight to compensate, as PX4 does). Then `qe = q^-1 * qd`, in its
/// canonical sign (`qe.w >= 0`: the short way round), `rate = 2 * imag(qe) * P`
/// elementwise, clamped to the rate limits. Inverted (the thrust axes opposite), the full
/// attitude error is used, as in PX4; the result is finite for any unit quaternions.
pub fn attitude_control(
    q: &UnitQuaternion<f64>,
    qd: &UnitQuaternion<f64>,
    gains: &AttitudeGains,
) -> Vector3<f64> {
    let yaw_w = gains.yaw_weight.clamp(0.0, 1.0);
    let mut p = gains.p;
    if yaw_w > 1e-4 {
        p.z /= yaw_w;
    }
    let (qv, qdv) = (q.into_inner(), qd.into_inner());
    let e_z = q * Vector3::z();
    let e_z_d = qd * Vector3::z();
    let tilt = rotation_between(&e_z, &e_z_d);
    let qd_red = if tilt.i.abs() > 1.0 - 1e-5 || tilt.j.abs() > 1.0 - 1e-5 {
        qdv
    } else {
        tilt * qv
    };
    let mut dyaw = canonical(qd_red.conjugate() * qdv);
    dyaw.w = dyaw.w.clamp(-1.0, 1.0);
    dyaw.k = dyaw.k.clamp(-1.0, 1.0);
    let yaw_part = Quaternion::new(
        (yaw_w * dyaw.w.acos()).cos(),
        0.0,
        0.0,
        (yaw_w * dyaw.k.asin()).sin(),
    );
    let qd_mix = qd_red * yaw_part;
    let qe = canonical(qv.conjugate() * qd_mix);
    let eq = qe.imag() * 2.0;
    let rate = eq.component_mul(&p);
    let lim = gains.max_rates.abs();
    let rate = rate.zip_map(&lim, |r, l| r.clamp(-l, l));
    if rate.iter().all(|r| r.is_finite()) {
        rate
    } else {
        Vector3::zeros()
    }
}

/// The heading (ENU yaw, rad) attitude `q` would have after the shortest rotation of its
/// thrust axis to vertical: the current heading when upright, and the heading it will come
/// out with when it recovers from a tilted or inverted attitude (the nose of a vehicle
/// pitched over backwards points the way it did before the flip).
fn tilt_free_heading(q: &UnitQuaternion<f64>) -> f64 {
    let level = rotation_between(&(q * Vector3::z()), &Vector3::z()) * q.into_inner();
    let x = UnitQuaternion::new_normalize(level) * Vector3::x();
    x.y.atan2(x.x)
}

/// A touchdown of the true vehicle.
#[derive(Clone, Debug, PartialEq)]
pub struct TouchdownRecord {
    /// Simulated time \[s\].
    pub time: f64,
    /// Downward speed at impact [m/s].
    pub vertical_speed: f64,
    /// Horizontal speed at impact [m/s].
    pub horizontal_speed: f64,
    /// Tilt at impact \[rad\].
    pub tilt: f64,
    /// Where (ENU) \[m\].
    pub position: Vector3<f64>,
    /// The height PX4's estimate reported then (true: 0) \[m\].
    pub estimated_height: f64,
}

/// A mode change of the simulated PX4.
#[derive(Clone, Debug, PartialEq)]
pub struct ModeChange {
    /// Simulated time \[s\].
    pub time: f64,
    /// The mode before.
    pub from: Px4Mode,
    /// The mode after.
    pub to: Px4Mode,
    /// Whether PX4 changed it on its own for the offboard-loss failsafe (otherwise it was
    /// commanded).
    pub failsafe: bool,
}

impl core::fmt::Display for ModeChange {
    /// "OFFBOARD -> POSCTL (offboard-loss failsafe)".
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{} -> {}", self.from, self.to)?;
        if self.failsafe {
            f.write_str(" (offboard-loss failsafe)")?;
        }
        Ok(())
    }
}

/// The true flight of a [`SimVehicle`], kept up to date at every 1 ms step.
#[derive(Clone, Debug, PartialEq)]
pub struct FlightRecord {
    /// Why the plant crashed, if it did (the plant is frozen from then on).
    pub crashed: Option<String>,
    /// When it crashed \[s\].
    pub crash_time: Option<f64>,
    /// Time spent airborne \[s\].
    pub airborne_time: f64,
    /// When it first left the ground \[s\].
    pub first_liftoff: Option<f64>,
    /// Highest true height (ENU z, the ground is z = 0) while airborne \[m\].
    pub max_height: Option<f64>,
    /// Lowest true height while airborne after the first lift-off \[m\] (close to 0 after a
    /// landing: it includes the final approach).
    pub min_height: Option<f64>,
    /// Integral of the true body rate about body y while in OFFBOARD \[rad\], in the models'
    /// FLU body frame: positive tips the nose down, so a back flip (nose up, positive FRD
    /// pitch rate) counts negative.
    pub offboard_pitch_rotation: f64,
    /// Largest true |pitch rate| while in OFFBOARD [rad/s].
    pub offboard_max_pitch_rate: f64,
    /// The touchdowns, in order.
    pub touchdowns: Vec<TouchdownRecord>,
    /// The mode changes, in order (the vehicle starts in POSCTL).
    pub mode_changes: Vec<ModeChange>,
    /// When it was armed \[s\].
    pub armed_at: Vec<f64>,
    /// When it was disarmed \[s\] (by command or by PX4 on its own).
    pub disarmed_at: Vec<f64>,
    /// When PX4 disarmed on its own, its land detector having said landed for
    /// COM_DISARM_LAND \[s\] (in any mode).
    pub auto_disarmed_at: Vec<f64>,
    /// The estimate's height error now (reported minus true) \[m\].
    pub height_bias: f64,
    /// The true position now (ENU) \[m\].
    pub final_position: Vector3<f64>,
    /// Simulated time now \[s\].
    pub time: f64,
}

impl FlightRecord {
    fn new(home: Vector3<f64>) -> Self {
        Self {
            crashed: None,
            crash_time: None,
            airborne_time: 0.0,
            first_liftoff: None,
            max_height: None,
            min_height: None,
            offboard_pitch_rotation: 0.0,
            offboard_max_pitch_rate: 0.0,
            touchdowns: Vec::new(),
            mode_changes: Vec::new(),
            armed_at: Vec::new(),
            disarmed_at: Vec::new(),
            auto_disarmed_at: Vec::new(),
            height_bias: 0.0,
            final_position: home,
            time: 0.0,
        }
    }

    /// A human summary, one fact a line.
    pub fn summary_lines(&self) -> Vec<String> {
        let mut out = Vec::new();
        out.push(match &self.crashed {
            Some(why) => format!(
                "CRASHED at {:.3} s: {why}",
                self.crash_time.unwrap_or(f64::NAN)
            ),
            None => "no crash".to_string(),
        });
        out.push(match self.first_liftoff {
            Some(t) => format!(
                "airborne {:.2} s of {:.2} s (first lift-off at {t:.3} s)",
                self.airborne_time, self.time
            ),
            None => format!("never left the ground ({:.2} s)", self.time),
        });
        if let (Some(hi), Some(lo)) = (self.max_height, self.min_height) {
            out.push(format!(
                "height while airborne: max {hi:.2} m, min {lo:.2} m"
            ));
        }
        let rot = self.offboard_pitch_rotation;
        out.push(format!(
            "pitch rotation in OFFBOARD: {rot:.2} rad ({:.0} deg, {:.2} turns; FLU, nose-down \
             positive), max |pitch rate| {:.2} rad/s",
            rot.to_degrees(),
            rot / std::f64::consts::TAU,
            self.offboard_max_pitch_rate
        ));
        let times = |v: &[f64]| {
            v.iter()
                .map(|t| format!("{t:.3} s"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if !self.armed_at.is_empty() {
            out.push(format!("armed at {}", times(&self.armed_at)));
        }
        if !self.disarmed_at.is_empty() {
            out.push(format!("disarmed at {}", times(&self.disarmed_at)));
        }
        if !self.auto_disarmed_at.is_empty() {
            out.push(format!(
                "disarmed by PX4 after its land detector said landed (COM_DISARM_LAND) at {}",
                times(&self.auto_disarmed_at)
            ));
        }
        for m in &self.mode_changes {
            out.push(format!("mode at {:.3} s: {m}", m.time));
        }
        for t in &self.touchdowns {
            out.push(format!(
                "touchdown at {:.3} s: {:.2} m/s down, {:.2} m/s across, tilt {:.1} deg, at \
                 ({:.2}, {:.2}) m; PX4's estimate said {:.2} m high",
                t.time,
                t.vertical_speed,
                t.horizontal_speed,
                t.tilt.to_degrees(),
                t.position.x,
                t.position.y,
                t.estimated_height
            ));
        }
        let p = self.final_position;
        out.push(format!(
            "final position (ENU): ({:.2}, {:.2}, {:.2}) m; estimate's height error {:+.2} m",
            p.x, p.y, p.z, self.height_bias
        ));
        out
    }
}

/// What PX4's own mode is flying towards: set when the mode begins.
#[derive(Clone, Copy, Debug)]
struct Px4Target {
    mode: Px4Mode,
    /// Hold point, or home (at the return height) for AUTO.RTL.
    point: Vector3<f64>,
    /// Heading to hold (ENU yaw) \[rad\].
    yaw: f64,
    /// Descending (AUTO.LAND; AUTO.RTL once over home).
    descending: bool,
}

/// A streamed message and its schedule.
#[derive(Clone, Copy, Debug)]
struct Stream {
    id: u32,
    default: Option<f64>,
    period: Option<f64>,
    next: f64,
    last: Option<f64>,
}

fn positive(period: f64) -> Option<f64> {
    (period.is_finite() && period > 0.0).then_some(period)
}

/// The simulated PX4 vehicle.
pub struct SimVehicle {
    cfg: VehicleConfig,
    plant: Plant,
    rate: RateController,
    /// Steps of 1 ms per rate-loop update, and the rotor command held until the next.
    rate_steps: u32,
    held: Option<HeldCommand>,
    est: Estimator,
    commander: Commander,
    detector: LandDetector,
    map: ThrustMap,
    t: f64,
    landed: bool,
    target: Option<Px4Target>,
    motors: MotorDemand,
    height_bias: f64,
    streams: Vec<Stream>,
    record: FlightRecord,
}

/// What PX4's land detector reads of the last control output.
#[derive(Clone, Copy, Debug, Default)]
struct MotorDemand {
    /// Normalized collective thrust.
    thrust: f64,
    /// Whether PX4's own position controller flew (climb-rate control).
    climb_rate_control: bool,
    /// Whether it commanded a descent.
    descending: bool,
}

const STEP: f64 = 0.001;

/// A rotor command of the rate loop, held for the steps left until its next update.
#[derive(Clone, Copy, Debug)]
struct HeldCommand {
    rotor_cmd: [f64; 4],
    steps_left: u32,
}

/// Steps of 1 ms per rate-loop update: 1, or the gyro filter's sample interval.
fn rate_steps(filter: Option<GyroFilter>) -> u32 {
    filter.map_or(1, |f| (f.period() / STEP).round().clamp(1.0, 1000.0) as u32)
}

impl SimVehicle {
    /// A disarmed vehicle on the ground at `cfg.home`.
    pub fn new(cfg: VehicleConfig) -> Self {
        let p = &cfg.params;
        // The hover thrust of this vehicle as PX4 would have calibrated it: hover over the
        // maximum collective thrust (linear thrust model, as PX4's).
        let hover_thrust = p.mass * p.g / (4.0 * p.rotor_thrust_max());
        let plant = Plant::new(p.clone(), QuadState::at_rest(cfg.home));
        let landed = plant.contact() == Contact::OnGround;
        Self {
            plant,
            rate: RateController::new(p, cfg.rate_gains.clone())
                .with_airmode(cfg.airmode)
                .with_gyro_filter(cfg.gyro_filter),
            rate_steps: rate_steps(cfg.gyro_filter),
            held: None,
            est: Estimator::new(cfg.estimator.clone(), cfg.seed),
            commander: Commander::new(cfg.commander),
            detector: LandDetector::new(cfg.land_detector),
            map: ThrustMap {
                hover_thrust,
                g: p.g,
            },
            t: 0.0,
            landed,
            target: None,
            motors: MotorDemand::default(),
            height_bias: cfg.final_height_bias(),
            streams: streams(&cfg),
            record: FlightRecord::new(cfg.home),
            cfg,
        }
    }

    /// The settings.
    pub fn config(&self) -> &VehicleConfig {
        &self.cfg
    }

    /// The thrust map a client must use for this vehicle (its true hover thrust).
    pub fn thrust_map(&self) -> ThrustMap {
        self.map
    }

    /// What PX4 answers for MPC_THR_HOVER.
    pub fn hover_thrust_param(&self) -> f64 {
        self.cfg.hover_thrust_param.unwrap_or(self.map.hover_thrust)
    }

    /// Simulated time \[s\].
    pub fn time(&self) -> f64 {
        self.t
    }

    /// The vehicle's clock now, as its timestamps show it \[s\]: the simulated time, shifted
    /// by the [`ClockJump`] once it has happened.
    pub fn clock(&self) -> f64 {
        match self.cfg.clock_jump {
            Some(j) if self.t >= j.at => self.t + j.by,
            _ => self.t,
        }
    }

    /// The true state (ENU/FLU).
    pub fn state(&self) -> &QuadState {
        self.plant.state()
    }

    /// The commander.
    pub fn commander(&self) -> &Commander {
        &self.commander
    }

    /// PX4's land detector.
    pub fn land_detector(&self) -> &LandDetector {
        &self.detector
    }

    /// Whether the plant crashed.
    pub fn crashed(&self) -> bool {
        self.plant.crashed().is_some()
    }

    /// The record of the true flight so far.
    pub fn record(&self) -> &FlightRecord {
        &self.record
    }

    /// Records the commander's mode and arming changes since (`mode`, `armed`).
    fn note_commander(&mut self, mode: Px4Mode, armed: bool, failsafe: bool) {
        let (now_mode, now_armed) = (self.commander.mode(), self.commander.armed());
        if now_mode != mode {
            self.record.mode_changes.push(ModeChange {
                time: self.t,
                from: mode,
                to: now_mode,
                failsafe: failsafe && mode == Px4Mode::Offboard && now_mode == Px4Mode::Position,
            });
        }
        if now_armed != armed {
            if now_armed {
                self.record.armed_at.push(self.t);
            } else {
                self.record.disarmed_at.push(self.t);
            }
        }
        let auto = self.commander.auto_disarmed_at();
        if auto.len() > self.record.auto_disarmed_at.len() {
            self.record.auto_disarmed_at = auto.to_vec();
        }
    }

    /// A message from the companion; returns PX4's answers.
    pub fn handle(&mut self, msg: &MavMessage) -> Vec<MavMessage> {
        match msg {
            MavMessage::PARAM_REQUEST_READ(r) => return self.param_value(r),
            MavMessage::TIMESYNC(ts) => return self.timesync(ts),
            _ => {}
        }
        let (mode, armed) = (self.commander.mode(), self.commander.armed());
        let out = self.commander.on_message(msg, self.t);
        self.note_commander(mode, armed, false);
        out
    }

    /// PX4's `MavlinkTimesync`: a request (`tc1` = 0) is answered with the vehicle's time
    /// \[ns\] in `tc1` and the request's `ts1`; an answer (`tc1` != 0) is not.
    fn timesync(&self, ts: &mc::TIMESYNC_DATA) -> Vec<MavMessage> {
        if ts.tc1 != 0 {
            return Vec::new();
        }
        vec![MavMessage::TIMESYNC(mc::TIMESYNC_DATA {
            tc1: (self.clock().max(0.0) * 1e9) as i64,
            ts1: ts.ts1,
        })]
    }

    /// The parameters this vehicle answers PARAM_REQUEST_READ for, in index order, with
    /// the values PX4 SITL would have for it: MPC_THR_HOVER, MPC_THR_MIN, MPC_MANTHR_MIN,
    /// MC_ROLLRATE_P, MC_PITCHRATE_P (PX4's normalized gains:
    /// `kp * inertia / px4_torque_per_command`), MC_ROLLRATE_MAX, MC_PITCHRATE_MAX
    /// \[deg/s\], SIH_MASS, SIH_IXX, SIH_IYY, SIH_IZZ, SIH_T_MAX (per rotor), SIH_Q_MAX
    /// (per rotor), SIH_L_ROLL, SIH_L_PITCH (the rotors' lever, `arm / sqrt(2)`),
    /// SIH_T_TAU, SIH_KDV, SIH_KDW, COM_DISARM_LAND, LNDMC_TRIG_TIME, LNDMC_Z_VEL_MAX.
    pub fn parameters(&self) -> Vec<(&'static str, f64)> {
        let p = &self.cfg.params;
        let t_max = p.rotor_thrust_max();
        let lever = p.arm * std::f64::consts::FRAC_1_SQRT_2;
        let per_cmd = px4_torque_per_command(p);
        let kp = &self.cfg.rate_gains.kp;
        let max_rates = self.cfg.attitude.max_rates.map(f64::to_degrees);
        let ld = &self.cfg.land_detector;
        vec![
            ("MPC_THR_HOVER", self.hover_thrust_param()),
            ("MPC_THR_MIN", ld.thr_min),
            ("MPC_MANTHR_MIN", ld.man_thr_min),
            ("MC_ROLLRATE_P", kp.x * p.inertia.x / per_cmd.x),
            ("MC_PITCHRATE_P", kp.y * p.inertia.y / per_cmd.y),
            ("MC_ROLLRATE_MAX", max_rates.x),
            ("MC_PITCHRATE_MAX", max_rates.y),
            ("SIH_MASS", p.mass),
            ("SIH_IXX", p.inertia.x),
            ("SIH_IYY", p.inertia.y),
            ("SIH_IZZ", p.inertia.z),
            ("SIH_T_MAX", t_max),
            ("SIH_Q_MAX", p.k_torque * t_max),
            ("SIH_L_ROLL", lever),
            ("SIH_L_PITCH", lever),
            ("SIH_T_TAU", p.rotor_tau),
            ("SIH_KDV", p.drag.x),
            ("SIH_KDW", self.cfg.angular_damping),
            ("COM_DISARM_LAND", self.cfg.commander.disarm_land_delay),
            ("LNDMC_TRIG_TIME", ld.trigger_time),
            ("LNDMC_Z_VEL_MAX", ld.z_vel_max),
        ]
    }

    /// PARAM_VALUE for a PARAM_REQUEST_READ, as PX4: by name when `param_index` is -1, else
    /// by index; REAL32, with the index and the count of [`SimVehicle::parameters`]. PX4
    /// does not answer a request for a parameter it does not have, nor does this.
    fn param_value(&self, r: &mc::PARAM_REQUEST_READ_DATA) -> Vec<MavMessage> {
        let table = self.parameters();
        let found = if r.param_index < 0 {
            table
                .iter()
                .position(|(n, _)| firmware_shim::messages::param_name_is(&r.param_id.into(), n))
        } else {
            usize::try_from(r.param_index)
                .ok()
                .filter(|&i| i < table.len())
        };
        let Some((index, &(name, value))) = found.and_then(|i| table.get(i).map(|e| (i, e))) else {
            return Vec::new();
        };
        vec![MavMessage::PARAM_VALUE(mc::PARAM_VALUE_DATA {
            param_value: value as f32,
            param_count: table.len() as u16,
            param_index: index as u16,
            param_id: name.into(),
            param_type: mc::MavParamType::MAV_PARAM_TYPE_REAL32,
        })]
    }

    /// PX4's position and attitude control: body rates (FLU) and collective acceleration
    /// towards `p_ref` with velocity `v_ref`, heading `yaw`.
    fn position_control(
        &self,
        e: &Estimate,
        p_ref: &Vector3<f64>,
        v_ref: &Vector3<f64>,
        yaw: f64,
    ) -> (Vector3<f64>, f64) {
        let (kp, kd) = (Vector3::new(2.0, 2.0, 4.0), Vector3::new(3.0, 3.0, 4.0));
        let mut a = kp.component_mul(&(p_ref - e.p)) + kd.component_mul(&(v_ref - e.v));
        // Tilt at most ~35 degrees, as PX4's MPC_TILTMAX_AIR.
        let lim = 0.7 * self.cfg.params.g;
        let h = a.xy().norm();
        if h > lim {
            a.x *= lim / h;
            a.y *= lim / h;
        }
        let f = a + Vector3::z() * self.cfg.params.g;
        let qd = attitude_from_thrust(&f, yaw);
        let rates_frd = attitude_control(
            &quat_enu_flu_to_ned_frd(&e.q),
            &quat_enu_flu_to_ned_frd(&qd),
            &self.cfg.attitude,
        );
        let bz = e.q * Vector3::z();
        (frd_to_flu(&rates_frd), f.dot(&bz).max(0.0))
    }

    /// The target of PX4's own `mode`, kept while the mode lasts.
    fn px4_target(&mut self, mode: Px4Mode, e: &Estimate) -> Px4Target {
        let mut target = match self.target {
            Some(t) if t.mode == mode => t,
            _ => {
                let point = match mode {
                    Px4Mode::Return => Vector3::new(
                        self.cfg.home.x,
                        self.cfg.home.y,
                        e.p.z.max(self.cfg.home.z + 2.0),
                    ),
                    _ => e.p,
                };
                Px4Target {
                    mode,
                    point,
                    yaw: tilt_free_heading(&e.q),
                    descending: mode == Px4Mode::Land,
                }
            }
        };
        // AUTO.RTL: over home, land (and keep landing).
        if mode == Px4Mode::Return && (e.p.xy() - target.point.xy()).norm() < 0.3 {
            target.descending = true;
        }
        self.target = Some(target);
        target
    }

    /// The estimator's estimate now, with EKF2's height error.
    fn estimate(&mut self) -> Estimate {
        let truth = self.plant.state().clone();
        let mut e = self.est.update(self.t, &truth);
        e.p.z += self.height_bias_now();
        e
    }

    /// The height error now: 0 until the first arming, then ramping to the final bias over
    /// [`HEIGHT_BIAS_RAMP`].
    fn height_bias_now(&self) -> f64 {
        let Some(&t0) = self.record.armed_at.first() else {
            return 0.0;
        };
        self.height_bias * ((self.t - t0) / HEIGHT_BIAS_RAMP).clamp(0.0, 1.0)
    }

    /// PX4's land detector on estimate `e` and the last control output.
    fn detect_landing(&mut self, e: &Estimate) -> bool {
        let input = LandDetectorInput {
            armed: self.commander.armed(),
            thrust: self.motors.thrust,
            hover_thrust: self.hover_thrust_param(),
            climb_rate_control: self.motors.climb_rate_control,
            descending: self.motors.descending,
            vz: e.v.z,
            v_xy: e.v.xy().norm(),
            rate_xy: e.w.xy().norm(),
        };
        self.detector.update(self.t, &input)
    }

    /// Body rates (FLU; `None`: motors off) and collective acceleration for `control`.
    fn fly(&mut self, control: Control, e: &Estimate) -> (Option<Vector3<f64>>, f64) {
        let (rates, c, motors) = match control {
            Control::Disarmed => (None, 0.0, MotorDemand::default()),
            Control::Offboard(sp) => {
                let r = sp.rates_frd.map(f64::from);
                let thrust = f64::from(sp.thrust);
                let motors = MotorDemand {
                    thrust,
                    ..MotorDemand::default()
                };
                let rates = frd_to_flu(&Vector3::new(r[0], r[1], r[2]));
                (Some(rates), self.map.acceleration(thrust), motors)
            }
            Control::Px4(mode) => return self.fly_px4(mode, e),
        };
        self.target = None;
        self.motors = motors;
        (rates, c)
    }

    /// PX4's own `mode` (hold, land, return) on estimate `e`.
    fn fly_px4(&mut self, mode: Px4Mode, e: &Estimate) -> (Option<Vector3<f64>>, f64) {
        let target = self.px4_target(mode, e);
        let (p_ref, v_ref) = if target.descending {
            let v = Vector3::new(0.0, 0.0, -self.cfg.land_speed);
            (Vector3::new(target.point.x, target.point.y, e.p.z), v)
        } else {
            (target.point, Vector3::zeros())
        };
        let (rates, c) = if self.landed && target.descending {
            (None, 0.0)
        } else {
            let (r, c) = self.position_control(e, &p_ref, &v_ref, target.yaw);
            (Some(r), c)
        };
        self.motors = MotorDemand {
            thrust: self.map.thrust(c).clamp(0.0, 1.0),
            climb_rate_control: true,
            descending: target.descending,
        };
        (rates, c)
    }

    /// Advances by `duration` seconds (1 kHz steps); returns PX4's messages of that time.
    pub fn step(&mut self, duration: f64) -> Vec<MavMessage> {
        let mut out = Vec::new();
        let steps = (duration / STEP).round().max(1.0) as usize;
        for _ in 0..steps {
            self.step_once(&mut out);
        }
        out
    }

    /// One 1 ms step.
    fn step_once(&mut self, out: &mut Vec<MavMessage>) {
        let e = self.estimate();
        let status = VehicleStatus {
            pose_valid: e.pose_valid,
            landed: self.detect_landing(&e),
        };
        let (mode, armed) = (self.commander.mode(), self.commander.armed());
        let (control, msgs) = self.commander.tick(self.t, status);
        self.note_commander(mode, armed, true);
        out.extend(msgs);
        let offboard = matches!(control, Control::Offboard(_));
        let (rates, c) = self.fly(control, &e);
        let rotor_cmd = match rates {
            Some(r) => self.rate_loop(&r, self.cfg.params.mass * c, &e.w),
            None => {
                self.rate.reset();
                self.held = None;
                [0.0; 4]
            }
        };
        let damping = Disturbance {
            torque: -self.cfg.angular_damping * self.plant.state().w,
            ..Disturbance::default()
        };
        let contact = self.plant.step(&rotor_cmd, &damping, STEP);
        match contact {
            Contact::OnGround | Contact::Touchdown { .. } => self.landed = true,
            Contact::Airborne => self.landed = false,
            Contact::Crash { .. } => {}
        }
        self.t += STEP;
        self.note_step(contact, offboard, e.p.z);
        self.stream(&e, out);
    }

    /// The rotor command for body rates `rates` (FLU) and collective thrust `thrust` \[N\]
    /// with gyro `w`: a new one every `rate_steps` steps (the gyro filter's sample interval),
    /// held in between.
    fn rate_loop(&mut self, rates: &Vector3<f64>, thrust: f64, w: &Vector3<f64>) -> [f64; 4] {
        match self.held.as_mut() {
            Some(h) if h.steps_left > 0 => {
                h.steps_left -= 1;
                h.rotor_cmd
            }
            _ => {
                let dt = f64::from(self.rate_steps) * STEP;
                let rotor_cmd = self.rate.update(rates, thrust, w, dt).rotor_cmd;
                self.held = Some(HeldCommand {
                    rotor_cmd,
                    steps_left: self.rate_steps - 1,
                });
                rotor_cmd
            }
        }
    }

    /// Updates the flight record after a step that ended in `contact`; `estimated_z` is the
    /// height PX4's estimate reported.
    fn note_step(&mut self, contact: Contact, offboard: bool, estimated_z: f64) {
        let s = self.plant.state();
        let bias = self.height_bias_now();
        let r = &mut self.record;
        r.time = self.t;
        r.final_position = s.p;
        r.height_bias = bias;
        match contact {
            Contact::Airborne => {
                r.airborne_time += STEP;
                r.first_liftoff.get_or_insert(self.t - STEP);
                let z = s.p.z;
                r.max_height = Some(r.max_height.map_or(z, |m| m.max(z)));
                r.min_height = Some(r.min_height.map_or(z, |m| m.min(z)));
            }
            Contact::Touchdown {
                vertical_speed,
                horizontal_speed,
                tilt,
            } => r.touchdowns.push(TouchdownRecord {
                time: self.t,
                vertical_speed,
                horizontal_speed,
                tilt,
                position: s.p,
                estimated_height: estimated_z,
            }),
            Contact::Crash {
                reason,
                vertical_speed,
                horizontal_speed,
                tilt,
                time,
            } => {
                if r.crashed.is_none() {
                    r.crashed = Some(format!(
                        "{reason:?}: {vertical_speed:.2} m/s down, {horizontal_speed:.2} m/s \
                         across, tilt {:.1} deg",
                        tilt.to_degrees()
                    ));
                    r.crash_time = Some(time);
                }
            }
            Contact::OnGround => {}
        }
        if offboard && !contact.is_crash() {
            r.offboard_pitch_rotation += s.w.y * STEP;
            r.offboard_max_pitch_rate = r.offboard_max_pitch_rate.max(s.w.y.abs());
        }
    }

    /// The streamed messages due now, at their current rates.
    fn stream(&mut self, e: &Estimate, out: &mut Vec<MavMessage>) {
        let now = self.t;
        for i in 0..self.streams.len() {
            let Some(s) = self.streams.get(i).copied() else {
                continue;
            };
            let period = match self.commander.message_interval(s.id) {
                Some(MessageInterval::Every(p)) => Some(p),
                Some(MessageInterval::Stopped) => None,
                Some(MessageInterval::Default) | None => s.default,
            };
            let mut s = s;
            if period != s.period {
                s.period = period;
                s.next = s.last.zip(period).map_or(now, |(l, p)| (l + p).max(now));
            }
            if let Some(p) = s.period
                && now + 1e-9 >= s.next
            {
                s.last = Some(now);
                // Keep the average rate (no drift from the 1 ms step), but never queue up.
                s.next = if s.next + p > now {
                    s.next + p
                } else {
                    now + p
                };
                out.push(self.message(s.id, e));
            }
            if let Some(slot) = self.streams.get_mut(i) {
                *slot = s;
            }
        }
    }

    /// EXTENDED_SYS_STATE's landed state, as PX4's stream: the land detector's verdict;
    /// airborne while PX4 itself lands, LANDING.
    fn landed_state(&self) -> MavLandedState {
        if self.detector.landed() {
            MavLandedState::MAV_LANDED_STATE_ON_GROUND
        } else if self.target.is_some_and(|t| t.descending) {
            MavLandedState::MAV_LANDED_STATE_LANDING
        } else {
            MavLandedState::MAV_LANDED_STATE_IN_AIR
        }
    }

    /// Streamed message `id` now, from estimate `e`.
    fn message(&self, id: u32, e: &Estimate) -> MavMessage {
        let clock = self.clock().max(0.0);
        let time_boot_ms = (clock * 1e3).round() as u32;
        match id {
            mc::LOCAL_POSITION_NED_DATA::ID => {
                let p = enu_to_ned(&e.p);
                let v = enu_to_ned(&e.v);
                MavMessage::LOCAL_POSITION_NED(mc::LOCAL_POSITION_NED_DATA {
                    time_boot_ms,
                    x: p.x as f32,
                    y: p.y as f32,
                    z: p.z as f32,
                    vx: v.x as f32,
                    vy: v.y as f32,
                    vz: v.z as f32,
                })
            }
            mc::ATTITUDE_QUATERNION_DATA::ID => {
                let [q1, q2, q3, q4] = quat_to_mavlink(&quat_enu_flu_to_ned_frd(&e.q));
                let w = flu_to_frd(&e.w);
                MavMessage::ATTITUDE_QUATERNION(mc::ATTITUDE_QUATERNION_DATA {
                    time_boot_ms,
                    q1,
                    q2,
                    q3,
                    q4,
                    rollspeed: w.x as f32,
                    pitchspeed: w.y as f32,
                    yawspeed: w.z as f32,
                })
            }
            mc::EXTENDED_SYS_STATE_DATA::ID => {
                MavMessage::EXTENDED_SYS_STATE(mc::EXTENDED_SYS_STATE_DATA {
                    vtol_state: MavVtolState::MAV_VTOL_STATE_UNDEFINED,
                    landed_state: self.landed_state(),
                })
            }
            _ => odometry(e, clock),
        }
    }
}

/// The streams of `cfg` at their default rates.
fn streams(cfg: &VehicleConfig) -> Vec<Stream> {
    let default_period = |id: u32| match id {
        mc::ODOMETRY_DATA::ID => positive(cfg.odometry_period),
        mc::LOCAL_POSITION_NED_DATA::ID => positive(cfg.local_position_period),
        mc::ATTITUDE_QUATERNION_DATA::ID => positive(cfg.attitude_quaternion_period),
        mc::EXTENDED_SYS_STATE_DATA::ID => positive(cfg.sys_state_period),
        _ => None,
    };
    STREAMED_MESSAGES
        .iter()
        .map(|&id| Stream {
            id,
            default: default_period(id),
            period: default_period(id),
            next: 0.0,
            last: None,
        })
        .collect()
}

/// ODOMETRY as PX4 sends it: LOCAL_NED position and velocity, NED->FRD attitude, FRD rates.
fn odometry(e: &Estimate, t: f64) -> MavMessage {
    let p = enu_to_ned(&e.p);
    let v = enu_to_ned(&e.v);
    let w = flu_to_frd(&e.w);
    MavMessage::ODOMETRY(mc::ODOMETRY_DATA {
        time_usec: (t * 1e6) as u64,
        x: p.x as f32,
        y: p.y as f32,
        z: p.z as f32,
        q: quat_to_mavlink(&quat_enu_flu_to_ned_frd(&e.q)),
        vx: v.x as f32,
        vy: v.y as f32,
        vz: v.z as f32,
        rollspeed: w.x as f32,
        pitchspeed: w.y as f32,
        yawspeed: w.z as f32,
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        ..mc::ODOMETRY_DATA::DEFAULT
    })
}

/// Serves `vehicle` on `link` in real time (the simulation follows the wall clock at
/// [`VehicleConfig::clock_rate`] simulated seconds per wall-clock second, clamped to
/// [`CLOCK_RATE_RANGE`], in 4 ms steps, as PX4's SIH at 250 Hz) until `duration` wall-clock
/// seconds have passed or `stop` is set: what arrives is handled at once, what the vehicle
/// sends goes out as it is produced.
/// Sending before anyone has been heard on a `udpin` link fails; such messages are dropped
/// (PX4 does the same until a client appears). Returns the number of messages received.
pub fn serve(
    link: &firmware_shim::transport::Link,
    vehicle: &mut SimVehicle,
    duration: f64,
    stop: &std::sync::atomic::AtomicBool,
) -> usize {
    serve_with(link, vehicle, duration, stop, |_| true)
}

/// [`serve`], calling `on_tick` after every 4 ms step (to report progress); serving ends
/// early when it returns false.
pub fn serve_with(
    link: &firmware_shim::transport::Link,
    vehicle: &mut SimVehicle,
    duration: f64,
    stop: &std::sync::atomic::AtomicBool,
    mut on_tick: impl FnMut(&SimVehicle) -> bool,
) -> usize {
    use std::time::{Duration, Instant};
    const TICK: f64 = 0.004;
    let start = Instant::now();
    let t0 = vehicle.time();
    let rate = vehicle
        .config()
        .clock_rate
        .clamp(CLOCK_RATE_RANGE.0, CLOCK_RATE_RANGE.1);
    let mut received = 0;
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        let now = start.elapsed().as_secs_f64();
        if now >= duration {
            break;
        }
        while let Some((_, msg)) = link.try_recv() {
            received += 1;
            for reply in vehicle.handle(&msg) {
                let _ = link.send(&reply);
            }
        }
        // Catch up with the wall clock at the vehicle's rate, 4 ms at a time.
        while vehicle.time() - t0 + TICK <= rate * now + 1e-9 {
            for m in vehicle.step(TICK) {
                let _ = link.send(&m);
            }
            if !on_tick(vehicle) {
                return received;
            }
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    received
}
