//! `firmware-shim`: the bridge between an mpcc-generated solver and the PX4 autopilot.
//!
//! Work in progress (issue 9). What is here:
//!
//! * [`frames`]: conversions between PX4's NED world frame / FRD body frame and the models'
//!   ENU / FLU, for positions, velocities, quaternions and body rates;
//! * [`setpoint`]: the body-rate + collective-thrust setpoint PX4 takes, made safe (never
//!   non-finite, always in range) and mapped to PX4's normalized thrust with a calibrated
//!   hover-thrust parameter;
//! * [`messages`]: the MAVLink 2 (common dialect) messages of the offboard link, built and
//!   read with the `mavlink` crate: HEARTBEAT, SET_ATTITUDE_TARGET, COMMAND_LONG (arm, mode,
//!   land, return) and the state PX4 sends (ODOMETRY, LOCAL_POSITION_NED,
//!   ATTITUDE_QUATERNION, EXTENDED_SYS_STATE, HEARTBEAT with PX4's custom mode);
//! * [`link`]: the offboard session as a state machine clocked by the caller: streaming
//!   before OFFBOARD, mode and arm commands with acknowledgements, retries and timeouts,
//!   and the failsafes (odometry lost, solver failures, operator abort, PX4 leaving
//!   OFFBOARD).
//!
//! * [`transport`]: the link (udpin, udpout, serial) through `mavlink::connect`, with
//!   non-blocking reads and typed address errors.
//!
//! * [`sitl`]: the simulated PX4's commander (PX4's offboard rules: OFFBOARD only while
//!   setpoints stream, arming checks, the offboard-loss failsafe, automatic disarm after an
//!   AUTO landing, double acknowledgement of mode changes), for `mpcc sitl`.
//!
//! * [`vehicle`]: the simulated PX4 vehicle: the commander around the simulator's plant and
//!   rate loop, flown by the offboard setpoint or by a PX4-like position controller (hold,
//!   land, return), sending ODOMETRY, HEARTBEAT and EXTENDED_SYS_STATE in PX4's frames.
//!
//! Not yet: the UDP endpoint around the vehicle (`mpcc sitl`), the controller loop that
//! ties the session to a generated solver, `mpcc fly`.

pub mod frames;
pub mod link;
pub mod messages;
pub mod pilot;
pub mod relay;
pub mod setpoint;
pub mod sitl;
pub mod transport;
pub mod vehicle;

/// The linear-algebra crate of this crate's API.
pub use nalgebra;
