//! The vehicle: its physical parameters ([`QuadParams`], with the rotors' lag [`RotorLag`])
//! and its full state ([`QuadState`]). The simulator's plant (`mpc_sim::plant`) flies them;
//! the missions, the log and the PX4 shim's vehicle profile read them.
//!
//! Conventions (those of the plant): world ENU, body FLU, attitude a Hamilton unit
//! quaternion rotating body to world; rotors in X configuration numbered as PX4's quad X
//! (`0` front-right, `1` rear-left, `2` front-left, `3` rear-right).

use nalgebra::{UnitQuaternion, Vector3};

/// What the rotors' first-order lag (time constant [`QuadParams::rotor_tau`]) acts on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RotorLag {
    /// The rotor speed: `omega' = (cmd - omega) / rotor_tau`, thrust `k_thrust omega^2`. A
    /// rotor spins down faster than it spins up, and slowest of all up from rest.
    #[default]
    Speed,
    /// The thrust, as PX4's SIH (`u += dt / SIH_T_TAU * (u_sp - u)`, thrust `SIH_T_MAX u`):
    /// `f' = (k_thrust cmd^2 - f) / rotor_tau`, the same lag up and down.
    Thrust,
}

/// Physical parameters of the quadrotor.
#[derive(Clone, Debug, PartialEq)]
pub struct QuadParams {
    /// Mass, kg.
    pub mass: f64,
    /// Diagonal of the inertia tensor (Ixx, Iyy, Izz) in body axes, kg m^2.
    pub inertia: Vector3<f64>,
    /// Distance from the centre of gravity to each rotor axis, m (rotors at 45 degrees, X).
    pub arm: f64,
    /// Time constant of the first-order rotor response, s.
    pub rotor_tau: f64,
    /// What that first-order lag acts on (the speed, or the thrust as in PX4's SIH).
    pub rotor_lag: RotorLag,
    /// Thrust coefficient, N/(rad/s)^2: `f = k_thrust omega^2`.
    pub k_thrust: f64,
    /// Yaw drag-torque coefficient, m: a rotor's yaw torque is `spin * k_torque * f`.
    pub k_torque: f64,
    /// Maximum rotor speed (motor saturation), rad/s.
    pub omega_max: f64,
    /// Minimum rotor speed (idle), rad/s.
    pub omega_min: f64,
    /// Linear aerodynamic drag coefficients in body axes, N/(m/s), acting on the
    /// air-relative velocity.
    pub drag: Vector3<f64>,
    /// Gravitational acceleration, m/s^2.
    pub g: f64,
}

impl Default for QuadParams {
    /// A small agile racing-class quadrotor:
    ///
    /// * `mass` 1.0 kg;
    /// * `inertia` (0.006, 0.006, 0.011) kg m^2;
    /// * `arm` 0.17 m (lever about x and y: 0.17/sqrt(2) = 0.120 m);
    /// * `rotor_tau` 0.03 s, the lag on the rotor speed ([`RotorLag::Speed`]);
    /// * `k_thrust` 1.25e-6 N/(rad/s)^2 and `omega_max` 2800 rad/s, so a rotor gives at most
    ///   9.8 N and the thrust-to-weight ratio is about 4.0; hover is at 1401 rad/s;
    /// * `k_torque` 0.016 m;
    /// * `omega_min` 0 rad/s (no idle);
    /// * `drag` (0.10, 0.10, 0.15) N/(m/s);
    /// * `g` 9.81 m/s^2.
    ///
    /// The maximum pitch torque is 2 * 0.120 m * 9.8 N = 2.36 N m, an angular acceleration of
    /// about 390 rad/s^2: enough to reach the 5*pi rad/s (15.7 rad/s) rate of a flip in about
    /// 0.04 s plus the rotor lag.
    fn default() -> Self {
        Self {
            mass: 1.0,
            inertia: Vector3::new(0.006, 0.006, 0.011),
            arm: 0.17,
            rotor_tau: 0.03,
            rotor_lag: RotorLag::Speed,
            k_thrust: 1.25e-6,
            k_torque: 0.016,
            omega_max: 2800.0,
            omega_min: 0.0,
            drag: Vector3::new(0.10, 0.10, 0.15),
            g: 9.81,
        }
    }
}

impl QuadParams {
    /// PX4's stock SIH quadrotor (simulator_sih's default parameters, airframe
    /// `sihsim_quadx`), in this plant's terms:
    ///
    /// * `mass` 1.0 kg (SIH_MASS);
    /// * `inertia` (0.025, 0.025, 0.030) kg m^2 (SIH_IXX, SIH_IYY, SIH_IZZ);
    /// * `arm` 0.2 * sqrt(2) m: SIH's SIH_L_ROLL and SIH_L_PITCH (0.2 m) are the levers
    ///   themselves, half the distance between the left and right (front and rear) rotors;
    /// * `rotor_tau` 0.05 s (SIH_T_TAU), the lag on the thrust as SIH's ([`RotorLag::Thrust`]);
    /// * `k_thrust` 5e-6 N/(rad/s)^2 and `omega_max` 1000 rad/s: 5 N per rotor (SIH_T_MAX),
    ///   thrust-to-weight 2.04, hover at 0.4905 of full thrust;
    /// * `k_torque` 0.02 m: 0.1 N m per rotor at full thrust (SIH_Q_MAX);
    /// * `omega_min` 0 (no idle);
    /// * `drag` (1, 1, 1) N/(m/s) (SIH_KDV, linear and isotropic in SIH);
    /// * `g` 9.81 m/s^2.
    ///
    /// The pitch authority is `2 * SIH_T_MAX * SIH_L_PITCH / SIH_IYY` = 80 rad/s^2 (SIH's
    /// pitch torque is `SIH_L_PITCH * SIH_T_MAX * (u0 - u1 + u2 - u3)` for rotor commands
    /// `u` in [0, 1]). Differences from SIH: SIH integrates with forward Euler at 250 Hz, this
    /// plant with RK4; SIH's angular damper (SIH_KDW) is not part of the plant (apply it as a
    /// disturbance torque).
    pub fn px4_sih() -> Self {
        Self {
            mass: 1.0,
            inertia: Vector3::new(0.025, 0.025, 0.030),
            arm: 0.2 * std::f64::consts::SQRT_2,
            rotor_tau: 0.05,
            rotor_lag: RotorLag::Thrust,
            k_thrust: 5e-6,
            k_torque: 0.02,
            omega_max: 1000.0,
            omega_min: 0.0,
            drag: Vector3::new(1.0, 1.0, 1.0),
            g: 9.81,
        }
    }

    /// Maximum thrust of one rotor, N: `k_thrust * omega_max^2`.
    pub fn rotor_thrust_max(&self) -> f64 {
        self.k_thrust * self.omega_max * self.omega_max
    }

    /// Minimum thrust of one rotor, N: `k_thrust * omega_min^2`.
    pub fn rotor_thrust_min(&self) -> f64 {
        self.k_thrust * self.omega_min * self.omega_min
    }

    /// Thrust-to-weight ratio with all rotors at `omega_max`.
    pub fn thrust_to_weight(&self) -> f64 {
        4.0 * self.rotor_thrust_max() / (self.mass * self.g)
    }

    /// Collective thrust that balances the weight, N.
    pub fn hover_thrust(&self) -> f64 {
        self.mass * self.g
    }

    /// Rotor speed at which the four rotors together balance the weight, rad/s.
    pub fn hover_rotor_speed(&self) -> f64 {
        (self.hover_thrust() / (4.0 * self.k_thrust))
            .max(0.0)
            .sqrt()
    }

    /// Rotor positions in the body frame (FLU), m, in the order
    /// front-right, rear-left, front-left, rear-right.
    pub fn rotor_positions(&self) -> [Vector3<f64>; 4] {
        let a = self.arm * std::f64::consts::FRAC_1_SQRT_2;
        [
            Vector3::new(a, -a, 0.0),
            Vector3::new(-a, a, 0.0),
            Vector3::new(a, a, 0.0),
            Vector3::new(-a, -a, 0.0),
        ]
    }

    /// Sign of each rotor's yaw drag torque on the airframe (about body +z):
    /// `[-1, -1, +1, +1]`.
    ///
    /// A rotor turning counter-clockwise seen from above (front-right and rear-left, as in
    /// PX4) drags the airframe clockwise, hence `-1`; the clockwise rotors (front-left,
    /// rear-right) give `+1`. The yaw torque is `sum spin_i * k_torque * f_i`.
    pub fn rotor_spin(&self) -> [f64; 4] {
        [-1.0, -1.0, 1.0, 1.0]
    }
}

/// Full continuous state of the plant.
#[derive(Clone, Debug, PartialEq)]
pub struct QuadState {
    /// Position of the centre of gravity in the world frame, m.
    pub p: Vector3<f64>,
    /// Velocity in the world frame, m/s.
    pub v: Vector3<f64>,
    /// Attitude, body to world.
    pub q: UnitQuaternion<f64>,
    /// Body angular rates (body frame), rad/s.
    pub w: Vector3<f64>,
    /// Rotor speeds, rad/s, in the order of [`QuadParams::rotor_positions`].
    pub omega: [f64; 4],
}

impl QuadState {
    /// Level, at rest at `p`, rotors stopped.
    pub fn at_rest(p: Vector3<f64>) -> Self {
        Self {
            p,
            v: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            w: Vector3::zeros(),
            omega: [0.0; 4],
        }
    }

    /// Level hover at `p` with the rotors at the hover speed of `params`.
    pub fn hovering(p: Vector3<f64>, params: &QuadParams) -> Self {
        Self {
            omega: [params.hover_rotor_speed(); 4],
            ..Self::at_rest(p)
        }
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.p.iter().all(|x| x.is_finite())
            && self.v.iter().all(|x| x.is_finite())
            && self.q.coords.iter().all(|x| x.is_finite())
            && self.w.iter().all(|x| x.is_finite())
            && self.omega.iter().all(|x| x.is_finite())
    }

    /// Tilt, rad: the angle between body z and world z.
    pub fn tilt(&self) -> f64 {
        let bz = self.q * Vector3::z();
        bz.z.clamp(-1.0, 1.0).acos()
    }
}
