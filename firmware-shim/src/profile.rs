//! The vehicle a mission flies: what it can do, and the flip planned for it.
//!
//! A [`VehicleProfile`] holds the few figures that decide what a quadrotor can fly: mass,
//! the most thrust of a rotor, the pitch lever and inertia, the rotors' time constant, the
//! hover thrust. `mpcc fly` takes them from PX4 (SIH's `SIH_*` parameters in simulation,
//! [`SIH_PARAMS`]) or from a profile file the user keeps and edits (JSON,
//! [`VehicleProfile::load`]), and writes what it flew with next to its log.
//!
//! From them: the collective acceleration the vehicle can make (`4 T / m`), its pitch
//! authority (`2 T l / Iyy`: two rotors full, two off, as SIH's X mixer), and the fastest
//! flip it can stop: braking from the flip's rate `w` at half the authority, plus one rotor
//! time constant at `w`, must take at most a quarter turn ([`MAX_BRAKE_ANGLE`]). The flip's
//! rate reference is then planned for the vehicle: it ramps up to `w` and down to zero at the
//! full turn at half the authority (the paper's step of the rate asks a slow vehicle for what
//! it cannot do: its attitude falls behind the reference, the NMPC asks for more rate to
//! catch up, and the vehicle overshoots the recovery), and the vehicle climbs into the flip
//! at least at half the speed it falls during the turn (`g t / 2`), so that a slower flip
//! does not come out lower.

use std::f64::consts::{FRAC_PI_2, PI};
use std::path::Path;

use mpc_mission::mission::{G, MissionConfig, MissionKind};
use mpc_mission::vehicle::QuadParams;
use serde::{Deserialize, Serialize};

/// PX4 SIH's parameters a profile is read from, in the order of [`VehicleProfile::from_sih`].
pub const SIH_PARAMS: [&str; 5] = [
    "SIH_MASS",
    "SIH_T_MAX",
    "SIH_L_PITCH",
    "SIH_IYY",
    "SIH_T_TAU",
];

/// The most the vehicle may turn while it brakes out of the flip \[rad\].
pub const MAX_BRAKE_ANGLE: f64 = FRAC_PI_2;
/// The share of the pitch authority the braking is planned on (the rest holds the thrust
/// and the other axes).
pub const BRAKE_SHARE: f64 = 0.5;
/// The least thrust-to-weight ratio a flip is tried with: the recovery needs the reserve.
pub const MIN_FLIP_THRUST_TO_WEIGHT: f64 = 1.8;
/// The fastest flip the NMPC's rate bound allows [rad/s].
pub const NMPC_RATE_BOUND: f64 = 20.0;

/// What a vehicle can do. See the [module documentation](self).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VehicleProfile {
    /// Where the figures came from, in words.
    pub source: String,
    /// Mass \[kg\].
    pub mass_kg: f64,
    /// The most thrust of one rotor \[N\] (four rotors).
    pub rotor_thrust_max_n: f64,
    /// Lever of the rotors about the pitch axis \[m\] (SIH's `SIH_L_PITCH`).
    pub pitch_lever_m: f64,
    /// Inertia about the pitch axis \[kg m^2\].
    pub iyy_kg_m2: f64,
    /// Time constant of the rotors \[s\].
    pub rotor_tau_s: f64,
}

/// A profile that cannot be flown, or a maneuver beyond the vehicle.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ProfileError {
    /// A figure out of range.
    #[error("vehicle profile: {name} = {value} is invalid: {why}")]
    Invalid {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        why: &'static str,
    },
    /// The file could not be read or parsed.
    #[error("vehicle profile {path}: {why}")]
    File {
        /// The file.
        path: String,
        /// What went wrong.
        why: String,
    },
    /// The flip asked for is beyond the vehicle.
    #[error(
        "the flip at {asked:.1} rad/s is beyond this vehicle ({vehicle}): it can flip at up to \
         {max:.1} rad/s; give --flip-rate {max:.1} or less, or fly another vehicle"
    )]
    FlipTooFast {
        /// The rate asked for [rad/s].
        asked: f64,
        /// The fastest the vehicle can stop [rad/s].
        max: f64,
        /// The vehicle, in words.
        vehicle: String,
    },
    /// Too little thrust to flip at all.
    #[error(
        "this vehicle ({vehicle}) cannot flip: a flip needs a thrust-to-weight ratio of at \
         least {MIN_FLIP_THRUST_TO_WEIGHT}"
    )]
    NoFlip {
        /// The vehicle, in words.
        vehicle: String,
    },
}

impl VehicleProfile {
    /// The simulator's design vehicle (`mpcc sim`, `mpcc sitl --vehicle agile`): thrust to
    /// weight 4, about 390 rad/s^2 of pitch authority, 30 ms rotors.
    pub fn design() -> Self {
        Self::from_plant("the simulator's design vehicle", &QuadParams::default())
    }

    /// The figures of a simulated plant.
    pub fn from_plant(source: &str, p: &QuadParams) -> Self {
        Self {
            source: source.to_string(),
            mass_kg: p.mass,
            rotor_thrust_max_n: p.rotor_thrust_max(),
            pitch_lever_m: p.arm * std::f64::consts::FRAC_1_SQRT_2,
            iyy_kg_m2: p.inertia.y,
            rotor_tau_s: p.rotor_tau,
        }
    }

    /// From PX4 SIH's parameters, in the order of [`SIH_PARAMS`].
    pub fn from_sih(values: [f64; 5]) -> Self {
        let [
            mass_kg,
            rotor_thrust_max_n,
            pitch_lever_m,
            iyy_kg_m2,
            rotor_tau_s,
        ] = values;
        Self {
            source: "PX4's SIH parameters".to_string(),
            mass_kg,
            rotor_thrust_max_n,
            pitch_lever_m,
            iyy_kg_m2,
            rotor_tau_s,
        }
    }

    /// Checks every figure.
    ///
    /// # Errors
    /// [`ProfileError::Invalid`] naming the first bad one.
    pub fn validate(&self) -> Result<(), ProfileError> {
        let checks = [
            ("mass_kg", self.mass_kg, 0.01, 100.0),
            ("rotor_thrust_max_n", self.rotor_thrust_max_n, 0.01, 1000.0),
            ("pitch_lever_m", self.pitch_lever_m, 0.01, 5.0),
            ("iyy_kg_m2", self.iyy_kg_m2, 1e-5, 100.0),
            ("rotor_tau_s", self.rotor_tau_s, 0.0, 1.0),
        ];
        for (name, value, lo, hi) in checks {
            if !(value.is_finite() && (lo..=hi).contains(&value)) {
                return Err(ProfileError::Invalid {
                    name,
                    value,
                    why: "a finite value in the physical range (kg, N, m, kg m^2, s)",
                });
            }
        }
        Ok(())
    }

    /// Reads a profile file (JSON, the fields of [`VehicleProfile`]).
    ///
    /// # Errors
    /// [`ProfileError::File`] if it cannot be read or parsed, [`ProfileError::Invalid`] if a
    /// figure is out of range.
    pub fn load(path: &Path) -> Result<Self, ProfileError> {
        let file = |why: String| ProfileError::File {
            path: path.display().to_string(),
            why,
        };
        let text = std::fs::read_to_string(path).map_err(|e| file(e.to_string()))?;
        let p: Self = serde_json::from_str(&text).map_err(|e| file(e.to_string()))?;
        p.validate()?;
        Ok(p)
    }

    /// Writes the profile as JSON.
    ///
    /// # Errors
    /// [`ProfileError::File`] if it cannot be written.
    pub fn save(&self, path: &Path) -> Result<(), ProfileError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| ProfileError::File {
            path: path.display().to_string(),
            why: e.to_string(),
        })?;
        std::fs::write(path, text + "\n").map_err(|e| ProfileError::File {
            path: path.display().to_string(),
            why: e.to_string(),
        })
    }

    /// Thrust over weight.
    pub fn thrust_to_weight(&self) -> f64 {
        4.0 * self.rotor_thrust_max_n / (self.mass_kg * G)
    }

    /// The most mass-normalized collective thrust [m/s^2].
    pub fn max_collective(&self) -> f64 {
        4.0 * self.rotor_thrust_max_n / self.mass_kg
    }

    /// Pitch authority [rad/s^2]: two rotors full, two off.
    pub fn pitch_authority(&self) -> f64 {
        2.0 * self.rotor_thrust_max_n * self.pitch_lever_m / self.iyy_kg_m2
    }

    /// The angle turned braking from `rate` at `share` of the authority, plus one rotor time
    /// constant at `rate` \[rad\].
    pub fn braking_angle(&self, rate: f64, share: f64) -> f64 {
        rate * rate / (2.0 * share * self.pitch_authority()) + rate.abs() * self.rotor_tau_s
    }

    /// The fastest flip the vehicle can stop within [`MAX_BRAKE_ANGLE`] at [`BRAKE_SHARE`]
    /// of its authority, at most [`NMPC_RATE_BOUND`] [rad/s].
    pub fn max_flip_rate(&self) -> f64 {
        // w^2 / (2 s a) + w tau = theta: the positive root.
        let a = 1.0 / (2.0 * BRAKE_SHARE * self.pitch_authority());
        let b = self.rotor_tau_s;
        let w = (-b + (b * b + 4.0 * a * MAX_BRAKE_ANGLE).sqrt()) / (2.0 * a);
        w.min(NMPC_RATE_BOUND)
    }

    /// The vehicle in a few words: where from, thrust to weight, pitch authority, rotors.
    pub fn describe(&self) -> String {
        format!(
            "{}: thrust to weight {:.1}, pitch authority {:.0} rad/s^2, rotors {:.0} ms",
            self.source,
            self.thrust_to_weight(),
            self.pitch_authority(),
            self.rotor_tau_s * 1e3
        )
    }
}

/// The flip planned for a vehicle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FlipPlan {
    /// Pitch rate of the turn [rad/s].
    pub rate: f64,
    /// The fastest the vehicle can fly [rad/s].
    pub max_rate: f64,
    /// The rate's ramps up and down [rad/s^2].
    pub accel: f64,
    /// Duration of the turn \[s\].
    pub duration: f64,
    /// Mass-normalized collective thrust during the turn [m/s^2].
    pub thrust: f64,
    /// Climb speed into the flip [m/s].
    pub ascend_speed: f64,
}

/// Plans `mission`'s flip for `vehicle`: at `asked` [rad/s] (`None`: the paper's 5*pi, or
/// the fastest the vehicle can fly if slower), ramped at half its pitch authority, climbed
/// into fast enough.
/// Missions without a flip are left as they are.
///
/// # Errors
/// [`ProfileError::FlipTooFast`] if `asked` is beyond the vehicle, [`ProfileError::NoFlip`]
/// if it has too little thrust to flip.
pub fn plan_flip(
    mission: &mut MissionConfig,
    vehicle: &VehicleProfile,
    asked: Option<f64>,
) -> Result<Option<FlipPlan>, ProfileError> {
    if mission.kind != MissionKind::Flip {
        return Ok(None);
    }
    if vehicle.thrust_to_weight() < MIN_FLIP_THRUST_TO_WEIGHT {
        return Err(ProfileError::NoFlip {
            vehicle: vehicle.describe(),
        });
    }
    let max_rate = vehicle.max_flip_rate();
    let rate = match asked {
        Some(w) if w > max_rate + 1e-9 => {
            return Err(ProfileError::FlipTooFast {
                asked: w,
                max: max_rate,
                vehicle: vehicle.describe(),
            });
        }
        Some(w) => w,
        None => (5.0 * PI).min(max_rate),
    };
    let accel = BRAKE_SHARE * vehicle.pitch_authority();
    // Half the most thrust: the rotors' differential, and so the pitch authority, is
    // largest there (at the paper's 5 m/s^2 a vehicle of thrust to weight 2 has half).
    mission.flip_thrust = 0.5 * vehicle.max_collective();
    mission.flip_rate = rate;
    mission.flip_angle = 2.0 * PI;
    mission.flip_accel = accel;
    // Climbing into the flip at half its fall: a slower flip falls longer, and comes out
    // as fast downwards as it went in upwards.
    let duration = mission.flip_time();
    mission.ascend_speed = mission.ascend_speed.max(0.5 * G * duration);
    Ok(Some(FlipPlan {
        rate,
        max_rate,
        accel,
        duration,
        thrust: mission.flip_thrust,
        ascend_speed: mission.ascend_speed,
    }))
}
