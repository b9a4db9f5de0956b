//! The simulated PX4 vehicle: flown by offboard setpoints, its offboard-loss failsafe holding
//! position with the physics, AUTO.LAND landing and disarming, PX4's attitude controller
//! recovering from a flip interrupted by AUTO.RTL, the streams at PX4's rates (and as
//! MAV_CMD_SET_MESSAGE_INTERVAL sets them) in PX4's frames, and the flight record.

use std::f64::consts::PI;

use firmware_shim::frames::{quat_enu_flu_to_ned_frd, quat_from_mavlink, quat_ned_frd_to_enu_flu};
use firmware_shim::messages::{self, Command, Inbound, Px4Mode, classify};
use mavlink::MavHeader;
use mavlink::dialects::common::{self as mc, MavCmd, MavMessage, MavResult};
use mpc_mission::estimate::EstimatorConfig;
use mpc_mission::vehicle::{QuadParams, RotorLag};
use mpc_sim::rate_loop::Airmode;
use nalgebra::{UnitQuaternion, Vector3};
use px4_sim::commander::CommanderConfig;
use px4_sim::vehicle::{AttitudeGains, SimVehicle, VehicleConfig, attitude_control};

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
    // AUTO.LAND: down at 0.5 m/s; on the ground PX4 idles, its land detector says landed
    // LNDMC_TRIG_TIME (1 s) later and PX4 disarms COM_DISARM_LAND (2 s) after that.
    v.handle(&messages::command_long(Command::SetMode(Px4Mode::Land), 0));
    v.step(p_hold.z / 0.5 + 1.0);
    assert!(!v.crashed(), "a soft landing");
    assert!(v.state().p.z.abs() < 1e-9);
    let td = v.record().touchdowns.last().expect("touched down").time;
    check_auto_disarm(&mut v, td);
}

/// Steps `v` until PX4 disarms on its own (at most 5 s after `touchdown`) and checks it did
/// so LNDMC_TRIG_TIME + COM_DISARM_LAND (3 s) after the touchdown, once.
fn check_auto_disarm(v: &mut SimVehicle, touchdown: f64) {
    while v.commander().armed() && v.time() < touchdown + 5.0 {
        v.step(0.001);
    }
    let r = v.record();
    assert_eq!(r.auto_disarmed_at.len(), 1, "PX4 disarmed on its own once");
    assert_eq!(r.disarmed_at, r.auto_disarmed_at);
    let after = r.auto_disarmed_at[0] - touchdown;
    assert!(
        (3.0..3.05).contains(&after),
        "{after} s after the touchdown"
    );
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
    // Armed once, disarmed once, by PX4's land detector 3 s after the touchdown.
    assert_eq!(r.armed_at.len(), 1);
    assert_eq!(r.disarmed_at, r.auto_disarmed_at);
    let after = r.disarmed_at[0] - td.time;
    assert!((3.0..3.05).contains(&after), "{after}");
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

/// A vehicle without estimation noise, and without height error unless `cfg` has one.
fn exact(cfg: VehicleConfig) -> SimVehicle {
    SimVehicle::new(VehicleConfig {
        estimator: EstimatorConfig::perfect(),
        height_bias: cfg.height_bias.or(Some(0.0)),
        ..cfg
    })
}

/// Streams thrust 0 for 1 s, then OFFBOARD and arm.
fn arm_in_offboard(v: &mut SimVehicle) {
    stream(v, 0.0, 1.0);
    v.handle(&messages::command_long(
        Command::SetMode(Px4Mode::Offboard),
        0,
    ));
    v.handle(&messages::command_long(Command::Arm, 0));
    assert!(v.commander().armed() && v.commander().mode() == Px4Mode::Offboard);
}

/// The timestamps of what `out` holds: ODOMETRY's `time_usec` and the others' `time_boot_ms`
/// [s].
fn stamps(out: &[MavMessage]) -> Vec<f64> {
    out.iter()
        .filter_map(|m| match m {
            MavMessage::ODOMETRY(o) => Some(o.time_usec as f64 * 1e-6),
            MavMessage::LOCAL_POSITION_NED(p) => Some(f64::from(p.time_boot_ms) * 1e-3),
            MavMessage::ATTITUDE_QUATERNION(a) => Some(f64::from(a.time_boot_ms) * 1e-3),
            _ => None,
        })
        .collect()
}

/// Every timestamp is the simulated time until the jump, and shifted by it afterwards,
/// either way; TIMESYNC answers with the same clock.
#[test]
fn the_clock_jumps_as_configured_and_every_timestamp_follows() {
    use px4_sim::vehicle::ClockJump;
    for by in [-0.5, 30.0] {
        let mut v = exact(VehicleConfig {
            clock_jump: Some(ClockJump { at: 1.0, by }),
            ..VehicleConfig::default()
        });
        for _ in 0..2000 {
            let out = v.step(0.001);
            let t = v.time();
            let want = if t >= 1.0 { t + by } else { t };
            assert!((v.clock() - want).abs() < 1e-9, "{t}: {}", v.clock());
            for s in stamps(&out) {
                assert!((s - want).abs() < 1e-3, "at {t} (jump {by}): stamped {s}");
            }
        }
        let reply = v.handle(&messages::timesync_request(7));
        let [MavMessage::TIMESYNC(ts)] = reply.as_slice() else {
            panic!("{reply:?}")
        };
        assert!(
            (ts.tc1 as f64 * 1e-9 - (v.time() + by)).abs() < 1e-6,
            "{ts:?}"
        );
    }
}

/// TIMESYNC as PX4's mavlink_timesync.cpp: a request (tc1 = 0) gets the vehicle's time in
/// tc1 [ns] and its own ts1 back; an answer (tc1 != 0) gets nothing.
#[test]
fn timesync_requests_are_answered_with_the_vehicle_clock() {
    let mut v = SimVehicle::new(VehicleConfig::default());
    v.step(2.345);
    let ts1 = 1_234_567_890_123;
    let reply = v.handle(&MavMessage::TIMESYNC(mc::TIMESYNC_DATA { tc1: 0, ts1 }));
    let [MavMessage::TIMESYNC(ts)] = reply.as_slice() else {
        panic!("{reply:?}")
    };
    assert_eq!(ts.ts1, ts1);
    assert!((ts.tc1 - 2_345_000_000).abs() < 1_000, "{}", ts.tc1);
    let answer = MavMessage::TIMESYNC(mc::TIMESYNC_DATA { tc1: 5, ts1 });
    assert!(v.handle(&answer).is_empty());
}

/// Clock rate, jump, height bias and vehicle names are checked, with messages that say what
/// to give.
#[test]
fn bad_clock_and_bias_settings_are_refused_with_what_to_give() {
    use px4_sim::vehicle::{Airframe, ClockJump, VehicleConfigError};
    let cfg = VehicleConfig::default();
    assert_eq!(
        cfg.clock_rate, 0.988,
        "PX4 SITL in lockstep: 1.0-1.5 % slow"
    );
    assert_eq!(cfg.validate(), Ok(()));
    for r in [0.49, 2.01, f64::NAN] {
        let e = VehicleConfig {
            clock_rate: r,
            ..VehicleConfig::default()
        }
        .validate()
        .unwrap_err();
        assert!(matches!(e, VehicleConfigError::ClockRate(_)));
        assert!(e.to_string().contains("0.5 to 2.0"), "{e}");
    }
    for r in [0.5, 2.0] {
        let cfg = VehicleConfig {
            clock_rate: r,
            ..VehicleConfig::default()
        };
        assert_eq!(cfg.validate(), Ok(()));
    }
    assert_eq!(
        "30:-5".parse::<ClockJump>(),
        Ok(ClockJump { at: 30.0, by: -5.0 })
    );
    for bad in ["30", "-1:5", "a:b", "1:inf", ""] {
        let e = bad.parse::<ClockJump>().unwrap_err();
        assert!(e.to_string().contains("AT:BY"), "{bad}: {e}");
    }
    let e = VehicleConfig {
        height_bias: Some(9.0),
        ..VehicleConfig::default()
    }
    .validate()
    .unwrap_err();
    assert_eq!(e, VehicleConfigError::HeightBias(9.0));
    assert_eq!("stock".parse::<Airframe>(), Ok(Airframe::Stock));
    assert_eq!("agile".parse::<Airframe>(), Ok(Airframe::Agile));
    let e = "x500".parse::<Airframe>().unwrap_err();
    assert!(e.to_string().contains("agile") && e.to_string().contains("stock"));
}

/// The default height error is drawn from the seed: 0.2 to 0.7 m, both signs, the same for
/// the same seed.
#[test]
fn the_default_height_bias_is_drawn_from_the_seed() {
    let bias = |seed| {
        VehicleConfig {
            seed,
            ..VehicleConfig::default()
        }
        .final_height_bias()
    };
    let all: Vec<f64> = (0..200).map(bias).collect();
    assert!(
        all.iter().all(|b| (0.2..=0.7).contains(&b.abs())),
        "{all:?}"
    );
    let up = all.iter().filter(|b| **b > 0.0).count();
    assert!((60..=140).contains(&up), "{up} of 200 positive");
    let (lo, hi) = all.iter().fold((1.0f64, 0.0f64), |(lo, hi), b| {
        (lo.min(b.abs()), hi.max(b.abs()))
    });
    assert!(lo < 0.25 && hi > 0.65, "{lo} {hi}");
    assert_eq!(bias(7), bias(7));
    let fixed = VehicleConfig {
        height_bias: Some(-0.3),
        ..VehicleConfig::default()
    };
    assert_eq!(fixed.final_height_bias(), -0.3);
}

/// A climb to about `z` m in OFFBOARD, then the controller stops: PX4's failsafe holds.
fn take_off_and_hold(v: &mut SimVehicle, z: f64) {
    let hover = v.thrust_map().hover_thrust as f32;
    arm_in_offboard(v);
    while v.state().p.z < z {
        stream(v, 1.2 * hover, 0.02);
        assert!(v.time() < 10.0, "climbs");
    }
    v.step(1.0);
    assert_eq!(v.commander().mode(), Px4Mode::Position);
}

/// EKF2's height error: none at arming, the configured bias 20 s later, in ODOMETRY and
/// LOCAL_POSITION_NED alike; PX4's own AUTO.LAND flies on it; the record stays true.
#[test]
fn the_estimate_carries_the_height_bias_and_the_truth_does_not() {
    let bias = 0.5;
    let mut v = exact(VehicleConfig {
        height_bias: Some(bias),
        ..VehicleConfig::default()
    });
    stream(&mut v, 0.0, 1.0);
    v.handle(&messages::command_long(
        Command::SetMode(Px4Mode::Offboard),
        0,
    ));
    v.handle(&messages::command_long(Command::Arm, 0));
    let first = odometry(&v.step(0.1)).pop().unwrap();
    assert!(first.position[2].abs() < 0.01, "{:?}", first.position);
    take_off_and_hold(&mut v, 2.0);
    v.step(21.0);
    let out = v.step(0.1);
    let truth_ned_z = -v.state().p.z;
    let o = odometry(&out).pop().unwrap();
    assert!(
        (f64::from(o.position[2]) - (truth_ned_z - bias)).abs() < 0.01,
        "ODOMETRY z {} vs true {truth_ned_z}",
        o.position[2]
    );
    let lp = out
        .iter()
        .rev()
        .find_map(|m| match m {
            MavMessage::LOCAL_POSITION_NED(p) => Some(p.z),
            _ => None,
        })
        .unwrap();
    assert!((f64::from(lp) - (truth_ned_z - bias)).abs() < 0.01, "{lp}");
    v.handle(&messages::command_long(Command::SetMode(Px4Mode::Land), 0));
    v.step(8.0);
    let r = v.record();
    let td = r.touchdowns.last().expect("landed");
    assert!((td.estimated_height - bias).abs() < 0.02, "{td:?}");
    assert_eq!(td.position.z, 0.0);
    assert!((r.height_bias - bias).abs() < 1e-9);
    assert!(r.min_height.unwrap() >= 0.0 && r.crashed.is_none());
}

fn landed_states(out: &[MavMessage]) -> Vec<mc::MavLandedState> {
    out.iter()
        .filter_map(|m| match m {
            MavMessage::EXTENDED_SYS_STATE(s) => Some(s.landed_state),
            _ => None,
        })
        .collect()
}

/// Flies `v` (OFFBOARD, armed, airborne) down at about 0.5 m/s until it touches down.
fn descend_in_offboard(v: &mut SimVehicle) -> f64 {
    let hover = v.thrust_map().hover_thrust;
    while v.record().touchdowns.is_empty() {
        let vz = v.state().v.z;
        let thrust = (hover * (1.0 + 0.5 * (-0.5 - vz))).clamp(0.0, 1.0) as f32;
        v.handle(&messages::set_attitude_target([0.0; 3], thrust, 0));
        v.step(0.01);
        assert!(v.time() < 60.0 && !v.crashed(), "descends");
    }
    v.record().touchdowns[0].time
}

/// PX4's land detector in OFFBOARD: on the ground with the thrust above MPC_MANTHR_MIN +
/// 0.01, never landed; at low thrust, landed 1 s later (EXTENDED_SYS_STATE, 5 Hz, says so
/// only then) and disarmed 2 s after that, still in OFFBOARD.
#[test]
fn the_land_detector_disarms_in_offboard_two_seconds_after_landed() {
    use mc::MavLandedState::{MAV_LANDED_STATE_IN_AIR, MAV_LANDED_STATE_ON_GROUND};
    let mut v = exact(VehicleConfig::default());
    let hover = v.thrust_map().hover_thrust as f32;
    arm_in_offboard(&mut v);
    for _ in 0..50 {
        stream(&mut v, 1.2 * hover, 0.02);
    }
    let out = v.step(0.01);
    assert!(v.state().p.z > 0.5);
    let touchdown = descend_in_offboard(&mut v);
    // Thrust 0.2 (0.8 x hover): more than PX4's MPC_MANTHR_MIN + 0.01, never landed.
    let mut seen = landed_states(&out);
    for _ in 0..250 {
        v.handle(&messages::set_attitude_target([0.0; 3], 0.2, 0));
        seen.extend(landed_states(&v.step(0.02)));
    }
    assert!(
        seen.iter().all(|s| *s == MAV_LANDED_STATE_IN_AIR),
        "{seen:?}"
    );
    assert!(v.commander().armed() && v.record().touchdowns.len() == 1);
    let low_from = v.time();
    // Thrust 0.05: landed after LNDMC_TRIG_TIME, disarmed after COM_DISARM_LAND.
    let mut first_on_ground = None;
    let mut n_sys_state = 0;
    while v.commander().armed() && v.time() < low_from + 5.0 {
        v.handle(&messages::set_attitude_target([0.0; 3], 0.05, 0));
        let states = landed_states(&v.step(0.01));
        n_sys_state += states.len();
        if states.contains(&MAV_LANDED_STATE_ON_GROUND) {
            first_on_ground.get_or_insert(v.time());
        }
    }
    let landed_after = first_on_ground.expect("ON_GROUND") - low_from;
    assert!((1.0..1.25).contains(&landed_after), "{landed_after}");
    let r = v.record();
    let disarm = *r.auto_disarmed_at.first().expect("PX4 disarmed");
    assert!(
        (3.0..3.05).contains(&(disarm - low_from)),
        "{}",
        disarm - low_from
    );
    let n_expected = (disarm - low_from) * 5.0;
    assert!(
        (n_sys_state as f64 - n_expected).abs() <= 1.5,
        "{n_sys_state}"
    );
    assert_eq!(v.commander().mode(), Px4Mode::Offboard);
    assert!(touchdown < low_from && r.crashed.is_none());
    let Inbound::Heartbeat { armed, mode } = classify(&PX4, &v.commander().heartbeat()) else {
        panic!()
    };
    assert!(!armed && mode == Px4Mode::Offboard);
}

/// Reads parameter `name` from `v` the way the shim does (by name, index -1).
fn read_param(v: &mut SimVehicle, name: &str) -> Option<mc::PARAM_VALUE_DATA> {
    let reply = v.handle(&messages::param_request_read(name));
    assert!(reply.len() <= 1, "{reply:?}");
    reply.into_iter().find_map(|m| match m {
        MavMessage::PARAM_VALUE(p) => Some(p),
        _ => None,
    })
}

fn param(v: &mut SimVehicle, name: &str) -> f64 {
    let p = read_param(v, name).unwrap_or_else(|| panic!("{name}: no answer"));
    assert!(messages::param_name_is(&p.param_id.into(), name));
    assert_eq!(p.param_type, mc::MavParamType::MAV_PARAM_TYPE_REAL32);
    f64::from(p.param_value)
}

/// The parameters as PX4 SITL with the SIH quadrotor answers them; MPC_THR_HOVER follows the
/// vehicle; indices and the count are consistent; unknown names get no answer.
#[test]
fn parameters_are_answered_as_px4_sitl_for_the_selected_vehicle() {
    let mut stock = SimVehicle::new(VehicleConfig::stock());
    let close = |a: f64, b: f64| (a - b).abs() < 1e-5;
    for (name, want) in [
        ("MPC_THR_HOVER", 0.5),
        ("MPC_THR_MIN", 0.12),
        ("MC_ROLLRATE_P", 0.15),
        ("MC_PITCHRATE_P", 0.15),
        ("MC_ROLLRATE_MAX", 220.0),
        ("MC_PITCHRATE_MAX", 220.0),
        ("SIH_MASS", 1.0),
        ("SIH_IXX", 0.025),
        ("SIH_IYY", 0.025),
        ("SIH_IZZ", 0.030),
        ("SIH_T_MAX", 5.0),
        ("SIH_Q_MAX", 0.1),
        ("SIH_L_ROLL", 0.2),
        ("SIH_L_PITCH", 0.2),
        ("SIH_T_TAU", 0.05),
        ("SIH_KDV", 1.0),
        ("SIH_KDW", 0.025),
        ("COM_DISARM_LAND", 2.0),
    ] {
        let got = param(&mut stock, name);
        assert!(close(got, want), "{name}: {got} (PX4: {want})");
    }
    // The true hover thrust of the stock vehicle is 0.4905 (PX4 SITL measured 0.495).
    assert!((stock.thrust_map().hover_thrust - 0.4905).abs() < 1e-4);
    // The agile vehicle answers its own (calibrated) hover thrust and geometry.
    let mut agile = SimVehicle::new(VehicleConfig::default());
    assert!((param(&mut agile, "MPC_THR_HOVER") - 9.81 / (4.0 * 9.8)).abs() < 1e-6);
    assert!(close(param(&mut agile, "SIH_T_MAX"), 9.8));
    assert!(close(param(&mut agile, "SIH_L_PITCH"), 0.17 / 2f64.sqrt()));
    // Index and count: by index gives the same parameter; one past the end, nothing.
    let p = read_param(&mut stock, "SIH_IYY").unwrap();
    let n = usize::from(p.param_count);
    assert_eq!(n, stock.parameters().len());
    let by_index = |v: &mut SimVehicle, i: i16| {
        v.handle(&MavMessage::PARAM_REQUEST_READ(
            mc::PARAM_REQUEST_READ_DATA {
                param_index: i,
                target_system: 1,
                target_component: 1,
                param_id: "".into(),
            },
        ))
    };
    let reply = by_index(&mut stock, p.param_index as i16);
    let [MavMessage::PARAM_VALUE(q)] = reply.as_slice() else {
        panic!("{reply:?}")
    };
    assert_eq!((q.param_id, q.param_value), (p.param_id, p.param_value));
    assert!(by_index(&mut stock, n as i16).is_empty());
    // PX4 does not answer for a parameter it does not have.
    assert!(read_param(&mut stock, "NO_SUCH_PARAM").is_none());
    assert!(read_param(&mut stock, "SIH_MAS").is_none());
}

/// The true pitch rate of `v`'s step response to `rate` (FRD) at hover thrust, 1 ms apart
/// for 0.4 s, from a steady hover at 1.5 m.
fn pitch_step(v: &mut SimVehicle, rate: f32) -> Vec<f64> {
    let hover = v.thrust_map().hover_thrust as f32;
    arm_in_offboard(v);
    while v.state().p.z < 1.5 {
        fly(v, [0.0; 3], 1.3 * hover);
        assert!(v.time() < 10.0, "climbs");
    }
    for _ in 0..50 {
        fly(v, [0.0; 3], hover);
    }
    (0..400)
        .map(|_| {
            v.handle(&messages::set_attitude_target([0.0, rate, 0.0], hover, 0));
            v.step(0.001);
            v.state().w.y.abs()
        })
        .collect()
}

/// PX4's stock SIH quadrotor: its pitch torque authority is 2 SIH_T_MAX SIH_L_PITCH (SIH's
/// mixer: `L_PITCH * T_MAX * (u0 - u1 + u2 - u3)`), 80 rad/s^2 over SIH_IYY, of which PX4's
/// mixer without airmode (MC_AIRMODE 0: the collective is kept) gives at most twice the
/// collective's share (at hover thrust 0.4905: the rotors between 0 and 0.981); PX4's
/// default rate gains saturate it on a step to the flip's 5*pi rad/s, which it reaches in
/// about 0.25 s (the agile vehicle: 0.10 s).
#[test]
fn the_stock_vehicle_has_px4s_pitch_authority() {
    let mut v = exact(VehicleConfig::stock());
    let (t_max, l_pitch, iyy, kdw) = (
        param(&mut v, "SIH_T_MAX"),
        param(&mut v, "SIH_L_PITCH"),
        param(&mut v, "SIH_IYY"),
        param(&mut v, "SIH_KDW"),
    );
    let authority = 2.0 * t_max * l_pitch;
    assert!((authority / iyy - 80.0).abs() < 1e-3);
    // The torque the rotors deliver, from the true motion: Iyy w' + KDW w. A step large
    // enough to keep the rotors saturated shows the whole authority.
    let torque = |w: &[f64]| {
        w.windows(2)
            .map(|p| iyy * (p[1] - p[0]) / 0.001 + kdw * p[1])
            .fold(0.0f64, f64::max)
    };
    let w_big = pitch_step(&mut exact(VehicleConfig::stock()), 30.0);
    let peak = torque(&w_big);
    let share = (2.0 * v.thrust_map().hover_thrust).min(1.0);
    assert!((share - 0.981).abs() < 1e-3, "{share}");
    assert!(
        (peak / (share * authority) - 1.0).abs() < 0.01,
        "{peak} N m vs {share} of {authority}"
    );
    // The flip's step: the angular acceleration approaches the authority (rotor lag and
    // damping keep it a little below), and 90 % of the rate comes after about 0.25 s.
    let flip = 5.0 * std::f32::consts::PI;
    let w = pitch_step(&mut v, flip);
    let acc = w
        .windows(2)
        .map(|p| (p[1] - p[0]) / 0.001)
        .fold(0.0f64, f64::max);
    assert!(
        (0.8 * authority / iyy..=authority / iyy).contains(&acc),
        "{acc} rad/s^2"
    );
    let t90 = |w: &[f64]| w.iter().position(|x| *x >= 0.9 * f64::from(flip)).unwrap();
    let t_stock = t90(&w) as f64 * 1e-3;
    eprintln!(
        "stock: peak torque {peak:.3} N m, flip step: up to {acc:.1} rad/s^2, 90 % after {t_stock:.3} s"
    );
    assert!((0.2..0.3).contains(&t_stock), "{t_stock} s");
    let t_agile = t90(&pitch_step(&mut exact(VehicleConfig::default()), flip)) as f64 * 1e-3;
    assert!(t_agile < 0.12, "{t_agile} s");
}

// ---------------------------------------------------------------------------------------
// The stock vehicle against PX4 itself: SIH's true pitch rate under PX4's rate controller,
// for the setpoints `mpcc fly` sent in a flip (an excerpt of a PX4 v1.16 SITL log, made by
// scripts/px4_stock_excerpt.py)

/// The numbers of a CSV file of tests/data (after its header).
fn data_csv(name: &str) -> Vec<Vec<f64>> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    text.lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.trim().parse().unwrap()).collect())
        .collect()
}

/// How long before its logged timestamp a logged setpoint was in force \[s\]: PX4's logger
/// samples `vehicle_rates_setpoint` every 20 ms, `mpcc fly` sent it every 10 ms, so a new
/// value was published 0 or 10 ms before the sample that shows it first.
const SETPOINT_LEAD: f64 = 0.005;

/// The vehicle's true pitch rate (FRD) \[rad/s\] every 1 ms, on the log's clock, flying the
/// logged setpoints of the excerpt `name`: first 1 s at the first setpoint's thrust and zero
/// rates (a steady climb, as PX4's before the excerpt), then each setpoint from its logged
/// time less [`SETPOINT_LEAD`].
fn replay(cfg: VehicleConfig, name: &str) -> Vec<(f64, f64)> {
    let sp = data_csv(&format!("{name}_setpoints.csv"));
    let truth = data_csv(&format!("{name}_truth.csv"));
    let (t0, t1) = (truth[0][0], truth[truth.len() - 1][0]);
    let mut v = exact(cfg);
    arm_in_offboard(&mut v);
    stream(&mut v, sp[0][4] as f32, 1.0);
    let steps = ((t1 - t0) / 0.001).ceil() as usize;
    (0..steps)
        .map(|k| {
            let t = t0 + k as f64 * 0.001;
            let row = sp
                .iter()
                .rev()
                .find(|r| r[0] - SETPOINT_LEAD <= t)
                .unwrap_or(&sp[0]);
            let rates = [row[1] as f32, row[2] as f32, row[3] as f32];
            v.handle(&messages::set_attitude_target(rates, row[4] as f32, 0));
            v.step(0.001);
            (t + 0.001, -v.state().w.y)
        })
        .collect()
}

/// `series` (times increasing, 1 ms apart) at time `t`, linearly interpolated.
fn at(series: &[(f64, f64)], t: f64) -> f64 {
    let i = series
        .partition_point(|(s, _)| *s <= t)
        .clamp(1, series.len() - 1);
    let ((ta, a), (tb, b)) = (series[i - 1], series[i]);
    a + (b - a) * ((t - ta) / (tb - ta)).clamp(0.0, 1.0)
}

/// How a replay compares with SIH's true pitch rate, at the truth's samples.
#[derive(Debug)]
struct ReplayFit {
    /// RMS of the difference \[rad/s\].
    rms: f64,
    /// The replay's and the truth's most negative and most positive pitch rates \[rad/s\].
    low: (f64, f64),
    high: (f64, f64),
    /// The replay's and the truth's pitch rotation over the excerpt \[rad\].
    rotation: (f64, f64),
}

impl std::fmt::Display for ReplayFit {
    /// The figures, replay against truth.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "RMS error {:.3} rad/s; most negative {:.2} vs {:.2}, most positive {:.2} vs {:.2} \
             rad/s; rotation {:.3} vs {:.3} rad",
            self.rms,
            self.low.0,
            self.low.1,
            self.high.0,
            self.high.1,
            self.rotation.0,
            self.rotation.1
        )
    }
}

fn fit(cfg: VehicleConfig, name: &str) -> ReplayFit {
    let model = replay(cfg, name);
    let truth = data_csv(&format!("{name}_truth.csv"));
    let pairs: Vec<(f64, f64, f64)> = truth
        .iter()
        .map(|r| (r[0], at(&model, r[0]), r[2]))
        .collect();
    let n = pairs.len() as f64;
    let rms = (pairs.iter().map(|(_, m, t)| (m - t).powi(2)).sum::<f64>() / n).sqrt();
    let extreme = |f: fn(f64, f64) -> f64, init: f64| {
        pairs
            .iter()
            .fold((init, init), |(a, b), (_, m, t)| (f(a, *m), f(b, *t)))
    };
    let rotation = pairs.windows(2).fold((0.0, 0.0), |(a, b), w| {
        let dt = w[1].0 - w[0].0;
        (
            a + 0.5 * dt * (w[0].1 + w[1].1),
            b + 0.5 * dt * (w[0].2 + w[1].2),
        )
    });
    ReplayFit {
        rms,
        low: extreme(f64::min, f64::INFINITY),
        high: extreme(f64::max, f64::NEG_INFINITY),
        rotation,
    }
}

/// The excerpts of tests/data (README.md there): six PX4 v1.16 SITL flips of the stock SIH
/// quadrotor by `mpcc fly`.
const PX4_STOCK_FLIPS: [&str; 6] = [
    "px4_stock_flip_1",
    "px4_stock_flip_2",
    "px4_stock_flip_3",
    "px4_stock_flip_4",
    "px4_stock_flip_5",
    "px4_stock_flip_6",
];

/// The stock vehicle flies each logged PX4 SITL flip's setpoints as PX4 and SIH flew them:
/// its pitch rate follows SIH's true one to within 0.15 rad/s RMS (about 2 % of the
/// excerpts' RMS rate, 6.5-7 rad/s), and its most negative and most positive rates (the
/// flip's -12 rad/s, the recovery's 7-8 rad/s) are within 3 % of the truth's.
///
/// The tolerances: the setpoints' times are known to +-5 ms only (see [`SETPOINT_LEAD`]);
/// over that range the RMS error of the first excerpt moves from 0.09 to 0.24 rad/s, its
/// extreme rates by less than 0.01 rad/s. Over the six, the stock vehicle's RMS error is
/// 0.08-0.14 rad/s and its extremes are within 2.3 %. The vehicle as it was before PX4's
/// mixer, SIH's thrust lag and PX4's gyro filtering were modelled misses every excerpt: RMS
/// 0.20-0.45 rad/s, the recovery's rate 5-11 % too high. (The rotation over an excerpt is
/// printed, not judged: the excerpt ends mid-swing; the stock vehicle is within 0.1-2.4 % of
/// it, the vehicle before within 0.3-4.4 %.)
#[test]
fn the_stock_vehicle_follows_px4_and_sih_through_logged_flips() {
    let within = |(a, b): (f64, f64)| (a - b).abs() <= 0.03 * b.abs();
    let fits = |f: &ReplayFit| f.rms < 0.15 && within(f.low) && within(f.high);
    let before = VehicleConfig {
        airmode: Airmode::RollPitch,
        gyro_filter: None,
        params: QuadParams {
            rotor_lag: RotorLag::Speed,
            ..QuadParams::px4_sih()
        },
        ..VehicleConfig::stock()
    };
    print_each_part(PX4_STOCK_FLIPS[0]);
    for name in PX4_STOCK_FLIPS {
        let stock = fit(VehicleConfig::stock(), name);
        eprintln!("{name}: stock vehicle: {stock}");
        assert!(fits(&stock), "{name}: {stock:?}");
        let old = fit(before.clone(), name);
        eprintln!("{name}: before: {old}");
        assert!(!fits(&old), "{name}: {old:?}");
    }
}

/// Prints the fit of the stock vehicle with one of PX4's mixer, SIH's thrust lag and PX4's
/// gyro filtering taken back at a time, on excerpt `name`.
fn print_each_part(name: &str) {
    let stock = VehicleConfig::stock;
    let speed_lag = QuadParams {
        rotor_lag: RotorLag::Speed,
        ..QuadParams::px4_sih()
    };
    for (what, cfg) in [
        (
            "the airmode mixer",
            VehicleConfig {
                airmode: Airmode::RollPitch,
                ..stock()
            },
        ),
        (
            "the speed lag",
            VehicleConfig {
                params: speed_lag,
                ..stock()
            },
        ),
        (
            "the raw 1 kHz gyro",
            VehicleConfig {
                gyro_filter: None,
                ..stock()
            },
        ),
    ] {
        eprintln!("{name}: stock vehicle with {what}: {}", fit(cfg, name));
    }
}
