//! The run-time API beyond a control step: validated settings, the escalation of repeated QP
//! failures, per-stage warm starts, weight validation and the read-outs (cost, KKT residual,
//! slacks, multipliers), checked against values computed here by hand.

use mpc_runtime::{Rti, RtiSettings, RtiStatus, SetError};
use nalgebra::{SMatrix, SVector};

mod support;

use support::double_integrator::DoubleIntegrator as Di2;

const N: usize = 15;
type S = Rti<f64, Di2, 2, 1, 0, 3, 2, 1, 0, N>;

const W: [f64; 3] = [10.0, 1.0, 0.1];
const WN: f64 = 10.0;

/// `|a| <= 1`, weights `diag(10, 1, 0.1)` and `10 I`, no shift.
fn solver() -> Box<S> {
    let mut s = Box::new(S::new(Di2 { dt: 0.1 }));
    let w = SMatrix::<f64, 3, 3>::from_diagonal(&SVector::from(W));
    s.set_weights(&w, &(SMatrix::identity() * WN)).unwrap();
    let inf = SVector::repeat(f64::INFINITY);
    s.set_bounds(&-inf, &inf, &SVector::from([-1.0]), &SVector::from([1.0]))
        .unwrap();
    s
}

/// [`solver`] with the soft row `p + v >= 0.5` (L1 50, L2 10).
fn soft_solver() -> Box<S> {
    let mut s = solver();
    s.set_constraint_bounds(
        &SVector::from([0.5]),
        &SVector::from([f64::INFINITY]),
        &SVector::zeros(),
        &SVector::zeros(),
    )
    .unwrap();
    s.set_soft_penalties(
        &SVector::from([50.0]),
        &SVector::from([10.0]),
        &SVector::zeros(),
        &SVector::zeros(),
    )
    .unwrap();
    s
}

fn step(s: &mut S, x: &SVector<f64, 2>) -> (SVector<f64, 1>, mpc_runtime::RtiInfo<f64>) {
    s.prepare();
    s.feedback(x)
}

#[test]
fn set_settings_validates_and_refusals_change_nothing() {
    let mut s = solver();
    let before = s.settings;
    let good = RtiSettings {
        shift: true,
        sqp_max_iter: 7,
        fallback_limit: 3,
        ..RtiSettings::DEFAULT
    };
    let mut cases: Vec<(RtiSettings<f64>, SetError)> = Vec::new();
    let mut bad = good;
    bad.qp.tol_stat = f64::NAN;
    cases.push((bad, SetError::NonFinite));
    let mut bad = good;
    bad.sqp_tol = f64::INFINITY;
    cases.push((bad, SetError::NonFinite));
    let mut bad = good;
    bad.qp.tol_comp = -1e-9;
    cases.push((bad, SetError::InvalidSetting));
    let mut bad = good;
    bad.sqp_kkt_tol = -1.0;
    cases.push((bad, SetError::InvalidSetting));
    let mut bad = good;
    bad.qp.max_iter = 0;
    cases.push((bad, SetError::InvalidSetting));
    let mut bad = good;
    bad.sqp_max_iter = 0;
    cases.push((bad, SetError::InvalidSetting));
    let mut bad = good;
    bad.fallback_limit = 0;
    cases.push((bad, SetError::InvalidSetting));
    let mut bad = good;
    bad.qp.mu0 = 0.0;
    cases.push((bad, SetError::InvalidSetting));
    let mut bad = good;
    bad.qp.reg = -1.0;
    cases.push((bad, SetError::InvalidSetting));
    for (bad, want) in cases {
        assert_eq!(s.set_settings(&bad), Err(want), "{bad:?}");
        assert_eq!(s.settings, before);
    }
    assert_eq!(s.set_settings(&good), Ok(()));
    assert_eq!(s.settings, good);
}

/// Contradictory constraints (`p + v >= 100` with `|a| <= 1`) make every QP infeasible: the
/// status is `UsedPreviousPlan` for failures `1 .. limit - 1` in a row and `PlanExhausted`
/// from failure `limit` on, with the count in the info and the control
/// `plan[min(j, N - 1)]`; the first solved QP resets it.
#[test]
fn repeated_qp_failures_escalate_after_the_limit_and_a_success_resets() {
    for limit in [3, u32::MAX] {
        let mut s = solver();
        s.settings.fallback_limit = limit;
        let x = SVector::from([2.0, 0.0]);
        for _ in 0..3 {
            assert_eq!(step(&mut s, &x).1.status, RtiStatus::Ok);
        }
        let plan: Vec<f64> = (0..N).map(|k| s.control(k).unwrap()[0]).collect();
        s.set_constraint_bounds(
            &SVector::from([100.0]),
            &SVector::from([f64::INFINITY]),
            &SVector::zeros(),
            &SVector::zeros(),
        )
        .unwrap();
        let escalate_at = (limit as usize).min(N);
        for j in 1..=N + 3 {
            let (u, info) = step(&mut s, &x);
            assert_eq!(info.consecutive_failures as usize, j);
            let want = if j >= escalate_at {
                RtiStatus::PlanExhausted
            } else {
                RtiStatus::UsedPreviousPlan
            };
            assert_eq!(info.status, want, "limit {limit}, failure {j}");
            assert_eq!(u[0], plan[j.min(N - 1)], "limit {limit}, failure {j}");
        }
        s.set_constraint_bounds(
            &SVector::from([f64::NEG_INFINITY]),
            &SVector::from([f64::INFINITY]),
            &SVector::zeros(),
            &SVector::zeros(),
        )
        .unwrap();
        let info = step(&mut s, &x).1;
        assert_eq!(info.status, RtiStatus::Ok);
        assert_eq!(info.consecutive_failures, 0);
    }
}

#[test]
fn per_stage_guesses_are_validated_and_warm_start_the_sqp() {
    let x0 = SVector::from([2.0, 0.0]);
    let mut cold = solver();
    let info = cold.solve_sqp(&x0);
    assert_eq!(info.status, RtiStatus::Ok);
    let xs: [SVector<f64, 2>; N] = core::array::from_fn(|k| *cold.state(k).unwrap());
    let us: [SVector<f64, 1>; N] = core::array::from_fn(|k| *cold.control(k).unwrap());
    let xn = *cold.state(N).unwrap();

    let mut warm = solver();
    let mut bad = xs;
    bad[4][1] = f64::NAN;
    assert_eq!(
        warm.set_trajectory_guess(&bad, &xn, &us),
        Err(SetError::NonFinite)
    );
    assert_eq!(*warm.state(4).unwrap(), SVector::<f64, 2>::zeros());
    assert_eq!(
        warm.set_state_guess(N + 1, &xn),
        Err(SetError::StageOutOfRange)
    );
    assert_eq!(
        warm.set_control_guess(N, &us[0]),
        Err(SetError::StageOutOfRange)
    );
    assert_eq!(
        warm.set_control_guess(2, &SVector::from([f64::INFINITY])),
        Err(SetError::NonFinite)
    );
    warm.set_trajectory_guess(&xs, &xn, &us).unwrap();
    for k in 0..N {
        assert_eq!(warm.state(k), Some(&xs[k]));
        assert_eq!(warm.control(k), Some(&us[k]));
    }
    warm.set_state_guess(N, &xn).unwrap();
    warm.set_control_guess(3, &us[3]).unwrap();
    // From the solution, the SQP stops on its first check.
    let info = warm.solve_sqp(&x0);
    assert_eq!(info.status, RtiStatus::Ok);
    assert!(info.sqp_iterations <= 2, "{info:?}");
    assert!(info.sqp_iterations < cold_iterations(), "{info:?}");
}

fn cold_iterations() -> u32 {
    let mut s = solver();
    s.settings.sqp_kkt_tol = 0.0;
    s.solve_sqp(&SVector::from([2.0, 0.0])).sqp_iterations
}

#[test]
fn negative_or_indefinite_weights_are_refused_and_change_nothing() {
    let mut s = solver();
    let (w0, wn0) = (*s.weights().0, *s.weights().1);
    let neg = SMatrix::<f64, 3, 3>::from_diagonal(&SVector::from([1.0, -1e-3, 1.0]));
    assert_eq!(
        s.set_weights(&neg, &SMatrix::identity()),
        Err(SetError::NegativeWeight)
    );
    // Positive diagonal, but `[[1, 2], [2, 1]]` has the eigenvalue -1.
    let mut indef = SMatrix::<f64, 3, 3>::identity();
    indef[(0, 1)] = 2.0;
    indef[(1, 0)] = 2.0;
    assert_eq!(
        s.set_weights(&indef, &SMatrix::identity()),
        Err(SetError::NegativeWeight)
    );
    let mut wn_bad = SMatrix::<f64, 2, 2>::identity();
    wn_bad[(1, 1)] = -5.0;
    assert_eq!(
        s.set_weights(&SMatrix::identity(), &wn_bad),
        Err(SetError::NegativeWeight)
    );
    assert_eq!((*s.weights().0, *s.weights().1), (w0, wn0));
    // Semidefinite (singular) weights are accepted: `[[1, 1], [1, 1]]`, and a zero row.
    let mut semi = SMatrix::<f64, 3, 3>::zeros();
    semi[(0, 0)] = 1.0;
    semi[(0, 1)] = 1.0;
    semi[(1, 0)] = 1.0;
    semi[(1, 1)] = 1.0;
    assert_eq!(s.set_weights(&semi, &SMatrix::identity()), Ok(()));
    assert_eq!(s.weights().0, &semi);
}

/// The cost read-out against the least-squares sum evaluated here from the trajectory.
#[test]
fn cost_is_the_objective_of_the_trajectory() {
    let mut s = soft_solver();
    let x = SVector::from([-1.0, 0.0]);
    for _ in 0..3 {
        assert_eq!(step(&mut s, &x).1.status, RtiStatus::Ok);
    }
    let mut by_hand = 0.0;
    for k in 0..N {
        let (xk, uk) = (s.state(k).unwrap(), s.control(k).unwrap());
        by_hand += 0.5 * (W[0] * xk[0] * xk[0] + W[1] * xk[1] * xk[1] + W[2] * uk[0] * uk[0]);
        let v = (0.5 - xk[0] - xk[1]).max(0.0);
        by_hand += 50.0 * v + 0.5 * 10.0 * v * v;
    }
    let xn = s.state(N).unwrap();
    by_hand += 0.5 * WN * xn.norm_squared();
    assert!(by_hand > 1.0, "the trajectory violates the row: {by_hand}");
    assert!(
        (s.cost() - by_hand).abs() <= 1e-12 * by_hand,
        "{} vs {by_hand}",
        s.cost()
    );
}

/// Soft rows: the QP's slacks are the trajectory's violations, and a violated row's
/// multiplier is its penalty's slope `l1 + l2 v` (the slack's optimality), a satisfied
/// row's zero.
#[test]
fn slacks_and_row_multipliers_match_the_soft_row_optimality() {
    let mut s = soft_solver();
    let (_, info) = step(&mut s, &SVector::from([-1.0, 0.0]));
    assert_eq!(info.status, RtiStatus::Ok);
    let mut violated = 0;
    for k in 0..N {
        let xk = s.state(k).unwrap();
        let v = (0.5 - xk[0] - xk[1]).max(0.0);
        let (sl, su) = s.slacks(k).unwrap();
        assert!((sl[0] - v).abs() <= 1e-5, "stage {k}: slack {sl} vs {v}");
        assert_eq!(su[0], 0.0);
        let lam = s.constraint_multipliers(k).unwrap()[0];
        if v > 1e-4 {
            violated += 1;
            // A lower side: `lam_u - lam_l = -(l1 + l2 v)`.
            assert!((lam + 50.0 + 10.0 * v).abs() <= 1e-3, "stage {k}: {lam}");
        } else if v == 0.0 && xk[0] + xk[1] > 0.6 {
            assert!(lam.abs() <= 1e-3, "stage {k}: {lam}");
        }
    }
    assert!(violated >= 1);
    assert!(s.slacks(N).is_none());
    assert_eq!(
        s.terminal_slacks(),
        (SVector::<f64, 0>::zeros(), SVector::<f64, 0>::zeros())
    );
}

/// Bound multipliers: zero where the control is strictly inside its bounds, of the bound's
/// sign where it sits on one (`a = -1` first, braking from `p = 2`), and the dynamics
/// multipliers make the states' stationarity hold.
#[test]
fn bound_multipliers_have_the_active_sets_signs() {
    let mut s = solver();
    let (_, info) = step(&mut s, &SVector::from([2.0, 0.0]));
    assert_eq!(info.status, RtiStatus::Ok);
    let mut on_lower = 0;
    for k in 0..N {
        let u = s.control(k).unwrap()[0];
        let mu = s.control_bound_multipliers(k).unwrap()[0];
        if u <= -1.0 + 1e-7 {
            on_lower += 1;
            assert!(mu < -1e-3, "stage {k}: u {u}, multiplier {mu}");
        } else if u < 1.0 - 1e-4 && u > -1.0 + 1e-4 {
            assert!(mu.abs() <= 1e-5, "stage {k}: u {u}, multiplier {mu}");
        }
        assert!(s.dynamics_multipliers(k).is_some());
    }
    assert!(on_lower >= 1, "the braking plan saturates");
    // No state bounds: the states' multipliers vanish (stationarity of the QP in `x_k`).
    for k in 1..=N {
        let m = s.state_bound_multipliers(k).unwrap();
        assert!(m.amax() <= 1e-5, "stage {k}: {m}");
    }
    assert!(s.state_bound_multipliers(0).is_none());
    assert!(s.control_bound_multipliers(N).is_none());
    assert!(s.dynamics_multipliers(N).is_none());
}

/// With a soft row, the full SQP stops on its KKT test (not on the step length, set to
/// zero here so it cannot), at a point whose KKT residual is below the tolerance.
#[test]
fn full_sqp_with_soft_rows_stops_at_a_kkt_point() {
    let mut s = soft_solver();
    s.settings.sqp_tol = 0.0;
    s.settings.sqp_kkt_tol = 1e-6;
    s.settings.sqp_max_iter = 30;
    let info = s.solve_sqp(&SVector::from([-1.0, 0.0]));
    assert_eq!(info.status, RtiStatus::Ok, "{info:?}");
    let r = s.kkt_residual().expect("soft rows keep their multipliers");
    assert!(r <= 1e-6, "{r}");
    // The row is violated at the start, so the slacks take part.
    assert!(s.slacks(0).unwrap().0[0] > 0.1);
    // A hard row with a bound: no residual.
    let mut hard = soft_solver();
    hard.set_soft_penalties(
        &SVector::zeros(),
        &SVector::zeros(),
        &SVector::zeros(),
        &SVector::zeros(),
    )
    .unwrap();
    hard.prepare();
    assert_eq!(hard.kkt_residual(), None);
}
