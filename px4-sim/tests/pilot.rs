//! The pilot ([`firmware_shim::pilot`]) flying whole missions in lockstep with the simulated
//! PX4 ([`px4_sim::vehicle`]), without sockets, threads or wall clocks (simulated time: the
//! pilot's wall clock is the vehicle's clock): hovers and flips, normal, without an answer to
//! the hover-thrust request, through an odometry blackout (AUTO.RTL), aborted (AUTO.LAND),
//! with PX4's clock off the wall's rate or jumping, on the stock vehicle.

use std::f64::consts::PI;

use firmware_shim::link::{Failsafe, Phase};
use firmware_shim::messages::{self, Px4Mode};
use firmware_shim::pilot::{ODOMETRY_PREFERENCE_US, Pilot, PilotConfig};
use firmware_shim::profile::VehicleProfile;
use firmware_shim::setpoint::{RateLimits, ThrustMap};
use mavlink::MavHeader;
use mavlink::dialects::common::{self as mc, MavCmd, MavMessage};
use mpc_mission::mission::{G, MissionConfig, MissionKind, Phase as MissionPhase};
use px4_sim::vehicle::{ClockJump, SimVehicle, VehicleConfig};

/// PX4's autopilot: system 1, component 1.
const PX4: MavHeader = MavHeader {
    system_id: 1,
    component_id: 1,
    sequence: 0,
};

fn hover_config() -> PilotConfig {
    let mut mission = MissionConfig::for_kind(MissionKind::Hover);
    mission.hover_time = 2.0;
    // The vehicle given, so that PX4 is asked for nothing but its hover thrust.
    PilotConfig {
        vehicle: Some(VehicleProfile::design()),
        ..PilotConfig::new(mission)
    }
}

fn is_state(m: &MavMessage) -> bool {
    matches!(
        m,
        MavMessage::ODOMETRY(_)
            | MavMessage::LOCAL_POSITION_NED(_)
            | MavMessage::ATTITUDE_QUATERNION(_)
    )
}

/// The pilot and the simulated PX4 in simulated time: the pilot's wall clock is the
/// vehicle's clock, 1 ms a step.
struct Lockstep {
    pilot: Pilot,
    vehicle: SimVehicle,
    /// Everything the pilot sent, with the (simulated) time.
    sent: Vec<(f64, MavMessage)>,
    /// Drop ODOMETRY, LOCAL_POSITION_NED and ATTITUDE_QUATERNION on the way to the pilot.
    block_states: bool,
    /// Drop PARAM_REQUEST_READ on the way to the vehicle.
    block_param_requests: bool,
    /// When the last ODOMETRY reached the pilot.
    last_odometry: Option<f64>,
    /// The vehicle's clock over the pilot's wall clock.
    clock_rate: f64,
}

impl Lockstep {
    fn new(cfg: PilotConfig, seed: u64) -> Self {
        Self::with_vehicle(
            cfg,
            VehicleConfig {
                seed,
                ..VehicleConfig::default()
            },
        )
    }

    fn with_vehicle(cfg: PilotConfig, vehicle: VehicleConfig) -> Self {
        Self {
            pilot: Pilot::new(cfg).unwrap(),
            vehicle: SimVehicle::new(vehicle),
            sent: Vec::new(),
            block_states: false,
            block_param_requests: false,
            last_odometry: None,
            clock_rate: 1.0,
        }
    }

    /// The pilot's wall clock.
    fn wall(&self) -> f64 {
        self.vehicle.time() / self.clock_rate
    }

    fn t(&self) -> f64 {
        self.vehicle.time()
    }

    fn step(&mut self) {
        let msgs = self.vehicle.step(0.001);
        let (t, wall) = (self.vehicle.time(), self.wall());
        for m in msgs {
            if self.block_states && is_state(&m) {
                continue;
            }
            if matches!(m, MavMessage::ODOMETRY(_)) {
                self.last_odometry = Some(t);
            }
            self.pilot.on_message(&PX4, &m, wall);
        }
        for m in self.pilot.poll(wall) {
            self.sent.push((t, m.clone()));
            if self.block_param_requests && matches!(m, MavMessage::PARAM_REQUEST_READ(_)) {
                continue;
            }
            for r in self.vehicle.handle(&m) {
                self.pilot.on_message(&PX4, &r, wall);
            }
        }
    }

    /// Steps until `done` or the pilot has finished, at most until `limit` [s]; whether
    /// `done` (or the end) came.
    fn run_until(&mut self, limit: f64, mut done: impl FnMut(&Self) -> bool) -> bool {
        while self.t() < limit {
            self.step();
            if self.pilot.finished() || done(self) {
                return true;
            }
        }
        false
    }

    fn setpoints(&self) -> impl Iterator<Item = (f64, &mc::SET_ATTITUDE_TARGET_DATA)> {
        self.sent.iter().filter_map(|(t, m)| match m {
            MavMessage::SET_ATTITUDE_TARGET(s) => Some((*t, s)),
            _ => None,
        })
    }

    /// The mode commands sent: (time, mode).
    fn mode_commands(&self) -> Vec<(f64, Px4Mode)> {
        self.sent
            .iter()
            .filter_map(|(t, m)| match m {
                MavMessage::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_DO_SET_MODE => Some((
                    *t,
                    Px4Mode::from_custom_mode(
                        (u32::from(c.param2 as u8) << 16) | (u32::from(c.param3 as u8) << 24),
                    ),
                )),
                _ => None,
            })
            .collect()
    }

    fn param_requests(&self) -> Vec<(f64, &mc::PARAM_REQUEST_READ_DATA)> {
        self.sent
            .iter()
            .filter_map(|(t, m)| match m {
                MavMessage::PARAM_REQUEST_READ(r) => Some((*t, r)),
                _ => None,
            })
            .collect()
    }

    fn show(&self, name: &str) {
        for e in self.pilot.events() {
            eprintln!("[{name}] {:8.3}  {}", e.t, e.what);
        }
        for line in self.vehicle.record().summary_lines() {
            eprintln!("[{name}] sitl: {line}");
        }
    }

    /// Flies until `phase` has lasted `after` seconds of simulated time.
    fn fly_into(&mut self, phase: MissionPhase, after: f64) -> f64 {
        let mut since = None;
        let reached = self.run_until(60.0, |ls| {
            if ls.pilot.mission_phase() == Some(phase) {
                let s = *since.get_or_insert(ls.t());
                ls.t() - s >= after
            } else {
                false
            }
        });
        assert!(reached && !self.pilot.finished(), "never in {phase:?}");
        self.t()
    }

    /// Every setpoint is a body-rate setpoint (attitude ignored), finite, within the rate
    /// limits, with a thrust in [0, 1].
    fn assert_setpoints_safe(&self) {
        let lim = RateLimits::default().max.map(|x| x as f32);
        let mut n = 0;
        for (t, s) in self.setpoints() {
            n += 1;
            assert_eq!(s.type_mask.bits(), 128, "at {t}");
            let rates = [s.body_roll_rate, s.body_pitch_rate, s.body_yaw_rate];
            for (r, l) in rates.iter().zip(lim.iter()) {
                assert!(r.is_finite() && r.abs() <= *l, "at {t}: {rates:?}");
            }
            assert!(
                s.thrust.is_finite() && (0.0..=1.0).contains(&s.thrust),
                "at {t}: {}",
                s.thrust
            );
            assert_eq!(s.q, [1.0, 0.0, 0.0, 0.0]);
        }
        assert!(n > 0, "no setpoint");
    }

    /// The vehicle is on the ground after a touchdown later than `after`, disarmed, not
    /// crashed.
    fn assert_landed_and_disarmed(&self, after: f64) {
        let r = self.vehicle.record();
        assert!(r.crashed.is_none(), "{:?}", r.crashed);
        assert!(r.max_height.is_some_and(|h| h > 1.5), "{:?}", r.max_height);
        let td = r.touchdowns.last().expect("touched down");
        assert!(td.time > after, "touchdown at {} before {after}", td.time);
        assert!(td.vertical_speed < 1.0, "{}", td.vertical_speed);
        assert!(!self.vehicle.commander().armed());
        assert!(r.disarmed_at.last().is_some_and(|t| *t >= td.time));
        assert!(r.final_position.z.abs() < 0.05, "{:?}", r.final_position);
    }
}

#[test]
fn a_hover_mission_flies_in_lockstep_with_the_simulated_px4() {
    let clock = std::time::Instant::now();
    let mut ls = Lockstep::new(hover_config(), 3);
    assert!(ls.run_until(60.0, |_| false), "finished");
    ls.show("hover");
    eprintln!(
        "[hover] {:.1} s simulated in {:.2} s",
        ls.t(),
        clock.elapsed().as_secs_f64()
    );
    // The hover thrust was read from PX4, with one request.
    assert_eq!(
        ls.pilot.thrust_map().map(|m| m.hover_thrust as f32),
        Some(ls.vehicle.thrust_map().hover_thrust as f32)
    );
    let requests = ls.param_requests();
    assert_eq!(requests.len(), 1);
    assert!(messages::param_name_is(
        &requests[0].1.param_id.into(),
        messages::HOVER_THRUST_PARAM
    ));
    assert_eq!(ls.pilot.failure(), None);
    // Through to the end: mission landed, AUTO.LAND asked, PX4 disarmed.
    assert_eq!(ls.pilot.session().map(|s| s.phase()), Some(Phase::Done));
    assert_eq!(ls.pilot.mission_phase(), Some(MissionPhase::Landed));
    assert_eq!(
        ls.mode_commands()
            .iter()
            .map(|(_, m)| *m)
            .collect::<Vec<_>>(),
        [Px4Mode::Offboard, Px4Mode::Land]
    );
    let r = ls.vehicle.record();
    assert_eq!(
        r.mode_changes.iter().map(|m| m.to).collect::<Vec<_>>(),
        [Px4Mode::Offboard, Px4Mode::Land]
    );
    assert!(r.mode_changes.iter().all(|m| !m.failsafe));
    assert_eq!(r.armed_at.len(), 1);
    ls.assert_landed_and_disarmed(0.0);
    let td = r.touchdowns.last().unwrap();
    assert!(td.position.xy().norm() < 0.3, "{:?}", td.position);
    // The mission held the take-off point: the highest point is about 2 m.
    assert!(r.max_height.is_some_and(|h| h < 2.5), "{:?}", r.max_height);
    let report = ls.pilot.report();
    assert!(report.failsafes.is_empty(), "{:?}", report.failsafes);
    assert_eq!(report.states_dropped, 0);
    assert_eq!(report.setpoints_replaced, 0);
    let summary = report.summary.as_ref().expect("flown");
    assert!(summary.success, "{:?}", summary.failures);
    ls.assert_setpoints_safe();

    // The stream at the configured rate, in simulated time: over the session and while the
    // vehicle was armed.
    let rate = ls.pilot.config().setpoint_rate;
    let times: Vec<f64> = ls.setpoints().map(|(t, _)| t).collect();
    assert_eq!(report.setpoints as usize, times.len());
    let (first, last) = (times[0], times[times.len() - 1]);
    let expected = (last - first) * rate;
    let n = (times.len() - 1) as f64;
    assert!(
        (n - expected).abs() <= 0.02 * expected,
        "{n} setpoints vs {expected}"
    );
    // From arming until the stream stops (PX4's HEARTBEAT shows AUTO.LAND; PX4 then lands
    // and disarms on its own, its land detector taking a few seconds on the ground).
    let (armed, disarmed) = (r.armed_at[0], *r.disarmed_at.last().unwrap());
    assert!(
        last < disarmed,
        "setpoints after the disarm: {last} s, {disarmed} s"
    );
    let in_flight = times.iter().filter(|t| **t >= armed).count() as f64 - 1.0;
    let expected = (last - armed) * rate;
    assert!(
        (in_flight - expected).abs() <= 0.02 * expected,
        "{in_flight} setpoints armed vs {expected}"
    );
    let longest = times.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!(longest < 2.0 / rate, "a gap of {longest} s");
    // The pilot's own figures agree (its wall clock is simulated here).
    let period = report.setpoint_period;
    assert!(
        (period.mean_ms - 1e3 / rate).abs() < 0.02 * 1e3 / rate,
        "{period:?}"
    );
}

#[test]
fn no_answer_to_the_hover_thrust_request_fails_after_five_seconds() {
    let mut ls = Lockstep::new(hover_config(), 4);
    ls.block_param_requests = true;
    assert!(ls.run_until(10.0, |_| false), "not finished");
    let finished_at = ls.t();
    assert!(ls.pilot.finished());
    let failure = ls.pilot.failure().expect("a failure");
    assert!(failure.contains(messages::HOVER_THRUST_PARAM), "{failure}");
    let requests = ls.param_requests();
    assert_eq!(requests.len(), 5, "one a second, five tries");
    for (_, r) in &requests {
        assert!(messages::param_name_is(
            &r.param_id.into(),
            messages::HOVER_THRUST_PARAM
        ));
    }
    for w in requests.windows(2) {
        let dt = w[1].0 - w[0].0;
        assert!((1.0..1.0015).contains(&dt), "requests {dt} s apart");
    }
    let first = requests[0].0;
    assert!(first < 0.01, "asked at {first}");
    let waited = finished_at - first;
    assert!((4.99..5.01).contains(&waited), "gave up after {waited} s");
    // Nothing else went out but TIMESYNC requests: no session, no setpoint, no command.
    assert_eq!(ls.setpoints().count(), 0);
    let others = ls
        .sent
        .iter()
        .filter(|(_, m)| !matches!(m, MavMessage::TIMESYNC(_)))
        .count();
    assert_eq!(others, requests.len());
    assert_eq!(ls.pilot.session(), None);
    assert_eq!(ls.pilot.thrust_map(), None);
    assert!(ls.vehicle.record().armed_at.is_empty());
    assert!(ls.pilot.report().session.starts_with("failed:"));
}

#[test]
fn an_unusable_or_foreign_hover_thrust_parameter_is_not_used() {
    let value = |v: f32| {
        MavMessage::PARAM_VALUE(mc::PARAM_VALUE_DATA {
            param_value: v,
            param_count: 1,
            param_index: 0,
            param_id: messages::HOVER_THRUST_PARAM.into(),
            param_type: mc::MavParamType::MAV_PARAM_TYPE_REAL32,
        })
    };
    // PX4's HEARTBEAT names the autopilot; what comes before it is not used.
    let heartbeat = MavMessage::HEARTBEAT(mc::HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: mc::MavType::MAV_TYPE_QUADROTOR,
        autopilot: mc::MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode: mc::MavModeFlag::empty(),
        system_status: mc::MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    });
    let new_pilot = || {
        let mut p = Pilot::new(hover_config()).unwrap();
        p.on_message(&PX4, &heartbeat, 0.0);
        p
    };
    let mut pilot = Pilot::new(hover_config()).unwrap();
    pilot.on_message(&PX4, &value(0.4), 0.0);
    assert_eq!(pilot.thrust_map(), None, "before PX4's HEARTBEAT");
    // From another component: ignored.
    let mut pilot = new_pilot();
    let other = MavHeader {
        component_id: 2,
        ..PX4
    };
    pilot.on_message(&other, &value(0.4), 0.0);
    assert_eq!(pilot.thrust_map(), None);
    assert!(!pilot.finished());
    // From PX4 but out of range: the loop cannot fly.
    for bad in [0.0, 1.5] {
        let mut pilot = new_pilot();
        pilot.on_message(&PX4, &value(bad), 0.0);
        assert_eq!(pilot.thrust_map(), None);
        assert!(pilot.finished());
        let f = pilot.failure().expect("a failure");
        assert!(
            f.contains(messages::HOVER_THRUST_PARAM) && f.contains(&bad.to_string()),
            "{f}"
        );
    }
    // In range: used.
    let mut pilot = new_pilot();
    pilot.on_message(&PX4, &value(0.4), 0.0);
    assert_eq!(pilot.thrust_map().map(|m| m.hover_thrust as f32), Some(0.4));
    assert!(!pilot.finished());
}

#[test]
fn a_given_thrust_map_is_not_asked_for() {
    let map = ThrustMap {
        hover_thrust: SimVehicle::new(VehicleConfig::default())
            .thrust_map()
            .hover_thrust,
        g: G,
    };
    let cfg = PilotConfig {
        thrust_map: Some(map),
        ..hover_config()
    };
    let mut ls = Lockstep::new(cfg, 5);
    let flying = ls.run_until(8.0, |ls| {
        ls.pilot.session().map(|s| s.phase()) == Some(Phase::Flying)
    });
    assert!(
        flying && !ls.pilot.finished(),
        "{:?}",
        ls.pilot.session().map(|s| s.phase())
    );
    assert!(ls.param_requests().is_empty());
    assert_eq!(ls.pilot.thrust_map(), Some(map));
    assert!(ls.setpoints().count() > 100);
    assert!(ls.vehicle.commander().armed());
}

#[test]
fn an_odometry_blackout_in_the_hover_commands_return_mode_in_time() {
    let mut ls = Lockstep::new(hover_config(), 6);
    let start = ls.fly_into(MissionPhase::Hold, 0.5);
    assert_eq!(ls.pilot.session().map(|s| s.phase()), Some(Phase::Flying));
    ls.block_states = true;
    let last_state = ls.last_odometry.expect("odometry");
    let limit = ls.pilot.config().link.odometry_timeout;
    let mut failsafe_seen = None;
    assert!(ls.run_until(60.0, |ls| {
        if failsafe_seen.is_none()
            && matches!(
                ls.pilot.session().map(|s| s.phase()),
                Some(Phase::Failsafe(_))
            )
        {
            failsafe_seen = Some(ls.t());
        }
        false
    }));
    ls.show("blackout");
    let seen = failsafe_seen.expect("a failsafe");
    assert_eq!(
        ls.pilot.session().map(|s| s.phase()),
        Some(Phase::Failsafe(Failsafe::OdometryLost))
    );
    let report = ls.pilot.report();
    let (kind, at) = report.failsafes.first().expect("a failsafe").clone();
    assert_eq!(kind, format!("{:?}", Failsafe::OdometryLost));
    assert_eq!(report.failsafes.len(), 1, "{:?}", report.failsafes);
    // On time: after the staleness limit, within 2 ms of it (the pilot's clock is the
    // vehicle's here, the states being stamped when sent, in whole microseconds: the
    // reported time may be a microsecond behind).
    let late = seen - last_state - limit;
    assert!((0.0..=0.002).contains(&late), "{late:.6} s after the limit");
    let late = at - last_state - limit;
    assert!(
        (-1e-5..=0.002).contains(&late),
        "{late:.6} s after the limit"
    );
    // AUTO.RTL asked at once, and flown by PX4 (commanded, not its offboard-loss failsafe).
    let modes = ls.mode_commands();
    let rtl = modes
        .iter()
        .find(|(_, m)| *m == Px4Mode::Return)
        .expect("AUTO.RTL commanded");
    assert!((rtl.0 - seen).abs() < 1e-9);
    assert!(modes.iter().all(|(_, m)| *m != Px4Mode::Land), "{modes:?}");
    assert_eq!(ls.vehicle.commander().mode(), Px4Mode::Return);
    let r = ls.vehicle.record();
    let change = r.mode_changes.last().unwrap();
    assert_eq!(
        (change.from, change.to, change.failsafe),
        (Px4Mode::Offboard, Px4Mode::Return, false)
    );
    ls.assert_landed_and_disarmed(start);
    assert!(r.touchdowns.last().unwrap().position.xy().norm() < 0.5);
    ls.assert_setpoints_safe();
    // The stream never paused while PX4 could have been in OFFBOARD.
    let times: Vec<f64> = ls.setpoints().map(|(t, _)| t).collect();
    let longest = times.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!(longest < 0.02, "a gap of {longest} s");
}

#[test]
fn an_abort_in_the_hover_commands_land_mode() {
    let mut ls = Lockstep::new(hover_config(), 7);
    let start = ls.fly_into(MissionPhase::Hold, 0.5);
    ls.pilot.abort();
    assert!(ls.run_until(60.0, |_| false), "not finished");
    ls.show("abort");
    assert!(ls.pilot.finished());
    assert_eq!(
        ls.pilot.session().map(|s| s.phase()),
        Some(Phase::Failsafe(Failsafe::Abort))
    );
    let modes = ls.mode_commands();
    let land: Vec<_> = modes.iter().filter(|(_, m)| *m == Px4Mode::Land).collect();
    assert_eq!(land.len(), 1, "{modes:?}");
    assert!(
        land[0].0 >= start && land[0].0 < start + 0.0015,
        "{modes:?}"
    );
    assert_eq!(ls.vehicle.commander().mode(), Px4Mode::Land);
    let r = ls.vehicle.record();
    let change = r.mode_changes.last().unwrap();
    assert_eq!((change.from, change.to), (Px4Mode::Offboard, Px4Mode::Land));
    ls.assert_landed_and_disarmed(start);
    let report = ls.pilot.report();
    assert_eq!(
        report
            .failsafes
            .iter()
            .map(|(k, _)| k.as_str())
            .collect::<Vec<_>>(),
        [format!("{:?}", Failsafe::Abort)]
    );
    ls.assert_setpoints_safe();
}

#[test]
fn a_vehicle_without_odometry_is_flown_on_position_and_attitude_pairs() {
    let mut cfg = hover_config();
    // Do not ask for ODOMETRY; the vehicle streams only LOCAL_POSITION_NED (30 Hz) and
    // ATTITUDE_QUATERNION (50 Hz).
    cfg.link.odometry_rate = 0.0;
    let mut ls = Lockstep::new(cfg, 8);
    ls.vehicle = SimVehicle::new(VehicleConfig {
        seed: 8,
        odometry_period: 0.0,
        ..VehicleConfig::default()
    });
    assert!(ls.run_until(60.0, |_| false), "finished");
    ls.show("pairs");
    assert_eq!(ls.last_odometry, None);
    assert_eq!(ls.pilot.session().map(|s| s.phase()), Some(Phase::Done));
    let report = ls.pilot.report();
    eprintln!(
        "[pairs] states {} dropped {} setpoints {}",
        report.states, report.states_dropped, report.setpoints
    );
    assert!(report.failsafes.is_empty(), "{:?}", report.failsafes);
    ls.assert_landed_and_disarmed(0.0);
    ls.assert_setpoints_safe();
    // No state before the preference time since the first state message (at 1 ms), one
    // soon after (the hover thrust is asked for at the first state).
    let first = ls.param_requests()[0].0;
    let pref = ODOMETRY_PREFERENCE_US as f64 * 1e-6;
    assert!(
        first >= 0.001 + pref - 1e-9 && first < 0.001 + pref + 0.035,
        "first state at {first}"
    );
}

#[test]
fn an_abort_before_arming_commands_land_mode_and_finishes_on_the_ground() {
    let mut ls = Lockstep::new(hover_config(), 9);
    // Streaming, not yet in OFFBOARD.
    assert!(!ls.run_until(1.5, |_| false));
    assert!(matches!(
        ls.pilot.session().map(|s| s.phase()),
        Some(Phase::Streaming { .. } | Phase::RequestingOffboard)
    ));
    let t = ls.t();
    ls.pilot.abort();
    assert!(ls.run_until(10.0, |_| false), "not finished");
    assert!(ls.t() - t < 3.0, "finished at {}", ls.t());
    assert_eq!(
        ls.pilot.session().map(|s| s.phase()),
        Some(Phase::Failsafe(Failsafe::Abort))
    );
    assert!(
        ls.mode_commands()
            .iter()
            .any(|(at, m)| *m == Px4Mode::Land && *at > t)
    );
    let r = ls.vehicle.record();
    assert!(r.armed_at.is_empty(), "{:?}", r.armed_at);
    assert!(r.first_liftoff.is_none());
    assert_eq!(ls.pilot.mission_phase(), None);
    // The setpoints were idle (zero thrust, zero rates) throughout.
    assert!(ls.setpoints().all(|(_, s)| s.thrust == 0.0
        && [s.body_roll_rate, s.body_pitch_rate, s.body_yaw_rate] == [0.0; 3]));
}

/// A PARAM_VALUE for MPC_THR_HOVER that arrives after the pilot gave up asking (five
/// unanswered requests, `failure()` set, `finished()` true), or after an unusable value, is
/// not taken: a caller that keeps polling never gets a session, setpoints or an armed
/// vehicle from a pilot that reported it could not start.
#[test]
fn a_late_hover_thrust_answer_does_not_start_a_failed_pilot() {
    let mut ls = Lockstep::new(hover_config(), 10);
    ls.block_param_requests = true;
    assert!(ls.run_until(10.0, |_| false));
    assert!(ls.pilot.failure().is_some() && ls.pilot.finished());
    // PX4's answer to the last request comes late.
    let (_, request) = ls.sent.last().cloned().unwrap();
    for r in ls.vehicle.handle(&request) {
        let t = ls.t();
        ls.pilot.on_message(&PX4, &r, t);
    }
    // The caller goes on polling for a while.
    let until = ls.t() + 5.0;
    while ls.t() < until {
        ls.step();
    }
    assert!(ls.pilot.failure().is_some());
    assert!(ls.pilot.finished());
    assert_eq!(ls.pilot.session(), None);
    assert_eq!(ls.setpoints().count(), 0, "setpoints after failure()");
    assert!(
        ls.vehicle.record().armed_at.is_empty(),
        "armed at {:?} after failure()",
        ls.vehicle.record().armed_at
    );
}

// ---------------------------------------------------------------------------------------
// PX4 as the real one showed it: its clock off the wall clock's rate, jumping; the stock SIH
// vehicle, whose flip is planned from its parameters

/// A flight in lockstep with the vehicle's clock at `rate` of the pilot's wall clock.
fn fly_at(cfg: PilotConfig, vehicle: VehicleConfig, rate: f64, limit: f64) -> Lockstep {
    let mut ls = Lockstep::with_vehicle(cfg, vehicle);
    ls.clock_rate = rate;
    let finished = ls.run_until(limit, |_| false);
    if !finished {
        ls.show("unfinished");
    }
    assert!(finished, "finished by {limit} s");
    ls
}

fn assert_flown(name: &str, ls: &Lockstep) {
    ls.show(name);
    let report = ls.pilot.report();
    let summary = report.summary.as_ref().expect("flown");
    assert!(summary.success, "{name}: {:?}", summary.failures);
    assert!(
        report.failsafes.is_empty(),
        "{name}: {:?}",
        report.failsafes
    );
    assert_eq!(ls.pilot.session().map(|s| s.phase()), Some(Phase::Done));
    let r = ls.vehicle.record();
    assert_eq!(r.crashed, None, "{name}");
    ls.assert_landed_and_disarmed(0.0);
}

#[test]
fn a_hover_flies_with_px4s_clock_five_percent_off_the_wall_clock() {
    for rate in [0.95, 0.988, 1.05] {
        let ls = fly_at(hover_config(), VehicleConfig::default(), rate, 60.0);
        assert_flown(&format!("hover at clock rate {rate}"), &ls);
        let est = ls.pilot.report().clock_rate;
        assert!((est - rate).abs() < 2e-3, "rate {rate}: estimated {est}");
        // The prediction is bounded by the round trip TIMESYNC measured (here no delay: the
        // least bound).
        assert!(ls.pilot.report().round_trip_ms.is_some());
    }
}

#[test]
fn a_jump_of_px4s_clock_in_the_hover_is_followed() {
    for by in [5.0, -5.0] {
        let vehicle = VehicleConfig {
            clock_jump: Some(ClockJump { at: 8.0, by }),
            ..VehicleConfig::default()
        };
        let ls = fly_at(hover_config(), vehicle, 1.0, 60.0);
        assert_flown(&format!("hover, clock jump {by:+}"), &ls);
        assert_eq!(ls.pilot.report().clock_jumps, 1);
        assert!(
            ls.pilot
                .events()
                .iter()
                .any(|e| e.what.contains("clock jumped by")),
            "{:?}",
            ls.pilot.events()
        );
    }
}

fn stock_flip_config(flip_rate: Option<f64>) -> PilotConfig {
    PilotConfig {
        flip_rate,
        ..PilotConfig::new(MissionConfig::flip())
    }
}

#[test]
fn the_flip_is_planned_from_px4s_sih_parameters_and_flown_off_the_walls_rate() {
    // The simulated PX4's design vehicle, its SIH parameters read, its clock 1.2 % slow as
    // the real PX4's in lockstep, and 5 % fast.
    for rate in [0.988, 1.05] {
        let cfg = PilotConfig::new(MissionConfig::flip());
        let ls = fly_at(cfg, VehicleConfig::default(), rate, 90.0);
        assert_flown(&format!("flip at clock rate {rate}"), &ls);
        let report = ls.pilot.report();
        let v = report.vehicle.expect("read from PX4");
        assert!(v.source.contains("SIH"), "{}", v.source);
        assert!((v.thrust_to_weight() - 4.0).abs() < 0.05);
        let flip = report.flip.expect("planned");
        assert!(
            (flip.rate - 5.0 * PI).abs() < 1e-9,
            "the paper's flip: {flip:?}"
        );
        let turn = ls.vehicle.record().offboard_pitch_rotation.abs();
        assert!(
            (2.0 * PI - 0.3..2.0 * PI + 0.5).contains(&turn),
            "turned {turn} rad"
        );
    }
}

#[test]
fn the_stock_vehicle_hovers_with_its_profile_read_from_px4() {
    let cfg = PilotConfig {
        vehicle: None,
        ..hover_config()
    };
    let ls = fly_at(cfg, VehicleConfig::stock(), 0.988, 60.0);
    assert_flown("stock hover", &ls);
    let v = ls.pilot.report().vehicle.expect("read from PX4");
    assert!((v.pitch_authority() - 80.0).abs() < 1e-3, "{v:?}");
}

#[test]
fn a_flip_beyond_the_vehicle_is_refused_before_arming() {
    let mut ls = Lockstep::with_vehicle(stock_flip_config(Some(5.0 * PI)), VehicleConfig::stock());
    assert!(ls.run_until(10.0, |_| false), "finished");
    let failure = ls.pilot.failure().expect("refused");
    assert!(
        failure.contains("beyond this vehicle") && failure.contains("--flip-rate"),
        "{failure}"
    );
    assert!(ls.vehicle.record().armed_at.is_empty());
    assert_eq!(ls.setpoints().count(), 0);
}

#[test]
fn the_touchdown_speed_is_the_fastest_descent_of_the_heights() {
    use firmware_shim::pilot::fastest_descent;
    use std::collections::VecDeque;
    // 0.3 m/s down, 0.7 m/s down for 0.4 s, then at rest (100 Hz).
    let mut h = 1.0;
    let heights: VecDeque<(f64, f64)> = (0..150)
        .map(|i| {
            let t = f64::from(i) * 0.01;
            let v = if t < 0.5 {
                0.3
            } else if t < 0.9 {
                0.7
            } else {
                0.0
            };
            h -= v * 0.01;
            (t, h)
        })
        .collect();
    let d = fastest_descent(&heights, 0.3);
    assert!((d - 0.7).abs() < 0.02, "{d}");
    assert_eq!(fastest_descent(&VecDeque::new(), 0.3), 0.0);
    let rest: VecDeque<(f64, f64)> = (0..50).map(|i| (f64::from(i) * 0.01, 0.2)).collect();
    assert_eq!(fastest_descent(&rest, 0.3), 0.0);
}

#[test]
fn the_nmpc_takes_the_vehicles_thrust_as_its_bound() {
    let peak = |ls: &Lockstep| {
        ls.pilot
            .samples()
            .iter()
            .map(|s| s.thrust_cmd)
            .fold(0.0, f64::max)
    };
    let said = |ls: &Lockstep, what: &str| ls.pilot.events().iter().any(|e| e.what.contains(what));
    // The design vehicle (thrust to weight 4): bounded at 4 g, and the take-off asks for
    // more than the weak vehicle below has.
    let strong = fly_at(hover_config(), VehicleConfig::default(), 1.0, 60.0);
    assert_flown("strong", &strong);
    assert!(said(&strong, "bounded by the vehicle's, 39.2 m/s^2"));
    // A profile with 0.28 of that thrust (thrust to weight 1.1: a hover's margin only).
    let weak = VehicleProfile {
        rotor_thrust_max_n: VehicleProfile::design().rotor_thrust_max_n * 0.28,
        ..VehicleProfile::design()
    };
    let c_max = weak.max_collective();
    assert!(peak(&strong) > c_max + 0.5, "{} vs {c_max}", peak(&strong));
    let cfg = PilotConfig {
        vehicle: Some(weak),
        ..hover_config()
    };
    let ls = fly_at(cfg, VehicleConfig::default(), 1.0, 60.0);
    assert_flown("weak", &ls);
    assert!(said(
        &ls,
        &format!("bounded by the vehicle's, {c_max:.1} m/s^2")
    ));
    assert!(peak(&ls) <= c_max + 1e-6, "{} > {c_max}", peak(&ls));
}

#[test]
fn the_stock_flip_flies_in_lockstep_with_the_stock_vehicle() {
    // The flip planned for PX4's SIH quadrotor (read from the simulated PX4), flown on the
    // stock vehicle as PX4 and SIH fly it. PX4 SITL flies it cleanly (the flight excerpted
    // in tests/data/px4_stock_flip_*: one turn, 6.31 rad, lowest 1.87 m after it).
    let ls = fly_at(stock_flip_config(None), VehicleConfig::stock(), 0.988, 90.0);
    assert_flown("stock flip", &ls);
    let turn = ls.vehicle.record().offboard_pitch_rotation.abs();
    assert!(
        (2.0 * PI - 0.3..2.0 * PI + 0.5).contains(&turn),
        "turned {turn} rad"
    );
}
