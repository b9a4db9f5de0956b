//! `px4-sim`: a simulated PX4 for testing mpcc's PX4 shim (`firmware-shim`) without PX4;
//! `mpcc sitl` serves it on a MAVLink link. `docs/shim.md` says what it simulates and what
//! not.
//!
//! * [`commander`]: the simulated PX4's commander (PX4's offboard rules: OFFBOARD only while
//!   setpoints stream, arming checks, the offboard-loss failsafe, PX4's land detector and its
//!   automatic disarm in any mode, message intervals, TIMESYNC, SIH's parameters);
//! * [`vehicle`]: the simulated PX4 vehicle: the commander around the simulator's plant and
//!   rate loop (`mpc-sim`), flown by the offboard setpoint or by PX4-like position and
//!   attitude control (hold, land, return), sending PX4's messages in PX4's frames (the
//!   shim's `messages` and `frames`), with a record of the true flight; [`vehicle::serve`]
//!   puts it on a link in real time.

pub mod commander;
pub mod vehicle;
