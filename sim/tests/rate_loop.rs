//! Tests of the rate loop and mixer.

use mpc_sim::plant::{Disturbance, Plant, QuadParams, QuadState};
use mpc_sim::rate_loop::{RateController, RateGains, allocation_matrix, mix, mix_detailed};
use nalgebra::{Matrix4, Vector3, Vector4};
use rand::{Rng, SeedableRng, rngs::StdRng};
use std::f64::consts::PI;

const FLIP_RATE: f64 = 5.0 * PI;

/// Simulates a pitch-rate step to `rate` at collective `thrust` on the plant `truth` (the
/// controller believes `QuadParams::default()`), plant at 1 kHz, controller at `ctrl_hz`;
/// returns (time, wy) samples.
fn pitch_step_on(
    truth: &QuadParams,
    gains: RateGains,
    rate: f64,
    thrust: f64,
    ctrl_hz: f64,
    t_end: f64,
) -> Vec<(f64, f64)> {
    let nominal = QuadParams::default();
    let mut plant = Plant::new(
        truth.clone(),
        QuadState::hovering(Vector3::new(0.0, 0.0, 50.0), truth),
    );
    let mut rc = RateController::new(&nominal, gains);
    let dt = 0.001;
    let every = (1.0 / (ctrl_hz * dt)).round() as usize;
    let n = (t_end / dt).round() as usize;
    let mut cmd = plant.state().omega;
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        if k % every == 0 {
            let o = rc.update(
                &Vector3::new(0.0, rate, 0.0),
                thrust,
                &plant.state().w,
                dt * every as f64,
            );
            cmd = o.rotor_cmd;
        }
        let c = plant.step(&cmd, &Disturbance::default(), dt);
        assert!(!c.is_crash(), "{c:?}");
        out.push(((k + 1) as f64 * dt, plant.state().w.y));
    }
    out
}

fn pitch_step(gains: RateGains, rate: f64, thrust: f64, ctrl_hz: f64) -> Vec<(f64, f64)> {
    pitch_step_on(&QuadParams::default(), gains, rate, thrust, ctrl_hz, 0.5)
}

/// (time to 90 %, overshoot fraction, max |error| / target after the 90 % time).
fn metrics(tr: &[(f64, f64)], target: f64) -> (f64, f64, f64) {
    let t90 = tr
        .iter()
        .find(|(_, w)| *w >= 0.9 * target)
        .map_or(f64::INFINITY, |x| x.0);
    let peak = tr.iter().map(|x| x.1).fold(f64::NEG_INFINITY, f64::max);
    let after = tr
        .iter()
        .filter(|x| x.0 >= t90)
        .map(|x| ((x.1 - target) / target).abs())
        .fold(0.0, f64::max);
    (t90, peak / target - 1.0, after)
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn allocation_matrix_by_hand() {
    // arm sqrt(2) => rotors at (+-1, +-1); k_torque 0.5.
    let p = QuadParams {
        arm: 2f64.sqrt(),
        k_torque: 0.5,
        ..QuadParams::default()
    };
    // Rotors: front-right (1,-1) spin -1, rear-left (-1,1) -1, front-left (1,1) +1,
    // rear-right (-1,-1) +1. tau_x = sum y f, tau_y = -sum x f, tau_z = sum s k f.
    #[rustfmt::skip]
    let expected = Matrix4::new(
        1.0,  1.0,  1.0,  1.0,
       -1.0,  1.0,  1.0, -1.0,
       -1.0,  1.0, -1.0,  1.0,
       -0.5, -0.5,  0.5,  0.5,
    );
    let a = allocation_matrix(&p);
    assert!((a - expected).abs().max() < 1e-12, "{a}");
}

#[test]
fn mix_unsaturated_is_exact() {
    let p = QuadParams::default();
    let a = allocation_matrix(&p);
    for (t, tau) in [
        (9.81, Vector3::new(0.0, 0.0, 0.0)),
        (9.81, Vector3::new(0.2, -0.3, 0.05)),
        (15.0, Vector3::new(-0.5, 0.4, -0.1)),
    ] {
        let (f, sat) = mix(&p, t, &tau);
        assert!(!sat);
        let got = a * Vector4::from(f);
        let want = Vector4::new(t, tau.x, tau.y, tau.z);
        assert!((got - want).abs().max() < 1e-9, "{got} vs {want}");
    }
}

#[test]
fn mix_huge_yaw_keeps_roll_pitch_and_thrust() {
    let p = QuadParams::default();
    let a = allocation_matrix(&p);
    let tau = Vector3::new(0.3, -0.2, 50.0);
    let r = mix_detailed(&p, 9.81, &tau);
    assert!(r.yaw_saturated && !r.roll_pitch_saturated && !r.thrust_saturated);
    let got = a * Vector4::from(r.thrusts);
    assert!(close(got[0], 9.81, 1e-9));
    assert!(close(got[1], 0.3, 1e-9));
    assert!(close(got[2], -0.2, 1e-9));
    assert!(got[3] > 0.0 && got[3] < 50.0);
    // Yaw is pushed to the limit: some rotor sits on a bound.
    let fmax = p.rotor_thrust_max();
    assert!(
        r.thrusts
            .iter()
            .any(|f| close(*f, 0.0, 1e-9) || close(*f, fmax, 1e-9))
    );
}

#[test]
fn mix_airmode_raises_and_lowers_collective() {
    let p = QuadParams::default();
    let a = allocation_matrix(&p);
    let fmax = p.rotor_thrust_max();
    // Low thrust, large pitch torque: collective must rise, pitch preserved.
    let tau = Vector3::new(0.0, 1.5, 0.0);
    let r = mix_detailed(&p, 0.5, &tau);
    assert!(r.thrust_saturated && !r.roll_pitch_saturated);
    let got = a * Vector4::from(r.thrusts);
    assert!(close(got[2], 1.5, 1e-9) && close(got[1], 0.0, 1e-9));
    assert!(got[0] > 0.5);
    // Pitch 1.5 N m needs a front/rear difference of 1.5 / (2 * 0.1202) per rotor = 6.24 N:
    // the front rotors sit at 0, so T = 2 * 6.24.
    let lever = p.arm / 2f64.sqrt();
    assert!(close(got[0], 2.0 * 1.5 / (2.0 * lever), 1e-9));
    // Near-max thrust with a roll torque: collective must drop, roll preserved.
    let tau = Vector3::new(1.0, 0.0, 0.0);
    let r = mix_detailed(&p, 4.0 * fmax, &tau);
    assert!(r.thrust_saturated && !r.roll_pitch_saturated);
    let got = a * Vector4::from(r.thrusts);
    assert!(close(got[1], 1.0, 1e-9) && got[0] < 4.0 * fmax);
    // Roll/pitch alone too large: scaled down, keeping the direction.
    let tau = Vector3::new(4.0, 4.0, 0.0);
    let r = mix_detailed(&p, 9.81, &tau);
    assert!(r.roll_pitch_saturated);
    let got = a * Vector4::from(r.thrusts);
    assert!(close(got[1], got[2], 1e-9) && got[1] < 4.0 && got[1] > 0.5);
}

#[test]
fn mix_always_within_bounds_random() {
    let p = QuadParams {
        omega_min: 300.0,
        ..QuadParams::default()
    };
    let (fmin, fmax) = (p.rotor_thrust_min(), p.rotor_thrust_max());
    let a = allocation_matrix(&p);
    let mut rng = StdRng::seed_from_u64(7);
    for _ in 0..20_000 {
        let t = rng.random_range(-10.0..60.0);
        let tau = Vector3::new(
            rng.random_range(-4.0..4.0),
            rng.random_range(-4.0..4.0),
            rng.random_range(-1.0..1.0),
        );
        let r = mix_detailed(&p, t, &tau);
        for f in r.thrusts {
            assert!(f >= fmin - 1e-12 && f <= fmax + 1e-12, "{f}");
        }
        let got = a * Vector4::from(r.thrusts);
        if !r.roll_pitch_saturated {
            assert!(close(got[1], tau.x, 1e-8) && close(got[2], tau.y, 1e-8));
        } else {
            // Direction of the roll/pitch torque kept, magnitude reduced.
            let (gx, gy) = (got[1], got[2]);
            assert!((gx * tau.y - gy * tau.x).abs() < 1e-8 * (1.0 + tau.norm()));
            assert!(gx.hypot(gy) <= tau.xy().norm() + 1e-9);
        }
        if !r.thrust_saturated {
            assert!(close(got[0], t, 1e-8));
        }
        if !r.yaw_saturated {
            assert!(close(got[3], tau.z, 1e-8));
        } else {
            assert!(got[3].abs() <= tau.z.abs() + 1e-9 && got[3] * tau.z >= -1e-12);
        }
    }
    // Non-finite demand: no panic, bounded output.
    let (f, sat) = mix(&p, f64::NAN, &Vector3::new(f64::INFINITY, 0.0, 0.0));
    assert!(sat && f.iter().all(|x| x.is_finite()));
}

#[test]
fn flip_rate_step_at_1khz() {
    for thrust in [9.81, 0.3 * 9.81] {
        let tr = pitch_step(RateGains::default(), FLIP_RATE, thrust, 1000.0);
        let (t90, overshoot, after) = metrics(&tr, FLIP_RATE);
        assert!(t90 <= 0.15, "thrust {thrust}: t90 {t90}");
        assert!(after <= 0.15, "thrust {thrust}: deviation {after}");
        assert!(overshoot <= 0.10, "thrust {thrust}: overshoot {overshoot}");
        // Settled at the end.
        let last = tr.last().unwrap().1;
        assert!(close(last, FLIP_RATE, 0.02 * FLIP_RATE), "{last}");
    }
}

#[test]
fn flip_rate_step_at_250hz() {
    let tr = pitch_step(RateGains::default(), FLIP_RATE, 0.3 * 9.81, 250.0);
    let (t90, _, after) = metrics(&tr, FLIP_RATE);
    assert!(t90 <= 0.15 && after <= 0.15, "t90 {t90} dev {after}");
}

#[test]
fn flip_rate_step_on_mismatched_plant() {
    let truth = QuadParams {
        inertia: QuadParams::default().inertia * 1.3,
        rotor_tau: 0.04,
        mass: 1.2,
        ..QuadParams::default()
    };
    let tr = pitch_step_on(
        &truth,
        RateGains::default(),
        FLIP_RATE,
        0.3 * 9.81,
        1000.0,
        0.5,
    );
    let (t90, _, after) = metrics(&tr, FLIP_RATE);
    assert!(t90 <= 0.2 && after <= 0.2, "t90 {t90} dev {after}");
}

#[test]
fn hover_rejects_constant_disturbance_torque() {
    let p = QuadParams::default();
    let mut plant = Plant::new(
        p.clone(),
        QuadState::hovering(Vector3::new(0.0, 0.0, 50.0), &p),
    );
    let mut rc = RateController::new(&p, RateGains::default());
    let dist = Disturbance {
        torque: Vector3::new(0.05, -0.04, 0.01),
        ..Disturbance::default()
    };
    let dt = 0.001;
    for _ in 0..5000 {
        let o = rc.update(&Vector3::zeros(), p.hover_thrust(), &plant.state().w, dt);
        assert!(!o.saturated);
        assert!(!plant.step(&o.rotor_cmd, &dist, dt).is_crash());
    }
    let w = plant.state().w;
    assert!(w.norm() < 1e-3, "{w}");
    // The integrator holds the disturbance: I . J = -torque.
    let held = rc.integral().component_mul(&p.inertia);
    assert!((held + dist.torque).norm() < 2e-3, "{held}");
    // Without the integrator, a steady-state rate error remains.
    let mut rc = RateController::new(
        &p,
        RateGains {
            ki: Vector3::zeros(),
            ..RateGains::default()
        },
    );
    let mut plant = Plant::new(
        p.clone(),
        QuadState::hovering(Vector3::new(0.0, 0.0, 50.0), &p),
    );
    for _ in 0..3000 {
        let o = rc.update(&Vector3::zeros(), p.hover_thrust(), &plant.state().w, dt);
        plant.step(&o.rotor_cmd, &dist, dt);
    }
    assert!(plant.state().w.norm() > 5e-3);
}

#[test]
fn hover_is_held() {
    let p = QuadParams::default();
    let mut plant = Plant::new(
        p.clone(),
        QuadState::hovering(Vector3::new(1.0, 2.0, 10.0), &p),
    );
    let mut rc = RateController::new(&p, RateGains::default());
    for _ in 0..2000 {
        let o = rc.update(&Vector3::zeros(), p.hover_thrust(), &plant.state().w, 0.001);
        plant.step(&o.rotor_cmd, &Disturbance::default(), 0.001);
    }
    let s = plant.state();
    assert!(
        (s.p - Vector3::new(1.0, 2.0, 10.0)).norm() < 1e-6,
        "{}",
        s.p
    );
    assert!(s.w.norm() < 1e-9);
}

#[test]
fn integrator_is_limited_and_reset() {
    let p = QuadParams::default();
    let g = RateGains::default();
    let mut rc = RateController::new(&p, g.clone());
    for _ in 0..10_000 {
        rc.update(&Vector3::new(1.0, 1.0, 1.0), 9.81, &Vector3::zeros(), 0.001);
    }
    let i = rc.integral();
    for k in 0..3 {
        assert!(i[k].abs() <= g.i_limit[k] + 1e-12);
    }
    rc.reset();
    assert_eq!(rc.integral(), Vector3::zeros());
    // Bad inputs: no panic.
    let o = rc.update(
        &Vector3::new(f64::NAN, 0.0, 0.0),
        9.81,
        &Vector3::zeros(),
        -1.0,
    );
    assert!(o.rotor_cmd.iter().all(|x| x.is_finite()));
}

/// PX4's mixer without airmode (MC_AIRMODE 0) on its SIH quadrotor: a pitch demand beyond
/// the rotors is cut around the collective (the collective is never raised); a demand that
/// fits only with less collective gets less collective and all of its torque.
#[test]
fn without_airmode_the_collective_is_kept_or_lowered_never_raised() {
    use mpc_sim::rate_loop::mix_airmode_disabled;
    let p = QuadParams::px4_sih();
    // 8.64 N (0.432 of the maximum) and -3 N m of pitch: the front rotors would need 5.91 N,
    // the rear ones -1.59 N (rotors 0..3: front-right, rear-left, front-left, rear-right).
    let m = mix_airmode_disabled(&p, 8.64, &Vector3::new(0.0, -3.0, 0.0));
    let want = [4.32, 0.0, 4.32, 0.0];
    for (f, w) in m.thrusts.iter().zip(want) {
        assert!((f - w).abs() < 1e-9, "{:?}", m.thrusts);
    }
    assert!((m.achieved[0] - 8.64).abs() < 1e-9 && (m.achieved[2] + 1.728).abs() < 1e-9);
    assert!(m.roll_pitch_saturated && !m.thrust_saturated && !m.yaw_saturated);
    // This loop's own airmode raises the collective to 10 N for -2 N m.
    let air = mix_detailed(&p, 8.64, &Vector3::new(0.0, -3.0, 0.0));
    assert!((air.achieved[0] - 10.0).abs() < 1e-9 && (air.achieved[2] + 2.0).abs() < 1e-9);
    // 13.94 N and -1.35 N m: the front rotors would need 5.17 N; the collective is lowered
    // by 0.69 N and the pitch torque delivered.
    let m = mix_airmode_disabled(&p, 13.94, &Vector3::new(0.0, -1.35, 0.0));
    assert!((m.achieved[0] - 13.25).abs() < 1e-9, "{:?}", m.achieved);
    assert!((m.achieved[2] + 1.35).abs() < 1e-9, "{:?}", m.achieved);
    assert!(m.thrust_saturated && !m.roll_pitch_saturated);
    // What fits is mixed exactly.
    let m = mix_airmode_disabled(&p, 9.81, &Vector3::new(0.1, -0.2, 0.05));
    assert!(!m.saturated());
    let a = allocation_matrix(&p) * Vector4::from(m.thrusts);
    assert!((a - Vector4::new(9.81, 0.1, -0.2, 0.05)).amax() < 1e-12);
}
