//! The full SQP with the dynamics' exact Lagrangian Hessian ([`Model::dynamics_hessian`]):
//! the hand-written pendulum's Hessian against finite differences of its Jacobians, the
//! same solution as Gauss-Newton's in fewer iterations, Newton's quadratic convergence
//! against Gauss-Newton's linear one, the fall back to Gauss-Newton where the Hessian
//! makes the QP non-convex, the watchdog's whole Newton steps and its way back where they do
//! not pay, and the KKT exit.

mod support;

use mpc_runtime::{Model, Rti, RtiStatus};
use nalgebra::{SMatrix, SVector};
use support::pendulum::Pendulum;

const N: usize = 20;
type Solver = Rti<f64, Pendulum, 2, 1, 0, 3, 2, 0, 0, N>;

/// Swing-up: from hanging (`theta = 0`) to upright (`pi`) in 2 s with `|u| <= 2` (too weak to
/// lift the pendulum straight up: it must swing).
fn swing_up(hessian_scale: f64, exact: bool) -> Box<Solver> {
    let mut s = Box::new(Solver::new(Pendulum {
        dt: 0.1,
        hessian_scale,
    }));
    let w = SMatrix::<f64, 3, 3>::from_diagonal(&SVector::from([10.0, 1.0, 0.1]));
    let wn = SMatrix::<f64, 2, 2>::from_diagonal(&SVector::from([100.0, 10.0]));
    s.set_weights(&w, &wn).unwrap();
    for k in 0..N {
        s.set_reference(k, &SVector::from([std::f64::consts::PI, 0.0, 0.0]))
            .unwrap();
    }
    s.set_terminal_reference(&SVector::from([std::f64::consts::PI, 0.0]))
        .unwrap();
    s.set_bounds(
        &SVector::repeat(f64::NEG_INFINITY),
        &SVector::repeat(f64::INFINITY),
        &SVector::from([-2.0]),
        &SVector::from([2.0]),
    )
    .unwrap();
    s.settings.sqp_exact_hessian = exact;
    // Converged far below the defaults, to compare the two Hessians' solutions.
    s.settings.sqp_tol = 1e-10;
    s.settings.sqp_kkt_tol = 1e-10;
    s
}

const X0: [f64; 2] = [0.0, 0.0];

/// The speed cap of [`the_kkt_exit_holds_with_active_state_bounds`].
const OMEGA_CAP: f64 = 4.0;

/// The largest difference of two solvers' trajectories (states and controls).
fn distance(a: &Solver, b: &Solver) -> f64 {
    let mut d = (a.state(N).unwrap() - b.state(N).unwrap()).amax();
    for k in 0..N {
        d = d
            .max((a.state(k).unwrap() - b.state(k).unwrap()).amax())
            .max((a.control(k).unwrap() - b.control(k).unwrap()).amax());
    }
    d
}

#[test]
fn the_pendulum_hessian_is_the_derivative_of_its_jacobians() {
    let m = Pendulum {
        dt: 0.1,
        hessian_scale: 1.0,
    };
    let p = SVector::<f64, 0>::zeros();
    // `pi' [A B]` at (x, u): the gradient of `pi' F`, differentiated centrally.
    let grad = |x: &SVector<f64, 2>, u: &SVector<f64, 1>, pi: &SVector<f64, 2>| {
        let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
        let _ = Model::<f64, 2, 1, 0, 3, 2, 0, 0>::dynamics(&m, x, u, &p, &mut a, &mut b);
        let (gx, gu) = (a.transpose() * pi, b.transpose() * pi);
        SVector::<f64, 3>::from([gx[0], gx[1], gu[0]])
    };
    for (th, om, uu, p1, p2) in [
        (0.3, -1.0, 0.7, 2.0, -3.0),
        (2.5, 0.4, -1.5, -0.5, 4.0),
        (-1.2, 2.0, 1.9, 1.0, 1.0),
    ] {
        let (x, u, pi) = (
            SVector::from([th, om]),
            SVector::from([uu]),
            SVector::from([p1, p2]),
        );
        let (mut hxx, mut hux, mut huu) = (SMatrix::zeros(), SMatrix::zeros(), SMatrix::zeros());
        Model::<f64, 2, 1, 0, 3, 2, 0, 0>::dynamics_hessian(
            &m, &x, &u, &p, &pi, &mut hxx, &mut hux, &mut huu,
        );
        let h = 1e-6;
        for j in 0..3 {
            let (mut xp, mut up, mut xm, mut um) = (x, u, x, u);
            if j < 2 {
                xp[j] += h;
                xm[j] -= h;
            } else {
                up[0] += h;
                um[0] -= h;
            }
            let col = (grad(&xp, &up, &pi) - grad(&xm, &um, &pi)) / (2.0 * h);
            let ours = if j < 2 {
                [hxx[(0, j)], hxx[(1, j)], hux[(0, j)]]
            } else {
                [hux[(0, 0)], hux[(0, 1)], huu[(0, 0)]]
            };
            for (i, (&fd, &o)) in col.iter().zip(&ours).enumerate() {
                assert!((fd - o).abs() <= 1e-6, "entry ({i}, {j}): {o} vs {fd}");
            }
        }
    }
}

/// [`swing_up`] solved from [`X0`] (a cold start: 50 iterations with Gauss-Newton's
/// Hessian, 18 with the exact one and its watchdog), then ready for
/// the next state, [`X1`], as in a closed loop.
fn converged(hessian_scale: f64, exact: bool) -> Box<Solver> {
    let mut s = swing_up(hessian_scale, exact);
    s.settings.sqp_max_iter = 300;
    let info = s.solve_sqp(&SVector::from(X0));
    assert_eq!(info.status, RtiStatus::Ok, "{info:?}");
    s
}

/// The next measured state: off the predicted one.
const X1: [f64; 2] = [0.1, -0.1];

#[test]
fn exact_hessian_steps_reach_gauss_newtons_solution_in_fewer_iterations() {
    let (mut gn, mut ex) = (converged(1.0, false), converged(1.0, true));
    // The same local solution from the cold start.
    let d = distance(&gn, &ex);
    assert!(d <= 1e-7, "the two solutions differ by {d}");
    // The swing uses the bounds: the solution is not the unconstrained one.
    let at_bound = (0..N).filter(|&k| ex.control(k).unwrap()[0].abs() >= 2.0 - 1e-9);
    assert!(at_bound.count() >= 2);
    let x1 = SVector::from(X1);
    let gi = gn.solve_sqp(&x1);
    let ei = ex.solve_sqp(&x1);
    assert_eq!(gi.status, RtiStatus::Ok, "{gi:?}");
    assert_eq!(ei.status, RtiStatus::Ok, "{ei:?}");
    let d = distance(&gn, &ex);
    assert!(d <= 1e-7, "the two solutions differ by {d}");
    assert!(
        2 * ei.sqp_iterations <= gi.sqp_iterations,
        "exact {} vs Gauss-Newton {} iterations",
        ei.sqp_iterations,
        gi.sqp_iterations
    );
}

/// Iterations one at a time (`sqp_max_iter = 1`) towards the solution at [`X1`], each one's
/// distance to `reference`, until below `1e-11` or 60 iterations.
fn errors(s: &mut Solver, reference: &Solver) -> Vec<f64> {
    let x1 = SVector::from(X1);
    s.settings.sqp_max_iter = 1;
    let mut e = Vec::new();
    for _ in 0..60 {
        let info = s.solve_sqp(&x1);
        assert_ne!(info.status, RtiStatus::UsedPreviousPlan, "{info:?}");
        e.push(distance(s, reference));
        if e.last().is_some_and(|&v| v < 1e-11) {
            break;
        }
    }
    e
}

#[test]
fn exact_hessian_converges_quadratically_and_gauss_newton_linearly() {
    let mut reference = converged(1.0, true);
    assert_eq!(
        reference.solve_sqp(&SVector::from(X1)).status,
        RtiStatus::Ok
    );
    let ex = errors(&mut converged(1.0, true), &reference);
    let gn = errors(&mut converged(1.0, false), &reference);
    // The sequences the docs quote (`-- --nocapture`).
    let show = |e: &[f64]| {
        e.iter()
            .map(|v| format!("{v:.1e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    eprintln!(
        "distance to the solution per iteration, exact: {}",
        show(&ex)
    );
    eprintln!("Gauss-Newton: {}", show(&gn));
    eprintln!("exact {ex:?}\nGauss-Newton {gn:?}");
    // Iterations from within 1e-2 of the solution to within 1e-10.
    let tail = |e: &[f64]| {
        let start = e.iter().position(|&v| v < 1e-2).unwrap_or(e.len());
        let end = e.iter().position(|&v| v < 1e-10).unwrap_or(e.len());
        end.saturating_sub(start)
    };
    assert!(ex.last().is_some_and(|&v| v < 1e-10), "exact: {ex:?}");
    assert!(tail(&ex) <= 3, "exact: {ex:?}");
    // Quadratic: each of those steps at least squares the error (up to a constant).
    let start = ex.iter().position(|&v| v < 1e-2).unwrap();
    for w in ex[start..].windows(2) {
        assert!(w[1] <= 100.0 * w[0] * w[0] || w[1] < 1e-11, "exact: {ex:?}");
    }
    // Gauss-Newton's linear rate needs more than twice as many.
    assert!(
        tail(&gn) > 2 * tail(&ex),
        "Gauss-Newton: {gn:?}, exact: {ex:?}"
    );
}

#[test]
fn a_hessian_that_makes_the_qp_non_convex_falls_back_to_gauss_newton() {
    let gn = converged(1.0, false);
    // The dynamics' curvature times -1e4: every QP with it has a negative definite block
    // (the fallback is taken at every iteration after the first).
    let bad = converged(-1e4, true);
    let d = distance(&gn, &bad);
    assert!(d <= 1e-7, "the solutions differ by {d}");
}

/// The KKT exit ([`mpc_runtime::RtiSettings::sqp_kkt_tol`], default `1e-6`) stops, where it
/// can, at the iterate after which the step test would need one more QP only to see a step
/// under `sqp_tol` (where the residual is still above its tolerance there, both stop
/// together): a closed loop of six solves from [`X1`] on, with both Hessians, each solve
/// checked against one converged to `1e-10` by the step test alone (an independent
/// certificate: it knows nothing of the KKT residual). The swing keeps controls on their
/// bounds, whose multipliers the natural residual does without.
#[test]
fn the_kkt_exit_saves_the_confirming_qp_and_lands_on_the_same_solution() {
    for exact in [true, false] {
        let start = converged(1.0, exact);
        let mut kkt = start.clone();
        kkt.settings.sqp_tol = 1e-6;
        kkt.settings.sqp_kkt_tol = 1e-6;
        let mut step_only = start.clone();
        step_only.settings.sqp_tol = 1e-6;
        step_only.settings.sqp_kkt_tol = 0.0;
        let mut reference = start;
        reference.settings.sqp_kkt_tol = 0.0;
        let (mut with_kkt, mut without) = (0, 0);
        let mut x = SVector::from(X1);
        for step in 0..6 {
            let (k, s) = kkt_step(
                [&mut kkt, &mut step_only, &mut reference],
                &x,
                &format!("step {step}, exact {exact}"),
            );
            (with_kkt, without) = (with_kkt + k, without + s);
            let at_bound = (0..N).filter(|&j| kkt.control(j).unwrap()[0].abs() >= 2.0 - 1e-6);
            assert!(
                at_bound.count() >= 1,
                "step {step}: no control on its bound"
            );
            // The next state: the prediction, off by a little, as in a closed loop.
            x = kkt.state(1).unwrap() + SVector::from([0.01, -0.01]);
            // Every solver goes on from its own trajectory.
        }
        eprintln!(
            "exact {exact}: {with_kkt} QPs with the KKT exit, {without} with the step test alone"
        );
        // Measured: 24 against 29 with the exact Hessian (at most one saved per solve: its
        // quadratic convergence leaves the KKT residual far below the tolerance one QP
        // before the step is), 36 against 37 with Gauss-Newton's.
        if exact {
            assert!(with_kkt < without, "{with_kkt} vs {without}");
        }
    }
}

/// One closed-loop step of the KKT-exit tests: the solver with the exit, the one with the
/// step test alone and the reference (to 1e-10) each solve from `x`; every solve ends `Ok`,
/// the exit takes no more iterations than the step test, and its solution is within 1e-6 of
/// the reference's. Returns the iterations with the exit and without it.
fn kkt_step(solvers: [&mut Solver; 3], x: &SVector<f64, 2>, at: &str) -> (u32, u32) {
    let [kkt, step_only, reference] = solvers;
    let k = kkt.solve_sqp(x);
    let s = step_only.solve_sqp(x);
    let r = reference.solve_sqp(x);
    for info in [k, s, r] {
        assert_eq!(info.status, RtiStatus::Ok, "{at}: {info:?}");
    }
    assert!(
        k.sqp_iterations <= s.sqp_iterations,
        "{at}: {} iterations with the KKT exit, {} without",
        k.sqp_iterations,
        s.sqp_iterations
    );
    let d = distance(kkt, reference);
    assert!(d <= 1e-6, "{at}: {d} from the reference");
    (k.sqp_iterations, s.sqp_iterations)
}

/// From the cold start, the watchdog (`sqp_watchdog`, default 4) takes Newton's steps whole
/// where the monotone search shortens them: half the iterations (measured 18 against 36),
/// the same solution as Gauss-Newton's.
#[test]
fn the_watchdog_takes_whole_newton_steps_from_a_cold_start() {
    let mut gn = swing_up(1.0, false);
    gn.settings.sqp_max_iter = 300;
    assert_eq!(gn.solve_sqp(&SVector::from(X0)).status, RtiStatus::Ok);
    let mut iterations = Vec::new();
    for watchdog in [4, 0] {
        let mut s = swing_up(1.0, true);
        s.settings.sqp_max_iter = 300;
        s.settings.sqp_watchdog = watchdog;
        let info = s.solve_sqp(&SVector::from(X0));
        assert_eq!(info.status, RtiStatus::Ok, "{info:?}");
        let d = distance(&gn, &s);
        assert!(
            d <= 1e-7,
            "watchdog {watchdog}: {d} from Gauss-Newton's solution"
        );
        iterations.push(info.sqp_iterations);
    }
    // The figures the docs quote (`-- --nocapture`).
    eprintln!(
        "cold start: {} iterations with the watchdog, {} without",
        iterations[0], iterations[1]
    );
    assert!(
        5 * iterations[0] <= 3 * iterations[1],
        "with the watchdog {}, without {}",
        iterations[0],
        iterations[1]
    );
}

/// A Hessian ten times the dynamics' curvature keeps the QPs convex but makes poor steps:
/// the watched ones do not bring the merit below their reference, and the watchdog goes
/// back to it (`RtiInfo::watchdog_returned`) and searches monotonically from there; the
/// solve still ends on Gauss-Newton's solution.
#[test]
fn poor_newton_steps_send_the_watchdog_back_and_the_solve_still_converges() {
    let mut gn = swing_up(1.0, false);
    gn.settings.sqp_max_iter = 300;
    assert_eq!(gn.solve_sqp(&SVector::from(X0)).status, RtiStatus::Ok);
    let mut s = swing_up(10.0, true);
    s.settings.sqp_max_iter = 300;
    let info = s.solve_sqp(&SVector::from(X0));
    assert_eq!(info.status, RtiStatus::Ok, "{info:?}");
    assert!(info.watchdog_returned, "{info:?}");
    let d = distance(&gn, &s);
    assert!(d <= 1e-7, "{d} from Gauss-Newton's solution");
    // With the true curvature the watched steps pay: no way back.
    let mut good = swing_up(1.0, true);
    good.settings.sqp_max_iter = 300;
    let info = good.solve_sqp(&SVector::from(X0));
    assert_eq!(info.status, RtiStatus::Ok, "{info:?}");
    assert!(!info.watchdog_returned, "{info:?}");
}

/// Cut off at every iteration limit up to 62 (at 63 it converges), the poor Hessian's cold start ends with a
/// finite plan from the pinned `x0`, at the watchdog's reference where a watch was open
/// (its last steps not judged) or where it had gone back: both say `watchdog_returned`,
/// which happens from a limit of 49 iterations on (measured).
#[test]
fn solves_cut_off_by_the_iteration_limit_end_on_a_finite_plan() {
    let mut went_back = 0;
    for limit in 1..=62 {
        let mut s = swing_up(10.0, true);
        s.settings.sqp_max_iter = limit;
        let info = s.solve_sqp(&SVector::from(X0));
        assert_eq!(info.status, RtiStatus::MaxIterations, "{limit}: {info:?}");
        went_back += u32::from(info.watchdog_returned);
        assert_eq!(s.state(0).unwrap(), &SVector::from(X0));
        for k in 0..N {
            assert!(s.control(k).unwrap().iter().all(|v| v.is_finite()));
            assert!(s.state(k + 1).unwrap().iter().all(|v| v.is_finite()));
        }
    }
    assert!(went_back > 0, "the watchdog never went back");
}

/// The KKT exit with state bounds that hold at the solution (the swing's speed capped): the
/// natural residual of a state entry at its bound is its distance to it where the gradient
/// pushes against it. Each solve of a closed loop lands within 1e-6 of one converged to
/// 1e-10 by the step test alone, with no more QPs than the step test's.
#[test]
fn the_kkt_exit_holds_with_active_state_bounds() {
    let cap = OMEGA_CAP;
    let capped = |kkt: f64, tol: f64| {
        let mut s = swing_up(1.0, true);
        s.set_bounds(
            &SVector::from([f64::NEG_INFINITY, -cap]),
            &SVector::from([f64::INFINITY, cap]),
            &SVector::from([-2.0]),
            &SVector::from([2.0]),
        )
        .unwrap();
        s.settings.sqp_max_iter = 300;
        s.settings.sqp_kkt_tol = kkt;
        s.settings.sqp_tol = tol;
        s
    };
    let mut kkt = capped(1e-6, 1e-6);
    let mut step_only = capped(0.0, 1e-6);
    let mut reference = capped(0.0, 1e-10);
    let (mut with_kkt, mut without, mut at_cap) = (0, 0, 0);
    let mut x = SVector::from(X0);
    for step in 0..6 {
        let (k, s) = kkt_step(
            [&mut kkt, &mut step_only, &mut reference],
            &x,
            &format!("step {step}"),
        );
        (with_kkt, without) = (with_kkt + k, without + s);
        at_cap += (1..=N)
            .filter(|&j| kkt.state(j).unwrap()[1].abs() >= cap - 1e-6)
            .count();
        x = kkt.state(1).unwrap() + SVector::from([0.01, -0.01]);
    }
    eprintln!(
        "capped speed: {with_kkt} QPs with the KKT exit, {without} without; {at_cap} states at the cap"
    );
    assert!(at_cap > 0, "no state at its bound");
    assert!(with_kkt < without, "{with_kkt} vs {without}");
}
