//! The MAVLink 2 messages of the offboard link (common dialect), built and read with the
//! `mavlink` crate; no packet code of our own.
//!
//! What PX4 (v1.16, observed on SITL; `docs/shim.md`) expects and sends:
//!
//! | direction | message | use |
//! | --- | --- | --- |
//! | out | HEARTBEAT (1 Hz) | the companion: type ONBOARD_CONTROLLER, autopilot INVALID |
//! | out | SET_ATTITUDE_TARGET | body rates (FRD, rad/s) + normalized thrust, type_mask 128 (attitude ignored; `q` identity) |
//! | out | COMMAND_LONG | arm/disarm (400), mode (176 with PX4's custom mode), message interval (511) |
//! | in | HEARTBEAT | armed flag and PX4's custom mode (main mode in bits 16-23, sub mode in 24-31) |
//! | in | ODOMETRY | position/velocity NED, attitude NED->FRD, body rates FRD, vehicle time |
//! | in | LOCAL_POSITION_NED + ATTITUDE_QUATERNION | the same when ODOMETRY is not streamed |
//! | in | EXTENDED_SYS_STATE | landed state |
//! | in | COMMAND_ACK | the answer to a COMMAND_LONG (PX4 may send it twice) |
//!
//! PX4 is system 1, component 1; its heartbeats are told apart by `autopilot == PX4 (12)`
//! and the sender's component (not 0). Everything here stays in PX4's frames (NED/FRD); the
//! conversion to the models' ENU/FLU is [`crate::frames`].

use mavlink::dialects::common::{
    self as mc, AttitudeTargetTypemask, MavAutopilot, MavCmd, MavFrame, MavLandedState, MavMessage,
    MavModeFlag, MavResult, MavState, MavType,
};
use mavlink::{MavHeader, MavlinkVersion};

/// PX4's system id.
pub const PX4_SYSTEM: u8 = 1;
/// PX4's autopilot component id.
pub const PX4_COMPONENT: u8 = 1;
/// Our component id: MAV_COMP_ID_ONBOARD_COMPUTER.
pub const COMPANION_COMPONENT: u8 = 191;
/// MAVLink message id of ODOMETRY (for MAV_CMD_SET_MESSAGE_INTERVAL).
pub const ODOMETRY_ID: u32 = 331;

/// PX4 main modes (`custom_mode` bits 16-23).
const MAIN_POSCTL: u8 = 3;
const MAIN_AUTO: u8 = 4;
const MAIN_OFFBOARD: u8 = 6;
/// PX4 AUTO sub modes (`custom_mode` bits 24-31).
const SUB_AUTO_RTL: u8 = 5;
const SUB_AUTO_LAND: u8 = 6;

/// A PX4 flight mode, as far as the shim cares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Px4Mode {
    /// OFFBOARD: our setpoints fly the vehicle.
    Offboard,
    /// AUTO.LAND.
    Land,
    /// AUTO.RTL (return).
    Return,
    /// POSCTL (position hold: PX4's offboard-loss fallback).
    Position,
    /// Anything else, as (main, sub).
    Other(u8, u8),
}

impl core::fmt::Display for Px4Mode {
    /// The mode as PX4's ground station names it ("OFFBOARD", "AUTO.RTL", ...).
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Px4Mode::Offboard => f.write_str("OFFBOARD"),
            Px4Mode::Land => f.write_str("AUTO.LAND"),
            Px4Mode::Return => f.write_str("AUTO.RTL"),
            Px4Mode::Position => f.write_str("POSCTL"),
            Px4Mode::Other(main, sub) => write!(f, "mode {main}.{sub}"),
        }
    }
}

impl Px4Mode {
    /// Decodes a HEARTBEAT `custom_mode`.
    pub fn from_custom_mode(custom_mode: u32) -> Self {
        let main = ((custom_mode >> 16) & 0xff) as u8;
        let sub = ((custom_mode >> 24) & 0xff) as u8;
        match (main, sub) {
            (MAIN_OFFBOARD, _) => Px4Mode::Offboard,
            (MAIN_AUTO, SUB_AUTO_LAND) => Px4Mode::Land,
            (MAIN_AUTO, SUB_AUTO_RTL) => Px4Mode::Return,
            (MAIN_POSCTL, _) => Px4Mode::Position,
            (m, s) => Px4Mode::Other(m, s),
        }
    }

    /// (main, sub) as MAV_CMD_DO_SET_MODE takes them (param2, param3).
    pub fn main_sub(self) -> (u8, u8) {
        match self {
            Px4Mode::Offboard => (MAIN_OFFBOARD, 0),
            Px4Mode::Land => (MAIN_AUTO, SUB_AUTO_LAND),
            Px4Mode::Return => (MAIN_AUTO, SUB_AUTO_RTL),
            Px4Mode::Position => (MAIN_POSCTL, 0),
            Px4Mode::Other(m, s) => (m, s),
        }
    }

    /// The HEARTBEAT `custom_mode` of this mode.
    pub fn custom_mode(self) -> u32 {
        let (m, s) = self.main_sub();
        (u32::from(m) << 16) | (u32::from(s) << 24)
    }
}

/// A command the shim sends with COMMAND_LONG.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// MAV_CMD_COMPONENT_ARM_DISARM, param1 = 1.
    Arm,
    /// MAV_CMD_COMPONENT_ARM_DISARM, param1 = 0.
    Disarm,
    /// MAV_CMD_DO_SET_MODE, param1 = 1 (custom mode enabled), param2/param3 = main/sub mode.
    SetMode(Px4Mode),
    /// MAV_CMD_SET_MESSAGE_INTERVAL: message id, rate \[Hz\].
    MessageInterval {
        /// The message id (e.g. 331 for ODOMETRY).
        message_id: u32,
        /// The rate \[Hz\] (> 0).
        hz: f32,
    },
}

impl Command {
    /// The MAV_CMD of this command (what its COMMAND_ACK names).
    pub fn mav_cmd(self) -> MavCmd {
        match self {
            Command::Arm | Command::Disarm => MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            Command::SetMode(_) => MavCmd::MAV_CMD_DO_SET_MODE,
            Command::MessageInterval { .. } => MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        }
    }
}

/// The companion's HEARTBEAT.
pub fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(mc::HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// PX4's hover thrust parameter: the normalized thrust of a hover, as configured (PX4's
/// hover-thrust estimator does not write it back: set it from a logged hover).
pub const HOVER_THRUST_PARAM: &str = "MPC_THR_HOVER";

/// PARAM_REQUEST_READ of the parameter `name` (at most 16 bytes) from PX4's autopilot.
pub fn param_request_read(name: &str) -> MavMessage {
    MavMessage::PARAM_REQUEST_READ(mc::PARAM_REQUEST_READ_DATA {
        param_index: -1,
        target_system: PX4_SYSTEM,
        target_component: PX4_COMPONENT,
        param_id: name.into(),
    })
}

/// Whether a NUL-padded parameter name is `name`.
pub fn param_name_is(padded: &[u8; 16], name: &str) -> bool {
    let len = padded.iter().position(|&b| b == 0).unwrap_or(padded.len());
    padded.get(..len) == Some(name.as_bytes())
}

/// TIMESYNC request (`tc1` = 0) stamped `ts1` \[ns, the companion's clock, > 0\]: PX4 answers
/// with its own time in `tc1` and `ts1` echoed.
pub fn timesync_request(ts1: i64) -> MavMessage {
    MavMessage::TIMESYNC(mc::TIMESYNC_DATA { tc1: 0, ts1 })
}

/// SET_ATTITUDE_TARGET with body rates `rates_frd` [rad/s] and normalized thrust in [0, 1];
/// the attitude is ignored (type_mask 128) and `q` is the identity, as PX4 wants it filled.
/// The values are sent as given: make them safe first ([`crate::setpoint`]).
pub fn set_attitude_target(rates_frd: [f32; 3], thrust: f32, time_boot_ms: u32) -> MavMessage {
    MavMessage::SET_ATTITUDE_TARGET(mc::SET_ATTITUDE_TARGET_DATA {
        time_boot_ms,
        q: [1.0, 0.0, 0.0, 0.0],
        body_roll_rate: rates_frd[0],
        body_pitch_rate: rates_frd[1],
        body_yaw_rate: rates_frd[2],
        thrust,
        target_system: PX4_SYSTEM,
        target_component: PX4_COMPONENT,
        type_mask: AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE,
    })
}

/// COMMAND_LONG for `cmd`; `confirmation` counts retransmissions (0 the first time).
pub fn command_long(cmd: Command, confirmation: u8) -> MavMessage {
    let (p1, p2, p3) = match cmd {
        Command::Arm => (1.0, 0.0, 0.0),
        Command::Disarm => (0.0, 0.0, 0.0),
        Command::SetMode(m) => {
            let (main, sub) = m.main_sub();
            // MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.
            (1.0, f32::from(main), f32::from(sub))
        }
        Command::MessageInterval { message_id, hz } => {
            let interval_us = if hz > 0.0 && hz.is_finite() {
                1e6 / hz
            } else {
                // -1: stop the message.
                -1.0
            };
            (message_id as f32, interval_us, 0.0)
        }
    };
    MavMessage::COMMAND_LONG(mc::COMMAND_LONG_DATA {
        param1: p1,
        param2: p2,
        param3: p3,
        param4: 0.0,
        param5: 0.0,
        param6: 0.0,
        param7: 0.0,
        command: cmd.mav_cmd(),
        target_system: PX4_SYSTEM,
        target_component: PX4_COMPONENT,
        confirmation,
    })
}

/// The vehicle's state as PX4 reports it, in PX4's frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdometryNed {
    /// Vehicle time \[us\] (clock the controller from it, not from wall time).
    pub time_us: u64,
    /// Position, NED \[m\].
    pub position: [f32; 3],
    /// Velocity, NED [m/s] (converted from FRD when PX4 sends it in the body frame).
    pub velocity: [f32; 3],
    /// Attitude NED -> FRD, [w, x, y, z].
    pub q: [f32; 4],
    /// Body rates, FRD [rad/s].
    pub rates: [f32; 3],
}

/// What an incoming message means to the shim.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Inbound {
    /// PX4's heartbeat.
    Heartbeat {
        /// Whether the vehicle is armed.
        armed: bool,
        /// PX4's mode.
        mode: Px4Mode,
    },
    /// ODOMETRY (or a matching LOCAL_POSITION_NED + ATTITUDE_QUATERNION pair, combined by
    /// the caller from [`Inbound::LocalPosition`] and [`Inbound::Attitude`]).
    Odometry(OdometryNed),
    /// LOCAL_POSITION_NED: time [ms since boot], position and velocity NED.
    LocalPosition {
        /// Time since boot \[ms\].
        time_boot_ms: u32,
        /// Position NED \[m\].
        position: [f32; 3],
        /// Velocity NED [m/s].
        velocity: [f32; 3],
    },
    /// ATTITUDE_QUATERNION: time [ms since boot], attitude NED -> FRD, body rates FRD.
    Attitude {
        /// Time since boot \[ms\].
        time_boot_ms: u32,
        /// [w, x, y, z].
        q: [f32; 4],
        /// Body rates FRD [rad/s].
        rates: [f32; 3],
    },
    /// EXTENDED_SYS_STATE's landed state.
    Landed(LandedState),
    /// PARAM_VALUE: a parameter's name (NUL-padded) and value (REAL32 parameters only).
    Param {
        /// The name, NUL-padded to 16 bytes.
        name: [u8; 16],
        /// The value.
        value: f32,
    },
    /// COMMAND_ACK.
    Ack {
        /// The command acknowledged.
        command: MavCmd,
        /// Whether PX4 accepted it.
        accepted: bool,
        /// Whether PX4 is still working on it (MAV_RESULT_IN_PROGRESS).
        in_progress: bool,
    },
    /// TIMESYNC answered by PX4 (`tc1` its time, `ts1` our request's) \[ns\].
    Timesync {
        /// PX4's time when it answered \[ns\].
        tc1: i64,
        /// The `ts1` of our request, echoed \[ns\].
        ts1: i64,
    },
    /// Not from PX4's autopilot, in a frame we do not use, or a message the shim ignores.
    Ignored,
}

/// EXTENDED_SYS_STATE's landed state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LandedState {
    /// Unknown.
    Undefined,
    /// On the ground.
    OnGround,
    /// Flying.
    InAir,
    /// Taking off.
    Takeoff,
    /// Landing.
    Landing,
}

fn rotate_frd_to_ned(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    // v_ned = q v_frd q*, q = [w, x, y, z] (NED -> FRD attitude, body to world).
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    let n = (w * w + x * x + y * y + z * z).sqrt();
    if !(n.is_finite() && n > 1e-6) {
        return [f32::NAN; 3];
    }
    let (w, x, y, z) = (w / n, x / n, y / n, z / n);
    let r = [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ];
    r.map(|row| row[0] * v[0] + row[1] * v[1] + row[2] * v[2])
}

/// Classifies a message received from `header`'s sender, PX4 being system [`PX4_SYSTEM`].
pub fn classify(header: &MavHeader, msg: &MavMessage) -> Inbound {
    classify_from(header, msg, PX4_SYSTEM)
}

/// The system id of a PX4 autopilot whose HEARTBEAT this is (autopilot PX4, component
/// [`PX4_COMPONENT`]): PX4 SITL's instance `i` is system `i + 1`.
pub fn px4_heartbeat_system(header: &MavHeader, msg: &MavMessage) -> Option<u8> {
    match msg {
        MavMessage::HEARTBEAT(h)
            if h.autopilot == MavAutopilot::MAV_AUTOPILOT_PX4
                && header.component_id == PX4_COMPONENT =>
        {
            Some(header.system_id)
        }
        _ => None,
    }
}

/// Addresses a message we send (setpoint, command, parameter request) to PX4's `system`.
pub fn retarget(msg: &mut MavMessage, system: u8) {
    match msg {
        MavMessage::SET_ATTITUDE_TARGET(m) => m.target_system = system,
        MavMessage::COMMAND_LONG(m) => m.target_system = system,
        MavMessage::PARAM_REQUEST_READ(m) => m.target_system = system,
        _ => {}
    }
}

/// [`classify`] for PX4 as system `system`: what comes from another system is ignored,
/// heartbeats included.
pub fn classify_from(header: &MavHeader, msg: &MavMessage, system: u8) -> Inbound {
    let from_px4 = header.system_id == system && header.component_id == PX4_COMPONENT;
    match msg {
        MavMessage::HEARTBEAT(h) => {
            if h.autopilot != MavAutopilot::MAV_AUTOPILOT_PX4
                || header.component_id == 0
                || header.system_id != system
            {
                return Inbound::Ignored;
            }
            Inbound::Heartbeat {
                armed: h
                    .base_mode
                    .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
                mode: Px4Mode::from_custom_mode(h.custom_mode),
            }
        }
        _ if !from_px4 => Inbound::Ignored,
        MavMessage::ODOMETRY(o) => {
            if o.frame_id != MavFrame::MAV_FRAME_LOCAL_NED {
                return Inbound::Ignored;
            }
            let velocity = match o.child_frame_id {
                MavFrame::MAV_FRAME_LOCAL_NED => [o.vx, o.vy, o.vz],
                MavFrame::MAV_FRAME_BODY_FRD => rotate_frd_to_ned(o.q, [o.vx, o.vy, o.vz]),
                _ => return Inbound::Ignored,
            };
            Inbound::Odometry(OdometryNed {
                time_us: o.time_usec,
                position: [o.x, o.y, o.z],
                velocity,
                q: o.q,
                rates: [o.rollspeed, o.pitchspeed, o.yawspeed],
            })
        }
        MavMessage::LOCAL_POSITION_NED(p) => Inbound::LocalPosition {
            time_boot_ms: p.time_boot_ms,
            position: [p.x, p.y, p.z],
            velocity: [p.vx, p.vy, p.vz],
        },
        MavMessage::ATTITUDE_QUATERNION(a) => Inbound::Attitude {
            time_boot_ms: a.time_boot_ms,
            q: [a.q1, a.q2, a.q3, a.q4],
            rates: [a.rollspeed, a.pitchspeed, a.yawspeed],
        },
        MavMessage::EXTENDED_SYS_STATE(s) => Inbound::Landed(match s.landed_state {
            MavLandedState::MAV_LANDED_STATE_ON_GROUND => LandedState::OnGround,
            MavLandedState::MAV_LANDED_STATE_IN_AIR => LandedState::InAir,
            MavLandedState::MAV_LANDED_STATE_TAKEOFF => LandedState::Takeoff,
            MavLandedState::MAV_LANDED_STATE_LANDING => LandedState::Landing,
            MavLandedState::MAV_LANDED_STATE_UNDEFINED => LandedState::Undefined,
        }),
        MavMessage::PARAM_VALUE(p) if p.param_type == mc::MavParamType::MAV_PARAM_TYPE_REAL32 => {
            Inbound::Param {
                name: p.param_id.into(),
                value: p.param_value,
            }
        }
        MavMessage::TIMESYNC(t) if t.tc1 > 0 => Inbound::Timesync {
            tc1: t.tc1,
            ts1: t.ts1,
        },
        MavMessage::COMMAND_ACK(a) => Inbound::Ack {
            command: a.command,
            accepted: a.result == MavResult::MAV_RESULT_ACCEPTED,
            in_progress: a.result == MavResult::MAV_RESULT_IN_PROGRESS,
        },
        _ => Inbound::Ignored,
    }
}

/// A message that could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum MessageError {
    /// The bytes are not one CRC-valid MAVLink 2 frame of the common dialect.
    #[error("not a valid MAVLink 2 common-dialect frame: {0}")]
    Decode(String),
    /// Writing the frame failed.
    #[error("cannot encode MAVLink frame: {0}")]
    Encode(String),
}

/// The header of a message we send: our system id, the companion component, `sequence`.
pub fn our_header(system_id: u8, sequence: u8) -> MavHeader {
    MavHeader {
        system_id,
        component_id: COMPANION_COMPONENT,
        sequence,
    }
}

/// One MAVLink 2 frame of `msg` with `header`.
///
/// # Errors
/// [`MessageError::Encode`] if the crate cannot serialize it.
pub fn encode(header: MavHeader, msg: &MavMessage) -> Result<Vec<u8>, MessageError> {
    let mut out = Vec::with_capacity(280);
    mavlink::write_v2_msg(&mut out, header, msg)
        .map_err(|e| MessageError::Encode(e.to_string()))?;
    Ok(out)
}

/// The first CRC-valid MAVLink 2 frame in `bytes`.
///
/// # Errors
/// [`MessageError::Decode`] if there is none.
pub fn decode(bytes: &[u8]) -> Result<(MavHeader, MavMessage), MessageError> {
    let mut reader = mavlink::MavlinkReader::new(bytes);
    reader
        .read_message::<MavMessage>(MavlinkVersion::V2)
        .map_err(|e| MessageError::Decode(e.to_string()))
}
