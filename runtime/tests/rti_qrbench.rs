//! The RTI solver on QR-bench, closed loop, against acados' closed loop of the same algorithm
//! from the same first guess, and against this crate's own converged full SQP.

mod support;

use mpc_runtime::{QpMethod, RtiStatus};
use nalgebra::SVector;
use support::quadrotor::{NU, NX, X0, plant, qrbench, qrbench_in, qrbench_unconfigured};

/// Rows of an anchor CSV: state (10) and control (4, absent in the last row).
fn anchor(name: &str) -> Vec<(SVector<f64, NX>, Option<SVector<f64, NU>>)> {
    let path = format!("{}/tests/data/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            let num = |i: usize| v[i].parse::<f64>().ok();
            let x = SVector::from_fn(|i, _| num(1 + i).unwrap());
            let u = (0..NU).map(|i| num(11 + i)).collect::<Option<Vec<_>>>();
            (x, u.map(|u| SVector::from_fn(|i, _| u[i])))
        })
        .collect()
}

/// Runs the closed loop and compares it with the anchor row by row. Returns the final state.
/// `NC = N` with `method` `Condensed` solves every QP condensed, `NC = 0` with the Riccati
/// recursion.
fn closed_loop<const N: usize, const NC: usize>(
    dt: f64,
    steps: usize,
    csv: &str,
) -> SVector<f64, NX> {
    let rows = anchor(csv);
    assert_eq!(rows.len(), steps + 1);
    let mut s = qrbench_in::<f64, N, NC>(dt);
    // acados' runs keep the last solution in place between steps: no shift.
    s.settings.shift = false;
    s.settings.qp.method = if NC == N {
        QpMethod::Condensed
    } else {
        QpMethod::Riccati
    };
    let mut x = SVector::from(X0);
    let mut worst = 0.0f64;
    for (k, (ax, au)) in rows.iter().enumerate() {
        let dx = (x - ax).amax();
        worst = worst.max(dx);
        assert!(
            dx <= 1e-4,
            "{csv} step {k}: state differs from acados by {dx:e}\n ours {x}\n acados {ax}"
        );
        let Some(au) = au else { break };
        s.prepare();
        let (u, info) = s.feedback(&x);
        assert_eq!(info.status, RtiStatus::Ok, "step {k}: {info:?}");
        let du = (u - au).amax();
        assert!(
            du <= 1e-4 * 20.0,
            "{csv} step {k}: control {u} vs acados {au}"
        );
        x = plant(&x, &u, dt, 10);
    }
    eprintln!("{csv}: largest state difference from acados {worst:e}");
    x
}

fn position_error(x: &SVector<f64, NX>) -> f64 {
    ((x[0] - 4.0).powi(2) + x[1].powi(2) + (x[2] - 2.0).powi(2)).sqrt()
}

#[test]
fn config_a_matches_acados_closed_loop() {
    let x = closed_loop::<10, 0>(0.04, 100, "acados_qrbench_A.csv");
    assert!(position_error(&x) < 0.05, "final position error {x}");
}

#[test]
fn config_b_matches_acados_closed_loop() {
    let x = closed_loop::<20, 0>(0.05, 80, "acados_qrbench_B.csv");
    assert!(position_error(&x) < 0.05, "final position error {x}");
}

#[test]
fn config_a_condensed_matches_acados_closed_loop() {
    let x = closed_loop::<10, 10>(0.04, 100, "acados_qrbench_A.csv");
    assert!(position_error(&x) < 0.05, "final position error {x}");
}

#[test]
fn config_b_condensed_matches_acados_closed_loop() {
    let x = closed_loop::<20, 20>(0.05, 80, "acados_qrbench_B.csv");
    assert!(position_error(&x) < 0.05, "final position error {x}");
}

/// The real-time iteration (one Gauss-Newton step per control step, trajectory shifted) tracks
/// the full SQP converged from the same state: within 0.1 once the first aggressive second
/// (bang-bang thrust, rates at their bounds) is past, within 1e-2 after 1.4 s. During the first
/// steps it lags by up to the control bounds, as any RTI scheme does on this maneuver.
#[test]
fn rti_tracks_converged_sqp() {
    let dt = 0.04;
    let mut s = qrbench::<10>(dt);
    s.settings.shift = true;
    let mut x = SVector::from(X0);
    for k in 0..100 {
        s.prepare();
        let before = s.clone();
        let (u, info) = s.feedback(&x);
        assert_eq!(info.status, RtiStatus::Ok);
        if k >= 13 {
            let mut full = before;
            // Gauss-Newton converges only linearly here (large residuals, bilinear thrust and
            // attitude: about 0.75 per iteration in the first steps), so allow many iterations.
            full.settings.sqp_max_iter = 400;
            let sqp = full.solve_sqp(&x);
            assert_eq!(sqp.status, RtiStatus::Ok, "step {k}: {sqp:?}");
            let u_sqp = *full.control(0).unwrap();
            let d = (u - u_sqp).amax();
            let bound = if k >= 36 { 1e-2 } else { 1e-1 };
            assert!(
                d <= bound,
                "step {k}: RTI {:?} vs SQP {:?}",
                u.as_slice(),
                u_sqp.as_slice()
            );
        }
        x = plant(&x, &u, dt, 10);
    }
}

/// The full SQP with its QPs solved loosely and polished (`RtiSettings::sqp_loose_qps`, the
/// f64 default) converges to what it converges to with every QP solved to the QP tolerances:
/// QR-bench B's converged-SQP closed loop, by the Riccati recursion (whose polish applies)
/// and by condensing, and in a solver with condensing storage forced to the Riccati
/// recursion, whose polish is refused (it then solves every QP to the tolerances): every
/// step's plan within the SQP's step tolerance (1e-6: both stop once a step is below it, and
/// the interior point's QP solutions at the default tolerances are some 1e-9 off the exact
/// ones the polish gives), the same SQP iteration counts give or take one.
#[test]
fn loosely_solved_polished_qps_give_the_full_sqp_its_iterates() {
    fn fly<const NC: usize>(method: QpMethod) {
        let dt = 0.05;
        let mut loose = qrbench_in::<f64, 20, NC>(dt);
        assert!(loose.settings.sqp_loose_qps, "the f64 default");
        loose.settings.qp.method = method;
        let mut tight = loose.clone();
        tight.settings.sqp_loose_qps = false;
        let mut x = SVector::<f64, NX>::from(X0);
        let mut worst = 0.0f64;
        for k in 0..40 {
            let a = loose.solve_sqp(&x);
            let b = tight.solve_sqp(&x);
            assert_eq!(a.status, b.status, "{method:?} step {k}");
            assert!(a.status == RtiStatus::Ok, "{method:?} step {k}: {a:?}");
            assert!(
                a.sqp_iterations.abs_diff(b.sqp_iterations) <= 1,
                "{method:?} step {k}: {} against {} SQP iterations",
                a.sqp_iterations,
                b.sqp_iterations
            );
            for i in 0..20 {
                let d = (loose.control(i).unwrap() - tight.control(i).unwrap()).amax();
                worst = worst.max(d);
            }
            let u = *loose.control(0).unwrap();
            x = plant(&x, &u, dt, 10);
        }
        assert!(worst <= 1e-6, "{method:?}: plans {worst:e} apart");
        eprintln!("NC = {NC}, {method:?}: plans at most {worst:.1e} apart");
    }
    fly::<0>(QpMethod::Riccati);
    fly::<20>(QpMethod::Condensed);
    fly::<20>(QpMethod::Riccati);
}

/// The same closed loop with the solver in f32 (the microcontroller precision; the plant stays
/// f64): every QP is solved, and the states stay within 1e-3 of the f64 closed loop at every
/// step.
#[test]
fn config_a_in_f32_follows_f64() {
    let dt = 0.04;
    let mut s32 = qrbench_in::<f32, 10, 0>(dt);
    let mut s64 = qrbench::<10>(dt);
    let (mut x32, mut x64) = (SVector::from(X0), SVector::from(X0));
    for k in 0..100 {
        s32.prepare();
        let (u32_, info) = s32.feedback(&x32.cast());
        assert_eq!(info.status, RtiStatus::Ok, "f32 step {k}: {info:?}");
        s64.prepare();
        let (u64_, _) = s64.feedback(&x64);
        x32 = plant(&x32, &u32_.cast(), dt, 10);
        x64 = plant(&x64, &u64_, dt, 10);
        let d = (x32 - x64).amax();
        assert!(
            d <= 1e-3,
            "step {k}: f32 and f64 closed loops differ by {d:e}"
        );
    }
}

/// The Gauss-Newton Hessian and gradient of every stage equal J'WJ and J'W(y - yref) computed
/// here with nalgebra, for a diagonal W (the row-scaling path), a dense symmetric W (the
/// product path), and a non-symmetric W (its symmetric part).
#[test]
fn gauss_newton_terms_match_j_w_j_for_diagonal_and_dense_weights() {
    use mpc_runtime::Model;
    use nalgebra::SMatrix;
    use support::quadrotor::{NY, Quadrotor, U_REF, X_REF};
    let mut s = qrbench::<10>(0.04);
    let x = SVector::<f64, NX>::from([0.3, -0.2, 1.9, 0.9, 0.1, -0.2, 0.3, 0.5, -0.4, 0.2]);
    let u = SVector::<f64, NU>::from([9.0, 0.3, -0.2, 0.1]);
    s.set_guess(&x, &u).unwrap();
    let model = Quadrotor::<f64> { dt: 0.04 };
    let mut w_diag = SMatrix::<f64, NY, NY>::zeros();
    for i in 0..NY {
        w_diag[(i, i)] = 1.0 + i as f64;
    }
    // A dense positive definite weight: diag + a rank-one coupling.
    let v = SVector::<f64, NY>::from_fn(|i, _| 0.1 * (i as f64 - 6.0));
    let w_dense = w_diag + v * v.transpose();
    // A non-symmetric weight: only its symmetric part (here w_dense) enters the cost.
    let skew = SMatrix::<f64, NY, NY>::from_fn(|i, j| 0.05 * (i as f64 - j as f64));
    let wn = SMatrix::<f64, NX, NX>::identity() * 3.0;
    for (given, w) in [
        (w_diag, w_diag),
        (w_dense, w_dense),
        (w_dense + skew, w_dense),
    ] {
        s.set_weights(&given, &wn).unwrap();
        s.prepare();
        let (mut jx, mut ju) = (
            SMatrix::<f64, NY, NX>::zeros(),
            SMatrix::<f64, NY, NU>::zeros(),
        );
        let y = model.residual(&x, &u, &SVector::zeros(), &mut jx, &mut ju);
        let yref =
            SVector::<f64, NY>::from_fn(|i, _| if i < NX { X_REF[i] } else { U_REF[i - NX] });
        let st = &s.qp().stages[3];
        let h = &s.qp().hessians[3];
        let tol = 1e-9 * w.amax() * 100.0;
        assert!((h.q - jx.transpose() * w * jx).amax() < tol);
        assert!((h.s - ju.transpose() * w * jx).amax() < tol);
        assert!((h.r - ju.transpose() * w * ju).amax() < tol);
        assert!((st.gx - jx.transpose() * w * (y - yref)).amax() < tol * 10.0);
        assert!((st.gu - ju.transpose() * w * (y - yref)).amax() < tol * 10.0);
    }
}

/// A model that declares its residual Jacobians constant (`J'WJ` then kept between
/// linearizations) flies the same closed loop bit for bit as the same model without the
/// declaration, through weight changes: every QP has the same Hessians, and after a
/// `set_weights` they are the new weights' `J'WJ`, not the old ones kept (and after a
/// `set_weights` with the same weights, still theirs). So does the model with one Hessian
/// for all stages in its QP (`NH = 1`): that Hessian is every stage's of the others.
#[test]
fn constant_residual_jacobians_keep_j_w_j_until_the_weights_change() {
    use support::quadrotor::{qrbench_constant_jacobians, qrbench_one_hessian};
    let dt = 0.05;
    let (mut a, mut b) = (qrbench::<20>(dt), qrbench_constant_jacobians::<20>(dt));
    let mut c = qrbench_one_hessian::<20>(dt);
    let mut x = SVector::<f64, NX>::from(X0);
    let mut weights = (
        nalgebra::SMatrix::<f64, 14, 14>::zeros(),
        nalgebra::SMatrix::<f64, NX, NX>::zeros(),
    );
    for k in 0..40 {
        if k == 22 {
            // The same weights again (a generated solver sets them whenever a stage-0
            // parameter changes): the cached J'WJ stays valid.
            let (w, wn) = (weights.0, weights.1);
            a.set_weights(&w, &wn).unwrap();
            b.set_weights(&w, &wn).unwrap();
            c.set_weights(&w, &wn).unwrap();
        }
        if k == 15 || k == 30 {
            // Heavier position weights, then a dense coupling (the product path).
            let scale = if k == 15 { 3.0 } else { 0.5 };
            let mut w = nalgebra::SMatrix::<f64, 14, 14>::zeros();
            for i in 0..14 {
                w[(i, i)] = if i < 3 {
                    100.0 * scale
                } else {
                    1.0 + 0.1 * i as f64
                };
            }
            if k == 30 {
                w[(0, 1)] = 5.0;
                w[(1, 0)] = 5.0;
            }
            let wn = nalgebra::SMatrix::<f64, NX, NX>::identity() * (50.0 * scale);
            a.set_weights(&w, &wn).unwrap();
            b.set_weights(&w, &wn).unwrap();
            c.set_weights(&w, &wn).unwrap();
            weights = (w, wn);
        }
        a.prepare();
        b.prepare();
        c.prepare();
        let hc = &c.qp().hessians[0];
        for (ha, hb) in a.qp().hessians.iter().zip(&b.qp().hessians) {
            assert_eq!((ha.q, ha.s, ha.r), (hb.q, hb.s, hb.r), "step {k}");
            assert_eq!((ha.q, ha.s, ha.r), (hc.q, hc.s, hc.r), "step {k}");
        }
        assert_eq!(a.qp().terminal.q, b.qp().terminal.q, "step {k}");
        assert_eq!(a.qp().terminal.q, c.qp().terminal.q, "step {k}");
        let (ua, ia) = a.feedback(&x);
        let (ub, ib) = b.feedback(&x);
        let (uc, ic) = c.feedback(&x);
        assert_eq!(ia.status, RtiStatus::Ok, "step {k}");
        assert_eq!((ua, ia), (ub, ib), "step {k}");
        assert_eq!((ua, ia), (uc, ic), "step {k}");
        x = plant(&x, &ua, dt, 10);
    }
    assert_eq!(a.qp().hessians[7].q[(0, 1)], 5.0, "the last weights' J'WJ");
}

/// A model whose stage residual Jacobians are constant but whose terminal residual is not
/// (`CONSTANT_STAGE_RESIDUAL_JACOBIANS` without `CONSTANT_RESIDUAL_JACOBIANS`, as the probe
/// model) keeps one stage Hessian (`NH = 1`) and computes the terminal `J'WJ` at every
/// linearization: it flies the closed loop bit for bit as the same model on the general path
/// (`NH = N`, nothing kept), and its terminal Hessian does change from step to step.
#[test]
fn a_nonlinear_terminal_residual_alone_keeps_the_stage_hessian() {
    use support::quadrotor::qrbench_curved_terminal;
    let dt = 0.05;
    let mut a = qrbench_curved_terminal::<20, false, 20>(dt);
    let mut c = qrbench_curved_terminal::<20, true, 1>(dt);
    let mut x = SVector::<f64, NX>::from(X0);
    let mut terminal_changes = 0;
    let mut last_terminal = c.qp().terminal.q;
    for k in 0..40 {
        a.prepare();
        c.prepare();
        for ha in &a.qp().hessians {
            let hc = &c.qp().hessians[0];
            assert_eq!((ha.q, ha.s, ha.r), (hc.q, hc.s, hc.r), "step {k}");
        }
        assert_eq!(a.qp().terminal.q, c.qp().terminal.q, "step {k}");
        if c.qp().terminal.q != last_terminal {
            terminal_changes += 1;
        }
        last_terminal = c.qp().terminal.q;
        let (ua, ia) = a.feedback(&x);
        let (uc, ic) = c.feedback(&x);
        assert_eq!(ia.status, RtiStatus::Ok, "step {k}");
        assert_eq!((ua, ia), (uc, ic), "step {k}");
        x = plant(&x, &ua, dt, 10);
    }
    assert!(terminal_changes > 30, "{terminal_changes}");
    assert!(position_error(&x) < 0.5, "{x}");
}

/// `Rti::unconfigured` (every field zero, so that a `static` of it is zero-filled memory)
/// configured like `Rti::new` flies the same closed loop bit for bit, with either QP method
/// and in f32; left unconfigured it still returns a finite control (the fallback), never a
/// solved status.
#[test]
fn unconfigured_then_configured_is_new() {
    fn fly<T: mpc_runtime::Real, const NC: usize>() {
        let dt = 0.04;
        let mut a = qrbench_in::<T, 10, NC>(dt);
        let mut b = qrbench_unconfigured::<T, 10, NC>(dt);
        let x0 = SVector::<f64, NX>::from(X0);
        let mut x = x0;
        for k in 0..100 {
            let xt = x.map(T::lit);
            a.prepare();
            b.prepare();
            let (ua, ia) = a.feedback(&xt);
            let (ub, ib) = b.feedback(&xt);
            assert_eq!(ia.status, RtiStatus::Ok, "step {k}");
            assert_eq!((ua, ia), (ub, ib), "step {k}");
            x = plant(&x, &ua.map(|v| v.to_f64()), dt, 10);
        }
        let mut raw = Box::new(support::quadrotor::QrSolver::<T, 10, NC>::unconfigured(
            support::quadrotor::Quadrotor { dt: T::lit(dt) },
        ));
        raw.prepare();
        let (u, info) = raw.feedback(&x0.map(T::lit));
        assert_ne!(info.status, RtiStatus::Ok);
        assert!(u.iter().all(|v| v.finite()), "{u}");
    }
    fly::<f64, 0>();
    fly::<f64, 10>();
    fly::<f32, 10>();
}

/// The warm active set (on by default in the real-time iteration): config A's closed loop
/// (condensed QPs) flies as with every QP solved by the interior point to tight tolerances,
/// within 1e-7 in every state at every step (the active set's solutions are exact), with the
/// trajectory shifted between steps (the stored active set shifted with it) and without;
/// after the first step, which has no active set to start from, at most a few steps need the
/// interior point, and the shifted active set holds more often than the one left in place
/// would. In f32 the same loop stays within 1e-3 of f64.
#[test]
fn the_warm_active_set_flies_the_interior_points_closed_loop() {
    // 89 and 94 steps held here (none needed the interior point); 89 with the shift but not
    // of the stored active set.
    fly_warm::<10, 10>(QpMethod::Condensed, 0.04, 3, [85, 92]);
}

/// The same for config B (N = 20, dt = 0.05), whose QPs the Riccati recursion solves.
#[test]
fn the_warm_active_set_flies_the_interior_points_closed_loop_with_the_riccati_recursion() {
    // 92 steps held here with and without the shift, none needed the interior point.
    fly_warm::<20, 20>(QpMethod::Riccati, 0.05, 3, [88, 88]);
}

/// [`the_warm_active_set_flies_the_interior_points_closed_loop`] for a horizon and a QP
/// method: the interior point in at most `max_interior` of the 99 steps after the first,
/// the set held in at least `least_held` of them (without, with the shift).
fn fly_warm<const N: usize, const NC: usize>(
    method: QpMethod,
    dt: f64,
    max_interior: usize,
    least_held: [usize; 2],
) {
    for shift in [false, true] {
        let mut warm = qrbench_in::<f64, N, NC>(dt);
        let mut ipm = qrbench_in::<f64, N, NC>(dt);
        let mut single = qrbench_in::<f32, N, NC>(dt);
        for s in [&mut warm.settings, &mut ipm.settings] {
            s.shift = shift;
            s.qp.method = method;
        }
        single.settings.shift = shift;
        single.settings.qp.method = method;
        assert!(warm.settings.qp.warm_active_set && single.settings.qp.warm_active_set);
        // The reference: every QP solved by the interior point to tight tolerances (at the
        // real-time iteration's, 1e-6, its controls differ from the exact ones by up to 1e-2
        // on B's flat stretches of the cost).
        ipm.settings.qp.warm_active_set = false;
        ipm.settings.qp.tol_stat = 1e-10;
        ipm.settings.qp.tol_eq = 1e-10;
        ipm.settings.qp.tol_ineq = 1e-10;
        ipm.settings.qp.tol_comp = 1e-12;
        let mut worst = 0.0f64;
        let (mut xw, mut xi, mut xs) = (SVector::from(X0), SVector::from(X0), SVector::from(X0));
        let (mut interior, mut held) = (0, 0);
        for k in 0..100 {
            warm.prepare();
            let (uw, info) = warm.feedback(&xw);
            assert_eq!(info.status, RtiStatus::Ok, "step {k}: {info:?}");
            assert_eq!(warm.condensed(), method == QpMethod::Condensed);
            if k > 0 {
                assert!(info.qp.active_set_solves >= 1, "step {k}: {info:?}");
                interior += usize::from(info.qp.iterations > 0);
                held += usize::from(info.qp.iterations == 0 && info.qp.active_set_solves == 1);
            }
            ipm.prepare();
            let (ui, info) = ipm.feedback(&xi);
            assert_eq!((info.status, info.qp.active_set_solves), (RtiStatus::Ok, 0));
            single.prepare();
            let (us, info) = single.feedback(&xs.cast());
            assert_eq!(info.status, RtiStatus::Ok, "f32 step {k}: {info:?}");
            xw = plant(&xw, &uw, dt, 10);
            xi = plant(&xi, &ui, dt, 10);
            xs = plant(&xs, &us.cast(), dt, 10);
            let d = (xw - xi).amax();
            worst = worst.max(d);
            assert!(
                d <= 1e-7,
                "shift {shift}, step {k}: {d:e} from the interior point's"
            );
            let d = (xs - xw).amax();
            assert!(d <= 1e-3, "shift {shift}, step {k}: f32 {d:e} from f64");
        }
        eprintln!(
            "{method:?}, shift {shift}: interior point in {interior} of 99 steps, held in {held}, \
             {worst:.1e} from the interior point's"
        );
        assert!(
            interior <= max_interior,
            "shift {shift}: interior point in {interior} steps"
        );
        let least = least_held[usize::from(shift)];
        assert!(
            held >= least,
            "shift {shift}: the active set held in {held} steps"
        );
    }
}
