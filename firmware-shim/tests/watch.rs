//! The flight watch on hand-made states: the landing's ground contact from PX4's land
//! detector or a stalled descent (not from a height that the estimate may have wrong), and
//! each way a vehicle leaves its mission, held for its time and not before.

use firmware_shim::link::Deviation;
use firmware_shim::pilot::State;
use firmware_shim::watch::{Watch, WatchConfig};
use mpc_mission::mission::{Phase, RefPoint};
use nalgebra::{UnitQuaternion, Vector3};

fn state(p: [f64; 3], v: [f64; 3], pitch: f64) -> State {
    State {
        t: 0.0,
        p: Vector3::from(p),
        v: Vector3::from(v),
        q: UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch),
        w: Vector3::zeros(),
    }
}

fn reference(phase: Phase, p: [f64; 3], v: [f64; 3]) -> RefPoint {
    RefPoint {
        phase,
        p: Vector3::from(p),
        v: Vector3::from(v),
        a: Vector3::zeros(),
        yaw: 0.0,
        attitude: None,
        rate: Vector3::zeros(),
        thrust: None,
    }
}

/// Feeds `watch` the same situation at 100 Hz from `t0` for `seconds`; the first time a
/// deviation or the ground is seen.
fn hold(
    watch: &mut Watch,
    t0: f64,
    seconds: f64,
    phase: Phase,
    s: &State,
    r: &RefPoint,
    px4_on_ground: bool,
) -> (Option<(f64, Deviation)>, Option<f64>) {
    let (mut dev, mut ground) = (None, None);
    for i in 0..(seconds * 100.0) as usize {
        let t = t0 + i as f64 * 0.01;
        let seen = watch.observe(t, phase, s, r, s.p.z, px4_on_ground);
        if let Some(d) = seen.deviation {
            dev.get_or_insert((t - t0, d));
        }
        if seen.on_ground {
            ground.get_or_insert(t - t0);
        }
    }
    (dev, ground)
}

fn airborne() -> Watch {
    let mut w = Watch::new(WatchConfig::default());
    let s = state([0.0, 0.0, 2.0], [0.0; 3], 0.0);
    let r = reference(Phase::Hold, [0.0, 0.0, 2.0], [0.0; 3]);
    assert_eq!(
        hold(&mut w, 0.0, 1.0, Phase::Hold, &s, &r, false),
        (None, None)
    );
    w
}

/// A landing at 100 Hz from `t0`: the estimate's height `h(t)` with a vertical speed `vz`
/// (EKF2's, which may be wrong), the reference descending at 0.3 m/s; when the watch first
/// says down.
fn landing(watch: &mut Watch, t0: f64, h: impl Fn(f64) -> f64, vz: f64, px4: bool) -> Option<f64> {
    let r = reference(Phase::Land, [0.0, 0.0, -0.5], [0.0, 0.0, -0.3]);
    (0..200).find_map(|i| {
        let t = i as f64 * 0.01;
        let s = state([0.0, 0.0, h(t)], [0.0, 0.0, vz], 0.0);
        let seen = watch.observe(t0 + t, Phase::Land, &s, &r, h(t), px4);
        assert_eq!(seen.deviation, None, "no deviation in the landing");
        seen.on_ground.then_some(t)
    })
}

#[test]
fn a_landing_is_down_when_the_estimates_height_stops_falling_whatever_its_speed_says() {
    // The estimate says 0.5 m up and 0.27 m/s down (EKF2 on the ground, as seen on SIH) but
    // its height does not fall: down once the 0.5 s window is full, and 0.1 s more.
    let t = landing(&mut airborne(), 1.0, |_| 0.5, -0.27, false).expect("down");
    assert!((0.59..0.62).contains(&t), "{t}");
    // Falling at the reference's 0.3 m/s, or at half of it: still flying, whatever the
    // height says.
    assert_eq!(
        landing(&mut airborne(), 1.0, |t| 0.2 - 0.3 * t, -0.3, false),
        None
    );
    assert_eq!(
        landing(&mut airborne(), 1.0, |t| 1.0 - 0.15 * t, 0.0, false),
        None
    );
    // A stall high up is no touchdown.
    assert_eq!(landing(&mut airborne(), 1.0, |_| 2.0, 0.0, false), None);
    // PX4's land detector: down at once.
    assert_eq!(
        landing(&mut airborne(), 1.0, |t| 0.6 - 0.3 * t, -0.3, true),
        Some(0.0)
    );
}

#[test]
fn far_below_the_reference_for_half_a_second_leaves_the_mission() {
    let s = state([0.0, 0.0, 0.3], [0.0; 3], 0.0);
    let r = reference(Phase::Hold, [0.0, 0.0, 2.0], [0.0; 3]);
    let (dev, _) = hold(&mut airborne(), 1.0, 1.0, Phase::Hold, &s, &r, false);
    let (t, d) = dev.expect("below");
    assert_eq!(d, Deviation::BelowReference);
    assert!((0.49..0.52).contains(&t), "{t}");
    // 1.7 m below is allowed around the flip (2.5 m), not in the hold (1.5 m).
    let r = reference(Phase::Recover, [0.0, 0.0, 2.0], [0.0; 3]);
    assert_eq!(
        hold(&mut airborne(), 1.0, 1.0, Phase::Recover, &s, &r, false).0,
        None
    );
}

#[test]
fn inverted_outside_the_flip_and_down_before_the_landing_leave_the_mission() {
    let up = [0.0, 0.0, 2.0];
    let r = reference(Phase::Hold, up, [0.0; 3]);
    let inverted = state(up, [0.0; 3], 170f64.to_radians());
    let (t, d) = hold(&mut airborne(), 1.0, 1.0, Phase::Hold, &inverted, &r, false)
        .0
        .expect("inverted");
    assert_eq!(d, Deviation::Inverted);
    assert!((0.24..0.27).contains(&t), "{t}");
    // In the flip, upside down is the point.
    let rf = reference(Phase::Flip, up, [0.0; 3]);
    assert_eq!(
        hold(
            &mut airborne(),
            1.0,
            1.0,
            Phase::Flip,
            &inverted,
            &rf,
            false
        )
        .0,
        None
    );
    // PX4's land detector in the hold, after take-off: down.
    let s = state(up, [0.0; 3], 0.0);
    let (t, d) = hold(&mut airborne(), 1.0, 0.1, Phase::Hold, &s, &r, true)
        .0
        .expect("down");
    assert_eq!((t, d), (0.0, Deviation::OnGround));
    // Before take-off PX4 says landed: that is no deviation.
    let mut w = Watch::new(WatchConfig::default());
    let s = state([0.0; 3], [0.0; 3], 0.0);
    let rt = reference(Phase::Takeoff, [0.0; 3], [0.0; 3]);
    assert_eq!(
        hold(&mut w, 0.0, 1.0, Phase::Takeoff, &s, &rt, true).0,
        None
    );
}

#[test]
fn three_metres_off_course_for_a_second_leaves_the_mission() {
    let s = state([3.5, 0.0, 2.0], [0.0; 3], 0.0);
    let r = reference(Phase::Rally, [0.0, 0.0, 2.0], [0.0; 3]);
    let (t, d) = hold(&mut airborne(), 1.0, 2.0, Phase::Rally, &s, &r, false)
        .0
        .expect("off");
    assert_eq!(d, Deviation::OffCourse);
    assert!((0.99..1.02).contains(&t), "{t}");
}

#[test]
fn a_landing_whose_reference_is_a_metre_below_the_ground_is_down() {
    // The estimate drifts down on the ground as fast as the reference (EKF2 correcting its
    // height): no stall, but the reference passes 1 m below the start point.
    let mut w = airborne();
    let r = |t: f64| reference(Phase::Land, [0.0, 0.0, 0.3 - 0.3 * t], [0.0, 0.0, -0.3]);
    let down = (0..1000).find_map(|i| {
        let t = f64::from(i) * 0.01;
        let h = 0.5 - 0.3 * t;
        let s = state([0.0, 0.0, h], [0.0, 0.0, -0.3], 0.0);
        w.observe(1.0 + t, Phase::Land, &s, &r(t), h, false)
            .on_ground
            .then_some(t)
    });
    let t = down.expect("down");
    // 0.3 - 0.3 t < -1.0 from t = 4.33 s.
    assert!((4.33..4.35).contains(&t), "{t}");
}

#[test]
fn the_estimate_on_the_ground_between_take_off_and_landing_leaves_the_mission_at_once() {
    // The recovery's reference 3 m up, the estimate 0.1 m over the start point: less than
    // the 2.5 m the flip is allowed below its reference, but on the ground.
    let r = reference(Phase::Recover, [0.0, 0.0, 2.6], [0.0; 3]);
    let down = state([0.0, 0.0, 0.1], [0.0, 0.0, -3.0], 0.0);
    let (t, d) = hold(&mut airborne(), 1.0, 0.1, Phase::Recover, &down, &r, false)
        .0
        .expect("down");
    assert_eq!((t, d), (0.0, Deviation::OnGround));
    // 0.4 m up is flying (if low).
    let low = state([0.0, 0.0, 0.4], [0.0; 3], 0.0);
    assert_eq!(
        hold(&mut airborne(), 1.0, 0.3, Phase::Recover, &low, &r, false).0,
        None
    );
    // In the take-off and the landing the ground is where the vehicle should be.
    let rt = reference(Phase::Takeoff, [0.0, 0.0, 0.5], [0.0; 3]);
    assert_eq!(
        hold(&mut airborne(), 1.0, 1.0, Phase::Takeoff, &down, &rt, false).0,
        None
    );
    let mut w = airborne();
    assert!(landing(&mut w, 1.0, |_| 0.1, 0.0, false).is_some());
}
