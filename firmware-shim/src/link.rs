//! The offboard session as a state machine, clocked by the caller (no threads, no sockets):
//! feed it what PX4 sends ([`Session::on_inbound`]) and call [`Session::tick`] at the
//! controller rate; it says which messages to send and whether the MPC's setpoints fly the
//! vehicle. The caller streams a setpoint at every tick, whatever the session's phase: PX4
//! drops out of OFFBOARD when the stream pauses (COM_OF_LOSS_T), so the stream never waits
//! for an acknowledgement.
//!
//! Sequence (as PX4 v1.16 accepted it on SITL; `docs/shim.md`):
//!
//! 0. ask for ODOMETRY at [`LinkConfig::odometry_rate`] (MAV_CMD_SET_MESSAGE_INTERVAL; PX4
//!    streams it at 30 Hz on the onboard link otherwise); a refusal is not fatal;
//! 1. stream setpoints for at least [`LinkConfig::stream_before_offboard`] (1 s);
//! 2. MAV_CMD_DO_SET_MODE OFFBOARD, until acknowledged (retries, timeouts; duplicate acks are
//!    fine) and the HEARTBEAT shows OFFBOARD (it may take up to 1 s to show);
//! 3. MAV_CMD_COMPONENT_ARM_DISARM arm, until acknowledged and the HEARTBEAT shows armed;
//! 4. flying: the MPC's setpoints fly the vehicle;
//! 5. when the mission is over ([`Session::finish`], on the ground): AUTO.LAND, which makes
//!    PX4 disarm on its own, and a disarm command as soon as PX4's land detector says landed
//!    (EXTENDED_SYS_STATE `ON_GROUND`) ([`Phase::Done`] once the HEARTBEAT shows it
//!    disarmed).
//!
//! Failsafes while flying:
//!
//! * no new odometry for [`LinkConfig::odometry_timeout`] (100 ms), or none ever: request
//!   return mode (AUTO.RTL), the paper's trial-9 behaviour;
//! * [`LinkConfig::max_solver_failures`] consecutive solver failures (each one already flew
//!   the previous plan, from the runtime): request return mode;
//! * operator abort ([`Session::abort`]): request AUTO.LAND, not just exit;
//! * PX4 leaving OFFBOARD on its own (its own failsafe, the pilot): the session stops flying
//!   and reports it;
//! * PX4 disarming the vehicle (HEARTBEAT's armed flag, in any mode): the same;
//! * the controller finding the vehicle off its mission ([`Session::trip`], the watch):
//!   request AUTO.LAND.
//!
//! In a failsafe PX4 flies; once its land detector says landed, the session disarms it.
//!
//! A command that stays unacknowledged after [`LinkConfig::retries`] retransmissions ends the
//! session in [`Phase::Failed`] with the reason; a failsafe command is retried the same way
//! but its failure leaves the session in its failsafe phase (there is nothing better to do
//! than to keep asking).

use mavlink::dialects::common::{MavCmd, MavMessage};

use crate::messages::{self, Command, Inbound, LandedState, Px4Mode};

/// Timing of the session. Times in seconds of the caller's clock (clock it from the
/// vehicle's timestamps in simulation: PX4 scales its timeouts with the speed-up factor).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkConfig {
    /// HEARTBEAT period.
    pub heartbeat_period: f64,
    /// Wait this long for a COMMAND_ACK before retransmitting.
    pub ack_timeout: f64,
    /// Retransmissions of a command that is not acknowledged (or not shown by the
    /// HEARTBEAT) before giving up. With 20 % loss each way an arm command and its single
    /// acknowledgement both get through with probability 0.64; six tries fail together with
    /// probability 0.2 %.
    pub retries: u8,
    /// Setpoints stream this long before OFFBOARD is requested (PX4 needs > 0).
    pub stream_before_offboard: f64,
    /// After an accepted mode or arm command, wait this long for the HEARTBEAT to show it.
    pub confirm_timeout: f64,
    /// No new odometry for longer than this in flight: lost, return mode.
    pub odometry_timeout: f64,
    /// This many consecutive solver failures: return mode.
    pub max_solver_failures: u32,
    /// ODOMETRY rate asked of PX4 at the start \[Hz\] (0: do not ask).
    pub odometry_rate: f32,
}

impl Default for LinkConfig {
    /// Heartbeat 1 s, ack timeout 0.5 s with 5 retries, 1 s of streaming before OFFBOARD,
    /// 2 s for the heartbeat to confirm, odometry timeout 0.1 s, 5 solver failures, ODOMETRY
    /// at 100 Hz.
    fn default() -> Self {
        Self {
            heartbeat_period: 1.0,
            ack_timeout: 0.5,
            retries: 5,
            stream_before_offboard: 1.0,
            confirm_timeout: 2.0,
            odometry_timeout: 0.1,
            max_solver_failures: 5,
            odometry_rate: 100.0,
        }
    }
}

/// A [`LinkConfig`] value that cannot work.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("link setting {name} = {value} is invalid: {why}")]
pub struct LinkConfigError {
    /// The field.
    pub name: &'static str,
    /// Its value.
    pub value: f64,
    /// What it must be.
    pub why: &'static str,
}

impl LinkConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`LinkConfigError`] naming the first bad field and what it must be.
    pub fn validate(&self) -> Result<(), LinkConfigError> {
        let positive = [
            ("heartbeat_period", self.heartbeat_period),
            ("ack_timeout", self.ack_timeout),
            ("confirm_timeout", self.confirm_timeout),
            ("odometry_timeout", self.odometry_timeout),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(LinkConfigError {
                    name,
                    value,
                    why: "a finite time > 0 s",
                });
            }
        }
        let checks = [
            (
                "stream_before_offboard",
                self.stream_before_offboard,
                self.stream_before_offboard.is_finite() && self.stream_before_offboard >= 0.5,
                "at least 0.5 s (PX4 needs the stream before it accepts OFFBOARD)",
            ),
            (
                "max_solver_failures",
                f64::from(self.max_solver_failures),
                self.max_solver_failures >= 1,
                "at least 1",
            ),
            (
                "odometry_rate",
                f64::from(self.odometry_rate),
                self.odometry_rate.is_finite() && (0.0..=1000.0).contains(&self.odometry_rate),
                "0 (do not ask) or a rate up to 1000 Hz",
            ),
        ];
        for (name, value, ok, why) in checks {
            if !ok {
                return Err(LinkConfigError { name, value, why });
            }
        }
        Ok(())
    }
}

/// Why the session stopped flying the MPC.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Failsafe {
    /// Odometry stale or lost.
    OdometryLost,
    /// Too many consecutive solver failures.
    SolverFailures,
    /// The operator aborted.
    Abort,
    /// PX4 left OFFBOARD on its own.
    Px4LeftOffboard,
    /// PX4 disarmed the vehicle in flight (its land detector, a kill switch, a crash).
    Px4Disarmed,
    /// The vehicle is not where the mission needs it: AUTO.LAND.
    OffMission(Deviation),
}

impl Failsafe {
    /// The mode the session asks PX4 for (`None`: PX4 decided already).
    pub fn mode(self) -> Option<Px4Mode> {
        match self {
            Failsafe::Abort | Failsafe::OffMission(_) => Some(Px4Mode::Land),
            Failsafe::OdometryLost | Failsafe::SolverFailures => Some(Px4Mode::Return),
            Failsafe::Px4LeftOffboard | Failsafe::Px4Disarmed => None,
        }
    }
}

/// How the vehicle left its mission ([`Failsafe::OffMission`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Deviation {
    /// Far below the reference.
    BelowReference,
    /// Far from the reference.
    OffCourse,
    /// Upside down outside the flip.
    Inverted,
    /// On the ground before the landing.
    OnGround,
}

/// Where the session is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// Streaming setpoints before asking for OFFBOARD, since the given time.
    Streaming {
        /// When streaming began.
        since: f64,
    },
    /// Waiting for OFFBOARD to be acknowledged and shown.
    RequestingOffboard,
    /// Waiting for arming to be acknowledged and shown.
    Arming,
    /// The MPC flies the vehicle.
    Flying,
    /// A failsafe asked PX4 for a mode (return or land); the MPC no longer flies.
    Failsafe(Failsafe),
    /// The session could not start (a command was refused or never acknowledged).
    Failed(SessionError),
    /// The mission is over: AUTO.LAND requested so that PX4 disarms.
    Finishing,
    /// Over: PX4 shows the vehicle disarmed after [`Session::finish`].
    Done,
}

/// Why a session could not start.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum SessionError {
    /// PX4 refused a command.
    #[error("PX4 refused {0:?}; check its pre-arm messages (QGroundControl) and the mode")]
    Refused(MavCmd),
    /// No COMMAND_ACK after every retry.
    #[error(
        "no COMMAND_ACK for {0:?} after all retries: is PX4 on this link (system 1, component \
         1) and is the link bidirectional?"
    )]
    NoAck(MavCmd),
    /// Acknowledged, but the HEARTBEAT never showed the result.
    #[error("PX4 acknowledged {0:?} but its HEARTBEAT never showed the result")]
    NotConfirmed(MavCmd),
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Pending {
    cmd: Command,
    sent_at: f64,
    attempts: u8,
    acked_at: Option<f64>,
}

/// What one tick asks of the caller.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tick {
    /// Messages to send now (besides the setpoint).
    pub send: Vec<MavMessage>,
    /// Whether the MPC's setpoint flies the vehicle (false: stream a neutral setpoint).
    pub mpc_in_control: bool,
    /// A failsafe that engaged at this tick.
    pub failsafe: Option<Failsafe>,
}

/// The offboard session.
#[derive(Clone, Debug, PartialEq)]
pub struct Session {
    cfg: LinkConfig,
    phase: Phase,
    pending: Option<Pending>,
    last_heartbeat_sent: Option<f64>,
    last_odometry: Option<f64>,
    px4_mode: Option<Px4Mode>,
    armed: bool,
    on_ground: bool,
    solver_failures: u32,
    abort: bool,
    trip: Option<Failsafe>,
    interval_requested: bool,
    finish: bool,
}

impl Session {
    /// A session that starts streaming at `now`.
    pub fn new(cfg: LinkConfig, now: f64) -> Self {
        Self {
            cfg,
            phase: Phase::Streaming { since: now },
            pending: None,
            last_heartbeat_sent: None,
            last_odometry: None,
            px4_mode: None,
            armed: false,
            on_ground: false,
            solver_failures: 0,
            abort: false,
            trip: None,
            interval_requested: false,
            finish: false,
        }
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// PX4's mode as its last HEARTBEAT showed it.
    pub fn px4_mode(&self) -> Option<Px4Mode> {
        self.px4_mode
    }

    /// Whether PX4's last HEARTBEAT showed it armed.
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// Records what PX4 sent at time `now`.
    pub fn on_inbound(&mut self, inbound: &Inbound, now: f64) {
        match *inbound {
            Inbound::Heartbeat { armed, mode } => {
                self.armed = armed;
                self.px4_mode = Some(mode);
            }
            Inbound::Odometry(_) => self.on_odometry(now),
            Inbound::Landed(l) => self.on_ground = l == LandedState::OnGround,
            Inbound::Ack {
                command,
                accepted,
                in_progress,
            } => {
                if let Some(p) = &mut self.pending
                    && p.cmd.mav_cmd() == command
                {
                    if accepted {
                        p.acked_at.get_or_insert(now);
                    } else if !in_progress {
                        if matches!(p.cmd, Command::MessageInterval { .. }) {
                            // Not fatal: PX4 keeps its default rate.
                            self.pending = None;
                        } else if matches!(self.phase, Phase::Failsafe(_) | Phase::Finishing) {
                            // Keep asking, an acknowledgement timeout later: a failsafe has
                            // no better option.
                            p.sent_at = now;
                        } else {
                            self.phase = Phase::Failed(SessionError::Refused(command));
                            self.pending = None;
                        }
                    }
                }
            }
            _ => {}
        }
    }

    /// A new state of the vehicle arrived at `now` (ODOMETRY, or what the caller made of
    /// LOCAL_POSITION_NED + ATTITUDE_QUATERNION): the odometry failsafe's clock.
    pub fn on_odometry(&mut self, now: f64) {
        self.last_odometry = Some(now);
    }

    /// The result of one solver step (call once per controller step while flying).
    pub fn on_solver(&mut self, ok: bool) {
        if ok {
            self.solver_failures = 0;
        } else {
            self.solver_failures = self.solver_failures.saturating_add(1);
        }
    }

    /// The operator asks to stop (Ctrl-C): the next tick requests AUTO.LAND.
    pub fn abort(&mut self) {
        self.abort = true;
    }

    /// The controller found the vehicle off its mission: the next tick engages `f` (only
    /// while flying; otherwise ignored).
    pub fn trip(&mut self, f: Failsafe) {
        if self.phase == Phase::Flying {
            self.trip = Some(f);
        }
    }

    /// The mission is over and the vehicle is on the ground: the next tick requests AUTO.LAND
    /// (PX4 disarms on its own after landing; a disarm command would be refused while its
    /// land detector still says airborne). Only while flying; otherwise ignored.
    pub fn finish(&mut self) {
        if self.phase == Phase::Flying {
            self.finish = true;
        }
    }

    fn start(&mut self, cmd: Command, now: f64, out: &mut Vec<MavMessage>) {
        self.pending = Some(Pending {
            cmd,
            sent_at: now,
            attempts: 0,
            acked_at: None,
        });
        out.push(messages::command_long(cmd, 0));
    }

    fn engage(&mut self, f: Failsafe, now: f64, tick: &mut Tick) {
        self.phase = Phase::Failsafe(f);
        tick.failsafe = Some(f);
        match f.mode() {
            Some(mode) => self.start(Command::SetMode(mode), now, &mut tick.send),
            None => self.pending = None,
        }
    }

    /// Whether the pending command is done: acknowledged and, for mode and arm commands,
    /// shown by the HEARTBEAT.
    fn confirmed(&self, p: &Pending) -> bool {
        p.acked_at.is_some()
            && match p.cmd {
                Command::SetMode(m) => self.px4_mode == Some(m),
                Command::Arm => self.armed,
                Command::Disarm => !self.armed,
                Command::MessageInterval { .. } => true,
            }
    }

    /// One step at time `now`.
    pub fn tick(&mut self, now: f64) -> Tick {
        let mut tick = Tick::default();
        if self
            .last_heartbeat_sent
            .is_none_or(|t| now - t >= self.cfg.heartbeat_period)
        {
            tick.send.push(messages::heartbeat());
            self.last_heartbeat_sent = Some(now);
        }
        self.service_pending(now, &mut tick);
        if self.abort
            && !matches!(
                self.phase,
                Phase::Failsafe(Failsafe::Abort) | Phase::Failed(_) | Phase::Done
            )
        {
            self.engage(Failsafe::Abort, now, &mut tick);
            return tick;
        }
        self.advance(now, &mut tick);
        tick.mpc_in_control = self.phase == Phase::Flying;
        tick
    }

    /// Retransmissions and timeouts of the pending command.
    fn service_pending(&mut self, now: f64, tick: &mut Tick) {
        let Some(p) = self.pending else {
            return;
        };
        if self.confirmed(&p) {
            self.pending = None;
        } else if let Some(ta) = p.acked_at {
            if now - ta > self.cfg.confirm_timeout {
                // Acknowledged, but the HEARTBEAT never showed it (heartbeats lost, or
                // PX4 changed its mind): ask again, as for a missing acknowledgement.
                let keep_asking = matches!(self.phase, Phase::Failsafe(_) | Phase::Finishing);
                if p.attempts >= self.cfg.retries && !keep_asking {
                    self.pending = None;
                    self.phase = Phase::Failed(SessionError::NotConfirmed(p.cmd.mav_cmd()));
                } else {
                    let attempts = p.attempts.saturating_add(1);
                    self.pending = Some(Pending {
                        sent_at: now,
                        attempts,
                        acked_at: None,
                        ..p
                    });
                    tick.send.push(messages::command_long(p.cmd, attempts));
                }
            }
        } else if now - p.sent_at >= self.cfg.ack_timeout {
            let keep_asking = matches!(self.phase, Phase::Failsafe(_) | Phase::Finishing);
            if p.attempts >= self.cfg.retries && matches!(p.cmd, Command::MessageInterval { .. }) {
                // Not fatal: PX4 keeps its default rate (the setpoints tell whether
                // anyone listens).
                self.pending = None;
            } else if p.attempts >= self.cfg.retries && !keep_asking {
                self.pending = None;
                self.phase = Phase::Failed(SessionError::NoAck(p.cmd.mav_cmd()));
            } else {
                let attempts = p.attempts.saturating_add(1);
                self.pending = Some(Pending {
                    sent_at: now,
                    attempts,
                    ..p
                });
                tick.send.push(messages::command_long(p.cmd, attempts));
            }
        }
    }

    /// The session's next step in its phase: the commands of the start, the failsafes in
    /// flight, the landing at the end.
    fn advance(&mut self, now: f64, tick: &mut Tick) {
        match self.phase {
            Phase::Streaming { since } => {
                if !self.interval_requested && self.cfg.odometry_rate > 0.0 {
                    self.interval_requested = true;
                    let cmd = Command::MessageInterval {
                        message_id: messages::ODOMETRY_ID,
                        hz: self.cfg.odometry_rate,
                    };
                    self.start(cmd, now, &mut tick.send);
                } else if now - since >= self.cfg.stream_before_offboard && self.pending.is_none() {
                    self.phase = Phase::RequestingOffboard;
                    self.start(Command::SetMode(Px4Mode::Offboard), now, &mut tick.send);
                }
            }
            Phase::RequestingOffboard => {
                if self.pending.is_none() {
                    self.phase = Phase::Arming;
                    self.start(Command::Arm, now, &mut tick.send);
                }
            }
            Phase::Arming => {
                if self.pending.is_none() {
                    self.phase = Phase::Flying;
                    self.solver_failures = 0;
                }
            }
            Phase::Flying if self.finish => {
                self.phase = Phase::Finishing;
                self.start(Command::SetMode(Px4Mode::Land), now, &mut tick.send);
            }
            Phase::Flying if !self.armed => self.engage(Failsafe::Px4Disarmed, now, tick),
            Phase::Flying if self.trip.is_some() => {
                let f = self.trip.take().unwrap_or(Failsafe::Abort);
                self.engage(f, now, tick);
            }
            Phase::Flying => {
                let stale = self
                    .last_odometry
                    .is_none_or(|t| now - t > self.cfg.odometry_timeout);
                if stale {
                    self.engage(Failsafe::OdometryLost, now, tick);
                } else if self.solver_failures >= self.cfg.max_solver_failures {
                    self.engage(Failsafe::SolverFailures, now, tick);
                } else if self.px4_mode.is_some_and(|m| m != Px4Mode::Offboard) {
                    self.engage(Failsafe::Px4LeftOffboard, now, tick);
                }
            }
            Phase::Finishing => {
                // Disarmed is done, whether PX4's AUTO.LAND did it or its land detector did
                // before (PX4 may refuse AUTO.LAND on a disarmed vehicle). Once PX4's land
                // detector says landed, disarm rather than wait for its own disarm (seconds
                // on the ground, armed).
                let disarming = self.pending.is_some_and(|p| p.cmd == Command::Disarm);
                if !self.armed {
                    self.pending = None;
                    self.phase = Phase::Done;
                } else if self.on_ground && !disarming {
                    self.start(Command::Disarm, now, &mut tick.send);
                }
            }
            Phase::Failsafe(_) => {
                // PX4 flies now; once its land detector says landed, disarm.
                let disarming = self.pending.is_some_and(|p| p.cmd == Command::Disarm);
                if self.armed && self.on_ground && !disarming {
                    self.start(Command::Disarm, now, &mut tick.send);
                }
            }
            Phase::Failed(_) | Phase::Done => {}
        }
    }
}
