//! The simulated PX4 vehicle: flown by offboard setpoints, its offboard-loss failsafe holding
//! position with the physics, AUTO.LAND landing and disarming, PX4's attitude controller
//! recovering from a flip interrupted by AUTO.RTL, the streams at PX4's rates (and as
//! MAV_CMD_SET_MESSAGE_INTERVAL sets them) in PX4's frames, and the flight record.

use std::f64::consts::PI;

use firmware_shim::frames::{quat_enu_flu_to_ned_frd, quat_from_mavlink, quat_ned_frd_to_enu_flu};
use firmware_shim::messages::{self, Command, Inbound, Px4Mode, classify};
use firmware_shim::sitl::CommanderConfig;
use firmware_shim::vehicle::{AttitudeGains, SimVehicle, VehicleConfig, attitude_control};
use mavlink::MavHeader;
use mavlink::dialects::common::{self as mc, MavCmd, MavMessage, MavResult};
use mpc_sim::estimator::EstimatorConfig;
use nalgebra::{UnitQuaternion, Vector3};

const PX4: MavHeader = MavHeader {
    system_id: 1,
    component_id: 1,
    sequence: 0,
};

fn odometry(msgs: &[MavMessage]) -> Vec<messages::OdometryNed> {
    msgs.iter()
        .filter_map(|m| match classify(&PX4, m) {
            Inbound::Odometry(o) => Some(o),
            _ => None,
        })
        .collect()
}

#[test]
fn odometry_is_in_px4s_frames() {
    let mut v = SimVehicle::new(VehicleConfig {
        estimator: EstimatorConfig::perfect(),
        home: nalgebra::Vector3::new(1.0, 2.0, 0.0),
        ..VehicleConfig::default()
    });
    let out = v.step(1.0);
    let odo = odometry(&out);
    assert!((29..=31).contains(&odo.len()), "PX4's 30 Hz: {}", odo.len());
    let o = odo.last().unwrap();
    // ENU (1, 2, 0) is NED (2, 1, 0); level with the nose east (ENU identity) is NED yaw 90°.
    assert_eq!(o.position, [2.0, 1.0, 0.0]);
    let s = std::f32::consts::FRAC_1_SQRT_2;
    for (got, want) in o.q.iter().zip([s, 0.0, 0.0, s]) {
        assert!((got - want).abs() < 1e-6, "{:?}", o.q);
    }
    assert!(out.iter().any(|m| matches!(m, MavMessage::HEARTBEAT(_))));
    assert!(
        out.iter()
            .any(|m| matches!(m, MavMessage::EXTENDED_SYS_STATE(_)))
    );
}

/// Streams `thrust` (rates zero) at 50 Hz for `seconds`.
fn stream(v: &mut SimVehicle, thrust: f32, seconds: f64) {
    let n = (seconds / 0.02).round() as usize;
    for _ in 0..n {
        v.handle(&messages::set_attitude_target([0.0; 3], thrust, 0));
        v.step(0.02);
    }
}

#[test]
fn offboard_flies_and_the_offboard_loss_failsafe_holds_position_then_land_disarms() {
    let cfg = VehicleConfig {
        commander: CommanderConfig::default(),
        ..VehicleConfig::default()
    };
    let mut v = SimVehicle::new(cfg);
    let hover = v.thrust_map().hover_thrust as f32;
    stream(&mut v, 0.0, 0.5);
    v.handle(&messages::command_long(
        Command::SetMode(Px4Mode::Offboard),
        0,
    ));
    v.handle(&messages::command_long(Command::Arm, 0));
    assert_eq!(v.commander().mode(), Px4Mode::Offboard);
    assert!(v.commander().armed());
    // Climb on 1.2 x hover thrust for 1.2 s.
    stream(&mut v, 1.2 * hover, 1.2);
    let z_climb = v.state().p.z;
    assert!(
        z_climb > 0.5,
        "the offboard setpoint flies it: z = {z_climb}"
    );
    // The controller dies: PX4 keeps the last setpoint until the loss timeout, then holds.
    // The last setpoint arrived at the start of the last 20 ms block.
    let t_last = v.time() - 0.02;
    v.step(0.45);
    assert_eq!(
        v.commander().mode(),
        Px4Mode::Offboard,
        "not before the timeout"
    );
    v.step(0.1);
    assert_eq!(v.commander().mode(), Px4Mode::Position);
    let t_fs = v.commander().failsafe_at().unwrap();
    assert!(
        t_fs - t_last > 0.5 && t_fs - t_last < 0.502,
        "{}",
        t_fs - t_last
    );
    // Hold: settles and stays.
    v.step(4.0);
    let p_hold = v.state().p;
    v.step(2.0);
    let drift = (v.state().p - p_hold).norm();
    assert!(drift < 0.1, "holds position: drift {drift} m");
    assert!(v.state().v.norm() < 0.2);
    assert!(!v.crashed() && p_hold.z > 1.0);
    // AUTO.LAND: down at 0.5 m/s, then disarmed on the ground.
    v.handle(&messages::command_long(Command::SetMode(Px4Mode::Land), 0));
    v.step(p_hold.z / 0.5 + 3.0);
    assert!(!v.crashed(), "a soft landing");
    assert!(v.state().p.z.abs() < 1e-9);
    assert!(!v.commander().armed(), "PX4 disarms after an AUTO landing");
}

const PX4_RATE_LIMIT: f64 = 220.0 * PI / 180.0;

#[test]
fn attitude_control_is_px4s_quaternion_law() {
    let g = AttitudeGains::default();
    let id = UnitQuaternion::identity();
    let about = |axis: Vector3<f64>, a: f64| UnitQuaternion::from_scaled_axis(axis * a);
    // Small errors: 2 sin(a/2) P per axis; yaw weighted by 0.4 with its gain divided by 0.4,
    // so a pure yaw error also gets about MC_YAW_P times the angle.
    let r = attitude_control(&id, &about(Vector3::x(), 0.1), &g);
    assert!((r.x - 2.0 * 0.05f64.sin() * 6.5).abs() < 1e-9 && r.y.abs() < 1e-9 && r.z.abs() < 1e-9);
    let r = attitude_control(&id, &about(Vector3::y(), -0.1), &g);
    assert!((r.y + 2.0 * 0.05f64.sin() * 6.5).abs() < 1e-9, "{r}");
    let r = attitude_control(&id, &about(Vector3::z(), 0.1), &g);
    assert!((r.z - 2.0 * 0.02f64.sin() * 2.8 / 0.4).abs() < 1e-9, "{r}");
    assert!(r.x.abs() < 1e-9 && r.y.abs() < 1e-9);
    // Large errors: clamped to PX4's maximum rates, the short way round.
    for (deg, sign) in [(90.0, -1.0), (170.0, -1.0), (190.0, 1.0), (270.0, 1.0)] {
        let q = about(Vector3::y(), f64::to_radians(deg));
        let r = attitude_control(&q, &id, &g);
        assert!(
            (r.y - sign * PX4_RATE_LIMIT).abs() < 1e-9 && r.x.abs() < 1e-9 && r.z.abs() < 1e-9,
            "{deg} deg: {r}"
        );
    }
    let r = attitude_control(&id, &about(Vector3::z(), 3.0), &g);
    assert!((r.z - 200f64.to_radians()).abs() < 1e-9, "{r}");
    // Exactly inverted, about any axis: finite, at full rate, no yaw.
    for axis in [
        Vector3::x(),
        Vector3::y(),
        Vector3::new(1.0, 1.0, 0.0).normalize(),
    ] {
        let r = attitude_control(&about(axis, PI), &id, &g);
        assert!(r.iter().all(|x| x.is_finite()), "{r}");
        assert!(
            r.xy().norm() > 0.99 * PX4_RATE_LIMIT && r.z.abs() < 1e-6,
            "{axis}: {r}"
        );
    }
    // Inverted with a different heading wanted: tilt first (the reduced attitude).
    let q = about(Vector3::x(), 2.5);
    let r = attitude_control(&q, &about(Vector3::z(), 1.0), &g);
    assert!((r.x + PX4_RATE_LIMIT).abs() < 1e-9, "{r}");
}

/// One 4 ms step of a companion streaming `rates` (FRD) and `thrust`.
fn fly(v: &mut SimVehicle, rates: [f32; 3], thrust: f32) -> Vec<MavMessage> {
    v.handle(&messages::set_attitude_target(rates, thrust, 0));
    v.step(0.004)
}

/// What happened after PX4's RTL took over.
#[derive(Debug)]
struct Recovery {
    /// When RTL was commanded, and the true height, climb rate and tilt then.
    switch: (f64, f64, f64, f64),
    /// The lowest true height before the vehicle was upright again (tilt < 10 deg, slower
    /// than 0.2 rad/s) and no longer sinking faster than 1 m/s.
    min_height_recovering: f64,
    /// When that was reached [s after the switch] and the height then.
    recovered: (f64, f64),
    /// Fastest sink rate after the switch [m/s].
    max_sink: f64,
}

/// Takes off in OFFBOARD, flies a 5*pi rad/s back flip and commands AUTO.RTL once the flip
/// has turned `switch_at` (rad); runs until PX4 disarms (at most 40 s).
fn flip_then_rtl(switch_at: f64) -> (SimVehicle, Recovery) {
    let mut v = SimVehicle::new(VehicleConfig::default());
    let hover = v.thrust_map().hover_thrust as f32;
    for _ in 0..250 {
        fly(&mut v, [0.0; 3], 0.0);
    }
    v.handle(&messages::command_long(
        Command::SetMode(Px4Mode::Offboard),
        0,
    ));
    v.handle(&messages::command_long(Command::Arm, 0));
    assert_eq!(v.commander().mode(), Px4Mode::Offboard);
    assert!(v.commander().armed());
    // Punch up, then flip on low thrust.
    while v.state().v.z < 4.5 {
        fly(&mut v, [0.0; 3], 1.5 * hover);
        assert!(v.time() < 5.0, "climbs");
    }
    let flip = [0.0, 5.0 * std::f32::consts::PI, 0.0];
    while v.record().offboard_pitch_rotation.abs() < switch_at {
        fly(&mut v, flip, 0.3 * hover);
        assert!(v.time() < 8.0, "flips");
    }
    let s = v.state().clone();
    let switch = (v.time(), s.p.z, s.v.z, s.tilt());
    v.handle(&messages::command_long(
        Command::SetMode(Px4Mode::Return),
        0,
    ));
    assert_eq!(v.commander().mode(), Px4Mode::Return);
    let mut rec = Recovery {
        switch,
        min_height_recovering: f64::INFINITY,
        recovered: (f64::NAN, f64::NAN),
        max_sink: 0.0,
    };
    let mut recovering = true;
    while v.commander().armed() && v.time() < switch.0 + 40.0 {
        // The companion keeps streaming its flip: PX4 ignores it outside OFFBOARD.
        fly(&mut v, flip, 0.3 * hover);
        let s = v.state();
        rec.max_sink = rec.max_sink.max(-s.v.z);
        if recovering {
            rec.min_height_recovering = rec.min_height_recovering.min(s.p.z);
            if s.tilt() < 10f64.to_radians() && s.w.norm() < 0.2 && s.v.z > -1.0 {
                recovering = false;
                rec.recovered = (v.time() - switch.0, s.p.z);
            }
        }
    }
    eprintln!("switch at {:.0} deg: {rec:?}", switch_at.to_degrees());
    for l in v.record().summary_lines() {
        eprintln!("  {l}");
    }
    (v, rec)
}

/// Checks a flip-then-RTL flight: recovered high enough, landed softly at home, disarmed,
/// and the record says so.
fn check_flip_then_rtl(v: &SimVehicle, rec: &Recovery, switch_at: f64) {
    let r = v.record();
    assert!(!v.crashed() && r.crashed.is_none(), "{:?}", r.crashed);
    let (t_switch, z, _, _) = rec.switch;
    assert!(z > 2.0, "{:?}", rec.switch);
    assert!(rec.recovered.0.is_finite(), "upright again: {rec:?}");
    assert!(rec.min_height_recovering > 1.0, "{rec:?}");
    // Landed at home (RTL descends once within 0.3 m of it), softly, and disarmed.
    assert!(!v.commander().armed());
    assert_eq!(v.commander().mode(), Px4Mode::Return);
    let home = VehicleConfig::default().home;
    assert!(
        (r.final_position.xy() - home.xy()).norm() < 0.5,
        "{}",
        r.final_position
    );
    assert_eq!(r.final_position.z, 0.0);
    assert_eq!(r.touchdowns.len(), 1, "{:?}", r.touchdowns);
    let td = &r.touchdowns[0];
    // At about the AUTO.LAND speed (0.5 m/s), well below the plant's 1.5 m/s crash limit.
    assert!(
        td.vertical_speed < 0.6 && td.horizontal_speed < 0.3,
        "{td:?}"
    );
    assert_eq!(td.position, r.final_position);
    // Armed once, disarmed once, by PX4 right after the touchdown.
    assert_eq!(r.armed_at.len(), 1);
    assert_eq!(r.disarmed_at.len(), 1);
    assert!(r.disarmed_at[0] >= td.time && r.disarmed_at[0] - td.time < 0.01);
    // Modes: OFFBOARD (commanded), then AUTO.RTL exactly when commanded; no failsafe.
    let to_rtl: Vec<_> = r
        .mode_changes
        .iter()
        .filter(|m| m.to == Px4Mode::Return)
        .collect();
    assert_eq!(to_rtl.len(), 1, "{:?}", r.mode_changes);
    assert_eq!(to_rtl[0].time, t_switch);
    assert_eq!(to_rtl[0].from, Px4Mode::Offboard);
    assert!(r.mode_changes.iter().all(|m| !m.failsafe));
    assert_eq!(r.mode_changes.len(), 2, "{:?}", r.mode_changes);
    assert_eq!(r.mode_changes[0].to, Px4Mode::Offboard);
    // The flip as flown in OFFBOARD: a back flip is negative about FLU y.
    let rot = r.offboard_pitch_rotation;
    assert!(rot <= -switch_at && rot > -switch_at - 0.1, "{rot}");
    let w = 5.0 * PI;
    assert!(
        (r.offboard_max_pitch_rate - w).abs() < 0.1 * w,
        "{}",
        r.offboard_max_pitch_rate
    );
    let (hi, lo) = (r.max_height.unwrap(), r.min_height.unwrap());
    assert!(hi > z && hi < 6.0 && (0.0..0.05).contains(&lo), "{hi} {lo}");
    assert!(r.airborne_time > 1.0 && r.airborne_time < r.time);
    assert!(!r.summary_lines().is_empty());
}

#[test]
fn rtl_at_180_degrees_of_a_flip_recovers_lands_at_home_and_disarms() {
    let (v, rec) = flip_then_rtl(PI);
    // Inverted, about 3 m up and climbing at about 2.5 m/s when RTL takes over.
    let (_, z, vz, tilt) = rec.switch;
    assert!(tilt > 170f64.to_radians(), "{:?}", rec.switch);
    assert!(
        (2.5..4.0).contains(&z) && (1.5..3.5).contains(&vz),
        "{:?}",
        rec.switch
    );
    check_flip_then_rtl(&v, &rec, PI);
}

#[test]
fn rtl_at_270_degrees_of_a_flip_recovers_lands_at_home_and_disarms() {
    let (v, rec) = flip_then_rtl(1.5 * PI);
    // Nose up past vertical, climbing.
    let (_, z, vz, tilt) = rec.switch;
    assert!((tilt - PI / 2.0).abs() < 0.2, "{:?}", rec.switch);
    assert!((2.5..4.5).contains(&z) && vz > 0.5, "{:?}", rec.switch);
    check_flip_then_rtl(&v, &rec, 1.5 * PI);
    assert!(rec.min_height_recovering > z - 0.5, "{rec:?}");
}

#[test]
fn rtl_after_a_full_flip_lands_at_home_and_the_record_has_the_flip() {
    let (v, rec) = flip_then_rtl(2.0 * PI);
    check_flip_then_rtl(&v, &rec, 2.0 * PI);
    assert!(v.record().offboard_pitch_rotation.abs() >= 2.0 * PI);
}

#[test]
fn the_offboard_loss_failsafe_is_recorded_as_such() {
    let mut v = SimVehicle::new(VehicleConfig::default());
    let hover = v.thrust_map().hover_thrust as f32;
    stream(&mut v, 0.0, 0.5);
    v.handle(&messages::command_long(
        Command::SetMode(Px4Mode::Offboard),
        0,
    ));
    v.handle(&messages::command_long(Command::Arm, 0));
    stream(&mut v, 1.3 * hover, 1.0);
    v.step(2.0);
    let r = v.record();
    let fs = v.commander().failsafe_at().expect("failsafe");
    assert_eq!(r.mode_changes.len(), 2, "{:?}", r.mode_changes);
    let m = &r.mode_changes[1];
    assert!(m.failsafe && m.from == Px4Mode::Offboard && m.to == Px4Mode::Position);
    assert!((m.time - fs).abs() < 0.0011, "{} vs {fs}", m.time);
    assert!(!r.mode_changes[0].failsafe);
    assert!(r.first_liftoff.is_some() && r.touchdowns.is_empty() && r.crashed.is_none());
    assert!(
        r.summary_lines()
            .iter()
            .any(|l| l.contains("offboard-loss failsafe"))
    );
}

fn count(out: &[MavMessage]) -> [usize; 3] {
    let mut n = [0; 3];
    for m in out {
        match m {
            MavMessage::ODOMETRY(_) => n[0] += 1,
            MavMessage::LOCAL_POSITION_NED(_) => n[1] += 1,
            MavMessage::ATTITUDE_QUATERNION(_) => n[2] += 1,
            _ => {}
        }
    }
    n
}

fn interval(message_id: u32, interval_us: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(mc::COMMAND_LONG_DATA {
        param1: message_id as f32,
        param2: interval_us,
        command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        target_system: 1,
        target_component: 1,
        ..mc::COMMAND_LONG_DATA::DEFAULT
    })
}

fn acks(out: &[MavMessage]) -> Vec<MavResult> {
    out.iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_ACK(a) => {
                assert_eq!(a.command, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
                Some(a.result)
            }
            _ => None,
        })
        .collect()
}

#[test]
fn streams_at_px4s_rates_and_as_set_message_interval_asks() {
    let within = |n: usize, hz: usize| n + 1 >= hz && n <= hz + 1;
    let mut v = SimVehicle::new(VehicleConfig {
        estimator: EstimatorConfig::perfect(),
        home: Vector3::new(1.0, 2.0, 0.0),
        ..VehicleConfig::default()
    });
    let out = v.step(1.0);
    let [odo, pos, att] = count(&out);
    assert!(
        within(odo, 30) && within(pos, 30) && within(att, 50),
        "{odo} {pos} {att}"
    );
    // LOCAL_POSITION_NED and ATTITUDE_QUATERNION say what ODOMETRY says, in PX4's frames,
    // stamped with the vehicle's time since boot.
    let last = |f: &dyn Fn(&Inbound) -> bool| {
        out.iter()
            .map(|m| classify(&PX4, m))
            .rfind(|i| f(i))
            .unwrap()
    };
    let Inbound::LocalPosition {
        time_boot_ms,
        position,
        velocity,
    } = last(&|i| matches!(i, Inbound::LocalPosition { .. }))
    else {
        unreachable!()
    };
    assert_eq!(position, [2.0, 1.0, 0.0]);
    assert_eq!(velocity, [0.0; 3]);
    assert!(time_boot_ms > 900 && time_boot_ms <= 1000, "{time_boot_ms}");
    let Inbound::Attitude { q, rates, .. } = last(&|i| matches!(i, Inbound::Attitude { .. }))
    else {
        unreachable!()
    };
    let q_ned = quat_from_mavlink(q).unwrap();
    assert!(quat_ned_frd_to_enu_flu(&q_ned).angle_to(&UnitQuaternion::identity()) < 1e-6);
    assert_eq!(rates, [0.0; 3]);
    let o = odometry(&out).pop().unwrap();
    assert!(quat_from_mavlink(o.q).unwrap().angle_to(&q_ned) < 1e-6);
    assert!(quat_enu_flu_to_ned_frd(&UnitQuaternion::identity()).angle_to(&q_ned) < 1e-6);

    // ODOMETRY at 100 Hz (the shim's request), ATTITUDE_QUATERNION off.
    let ok = [MavResult::MAV_RESULT_ACCEPTED];
    assert_eq!(acks(&v.handle(&interval(331, 10_000.0))), ok);
    assert_eq!(acks(&v.handle(&interval(31, -1.0))), ok);
    let [odo, pos, att] = count(&v.step(1.0));
    assert!(
        within(odo, 100) && within(pos, 30) && att == 0,
        "{odo} {pos} {att}"
    );
    // The shim's own command (100 Hz), LOCAL_POSITION_NED at 5 Hz, ATTITUDE_QUATERNION back
    // to its default, ODOMETRY stopped.
    let cmd = messages::command_long(
        Command::MessageInterval {
            message_id: 32,
            hz: 5.0,
        },
        0,
    );
    assert_eq!(acks(&v.handle(&cmd)), ok);
    assert_eq!(acks(&v.handle(&interval(31, 0.0))), ok);
    assert_eq!(acks(&v.handle(&interval(331, -1.0))), ok);
    let [odo, pos, att] = count(&v.step(1.0));
    assert!(
        odo == 0 && within(pos, 5) && within(att, 50),
        "{odo} {pos} {att}"
    );
    // What this vehicle cannot stream, and HEARTBEAT: PX4's answer is FAILED, rates kept.
    for id in [0, 105, 9999] {
        assert_eq!(
            acks(&v.handle(&interval(id, 10_000.0))),
            [MavResult::MAV_RESULT_FAILED]
        );
    }
    let [odo, pos, att] = count(&v.step(1.0));
    assert!(
        odo == 0 && within(pos, 5) && within(att, 50),
        "{odo} {pos} {att}"
    );
}

#[test]
fn initial_rates_come_from_the_config() {
    let mut v = SimVehicle::new(VehicleConfig {
        odometry_period: 0.01,
        local_position_period: 0.0,
        attitude_quaternion_period: f64::INFINITY,
        ..VehicleConfig::default()
    });
    let [odo, pos, att] = count(&v.step(1.0));
    assert!(
        (99..=101).contains(&odo) && pos == 0 && att == 0,
        "{odo} {pos} {att}"
    );
    // Interval 0 restores those defaults.
    v.handle(&interval(331, 50_000.0));
    assert!((19..=21).contains(&count(&v.step(1.0))[0]));
    v.handle(&interval(331, 0.0));
    assert!((99..=101).contains(&count(&v.step(1.0))[0]));
}
