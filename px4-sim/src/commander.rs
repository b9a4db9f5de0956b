//! The simulated PX4's commander: PX4's offboard rules as a state machine clocked by the
//! caller, for `mpcc sitl` (the vehicle around it, physics and streams, is
//! [`crate::vehicle`]). It decides what PX4 would: which mode it is in, whether it is armed,
//! which commands it accepts (and acknowledges, twice for a mode change as PX4 v1.16 did), and when
//! it leaves OFFBOARD because the setpoint stream stopped.
//!
//! Rules (PX4 v1.16 as observed on SITL, `docs/shim.md`, and PX4's commander):
//!
//! * OFFBOARD is accepted only while setpoints stream: the last valid SET_ATTITUDE_TARGET
//!   (finite, thrust in [0, 1], attitude ignored) is younger than
//!   [`CommanderConfig::offboard_loss_timeout`]; otherwise the mode command is
//!   TEMPORARILY_REJECTED.
//! * Arming needs a valid pose and the vehicle landed; disarming needs it landed (no forced
//!   disarm here). "Landed" is the verdict of PX4's land detector ([`LandDetector`]), which
//!   the vehicle around the commander runs and reports in [`VehicleStatus::landed`].
//! * In OFFBOARD, a stream silent for longer than the offboard-loss timeout (0.5 s here, the
//!   issue's figure; PX4's COM_OF_LOSS_T defaults to 1.0 s) is a failsafe: position hold
//!   (POSCTL, COM_OBL_RC_ACT = 0) with the failsafe flagged.
//! * Once the vehicle has taken off (the land detector said airborne since arming), PX4
//!   disarms on its own when the land detector has said landed for
//!   [`CommanderConfig::disarm_land_delay`] (COM_DISARM_LAND, 2 s), in any mode, OFFBOARD
//!   included (commander's `checkForAutoDisarm`; seen on PX4 v1.16 SITL).
//! * The mode shows in the 1 Hz HEARTBEAT (`custom_mode`), so a client sees it late.
//! * [`LandDetector`]: PX4's `MulticopterLandDetector` (ground contact, maybe landed,
//!   landed, each a third of LNDMC_TRIG_TIME) on the estimate and the commanded thrust.
//! * MAV_CMD_SET_MESSAGE_INTERVAL (511) sets the rate of the messages the simulated vehicle
//!   streams ([`STREAMED_MESSAGES`]) as PX4's mavlink module does (`set_message_interval`):
//!   param1 the message id (rounded), param2 the interval \[us\] (negative: stop, 0: the
//!   default rate, positive: that interval); the vehicle reads the result with
//!   [`Commander::message_interval`]. PX4 answers MAV_RESULT_FAILED for HEARTBEAT, for a
//!   message it cannot stream, and for a non-zero param3, param4 or param7 (unsupported
//!   options); so does this commander, for any message outside [`STREAMED_MESSAGES`]
//!   (PX4 itself knows many more streams, e.g. ATTITUDE or HIGHRES_IMU, which this
//!   simulation does not produce). A single ACK, as PX4 sends for this command.

use firmware_shim::messages::Px4Mode;
use mavlink::MessageData;
use mavlink::dialects::common::{
    self as mc, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState, MavType,
};

/// Timing of the simulated PX4.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommanderConfig {
    /// A stream silent this long ends OFFBOARD \[s\].
    pub offboard_loss_timeout: f64,
    /// HEARTBEAT period \[s\].
    pub heartbeat_period: f64,
    /// After a take-off, PX4 disarms once its land detector has said landed this long
    /// (COM_DISARM_LAND) \[s\]; not positive: never.
    pub disarm_land_delay: f64,
}

impl Default for CommanderConfig {
    /// Offboard loss 0.5 s, heartbeat 1 s, disarm 2 s after landing (PX4's COM_DISARM_LAND).
    fn default() -> Self {
        Self {
            offboard_loss_timeout: 0.5,
            heartbeat_period: 1.0,
            disarm_land_delay: 2.0,
        }
    }
}

/// PX4's `systemlib::Hysteresis`: the state follows the requested one once the request has
/// stood for the delay of the current state (here: from false to true only; true to false
/// at once, as the land detector and the auto-disarm use it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hysteresis {
    state: bool,
    requested: bool,
    since: f64,
    delay_from_false: f64,
}

impl Hysteresis {
    /// Starting in `state`; a request for true must stand `delay_from_false` seconds.
    pub fn new(state: bool, delay_from_false: f64) -> Self {
        Self {
            state,
            requested: state,
            since: 0.0,
            delay_from_false,
        }
    }

    /// The state now.
    pub fn state(&self) -> bool {
        self.state
    }

    /// PX4's `set_state_and_update`: requests `new` at `now` and updates the state.
    pub fn update(&mut self, new: bool, now: f64) -> bool {
        if new == self.state {
            self.requested = new;
        } else if new != self.requested {
            self.requested = new;
            self.since = now;
        }
        if self.requested != self.state
            && (!self.requested || now - self.since >= self.delay_from_false - 1e-9)
        {
            self.state = self.requested;
        }
        self.state
    }
}

/// PX4's multicopter land-detector parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LandDetectorConfig {
    /// LNDMC_TRIG_TIME: ground contact, maybe landed and landed each need a third \[s\].
    pub trigger_time: f64,
    /// LNDMC_Z_VEL_MAX: vertical speed below which the vehicle is not moving vertically
    /// (2.5 times that once maybe landed) [m/s].
    pub z_vel_max: f64,
    /// LNDMC_XY_VEL_MAX: horizontal speed above which it is moving [m/s].
    pub xy_vel_max: f64,
    /// LNDMC_ROT_MAX: roll/pitch rate above which it is rotating (2.5 times that once maybe
    /// landed) [rad/s].
    pub rot_max: f64,
    /// MPC_THR_MIN: the position controller's minimum normalized thrust.
    pub thr_min: f64,
    /// MPC_MANTHR_MIN: the minimum normalized thrust of the modes without climb-rate
    /// control (OFFBOARD body rates among them).
    pub man_thr_min: f64,
}

impl Default for LandDetectorConfig {
    /// PX4 v1.16's defaults: LNDMC_TRIG_TIME 1 s, LNDMC_Z_VEL_MAX 0.25 m/s,
    /// LNDMC_XY_VEL_MAX 1.5 m/s, LNDMC_ROT_MAX 20 deg/s, MPC_THR_MIN 0.12,
    /// MPC_MANTHR_MIN 0.08.
    fn default() -> Self {
        Self {
            trigger_time: 1.0,
            z_vel_max: 0.25,
            xy_vel_max: 1.5,
            rot_max: 20f64.to_radians(),
            thr_min: 0.12,
            man_thr_min: 0.08,
        }
    }
}

/// What PX4's land detector reads at one update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LandDetectorInput {
    /// Armed (disarmed: landed).
    pub armed: bool,
    /// The normalized collective thrust last commanded to the motors, in [0, 1].
    pub thrust: f64,
    /// MPC_THR_HOVER.
    pub hover_thrust: f64,
    /// Whether the mode controls the climb rate (POSCTL, AUTO; not OFFBOARD body rates).
    pub climb_rate_control: bool,
    /// Whether that controller commands a descent (AUTO.LAND, RTL's landing).
    pub descending: bool,
    /// The estimated vertical speed [m/s].
    pub vz: f64,
    /// The estimated horizontal speed [m/s].
    pub v_xy: f64,
    /// The roll/pitch rate magnitude [rad/s].
    pub rate_xy: f64,
}

/// PX4's `MulticopterLandDetector` (src/modules/land_detector), without the free-fall and
/// distance-sensor checks:
///
/// * **ground contact**: low thrust (at most MPC_THR_MIN + 0.3 (MPC_THR_HOVER -
///   MPC_THR_MIN)), no vertical movement (|vz| <= LNDMC_Z_VEL_MAX) and no horizontal
///   movement; in a mode with climb-rate control, before maybe landed, a descent must be
///   commanded too;
/// * **maybe landed**: ground contact, thrust at most MPC_THR_MIN + 0.1 (MPC_THR_HOVER -
///   MPC_THR_MIN) with climb-rate control or MPC_MANTHR_MIN + 0.01 without (OFFBOARD body
///   rates), and no roll/pitch rotation above LNDMC_ROT_MAX;
/// * **landed**: maybe landed.
///
/// Each state needs its condition for a third of LNDMC_TRIG_TIME and drops at once; so
/// landed comes 1 s after the first ground contact. Disarmed, all three are true.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LandDetector {
    cfg: LandDetectorConfig,
    ground_contact: Hysteresis,
    maybe_landed: Hysteresis,
    landed: Hysteresis,
}

impl LandDetector {
    /// A detector that starts landed (a vehicle on the ground, disarmed).
    pub fn new(cfg: LandDetectorConfig) -> Self {
        let h = Hysteresis::new(true, cfg.trigger_time / 3.0);
        Self {
            cfg,
            ground_contact: h,
            maybe_landed: h,
            landed: h,
        }
    }

    /// The verdict now: landed.
    pub fn landed(&self) -> bool {
        self.landed.state()
    }

    /// Maybe landed now.
    pub fn maybe_landed(&self) -> bool {
        self.maybe_landed.state()
    }

    /// Ground contact now.
    pub fn ground_contact(&self) -> bool {
        self.ground_contact.state()
    }

    /// One update at `now`; returns whether landed.
    pub fn update(&mut self, now: f64, i: &LandDetectorInput) -> bool {
        let contact = self.ground_contact_now(i);
        self.ground_contact.update(contact, now);
        let maybe = self.maybe_landed_now(i);
        self.maybe_landed.update(maybe, now);
        let landed = !i.armed || self.maybe_landed.state();
        self.landed.update(landed, now)
    }

    fn ground_contact_now(&self, i: &LandDetectorInput) -> bool {
        if !i.armed {
            return true;
        }
        let c = &self.cfg;
        let widen = if self.maybe_landed.state() { 2.5 } else { 1.0 };
        let vertical = i.vz.abs() > c.z_vel_max * widen;
        let horizontal = i.v_xy > c.xy_vel_max;
        let low = i.thrust <= c.thr_min + (i.hover_thrust - c.thr_min) * 0.3;
        let settled = self.maybe_landed.state() || self.landed.state();
        let descent_ok = !i.climb_rate_control || settled || i.descending;
        low && descent_ok && !vertical && !horizontal
    }

    fn maybe_landed_now(&self, i: &LandDetectorInput) -> bool {
        if !i.armed {
            return true;
        }
        let c = &self.cfg;
        let min_thrust = if i.climb_rate_control {
            c.thr_min + (i.hover_thrust - c.thr_min) * 0.1
        } else {
            c.man_thr_min + 0.01
        };
        let widen = if self.maybe_landed.state() { 2.5 } else { 1.0 };
        i.thrust <= min_thrust && i.rate_xy <= c.rot_max * widen && self.ground_contact.state()
    }
}

/// The messages whose rate MAV_CMD_SET_MESSAGE_INTERVAL sets on the simulated vehicle:
/// ATTITUDE_QUATERNION (31), LOCAL_POSITION_NED (32), EXTENDED_SYS_STATE (245) and
/// ODOMETRY (331).
pub const STREAMED_MESSAGES: [u32; 4] = [
    mc::ATTITUDE_QUATERNION_DATA::ID,
    mc::LOCAL_POSITION_NED_DATA::ID,
    mc::EXTENDED_SYS_STATE_DATA::ID,
    mc::ODOMETRY_DATA::ID,
];

/// The rate of a streamed message as the companion last set it with
/// MAV_CMD_SET_MESSAGE_INTERVAL.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MessageInterval {
    /// The vehicle's default rate (never set, or set with interval 0).
    Default,
    /// Not streamed (a negative interval; -1 in the MAVLink spec).
    Stopped,
    /// One message every this many seconds (> 0).
    Every(f64),
}

/// A rate + thrust setpoint as PX4 received it (FRD rates, normalized thrust).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateSetpoint {
    /// Body rates FRD [rad/s].
    pub rates_frd: [f32; 3],
    /// Normalized thrust [0, 1].
    pub thrust: f32,
}

/// What the vehicle around the commander reports at each tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VehicleStatus {
    /// Whether the estimator has a valid pose (arming check).
    pub pose_valid: bool,
    /// Whether PX4's land detector says landed ([`LandDetector`]).
    pub landed: bool,
}

/// Who flies the vehicle now.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Control {
    /// Motors off.
    Disarmed,
    /// The offboard setpoint.
    Offboard(RateSetpoint),
    /// PX4's own position controller: hold, land or return.
    Px4(Px4Mode),
}

/// The simulated PX4 commander.
#[derive(Clone, Debug, PartialEq)]
pub struct Commander {
    cfg: CommanderConfig,
    mode: Px4Mode,
    armed: bool,
    last_setpoint: Option<(f64, RateSetpoint)>,
    last_heartbeat: Option<f64>,
    failsafe_at: Option<f64>,
    status: VehicleStatus,
    intervals: [MessageInterval; STREAMED_MESSAGES.len()],
    taken_off: bool,
    auto_disarm: Hysteresis,
    auto_disarmed_at: Vec<f64>,
}

impl Commander {
    /// A disarmed vehicle on the ground in POSCTL.
    pub fn new(cfg: CommanderConfig) -> Self {
        Self {
            cfg,
            mode: Px4Mode::Position,
            armed: false,
            last_setpoint: None,
            last_heartbeat: None,
            failsafe_at: None,
            status: VehicleStatus {
                pose_valid: true,
                landed: true,
            },
            intervals: [MessageInterval::Default; STREAMED_MESSAGES.len()],
            taken_off: false,
            auto_disarm: Hysteresis::new(false, cfg.disarm_land_delay),
            auto_disarmed_at: Vec::new(),
        }
    }

    /// When PX4 disarmed on its own after a landing (COM_DISARM_LAND), in order.
    pub fn auto_disarmed_at(&self) -> &[f64] {
        &self.auto_disarmed_at
    }

    /// The rate of `message_id` as last set with MAV_CMD_SET_MESSAGE_INTERVAL
    /// ([`MessageInterval::Default`] if never set; `None` for a message outside
    /// [`STREAMED_MESSAGES`]).
    pub fn message_interval(&self, message_id: u32) -> Option<MessageInterval> {
        STREAMED_MESSAGES
            .iter()
            .position(|&id| id == message_id)
            .and_then(|i| self.intervals.get(i).copied())
    }

    /// MAV_CMD_SET_MESSAGE_INTERVAL as PX4's `MavlinkReceiver::set_message_interval`.
    fn set_message_interval(&mut self, c: &mc::COMMAND_LONG_DATA) -> MavResult {
        // PX4: (int)(param + 0.5f); an `as` cast truncates towards zero like C's (and maps
        // NaN to 0).
        let round = |p: f32| (p + 0.5) as i32;
        let unsupported = |p: f32| p.is_finite() && round(p) != 0;
        if unsupported(c.param3) || unsupported(c.param4) || unsupported(c.param7) {
            return MavResult::MAV_RESULT_FAILED;
        }
        let id = round(c.param1);
        let Some(slot) = u32::try_from(id)
            .ok()
            .and_then(|id| STREAMED_MESSAGES.iter().position(|&s| s == id))
            .and_then(|i| self.intervals.get_mut(i))
        else {
            // HEARTBEAT (0) and anything this vehicle does not stream.
            return MavResult::MAV_RESULT_FAILED;
        };
        let interval = c.param2;
        *slot = if interval < -0.00001 {
            MessageInterval::Stopped
        } else if interval > 0.00001 {
            MessageInterval::Every(f64::from(interval) * 1e-6)
        } else {
            // 0 (and NaN, as in PX4, whose comparisons fail the same way): the default.
            MessageInterval::Default
        };
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// The current mode.
    pub fn mode(&self) -> Px4Mode {
        self.mode
    }

    /// Whether armed.
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// When the offboard-loss failsafe engaged, if it did.
    pub fn failsafe_at(&self) -> Option<f64> {
        self.failsafe_at
    }

    fn streaming(&self, now: f64) -> bool {
        self.last_setpoint
            .is_some_and(|(t, _)| now - t <= self.cfg.offboard_loss_timeout)
    }

    fn ack(command: MavCmd, result: MavResult) -> MavMessage {
        MavMessage::COMMAND_ACK(mc::COMMAND_ACK_DATA { command, result })
    }

    /// Handles a message from the companion at time `now`; returns PX4's answers.
    pub fn on_message(&mut self, msg: &MavMessage, now: f64) -> Vec<MavMessage> {
        match msg {
            MavMessage::SET_ATTITUDE_TARGET(s) => {
                let attitude_ignored = s
                    .type_mask
                    .contains(mc::AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE);
                let rates = [s.body_roll_rate, s.body_pitch_rate, s.body_yaw_rate];
                let valid = attitude_ignored
                    && rates.iter().all(|r| r.is_finite())
                    && s.thrust.is_finite()
                    && (0.0..=1.0).contains(&s.thrust);
                if valid {
                    self.last_setpoint = Some((
                        now,
                        RateSetpoint {
                            rates_frd: rates,
                            thrust: s.thrust,
                        },
                    ));
                }
                Vec::new()
            }
            MavMessage::COMMAND_LONG(c) => self.on_command(c, now),
            _ => Vec::new(),
        }
    }

    fn on_command(&mut self, c: &mc::COMMAND_LONG_DATA, now: f64) -> Vec<MavMessage> {
        let reply = |r| vec![Self::ack(c.command, r)];
        match c.command {
            MavCmd::MAV_CMD_DO_SET_MODE => {
                let mode = Px4Mode::from_custom_mode(
                    (u32::from(c.param2 as u8) << 16) | (u32::from(c.param3 as u8) << 24),
                );
                let result = match mode {
                    Px4Mode::Offboard if !self.streaming(now) => {
                        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
                    }
                    Px4Mode::Other(..) => MavResult::MAV_RESULT_UNSUPPORTED,
                    m => {
                        self.mode = m;
                        MavResult::MAV_RESULT_ACCEPTED
                    }
                };
                // PX4 v1.16 acknowledged a mode change twice.
                let a = Self::ack(c.command, result);
                vec![a.clone(), a]
            }
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
                if c.param1 == 1.0 {
                    if self.status.pose_valid && self.status.landed {
                        if !self.armed {
                            self.taken_off = false;
                            self.auto_disarm = Hysteresis::new(false, self.cfg.disarm_land_delay);
                        }
                        self.armed = true;
                        reply(MavResult::MAV_RESULT_ACCEPTED)
                    } else {
                        reply(MavResult::MAV_RESULT_DENIED)
                    }
                } else if self.status.landed {
                    self.armed = false;
                    reply(MavResult::MAV_RESULT_ACCEPTED)
                } else {
                    reply(MavResult::MAV_RESULT_DENIED)
                }
            }
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => reply(self.set_message_interval(c)),
            _ => reply(MavResult::MAV_RESULT_UNSUPPORTED),
        }
    }

    /// One step at `now` with the vehicle's `status`: applies the failsafes and the automatic
    /// disarm; returns who flies and the messages PX4 sends now (the HEARTBEAT when due).
    pub fn tick(&mut self, now: f64, status: VehicleStatus) -> (Control, Vec<MavMessage>) {
        self.status = status;
        if self.mode == Px4Mode::Offboard && !self.streaming(now) {
            self.mode = Px4Mode::Position;
            self.failsafe_at.get_or_insert(now);
        }
        self.auto_disarm_check(now, status.landed);
        let mut out = Vec::new();
        if self
            .last_heartbeat
            .is_none_or(|t| now - t >= self.cfg.heartbeat_period)
        {
            self.last_heartbeat = Some(now);
            out.push(self.heartbeat());
        }
        let control = if !self.armed {
            Control::Disarmed
        } else {
            match (self.mode, self.last_setpoint) {
                (Px4Mode::Offboard, Some((_, sp))) => Control::Offboard(sp),
                (m, _) => Control::Px4(m),
            }
        };
        (control, out)
    }

    /// PX4's `checkForAutoDisarm` after a take-off: landed for COM_DISARM_LAND disarms, in
    /// any mode.
    fn auto_disarm_check(&mut self, now: f64, landed: bool) {
        if !self.armed {
            return;
        }
        self.taken_off |= !landed;
        let due = self.auto_disarm.update(self.taken_off && landed, now);
        if due && self.cfg.disarm_land_delay > 0.0 {
            self.armed = false;
            self.auto_disarmed_at.push(now);
        }
    }

    /// PX4's HEARTBEAT now.
    pub fn heartbeat(&self) -> MavMessage {
        let mut base = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if self.armed {
            base |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        MavMessage::HEARTBEAT(mc::HEARTBEAT_DATA {
            custom_mode: self.mode.custom_mode(),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            base_mode: base,
            system_status: if self.armed {
                MavState::MAV_STATE_ACTIVE
            } else {
                MavState::MAV_STATE_STANDBY
            },
            mavlink_version: 3,
        })
    }
}
