//! The simulated PX4 vehicle: flown by offboard setpoints, its offboard-loss failsafe holding
//! position with the physics, AUTO.LAND landing and disarming, ODOMETRY in PX4's frames.

use firmware_shim::messages::{self, Command, Inbound, Px4Mode, classify};
use firmware_shim::sitl::CommanderConfig;
use firmware_shim::vehicle::{SimVehicle, VehicleConfig};
use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use mpc_sim::estimator::EstimatorConfig;

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
    let out = v.step(0.1);
    let odo = odometry(&out);
    assert!((9..=11).contains(&odo.len()), "100 Hz: {}", odo.len());
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
