//! The offboard link's messages: the wire bytes checked by an independent decoder written
//! here from the MAVLink 2 specification (header layout, field order, X.25 CRC with the
//! message's CRC_EXTRA), PX4's custom-mode encoding as observed on PX4 v1.16 SITL, and the
//! classification of what PX4 sends.

use firmware_shim::messages::{
    self as m, Command, Inbound, LandedState, Px4Mode, classify, command_long, decode, encode,
    heartbeat, our_header, set_attitude_target,
};
use mavlink::MavHeader;
use mavlink::dialects::common::{
    self as mc, MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag,
};

/// CRC-16/MCRF4XX (X.25) as MAVLink defines it.
fn x25(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xffff;
    for &b in bytes {
        let mut tmp = b ^ (crc & 0xff) as u8;
        tmp ^= tmp << 4;
        crc = (crc >> 8) ^ (u16::from(tmp) << 8) ^ (u16::from(tmp) << 3) ^ (u16::from(tmp) >> 4);
    }
    crc
}

/// Splits a MAVLink 2 frame: (seq, sysid, compid, msgid, payload), checking magic, flags and
/// the CRC with `crc_extra`.
fn parse_v2(frame: &[u8], crc_extra: u8) -> (u8, u8, u8, u32, Vec<u8>) {
    assert_eq!(frame[0], 0xFD, "MAVLink 2 magic");
    let len = usize::from(frame[1]);
    assert_eq!(frame[2], 0, "no incompatibility flags (unsigned)");
    assert_eq!(frame.len(), 10 + len + 2, "header + payload + CRC");
    let msgid = u32::from(frame[7]) | (u32::from(frame[8]) << 8) | (u32::from(frame[9]) << 16);
    let mut crc_in = frame[1..10 + len].to_vec();
    crc_in.push(crc_extra);
    let crc = x25(&crc_in);
    let got = u16::from(frame[10 + len]) | (u16::from(frame[11 + len]) << 8);
    assert_eq!(crc, got, "CRC");
    (
        frame[4],
        frame[5],
        frame[6],
        msgid,
        frame[10..10 + len].to_vec(),
    )
}

fn f32_at(p: &[u8], at: usize) -> f32 {
    // MAVLink 2 truncates trailing zero bytes of the payload: read them back as zeros.
    let mut b = [0u8; 4];
    for (i, x) in b.iter_mut().enumerate() {
        *x = p.get(at + i).copied().unwrap_or(0);
    }
    f32::from_le_bytes(b)
}

#[test]
fn set_attitude_target_on_the_wire() {
    let msg = set_attitude_target([0.5, -1.25, 2.0], 0.625, 123_456);
    let frame = encode(our_header(42, 7), &msg).unwrap();
    // SET_ATTITUDE_TARGET: id 82, CRC_EXTRA 49 (MAVLink common.xml).
    let (seq, sys, comp, id, p) = parse_v2(&frame, 49);
    assert_eq!((seq, sys, comp, id), (7, 42, m::COMPANION_COMPONENT, 82));
    // Field order of the payload (sorted by size): time_boot_ms, q[4], roll, pitch, yaw rates,
    // thrust, target_system, target_component, type_mask.
    assert_eq!(u32::from_le_bytes([p[0], p[1], p[2], p[3]]), 123_456);
    let q: Vec<f32> = (0..4).map(|i| f32_at(&p, 4 + 4 * i)).collect();
    assert_eq!(q, [1.0, 0.0, 0.0, 0.0], "q must be filled (identity)");
    assert_eq!(f32_at(&p, 20), 0.5);
    assert_eq!(f32_at(&p, 24), -1.25);
    assert_eq!(f32_at(&p, 28), 2.0);
    assert_eq!(f32_at(&p, 32), 0.625);
    assert_eq!((p[36], p[37]), (m::PX4_SYSTEM, m::PX4_COMPONENT));
    assert_eq!(
        p[38], 128,
        "type_mask: attitude ignored, rates and thrust used"
    );
    // And the crate's own decoder agrees.
    let (h, back) = decode(&frame).unwrap();
    assert_eq!(h.sequence, 7);
    assert_eq!(back, msg);
}

#[test]
fn heartbeat_and_commands_on_the_wire() {
    // HEARTBEAT: id 0, CRC_EXTRA 50; payload custom_mode u32, type, autopilot, base_mode,
    // system_status, mavlink_version.
    let frame = encode(our_header(1, 0), &heartbeat()).unwrap();
    let (_, _, _, id, p) = parse_v2(&frame, 50);
    assert_eq!(id, 0);
    let b = |i: usize| p.get(i).copied().unwrap_or(0);
    assert_eq!((b(4), b(5), b(6), b(7), b(8)), (18, 8, 0, 4, 3));

    // COMMAND_LONG: id 76, CRC_EXTRA 152; params 1-7 (f32), command u16, target system,
    // target component, confirmation.
    let cases = [
        (Command::Arm, 400, [1.0, 0.0, 0.0]),
        (Command::Disarm, 400, [0.0, 0.0, 0.0]),
        (Command::SetMode(Px4Mode::Offboard), 176, [1.0, 6.0, 0.0]),
        (Command::SetMode(Px4Mode::Land), 176, [1.0, 4.0, 6.0]),
        (Command::SetMode(Px4Mode::Return), 176, [1.0, 4.0, 5.0]),
        (
            Command::MessageInterval {
                message_id: 331,
                hz: 100.0,
            },
            511,
            [331.0, 10_000.0, 0.0],
        ),
    ];
    for (cmd, id_want, params) in cases {
        let frame = encode(our_header(1, 3), &command_long(cmd, 2)).unwrap();
        let (_, _, _, id, p) = parse_v2(&frame, 152);
        assert_eq!(id, 76);
        for (i, want) in params.iter().enumerate() {
            assert_eq!(f32_at(&p, 4 * i), *want, "{cmd:?} param{}", i + 1);
        }
        let command = u16::from(p[28]) | (u16::from(p[29]) << 8);
        assert_eq!(u32::from(command), id_want, "{cmd:?}");
        assert_eq!((p[30], p[31]), (1, 1), "{cmd:?} targets PX4");
        assert_eq!(p.get(32).copied().unwrap_or(0), 2, "confirmation");
    }
}

#[test]
fn px4_custom_modes_as_observed_on_sitl() {
    // main mode in bits 16-23, sub mode in 24-31 (PX4 v1.16).
    let cases = [
        (6u32 << 16, Px4Mode::Offboard),
        ((4 << 16) | (6 << 24), Px4Mode::Land),
        ((4 << 16) | (5 << 24), Px4Mode::Return),
        (3 << 16, Px4Mode::Position),
        ((4 << 16) | (4 << 24), Px4Mode::Other(4, 4)),
    ];
    for (custom, mode) in cases {
        assert_eq!(Px4Mode::from_custom_mode(custom), mode, "{custom:#x}");
        assert_eq!(mode.custom_mode(), custom, "{mode:?}");
    }
}

fn px4() -> MavHeader {
    MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    }
}

fn px4_heartbeat(armed: bool, custom_mode: u32) -> MavMessage {
    MavMessage::HEARTBEAT(mc::HEARTBEAT_DATA {
        custom_mode,
        mavtype: mc::MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode: if armed {
            MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        } else {
            MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        },
        system_status: mc::MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

#[test]
fn heartbeats_are_px4s_only() {
    assert_eq!(
        classify(&px4(), &px4_heartbeat(true, 6 << 16)),
        Inbound::Heartbeat {
            armed: true,
            mode: Px4Mode::Offboard
        }
    );
    assert_eq!(
        classify(&px4(), &px4_heartbeat(false, 3 << 16)),
        Inbound::Heartbeat {
            armed: false,
            mode: Px4Mode::Position
        }
    );
    // A ground station (autopilot INVALID) and component 0 are not the autopilot.
    let gcs = MavHeader {
        system_id: 255,
        component_id: 190,
        sequence: 0,
    };
    assert_eq!(classify(&gcs, &heartbeat()), Inbound::Ignored);
    let comp0 = MavHeader {
        component_id: 0,
        ..px4()
    };
    assert_eq!(classify(&comp0, &px4_heartbeat(true, 0)), Inbound::Ignored);
}

fn odometry(child: MavFrame, q: [f32; 4], v: [f32; 3]) -> MavMessage {
    MavMessage::ODOMETRY(mc::ODOMETRY_DATA {
        time_usec: 5_000_000,
        x: 1.0,
        y: 2.0,
        z: -3.0,
        q,
        vx: v[0],
        vy: v[1],
        vz: v[2],
        rollspeed: 0.1,
        pitchspeed: 0.2,
        yawspeed: 0.3,
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: child,
        ..mc::ODOMETRY_DATA::DEFAULT
    })
}

#[test]
fn odometry_in_ned_and_in_the_body_frame() {
    let s = std::f32::consts::FRAC_1_SQRT_2;
    // Facing east (yaw +90 deg in NED): q = (cos 45, 0, 0, sin 45).
    let q = [s, 0.0, 0.0, s];
    let Inbound::Odometry(o) = classify(
        &px4(),
        &odometry(MavFrame::MAV_FRAME_LOCAL_NED, q, [0.5, -0.5, 0.25]),
    ) else {
        panic!("not odometry");
    };
    assert_eq!(o.time_us, 5_000_000);
    assert_eq!(o.position, [1.0, 2.0, -3.0]);
    assert_eq!(o.velocity, [0.5, -0.5, 0.25]);
    assert_eq!(o.rates, [0.1, 0.2, 0.3]);
    assert_eq!(o.q, q);
    // Velocity in FRD: 1 m/s forward while facing east is 1 m/s east in NED; 1 m/s right
    // is 1 m/s south; down stays down.
    let Inbound::Odometry(b) = classify(
        &px4(),
        &odometry(MavFrame::MAV_FRAME_BODY_FRD, q, [1.0, 2.0, 3.0]),
    ) else {
        panic!("not odometry");
    };
    let want = [-2.0, 1.0, 3.0];
    for (got, want) in b.velocity.iter().zip(want) {
        assert!((got - want).abs() < 1e-6, "{:?}", b.velocity);
    }
    // Not from PX4's autopilot, or in another world frame: ignored.
    let other = MavHeader {
        system_id: 2,
        ..px4()
    };
    assert_eq!(
        classify(
            &other,
            &odometry(MavFrame::MAV_FRAME_LOCAL_NED, q, [0.0; 3])
        ),
        Inbound::Ignored
    );
    let mut enu = odometry(MavFrame::MAV_FRAME_LOCAL_NED, q, [0.0; 3]);
    if let MavMessage::ODOMETRY(d) = &mut enu {
        d.frame_id = MavFrame::MAV_FRAME_LOCAL_ENU;
    }
    assert_eq!(classify(&px4(), &enu), Inbound::Ignored);
}

#[test]
fn acks_and_landed_state() {
    let ack = |result| {
        MavMessage::COMMAND_ACK(mc::COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            result,
        })
    };
    assert_eq!(
        classify(&px4(), &ack(mc::MavResult::MAV_RESULT_ACCEPTED)),
        Inbound::Ack {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            accepted: true,
            in_progress: false
        }
    );
    assert_eq!(
        classify(&px4(), &ack(mc::MavResult::MAV_RESULT_DENIED)),
        Inbound::Ack {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            accepted: false,
            in_progress: false
        }
    );
    let landed = MavMessage::EXTENDED_SYS_STATE(mc::EXTENDED_SYS_STATE_DATA {
        landed_state: mc::MavLandedState::MAV_LANDED_STATE_ON_GROUND,
        ..mc::EXTENDED_SYS_STATE_DATA::DEFAULT
    });
    assert_eq!(
        classify(&px4(), &landed),
        Inbound::Landed(LandedState::OnGround)
    );
}

#[test]
fn bad_frames_are_errors() {
    assert!(decode(&[]).is_err());
    assert!(decode(&[0xFD, 3, 0, 0]).is_err());
    let mut frame = encode(our_header(1, 0), &heartbeat()).unwrap();
    let last = frame.len() - 1;
    frame[last] ^= 0x5a;
    assert!(decode(&frame).is_err(), "a corrupted CRC is refused");
}

fn from(system_id: u8, component_id: u8) -> MavHeader {
    MavHeader {
        system_id,
        component_id,
        sequence: 0,
    }
}

#[test]
fn px4_sitl_instance_i_is_system_i_plus_1_and_nothing_else_is_taken_for_it() {
    let hb = px4_heartbeat(true, 0);
    // PX4 SITL's instance 5: system 6.
    assert_eq!(m::px4_heartbeat_system(&from(6, 1), &hb), Some(6));
    assert_eq!(m::px4_heartbeat_system(&from(6, 0), &hb), None);
    assert_eq!(m::px4_heartbeat_system(&from(6, 1), &heartbeat()), None);
    let Inbound::Heartbeat { armed, .. } = m::classify_from(&from(6, 1), &hb, 6) else {
        panic!("PX4's heartbeat as system 6");
    };
    assert!(armed);
    // Another system's heartbeat and state are ignored once the autopilot is known.
    assert_eq!(m::classify_from(&from(1, 1), &hb, 6), Inbound::Ignored);
    let ts = MavMessage::TIMESYNC(mc::TIMESYNC_DATA { tc1: 5, ts1: 7 });
    assert_eq!(m::classify_from(&from(1, 1), &ts, 6), Inbound::Ignored);
    assert_eq!(
        m::classify_from(&from(6, 1), &ts, 6),
        Inbound::Timesync { tc1: 5, ts1: 7 }
    );
}

#[test]
fn timesync_requests_carry_tc1_zero_and_requests_are_not_answers() {
    let MavMessage::TIMESYNC(t) = m::timesync_request(123_456_789) else {
        panic!("a TIMESYNC");
    };
    assert_eq!((t.tc1, t.ts1), (0, 123_456_789));
    // A request from PX4 (tc1 = 0) is not an answer to ours.
    let req = m::timesync_request(1);
    assert_eq!(classify(&from(1, 1), &req), Inbound::Ignored);
    // Through the wire and an independent decoder's id: TIMESYNC is message 111.
    let bytes = encode(our_header(1, 0), &m::timesync_request(42)).unwrap();
    let (_, _, _, id, _) = parse_v2(&bytes, 34);
    assert_eq!(id, 111);
}

#[test]
fn what_we_send_is_addressed_to_the_autopilot_we_locked_on() {
    let mut msgs = vec![
        set_attitude_target([0.0; 3], 0.5, 0),
        command_long(Command::Arm, 0),
        m::param_request_read(m::HOVER_THRUST_PARAM),
    ];
    for msg in &mut msgs {
        m::retarget(msg, 6);
    }
    let targets: Vec<u8> = msgs
        .iter()
        .map(|msg| match msg {
            MavMessage::SET_ATTITUDE_TARGET(s) => s.target_system,
            MavMessage::COMMAND_LONG(c) => c.target_system,
            MavMessage::PARAM_REQUEST_READ(p) => p.target_system,
            _ => 0,
        })
        .collect();
    assert_eq!(targets, [6, 6, 6]);
}
