//! The closed-loop log: one [`Sample`] per logging period (every inner-loop step).

use serde::Serialize;

use crate::controller::OuterStats;
use crate::vehicle::QuadState;

/// One row of the closed-loop log (and of the CSV file, in this column order).
///
/// Angles in rad, rates in rad/s, positions in m (world ENU), thrust in N. Solver columns are
/// NaN (an empty CSV cell) on rows where the outer loop did not run.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Sample {
    /// Simulation time \[s\].
    pub t: f64,
    /// Mission phase (index into [`crate::mission::Phase::ALL`]).
    pub phase: u8,
    /// Whether the return failsafe is active.
    pub failsafe: bool,
    /// Whether the pose estimate was available at this step.
    pub pose_valid: bool,
    /// True position x, y, z \[m\].
    pub x: f64,
    /// True position y \[m\].
    pub y: f64,
    /// True position z \[m\].
    pub z: f64,
    /// Position reference x \[m\].
    pub x_ref: f64,
    /// Position reference y \[m\].
    pub y_ref: f64,
    /// Position reference z \[m\].
    pub z_ref: f64,
    /// True velocity x [m/s].
    pub vx: f64,
    /// True velocity y [m/s].
    pub vy: f64,
    /// True velocity z [m/s].
    pub vz: f64,
    /// True attitude quaternion w (body to world).
    pub qw: f64,
    /// True attitude quaternion x.
    pub qx: f64,
    /// True attitude quaternion y.
    pub qy: f64,
    /// True attitude quaternion z.
    pub qz: f64,
    /// Accumulated pitch rotation since the flip began \[rad\] (integral of the body y rate).
    pub pitch_turned: f64,
    /// True body rate x (roll) [rad/s].
    pub wx: f64,
    /// True body rate y (pitch) [rad/s].
    pub wy: f64,
    /// True body rate z (yaw) [rad/s].
    pub wz: f64,
    /// Commanded body rate x [rad/s] (the outer loop's output).
    pub wx_cmd: f64,
    /// Commanded body rate y [rad/s].
    pub wy_cmd: f64,
    /// Commanded body rate z [rad/s].
    pub wz_cmd: f64,
    /// Mission's body-rate reference y (5*pi in the flip, else 0) [rad/s].
    pub wy_ref: f64,
    /// Commanded collective thrust \[N\].
    pub thrust_cmd: f64,
    /// Actual collective thrust of the four rotors \[N\].
    pub thrust: f64,
    /// Rotor 1 thrust \[N\] (numbering: see [`crate::vehicle::QuadParams::rotor_positions`]).
    pub f1: f64,
    /// Rotor 2 thrust \[N\].
    pub f2: f64,
    /// Rotor 3 thrust \[N\].
    pub f3: f64,
    /// Rotor 4 thrust \[N\].
    pub f4: f64,
    /// Outer-loop solver time of this step \[us\] (NaN when the outer loop did not run).
    pub solver_us: f64,
    /// QP iterations of this step (NaN when the outer loop did not run).
    pub qp_iterations: f64,
    /// Whether the solver fell back to the previous plan at this step.
    pub fallback: bool,
}

impl Sample {
    /// A row at time `t` with the true state `s`, the rotor thrusts `rotors` \[N\] and the
    /// outer loop's `stats` if it ran at this step; the mission and command columns are zero
    /// (set them with struct update syntax).
    pub fn at(t: f64, s: &QuadState, rotors: [f64; 4], stats: Option<OuterStats>) -> Self {
        Self {
            t,
            x: s.p.x,
            y: s.p.y,
            z: s.p.z,
            vx: s.v.x,
            vy: s.v.y,
            vz: s.v.z,
            qw: s.q.w,
            qx: s.q.i,
            qy: s.q.j,
            qz: s.q.k,
            wx: s.w.x,
            wy: s.w.y,
            wz: s.w.z,
            thrust: rotors.iter().sum(),
            f1: rotors[0],
            f2: rotors[1],
            f3: rotors[2],
            f4: rotors[3],
            solver_us: stats.map_or(f64::NAN, |s| s.solver_us),
            qp_iterations: stats.map_or(f64::NAN, |s| f64::from(s.qp_iterations)),
            fallback: stats.is_some_and(|s| s.fallback),
            ..Self::default()
        }
    }
}
