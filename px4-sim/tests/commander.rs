//! The simulated PX4's commander against PX4's offboard rules, and the shim's session
//! talking to it through real MAVLink frames (encoded and decoded), without physics.

use firmware_shim::link::{Failsafe, LinkConfig, Phase, Session};
use firmware_shim::messages::{self, Inbound, OdometryNed, Px4Mode, classify, decode, encode};
use mavlink::MavHeader;
use mavlink::dialects::common::{MavMessage, MavResult};
use px4_sim::commander::{Commander, CommanderConfig, Control, VehicleStatus};

const GROUND: VehicleStatus = VehicleStatus {
    pose_valid: true,
    landed: true,
};
const AIR: VehicleStatus = VehicleStatus {
    pose_valid: true,
    landed: false,
};

fn results(out: &[MavMessage]) -> Vec<MavResult> {
    out.iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_ACK(a) => Some(a.result),
            _ => None,
        })
        .collect()
}

fn mode(m: Px4Mode) -> MavMessage {
    messages::command_long(messages::Command::SetMode(m), 0)
}

#[test]
fn offboard_needs_a_live_stream_and_acks_come_twice() {
    let mut px4 = Commander::new(CommanderConfig::default());
    assert_eq!(
        results(&px4.on_message(&mode(Px4Mode::Offboard), 0.0)),
        [MavResult::MAV_RESULT_TEMPORARILY_REJECTED; 2]
    );
    assert_eq!(px4.mode(), Px4Mode::Position);
    // Invalid setpoints do not count as a stream.
    for bad in [
        messages::set_attitude_target([0.0; 3], f32::NAN, 0),
        messages::set_attitude_target([0.0; 3], 1.5, 0),
        messages::set_attitude_target([f32::INFINITY, 0.0, 0.0], 0.5, 0),
    ] {
        px4.on_message(&bad, 0.1);
    }
    assert_eq!(
        results(&px4.on_message(&mode(Px4Mode::Offboard), 0.2)),
        [MavResult::MAV_RESULT_TEMPORARILY_REJECTED; 2]
    );
    px4.on_message(&messages::set_attitude_target([0.0; 3], 0.0, 0), 0.3);
    assert_eq!(
        results(&px4.on_message(&mode(Px4Mode::Offboard), 0.4)),
        [MavResult::MAV_RESULT_ACCEPTED; 2]
    );
    assert_eq!(px4.mode(), Px4Mode::Offboard);
    // The heartbeat shows it.
    let hb = px4.heartbeat();
    let header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
    assert_eq!(
        classify(&header, &hb),
        Inbound::Heartbeat {
            armed: false,
            mode: Px4Mode::Offboard
        }
    );
}

#[test]
fn arming_checks_and_auto_disarm_after_landing() {
    let mut px4 = Commander::new(CommanderConfig::default());
    let arm = messages::command_long(messages::Command::Arm, 0);
    px4.tick(
        0.0,
        VehicleStatus {
            pose_valid: false,
            landed: true,
        },
    );
    assert_eq!(
        results(&px4.on_message(&arm, 0.0)),
        [MavResult::MAV_RESULT_DENIED]
    );
    px4.tick(0.1, GROUND);
    assert_eq!(
        results(&px4.on_message(&arm, 0.1)),
        [MavResult::MAV_RESULT_ACCEPTED]
    );
    assert!(px4.armed());
    // In the air: no disarm.
    px4.tick(1.0, AIR);
    let disarm = messages::command_long(messages::Command::Disarm, 0);
    assert_eq!(
        results(&px4.on_message(&disarm, 1.0)),
        [MavResult::MAV_RESULT_DENIED]
    );
    // AUTO.LAND: PX4 flies, then disarms on its own once its land detector has said
    // landed for COM_DISARM_LAND (2 s).
    px4.on_message(&mode(Px4Mode::Land), 1.1);
    assert_eq!(px4.tick(1.2, AIR).0, Control::Px4(Px4Mode::Land));
    assert_eq!(px4.tick(5.0, GROUND).0, Control::Px4(Px4Mode::Land));
    assert_eq!(px4.tick(6.99, GROUND).0, Control::Px4(Px4Mode::Land));
    assert!(px4.armed() && px4.auto_disarmed_at().is_empty());
    assert_eq!(px4.tick(7.0, GROUND).0, Control::Disarmed);
    assert!(!px4.armed());
    assert_eq!(px4.auto_disarmed_at(), [7.0]);
}

/// COM_DISARM_LAND in OFFBOARD too (PX4 v1.16 did), only after a take-off, and a moment in
/// the air restarts the 2 s.
#[test]
fn px4_disarms_two_seconds_after_landed_in_any_mode_once_it_has_flown() {
    let mut px4 = Commander::new(CommanderConfig::default());
    let sp = messages::set_attitude_target([0.0; 3], 0.1, 0);
    px4.tick(0.0, GROUND);
    px4.on_message(&sp, 0.0);
    px4.on_message(&mode(Px4Mode::Offboard), 0.0);
    px4.on_message(&messages::command_long(messages::Command::Arm, 0), 0.0);
    // Armed on the ground, never flown: no automatic disarm (COM_DISARM_PRFLT is not
    // simulated).
    let mut t = 0.0;
    while t < 5.0 {
        px4.on_message(&sp, t);
        assert!(matches!(px4.tick(t, GROUND).0, Control::Offboard(_)), "{t}");
        t += 0.01;
    }
    // Flies, lands, lifts off again briefly at 7.5 s, lands for good.
    let air = |t: f64| (5.0..6.0).contains(&t) || (7.5..7.6).contains(&t);
    let mut disarmed_at = None;
    while t < 12.0 && disarmed_at.is_none() {
        px4.on_message(&sp, t);
        px4.tick(t, if air(t) { AIR } else { GROUND });
        if !px4.armed() {
            disarmed_at = Some(t);
        }
        t += 0.01;
    }
    let at = disarmed_at.expect("PX4 disarmed");
    assert!((at - 9.6).abs() < 0.015, "{at}");
    assert_eq!(px4.mode(), Px4Mode::Offboard);
    assert_eq!(px4.auto_disarmed_at(), [at]);
    // Never with COM_DISARM_LAND <= 0.
    let mut px4 = Commander::new(CommanderConfig {
        disarm_land_delay: 0.0,
        ..CommanderConfig::default()
    });
    px4.tick(0.0, GROUND);
    px4.on_message(&messages::command_long(messages::Command::Arm, 0), 0.0);
    px4.tick(1.0, AIR);
    px4.tick(2.0, GROUND);
    px4.tick(60.0, GROUND);
    assert!(px4.armed());
}

/// PX4's `Hysteresis` as the land detector uses it: true after the delay, false at once.
#[test]
fn hysteresis_switches_on_after_its_delay_and_off_at_once() {
    use px4_sim::commander::Hysteresis;
    let mut h = Hysteresis::new(false, 1.0);
    assert!(!h.update(true, 0.0));
    assert!(!h.update(true, 0.99));
    assert!(h.update(true, 1.0));
    assert!(!h.update(false, 1.5));
    // An interrupted request starts over.
    assert!(!h.update(true, 2.0));
    assert!(!h.update(false, 2.5));
    assert!(!h.update(true, 2.6));
    assert!(!h.update(true, 3.5));
    assert!(h.update(true, 3.6));
}

fn detector_input(thrust: f64, vz: f64) -> px4_sim::commander::LandDetectorInput {
    px4_sim::commander::LandDetectorInput {
        armed: true,
        thrust,
        hover_thrust: 0.5,
        climb_rate_control: false,
        descending: false,
        vz,
        v_xy: 0.0,
        rate_xy: 0.0,
    }
}

/// Runs a fresh armed detector on `input` for `seconds` at 1 kHz after one airborne update;
/// returns when it first said landed.
fn landed_after(input: px4_sim::commander::LandDetectorInput, seconds: f64) -> Option<f64> {
    use px4_sim::commander::{LandDetector, LandDetectorConfig};
    let mut d = LandDetector::new(LandDetectorConfig::default());
    // Airborne: full thrust, climbing.
    assert!(!d.update(0.0, &detector_input(0.6, 1.0)));
    (1..=(seconds * 1000.0) as usize)
        .map(|i| i as f64 * 1e-3)
        .find(|&t| d.update(t, &input))
}

/// PX4's multicopter land detector: ground contact (low thrust, no vertical movement), maybe
/// landed (minimal thrust, no rotation), landed, each a third of LNDMC_TRIG_TIME (1 s).
#[test]
fn the_land_detector_says_landed_one_second_after_ground_contact() {
    use px4_sim::commander::{LandDetector, LandDetectorConfig};
    // OFFBOARD (no climb-rate control): thrust at most MPC_MANTHR_MIN + 0.01 = 0.09.
    let t = landed_after(detector_input(0.05, 0.0), 3.0).expect("landed");
    assert!((t - 1.0).abs() < 0.005, "{t}");
    assert_eq!(
        landed_after(detector_input(0.1, 0.0), 3.0),
        None,
        "thrust 0.1"
    );
    assert_eq!(
        landed_after(detector_input(0.05, 0.3), 3.0),
        None,
        "sinking"
    );
    let rotating = px4_sim::commander::LandDetectorInput {
        rate_xy: 0.5,
        ..detector_input(0.05, 0.0)
    };
    assert_eq!(landed_after(rotating, 3.0), None, "rotating");
    let sliding = px4_sim::commander::LandDetectorInput {
        v_xy: 2.0,
        ..detector_input(0.05, 0.0)
    };
    assert_eq!(landed_after(sliding, 3.0), None, "sliding");
    // PX4's position control: ground contact needs a commanded descent, and the thrust
    // threshold is MPC_THR_MIN + 0.1 (MPC_THR_HOVER - MPC_THR_MIN) = 0.158.
    let hold = px4_sim::commander::LandDetectorInput {
        climb_rate_control: true,
        ..detector_input(0.15, 0.0)
    };
    assert_eq!(landed_after(hold, 3.0), None, "holding");
    let land = px4_sim::commander::LandDetectorInput {
        descending: true,
        ..hold
    };
    let t = landed_after(land, 3.0).expect("landed in AUTO.LAND");
    assert!((t - 1.0).abs() < 0.005, "{t}");
    // Ground contact alone needs only low thrust: MPC_THR_MIN + 0.3 (MPC_THR_HOVER -
    // MPC_THR_MIN) = 0.234.
    for (thrust, contact) in [(0.2, true), (0.25, false)] {
        let mut d = LandDetector::new(LandDetectorConfig::default());
        d.update(0.0, &detector_input(0.6, 1.0));
        for i in 1..=500 {
            d.update(f64::from(i) * 1e-3, &detector_input(thrust, 0.0));
        }
        assert_eq!(d.ground_contact(), contact, "thrust {thrust}");
        assert!(!d.maybe_landed() && !d.landed());
    }
    // Landed drops at once with thrust; disarmed, it is landed a third of
    // LNDMC_TRIG_TIME later whatever it reads.
    let mut d = LandDetector::new(LandDetectorConfig::default());
    assert!(d.update(0.0, &detector_input(0.05, 0.0)), "starts landed");
    assert!(!d.update(0.001, &detector_input(0.3, 0.0)));
    let disarmed = px4_sim::commander::LandDetectorInput {
        armed: false,
        ..detector_input(0.9, 3.0)
    };
    assert!(!d.update(0.002, &disarmed));
    assert!(!d.update(0.33, &disarmed));
    assert!(d.update(0.336, &disarmed));
}

#[test]
fn a_silent_stream_in_offboard_is_the_offboard_loss_failsafe() {
    let cfg = CommanderConfig::default();
    let mut px4 = Commander::new(cfg);
    px4.tick(0.0, GROUND);
    let sp = messages::set_attitude_target([0.1, 0.0, 0.0], 0.6, 0);
    px4.on_message(&sp, 0.0);
    px4.on_message(&mode(Px4Mode::Offboard), 0.0);
    px4.on_message(&messages::command_long(messages::Command::Arm, 0), 0.0);
    let mut t = 0.0;
    while t < 2.0 {
        px4.on_message(&sp, t);
        let (c, _) = px4.tick(t, AIR);
        assert!(
            matches!(c, Control::Offboard(s) if s.thrust == 0.6),
            "{c:?}"
        );
        t += 0.01;
    }
    // The controller dies at 2.0 s: PX4 holds position after the timeout, not before.
    let last = t - 0.01;
    while t < 3.0 {
        let (c, _) = px4.tick(t, AIR);
        if t - last <= cfg.offboard_loss_timeout {
            assert!(matches!(c, Control::Offboard(_)), "at {t}");
        } else {
            assert_eq!(c, Control::Px4(Px4Mode::Position), "at {t}");
        }
        t += 0.01;
    }
    let at = px4.failsafe_at().expect("the failsafe engaged");
    assert!(
        at - last > cfg.offboard_loss_timeout && at - last <= cfg.offboard_loss_timeout + 0.011
    );
    // Back in OFFBOARD needs a new request with a live stream.
    px4.on_message(&sp, 3.0);
    assert_eq!(px4.tick(3.0, AIR).0, Control::Px4(Px4Mode::Position));
}

/// The shim's session and the simulated commander, exchanging encoded MAVLink frames: the
/// session reaches Flying; when the controller stops streaming, the commander fails safe and
/// the session notices PX4 left OFFBOARD.
#[test]
fn the_session_flies_the_simulated_px4_and_notices_its_failsafe() {
    let mut px4 = Commander::new(CommanderConfig::default());
    let mut s = Session::new(LinkConfig::default(), 0.0);
    let px4_header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
    let odom = Inbound::Odometry(OdometryNed {
        time_us: 0,
        position: [0.0; 3],
        velocity: [0.0; 3],
        q: [1.0, 0.0, 0.0, 0.0],
        rates: [0.0; 3],
    });
    let wire = |m: &MavMessage, h: MavHeader| decode(&encode(h, m).unwrap()).unwrap();
    let dt = 0.02;
    let mut t = 0.0;
    let mut streaming = true;
    let mut flying_at = None;
    let mut noticed = None;
    while t < 12.0 {
        let tick = s.tick(t);
        let mut to_px4 = tick.send.clone();
        if streaming {
            to_px4.push(messages::set_attitude_target([0.0; 3], 0.5, 0));
        }
        let mut from_px4 = Vec::new();
        for m in &to_px4 {
            let (_, m) = wire(m, messages::our_header(1, 0));
            from_px4.extend(px4.on_message(&m, t));
        }
        let status = if px4.armed() { AIR } else { GROUND };
        let (_, out) = px4.tick(t, status);
        from_px4.extend(out);
        for m in &from_px4 {
            let (h, m) = wire(m, px4_header);
            s.on_inbound(&classify(&h, &m), t);
        }
        s.on_inbound(&odom, t);
        if s.phase() == Phase::Flying && flying_at.is_none() {
            flying_at = Some(t);
        }
        if flying_at.is_some_and(|f| t - f > 2.0) {
            streaming = false; // the controller process dies
        }
        if tick.failsafe == Some(Failsafe::Px4LeftOffboard) {
            noticed = Some(t);
            break;
        }
        t += dt;
    }
    let flying_at = flying_at.expect("the session reached Flying");
    assert!(flying_at >= 1.0, "OFFBOARD only after 1 s of streaming");
    assert!(px4.armed());
    let failsafe = px4.failsafe_at().expect("the commander failed safe");
    let noticed = noticed.expect("the session noticed");
    // The commander within the timeout (+ a step) of the last setpoint; the session at the
    // next heartbeat (1 Hz).
    let stopped = flying_at + 2.0;
    assert!(
        failsafe - stopped <= 0.5 + 2.0 * dt + 1e-9,
        "{failsafe} vs {stopped}"
    );
    assert!(noticed >= failsafe && noticed - failsafe <= 1.0 + dt + 1e-9);
    assert_eq!(px4.mode(), Px4Mode::Position);
}

/// MAV_CMD_SET_MESSAGE_INTERVAL as PX4's mavlink module takes it: param1 the id (rounded),
/// param2 the interval in microseconds (negative stops, 0 restores the default), one ACK;
/// FAILED for HEARTBEAT, for messages the vehicle does not stream and for options PX4 does
/// not support (param3, param4, param7 not 0).
#[test]
fn set_message_interval_sets_the_stream_rates_as_px4() {
    use mavlink::dialects::common::{COMMAND_LONG_DATA, MavCmd};
    use px4_sim::commander::{MessageInterval, STREAMED_MESSAGES};
    let cmd = |p1: f32, p2: f32, p3: f32, p7: f32| {
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: p1,
            param2: p2,
            param3: p3,
            param7: p7,
            command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            target_system: 1,
            target_component: 1,
            ..COMMAND_LONG_DATA::DEFAULT
        })
    };
    let mut px4 = Commander::new(CommanderConfig::default());
    assert_eq!(STREAMED_MESSAGES, [31, 32, 245, 331]);
    for id in STREAMED_MESSAGES {
        assert_eq!(px4.message_interval(id), Some(MessageInterval::Default));
    }
    assert_eq!(px4.message_interval(30), None);
    let ok = [MavResult::MAV_RESULT_ACCEPTED];
    let failed = [MavResult::MAV_RESULT_FAILED];
    // The shim's request: ODOMETRY at 100 Hz.
    let shim = messages::command_long(
        messages::Command::MessageInterval {
            message_id: 331,
            hz: 100.0,
        },
        0,
    );
    assert_eq!(results(&px4.on_message(&shim, 0.0)), ok);
    let Some(MessageInterval::Every(p)) = px4.message_interval(331) else {
        panic!("{:?}", px4.message_interval(331))
    };
    assert!((p - 0.01).abs() < 1e-9, "{p}");
    // The id is rounded as PX4 does; -1 (any negative) stops; 0 and NaN restore the default.
    assert_eq!(
        results(&px4.on_message(&cmd(30.6, -1.0, 0.0, 0.0), 0.0)),
        ok
    );
    assert_eq!(px4.message_interval(31), Some(MessageInterval::Stopped));
    assert_eq!(
        results(&px4.on_message(&cmd(32.0, -5.0, 0.0, 0.0), 0.0)),
        ok
    );
    assert_eq!(px4.message_interval(32), Some(MessageInterval::Stopped));
    assert_eq!(results(&px4.on_message(&cmd(31.0, 0.0, 0.0, 0.0), 0.0)), ok);
    assert_eq!(px4.message_interval(31), Some(MessageInterval::Default));
    assert_eq!(
        results(&px4.on_message(&cmd(32.0, f32::NAN, 0.0, 0.0), 0.0)),
        ok
    );
    assert_eq!(px4.message_interval(32), Some(MessageInterval::Default));
    // PX4 answers FAILED and changes nothing for these.
    for bad in [
        cmd(0.0, 1e6, 0.0, 0.0),      // HEARTBEAT
        cmd(105.0, 1e4, 0.0, 0.0),    // HIGHRES_IMU: not simulated
        cmd(-331.0, 1e4, 0.0, 0.0),   // no such id
        cmd(f32::NAN, 1e4, 0.0, 0.0), // id 0
        cmd(331.0, 5e4, 1.0, 0.0),    // param3: unsupported
        cmd(331.0, 5e4, 0.0, 2.0),    // param7: response target
    ] {
        assert_eq!(results(&px4.on_message(&bad, 0.0)), failed, "{bad:?}");
    }
    let kept = px4.message_interval(331);
    assert!(
        matches!(kept, Some(MessageInterval::Every(p)) if (p - 0.01).abs() < 1e-9),
        "{kept:?}"
    );
    // Not a mode change: the mode and arming are untouched.
    assert_eq!(px4.mode(), Px4Mode::Position);
    assert!(!px4.armed());
}
