//! Failure handling of the RTI solver: non-finite inputs leave no trace, a failing QP returns
//! the previous plan shifted, soft constraints keep an infeasible start solvable, and no step
//! allocates.

mod support;

use support::double_integrator::DoubleIntegrator;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use mpc_runtime::{Model, QpMethod, Rti, RtiStatus, SetError};
use nalgebra::{SMatrix, SVector};

/// Counts allocations made on the thread that armed it (other test threads do not count).
struct Counting;
static ARMED: AtomicBool = AtomicBool::new(false);
static COUNT: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    static MINE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

// SAFETY: forwards every call to `System` unchanged; only counts.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if ARMED.load(Ordering::Relaxed) && MINE.with(|m| m.get()) {
            COUNT.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn count_allocations<R>(f: impl FnOnce() -> R) -> (R, usize) {
    MINE.with(|m| m.set(true));
    COUNT.store(0, Ordering::Relaxed);
    ARMED.store(true, Ordering::Relaxed);
    let r = f();
    ARMED.store(false, Ordering::Relaxed);
    MINE.with(|m| m.set(false));
    (r, COUNT.load(Ordering::Relaxed))
}

/// With storage for condensing and `NBX` state-bound rows; [`di`] sets the method.
type DiRows<const NBX: usize> = Rti<f64, DoubleIntegrator, 2, 1, 0, 3, 2, 1, 0, 15, 15, NBX>;

/// A row for each state.
type Di = DiRows<2>;

/// Both ways of solving the QPs: each test below runs with both.
const METHODS: [QpMethod; 2] = [QpMethod::Riccati, QpMethod::Condensed];

fn di(method: QpMethod) -> Box<Di> {
    di_rows(method)
}

fn di_rows<const NBX: usize>(method: QpMethod) -> Box<DiRows<NBX>> {
    let mut s = Box::new(DiRows::<NBX>::new(DoubleIntegrator { dt: 0.1 }));
    s.settings.qp.method = method;
    let w = SMatrix::<f64, 3, 3>::from_diagonal(&SVector::from([10.0, 1.0, 0.1]));
    s.set_weights(&w, &(SMatrix::identity() * 10.0)).unwrap();
    s.set_bounds(
        &SVector::repeat(f64::NEG_INFINITY),
        &SVector::repeat(f64::INFINITY),
        &SVector::from([-1.0]),
        &SVector::from([1.0]),
    )
    .unwrap();
    s.settings.shift = true;
    s
}

fn step<const NBX: usize>(s: &mut DiRows<NBX>, x: &SVector<f64, 2>) -> SVector<f64, 2> {
    s.prepare();
    let (u, info) = s.feedback(x);
    assert_eq!(info.status, RtiStatus::Ok);
    let mut a = SMatrix::zeros();
    let mut b = SMatrix::zeros();
    <DoubleIntegrator as Model<f64, 2, 1, 0, 3, 2, 1, 0>>::dynamics(
        &s.model,
        x,
        &u,
        &SVector::zeros(),
        &mut a,
        &mut b,
    )
}

#[test]
fn non_finite_inputs_are_rejected_and_leave_no_trace() {
    for method in METHODS {
        non_finite_inputs_with(method);
    }
}

fn non_finite_inputs_with(method: QpMethod) {
    let mut clean = di(method);
    let mut dirty = di(method);
    let mut x = SVector::from([2.0, 0.0]);
    let mut xd = x;
    for k in 0..20 {
        if k == 7 {
            // A bad measurement, a bad reference, bad weights, bad bounds: all refused.
            dirty.prepare();
            let (u, info) = dirty.feedback(&SVector::from([f64::NAN, 0.0]));
            assert_eq!(info.status, RtiStatus::NonFiniteInput);
            assert!(u.iter().all(|v| v.is_finite()));
            assert_eq!(
                dirty.set_reference(3, &SVector::from([f64::INFINITY, 0.0, 0.0])),
                Err(SetError::NonFinite)
            );
            assert_eq!(
                dirty.set_weights(&SMatrix::repeat(f64::NAN), &SMatrix::identity()),
                Err(SetError::NonFinite)
            );
            assert_eq!(
                dirty.set_reference(99, &SVector::zeros()),
                Err(SetError::StageOutOfRange)
            );
            assert_eq!(
                dirty.set_bounds(
                    &SVector::repeat(0.0),
                    &SVector::repeat(-1.0),
                    &SVector::repeat(0.0),
                    &SVector::repeat(1.0)
                ),
                Err(SetError::CrossedBounds)
            );
        }
        x = step(&mut clean, &x);
        xd = step(&mut dirty, &xd);
        assert_eq!(clean.condensed(), method == QpMethod::Condensed);
        assert_eq!(
            x, xd,
            "{method:?} step {k}: the refused inputs changed the closed loop"
        );
    }
}

/// A solver with one state-bound row (`NBX = 1`) refuses bounds on both states and keeps
/// what it had; with a bound on one state its closed loop is that of a solver with a row
/// for each state, bit for bit, and the bound is active.
#[test]
fn state_bounds_beyond_the_rows_are_refused() {
    for method in METHODS {
        let mut one = di_rows::<1>(method);
        let mut both = di_rows::<2>(method);
        let (lbu, ubu) = (SVector::from([-1.0]), SVector::from([1.0]));
        // v >= -0.3 while the double integrator brakes from p = 2 to 0.
        let (lbx, ubx) = (
            SVector::from([f64::NEG_INFINITY, -0.3]),
            SVector::repeat(1e30),
        );
        one.set_bounds(&lbx, &ubx, &lbu, &ubu).unwrap();
        both.set_bounds(&lbx, &ubx, &lbu, &ubu).unwrap();
        assert_eq!(
            one.set_bounds(&SVector::from([-5.0, -0.3]), &ubx, &lbu, &ubu),
            Err(SetError::TooManyStateBounds)
        );
        assert_eq!(
            one.set_bounds(&lbx, &SVector::from([5.0, f64::INFINITY]), &lbu, &ubu),
            Err(SetError::TooManyStateBounds)
        );
        let (mut x1, mut x2) = (SVector::from([2.0, 0.0]), SVector::from([2.0, 0.0]));
        let mut slowest = 0.0f64;
        for k in 0..30 {
            x1 = step(&mut one, &x1);
            x2 = step(&mut both, &x2);
            assert_eq!(x1, x2, "{method:?} step {k}");
            slowest = slowest.min(x1[1]);
        }
        assert!(
            (-0.3 - 1e-6..-0.29).contains(&slowest),
            "{method:?}: the bound v >= -0.3 was not active (v down to {slowest})"
        );
    }
}

#[test]
fn failing_qp_returns_the_previous_plan_shifted() {
    for method in METHODS {
        failing_qp_with(method);
    }
}

/// With `Condensed`, the QPs are condensed until the constraint appears, then solved by the
/// Riccati recursion (a general row cannot be condensed), which finds them infeasible.
fn failing_qp_with(method: QpMethod) {
    let mut s = di(method);
    let mut x = SVector::from([2.0, 0.0]);
    for _ in 0..5 {
        x = step(&mut s, &x);
    }
    s.prepare();
    assert_eq!(s.condensed(), method == QpMethod::Condensed);
    let (_, info) = s.feedback(&x);
    assert_eq!(info.status, RtiStatus::Ok);
    let plan: Vec<f64> = (0..15).map(|k| s.control(k).unwrap()[0]).collect();
    // Now contradictory constraints: p + v >= 100 with |a| <= 1 from here.
    s.set_constraint_bounds(
        &SVector::from([100.0]),
        &SVector::from([f64::INFINITY]),
        &SVector::zeros(),
        &SVector::zeros(),
    )
    .unwrap();
    for (age, planned) in plan.iter().enumerate().take(4).skip(1) {
        s.prepare();
        assert!(!s.condensed());
        let (u, info) = s.feedback(&x);
        assert_eq!(info.status, RtiStatus::UsedPreviousPlan, "{info:?}");
        assert_eq!(
            info.qp.status,
            mpc_runtime::QpStatus::Infeasible,
            "{info:?}"
        );
        assert_eq!(u[0], *planned, "control {age} of the last good plan");
    }
}

/// `di` with the soft constraint `p + v >= 0.5` (L1 penalty 50, L2 penalty 10): never
/// condensed (a general row), though condensing is asked for.
fn di_soft() -> Box<Di> {
    let mut s = di(QpMethod::Condensed);
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

#[test]
fn bad_soft_penalties_are_rejected_and_leave_no_trace() {
    let mut clean = di_soft();
    let mut dirty = di_soft();
    let mut x = SVector::from([-1.0, 0.0]);
    let mut xd = x;
    let (z, z0) = (SVector::<f64, 1>::zeros(), SVector::<f64, 0>::zeros());
    for k in 0..20 {
        if k == 7 {
            let bad = [
                (SVector::from([-1.0]), z, Err(SetError::NegativePenalty)),
                (z, SVector::from([-1e-12]), Err(SetError::NegativePenalty)),
                (SVector::from([f64::NAN]), z, Err(SetError::NonFinite)),
                (z, SVector::from([f64::INFINITY]), Err(SetError::NonFinite)),
                // NaN is reported before a negative value elsewhere.
                (
                    SVector::from([-1.0]),
                    SVector::from([f64::NAN]),
                    Err(SetError::NonFinite),
                ),
            ];
            for (l1, l2, want) in bad {
                assert_eq!(dirty.set_soft_penalties(&l1, &l2, &z0, &z0), want);
            }
        }
        x = step(&mut clean, &x);
        xd = step(&mut dirty, &xd);
        assert_eq!(
            x, xd,
            "step {k}: the refused penalties changed the closed loop"
        );
    }
}

/// The initial state violates `p + v >= 0.5` at stage 0, where no control can help: with the
/// row soft every QP is solved and the closed loop settles on the constraint (`p = 0.5`: the
/// L1 penalty exceeds the multiplier, so the penalty is exact); with the row hard the first
/// QP is infeasible and the solver falls back on its plan.
#[test]
fn soft_constraint_violated_at_start_keeps_the_loop_running() {
    let mut s = di_soft();
    let mut x = SVector::from([-1.0, 0.0]);
    for k in 0..80 {
        s.prepare();
        assert!(!s.condensed());
        let (u, info) = s.feedback(&x);
        assert_eq!(info.status, RtiStatus::Ok, "step {k}: {info:?}");
        let mut a = SMatrix::zeros();
        let mut b = SMatrix::zeros();
        x = <DoubleIntegrator as Model<f64, 2, 1, 0, 3, 2, 1, 0>>::dynamics(
            &s.model,
            &x,
            &u,
            &SVector::zeros(),
            &mut a,
            &mut b,
        );
    }
    assert!(
        (x[0] - 0.5).abs() <= 1e-3 && x[1].abs() <= 1e-3,
        "final state {x}"
    );

    let mut hard = di_soft();
    hard.set_soft_penalties(
        &SVector::zeros(),
        &SVector::zeros(),
        &SVector::zeros(),
        &SVector::zeros(),
    )
    .unwrap();
    hard.prepare();
    let (_, info) = hard.feedback(&SVector::from([-1.0, 0.0]));
    assert_eq!(info.status, RtiStatus::UsedPreviousPlan, "{info:?}");
    assert_eq!(info.qp.status, mpc_runtime::QpStatus::Infeasible);
}

/// The same in `f32`: every QP is solved and the loop settles on the soft constraint.
#[test]
fn soft_constraint_violated_at_start_in_f32() {
    let mut s = Box::new(Rti::<f32, DoubleIntegrator, 2, 1, 0, 3, 2, 1, 0, 15>::new(
        DoubleIntegrator { dt: 0.1 },
    ));
    let w = SMatrix::<f32, 3, 3>::from_diagonal(&SVector::from([10.0, 1.0, 0.1]));
    s.set_weights(&w, &(SMatrix::identity() * 10.0)).unwrap();
    let inf = SVector::repeat(f32::INFINITY);
    s.set_bounds(&-inf, &inf, &SVector::from([-1.0]), &SVector::from([1.0]))
        .unwrap();
    s.set_constraint_bounds(
        &SVector::from([0.5]),
        &SVector::from([f32::INFINITY]),
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
    s.settings.shift = true;
    let mut x = SVector::<f32, 2>::from([-1.0, 0.0]);
    for k in 0..80 {
        s.prepare();
        let (u, info) = s.feedback(&x);
        assert_eq!(info.status, RtiStatus::Ok, "step {k}: {info:?}");
        let mut a = SMatrix::zeros();
        let mut b = SMatrix::zeros();
        x = <DoubleIntegrator as Model<f32, 2, 1, 0, 3, 2, 1, 0>>::dynamics(
            &s.model,
            &x,
            &u,
            &SVector::zeros(),
            &mut a,
            &mut b,
        );
    }
    assert!(
        (x[0] - 0.5).abs() <= 1e-2 && x[1].abs() <= 1e-2,
        "final state {x}"
    );
}

/// The full SQP's merit function carries the soft rows' penalties. From rest at the origin
/// the zero trajectory is dynamically feasible and has zero cost, but violates the soft row
/// `p + v >= 0.5` everywhere: the QP step trades tracking cost for less violation, which a
/// merit of cost and dynamics defects alone would refuse at every step length (the SQP would
/// crawl to its iteration limit). With the penalties, this linear model converges at once.
#[test]
fn full_sqp_merit_includes_the_soft_penalties() {
    let mut s = di_soft();
    let x0 = SVector::from([0.0, 0.0]);
    let info = s.solve_sqp(&x0);
    assert_eq!(info.status, RtiStatus::Ok, "{info:?}");
    assert!(info.sqp_iterations <= 4, "{info:?}");
    // The RTI from the same start reaches the same first control once converged.
    let mut r = di_soft();
    r.settings.shift = false;
    let mut u = SVector::zeros();
    for _ in 0..10 {
        r.prepare();
        u = r.feedback(&x0).0;
    }
    let d = (u - s.control(0).unwrap()).amax();
    assert!(d <= 1e-6, "SQP u0 {} vs RTI {u}", s.control(0).unwrap());
}

#[test]
fn prepare_feedback_and_sqp_do_not_allocate() {
    for method in METHODS {
        let mut s = di(method);
        let x = SVector::from([2.0, 0.0]);
        // Warm up once (nothing in the solver allocates, but the test harness might lazily).
        s.prepare();
        let _ = s.feedback(&x);
        let (_, n) = count_allocations(|| {
            for _ in 0..10 {
                s.prepare();
                let _ = s.feedback(&x);
            }
            s.solve_sqp(&x)
        });
        assert_eq!(s.condensed(), method == QpMethod::Condensed);
        assert_eq!(
            n, 0,
            "allocations during prepare/feedback/solve_sqp ({method:?})"
        );
    }
    // With a soft row violated at the start (slacks active, merit with penalties).
    let mut s = di_soft();
    let x = SVector::from([-1.0, 0.0]);
    s.prepare();
    let _ = s.feedback(&x);
    let (info, n) = count_allocations(|| {
        for _ in 0..10 {
            s.prepare();
            let _ = s.feedback(&x);
        }
        s.solve_sqp(&x)
    });
    assert_eq!(info.status, RtiStatus::Ok, "{info:?}");
    assert_eq!(n, 0, "allocations with soft constraints");
    // The full SQP with the exact Hessian (the pendulum's, written by hand).
    let mut pend = Box::new(Rti::<
        f64,
        support::pendulum::Pendulum,
        2,
        1,
        0,
        3,
        2,
        0,
        0,
        20,
    >::new(support::pendulum::Pendulum {
        dt: 0.1,
        hessian_scale: 1.0,
    }));
    pend.set_weights(&SMatrix::identity(), &SMatrix::identity())
        .unwrap();
    pend.set_bounds(
        &SVector::repeat(f64::NEG_INFINITY),
        &SVector::repeat(f64::INFINITY),
        &SVector::from([-2.0]),
        &SVector::from([2.0]),
    )
    .unwrap();
    let (info, n) = count_allocations(|| pend.solve_sqp(&SVector::from([1.0, 0.0])));
    assert_eq!(info.status, RtiStatus::Ok, "{info:?}");
    assert!(info.sqp_iterations >= 2, "{info:?}");
    assert_eq!(n, 0, "allocations in the exact-Hessian SQP");
    // The counter works: a Vec allocates.
    let (_, n) = count_allocations(|| vec![1u8; 16]);
    assert_eq!(n, 1);
    // And the f32 instantiation, on the quadrotor.
    let mut q = Box::new(Rti::<
        f32,
        support::quadrotor::Quadrotor<f32>,
        10,
        4,
        0,
        14,
        10,
        0,
        0,
        10,
        10,
    >::new(support::quadrotor::Quadrotor { dt: 0.04 }));
    let x0 = SVector::<f32, 10>::from_fn(|i, _| support::quadrotor::X0[i] as f32);
    for method in METHODS {
        q.settings.qp.method = method;
        let (_, n) = count_allocations(|| {
            q.prepare();
            q.feedback(&x0)
        });
        assert_eq!(q.condensed(), method == QpMethod::Condensed);
        assert_eq!(n, 0, "f32 quadrotor, {method:?}");
    }
}
