//! The bicycle's closed loop (`models/bicycle.mpc`, its soft obstacle row) on the warm active
//! set: the same closed loop as with the interior point at tight tolerances, with the
//! interior point in few steps; also with the row made hard, and switched off, at run time.

#[path = "../examples/soft_rows/bicycle_loop.rs"]
mod bicycle_loop;

use bicycle_loop::{Row, run};

/// The warm active set against the interior point (no warm set), both at tight tolerances
/// (1e-12; at 1e-10 the two closed loops were 2e-7 apart, the interior point's error), with the
/// row `row`: the closed loops agree to 1e-7 in every state of every step, the same steps
/// are `Ok` (the hard row cannot be met in one), and the interior point ran in at most
/// `ip_steps` steps with the warm set (the first ones, as the trajectory settles, and where
/// the obstacle comes into the horizon).
fn same_closed_loop(row: Row, ip_steps: usize) {
    let tight = |warm: bool| {
        let mut st = bicycle::default_settings();
        st.qp.warm_active_set = warm;
        st.qp.tol_stat = 1e-12;
        st.qp.tol_eq = 1e-12;
        st.qp.tol_ineq = 1e-12;
        st.qp.tol_comp = 1e-14;
        st
    };
    let warm = run(tight(true), row);
    let ip = run(tight(false), row);
    assert_eq!(warm.not_ok, ip.not_ok, "{row:?}");
    let gap = warm
        .xs
        .iter()
        .zip(&ip.xs)
        .flat_map(|(a, b)| a.iter().zip(b).map(|(p, q)| (p - q).abs()))
        .fold(0.0f64, f64::max);
    let with_ip = warm.iterations.iter().filter(|&&i| i > 0).count();
    eprintln!(
        "{row:?}: closed loops {gap:.2e} apart; interior point in {with_ip} of {} steps \
         with the warm set, {} without",
        warm.iterations.len(),
        ip.iterations.iter().filter(|&&i| i > 0).count()
    );
    assert!(gap <= 1e-7, "{row:?}: {gap:e}");
    assert!(
        with_ip <= ip_steps,
        "{row:?}: interior point in {with_ip} steps"
    );
    // Not a loop that never meets the obstacle: the row was active (the plant passes
    // within 0.05 of the circle) on its way.
    let ([ox, oy], r) = ([6.0, -0.3], 1.0);
    let closest = warm
        .xs
        .iter()
        .map(|x| (x[0] - ox).hypot(x[1] - oy) - r)
        .fold(f64::INFINITY, f64::min);
    assert!(closest < 0.05, "{row:?}: clearance never below {closest}");
}

#[test]
fn the_soft_obstacle_row_on_the_warm_active_set_gives_the_interior_points_closed_loop() {
    same_closed_loop(Row::Soft, 6);
}

#[test]
fn the_obstacle_row_made_hard_on_the_warm_active_set_gives_the_same_closed_loop() {
    same_closed_loop(Row::Hard, 6);
}

#[test]
fn the_bicycle_without_the_obstacle_row_gives_the_same_closed_loop() {
    same_closed_loop(Row::Off, 0);
}
