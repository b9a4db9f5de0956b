//! The mission state machine and its references, driven by synthetic vehicle states.

use core::f64::consts::PI;

use mpc_mission::mission::{
    G, Mission, MissionConfig, MissionInput, MissionKind, Phase, attitude_from_thrust, flip_state,
};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

const DT: f64 = 0.001;

/// A vehicle that follows the reference exactly (or with a fixed offset).
fn input(
    m: &Mission,
    t: f64,
    offset: Vector3<f64>,
    pose_valid: bool,
    on_ground: bool,
) -> MissionInput {
    let r = m.reference(t);
    MissionInput {
        t,
        p: r.p + offset,
        v: r.v,
        pose_valid,
        on_ground,
    }
}

/// Runs the mission with a perfectly tracking vehicle until `t_end` or landing; the vehicle
/// touches down when the reference goes below the ground.
fn fly(m: &mut Mission, t_end: f64) -> f64 {
    fly_from(m, 0.0, t_end)
}

/// [`fly`] from time `t0`.
fn fly_from(m: &mut Mission, t0: f64, t_end: f64) -> f64 {
    let mut t = t0;
    while t < t_end && !m.done() {
        step(m, t);
        t += DT;
    }
    t
}

/// Flies (as [`fly`]) until `stop` holds; returns the time.
fn fly_until(m: &mut Mission, stop: impl Fn(&Mission) -> bool) -> f64 {
    let mut t = 0.0;
    while !stop(m) && t < 120.0 {
        step(m, t);
        t += DT;
    }
    t
}

fn step(m: &mut Mission, t: f64) {
    let r = m.reference(t);
    let on_ground = t > 0.5 && r.p.z <= 0.0;
    m.update(&input(m, t, Vector3::zeros(), true, on_ground));
}

#[test]
fn flip_mission_visits_the_papers_phases_in_order() {
    let cfg = MissionConfig::flip();
    let mut m = Mission::new(cfg.clone());
    fly(&mut m, 120.0);
    assert!(m.done(), "the mission did not end: {:?}", m.transitions());
    let phases: Vec<Phase> = m.transitions().iter().map(|t| t.phase).collect();
    assert_eq!(
        phases,
        [
            Phase::Takeoff,
            Phase::Rally,
            Phase::Ascend,
            Phase::Flip,
            Phase::Recover,
            Phase::Hold,
            Phase::ReturnHome,
            Phase::Land,
            Phase::Landed
        ]
    );
    let tr = m.transitions();
    let at = |p: Phase| tr.iter().find(|t| t.phase == p).map(|t| t.t).unwrap();
    // Settled vehicle: each leg ends after its duration plus the settling time.
    let eps = 2.0 * DT;
    assert!((at(Phase::Rally) - (cfg.takeoff_time + cfg.settle_time)).abs() < eps);
    assert!(
        (at(Phase::Ascend) - at(Phase::Rally) - (cfg.rally_time + cfg.settle_time)).abs() < eps
    );
    assert!((at(Phase::Flip) - at(Phase::Ascend) - cfg.ascend_time).abs() < eps);
    // The flip lasts one turn at the reference rate: 2 pi / (5 pi) = 0.4 s.
    assert!((at(Phase::Recover) - at(Phase::Flip) - 0.4).abs() < eps);
    assert!((at(Phase::Hold) - at(Phase::Recover) - cfg.recover_time).abs() < eps);
    assert!((at(Phase::ReturnHome) - at(Phase::Hold) - cfg.hold_time).abs() < eps);
    assert!(tr.iter().all(|t| !t.failsafe));
}

#[test]
fn an_unsettled_vehicle_waits_until_the_timeout() {
    let cfg = MissionConfig::flip();
    let mut m = Mission::new(cfg.clone());
    let off = Vector3::new(0.5, 0.0, 0.0);
    let mut t = 0.0;
    while t < cfg.takeoff_time + cfg.settle_timeout - 0.01 {
        m.update(&input(&m, t, off, true, t < 0.5));
        t += DT;
    }
    assert_eq!(m.phase(), Phase::Takeoff, "left take-off while 0.5 m off");
    while t < cfg.takeoff_time + cfg.settle_timeout + 0.01 {
        m.update(&input(&m, t, off, true, false));
        t += DT;
    }
    assert_eq!(
        m.phase(),
        Phase::Rally,
        "the settling timeout did not move on"
    );
}

#[test]
fn pose_loss_engages_return_mode_after_the_timeout_and_lands_at_home() {
    let cfg = MissionConfig::flip();
    let mut m = Mission::new(cfg.clone());
    fly(&mut m, 5.5); // in the rally leg
    assert_eq!(m.phase(), Phase::Rally);
    // A glitch shorter than the timeout changes nothing.
    let mut t = 5.5;
    let t_glitch = t + cfg.pose_timeout * 0.5;
    while t < t_glitch {
        m.update(&input(&m, t, Vector3::zeros(), false, false));
        t += DT;
    }
    m.update(&input(&m, t, Vector3::zeros(), true, false));
    assert_eq!(m.phase(), Phase::Rally);
    assert!(m.failsafe_since().is_none());
    // A real loss.
    let t_loss = t + DT;
    t = t_loss;
    let mut p_engage = Vector3::zeros();
    while m.failsafe_since().is_none() && t < t_loss + 1.0 {
        p_engage = m.reference(t).p;
        m.update(&input(&m, t, Vector3::zeros(), false, false));
        t += DT;
    }
    let engaged = m.failsafe_since().expect("return mode never engaged");
    assert!(
        engaged - t_loss <= cfg.pose_timeout + 2.0 * DT,
        "{}",
        engaged - t_loss
    );
    assert_eq!(m.phase(), Phase::ReturnHome);
    // Climb first, from where return mode took over: straight up, then home.
    assert!((m.reference(engaged).p - p_engage).norm() < 1e-12);
    let climb = m.reference(engaged + cfg.failsafe_climb_time);
    let want_z = p_engage.z.max(cfg.takeoff_point.z) + cfg.failsafe_climb;
    assert!((climb.p.z - want_z).abs() < 1e-9);
    assert!((climb.p.x - p_engage.x).abs() < 1e-9);
    // Stay lost; the mission still lands, at home.
    let mut t_end = t;
    while !m.done() && t_end < t + 60.0 {
        let r = m.reference(t_end);
        let on_ground = r.p.z <= 0.0;
        m.update(&input(&m, t_end, Vector3::zeros(), false, on_ground));
        t_end += DT;
    }
    assert!(m.done());
    let last = m.reference(t_end);
    assert!((last.p.x - cfg.home.x).abs() < 1e-9 && (last.p.y - cfg.home.y).abs() < 1e-9);
    assert!(
        m.transitions()
            .iter()
            .skip_while(|t| !t.failsafe)
            .all(|t| t.failsafe)
    );
}

#[test]
fn no_failsafe_on_the_ground_before_take_off() {
    let mut m = Mission::new(MissionConfig::flip());
    for i in 0..200 {
        m.update(&input(&m, i as f64 * DT, Vector3::zeros(), false, true));
    }
    assert!(m.failsafe_since().is_none());
    assert_eq!(m.phase(), Phase::Takeoff);
}

#[test]
fn hover_and_step_missions() {
    let mut m = Mission::new(MissionConfig::for_kind(MissionKind::Hover));
    fly(&mut m, 60.0);
    let p: Vec<Phase> = m.transitions().iter().map(|t| t.phase).collect();
    assert_eq!(p, [Phase::Takeoff, Phase::Hold, Phase::Land, Phase::Landed]);
    let cfg = MissionConfig::for_kind(MissionKind::Step);
    let mut m = Mission::new(cfg.clone());
    let t_step = fly_until(&mut m, |m| m.phase() == Phase::Step);
    let r = m.reference(t_step);
    assert!(
        (r.p - (cfg.takeoff_point + cfg.step)).norm() < 1e-12,
        "a step, not a ramp: {}",
        r.p
    );
    fly_from(&mut m, t_step, 60.0);
    let p: Vec<Phase> = m.transitions().iter().map(|t| t.phase).collect();
    assert_eq!(
        p,
        [
            Phase::Takeoff,
            Phase::Hold,
            Phase::Step,
            Phase::Land,
            Phase::Landed
        ]
    );
}

/// The references are smooth where the legs meet: position and velocity continuous
/// everywhere, acceleration continuous except where the flip starts and ends (thrust and
/// rotation switch there by design).
#[test]
fn references_are_continuous_across_phases() {
    let mut m = Mission::new(MissionConfig::flip());
    fly_until(&mut m, |m| m.phase() == Phase::Ascend);
    let t0 = m.phase_start();
    let mut prev = m.reference(t0);
    let mut t = t0;
    while t < t0 + 3.0 {
        t += 1e-4;
        let r = m.reference(t);
        assert!((r.p - prev.p).norm() < 1e-3, "position jumps at {t}");
        assert!((r.v - prev.v).norm() < 2e-2, "velocity jumps at {t}");
        prev = r;
    }
}

/// The flip's closed form against a numerical integration of the same motion: thrust c
/// along the body z axis of the attitude q(t) = Ry(rate t), minus gravity.
#[test]
fn flip_reference_matches_integrated_motion() {
    let p0 = Vector3::new(4.0, 0.0, 2.75);
    let v0 = Vector3::new(0.0, 0.0, 2.5);
    let (rate, c, yaw) = (5.0 * PI, 5.0, 0.3);
    let (mut p, mut v) = (p0, v0);
    let h = 1e-5;
    let n = (0.4 / h) as usize;
    for i in 0..n {
        let acc = |t: f64| {
            let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), rate * t);
            q * Vector3::z() * c - Vector3::z() * G
        };
        let t = i as f64 * h;
        // Midpoint rule on v, trapezoid on p (second order).
        let a0 = acc(t);
        let am = acc(t + 0.5 * h);
        let a1 = acc(t + h);
        let dv = (a0 + 4.0 * am + a1) * (h / 6.0);
        p += v * h + (a0 + 2.0 * am) * (h * h / 6.0);
        v += dv;
    }
    let (pf, vf, af, qf) = flip_state(&p0, &v0, rate, c, yaw, n as f64 * h);
    assert!((pf - p).norm() < 1e-8, "{pf} vs {p}");
    assert!((vf - v).norm() < 1e-8, "{vf} vs {v}");
    // After one full turn the thrust is back along world z.
    assert!((af - Vector3::new(0.0, 0.0, c - G)).norm() < 1e-9);
    // q(0.4) is a full turn: the same attitude as the start (q = -q0).
    let q0 = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    assert!(qf.angle_to(&q0) < 1e-9);
    // d/dt q = 1/2 q (0, w) with w = (0, rate, 0) in the body.
    let tau = 0.123;
    let (_, _, _, qa) = flip_state(&p0, &v0, rate, c, yaw, tau);
    let (_, _, _, qb) = flip_state(&p0, &v0, rate, c, yaw, tau + 1e-6);
    let dq = (qb.into_inner().coords - qa.into_inner().coords) / 1e-6;
    let want = (qa.into_inner() * Quaternion::new(0.0, 0.0, rate, 0.0)).coords * 0.5;
    assert!((dq - want).norm() < 1e-4, "{dq} vs {want}");
}

#[test]
fn attitude_from_thrust_points_body_z_along_the_thrust() {
    for (f, yaw) in [
        (Vector3::new(0.0, 0.0, 9.81), 0.0),
        (Vector3::new(3.0, -1.0, 9.0), 0.7),
        (Vector3::new(-2.0, 4.0, 1.0), -2.0),
    ] {
        let q = attitude_from_thrust(&f, yaw);
        let b3 = q * Vector3::z();
        assert!((b3 - f.normalize()).norm() < 1e-12);
        // Lee's construction: b2 is normal to the heading direction b1c (and to b3), and
        // b1 points along the heading.
        let b1c = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
        assert!((q * Vector3::y()).dot(&b1c).abs() < 1e-12);
        assert!((q * Vector3::x()).dot(&b1c) > 0.0);
    }
}
