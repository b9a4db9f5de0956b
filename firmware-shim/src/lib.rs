//! `firmware-shim`: the bridge between an mpcc-generated solver and the PX4 autopilot, as
//! the paper flew it (a companion computer commanding PX4 in OFFBOARD), without ROS.
//! `mpcc fly` is built on it; `docs/shim.md` is the user's guide. The missions and the
//! controller it flies are `mpc-mission`'s (the simulator's); the simulated PX4 it is tested
//! against is `px4-sim` (`mpcc sitl`), the tests' fault-injecting relay `mav-relay`.
//!
//! * [`pilot`]: the controller loop: PX4's state in (ODOMETRY, or LOCAL_POSITION_NED +
//!   ATTITUDE_QUATERNION), the generated NMPC flying the simulator's missions, body-rate +
//!   thrust setpoints out, clocked by the vehicle, with latency compensation and the
//!   session's failsafes; [`pilot::run`] drives it on a link in real time;
//! * [`clock`]: the vehicle's clock (rate and offset from the states' timestamps, jumps) and
//!   the link's round trip (TIMESYNC);
//! * [`profile`]: the vehicle a mission flies (from PX4's SIH parameters or a profile file)
//!   and the flip planned for it;
//! * [`link`]: the offboard session as a state machine clocked by the caller: odometry rate,
//!   streaming before OFFBOARD, mode and arm commands with acknowledgements, retries and
//!   timeouts, landing at the end, and the failsafes (odometry lost, solver failures,
//!   operator abort, PX4 leaving OFFBOARD);
//! * [`messages`]: the MAVLink 2 (common dialect) messages of the offboard link, built and
//!   read with the `mavlink` crate;
//! * [`watch`]: the flight watch: on the ground (PX4's land detector, a stalled landing) and
//!   off the mission (far below or off the reference, inverted outside the flip, down
//!   before the landing);
//! * [`frames`]: PX4's NED world / FRD body frames against the models' ENU / FLU, for
//!   positions, velocities, quaternions and body rates;
//! * [`setpoint`]: the body-rate + collective-thrust setpoint PX4 takes, made safe (never
//!   non-finite, always in range) and mapped to PX4's normalized thrust with the vehicle's
//!   hover thrust;
//! * [`transport`]: the link (udpin, udpout, serial), with non-blocking reads and typed
//!   address errors; on UDP locked onto one peer by [`trust`], and signed by [`signing`]
//!   when given a key;
//! * [`trust`]: whom a UDP link listens to (the first PX4 HEARTBEAT's sender, relocked only
//!   after silence) and the count of everything else;
//! * [`signing`]: MAVLink 2 message signing: the key file, the check of every frame.

pub mod clock;
pub mod frames;
pub mod link;
pub mod messages;
pub mod pilot;
pub mod profile;
pub mod setpoint;
pub mod signing;
pub mod transport;
pub mod trust;
pub mod watch;

/// The linear-algebra crate of this crate's API.
pub use nalgebra;
