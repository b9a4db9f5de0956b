//! The Riccati interior-point QP solver against clarabel (an independent general-purpose
//! conic solver, given the same QP in full sparse form), against the closed-form LQR, and on
//! infeasible and non-finite input.

mod support;

use mpc_runtime::{OcpQp, QpSolver, QpStatus};
use nalgebra::{SMatrix, SVector};
use proptest::prelude::*;
use support::{Reference, clarabel_solve, random_qp};

/// Largest difference between our solution and a reference, relative to the solution's size.
fn compare<const NX: usize, const NU: usize>(
    reference: &Reference<NX, NU>,
    us: &[SVector<f64, NU>],
    xs: &[SVector<f64, NX>],
) -> f64 {
    let (ru, rx) = (&reference.u, &reference.x);
    let scale = ru
        .iter()
        .map(|v| v.amax())
        .chain(rx.iter().map(|v| v.amax()))
        .fold(1.0f64, f64::max);
    let du = us
        .iter()
        .zip(ru)
        .map(|(a, b)| (a - b).amax())
        .fold(0.0, f64::max);
    let dx = xs
        .iter()
        .zip(rx)
        .map(|(a, b)| (a - b).amax())
        .fold(0.0, f64::max);
    du.max(dx) / scale
}

macro_rules! against_clarabel {
    ($name:ident, $nx:literal, $nu:literal, $ng:literal, $ngn:literal, $n:literal) => {
        proptest! {
            #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]
            #[test]
            fn $name(seed in any::<u64>()) {
                let qp = random_qp::<$nx, $nu, $ng, $ngn, $n>(seed);
                let reference = clarabel_solve(&qp);
                prop_assume!(reference.is_some(), "clarabel found no reference solution");
                let reference = reference.unwrap();
                // Interior-point solutions (clarabel's as much as ours) sit about mu / lambda off
                // a bound whose multiplier lambda is tiny. Where some constraint has both slack
                // and multiplier below 1e-3 the solution is nearly degenerate and neither solver
                // pins it to 1e-7; such draws are not judged.
                prop_assume!(reference.strict_complementarity > 1e-3, "nearly degenerate solution");
                let mut solver = Box::new(QpSolver::<f64, $nx, $nu, $ng, $ngn, $n>::NEW);
                // Tighter than the defaults: complementarity decides how close weakly active
                // bounds (small multipliers) get to their bounds, about mu / lambda.
                solver.settings.tol_stat = 1e-10;
                solver.settings.tol_comp = 1e-12;
                let info = solver.solve(&qp);
                prop_assert_eq!(info.status, QpStatus::Solved, "{:?}", info);
                let st = solver.settings;
                prop_assert!(info.res_stat <= st.tol_stat && info.res_eq <= st.tol_eq
                    && info.res_ineq <= st.tol_ineq && info.mu <= st.tol_comp, "{:?}", info);
                let sol = solver.solution();
                let xs: Vec<_> = (0..=$n).map(|k| *sol.state(k).unwrap()).collect();
                let err = compare(&reference, &sol.u, &xs);
                prop_assert!(err <= 1e-7, "f64 differs from clarabel by {err:e} (relative)");

            }
        }
    };
}

against_clarabel!(small_n5, 2, 1, 1, 0, 5);
against_clarabel!(medium_n10, 4, 2, 2, 1, 10);
against_clarabel!(qrbench_sized_n20, 10, 4, 0, 0, 20);
against_clarabel!(large_n30, 12, 5, 3, 2, 30);

/// Unconstrained LQ: with the terminal weight equal to the solution of the discrete algebraic
/// Riccati equation, the first control is the infinite-horizon LQR feedback.
#[test]
fn lqr_first_control_matches_dare() {
    const NX: usize = 4;
    const NU: usize = 2;
    const N: usize = 15;
    let mut rng = support::Rng::new(7);
    let a = SMatrix::<f64, NX, NX>::identity() + rng.mat::<NX, NX>(0.2);
    let b: SMatrix<f64, NX, NU> = rng.mat(1.0);
    let q = SMatrix::<f64, NX, NX>::identity() * 2.0;
    let r = SMatrix::<f64, NU, NU>::identity() * 0.5;
    // DARE by fixed-point iteration (independent of the solver): P = Q + A'PA - A'PB (R + B'PB)^-1 B'PA.
    let mut p = q;
    for _ in 0..10_000 {
        let bpb = r + b.transpose() * p * b;
        let k = bpb.try_inverse().unwrap() * b.transpose() * p * a;
        let next = q + a.transpose() * p * a - a.transpose() * p * b * k;
        if (next - p).amax() < 1e-14 * p.amax() {
            p = next;
            break;
        }
        p = next;
    }
    let k_lqr = (r + b.transpose() * p * b).try_inverse().unwrap() * b.transpose() * p * a;
    let mut qp = OcpQp::<f64, NX, NU, 0, 0, N>::NEW;
    qp.x0 = rng.vec(1.0);
    for s in qp.stages.iter_mut() {
        s.q = q;
        s.r = r;
        s.a = a;
        s.b = b;
    }
    qp.terminal.q = p;
    let mut solver = QpSolver::<f64, NX, NU, 0, 0, N>::NEW;
    solver.settings.tol_stat = 1e-10;
    let info = solver.solve(&qp);
    assert_eq!(info.status, QpStatus::Solved);
    let u0 = solver.solution().u[0];
    let want = -k_lqr * qp.x0;
    assert!((u0 - want).amax() <= 1e-9, "u0 {u0} vs LQR {want}");
}

#[test]
fn crossed_bounds_are_infeasible_at_once() {
    let mut qp = random_qp::<4, 2, 1, 0, 8>(3);
    qp.stages[3].lbu[1] = 2.0;
    qp.stages[3].ubu[1] = 1.0;
    let mut solver = QpSolver::<f64, 4, 2, 1, 0, 8>::NEW;
    let info = solver.solve(&qp);
    assert_eq!(info.status, QpStatus::Infeasible);
    assert_eq!(info.iterations, 0);
}

/// Bounds that are each fine but contradict the dynamics: x_1 = x0 + u0 with u0 in [0, 1]
/// and x_1 >= 5 from x0 = 0.
#[test]
fn contradictory_constraints_are_detected_in_bounded_iterations() {
    let mut qp = OcpQp::<f64, 1, 1, 0, 0, 3>::NEW;
    for s in qp.stages.iter_mut() {
        s.a[(0, 0)] = 1.0;
        s.b[(0, 0)] = 1.0;
        s.q[(0, 0)] = 1.0;
        s.r[(0, 0)] = 1.0;
        s.lbu[0] = 0.0;
        s.ubu[0] = 1.0;
    }
    qp.stages[1].lbx[0] = 5.0;
    let mut solver = QpSolver::<f64, 1, 1, 0, 0, 3>::NEW;
    solver.settings.max_iter = 200;
    let info = solver.solve(&qp);
    assert_eq!(info.status, QpStatus::Infeasible, "{info:?}");
    assert!(info.iterations < 200);
}

#[test]
fn non_finite_data_is_rejected() {
    let mut qp = random_qp::<4, 2, 1, 0, 8>(5);
    qp.stages[2].a[(1, 1)] = f64::NAN;
    let mut solver = QpSolver::<f64, 4, 2, 1, 0, 8>::NEW;
    assert_eq!(solver.solve(&qp).status, QpStatus::NonFiniteInput);
    let mut qp = random_qp::<4, 2, 1, 0, 8>(5);
    qp.x0[0] = f64::INFINITY;
    assert_eq!(solver.solve(&qp).status, QpStatus::NonFiniteInput);
    // Infinite bounds are allowed (absent).
    let mut qp = random_qp::<4, 2, 1, 0, 8>(5);
    qp.stages[2].ubu[0] = f64::INFINITY;
    qp.stages[2].lbu[0] = f64::NEG_INFINITY;
    assert_eq!(solver.solve(&qp).status, QpStatus::Solved);
}

/// A dual warm start (multipliers of the previous solve) reaches the same solution as a cold
/// start on a nearby QP, in fewer iterations. Both stop at the default tolerances, which pin
/// the solution to about 1e-6 (weakly active bounds sit mu / lambda off), hence that bound.
#[test]
fn dual_warm_start_gives_the_same_solution_faster() {
    let qp = random_qp::<10, 4, 0, 0, 20>(11);
    let mut warm = Box::new(QpSolver::<f64, 10, 4, 0, 0, 20>::NEW);
    warm.settings.warm_start_dual = true;
    assert_eq!(warm.solve(&qp).status, QpStatus::Solved);
    // The next QP: the same with slightly different gradients, as between control steps.
    let mut next = qp;
    for s in next.stages.iter_mut() {
        s.gx *= 1.01;
        s.gu *= 0.99;
    }
    let w = warm.solve(&next);
    let mut cold = Box::new(QpSolver::<f64, 10, 4, 0, 0, 20>::NEW);
    let c = cold.solve(&next);
    assert_eq!((w.status, c.status), (QpStatus::Solved, QpStatus::Solved));
    assert!(
        w.iterations < c.iterations,
        "warm {} vs cold {}",
        w.iterations,
        c.iterations
    );
    let (ws, cs) = (warm.solution(), cold.solution());
    for k in 0..20 {
        let d = (ws.u[k] - cs.u[k]).amax();
        assert!(
            d <= 1e-6 * cs.u[k].amax().max(1.0),
            "stage {k}: {d:e}; {w:?} {c:?}"
        );
    }
}
