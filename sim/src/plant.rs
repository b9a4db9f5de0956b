//! The quadrotor plant: a 6-DoF rigid body with four first-order rotors, linear drag,
//! external disturbances and a flat ground plane at `z = 0`.
//!
//! # Conventions
//!
//! * World frame ENU: x east/forward, y north/left, **z up**. Gravity is `-g e_z`.
//! * Body frame FLU: x forward (nose), y left, z up (thrust direction).
//! * Attitude `q` is a Hamilton unit quaternion, scalar first, rotating **body to world**
//!   (`v_world = q * v_body`, `R = R(q)`).
//! * Body rates `w` are expressed in the body frame. A positive pitch rate (about body +y,
//!   i.e. left) tips the nose **down**: `R_y(theta) e_x = (cos theta, 0, -sin theta)`.
//! * Rotors are in X configuration at 45 degrees, numbered like PX4's quad X:
//!   `0` front-right, `1` rear-left, `2` front-left, `3` rear-right
//!   (see [`QuadParams::rotor_positions`] and [`QuadParams::rotor_spin`]).
//!
//! # Dynamics
//!
//! ```text
//! p' = v
//! v' = (R (0, 0, sum f_i) - R diag(drag) R^T (v - wind) + dist.force) / m - g e_z
//! q' = 1/2 q (x) (0, w)                      (renormalised after every step)
//! J w' = tau - w x J w,   tau = sum r_i x (0, 0, f_i) + (0, 0, sum s_i k_torque f_i) + dist.torque
//! omega_i' = (clamp(cmd_i, omega_min, omega_max) - omega_i) / rotor_tau,   f_i = k_thrust omega_i^2
//! ```
//!
//! With [`RotorLag::Thrust`] (PX4's SIH) the lag acts on the thrust instead of the speed:
//! `f_i' = (k_thrust clamp(cmd_i, omega_min, omega_max)^2 - f_i) / rotor_tau` (integrated as
//! `omega_i^2`; the state still holds the speed `omega_i = sqrt(f_i / k_thrust)`).
//!
//! All 17 continuous states are advanced together by one classical Runge-Kutta 4 step per
//! [`Plant::step`]; the disturbance and the rotor commands are held constant over the step.
//!
//! # Ground contact
//!
//! The ground is the plane `z = 0`. While [`Contact::OnGround`], the vehicle is held
//! (`z = 0`, `v = 0`, `w = 0`, attitude and horizontal position kept) until the vertical
//! component of the non-gravitational force exceeds the weight (lift-off). When airborne and
//! `z` becomes negative, the impact is evaluated: a vertical speed above
//! [`MAX_TOUCHDOWN_VERTICAL_SPEED`], a horizontal speed above
//! [`MAX_TOUCHDOWN_HORIZONTAL_SPEED`] or a tilt above [`MAX_TOUCHDOWN_TILT`] is a
//! [`Contact::Crash`]; otherwise it is a [`Contact::Touchdown`] and the vehicle is on the
//! ground from then on. A crash freezes the plant: further [`Plant::step`] calls do nothing
//! and return the same crash. Any non-finite input or state is a crash
//! ([`CrashReason::NonFinite`]); the state is never left non-finite.
//!
//! # Tethered probe
//!
//! A probe ([`crate::probe`]) can hang from the centre of gravity on a rigid link
//! ([`Plant::attach_probe`]). While attached, its link direction `n` and rate `n'` are
//! integrated with the vehicle in the same RK4 step (23 states; not the swing angles, which
//! are singular at `|beta| = pi/2`) and the link tension `lambda n` acts on
//! the vehicle: `v' = (F + lambda n) / m - g e_z` with `F` the force above, and the
//! accelerometer ([`Plant::specific_acceleration`]) measures `(F + lambda n) / m`. The
//! attitude, rate and rotor dynamics are unchanged (free pivot). Lift-off needs the total
//! weight `(m + mp) g`; while the vehicle is held on the ground the link direction is held and
//! its rate is zero. After [`Plant::release_probe`] the probe flies ballistically,
//! independent of the vehicle, and lands on `z = 0`. With a probe of zero mass (or none) the
//! vehicle's motion is bit-identical to the plant without a probe.

use nalgebra::{Quaternion, SVector, UnitQuaternion, Vector3};

pub use mpc_mission::vehicle::{QuadParams, QuadState, RotorLag};

use crate::probe::{
    CoupledAcceleration, Probe, ProbeParams, Release, coupled_acceleration,
    coupled_link_acceleration,
};

/// Touchdown vertical speed (m/s, downward) above which an impact is a crash.
pub const MAX_TOUCHDOWN_VERTICAL_SPEED: f64 = 1.5;
/// Touchdown horizontal speed (m/s) above which an impact is a crash.
pub const MAX_TOUCHDOWN_HORIZONTAL_SPEED: f64 = 1.5;
/// Touchdown tilt (rad, angle between body z and world z) above which an impact is a crash
/// (0.6 rad, about 35 degrees).
pub const MAX_TOUCHDOWN_TILT: f64 = 0.6;

/// Speed (m/s) below which a state at or below the ground plane counts as resting on it.
const REST_SPEED: f64 = 1e-9;

/// External disturbances, held constant over a step. `Default` is no disturbance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Disturbance {
    /// Air velocity in the world frame (wind), m/s.
    pub wind: Vector3<f64>,
    /// Extra force at the centre of gravity, world frame, N.
    pub force: Vector3<f64>,
    /// Extra torque, body frame, N m.
    pub torque: Vector3<f64>,
}

/// Why the plant crashed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CrashReason {
    /// Hit the ground faster than [`MAX_TOUCHDOWN_VERTICAL_SPEED`].
    VerticalSpeed,
    /// Hit the ground more tilted than [`MAX_TOUCHDOWN_TILT`].
    Tilt,
    /// Hit the ground faster than [`MAX_TOUCHDOWN_HORIZONTAL_SPEED`] horizontally.
    HorizontalSpeed,
    /// A non-finite input (rotor command, disturbance, time step) or state.
    NonFinite,
}

/// Contact status reported by [`Plant::step`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Contact {
    /// Flying.
    Airborne,
    /// Resting on the ground plane (held at `z = 0`).
    OnGround,
    /// A soft landing happened during this step; the vehicle is now on the ground.
    Touchdown {
        /// Downward speed at impact, m/s.
        vertical_speed: f64,
        /// Horizontal speed at impact, m/s.
        horizontal_speed: f64,
        /// Tilt at impact, rad.
        tilt: f64,
    },
    /// The vehicle crashed (now or earlier); the plant is frozen.
    Crash {
        /// Why.
        reason: CrashReason,
        /// Downward speed at the crash, m/s (of the last finite state for `NonFinite`).
        vertical_speed: f64,
        /// Horizontal speed at the crash, m/s (of the last finite state for `NonFinite`).
        horizontal_speed: f64,
        /// Tilt at the crash, rad (of the last finite state for `NonFinite`).
        tilt: f64,
        /// Simulated time of the crash, s.
        time: f64,
    },
}

impl Contact {
    /// Whether this is a [`Contact::Crash`].
    pub fn is_crash(&self) -> bool {
        matches!(self, Contact::Crash { .. })
    }
}

/// Internal contact mode.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    Airborne,
    OnGround,
    Crashed(Contact),
}

type Vec17 = SVector<f64, 17>;
/// The vehicle's 17 states followed by the link direction `n` and its rate `n'` of an
/// attached probe (not the swing angles, which are singular at `|beta| = pi/2`:
/// [`crate::probe`]).
type Vec23 = SVector<f64, 23>;

/// The simulated quadrotor.
#[derive(Clone, Debug)]
pub struct Plant {
    /// True physical parameters.
    pub params: QuadParams,
    state: QuadState,
    mode: Mode,
    last: Contact,
    time: f64,
    last_dist: Disturbance,
    probe: Option<Probe>,
}

impl Plant {
    /// A plant in `state`. A state at `z <= 0` with zero velocity starts
    /// [`Contact::OnGround`] (and is put on the plane `z = 0`); anything else starts
    /// airborne. The time starts at 0.
    pub fn new(params: QuadParams, state: QuadState) -> Self {
        let mut plant = Self {
            params,
            state: QuadState::at_rest(Vector3::zeros()),
            mode: Mode::Airborne,
            last: Contact::Airborne,
            time: 0.0,
            last_dist: Disturbance::default(),
            probe: None,
        };
        plant.set_state(state);
        plant
    }

    /// Current state.
    pub fn state(&self) -> &QuadState {
        &self.state
    }

    /// Replaces the state (clearing any crash), with the same ground rule as [`Plant::new`].
    /// A non-finite state is a [`CrashReason::NonFinite`] crash. An attached probe keeps its
    /// link direction (and its rate, unless the new state is on the ground).
    pub fn set_state(&mut self, s: QuadState) {
        if !s.is_finite() {
            let c = Contact::Crash {
                reason: CrashReason::NonFinite,
                vertical_speed: 0.0,
                horizontal_speed: 0.0,
                tilt: 0.0,
                time: self.time,
            };
            self.state = QuadState::at_rest(Vector3::zeros());
            self.mode = Mode::Crashed(c);
            self.last = c;
            return;
        }
        self.state = s;
        if self.state.p.z <= 0.0 && self.state.v.norm() <= REST_SPEED {
            self.state.p.z = 0.0;
            self.state.v = Vector3::zeros();
            self.state.w = Vector3::zeros();
            self.mode = Mode::OnGround;
            self.last = Contact::OnGround;
            self.hold_probe();
        } else {
            self.mode = Mode::Airborne;
            self.last = Contact::Airborne;
        }
    }

    /// Attaches a probe with parameters `params` at swing angles `ang` (rad) and rates
    /// `dang` (rad/s), replacing any probe (attached, free or landed). Its
    /// [`Probe::start`] is its position now. On the ground the swing rates are set to zero
    /// (the probe is held with the vehicle).
    ///
    /// Invalid parameters (see [`ProbeParams::is_valid`]) or non-finite angles or rates
    /// remove the probe and are a [`CrashReason::NonFinite`] crash (unless the plant has
    /// already crashed).
    pub fn attach_probe(&mut self, params: ProbeParams, ang: [f64; 2], dang: [f64; 2]) {
        let finite = ang.iter().chain(dang.iter()).all(|x| x.is_finite());
        if !params.is_valid() || !finite {
            self.probe = None;
            if self.crashed().is_none() {
                let at = self.state.clone();
                self.crash(CrashReason::NonFinite, &at);
            }
            return;
        }
        self.probe = Some(Probe::attached(params, ang, dang, &self.state, self.time));
        if self.mode == Mode::OnGround {
            self.hold_probe();
        }
    }

    /// The probe, if one was attached (in any phase).
    pub fn probe(&self) -> Option<&Probe> {
        self.probe.as_ref()
    }

    /// Releases the attached probe: it becomes [`crate::probe::ProbePhase::Free`] with its
    /// current position and velocity, and the link force on the vehicle disappears (the
    /// vehicle's velocity is unchanged at this instant). Returns the release record, or
    /// `None` if no probe is attached.
    pub fn release_probe(&mut self) -> Option<Release> {
        let (state, time) = (&self.state, self.time);
        self.probe.as_mut().and_then(|p| p.release_at(state, time))
    }

    /// Mass carried by the thrust, kg: the vehicle's plus an attached probe's.
    pub fn total_mass(&self) -> f64 {
        self.params.mass + self.attached_probe().map_or(0.0, |p| p.params().mass)
    }

    /// Link tension `lambda` (N) at the current state with the last step's disturbance, if a
    /// probe is attached and the vehicle airborne (see [`crate::probe::CoupledAcceleration`]).
    pub fn link_tension(&self) -> Option<f64> {
        if self.mode != Mode::Airborne {
            return None;
        }
        self.attached_probe().map(|p| {
            let f = self.nongravity_force(&self.state, &self.last_dist);
            self.coupled_link(&f, p.params(), &p.link_direction(), &p.link_rate())
                .2
        })
    }

    /// The airborne accelerations at the current state under the disturbance `dist`: the
    /// vehicle's world acceleration `v'` and, with an attached probe, the swing
    /// accelerations `(alpha'', beta'')`. The same function the RK4 stages evaluate.
    #[doc(hidden)]
    pub fn accelerations(&self, dist: &Disturbance) -> (Vector3<f64>, Option<[f64; 2]>) {
        let f = self.nongravity_force(&self.state, dist);
        match self.attached_probe() {
            Some(p) => {
                let acc = self.coupled(&f, p.params(), p.ang(), p.dang());
                (acc.vehicle, Some(acc.swing))
            }
            None => (
                f / self.params.mass - Vector3::new(0.0, 0.0, self.params.g),
                None,
            ),
        }
    }

    /// The probe if it is attached.
    fn attached_probe(&self) -> Option<&Probe> {
        self.probe.as_ref().filter(|p| p.is_attached())
    }

    /// Coupled accelerations of the vehicle and an attached probe of parameters `pp` at
    /// swing `ang`, `dang` under the non-gravitational force `f`.
    fn coupled(
        &self,
        f: &Vector3<f64>,
        pp: &ProbeParams,
        ang: [f64; 2],
        dang: [f64; 2],
    ) -> CoupledAcceleration {
        coupled_acceleration(f, self.params.mass, self.params.g, pp, ang, dang)
    }

    /// The same in the plant's coordinates, the link direction `n` and its rate `nd`:
    /// (vehicle acceleration, `n''`, tension).
    fn coupled_link(
        &self,
        f: &Vector3<f64>,
        pp: &ProbeParams,
        n: &Vector3<f64>,
        nd: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>, f64) {
        coupled_link_acceleration(f, self.params.mass, self.params.g, pp, n, nd)
    }

    /// Holds an attached probe with the grounded vehicle: swing rates zero.
    fn hold_probe(&mut self) {
        if let Some(p) = self.probe.as_mut().filter(|p| p.is_attached()) {
            let n = p.link_direction();
            p.set_link(n, Vector3::zeros());
        }
    }

    /// Simulated time, s (sum of the `dt` of all effective steps).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// The contact status returned by the last step (or set by [`Plant::new`]).
    pub fn contact(&self) -> Contact {
        self.last
    }

    /// The crash, if the plant has crashed (always a [`Contact::Crash`]).
    pub fn crashed(&self) -> Option<Contact> {
        match self.mode {
            Mode::Crashed(c) => Some(c),
            _ => None,
        }
    }

    /// Current rotor thrusts, N.
    pub fn rotor_thrusts(&self) -> [f64; 4] {
        let k = self.params.k_thrust;
        self.state.omega.map(|o| k * o * o.abs())
    }

    /// Current collective thrust, N.
    pub fn collective_thrust(&self) -> f64 {
        self.rotor_thrusts().iter().sum()
    }

    /// Specific acceleration (what an accelerometer measures), body frame, m/s^2: the
    /// non-gravitational force over the mass, with the last step's disturbance, including
    /// the link force `lambda n` of an attached probe. On the ground it is the support
    /// force, `R^T (0, 0, g)`.
    pub fn specific_acceleration(&self) -> Vector3<f64> {
        let s = &self.state;
        match self.mode {
            Mode::OnGround | Mode::Crashed(_) => {
                s.q.inverse_transform_vector(&Vector3::new(0.0, 0.0, self.params.g))
            }
            Mode::Airborne => {
                let mut f_world = self.nongravity_force(s, &self.last_dist);
                if let Some(p) = self.attached_probe()
                    && p.params().mass != 0.0
                {
                    let tension = self
                        .coupled_link(&f_world, p.params(), &p.link_direction(), &p.link_rate())
                        .2;
                    f_world += p.link_direction() * tension;
                }
                s.q.inverse_transform_vector(&f_world) / self.params.mass
            }
        }
    }

    /// Non-gravitational force in the world frame: thrust, drag, disturbance.
    fn nongravity_force(&self, s: &QuadState, dist: &Disturbance) -> Vector3<f64> {
        let k = self.params.k_thrust;
        let thrust: f64 = s.omega.iter().map(|o| k * o * o.abs()).sum();
        let v_air_body = s.q.inverse_transform_vector(&(s.v - dist.wind));
        let drag_body = self.params.drag.component_mul(&v_air_body);
        s.q * (Vector3::new(0.0, 0.0, thrust) - drag_body) + dist.force
    }

    /// Advances the plant by `dt` seconds with rotor speed commands `rotor_cmd` (rad/s,
    /// clamped to `[omega_min, omega_max]`) and the disturbance `dist`, by one RK4 step
    /// (with the swing states of an attached probe in the same step; a free probe is
    /// advanced by its own RK4 step over the same interval).
    ///
    /// Returns the contact status; see the [module documentation](self). Once crashed, does
    /// nothing and returns the crash (the probe is frozen too). A `dt <= 0` does nothing and
    /// returns the last status. A non-finite probe state is a [`CrashReason::NonFinite`]
    /// crash like a non-finite vehicle state.
    pub fn step(&mut self, rotor_cmd: &[f64; 4], dist: &Disturbance, dt: f64) -> Contact {
        if let Mode::Crashed(c) = self.mode {
            return c;
        }
        let inputs_finite = rotor_cmd.iter().all(|x| x.is_finite())
            && dist.wind.iter().all(|x| x.is_finite())
            && dist.force.iter().all(|x| x.is_finite())
            && dist.torque.iter().all(|x| x.is_finite())
            && dt.is_finite();
        if !inputs_finite {
            return self.crash(CrashReason::NonFinite, &self.state.clone());
        }
        if dt <= 0.0 {
            return self.last;
        }
        let lo = self.params.omega_min;
        let hi = self.params.omega_max.max(lo);
        let cmd = rotor_cmd.map(|c| c.clamp(lo, hi));
        self.last_dist = *dist;

        let old = self.state.clone();
        let on_ground = self.mode == Mode::OnGround;
        let lift_off = on_ground && {
            let f = self.nongravity_force(&old, dist);
            f.z > self.total_mass() * self.params.g
        };

        let lag = self.params.rotor_lag;
        // The link direction to hold if the vehicle stays on the ground.
        let held_n = self.attached_probe().map(|p| p.link_direction());
        let mut probe = self.probe.clone();
        let mut new = match probe.as_mut().filter(|p| p.is_attached()) {
            Some(p) => {
                let x0 = pack_attached(&old, p, lag);
                let pp = *p.params();
                let x1 = rk4(&x0, dt, |x: &Vec23| {
                    self.derivative_attached(x, &cmd, dist, &pp)
                });
                p.set_link(
                    x1.fixed_rows::<3>(17).into_owned(),
                    x1.fixed_rows::<3>(20).into_owned(),
                );
                unpack(&x1.fixed_rows::<17>(0).into_owned(), lag)
            }
            None => {
                let x0 = pack(&old, lag);
                let x1 = rk4(&x0, dt, |x: &Vec17| self.derivative(x, &cmd, dist));
                unpack(&x1, lag)
            }
        };
        if let Some(p) = probe.as_mut() {
            p.advance_free(self.time, dt, self.params.g, &dist.wind);
        }
        if !new.is_finite() || !probe.as_ref().is_none_or(|p| p.is_finite()) {
            return self.crash(CrashReason::NonFinite, &old);
        }
        self.time += dt;
        self.probe = probe;

        if on_ground && (!lift_off || new.p.z <= 0.0) {
            // Held on the ground: only the rotors move.
            let mut held = old;
            held.p.z = 0.0;
            held.v = Vector3::zeros();
            held.w = Vector3::zeros();
            held.omega = new.omega;
            self.state = held;
            self.mode = Mode::OnGround;
            self.last = Contact::OnGround;
            if let (Some(p), Some(n)) = (self.probe.as_mut(), held_n) {
                p.set_link(n, Vector3::zeros());
            }
            self.note_probe_strike();
            return self.last;
        }

        if new.p.z < 0.0 {
            let (vs, hs, tilt) = impact(&new);
            let reason = if vs > MAX_TOUCHDOWN_VERTICAL_SPEED {
                Some(CrashReason::VerticalSpeed)
            } else if tilt > MAX_TOUCHDOWN_TILT {
                Some(CrashReason::Tilt)
            } else if hs > MAX_TOUCHDOWN_HORIZONTAL_SPEED {
                Some(CrashReason::HorizontalSpeed)
            } else {
                None
            };
            new.p.z = 0.0;
            if let Some(r) = reason {
                return self.crash(r, &new);
            }
            new.v = Vector3::zeros();
            new.w = Vector3::zeros();
            self.state = new;
            self.mode = Mode::OnGround;
            self.last = Contact::Touchdown {
                vertical_speed: vs,
                horizontal_speed: hs,
                tilt,
            };
            self.hold_probe();
            self.note_probe_strike();
            return self.last;
        }

        self.state = new;
        self.mode = Mode::Airborne;
        self.last = Contact::Airborne;
        self.note_probe_strike();
        self.last
    }

    /// Records a ground strike of the attached probe at the current time, if any.
    fn note_probe_strike(&mut self) {
        let (state, time) = (&self.state, self.time);
        if let Some(p) = self.probe.as_mut() {
            p.note_ground_strike(state, time);
        }
    }

    /// Freezes the plant in `at` with a crash of `reason`.
    fn crash(&mut self, reason: CrashReason, at: &QuadState) -> Contact {
        let (vertical_speed, horizontal_speed, tilt) = impact(at);
        let c = Contact::Crash {
            reason,
            vertical_speed,
            horizontal_speed,
            tilt,
            time: self.time,
        };
        self.state = at.clone();
        self.mode = Mode::Crashed(c);
        self.last = c;
        c
    }

    /// Time derivative of the packed state.
    fn derivative(&self, x: &Vec17, cmd: &[f64; 4], dist: &Disturbance) -> Vec17 {
        let prm = &self.params;
        let s = unpack(x, prm.rotor_lag);
        let vdot = self.nongravity_force(&s, dist) / prm.mass - Vector3::new(0.0, 0.0, prm.g);
        self.rigid_derivative(x, &s, cmd, dist, &vdot)
    }

    /// Time derivative of the packed vehicle and attached-probe state (probe parameters
    /// `pp`).
    fn derivative_attached(
        &self,
        x: &Vec23,
        cmd: &[f64; 4],
        dist: &Disturbance,
        pp: &ProbeParams,
    ) -> Vec23 {
        let xv: Vec17 = x.fixed_rows::<17>(0).into_owned();
        let s = unpack(&xv, self.params.rotor_lag);
        let n: Vector3<f64> = x.fixed_rows::<3>(17).into_owned();
        let nd: Vector3<f64> = x.fixed_rows::<3>(20).into_owned();
        let f = self.nongravity_force(&s, dist);
        let (vehicle, ndd, _) = self.coupled_link(&f, pp, &n, &nd);
        let dv = self.rigid_derivative(&xv, &s, cmd, dist, &vehicle);
        let mut d = Vec23::zeros();
        d.fixed_rows_mut::<17>(0).copy_from(&dv);
        d.fixed_rows_mut::<3>(17).copy_from(&nd);
        d.fixed_rows_mut::<3>(20).copy_from(&ndd);
        d
    }

    /// Time derivative of the vehicle's packed state `x` (unpacked: `s`) given its
    /// translational acceleration `vdot`.
    fn rigid_derivative(
        &self,
        x: &Vec17,
        s: &QuadState,
        cmd: &[f64; 4],
        dist: &Disturbance,
        vdot: &Vector3<f64>,
    ) -> Vec17 {
        let prm = &self.params;
        let qraw = Quaternion::new(x[6], x[7], x[8], x[9]);
        let thrusts = s.omega.map(|o| prm.k_thrust * o * o.abs());
        let qdot = qraw * Quaternion::new(0.0, s.w.x, s.w.y, s.w.z) * 0.5;

        let pos = prm.rotor_positions();
        let spin = prm.rotor_spin();
        let mut tau = dist.torque;
        for i in 0..4 {
            tau += pos[i].cross(&Vector3::new(0.0, 0.0, thrusts[i]));
            tau.z += spin[i] * prm.k_torque * thrusts[i];
        }
        let j = prm.inertia;
        let wdot = (tau - s.w.cross(&j.component_mul(&s.w))).component_div(&j);

        let mut d = Vec17::zeros();
        d.fixed_rows_mut::<3>(0).copy_from(&s.v);
        d.fixed_rows_mut::<3>(3).copy_from(vdot);
        d[6] = qdot.w;
        d[7] = qdot.i;
        d[8] = qdot.j;
        d[9] = qdot.k;
        d.fixed_rows_mut::<3>(10).copy_from(&wdot);
        match prm.rotor_lag {
            RotorLag::Speed => {
                for i in 0..4 {
                    d[13 + i] = (cmd[i] - s.omega[i]) / prm.rotor_tau;
                }
            }
            RotorLag::Thrust => {
                for i in 0..4 {
                    d[13 + i] = (cmd[i] * cmd[i].abs() - x[13 + i]) / prm.rotor_tau;
                }
            }
        }
        d
    }
}

/// (downward speed, horizontal speed, tilt) of a state.
fn impact(s: &QuadState) -> (f64, f64, f64) {
    (-s.v.z, s.v.xy().norm(), s.tilt())
}

/// One classical Runge-Kutta 4 step of `dt` from `x0` for `x' = f(x)`.
fn rk4<const N: usize>(
    x0: &SVector<f64, N>,
    dt: f64,
    f: impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
) -> SVector<f64, N> {
    let k1 = f(x0);
    let k2 = f(&(x0 + k1 * (0.5 * dt)));
    let k3 = f(&(x0 + k2 * (0.5 * dt)));
    let k4 = f(&(x0 + k3 * dt));
    x0 + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (dt / 6.0)
}

/// The vehicle state `s` followed by the link state of the attached probe `p`.
fn pack_attached(s: &QuadState, p: &Probe, lag: RotorLag) -> Vec23 {
    let mut x = Vec23::zeros();
    x.fixed_rows_mut::<17>(0).copy_from(&pack(s, lag));
    x.fixed_rows_mut::<3>(17).copy_from(&p.link_direction());
    x.fixed_rows_mut::<3>(20).copy_from(&p.link_rate());
    x
}

/// The packed state: position, velocity, attitude, rates and the rotors' lagged quantity
/// (the speed, or with [`RotorLag::Thrust`] the signed square of the speed).
fn pack(s: &QuadState, lag: RotorLag) -> Vec17 {
    let mut x = Vec17::zeros();
    x.fixed_rows_mut::<3>(0).copy_from(&s.p);
    x.fixed_rows_mut::<3>(3).copy_from(&s.v);
    let q = s.q.quaternion();
    x[6] = q.w;
    x[7] = q.i;
    x[8] = q.j;
    x[9] = q.k;
    x.fixed_rows_mut::<3>(10).copy_from(&s.w);
    for i in 0..4 {
        x[13 + i] = match lag {
            RotorLag::Speed => s.omega[i],
            RotorLag::Thrust => s.omega[i] * s.omega[i].abs(),
        };
    }
    x
}

/// The state packed by [`pack`].
fn unpack(x: &Vec17, lag: RotorLag) -> QuadState {
    let speed = |r: f64| match lag {
        RotorLag::Speed => r,
        RotorLag::Thrust => r.signum() * r.abs().sqrt(),
    };
    QuadState {
        p: x.fixed_rows::<3>(0).into_owned(),
        v: x.fixed_rows::<3>(3).into_owned(),
        q: UnitQuaternion::new_normalize(Quaternion::new(x[6], x[7], x[8], x[9])),
        w: x.fixed_rows::<3>(10).into_owned(),
        omega: [speed(x[13]), speed(x[14]), speed(x[15]), speed(x[16])],
    }
}
