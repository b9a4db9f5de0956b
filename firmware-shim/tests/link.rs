//! The offboard session against PX4's rules, with a scripted PX4 and a fake clock.

use firmware_shim::link::{Deviation, Failsafe, LinkConfig, Phase, Session, SessionError};
use firmware_shim::messages::{Inbound, LandedState, OdometryNed, Px4Mode};
use mavlink::dialects::common::{MavCmd, MavMessage};

const DT: f64 = 0.01;

fn odom() -> Inbound {
    Inbound::Odometry(OdometryNed {
        time_us: 0,
        position: [0.0; 3],
        velocity: [0.0; 3],
        q: [1.0, 0.0, 0.0, 0.0],
        rates: [0.0; 3],
    })
}

fn ack(command: MavCmd, accepted: bool) -> Inbound {
    Inbound::Ack {
        command,
        accepted,
        in_progress: false,
    }
}

/// The commands in `msgs`: (command, param2, confirmation).
fn commands(msgs: &[MavMessage]) -> Vec<(MavCmd, f32, u8)> {
    msgs.iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_LONG(c) => Some((c.command, c.param2, c.confirmation)),
            _ => None,
        })
        .collect()
}

/// The param3 of the commands in `msgs` (the sub mode of DO_SET_MODE).
fn param3(msgs: &[MavMessage]) -> Vec<f32> {
    msgs.iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_LONG(c) => Some(c.param3),
            _ => None,
        })
        .collect()
}

/// A well-behaved PX4: acknowledges every command (twice, as PX4 v1.16 did for the mode),
/// shows the mode and the armed flag in the next heartbeat, streams odometry.
struct Px4 {
    mode: Px4Mode,
    armed: bool,
    odometry: bool,
    acks: bool,
    interval_ok: bool,
    /// Whether the HEARTBEAT shows what was commanded.
    shows: bool,
}

impl Px4 {
    fn new() -> Self {
        Self {
            mode: Px4Mode::Position,
            armed: false,
            odometry: true,
            acks: true,
            interval_ok: true,
            shows: true,
        }
    }

    fn answer(&mut self, s: &mut Session, sent: &[MavMessage], now: f64) {
        for ((cmd, p2, _), p3) in commands(sent).into_iter().zip(param3(sent)) {
            match cmd {
                MavCmd::MAV_CMD_DO_SET_MODE => {
                    let mode = match p2 as u8 {
                        6 => Px4Mode::Offboard,
                        4 if p3 as u8 == 6 => Px4Mode::Land,
                        4 => Px4Mode::Return,
                        _ => self.mode,
                    };
                    if self.shows {
                        self.mode = mode;
                    }
                    if self.acks {
                        s.on_inbound(&ack(cmd, true), now);
                        s.on_inbound(&ack(cmd, true), now);
                    }
                }
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
                    self.armed |= self.shows;
                    if self.acks {
                        s.on_inbound(&ack(cmd, true), now);
                    }
                }
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL if self.acks => {
                    s.on_inbound(&ack(cmd, self.interval_ok), now);
                }
                _ => {}
            }
        }
        s.on_inbound(
            &Inbound::Heartbeat {
                armed: self.armed,
                mode: self.mode,
            },
            now,
        );
        if self.odometry {
            s.on_inbound(&odom(), now);
        }
    }
}

/// Runs until `until`, returning every message sent with its time.
fn run(s: &mut Session, px4: &mut Px4, from: f64, until: f64) -> Vec<(f64, MavMessage)> {
    let mut log = Vec::new();
    let mut t = from;
    while t < until {
        let tick = s.tick(t);
        px4.answer(s, &tick.send, t);
        log.extend(tick.send.into_iter().map(|m| (t, m)));
        t += DT;
    }
    log
}

#[test]
fn offboard_only_after_a_second_of_streaming_then_arm_then_fly() {
    let mut s = Session::new(LinkConfig::default(), 0.0);
    let mut px4 = Px4::new();
    let log = run(&mut s, &mut px4, 0.0, 3.0);
    let first_mode = log
        .iter()
        .find(|(_, m)| {
            commands(std::slice::from_ref(m))
                .iter()
                .any(|c| c.0 == MavCmd::MAV_CMD_DO_SET_MODE)
        })
        .map(|(t, _)| *t)
        .unwrap();
    assert!(
        first_mode >= 1.0 - 1e-9,
        "OFFBOARD requested at {first_mode} s"
    );
    let first_arm = log
        .iter()
        .find(|(_, m)| {
            commands(std::slice::from_ref(m))
                .iter()
                .any(|c| c.0 == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM)
        })
        .map(|(t, _)| *t)
        .unwrap();
    assert!(first_arm > first_mode, "arm after OFFBOARD");
    assert_eq!(s.phase(), Phase::Flying);
    // Heartbeats at 1 Hz.
    let hb: Vec<f64> = log
        .iter()
        .filter(|(_, m)| matches!(m, MavMessage::HEARTBEAT(_)))
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(hb.len(), 3, "{hb:?}");
    // Flying: the MPC is in control, no failsafe.
    let t = s.tick(3.0);
    assert!(t.mpc_in_control);
    assert_eq!(t.failsafe, None);
}

#[test]
fn unacknowledged_commands_are_retried_then_the_session_fails() {
    let cfg = LinkConfig::default();
    let mut s = Session::new(cfg, 0.0);
    let mut px4 = Px4 {
        acks: false,
        ..Px4::new()
    };
    let log = run(&mut s, &mut px4, 0.0, 8.0);
    let sent = |which: MavCmd| -> Vec<(f64, u8)> {
        log.iter()
            .flat_map(|(t, m)| {
                commands(std::slice::from_ref(m))
                    .into_iter()
                    .filter(|c| c.0 == which)
                    .map(move |c| (*t, c.2))
            })
            .collect()
    };
    // The ODOMETRY rate request goes unanswered too: retried, then given up without failing
    // the session (PX4 would keep its default rate).
    let interval = sent(MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
    assert_eq!(interval.len(), 1 + usize::from(cfg.retries), "{interval:?}");
    let modes = sent(MavCmd::MAV_CMD_DO_SET_MODE);
    assert!(
        modes[0].0 >= interval.last().unwrap().0 + cfg.ack_timeout - 1e-9,
        "one command at a time: {modes:?}"
    );
    // The first request and `retries` retransmissions, `ack_timeout` apart, with the
    // confirmation count going up.
    assert_eq!(modes.len(), 1 + usize::from(cfg.retries), "{modes:?}");
    for (i, w) in modes.windows(2).enumerate() {
        assert!(
            (w[1].0 - w[0].0 - cfg.ack_timeout).abs() < DT + 1e-9,
            "{modes:?}"
        );
        assert_eq!(w[1].1, i as u8 + 1);
    }
    assert_eq!(
        s.phase(),
        Phase::Failed(SessionError::NoAck(MavCmd::MAV_CMD_DO_SET_MODE))
    );
    let msg = SessionError::NoAck(MavCmd::MAV_CMD_DO_SET_MODE).to_string();
    assert!(msg.contains("system 1"), "{msg}");
}

#[test]
fn a_refused_command_fails_the_session_with_the_command_named() {
    let cfg = LinkConfig {
        odometry_rate: 0.0,
        ..LinkConfig::default()
    };
    let mut s = Session::new(cfg, 0.0);
    let _ = s.tick(0.0);
    let t = s.tick(1.0);
    assert_eq!(commands(&t.send).len(), 1);
    s.on_inbound(&ack(MavCmd::MAV_CMD_DO_SET_MODE, false), 1.01);
    assert_eq!(
        s.phase(),
        Phase::Failed(SessionError::Refused(MavCmd::MAV_CMD_DO_SET_MODE))
    );
    assert!(!s.tick(1.02).mpc_in_control);
}

fn flying() -> (Session, Px4) {
    let mut s = Session::new(LinkConfig::default(), 0.0);
    let mut px4 = Px4::new();
    let _ = run(&mut s, &mut px4, 0.0, 3.0);
    assert_eq!(s.phase(), Phase::Flying);
    (s, px4)
}

#[test]
fn odometry_blackout_commands_return_within_one_tick_of_the_limit() {
    let (mut s, mut px4) = flying();
    px4.odometry = false;
    let lost_at = 3.0 - DT; // the last odometry
    let mut t = 3.0;
    let mut engaged = None;
    while t < 4.0 {
        let tick = s.tick(t);
        if tick.failsafe.is_some() {
            engaged = Some((t, tick.failsafe, commands(&tick.send)));
            break;
        }
        px4.answer(&mut s, &tick.send, t);
        t += DT;
    }
    let (t, f, cmds) = engaged.expect("the failsafe engaged");
    assert_eq!(f, Some(Failsafe::OdometryLost));
    let limit = LinkConfig::default().odometry_timeout;
    assert!(
        t - lost_at > limit && t - lost_at <= limit + DT + 1e-9,
        "{t}"
    );
    assert_eq!(
        cmds,
        vec![(MavCmd::MAV_CMD_DO_SET_MODE, 4.0, 0)],
        "AUTO.RTL"
    );
    assert_eq!(s.phase(), Phase::Failsafe(Failsafe::OdometryLost));
    assert!(!s.tick(t + DT).mpc_in_control);
}

#[test]
fn consecutive_solver_failures_command_return_intermittent_ones_do_not() {
    let (mut s, mut px4) = flying();
    let k = LinkConfig::default().max_solver_failures;
    let mut t = 3.0;
    for i in 0..(5 * k) {
        s.on_solver(i % 2 == 0); // every other step fails: never k in a row
        let tick = s.tick(t);
        assert!(tick.failsafe.is_none(), "step {i}");
        px4.answer(&mut s, &tick.send, t);
        t += DT;
    }
    for i in 0..k {
        s.on_solver(false);
        let tick = s.tick(t);
        if i + 1 < k {
            assert!(tick.failsafe.is_none(), "failure {i}");
        } else {
            assert_eq!(tick.failsafe, Some(Failsafe::SolverFailures));
            assert_eq!(commands(&tick.send)[0].0, MavCmd::MAV_CMD_DO_SET_MODE);
        }
        px4.answer(&mut s, &tick.send, t);
        t += DT;
    }
}

#[test]
fn abort_lands_and_px4_leaving_offboard_is_noticed() {
    let (mut s, _) = flying();
    s.abort();
    let tick = s.tick(3.0);
    assert_eq!(tick.failsafe, Some(Failsafe::Abort));
    // AUTO.LAND: main 4, sub 6.
    let cmds = commands(&tick.send);
    assert_eq!(cmds, vec![(MavCmd::MAV_CMD_DO_SET_MODE, 4.0, 0)]);
    if let Some(MavMessage::COMMAND_LONG(c)) = tick
        .send
        .iter()
        .find(|m| matches!(m, MavMessage::COMMAND_LONG(_)))
    {
        assert_eq!(c.param3, 6.0);
    }
    // The land request is retried until PX4 acknowledges it.
    let again = s.tick(3.0 + LinkConfig::default().ack_timeout);
    assert_eq!(commands(&again.send).len(), 1);

    let (mut s, mut px4) = flying();
    px4.mode = Px4Mode::Position; // PX4's own offboard-loss fallback
    px4.answer(&mut s, &[], 3.0);
    let tick = s.tick(3.0);
    assert_eq!(tick.failsafe, Some(Failsafe::Px4LeftOffboard));
    assert!(
        commands(&tick.send).is_empty(),
        "PX4 decided; we do not fight it"
    );
}

#[test]
fn odometry_rate_is_asked_first_and_a_refusal_is_not_fatal() {
    let cfg = LinkConfig::default();
    let mut s = Session::new(cfg, 0.0);
    let first = s.tick(0.0);
    let c = first
        .send
        .iter()
        .find_map(|m| match m {
            MavMessage::COMMAND_LONG(c) => Some(c.clone()),
            _ => None,
        })
        .expect("a command at the first tick");
    assert_eq!(c.command, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
    assert_eq!(c.param1, 331.0, "ODOMETRY");
    assert_eq!(c.param2, 1e6 / cfg.odometry_rate, "interval in us");
    let mut px4 = Px4 {
        interval_ok: false,
        ..Px4::new()
    };
    px4.answer(&mut s, &first.send, 0.0);
    let _ = run(&mut s, &mut px4, DT, 3.0);
    assert_eq!(s.phase(), Phase::Flying);
}

#[test]
fn finish_lands_and_the_session_is_done_when_px4_disarms() {
    let (mut s, mut px4) = flying();
    s.finish();
    let tick = s.tick(3.0);
    assert!(!tick.mpc_in_control);
    assert_eq!(tick.failsafe, None);
    assert_eq!(
        commands(&tick.send),
        vec![(MavCmd::MAV_CMD_DO_SET_MODE, 4.0, 0)]
    );
    assert_eq!(param3(&tick.send), vec![6.0], "AUTO.LAND");
    assert_eq!(s.phase(), Phase::Finishing);
    px4.answer(&mut s, &tick.send, 3.0);
    let _ = run(&mut s, &mut px4, 3.0 + DT, 3.5);
    assert_eq!(s.phase(), Phase::Finishing, "still armed");
    px4.armed = false; // PX4 disarmed after landing
    let _ = run(&mut s, &mut px4, 3.5, 3.6);
    assert_eq!(s.phase(), Phase::Done);
    // finish() outside flight does nothing.
    let mut idle = Session::new(LinkConfig::default(), 0.0);
    idle.finish();
    let _ = idle.tick(0.0);
    assert!(matches!(idle.phase(), Phase::Streaming { .. }));
}

#[test]
fn bad_link_settings_are_named() {
    assert!(LinkConfig::default().validate().is_ok());
    let bad = LinkConfig {
        odometry_timeout: 0.0,
        ..LinkConfig::default()
    };
    let e = bad.validate().unwrap_err();
    assert_eq!(e.name, "odometry_timeout");
    assert!(e.to_string().contains("odometry_timeout = 0"), "{e}");
    let bad = LinkConfig {
        stream_before_offboard: 0.1,
        ..LinkConfig::default()
    };
    assert_eq!(bad.validate().unwrap_err().name, "stream_before_offboard");
    let bad = LinkConfig {
        odometry_rate: f32::NAN,
        ..LinkConfig::default()
    };
    assert_eq!(bad.validate().unwrap_err().name, "odometry_rate");
}

#[test]
fn an_acknowledged_command_the_heartbeat_never_shows_is_asked_again_then_fails() {
    let cfg = LinkConfig {
        odometry_rate: 0.0,
        ..LinkConfig::default()
    };
    let mut s = Session::new(cfg, 0.0);
    let mut px4 = Px4 {
        shows: false,
        ..Px4::new()
    };
    let log = run(&mut s, &mut px4, 0.0, 30.0);
    let modes: Vec<(f64, u8)> = log
        .iter()
        .flat_map(|(t, m)| {
            commands(std::slice::from_ref(m))
                .into_iter()
                .map(move |c| (*t, c.2))
        })
        .collect();
    // Each try waits confirm_timeout after its acknowledgement, then asks again.
    assert_eq!(modes.len(), 1 + usize::from(cfg.retries), "{modes:?}");
    for w in modes.windows(2) {
        assert!(w[1].0 - w[0].0 > cfg.confirm_timeout, "{modes:?}");
    }
    assert_eq!(
        s.phase(),
        Phase::Failed(SessionError::NotConfirmed(MavCmd::MAV_CMD_DO_SET_MODE))
    );
}

#[test]
fn a_disarm_by_px4_in_flight_stops_the_mission_without_a_mode_request() {
    let mut s = Session::new(LinkConfig::default(), 0.0);
    let mut px4 = Px4::new();
    run(&mut s, &mut px4, 0.0, 3.0);
    assert_eq!(s.phase(), Phase::Flying);
    // PX4's land detector (or a kill switch) disarms it in OFFBOARD.
    px4.armed = false;
    px4.answer(&mut s, &[], 3.0);
    let t = s.tick(3.01);
    assert_eq!(t.failsafe, Some(Failsafe::Px4Disarmed));
    assert!(!t.mpc_in_control);
    assert!(
        commands(&t.send).is_empty(),
        "no mode asked of a disarmed PX4"
    );
    assert_eq!(s.phase(), Phase::Failsafe(Failsafe::Px4Disarmed));
}

#[test]
fn a_landing_is_done_when_px4_disarms_even_before_it_shows_auto_land() {
    let mut s = Session::new(LinkConfig::default(), 0.0);
    let mut px4 = Px4 {
        acks: true,
        ..Px4::new()
    };
    run(&mut s, &mut px4, 0.0, 3.0);
    s.finish();
    let t = s.tick(3.0);
    assert_eq!(
        commands(&t.send).first().map(|c| c.0),
        Some(MavCmd::MAV_CMD_DO_SET_MODE)
    );
    assert_eq!(s.phase(), Phase::Finishing);
    // PX4's land detector disarmed it in OFFBOARD; the AUTO.LAND request is never shown.
    px4.shows = false;
    px4.armed = false;
    px4.answer(&mut s, &[], 3.05);
    s.tick(3.1);
    assert_eq!(s.phase(), Phase::Done);
}

#[test]
fn off_mission_trips_ask_for_auto_land_only_while_flying() {
    let mut s = Session::new(LinkConfig::default(), 0.0);
    let mut px4 = Px4::new();
    let f = Failsafe::OffMission(Deviation::Inverted);
    s.trip(f);
    run(&mut s, &mut px4, 0.0, 3.0);
    assert_eq!(
        s.phase(),
        Phase::Flying,
        "a trip before the flight is ignored"
    );
    s.trip(f);
    let t = s.tick(3.0);
    assert_eq!(t.failsafe, Some(f));
    let modes = param3(&t.send);
    assert_eq!(
        commands(&t.send).first().map(|c| (c.0, c.1 as u8)),
        Some((MavCmd::MAV_CMD_DO_SET_MODE, 4))
    );
    assert_eq!(modes.first().map(|p| *p as u8), Some(6), "AUTO.LAND");
    assert_eq!(f.mode(), Some(Px4Mode::Land));
}

#[test]
fn once_px4_says_landed_the_finished_session_disarms_it() {
    let mut s = Session::new(LinkConfig::default(), 0.0);
    let mut px4 = Px4::new();
    run(&mut s, &mut px4, 0.0, 3.0);
    s.finish();
    s.tick(3.0);
    assert_eq!(s.phase(), Phase::Finishing);
    // Still in the air: no disarm.
    s.on_inbound(&Inbound::Landed(LandedState::InAir), 3.1);
    assert!(disarms(&s.tick(3.1).send).is_empty());
    s.on_inbound(&Inbound::Landed(LandedState::OnGround), 3.2);
    let sent = s.tick(3.2).send;
    assert_eq!(disarms(&sent).len(), 1, "{sent:?}");
    // Not asked again before its acknowledgement times out.
    assert!(disarms(&s.tick(3.3).send).is_empty());
    px4.armed = false;
    px4.answer(&mut s, &[], 3.4);
    s.tick(3.4);
    assert_eq!(s.phase(), Phase::Done);
}

/// The disarm commands (ARM_DISARM with param1 = 0) among `msgs`.
fn disarms(msgs: &[MavMessage]) -> Vec<&MavMessage> {
    msgs.iter()
        .filter(|m| {
            matches!(m, MavMessage::COMMAND_LONG(c)
                if c.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM && c.param1 == 0.0)
        })
        .collect()
}

#[test]
fn after_a_failsafe_px4_flies_and_is_disarmed_once_it_says_landed() {
    let mut s = Session::new(LinkConfig::default(), 0.0);
    let mut px4 = Px4::new();
    run(&mut s, &mut px4, 0.0, 3.0);
    // PX4's own failsafe takes the vehicle (DESCEND after a crash).
    px4.mode = Px4Mode::Other(4, 12);
    px4.answer(&mut s, &[], 3.0);
    assert_eq!(s.tick(3.01).failsafe, Some(Failsafe::Px4LeftOffboard));
    assert!(
        disarms(&s.tick(3.1).send).is_empty(),
        "not while in the air"
    );
    s.on_inbound(&Inbound::Landed(LandedState::OnGround), 3.2);
    assert_eq!(disarms(&s.tick(3.2).send).len(), 1);
}
