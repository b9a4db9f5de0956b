//! Tests of the quadrotor plant against closed-form references and invariants.

use mpc_sim::plant::{
    Contact, CrashReason, Disturbance, MAX_TOUCHDOWN_VERTICAL_SPEED, Plant, QuadParams, QuadState,
};
use nalgebra::{UnitQuaternion, Vector3};

const DT: f64 = 0.001;

fn no_drag() -> QuadParams {
    QuadParams {
        drag: Vector3::zeros(),
        omega_min: 0.0,
        ..QuadParams::default()
    }
}

fn run(plant: &mut Plant, cmd: [f64; 4], dist: &Disturbance, steps: usize) -> Contact {
    let mut c = plant.contact();
    for _ in 0..steps {
        c = plant.step(&cmd, dist, DT);
    }
    c
}

#[test]
fn default_params_are_an_agile_quad() {
    let p = QuadParams::default();
    assert!((p.thrust_to_weight() - 4.0).abs() < 0.05);
    assert!((p.rotor_thrust_max() - 9.8).abs() < 0.05);
    let hover = p.hover_rotor_speed();
    assert!((4.0 * p.k_thrust * hover * hover - p.mass * p.g).abs() < 1e-9);
}

#[test]
fn free_fall_matches_closed_form_and_conserves_energy() {
    let p = no_drag();
    let (m, g) = (p.mass, p.g);
    let mut plant = Plant::new(p, QuadState::at_rest(Vector3::new(1.0, -2.0, 100.0)));
    let e0 = m * g * 100.0;
    for k in 1..=3000 {
        assert_eq!(
            plant.step(&[0.0; 4], &Disturbance::default(), DT),
            Contact::Airborne
        );
        let t = k as f64 * DT;
        let s = plant.state();
        assert!((s.p.z - (100.0 - 0.5 * g * t * t)).abs() < 1e-6, "t {t}");
        assert!((s.v.z + g * t).abs() < 1e-6);
        assert!((s.p.xy() - nalgebra::Vector2::new(1.0, -2.0)).norm() < 1e-12);
        let e = m * g * s.p.z + 0.5 * m * s.v.norm_squared();
        assert!((e - e0).abs() < 1e-9 * e0, "energy {e} vs {e0}");
    }
    assert!((plant.time() - 3.0).abs() < 1e-9);
}

#[test]
fn torque_free_spin_conserves_momentum_and_energy() {
    let p = QuadParams {
        inertia: Vector3::new(0.006, 0.009, 0.013),
        ..no_drag()
    };
    let j = p.inertia;
    let state = QuadState {
        w: Vector3::new(1.0, 2.0, 3.0),
        q: UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0),
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 1000.0))
    };
    let mut plant = Plant::new(p, state.clone());
    let l = |s: &QuadState| s.q * j.component_mul(&s.w);
    let energy = |s: &QuadState| 0.5 * s.w.dot(&j.component_mul(&s.w));
    let (l0, e0) = (l(&state), energy(&state));
    let mut max_dw: f64 = 0.0;
    for _ in 0..2000 {
        plant.step(&[0.0; 4], &Disturbance::default(), DT);
        let s = plant.state();
        assert!((l(s) - l0).norm() < 1e-6 * l0.norm(), "{}", l(s) - l0);
        assert!((energy(s) - e0).abs() < 1e-6 * e0);
        assert!((s.q.norm() - 1.0).abs() < 1e-12);
        max_dw = max_dw.max((s.w - state.w).norm());
    }
    // The body rates do change (this is not a trivially constant spin).
    assert!(max_dw > 0.5);
}

#[test]
fn rotor_first_order_response_and_saturation() {
    let p = QuadParams::default();
    let tau = p.rotor_tau;
    // On the ground, 1000 rad/s is well below lift-off, so only the rotors move.
    let mut plant = Plant::new(p.clone(), QuadState::at_rest(Vector3::zeros()));
    let c = 1000.0;
    for k in 1..=300 {
        assert_eq!(
            plant.step(&[c; 4], &Disturbance::default(), DT),
            Contact::OnGround
        );
        let t = k as f64 * DT;
        let want = c * (1.0 - (-t / tau).exp());
        for o in plant.state().omega {
            assert!((o - want).abs() < 1e-5 * c, "t {t}: {o} vs {want}");
        }
    }
    // A command far above omega_max saturates.
    let mut plant = Plant::new(p.clone(), QuadState::at_rest(Vector3::new(0.0, 0.0, 100.0)));
    for _ in 0..500 {
        plant.step(&[1e6; 4], &Disturbance::default(), DT);
        for f in plant.rotor_thrusts() {
            assert!(f <= p.rotor_thrust_max() * (1.0 + 1e-12));
        }
    }
    for f in plant.rotor_thrusts() {
        assert!(f > 0.99 * p.rotor_thrust_max());
    }
    assert!((plant.collective_thrust() - 4.0 * p.rotor_thrust_max()).abs() < 0.05);
}

#[test]
fn hover_keeps_the_vehicle_still() {
    let p = QuadParams::default();
    let w_h = (p.mass * p.g / (4.0 * p.k_thrust)).sqrt();
    let p0 = Vector3::new(3.0, 4.0, 10.0);
    let state = QuadState {
        omega: [w_h; 4],
        ..QuadState::at_rest(p0)
    };
    let mut plant = Plant::new(p.clone(), state);
    assert_eq!(
        run(&mut plant, [w_h; 4], &Disturbance::default(), 5000),
        Contact::Airborne
    );
    let s = plant.state();
    assert!((s.p - p0).norm() < 1e-9, "{}", s.p - p0);
    assert!(s.v.norm() < 1e-9 && s.w.norm() < 1e-9);
    let a = plant.specific_acceleration();
    assert!((a - Vector3::new(0.0, 0.0, p.g)).norm() < 1e-9, "{a}");
}

#[test]
fn frame_convention_pitch_and_roll() {
    let p = QuadParams::default();
    let pos = p.rotor_positions();
    let w_h = p.hover_rotor_speed();
    let hover = QuadState {
        omega: [w_h; 4],
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 50.0))
    };
    // Rear rotors (x < 0) faster than the front ones: positive torque about +y.
    let cmd: [f64; 4] = std::array::from_fn(|i| if pos[i].x < 0.0 { 1.1 * w_h } else { 0.9 * w_h });
    let mut plant = Plant::new(p.clone(), hover.clone());
    run(&mut plant, cmd, &Disturbance::default(), 100);
    let s = plant.state();
    assert!(s.w.y > 0.1, "{}", s.w);
    assert!(s.w.x.abs() < 1e-9 && s.w.z.abs() < 1e-9);
    let nose = s.q * Vector3::x();
    assert!(nose.z < -1e-3, "nose {nose}");
    // A pure body torque about +y does the same: R_y(theta) x = (cos, 0, -sin).
    let mut plant = Plant::new(p.clone(), hover.clone());
    let d = Disturbance {
        torque: Vector3::new(0.0, 0.01, 0.0),
        ..Disturbance::default()
    };
    run(&mut plant, [w_h; 4], &d, 200);
    let s = plant.state();
    let theta = 0.5 * 0.01 / p.inertia.y * 0.2 * 0.2;
    let nose = s.q * Vector3::x();
    assert!(
        (nose - Vector3::new(theta.cos(), 0.0, -theta.sin())).norm() < 1e-6,
        "{nose}"
    );
    // Left rotors (y > 0) faster: positive roll, the left side (body +y) goes up.
    let cmd: [f64; 4] = std::array::from_fn(|i| if pos[i].y > 0.0 { 1.1 * w_h } else { 0.9 * w_h });
    let mut plant = Plant::new(p.clone(), hover.clone());
    run(&mut plant, cmd, &Disturbance::default(), 100);
    let s = plant.state();
    assert!(s.w.x > 0.1 && (s.q * Vector3::y()).z > 1e-3);
    // Rotors with spin +1 faster: positive yaw torque.
    let spin = p.rotor_spin();
    let cmd: [f64; 4] = std::array::from_fn(|i| if spin[i] > 0.0 { 1.1 * w_h } else { 0.9 * w_h });
    let mut plant = Plant::new(p.clone(), hover);
    run(&mut plant, cmd, &Disturbance::default(), 100);
    let s = plant.state();
    assert!(s.w.z > 0.01 && s.w.x.abs() < 1e-9 && s.w.y.abs() < 1e-9);
}

#[test]
fn drag_acts_on_air_relative_velocity() {
    let p = QuadParams::default();
    let w_h = p.hover_rotor_speed();
    let state = QuadState {
        omega: [w_h; 4],
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 50.0))
    };
    let mut plant = Plant::new(p.clone(), state);
    let d = Disturbance {
        wind: Vector3::new(5.0, 0.0, 0.0),
        ..Disturbance::default()
    };
    plant.step(&[w_h; 4], &d, DT);
    // Initial acceleration drag_x * wind / m.
    let ax = plant.state().v.x / DT;
    assert!((ax - p.drag.x * 5.0 / p.mass).abs() < 1e-3, "{ax}");
}

#[test]
fn ground_rest_liftoff_touchdown_and_crash() {
    let p = QuadParams::default();
    // Resting with rotors off.
    let mut plant = Plant::new(p.clone(), QuadState::at_rest(Vector3::new(1.0, 1.0, 0.0)));
    assert_eq!(plant.contact(), Contact::OnGround);
    for _ in 0..2000 {
        assert_eq!(
            plant.step(&[0.0; 4], &Disturbance::default(), DT),
            Contact::OnGround
        );
    }
    assert_eq!(plant.state().p, Vector3::new(1.0, 1.0, 0.0));
    // Thrust below the weight: still on the ground.
    let below = 0.95 * p.hover_rotor_speed();
    assert_eq!(
        run(&mut plant, [below; 4], &Disturbance::default(), 1000),
        Contact::OnGround
    );
    assert_eq!(plant.state().p.z, 0.0);
    // Above the weight: lifts off.
    let above = 1.1 * p.hover_rotor_speed();
    assert_eq!(
        run(&mut plant, [above; 4], &Disturbance::default(), 1000),
        Contact::Airborne
    );
    assert!(plant.state().p.z > 0.1);

    // Soft drop from 0.1 m (impact at sqrt(2 g h) = 1.40 m/s).
    let drop = |h: f64| {
        let mut plant = Plant::new(no_drag(), QuadState::at_rest(Vector3::new(0.0, 0.0, h)));
        let mut events = Vec::new();
        for _ in 0..3000 {
            let c = plant.step(&[0.0; 4], &Disturbance::default(), DT);
            if c != Contact::Airborne {
                events.push(c);
            }
        }
        (plant, events)
    };
    let (plant, events) = drop(0.1);
    let v_impact = (2.0 * p.g * 0.1_f64).sqrt();
    assert!(v_impact < MAX_TOUCHDOWN_VERTICAL_SPEED);
    match events[0] {
        Contact::Touchdown {
            vertical_speed,
            horizontal_speed,
            tilt,
        } => {
            assert!((vertical_speed - v_impact).abs() < 0.02, "{vertical_speed}");
            assert!(horizontal_speed < 1e-12 && tilt < 1e-12);
        }
        c => panic!("expected a touchdown, got {c:?}"),
    }
    assert!(events[1..].iter().all(|c| *c == Contact::OnGround));
    assert_eq!(plant.state().p.z, 0.0);
    assert_eq!(plant.state().v, Vector3::zeros());

    // Hard drops: 0.5 m (3.1 m/s) and 5 m (9.9 m/s) crash; the plant then stays frozen.
    for h in [0.5, 5.0] {
        let (mut plant, events) = drop(h);
        let v_impact = (2.0 * p.g * h).sqrt();
        match events[0] {
            Contact::Crash {
                reason: CrashReason::VerticalSpeed,
                vertical_speed,
                ..
            } => assert!((vertical_speed - v_impact).abs() < 0.02),
            c => panic!("expected a crash, got {c:?}"),
        }
        assert!(events.iter().all(|c| *c == events[0]));
        assert_eq!(plant.crashed(), Some(events[0]));
        let frozen = plant.state().clone();
        assert_eq!(
            plant.step(&[2000.0; 4], &Disturbance::default(), DT),
            events[0]
        );
        assert_eq!(*plant.state(), frozen);
    }
}

#[test]
fn tilted_or_sliding_landing_crashes() {
    let tilted = QuadState {
        q: UnitQuaternion::from_euler_angles(0.8, 0.0, 0.0),
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 0.02))
    };
    let mut plant = Plant::new(no_drag(), tilted);
    let c = run(&mut plant, [0.0; 4], &Disturbance::default(), 500);
    assert!(
        matches!(
            c,
            Contact::Crash {
                reason: CrashReason::Tilt,
                ..
            }
        ),
        "{c:?}"
    );

    let sliding = QuadState {
        v: Vector3::new(3.0, 0.0, 0.0),
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 0.02))
    };
    let mut plant = Plant::new(no_drag(), sliding);
    let c = run(&mut plant, [0.0; 4], &Disturbance::default(), 500);
    assert!(
        matches!(
            c,
            Contact::Crash {
                reason: CrashReason::HorizontalSpeed,
                ..
            }
        ),
        "{c:?}"
    );
}

#[test]
fn non_finite_inputs_crash_without_nan_state() {
    let p = QuadParams::default();
    let start = QuadState::hovering(Vector3::new(0.0, 0.0, 10.0), &p);
    let w_h = p.hover_rotor_speed();
    let bad_dists = [
        Disturbance {
            force: Vector3::new(f64::NAN, 0.0, 0.0),
            ..Disturbance::default()
        },
        Disturbance {
            wind: Vector3::new(0.0, f64::INFINITY, 0.0),
            ..Disturbance::default()
        },
        Disturbance {
            torque: Vector3::new(0.0, 0.0, f64::NEG_INFINITY),
            ..Disturbance::default()
        },
        // Finite but overflowing the state.
        Disturbance {
            torque: Vector3::new(1e308, 1e308, 0.0),
            ..Disturbance::default()
        },
    ];
    let mut cases: Vec<([f64; 4], Disturbance, f64)> = vec![
        ([f64::NAN, w_h, w_h, w_h], Disturbance::default(), DT),
        ([w_h; 4], Disturbance::default(), f64::NAN),
    ];
    cases.extend(bad_dists.iter().map(|d| ([w_h; 4], *d, DT)));
    for (cmd, d, dt) in cases {
        let mut plant = Plant::new(p.clone(), start.clone());
        plant.step(&[w_h; 4], &Disturbance::default(), DT);
        let c = plant.step(&cmd, &d, dt);
        assert!(
            matches!(
                c,
                Contact::Crash {
                    reason: CrashReason::NonFinite,
                    ..
                }
            ),
            "{c:?}"
        );
        assert!(plant.state().is_finite());
        assert_eq!(plant.step(&[w_h; 4], &Disturbance::default(), DT), c);
        assert!(plant.state().is_finite());
    }
    // A non-finite state given directly is refused the same way.
    let mut plant = Plant::new(p, start);
    plant.set_state(QuadState::at_rest(Vector3::new(f64::NAN, 0.0, 1.0)));
    assert!(plant.crashed().is_some() && plant.state().is_finite());
}

#[test]
fn the_thrust_lag_of_px4s_sih_is_first_order_in_thrust_up_and_down() {
    use mpc_sim::plant::RotorLag;
    let p = QuadParams::px4_sih();
    assert_eq!(p.rotor_lag, RotorLag::Thrust);
    let (tau, f_max) = (p.rotor_tau, p.rotor_thrust_max());
    // On the ground below lift-off (4 x 2 N < 9.81 N): from rest to 2 N per rotor, then
    // back to 0.4 N; the thrust follows each command exponentially.
    let mut plant = Plant::new(p.clone(), QuadState::at_rest(Vector3::zeros()));
    let speed = |f: f64| (f / p.k_thrust).sqrt();
    let mut f0 = 0.0;
    for (f_cmd, steps) in [(2.0, 200), (0.4, 200)] {
        for k in 1..=steps {
            assert_eq!(
                plant.step(&[speed(f_cmd); 4], &Disturbance::default(), DT),
                Contact::OnGround
            );
            let want = f_cmd + (f0 - f_cmd) * (-(k as f64) * DT / tau).exp();
            for f in plant.rotor_thrusts() {
                assert!((f - want).abs() < 1e-6 * f_max, "{k}: {f} vs {want}");
            }
        }
        f0 = plant.rotor_thrusts()[0];
    }
    // The speed lag (the default) is slower up from rest: 0.4 of the thrust after one
    // time constant instead of 0.63.
    let slow = QuadParams {
        rotor_lag: RotorLag::Speed,
        ..p.clone()
    };
    let mut plant = Plant::new(slow, QuadState::at_rest(Vector3::zeros()));
    run(&mut plant, [speed(2.0); 4], &Disturbance::default(), 50);
    let f = plant.rotor_thrusts()[0];
    assert!(
        (f / 2.0 - (1.0 - (-1.0f64).exp()).powi(2)).abs() < 1e-3,
        "{f}"
    );
}
