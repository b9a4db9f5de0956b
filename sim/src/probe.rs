//! The tethered probe: a point mass on a rigid massless link hanging from the vehicle's centre
//! of gravity, fully coupled to the vehicle while attached, then a ballistic body after release.
//!
//! # Model
//!
//! The probe is a point mass `mp` ([`ProbeParams::mass`]) at the end of a rigid massless link
//! of length `l` ([`ProbeParams::length`]). The link is attached at the vehicle's centre of
//! gravity by a free pivot: it transmits a force along the link (the tension) and no torque,
//! so the attitude, body-rate and rotor dynamics of [`crate::plant`] are unchanged. Two swing
//! angles `theta = (alpha, beta)` give the link direction (unit vector, vehicle to probe),
//! world frame ENU with z up:
//!
//! ```text
//! n(a, b)   = ( sin a cos b,  sin b,  -cos a cos b)     straight down at a = b = 0
//! n_a = dn/da = ( cos a cos b,  0,      sin a cos b)
//! n_b = dn/db = (-sin a sin b,  cos b,  cos a sin b)
//! Pl  = P + l n,   Pl' = P' + l (n_a a' + n_b b'),   |n'|^2 = cos^2 b a'^2 + b'^2
//! ```
//!
//! `alpha` swings the probe towards world +x (in the x-z plane), `beta` towards world +y.
//!
//! # Equations while attached
//!
//! With `F` the vehicle's non-gravitational world force (thrust, drag and disturbance force,
//! as in [`crate::plant`]), the vehicle mass `mq`, `M = mq + mp` and gravity `-g e3`, the
//! Lagrangian `1/2 mq |P'|^2 + 1/2 mp |Pl'|^2 - mq g z - mp g zl` gives
//! (derivation in the header of `models/quadrotor_probe.mpc`):
//!
//! ```text
//! b      = F - mq g e3 - mp (g n_z - l |n'|^2) n
//! P''    = (b - mp/M (n.b) n) / mq             Sherman-Morrison inverse of (mq I + mp n n^T)
//!        = F/mq - g e3 + (lambda/mq) n          (the form evaluated here)
//! lambda = mp (mq l |n'|^2 - n.F) / M           link tension; the vehicle feels lambda n
//! a''    = -n_a.(P'' + g e3) / (l cos^2 b) + 2 tan b a' b'
//! b''    = -n_b.(P'' + g e3) / l - sin b cos b a'^2
//! ```
//!
//! The swing equations ([`swing_acceleration`]) say that the probe's acceleration plus
//! gravity lies along the link. `lambda > 0` pulls the vehicle towards the probe (a hanging
//! probe in hover: `lambda = mp g`). The accelerometer of the vehicle measures
//! `(F + lambda n) / mq`. With `mp = 0` the vehicle's acceleration is computed exactly as
//! without a probe (the tension term is skipped, so the result is bit-identical) and the
//! angles follow the vehicle as a massless pendulum.
//!
//! Air drag on the probe is **not** modelled while it is attached (the seed paper's
//! equations); [`ProbeParams::drag`] acts only in free flight.
//!
//! # Singularity, and the state the plant keeps
//!
//! The two-angle parametrisation is singular at `|beta| = pi/2` (the link along world +-y:
//! `alpha` is then undefined and `a''` divides by `cos^2 b`). The plant therefore does not
//! integrate the angles: it keeps the link direction `n` itself and its rate `n'` (six
//! numbers for two degrees of freedom), whose equation has no singularity
//! ([`link_acceleration`]):
//!
//! ```text
//! n'' = -(I - n n^T) (P'' + g e3) / l - |n'|^2 n
//! ```
//!
//! (the tangential part says the probe's acceleration plus gravity is along the link, the
//! normal part is `d^2/dt^2 |n|^2 = 0`). After each step `n` is normalized and `n'` made
//! tangent again, which removes the integrator's drift from `|n| = 1`. The angles
//! ([`Probe::ang`], [`Probe::dang`]) are computed from `n` and `n'` when asked for: they are
//! what an encoder on a two-axis gimbal reads, and the rates are singular where the angles
//! are. A controller that uses the angles works in a frame where `beta` stays small (the
//! flip-and-throw mission's throw frame, `crate::throw`).
//!
//! # Phases
//!
//! * [`ProbePhase::Attached`]: integrated with the vehicle in the same RK4 step (23 states:
//!   the vehicle's 17 plus `n` and `n'`). If the probe goes below the ground
//!   plane while attached, the time is recorded ([`Probe::struck_ground_attached`]) and the
//!   dynamics continue (there is no ground contact for the attached probe). While the vehicle
//!   is held on the ground, the swing angles are held and the swing rates are zero.
//! * [`ProbePhase::Free`]: after [`crate::plant::Plant::release_probe`] the probe keeps its
//!   position and velocity and flies ballistically, independent of the vehicle, under gravity
//!   and the quadratic drag `-drag |v - wind| (v - wind)` (`wind` of the step's
//!   disturbance; in still air `-drag |v| v`), advanced by its own RK4 step within each plant
//!   step. A massless free probe ignores drag.
//! * [`ProbePhase::Landed`]: when the free probe reaches `z <= 0` during a step, the landing
//!   point is interpolated inside that step and the probe stops there. Without drag the
//!   crossing is exact: the step starts at `(p0, v0)` under the constant acceleration
//!   `-g e3` (which RK4 integrates exactly), so the crossing time is the positive root `tau`
//!   of `z0 + vz0 tau - g tau^2 / 2 = 0` and the landing point is `p0 + v0 tau`. With drag,
//!   the RK4 step is interpolated linearly between its end points (error `O(dt^2)`, below
//!   1e-6 m at 1 kHz for the default probe). The landing position has `z = 0` exactly.
//!
//! Once the vehicle has crashed, the plant (probe included) is frozen.

use mpc_mission::vehicle::QuadState;
use nalgebra::Vector3;

/// Physical parameters of the probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeParams {
    /// Probe mass, kg (`>= 0`).
    pub mass: f64,
    /// Link length, pivot (vehicle centre of gravity) to probe, m (`> 0`).
    pub length: f64,
    /// Quadratic air-drag coefficient of the free probe, N/(m/s)^2 (`>= 0`): the drag force
    /// is `-drag |v_air| v_air`. Not applied while attached.
    pub drag: f64,
}

impl Default for ProbeParams {
    /// The seed paper's probe: 0.2 kg on a 0.5 m link, no drag.
    fn default() -> Self {
        Self {
            mass: 0.2,
            length: 0.5,
            drag: 0.0,
        }
    }
}

impl ProbeParams {
    /// Whether the parameters are usable: all finite, `mass >= 0`, `length > 0`,
    /// `drag >= 0`.
    pub fn is_valid(&self) -> bool {
        self.mass.is_finite()
            && self.length.is_finite()
            && self.drag.is_finite()
            && self.mass >= 0.0
            && self.length > 0.0
            && self.drag >= 0.0
    }
}

/// Link direction `n(alpha, beta)`, the unit vector from the vehicle to the probe, world
/// frame: `(sin a cos b, sin b, -cos a cos b)`.
pub fn link_direction(ang: [f64; 2]) -> Vector3<f64> {
    let [a, b] = ang;
    let (sa, ca) = a.sin_cos();
    let (sb, cb) = b.sin_cos();
    Vector3::new(sa * cb, sb, -ca * cb)
}

/// Partial derivatives `(n_a, n_b) = (dn/dalpha, dn/dbeta)` of [`link_direction`]:
/// `n_a = (cos a cos b, 0, sin a cos b)`, `n_b = (-sin a sin b, cos b, cos a sin b)`.
pub fn link_jacobian(ang: [f64; 2]) -> (Vector3<f64>, Vector3<f64>) {
    let [a, b] = ang;
    let (sa, ca) = a.sin_cos();
    let (sb, cb) = b.sin_cos();
    (
        Vector3::new(ca * cb, 0.0, sa * cb),
        Vector3::new(-sa * sb, cb, ca * sb),
    )
}

/// `|n'|^2 = cos^2 b a'^2 + b'^2`, the squared rate of the link direction.
fn link_rate_squared(ang: [f64; 2], dang: [f64; 2]) -> f64 {
    let cb = ang[1].cos();
    let [da, db] = dang;
    cb * cb * da * da + db * db
}

/// Swing accelerations `(alpha'', beta'')` of a pendulum of length `l` whose pivot
/// accelerates by `pivot_acc` (world frame, m/s^2) under gravity `-g e3`:
///
/// ```text
/// a'' = -n_a.(pivot_acc + g e3) / (l cos^2 b) + 2 tan b a' b'
/// b'' = -n_b.(pivot_acc + g e3) / l - sin b cos b a'^2
/// ```
///
/// `pivot_acc = 0` is the fixed-pivot spherical pendulum. Singular at `|beta| = pi/2` (see
/// the [module documentation](self)).
pub fn swing_acceleration(
    ang: [f64; 2],
    dang: [f64; 2],
    pivot_acc: &Vector3<f64>,
    g: f64,
    l: f64,
) -> [f64; 2] {
    let (na, nb) = link_jacobian(ang);
    let (sb, cb) = ang[1].sin_cos();
    let [da, db] = dang;
    let gacc = pivot_acc + Vector3::new(0.0, 0.0, g);
    [
        -na.dot(&gacc) / (l * cb * cb) + 2.0 * (sb / cb) * da * db,
        -nb.dot(&gacc) / l - sb * cb * da * da,
    ]
}

/// Accelerations of the coupled vehicle and attached probe, see [`coupled_acceleration`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoupledAcceleration {
    /// Vehicle (pivot) acceleration `P''`, world frame, m/s^2.
    pub vehicle: Vector3<f64>,
    /// Swing accelerations `(alpha'', beta'')`, rad/s^2.
    pub swing: [f64; 2],
    /// Link tension `lambda`, N: the link pulls the vehicle with `lambda n` and the probe
    /// with `-lambda n` (`lambda > 0`: taut, pulling the vehicle towards the probe).
    pub tension: f64,
}

/// The coupled accelerations of a vehicle of mass `vehicle_mass` under the
/// non-gravitational world force `force` and an attached probe at swing angles `ang` and
/// rates `dang` (see the [module documentation](self) for the equations).
///
/// With `params.mass == 0` the vehicle acceleration is `force / vehicle_mass - g e3`,
/// computed exactly as by the plant without a probe.
pub fn coupled_acceleration(
    force: &Vector3<f64>,
    vehicle_mass: f64,
    g: f64,
    params: &ProbeParams,
    ang: [f64; 2],
    dang: [f64; 2],
) -> CoupledAcceleration {
    let (mq, mp, l) = (vehicle_mass, params.mass, params.length);
    let n = link_direction(ang);
    let tension = mp * (mq * l * link_rate_squared(ang, dang) - n.dot(force)) / (mq + mp);
    let mut vehicle = force / mq - Vector3::new(0.0, 0.0, g);
    if mp != 0.0 {
        vehicle += n * (tension / mq);
    }
    let swing = swing_acceleration(ang, dang, &vehicle, g, l);
    CoupledAcceleration {
        vehicle,
        swing,
        tension,
    }
}

/// Swing angles `(alpha, beta)` of a link direction `n` (the inverse of
/// [`link_direction`]; `n` need not be normalized): `alpha = atan2(n_x, -n_z)`,
/// `beta = atan2(n_y, |(n_x, n_z)|)`.
pub fn swing_angles(n: &Vector3<f64>) -> [f64; 2] {
    [n.x.atan2(-n.z), n.y.atan2(n.x.hypot(n.z))]
}

/// Swing rates `(alpha', beta')` of a link moving at `nd = n'` at the swing angles `ang`:
/// `n' = n_a alpha' + n_b beta'` with `n_a . n_b = 0`, `|n_a|^2 = cos^2 b`, `|n_b| = 1`.
/// Singular at `|beta| = pi/2`, like the angles.
pub fn swing_rates(ang: [f64; 2], nd: &Vector3<f64>) -> [f64; 2] {
    let (na, nb) = link_jacobian(ang);
    let cb = ang[1].cos();
    [na.dot(nd) / (cb * cb), nb.dot(nd)]
}

/// The link's rate `n' = n_a alpha' + n_b beta'` at swing angles `ang` and rates `dang`.
pub fn link_rate(ang: [f64; 2], dang: [f64; 2]) -> Vector3<f64> {
    let (na, nb) = link_jacobian(ang);
    na * dang[0] + nb * dang[1]
}

/// The link's acceleration `n''` for a unit link direction `n` moving at `nd`, of a pendulum
/// of length `l` whose pivot accelerates by `pivot_acc` under gravity `-g e3`:
/// `n'' = -(I - n n^T)(pivot_acc + g e3) / l - |n'|^2 n`. No singularity (the plant's
/// equation; [`swing_acceleration`] is the same in angles).
pub fn link_acceleration(
    n: &Vector3<f64>,
    nd: &Vector3<f64>,
    pivot_acc: &Vector3<f64>,
    g: f64,
    l: f64,
) -> Vector3<f64> {
    let gacc = pivot_acc + Vector3::new(0.0, 0.0, g);
    let tangential = gacc - n * n.dot(&gacc);
    -tangential / l - n * nd.norm_squared()
}

/// The coupled accelerations in the plant's coordinates: as [`coupled_acceleration`], for
/// the link direction `n` and its rate `nd`; the swing part is `n''` ([`link_acceleration`]).
pub fn coupled_link_acceleration(
    force: &Vector3<f64>,
    vehicle_mass: f64,
    g: f64,
    params: &ProbeParams,
    n: &Vector3<f64>,
    nd: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>, f64) {
    let (mq, mp, l) = (vehicle_mass, params.mass, params.length);
    let tension = mp * (mq * l * nd.norm_squared() - n.dot(force)) / (mq + mp);
    let mut vehicle = force / mq - Vector3::new(0.0, 0.0, g);
    if mp != 0.0 {
        vehicle += n * (tension / mq);
    }
    let link = link_acceleration(n, nd, &vehicle, g, l);
    (vehicle, link, tension)
}

/// Phase of the probe's flight.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProbePhase {
    /// On the link, swinging under the vehicle.
    Attached,
    /// Released, flying ballistically.
    Free,
    /// On the ground (`z = 0`), no longer moving.
    Landed,
}

/// The release of the probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Release {
    /// Simulated time of the release, s.
    pub time: f64,
    /// Probe position at the release, world frame, m.
    pub position: Vector3<f64>,
    /// Probe velocity at the release, world frame, m/s.
    pub velocity: Vector3<f64>,
    /// Vehicle velocity at the release, world frame, m/s (unchanged by the release).
    pub vehicle_velocity: Vector3<f64>,
}

/// The landing of the free probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landing {
    /// Simulated time of the ground crossing (interpolated inside the step), s.
    pub time: f64,
    /// Landing point, world frame, m, with `z = 0` exactly.
    pub position: Vector3<f64>,
}

/// A tethered probe: its parameters, phase, state and event records. Held by
/// [`crate::plant::Plant`] (see [`crate::plant::Plant::attach_probe`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Probe {
    params: ProbeParams,
    phase: ProbePhase,
    /// Link direction, vehicle to probe (unit); the values at the release once released.
    n: Vector3<f64>,
    /// Its rate `n'` (tangent: `n . n' = 0`).
    nd: Vector3<f64>,
    /// Free-flight position (landing point once landed); unused while attached.
    pos: Vector3<f64>,
    /// Free-flight velocity (zero once landed); unused while attached.
    vel: Vector3<f64>,
    start: Vector3<f64>,
    release: Option<Release>,
    landing: Option<Landing>,
    struck: Option<f64>,
}

impl Probe {
    /// An attached probe on `vehicle` at simulated time `time`.
    pub(crate) fn attached(
        params: ProbeParams,
        ang: [f64; 2],
        dang: [f64; 2],
        vehicle: &QuadState,
        time: f64,
    ) -> Self {
        let mut probe = Self {
            params,
            phase: ProbePhase::Attached,
            n: link_direction(ang),
            nd: link_rate(ang, dang),
            pos: Vector3::zeros(),
            vel: Vector3::zeros(),
            start: Vector3::zeros(),
            release: None,
            landing: None,
            struck: None,
        };
        probe.start = probe.position(vehicle);
        probe.note_ground_strike(vehicle, time);
        probe
    }

    /// The probe's parameters.
    pub fn params(&self) -> &ProbeParams {
        &self.params
    }

    /// Current phase.
    pub fn phase(&self) -> ProbePhase {
        self.phase
    }

    /// Whether the probe is on the link ([`ProbePhase::Attached`]).
    pub fn is_attached(&self) -> bool {
        self.phase == ProbePhase::Attached
    }

    /// Swing angles `(alpha, beta)`, rad, of the link direction ([`swing_angles`]).
    /// Meaningful while attached; afterwards the values at the release.
    pub fn ang(&self) -> [f64; 2] {
        swing_angles(&self.n)
    }

    /// Swing rates `(alpha', beta')`, rad/s ([`swing_rates`]; not finite at
    /// `|beta| = pi/2`). Meaningful while attached; afterwards the values at the release.
    pub fn dang(&self) -> [f64; 2] {
        swing_rates(self.ang(), &self.nd)
    }

    /// Link direction `n` (unit, vehicle to probe, world frame).
    pub fn link_direction(&self) -> Vector3<f64> {
        self.n
    }

    /// The link direction's rate `n'`, world frame, 1/s.
    pub fn link_rate(&self) -> Vector3<f64> {
        self.nd
    }

    /// Probe position, world frame, m, in every phase: `P + l n` while attached (with the
    /// vehicle state `vehicle`), the free-flight position, or the landing point.
    pub fn position(&self, vehicle: &QuadState) -> Vector3<f64> {
        match self.phase {
            ProbePhase::Attached => vehicle.p + self.n * self.params.length,
            ProbePhase::Free | ProbePhase::Landed => self.pos,
        }
    }

    /// Probe velocity, world frame, m/s, in every phase: `P' + l n'` while attached, the
    /// free-flight velocity, or zero once landed.
    pub fn velocity(&self, vehicle: &QuadState) -> Vector3<f64> {
        match self.phase {
            ProbePhase::Attached => vehicle.v + self.nd * self.params.length,
            ProbePhase::Free => self.vel,
            ProbePhase::Landed => Vector3::zeros(),
        }
    }

    /// The probe's world position when it was attached, m.
    pub fn start(&self) -> Vector3<f64> {
        self.start
    }

    /// The release, once released.
    pub fn release(&self) -> Option<Release> {
        self.release
    }

    /// The landing, once landed.
    pub fn landing(&self) -> Option<Landing> {
        self.landing
    }

    /// Simulated time (s) at the end of the first step after which the probe, still
    /// attached, was below the ground plane `z = 0` (or the time of attachment if it was
    /// attached there). The dynamics continue regardless; a mission treats it as a failure.
    pub fn struck_ground_attached(&self) -> Option<f64> {
        self.struck
    }

    /// Whether every state component is finite.
    pub fn is_finite(&self) -> bool {
        self.n.iter().chain(self.nd.iter()).all(|x| x.is_finite())
            && self
                .pos
                .iter()
                .chain(self.vel.iter())
                .all(|x| x.is_finite())
    }

    /// Replaces the swing state (attached probe) with the link direction `n` (normalized
    /// here) and its rate `nd` (its component along `n` removed): the constraint `|n| = 1`
    /// and its derivative hold again after an integration step.
    pub(crate) fn set_link(&mut self, n: Vector3<f64>, nd: Vector3<f64>) {
        let n = n.normalize();
        self.nd = nd - n * n.dot(&nd);
        self.n = n;
    }

    /// Records a ground strike at `time` if the attached probe is below the ground and none
    /// was recorded before.
    pub(crate) fn note_ground_strike(&mut self, vehicle: &QuadState, time: f64) {
        if self.struck.is_none() && self.is_attached() && self.position(vehicle).z < 0.0 {
            self.struck = Some(time);
        }
    }

    /// Releases an attached probe at `time` (keeping its position and velocity); `None` if
    /// it is not attached.
    pub(crate) fn release_at(&mut self, vehicle: &QuadState, time: f64) -> Option<Release> {
        if !self.is_attached() {
            return None;
        }
        let r = Release {
            time,
            position: self.position(vehicle),
            velocity: self.velocity(vehicle),
            vehicle_velocity: vehicle.v,
        };
        self.pos = r.position;
        self.vel = r.velocity;
        self.phase = ProbePhase::Free;
        self.release = Some(r);
        Some(r)
    }

    /// Free-flight acceleration at velocity `v`: gravity plus quadratic drag on the
    /// air-relative velocity.
    fn free_acceleration(&self, v: &Vector3<f64>, g: f64, wind: &Vector3<f64>) -> Vector3<f64> {
        let mut a = Vector3::new(0.0, 0.0, -g);
        let k = self.drag_per_mass();
        if k > 0.0 {
            let v_air = v - wind;
            a -= v_air * (k * v_air.norm());
        }
        a
    }

    /// `drag / mass`, 0 without drag or for a massless probe.
    fn drag_per_mass(&self) -> f64 {
        if self.params.drag > 0.0 && self.params.mass > 0.0 {
            self.params.drag / self.params.mass
        } else {
            0.0
        }
    }

    /// Advances a free probe by one RK4 step of `dt` starting at simulated time `t0`, and
    /// lands it if it reaches `z <= 0` (see the [module documentation](self)). Does
    /// nothing in the other phases.
    pub(crate) fn advance_free(&mut self, t0: f64, dt: f64, g: f64, wind: &Vector3<f64>) {
        if self.phase != ProbePhase::Free {
            return;
        }
        let (p0, v0) = (self.pos, self.vel);
        if p0.z <= 0.0 {
            self.land(t0, Vector3::new(p0.x, p0.y, 0.0));
            return;
        }
        let a1 = self.free_acceleration(&v0, g, wind);
        let v2 = v0 + a1 * (0.5 * dt);
        let a2 = self.free_acceleration(&v2, g, wind);
        let v3 = v0 + a2 * (0.5 * dt);
        let a3 = self.free_acceleration(&v3, g, wind);
        let v4 = v0 + a3 * dt;
        let a4 = self.free_acceleration(&v4, g, wind);
        let p1 = p0 + (v0 + v2 * 2.0 + v3 * 2.0 + v4) * (dt / 6.0);
        let v1 = v0 + (a1 + a2 * 2.0 + a3 * 2.0 + a4) * (dt / 6.0);
        if p1.z > 0.0 {
            self.pos = p1;
            self.vel = v1;
            return;
        }
        let (tau, at) = if self.drag_per_mass() == 0.0 {
            // Constant acceleration -g e3: the exact crossing of z0 + vz tau - g tau^2/2 = 0,
            // each root formula used where it does not cancel.
            let (z0, vz) = (p0.z, v0.z);
            let disc = (vz * vz + 2.0 * g * z0).max(0.0).sqrt();
            let tau = if vz <= 0.0 {
                let den = disc - vz;
                if den > 0.0 { 2.0 * z0 / den } else { 0.0 }
            } else if g > 0.0 {
                (vz + disc) / g
            } else {
                dt
            };
            let tau = tau.clamp(0.0, dt);
            (tau, p0 + v0 * tau)
        } else {
            // Linear interpolation of the RK4 step.
            let s = (p0.z / (p0.z - p1.z)).clamp(0.0, 1.0);
            (s * dt, p0 + (p1 - p0) * s)
        };
        self.land(t0 + tau, Vector3::new(at.x, at.y, 0.0));
    }

    fn land(&mut self, time: f64, position: Vector3<f64>) {
        self.pos = position;
        self.vel = Vector3::zeros();
        self.phase = ProbePhase::Landed;
        self.landing = Some(Landing { time, position });
    }
}
