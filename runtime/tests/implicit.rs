//! `mpc_runtime::implicit` on a stiff linear system `x' = M x + N u`, against the exact step
//! `exp([[M, N u], [0, 0]] dt)` (nalgebra's matrix exponential): the state, `A = exp(M dt)`,
//! `B = int_0^dt exp(M s) ds N`, the order of accuracy `2s` of each Gauss-Legendre method, and
//! the same step in `f32`; and a singular Newton system in an RTI: a failed step, no panic.
//! Radau IIA: its order `2s - 1` and its damping of the stiff mode (L-stability).

use mpc_runtime::implicit::{GAUSS_LEGENDRE, Irk, IrkError, RADAU_IIA, Tableau, irk_step};
use nalgebra::{SMatrix, SVector};

const DT: f64 = 0.05;

/// A step's state and Jacobians `A`, `B`.
type Step = (SVector<f64, 3>, SMatrix<f64, 3, 3>, SMatrix<f64, 3, 1>);

/// A damped oscillator driven through a first-order lag of 5 ms (eigenvalues about
/// -0.2 +- 2i and -200: stiff at dt = 0.05).
fn system() -> (SMatrix<f64, 3, 3>, SMatrix<f64, 3, 1>) {
    let m = SMatrix::<f64, 3, 3>::new(0.0, 1.0, 0.0, -4.0, -0.4, 1.0, 0.0, 0.0, -200.0);
    let n = SMatrix::<f64, 3, 1>::new(0.0, 0.0, 200.0);
    (m, n)
}

/// The exact step and its Jacobians from one 5x5 matrix exponential.
fn exact(x: &SVector<f64, 3>, u: f64) -> Step {
    let (m, n) = system();
    let mut big = SMatrix::<f64, 5, 5>::zeros();
    big.fixed_view_mut::<3, 3>(0, 0).copy_from(&(m * DT));
    big.fixed_view_mut::<3, 1>(0, 3).copy_from(&(n * DT));
    let e = big.exp();
    let a: SMatrix<f64, 3, 3> = e.fixed_view::<3, 3>(0, 0).into();
    let b: SMatrix<f64, 3, 1> = e.fixed_view::<3, 1>(0, 3).into();
    (a * x + b * u, a, b)
}

fn step<const NK: usize>(
    stages: usize,
    steps: usize,
    x: &SVector<f64, 3>,
    u: f64,
) -> Result<Step, IrkError> {
    step_with::<NK>(&GAUSS_LEGENDRE, stages, steps, x, u)
}

fn step_with<const NK: usize>(
    tables: &'static [Tableau; 3],
    stages: usize,
    steps: usize,
    x: &SVector<f64, 3>,
    u: f64,
) -> Result<Step, IrkError> {
    let (m, n) = system();
    let irk = Irk {
        tableau: &tables[stages - 1],
        steps,
        newton: 1,
        dt: DT,
    };
    let mut f = |x: &SVector<f64, 3>, fx: &mut SMatrix<f64, 3, 3>, fu: &mut SMatrix<f64, 3, 1>| {
        *fx = m;
        *fu = n;
        m * x + n * u
    };
    let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
    let xn = irk_step::<f64, 3, 1, NK, _>(&irk, x, &mut f, Some((&mut a, &mut b)))?;
    Ok((xn, a, b))
}

fn err(stages: usize, steps: usize) -> f64 {
    err_with(&GAUSS_LEGENDRE, stages, steps)
}

fn err_with(tables: &'static [Tableau; 3], stages: usize, steps: usize) -> f64 {
    let x = SVector::<f64, 3>::new(0.3, -1.0, 2.0);
    let u = 5.0;
    let (xe, ae, be) = exact(&x, u);
    let (xn, a, b) = match stages {
        1 => step_with::<3>(tables, 1, steps, &x, u),
        2 => step_with::<6>(tables, 2, steps, &x, u),
        _ => step_with::<9>(tables, 3, steps, &x, u),
    }
    .unwrap();
    (xn - xe).amax().max((a - ae).amax()).max((b - be).amax())
}

#[test]
fn the_step_and_its_jacobians_match_the_matrix_exponential() {
    // One Newton iteration solves a linear system's collocation equations exactly.
    let e = err(3, 20);
    println!("3 stages, 20 substeps: max |irk - expm| over x+, A, B = {e:.2e}");
    assert!(e < 1e-9, "{e}");
    // At one substep (dt |lambda| = 10, far beyond an explicit method's stability limit)
    // Gauss-Legendre is A-stable: the step's `A` does not amplify, 200 steps decay.
    let x = SVector::<f64, 3>::new(0.3, -1.0, 2.0);
    for s in 1..=3 {
        let a = match s {
            1 => step::<3>(1, 1, &x, 0.0),
            2 => step::<6>(2, 1, &x, 0.0),
            _ => step::<9>(3, 1, &x, 0.0),
        }
        .unwrap()
        .1;
        let mut y = x;
        for _ in 0..200 {
            y = a * y;
        }
        println!("{s} stage(s), 1 substep: |A^200 x| = {:.2e}", y.norm());
        assert!(y.norm() < x.norm(), "{s}: {}", y.norm());
    }
}

#[test]
fn each_method_has_order_two_s_against_expm() {
    for s in 1..=3 {
        let (lo, hi) = if s == 3 { (8, 16) } else { (32, 64) };
        let ratio = err(s, lo) / err(s, hi);
        let expect = f64::powi(2.0, 2 * s as i32);
        println!(
            "{s} stage(s): error ratio {ratio:.2} per halving (2^{} = {expect})",
            2 * s
        );
        assert!(
            ratio > 0.8 * expect && ratio < 1.25 * expect,
            "{s}: {ratio}"
        );
    }
}

#[test]
fn the_step_runs_in_f32() {
    let (m, n) = system();
    let (m32, n32) = (m.cast::<f32>(), n.cast::<f32>());
    let irk = Irk {
        tableau: &GAUSS_LEGENDRE[1],
        steps: 4,
        newton: 2,
        dt: DT,
    };
    let mut f = |x: &SVector<f32, 3>, fx: &mut SMatrix<f32, 3, 3>, fu: &mut SMatrix<f32, 3, 1>| {
        *fx = m32;
        *fu = n32;
        m32 * x + n32 * 5.0
    };
    let x = SVector::<f32, 3>::new(0.3, -1.0, 2.0);
    let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
    let xn = irk_step::<f32, 3, 1, 6, _>(&irk, &x, &mut f, Some((&mut a, &mut b))).unwrap();
    let (x64, a64, b64) = step::<6>(2, 4, &x.cast::<f64>(), 5.0).unwrap();
    let e = (xn.cast::<f64>() - x64)
        .amax()
        .max((a.cast::<f64>() - a64).amax())
        .max((b.cast::<f64>() - b64).amax());
    println!("f32 against f64: {e:.2e}");
    assert!(e < 1e-4, "{e}");
}

/// `x' = lam x + u` integrated by one-stage Gauss-Legendre; with `lam = 1 / (dt a_11)` every
/// Newton matrix `1 - dt a_11 lam` is singular.
#[derive(Clone, Copy, Debug)]
struct Implicit {
    lam: f64,
}

impl mpc_runtime::Model<f64, 1, 1, 0, 2, 1, 0, 0> for Implicit {
    fn dynamics(
        &self,
        x: &SVector<f64, 1>,
        u: &SVector<f64, 1>,
        _p: &SVector<f64, 0>,
        a: &mut SMatrix<f64, 1, 1>,
        b: &mut SMatrix<f64, 1, 1>,
    ) -> SVector<f64, 1> {
        let irk = Irk {
            tableau: &GAUSS_LEGENDRE[0],
            steps: 1,
            newton: 2,
            dt: DT,
        };
        let lam = self.lam;
        let mut f =
            |x: &SVector<f64, 1>, fx: &mut SMatrix<f64, 1, 1>, fu: &mut SMatrix<f64, 1, 1>| {
                fx[(0, 0)] = lam;
                fu[(0, 0)] = 1.0;
                x * lam + u
            };
        mpc_runtime::implicit::irk_step_or_nan::<f64, 1, 1, 1, _>(&irk, x, &mut f, Some((a, b)))
    }
    fn residual(
        &self,
        x: &SVector<f64, 1>,
        u: &SVector<f64, 1>,
        _p: &SVector<f64, 0>,
        jx: &mut SMatrix<f64, 2, 1>,
        ju: &mut SMatrix<f64, 2, 1>,
    ) -> SVector<f64, 2> {
        *jx = SMatrix::from_column_slice(&[1.0, 0.0]);
        *ju = SMatrix::from_column_slice(&[0.0, 1.0]);
        SVector::from([x[0], u[0]])
    }
    fn terminal_residual(
        &self,
        x: &SVector<f64, 1>,
        _p: &SVector<f64, 0>,
        jx: &mut SMatrix<f64, 1, 1>,
    ) -> SVector<f64, 1> {
        *jx = SMatrix::identity();
        *x
    }
}

#[test]
fn a_singular_newton_system_is_a_failed_step_not_a_panic() {
    type Solver = mpc_runtime::Rti<f64, Implicit, 1, 1, 0, 2, 1, 0, 0, 5, 0, 0>;
    let run = |lam: f64| {
        let mut s = Box::new(Solver::new(Implicit { lam }));
        s.set_weights(&SMatrix::identity(), &SMatrix::identity())
            .unwrap();
        let mut statuses = Vec::new();
        let mut u = 0.0;
        for _ in 0..3 {
            s.prepare();
            let (u0, info) = s.feedback(&SVector::from([1.0]));
            statuses.push(info.status);
            u = u0[0];
        }
        (statuses, u)
    };
    // A regular system (stable, lam = -1) solves; the singular one fails every step, and the
    // control it returns is finite.
    let (ok, _) = run(-1.0);
    assert!(
        ok.iter().all(|&s| s == mpc_runtime::RtiStatus::Ok),
        "{ok:?}"
    );
    let (failed, u) = run(1.0 / (DT * 0.5));
    println!("singular Newton matrix: statuses {failed:?}, u0 = {u}");
    assert!(
        failed.iter().all(|&s| s != mpc_runtime::RtiStatus::Ok),
        "{failed:?}"
    );
    assert!(u.is_finite());
}

#[test]
fn radau_iia_has_order_two_s_minus_one_and_damps_the_stiff_mode() {
    // The error constants differ: implicit Euler needs smaller steps to be asymptotic.
    for (s, lo) in [(1, 256), (2, 32), (3, 8)] {
        let hi = 2 * lo;
        let ratio = err_with(&RADAU_IIA, s, lo) / err_with(&RADAU_IIA, s, hi);
        let expect = f64::powi(2.0, 2 * s as i32 - 1);
        println!("Radau IIA, {s} stage(s): error ratio {ratio:.2} per halving (expected {expect})");
        assert!(
            ratio > 0.8 * expect && ratio < 1.25 * expect,
            "{s}: {ratio}"
        );
    }
    // One substep, dt |lambda| = 10 on the lag: L-stability damps it (the exact factor is
    // exp(-10) = 4.5e-5); Gauss-Legendre's stability function tends to (-1)^s instead.
    let x = SVector::<f64, 3>::new(0.3, -1.0, 2.0);
    for s in 1..=3 {
        let radau = match s {
            1 => step_with::<3>(&RADAU_IIA, 1, 1, &x, 0.0),
            2 => step_with::<6>(&RADAU_IIA, 2, 1, &x, 0.0),
            _ => step_with::<9>(&RADAU_IIA, 3, 1, &x, 0.0),
        };
        let gauss = match s {
            1 => step::<3>(1, 1, &x, 0.0),
            2 => step::<6>(2, 1, &x, 0.0),
            _ => step::<9>(3, 1, &x, 0.0),
        };
        let (r, g) = (radau.unwrap().1[(2, 2)], gauss.unwrap().1[(2, 2)]);
        println!("{s} stage(s), dt lambda = -10: Radau IIA {r:.2e}, Gauss-Legendre {g:.2e}");
        assert!(r.abs() < 0.1 && r.abs() < g.abs(), "{s}: {r} against {g}");
    }
}
