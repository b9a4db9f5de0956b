//! The flight watch on hand-made states: the landing's ground contact from PX4's land
//! detector or a stalled descent (not from a height that the estimate may have wrong), and
//! each way a vehicle leaves its mission, held for its time and not before.

use firmware_shim::link::Deviation;
use firmware_shim::pilot::State;
use firmware_shim::watch::{Watch, WatchConfig};
use mpc_sim::mission::{Phase, RefPoint};
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

#[test]
fn a_landing_whose_estimate_is_half_a_metre_high_is_down_when_the_descent_stalls() {
    let mut w = airborne();
    // The estimate says 0.5 m, the reference still descends, the vehicle does not.
    let s = state([0.0, 0.0, 0.5], [0.0, 0.0, 0.0], 0.0);
    let r = reference(Phase::Land, [0.0, 0.0, -0.5], [0.0, 0.0, -0.3]);
    let (dev, ground) = hold(&mut w, 1.0, 1.0, Phase::Land, &s, &r, false);
    assert_eq!(dev, None, "no deviation in the landing");
    let t = ground.expect("down");
    assert!((0.49..0.52).contains(&t), "after the stall time: {t}");
    // Still descending at 0.3 m/s: not down, whatever the height says.
    let mut w = airborne();
    let s = state([0.0, 0.0, -0.2], [0.0, 0.0, -0.3], 0.0);
    assert_eq!(hold(&mut w, 1.0, 1.0, Phase::Land, &s, &r, false).1, None);
    // PX4's land detector: down at once.
    let mut w = airborne();
    let s = state([0.0, 0.0, 0.6], [0.0, 0.0, -0.3], 0.0);
    assert_eq!(
        hold(&mut w, 1.0, 0.1, Phase::Land, &s, &r, true).1,
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
