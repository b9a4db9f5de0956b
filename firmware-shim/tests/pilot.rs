//! The controller loop ([`firmware_shim::pilot`]) without sockets, threads or wall clocks:
//! the state input (frames, duplicates, ODOMETRY vs LOCAL_POSITION_NED + ATTITUDE_QUATERNION
//! pairs), the latency prediction against closed forms, the period statistics, the
//! configuration checks. The pilot flying whole missions in lockstep with the simulated PX4
//! is tested beside it (`px4-sim/tests/pilot.rs`).

use std::f64::consts::FRAC_1_SQRT_2;

use firmware_shim::messages::{Inbound, OdometryNed, Px4Mode, classify};
use firmware_shim::pilot::{
    MAX_PREDICTION_S, ODOMETRY_PREFERENCE_US, PAIR_WINDOW_US, PeriodStats, Pilot, PilotConfig,
    PilotError, RESPONSE_TIME_CONSTANT, State, StateInput, predict,
};
use firmware_shim::profile::VehicleProfile;
use firmware_shim::setpoint::{RateLimits, SetpointError, ThrustMap};
use mavlink::MavHeader;
use mavlink::dialects::common::{self as mc, MavFrame, MavMessage};
use mpc_mission::controller::InnerCommand;
use mpc_mission::mission::{G, MissionConfig, MissionKind};
use nalgebra::{UnitQuaternion, Vector3};

/// PX4's autopilot: system 1, component 1.
const PX4: MavHeader = MavHeader {
    system_id: 1,
    component_id: 1,
    sequence: 0,
};

// ---------------------------------------------------------------------------------------
// StateInput
// ---------------------------------------------------------------------------------------

fn odo(
    time_us: u64,
    position: [f32; 3],
    velocity: [f32; 3],
    q: [f32; 4],
    rates: [f32; 3],
) -> Inbound {
    Inbound::Odometry(OdometryNed {
        time_us,
        position,
        velocity,
        q,
        rates,
    })
}

/// A level, nose-north ODOMETRY at rest at the origin.
fn odo_at(time_us: u64) -> Inbound {
    odo(time_us, [0.0; 3], [0.0; 3], [1.0, 0.0, 0.0, 0.0], [0.0; 3])
}

fn lp(time_ms: u32, position: [f32; 3]) -> Inbound {
    Inbound::LocalPosition {
        time_boot_ms: time_ms,
        position,
        velocity: [0.0; 3],
    }
}

fn att(time_ms: u32) -> Inbound {
    Inbound::Attitude {
        time_boot_ms: time_ms,
        q: [1.0, 0.0, 0.0, 0.0],
        rates: [0.0; 3],
    }
}

fn assert_vec(got: &Vector3<f64>, want: [f64; 3], tol: f64) {
    let want = Vector3::from(want);
    assert!((got - want).norm() <= tol, "got {got:?}, want {want:?}");
}

#[test]
fn odometry_is_converted_from_ned_frd_to_enu_flu() {
    let s = FRAC_1_SQRT_2 as f32;
    let mut input = StateInput::default();
    // Nose east (NED yaw 90 deg): the ENU/FLU identity.
    let st = input
        .on_inbound(&odo(
            1_250_000,
            [1.0, 2.0, -3.0],
            [0.5, -1.5, 2.0],
            [s, 0.0, 0.0, s],
            [0.1, 0.2, 0.3],
        ))
        .expect("a state");
    assert!((st.t - 1.25).abs() < 1e-12, "{}", st.t);
    // North 1, east 2, 3 m up.
    assert_vec(&st.p, [2.0, 1.0, 3.0], 0.0);
    // North 0.5, west 1.5, 2 m/s down.
    assert_vec(&st.v, [-1.5, 0.5, -2.0], 0.0);
    assert!(
        st.q.angle_to(&UnitQuaternion::identity()) < 1e-6,
        "{:?}",
        st.q
    );
    // Roll rate keeps its sign, pitch and yaw rates flip.
    assert_vec(&st.w, [0.1, -0.2, -0.3], 1e-7);

    // Level, nose north (the NED identity): ENU yaw +90 deg, the nose along ENU +y.
    let st = input.on_inbound(&odo_at(1_260_000)).expect("a newer state");
    let yaw90 = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
    assert!(st.q.angle_to(&yaw90) < 1e-9, "{:?}", st.q);

    // Nose north, pitched up 30 deg (NED pitch +30 deg about east): the nose points north
    // and up in ENU, the body left (FLU +y) points west, the thrust axis (FLU +z) up and
    // back (south).
    let th = 30f64.to_radians();
    let qp = [(th / 2.0).cos() as f32, 0.0, (th / 2.0).sin() as f32, 0.0];
    let st = input
        .on_inbound(&odo(1_270_000, [0.0; 3], [0.0; 3], qp, [0.0; 3]))
        .expect("a newer state");
    assert_vec(&(st.q * Vector3::x()), [0.0, th.cos(), th.sin()], 1e-6);
    assert_vec(&(st.q * Vector3::y()), [-1.0, 0.0, 0.0], 1e-6);
    assert_vec(&(st.q * Vector3::z()), [0.0, -th.sin(), th.cos()], 1e-6);
    assert_eq!((input.accepted, input.dropped, input.from_pairs), (3, 0, 0));
}

/// A body vector through PX4's attitude and the two vector maps, against the converted
/// attitude: `q_enu_flu * v = ned_to_enu(q_ned_frd * flu_to_frd(v))`, for attitudes all
/// round.
#[test]
fn the_converted_attitude_rotates_body_vectors_as_px4s_does() {
    let mut input = StateInput::default();
    let mut t = 0;
    for i in 0..50 {
        let x = f64::from(i);
        let q_ned = UnitQuaternion::from_euler_angles(0.37 * x, -0.21 * x + 0.1, 0.73 * x - 2.0);
        t += 10_000;
        let q = [
            q_ned.w as f32,
            q_ned.i as f32,
            q_ned.j as f32,
            q_ned.k as f32,
        ];
        let st = input
            .on_inbound(&odo(t, [0.0; 3], [0.0; 3], q, [0.0; 3]))
            .unwrap();
        for v in [
            Vector3::x(),
            Vector3::y(),
            Vector3::z(),
            Vector3::new(0.3, -0.7, 1.1),
        ] {
            let frd = Vector3::new(v.x, -v.y, -v.z);
            let ned = q_ned * frd;
            let enu = Vector3::new(ned.y, ned.x, -ned.z);
            assert!((st.q * v - enu).norm() < 1e-6, "attitude {i}, {v:?}");
        }
    }
}

#[test]
fn odometry_through_classify_from_px4_only() {
    let msg = MavMessage::ODOMETRY(mc::ODOMETRY_DATA {
        time_usec: 42_000,
        x: 1.0,
        y: 2.0,
        z: -3.0,
        q: [1.0, 0.0, 0.0, 0.0],
        vx: 0.1,
        vy: 0.2,
        vz: 0.3,
        rollspeed: 0.4,
        pitchspeed: 0.5,
        yawspeed: 0.6,
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        ..mc::ODOMETRY_DATA::DEFAULT
    });
    let mut input = StateInput::default();
    let other = MavHeader {
        system_id: 2,
        ..PX4
    };
    assert_eq!(input.on_inbound(&classify(&other, &msg)), None);
    assert_eq!((input.accepted, input.dropped), (0, 0));
    let st = input.on_inbound(&classify(&PX4, &msg)).expect("from PX4");
    assert!((st.t - 0.042).abs() < 1e-12);
    assert_vec(&st.p, [2.0, 1.0, 3.0], 0.0);
    assert_vec(&st.v, [0.2, 0.1, -0.3], 1e-7);
    assert_vec(&st.w, [0.4, -0.5, -0.6], 1e-7);
}

#[test]
fn duplicate_and_older_states_are_dropped_and_counted() {
    let mut input = StateInput::default();
    assert!(input.on_inbound(&odo_at(1_000)).is_some());
    assert_eq!(input.on_inbound(&odo_at(1_000)), None, "duplicate");
    assert_eq!(input.on_inbound(&odo_at(999)), None, "older");
    assert_eq!(input.on_inbound(&odo_at(0)), None, "older");
    assert_eq!((input.accepted, input.dropped), (1, 3));
    let st = input.on_inbound(&odo_at(1_001)).expect("newer");
    assert!((st.t - 0.001_001).abs() < 1e-15);
    assert_eq!((input.accepted, input.dropped), (2, 3));
    // Messages that are not states are neither.
    let hb = Inbound::Heartbeat {
        armed: false,
        mode: Px4Mode::Position,
    };
    assert_eq!(input.on_inbound(&hb), None);
    assert_eq!(input.on_inbound(&Inbound::Ignored), None);
    assert_eq!((input.accepted, input.dropped), (2, 3));
}

#[test]
fn non_finite_states_are_dropped_and_counted() {
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    let id = [1.0, 0.0, 0.0, 0.0];
    let bad = [
        odo(10, [nan, 0.0, 0.0], [0.0; 3], id, [0.0; 3]),
        odo(20, [0.0, 0.0, inf], [0.0; 3], id, [0.0; 3]),
        odo(30, [0.0; 3], [0.0, nan, 0.0], id, [0.0; 3]),
        odo(40, [0.0; 3], [0.0; 3], [nan, 0.0, 0.0, 0.0], [0.0; 3]),
        odo(50, [0.0; 3], [0.0; 3], [0.0; 4], [0.0; 3]),
        odo(60, [0.0; 3], [0.0; 3], id, [0.0, 0.0, -inf]),
    ];
    let mut input = StateInput::default();
    for (i, m) in bad.iter().enumerate() {
        assert_eq!(input.on_inbound(m), None, "bad state {i}");
    }
    assert_eq!((input.accepted, input.dropped), (0, 6));
    // A dropped state does not advance the time: a good one with its timestamp is new.
    assert!(input.on_inbound(&odo_at(60)).is_some());
    assert_eq!((input.accepted, input.dropped), (1, 6));
}

#[test]
fn pairs_wait_for_the_odometry_preference_from_the_first_state_message() {
    let mut input = StateInput::default();
    let pref_ms = u32::try_from(ODOMETRY_PREFERENCE_US / 1000).unwrap();
    let mut first = None;
    // LOCAL_POSITION_NED and ATTITUDE_QUATERNION every 10 ms, 5 ms apart, from 1 s after
    // boot.
    let start = 1000;
    for k in 0..100u32 {
        let t = start + 10 * k;
        for m in [lp(t, [1.0, 2.0, -3.0]), att(t + 5)] {
            if let Some(s) = input.on_inbound(&m) {
                first.get_or_insert((t, s));
            }
        }
    }
    let (t, s) = first.expect("pairs make states without ODOMETRY");
    assert_eq!(
        t,
        start + pref_ms,
        "the first pair state comes when the preference ran out"
    );
    // Stamped with the later of the two (the position at 1500 ms, the attitude at 1495 ms).
    assert!(
        (s.t - f64::from(start + pref_ms) * 1e-3).abs() < 1e-12,
        "{}",
        s.t
    );
    assert_vec(&s.p, [2.0, 1.0, 3.0], 0.0);
    assert_eq!(input.accepted, input.from_pairs);
    assert_eq!(input.dropped, 0);
    // Every message from then on makes a state with its partner 5 ms away.
    assert_eq!(input.accepted, 2 * (100 - u64::from(pref_ms / 10)));
}

#[test]
fn pairs_are_used_only_when_odometry_stopped_for_the_preference_time() {
    let mut input = StateInput::default();
    let mut odometry_states = 0;
    // 1 s of ODOMETRY and pairs together: only ODOMETRY makes states.
    for k in 1..=100u32 {
        let t = 10 * k;
        if input.on_inbound(&odo_at(u64::from(t) * 1000)).is_some() {
            odometry_states += 1;
        }
        assert_eq!(input.on_inbound(&lp(t, [0.0; 3])), None, "at {t} ms");
        assert_eq!(input.on_inbound(&att(t)), None, "at {t} ms");
    }
    assert_eq!(odometry_states, 100);
    assert_eq!(input.from_pairs, 0);
    // ODOMETRY stops at 1000 ms: pairs only from 1000 ms + the preference on.
    let last_odometry_ms = 1000;
    let pref_ms = u32::try_from(ODOMETRY_PREFERENCE_US / 1000).unwrap();
    let mut pair_times = Vec::new();
    for k in 101..=200u32 {
        let t = 10 * k;
        if input.on_inbound(&lp(t, [0.0; 3])).is_some() {
            pair_times.push(t);
        }
        // The attitude of the same instant makes the same state again: not newer.
        let again = input.on_inbound(&att(t));
        assert!(
            again.is_none() || t < last_odometry_ms + pref_ms,
            "at {t} ms"
        );
    }
    assert_eq!(pair_times.first(), Some(&(last_odometry_ms + pref_ms)));
    assert_eq!(pair_times.len(), 51, "{pair_times:?}");
    assert_eq!(input.from_pairs, 51);
    // ODOMETRY is back: it is preferred again at once, pairs wait the preference time.
    assert!(input.on_inbound(&odo_at(2_005_000)).is_some());
    assert_eq!(input.on_inbound(&lp(2010, [0.0; 3])), None);
    assert_eq!(input.on_inbound(&att(2010)), None);
    assert_eq!(input.from_pairs, 51);
}

#[test]
fn pairs_further_apart_than_the_window_make_no_state() {
    let window_ms = u32::try_from(PAIR_WINDOW_US / 1000).unwrap();
    let mut input = StateInput::default();
    // The first state message at 0 ms; the preference has run out from 500 ms on.
    assert_eq!(input.on_inbound(&att(0)), None);
    assert_eq!(
        input.on_inbound(&lp(600, [0.0; 3])),
        None,
        "attitude 600 ms old"
    );
    let late = 600 + window_ms + 1;
    assert_eq!(
        input.on_inbound(&att(late)),
        None,
        "just outside the window"
    );
    assert_eq!(
        input.on_inbound(&lp(700, [4.0, 0.0, 0.0])),
        None,
        "attitude 74 ms old"
    );
    // Exactly the window apart: a state, stamped with the later of the two.
    let a = 700 + window_ms;
    let s = input.on_inbound(&att(a)).expect("exactly the window apart");
    assert!((s.t - f64::from(a) * 1e-3).abs() < 1e-12, "{}", s.t);
    assert_vec(&s.p, [0.0, 4.0, 0.0], 0.0);
    assert_eq!((input.accepted, input.from_pairs, input.dropped), (1, 1, 0));
}

// ---------------------------------------------------------------------------------------
// predict
// ---------------------------------------------------------------------------------------

fn cmd(thrust_c: f64, rates: Vector3<f64>) -> InnerCommand {
    InnerCommand { thrust_c, rates }
}

/// A state at a time whose sums with the test horizons are exact (0.5 s).
fn state(p: [f64; 3], v: [f64; 3], q: UnitQuaternion<f64>, w: [f64; 3]) -> State {
    State {
        t: 0.5,
        p: Vector3::from(p),
        v: Vector3::from(v),
        q,
        w: Vector3::from(w),
    }
}

/// Horizons (the age of the state) on the 2.5 ms grid and off it.
const HORIZONS: [f64; 6] = [0.0025, 0.01, 0.0625, 0.125, 0.1, 0.25];

#[test]
fn a_constant_commanded_rate_turns_the_attitude_by_its_exponential() {
    let w = Vector3::new(0.7, -1.3, 2.1);
    let s = State {
        w,
        ..state(
            [0.0; 3],
            [0.0; 3],
            UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0),
            [0.0; 3],
        )
    };
    let commands = [(s.t - 0.1, cmd(G, w))];
    for age in HORIZONS {
        let out = predict(&s, &commands, s.t + age);
        let want = s.q * UnitQuaternion::from_scaled_axis(w * age);
        assert!(
            out.q.angle_to(&want) < 1e-9,
            "age {age}: {}",
            out.q.angle_to(&want)
        );
        assert!((out.w - w).norm() < 1e-12, "age {age}: {:?}", out.w);
        assert!((out.t - (s.t + age)).abs() < 1e-12);
    }
}

#[test]
fn no_command_history_means_zero_commands() {
    // No setpoint sent: the rates decay to zero from the measured ones, no thrust.
    let w0 = Vector3::new(1.0, -2.0, 0.5);
    let s = state(
        [1.0, 2.0, 3.0],
        [0.0; 3],
        UnitQuaternion::identity(),
        [1.0, -2.0, 0.5],
    );
    let age = 0.125;
    let out = predict(&s, &[], s.t + age);
    let decay = (-age / RESPONSE_TIME_CONSTANT).exp();
    assert!((out.w - w0 * decay).norm() < 1e-9, "{:?}", out.w);
    assert_vec(&out.p, [1.0, 2.0, 3.0 - 0.5 * G * age * age], 1e-9);
    // At rest, level, nothing commanded: only gravity.
    let rest = state([0.0; 3], [0.0; 3], UnitQuaternion::identity(), [0.0; 3]);
    let out = predict(&rest, &[], rest.t + age);
    assert!(out.q.angle_to(&rest.q) < 1e-12);
    assert_vec(&out.v, [0.0, 0.0, -G * age], 1e-9);
}

#[test]
fn a_level_hover_thrust_keeps_the_velocity() {
    // Level at any heading, c = g, no rates: unaccelerated.
    for yaw in [0.0, 0.7, -2.5] {
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
        let s = state([1.0, -2.0, 3.0], [1.0, -2.0, 0.5], q, [0.0; 3]);
        let commands = [(s.t - 0.05, cmd(G, Vector3::zeros()))];
        for age in HORIZONS {
            let out = predict(&s, &commands, s.t + age);
            assert_vec(&out.v, [1.0, -2.0, 0.5], 1e-9);
            assert_vec(&out.p, [1.0 + age, -2.0 - 2.0 * age, 3.0 + 0.5 * age], 1e-9);
            assert!(out.q.angle_to(&q) < 1e-12);
        }
    }
}

#[test]
fn without_thrust_it_falls_freely_whatever_the_attitude() {
    let q = UnitQuaternion::from_euler_angles(0.4, -0.3, 1.2);
    let s = state([1.0, 2.0, 3.0], [0.5, 0.0, 2.0], q, [0.0; 3]);
    let commands = [(s.t - 0.05, cmd(0.0, Vector3::zeros()))];
    for age in HORIZONS {
        let out = predict(&s, &commands, s.t + age);
        let z = 3.0 + 2.0 * age - 0.5 * G * age * age;
        assert_vec(&out.p, [1.0 + 0.5 * age, 2.0, z], 1e-9);
        assert_vec(&out.v, [0.5, 0.0, 2.0 - G * age], 1e-9);
    }
}

#[test]
fn a_tilted_constant_thrust_accelerates_along_the_thrust_axis() {
    let q = UnitQuaternion::from_euler_angles(0.3, 0.0, 0.0);
    let c = 12.0;
    let s = state([0.0; 3], [1.0, 0.0, 0.0], q, [0.0; 3]);
    let commands = [(s.t - 0.05, cmd(c, Vector3::zeros()))];
    let a = q * Vector3::new(0.0, 0.0, c) - Vector3::new(0.0, 0.0, G);
    for age in HORIZONS {
        let out = predict(&s, &commands, s.t + age);
        let p = s.p + s.v * age + a * (0.5 * age * age);
        assert!((out.p - p).norm() < 1e-9, "age {age}");
        assert!((out.v - (s.v + a * age)).norm() < 1e-9, "age {age}");
    }
}

#[test]
fn the_prediction_is_at_most_max_prediction_s_and_never_backwards() {
    let s = state(
        [1.0, 2.0, 3.0],
        [0.5, 0.0, 2.0],
        UnitQuaternion::identity(),
        [0.0; 3],
    );
    let commands = [(s.t - 0.05, cmd(0.0, Vector3::zeros()))];
    let t = MAX_PREDICTION_S;
    let capped = predict(&s, &commands, s.t + 1.0);
    assert!((capped.t - (s.t + t)).abs() < 1e-12, "{}", capped.t);
    assert_vec(
        &capped.p,
        [1.0 + 0.5 * t, 2.0, 3.0 + 2.0 * t - 0.5 * G * t * t],
        1e-9,
    );
    assert_eq!(capped, predict(&s, &commands, s.t + t));
    assert_eq!(capped, predict(&s, &commands, s.t + 100.0));
    // A solve time before the state: the state itself.
    for until in [s.t, s.t - 0.1, s.t - 10.0] {
        assert_eq!(predict(&s, &commands, until), s, "until {until}");
    }
}

#[test]
fn the_rates_follow_the_command_as_a_first_order_lag() {
    let w0 = Vector3::new(0.5, -1.0, 2.0);
    let target = Vector3::new(2.0, 1.0, -1.0);
    let s = state(
        [0.0; 3],
        [0.0; 3],
        UnitQuaternion::identity(),
        [0.5, -1.0, 2.0],
    );
    let commands = [(s.t - 0.02, cmd(G, target))];
    for age in HORIZONS {
        let out = predict(&s, &commands, s.t + age);
        let want = target + (w0 - target) * (-age / RESPONSE_TIME_CONSTANT).exp();
        // The discrete update is the exponential at the step points: round-off only.
        assert!(
            (out.w - want).norm() < 1e-9,
            "age {age}: {:?} vs {want:?}",
            out.w
        );
    }
    // After one time constant, 1 - 1/e of the way.
    let out = predict(&s, &commands, s.t + RESPONSE_TIME_CONSTANT);
    let frac = (out.w - w0).component_div(&(target - w0));
    for f in frac.iter() {
        assert!((f - (1.0 - (-1.0f64).exp())).abs() < 1e-9, "{frac:?}");
    }
}

#[test]
fn the_command_in_force_at_each_instant_is_the_last_sent_before_it() {
    // The rate command switches from a to b part-way through the horizon: the rates are a
    // until then, and approach b from the switch on (within one 2.5 ms step of the switch).
    let a = Vector3::new(1.0, 0.0, -1.0);
    let b = Vector3::new(-3.0, 2.0, 1.0);
    let s = state(
        [0.0; 3],
        [0.0; 3],
        UnitQuaternion::identity(),
        [1.0, 0.0, -1.0],
    );
    let switch = s.t + 0.06375;
    let commands = [(s.t - 0.1, cmd(G, a)), (switch, cmd(G, b))];
    let age = 0.125;
    let out = predict(&s, &commands, s.t + age);
    let want = b + (a - b) * (-(s.t + age - switch) / RESPONSE_TIME_CONSTANT).exp();
    let step = 1.0 - (-0.0025 / RESPONSE_TIME_CONSTANT).exp();
    let tol = (b - a).norm() * step;
    assert!(
        (out.w - want).norm() <= tol,
        "{:?} vs {want:?} (tol {tol})",
        out.w
    );
    // Before the switch, still a.
    let before = predict(&s, &commands, s.t + 0.0625);
    assert!((before.w - a).norm() < 1e-12, "{:?}", before.w);
}

#[test]
fn the_thrust_follows_its_command_as_a_first_order_lag() {
    // Level, hovering thrust in force; 5 m/s^2 more commanded just after the state: the
    // vertical velocity is the integral of the lagged excess thrust.
    let s = state([0.0; 3], [0.0; 3], UnitQuaternion::identity(), [0.0; 3]);
    let step = 5.0;
    let switch = s.t + 1e-4;
    let commands = [
        (s.t - 0.1, cmd(G, Vector3::zeros())),
        (switch, cmd(G + step, Vector3::zeros())),
    ];
    let tau = RESPONSE_TIME_CONSTANT;
    for age in [0.0625, 0.125, 0.25] {
        let out = predict(&s, &commands, s.t + age);
        let d = s.t + age - switch;
        let want = step * (d - tau * (1.0 - (-d / tau).exp()));
        let tol = step * 0.0025;
        assert!(
            (out.v.z - want).abs() <= tol,
            "age {age}: {} vs {want}",
            out.v.z
        );
        // Clearly not the unlagged answer.
        assert!(step * d - out.v.z > 5.0 * tol, "age {age}");
        assert!(out.v.xy().norm() < 1e-12);
    }
}

// ---------------------------------------------------------------------------------------
// PeriodStats
// ---------------------------------------------------------------------------------------

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}

#[test]
fn period_stats_of_known_values() {
    // 4, 1, 3, 2 ms and a NaN (ignored), unsorted.
    let st = PeriodStats::of(&[0.004, 0.001, f64::NAN, 0.003, 0.002]);
    assert_eq!(st.count, 4);
    assert!(close(st.mean_ms, 2.5), "{st:?}");
    // Nearest rank: the ceil(0.5 * 4) = 2nd value, the ceil(0.99 * 4) = 4th value.
    assert!(close(st.median_ms, 2.0), "{st:?}");
    assert!(close(st.p99_ms, 4.0), "{st:?}");
    assert!(close(st.max_ms, 4.0), "{st:?}");

    // 1..=200 ms, reversed: median the 100th, p99 the 198th.
    let v: Vec<f64> = (1..=200).rev().map(|i| f64::from(i) * 1e-3).collect();
    let st = PeriodStats::of(&v);
    assert_eq!(st.count, 200);
    assert!(close(st.mean_ms, 100.5), "{st:?}");
    assert!(close(st.median_ms, 100.0), "{st:?}");
    assert!(close(st.p99_ms, 198.0), "{st:?}");
    assert!(close(st.max_ms, 200.0), "{st:?}");

    // 1..=101 ms: median the 51st, p99 the ceil(99.99) = 100th.
    let v: Vec<f64> = (1..=101).map(|i| f64::from(i) * 1e-3).collect();
    let st = PeriodStats::of(&v);
    assert!(close(st.median_ms, 51.0), "{st:?}");
    assert!(close(st.p99_ms, 100.0), "{st:?}");
    assert!(close(st.max_ms, 101.0), "{st:?}");

    // 1..=160 ms: p99 the ceil(158.4) = 159th (rounding would give the 158th).
    let v: Vec<f64> = (1..=160).map(|i| f64::from(i) * 1e-3).collect();
    let st = PeriodStats::of(&v);
    assert!(close(st.median_ms, 80.0), "{st:?}");
    assert!(close(st.p99_ms, 159.0), "{st:?}");

    // One value: all of them; an infinite value is not counted either.
    let st = PeriodStats::of(&[0.0123, f64::INFINITY]);
    assert_eq!(st.count, 1);
    for x in [st.mean_ms, st.median_ms, st.p99_ms, st.max_ms] {
        assert!(close(x, 12.3), "{st:?}");
    }
}

#[test]
fn period_stats_of_nothing_are_the_default() {
    assert_eq!(PeriodStats::of(&[]), PeriodStats::default());
    assert_eq!(
        PeriodStats::of(&[f64::NAN, f64::NAN]),
        PeriodStats::default()
    );
    assert_eq!(PeriodStats::default().count, 0);
}

// ---------------------------------------------------------------------------------------
// PilotConfig::validate
// ---------------------------------------------------------------------------------------

fn hover_config() -> PilotConfig {
    let mut mission = MissionConfig::for_kind(MissionKind::Hover);
    mission.hover_time = 2.0;
    // The vehicle given, so that PX4 is asked for nothing but its hover thrust.
    PilotConfig {
        vehicle: Some(VehicleProfile::design()),
        ..PilotConfig::new(mission)
    }
}

#[test]
fn the_setpoint_rate_must_be_25_to_250_hz() {
    for rate in [10.0, 300.0, 24.9, 250.1, 0.0, -100.0] {
        let cfg = PilotConfig {
            setpoint_rate: rate,
            ..hover_config()
        };
        let e = cfg.validate().unwrap_err();
        assert_eq!(e, PilotError::SetpointRate(rate));
        assert!(e.to_string().contains(&format!("{rate} Hz")), "{e}");
        assert!(Pilot::new(cfg).is_err());
    }
    for rate in [f64::NAN, f64::INFINITY] {
        let cfg = PilotConfig {
            setpoint_rate: rate,
            ..hover_config()
        };
        assert!(
            matches!(cfg.validate(), Err(PilotError::SetpointRate(_))),
            "{rate}"
        );
    }
    for rate in [25.0, 100.0, 250.0] {
        let cfg = PilotConfig {
            setpoint_rate: rate,
            ..hover_config()
        };
        assert_eq!(cfg.validate(), Ok(()), "{rate}");
    }
}

#[test]
fn a_bad_thrust_map_or_rate_limit_is_rejected() {
    for hover in [0.0, 1.5, 1.0, -0.2, f64::NAN] {
        let cfg = PilotConfig {
            thrust_map: Some(ThrustMap {
                hover_thrust: hover,
                g: G,
            }),
            ..hover_config()
        };
        let e = cfg.validate().unwrap_err();
        assert!(
            matches!(e, PilotError::Setpoint(SetpointError::HoverThrust(h)) if h.to_bits() == hover.to_bits()),
            "{hover}: {e:?}"
        );
        assert!(Pilot::new(cfg).is_err());
    }
    let cfg = PilotConfig {
        thrust_map: Some(ThrustMap {
            hover_thrust: 0.4,
            g: G,
        }),
        ..hover_config()
    };
    assert_eq!(cfg.validate(), Ok(()));
    let cfg = PilotConfig {
        limits: RateLimits {
            max: Vector3::new(20.0, 0.0, 6.0),
        },
        ..hover_config()
    };
    assert!(matches!(
        cfg.validate(),
        Err(PilotError::Setpoint(SetpointError::RateLimit { .. }))
    ));
    let mut cfg = hover_config();
    cfg.link.odometry_timeout = 0.0;
    assert!(matches!(cfg.validate(), Err(PilotError::Link(_))));
}
