//! The shim's session against the simulated PX4 vehicle over loopback UDP, in real time: the
//! session brings it to OFFBOARD and armed, a small altitude controller lifts it, then the
//! controller "dies" (stops sending) and the simulated PX4 must enter its offboard-loss
//! failsafe (position hold) on its own and keep the vehicle in the air; and the served
//! vehicle's clock runs at its configured rate of the wall clock, as PX4 SITL's in lockstep.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use firmware_shim::link::{LinkConfig, Phase, Session};
use firmware_shim::messages::{self, Inbound, Px4Mode, classify};
use firmware_shim::transport::Link;
use px4_sim::vehicle::{SimVehicle, VehicleConfig, serve};

mod support;

#[test]
fn killed_controller_makes_the_simulated_px4_hold_position() {
    let (shim, port) = support::open_udpin_on_a_free_port();
    let stop = AtomicBool::new(false);
    let vehicle = SimVehicle::new(VehicleConfig::default());
    let hover = vehicle.thrust_map().hover_thrust;
    let rate = vehicle.config().clock_rate;
    let sitl_link = Link::open_as(
        &format!("udpout:127.0.0.1:{port}").parse().unwrap(),
        messages::PX4_SYSTEM,
        messages::PX4_COMPONENT,
    )
    .unwrap();
    let start = Instant::now();
    let (vehicle, killed_at, z_at_kill) = std::thread::scope(|s| {
        let sitl = s.spawn(|| {
            let mut v = vehicle;
            serve(&sitl_link, &mut v, 30.0, &stop);
            v
        });
        let mut session = Session::new(LinkConfig::default(), 0.0);
        let mut z = 0.0f64;
        let mut vz = 0.0f64;
        let mut flying_since = None;
        let mut killed = None;
        while start.elapsed() < Duration::from_secs(25) {
            let t = start.elapsed().as_secs_f64();
            while let Some((h, m)) = shim.try_recv() {
                let inbound = classify(&h, &m);
                if let Inbound::Odometry(o) = inbound {
                    z = -f64::from(o.position[2]);
                    vz = -f64::from(o.velocity[2]);
                }
                session.on_inbound(&inbound, t);
            }
            if killed.is_none() {
                let tick = session.tick(t);
                for m in &tick.send {
                    let _ = shim.send(m);
                }
                // Altitude hold at 2 m while flying; thrust 0 before.
                let thrust = if tick.mpc_in_control {
                    (hover * (1.0 + 0.4 * (2.0 - z) - 0.4 * vz)).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let _ = shim.send(&messages::set_attitude_target([0.0; 3], thrust as f32, 0));
                if session.phase() == Phase::Flying {
                    let since = *flying_since.get_or_insert(t);
                    if t - since > 3.0 && z > 1.0 {
                        killed = Some((t, z));
                    }
                }
            } else if killed.is_some_and(|(tk, _)| t - tk > 3.0) {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        stop.store(true, Ordering::Relaxed);
        let v = sitl.join().unwrap();
        let (tk, zk) = killed.expect("the session reached Flying and lifted off");
        (v, tk, zk)
    });
    assert_eq!(vehicle.commander().mode(), Px4Mode::Position);
    assert!(vehicle.commander().armed());
    let fs = vehicle
        .commander()
        .failsafe_at()
        .expect("offboard-loss failsafe");
    // Both clocks start within milliseconds of each other, the vehicle's running at `rate`;
    // the failsafe comes 0.5 s (of the vehicle's clock) after the last setpoint (generous
    // bounds for a loaded machine).
    let after = fs - rate * killed_at;
    assert!(
        after > 0.3 && after < 1.5,
        "failsafe {after} s after the kill"
    );
    assert!(!vehicle.crashed());
    let z_end = vehicle.state().p.z;
    assert!(
        z_end > 0.5 && (z_end - z_at_kill).abs() < 1.0,
        "held at {z_end} m (killed at {z_at_kill})"
    );
}

/// Serves a vehicle with clock rate `rate` for `wall` seconds; returns it and the ODOMETRY
/// timestamps with their arrival times (s since the start, s of the vehicle's clock).
fn serve_for(rate: f64, wall: f64) -> (SimVehicle, Vec<(f64, f64)>) {
    let (shim, port) = support::open_udpin_on_a_free_port();
    let mut vehicle = SimVehicle::new(VehicleConfig {
        clock_rate: rate,
        ..VehicleConfig::default()
    });
    let sitl_link = Link::open_as(
        &format!("udpout:127.0.0.1:{port}").parse().unwrap(),
        messages::PX4_SYSTEM,
        messages::PX4_COMPONENT,
    )
    .unwrap();
    let stop = AtomicBool::new(false);
    let start = Instant::now();
    let mut stamps = Vec::new();
    std::thread::scope(|s| {
        let sitl = s.spawn(|| serve(&sitl_link, &mut vehicle, wall, &stop));
        while !sitl.is_finished() {
            while let Some((h, m)) = shim.try_recv() {
                if let Inbound::Odometry(o) = classify(&h, &m) {
                    let arrival = start.elapsed().as_secs_f64();
                    stamps.push((arrival, o.time_us as f64 * 1e-6));
                }
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    });
    (vehicle, stamps)
}

/// The least-squares slope of `y` over `x`.
fn slope(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (sxy, sxx) = points.iter().fold((0.0, 0.0), |(sxy, sxx), (x, y)| {
        (sxy + (x - mx) * (y - my), sxx + (x - mx) * (x - mx))
    });
    sxy / sxx
}

/// Served, the simulation runs `rate` vehicle seconds per wall-clock second (never ahead),
/// and the timestamps PX4 sends grow at that rate: PX4 SITL's 1.2 % slow clock by default,
/// half and twice the wall clock's rate when asked.
#[test]
fn the_served_vehicle_clock_runs_at_its_rate() {
    for (rate, wall) in [(0.988, 3.0), (0.5, 1.5), (2.0, 1.5)] {
        let (v, stamps) = serve_for(rate, wall);
        let t = v.time();
        assert!(
            t <= rate * wall + 1e-9 && t > rate * wall - 0.03,
            "rate {rate}: {t} s simulated in {wall} s"
        );
        let s = slope(&stamps);
        assert!(stamps.len() > 20, "{} stamps", stamps.len());
        assert!((s - rate).abs() < 0.004, "rate {rate}: timestamps at {s}");
    }
    assert_eq!(VehicleConfig::default().clock_rate, 0.988);
}
