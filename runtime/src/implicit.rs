//! Implicit integration for stiff dynamics: Gauss-Legendre or Radau IIA collocation (implicit
//! Runge-Kutta methods, [`GAUSS_LEGENDRE`], [`RADAU_IIA`]) with a fixed number of Newton
//! iterations and exact sensitivities, the step generated code calls for
//! `dynamics ode irk(...)`.
//!
//! One substep of length `h` from `x` solves the collocation equations for the stage
//! derivatives `K = (K_1, ..., K_s)`:
//!
//! ```text
//! G_i(K) = K_i - f(x + h sum_j a_ij K_j, u) = 0,   i = 1..s
//! x+ = x + h sum_i b_i K_i
//! ```
//!
//! - **Newton.** `K` starts at `f(x, u)` in every stage, then `newton` iterations of
//!   `(dG/dK) dK = -G`, with `dG/dK = I - h A (x) df/dx` evaluated afresh at every iteration
//!   (exact Newton; acados can reuse it instead) and factorized by a dense LU with
//!   partial pivoting ([`lu_factor`]) of size `s * nx`. There is no convergence test: the
//!   number of iterations is fixed, as in acados, so the cost of a step is fixed.
//! - **Sensitivities.** After the last iteration `f`, `df/dx`, `df/du` are evaluated once more
//!   at the final stages, and the implicit function theorem gives
//!   `dK/d(x, u) = -(dG/dK)^{-1} dG/d(x, u)`, one LU and `nx + nu` solves; then
//!   `dx+/d(x, u) = [I 0] + h sum_i b_i dK_i/d(x, u)`, chained over the substeps. These are
//!   the exact derivatives of the converged collocation step (the step the iterations
//!   approximate), as acados computes them.
//! - **Failure.** A singular (or non-finite) Newton matrix, a non-finite result, or stage
//!   sizes that do not match ([`IrkError`]) never panic: [`irk_step_or_nan`] then returns NaN
//!   in every output, which the RTI treats as a failed linearization (the QP fails, the
//!   shifted previous plan is applied).
//!
//! The stage vector has `NK = stages * NX` entries; stable Rust cannot compute that in a
//! const generic, so the caller passes `NK` and a mismatch is reported as
//! [`IrkError::Size`].

use nalgebra::{SMatrix, SVector};

use crate::Real;

/// The Butcher tableau of a collocation method with at most three stages (entries beyond
/// `stages` are zero).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tableau {
    /// Number of stages `s`.
    pub stages: usize,
    /// `a_ij`.
    pub a: [[f64; 3]; 3],
    /// `b_i`.
    pub b: [f64; 3],
}

/// Gauss-Legendre collocation with 1, 2 and 3 stages (orders 2, 4 and 6): index `s - 1`.
/// The entries are the closed forms (with `sqrt(3)` and `sqrt(15)`) rounded to `f64`.
pub const GAUSS_LEGENDRE: [Tableau; 3] = [
    Tableau {
        stages: 1,
        a: [[0.5, 0.0, 0.0], [0.0; 3], [0.0; 3]],
        b: [1.0, 0.0, 0.0],
    },
    Tableau {
        stages: 2,
        a: [
            [0.25, -0.038675134594812866, 0.0],
            [0.5386751345948129, 0.25, 0.0],
            [0.0; 3],
        ],
        b: [0.5, 0.5, 0.0],
    },
    Tableau {
        stages: 3,
        a: [
            [
                0.1388888888888889,
                -0.03597666752493894,
                0.009789444015308318,
            ],
            [
                0.3002631949808646,
                0.2222222222222222,
                -0.022485417203086805,
            ],
            [0.26798833376246944, 0.48042111196938336, 0.1388888888888889],
        ],
        b: [0.2777777777777778, 0.4444444444444444, 0.2777777777777778],
    },
];

/// Radau IIA collocation with 1, 2 and 3 stages (orders 1, 3 and 5; L-stable: a transient
/// much faster than a step is damped out, where Gauss-Legendre only keeps it bounded): index
/// `s - 1`. One stage is implicit Euler. The entries are the closed forms (with `sqrt(6)`)
/// rounded to `f64`.
pub const RADAU_IIA: [Tableau; 3] = [
    Tableau {
        stages: 1,
        a: [[1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]],
        b: [1.0, 0.0, 0.0],
    },
    Tableau {
        stages: 2,
        a: [
            [0.4166666666666667, -0.08333333333333333, 0.0],
            [0.75, 0.25, 0.0],
            [0.0; 3],
        ],
        b: [0.75, 0.25, 0.0],
    },
    Tableau {
        stages: 3,
        a: [
            [
                0.19681547722366044,
                -0.06553542585019838,
                0.02377097434822015,
            ],
            [
                0.3944243147390873,
                0.29207341166522843,
                -0.04154875212599792,
            ],
            [0.37640306270046725, 0.5124858261884216, 0.1111111111111111],
        ],
        b: [0.37640306270046725, 0.5124858261884216, 0.1111111111111111],
    },
];

/// The settings of an implicit step over one shooting interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Irk {
    /// The method.
    pub tableau: &'static Tableau,
    /// Equal substeps per interval (0 is taken as 1).
    pub steps: usize,
    /// Newton iterations per substep.
    pub newton: usize,
    /// The interval's length in seconds.
    pub dt: f64,
}

/// Why an implicit step failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IrkError {
    /// `NK` is not `stages * NX`, or the tableau has more than three stages.
    Size,
    /// A Newton matrix `I - h A (x) df/dx` is singular (or not finite).
    Singular,
    /// The result is not finite.
    NonFinite,
}

/// LU factorization with partial pivoting in place: `P m = L U`, `L` unit lower triangular
/// below the diagonal of `m`, `U` on and above it, `piv[k]` the row swapped into row `k` at
/// step `k`. Returns `false` (and leaves `m` partly factorized) when a pivot is zero or not
/// finite.
pub fn lu_factor<T: Real, const N: usize>(m: &mut SMatrix<T, N, N>, piv: &mut [usize; N]) -> bool {
    for k in 0..N {
        let mut p = k;
        let mut best = m[(k, k)].abs();
        for r in k + 1..N {
            let v = m[(r, k)].abs();
            if v > best {
                best = v;
                p = r;
            }
        }
        if !(best.finite() && best > T::ZERO) {
            return false;
        }
        piv[k] = p;
        if p != k {
            m.swap_rows(k, p);
        }
        let d = m[(k, k)];
        for r in k + 1..N {
            let l = m[(r, k)] / d;
            m[(r, k)] = l;
            if l != T::ZERO {
                for c in k + 1..N {
                    let v = m[(k, c)];
                    m[(r, c)] -= l * v;
                }
            }
        }
    }
    true
}

/// Solves `m x = b` in place with the factors of [`lu_factor`].
pub fn lu_solve<T: Real, const N: usize>(
    m: &SMatrix<T, N, N>,
    piv: &[usize; N],
    b: &mut SVector<T, N>,
) {
    for (k, &p) in piv.iter().enumerate() {
        if p != k && p < N {
            b.swap_rows(k, p);
        }
    }
    for r in 0..N {
        let mut s = b[r];
        for c in 0..r {
            s -= m[(r, c)] * b[c];
        }
        b[r] = s;
    }
    for r in (0..N).rev() {
        let mut s = b[r];
        for c in r + 1..N {
            s -= m[(r, c)] * b[c];
        }
        b[r] = s / m[(r, r)];
    }
}

/// `f`, `df/dx` and `df/du` at the stage points `x + h sum_j a_ij K_j`.
struct Stages<T: Real, const NX: usize, const NU: usize> {
    f: [SVector<T, NX>; 3],
    fx: [SMatrix<T, NX, NX>; 3],
    fu: [SMatrix<T, NX, NU>; 3],
}

impl<T: Real, const NX: usize, const NU: usize> Stages<T, NX, NU> {
    fn at<const NK: usize, F>(
        tab: &Tableau,
        h: T,
        x: &SVector<T, NX>,
        k: &SVector<T, NK>,
        f: &mut F,
    ) -> Self
    where
        F: FnMut(
            &SVector<T, NX>,
            &mut SMatrix<T, NX, NX>,
            &mut SMatrix<T, NX, NU>,
        ) -> SVector<T, NX>,
    {
        let mut st = Stages {
            f: [SVector::zeros(); 3],
            fx: [SMatrix::zeros(); 3],
            fu: [SMatrix::zeros(); 3],
        };
        for i in 0..tab.stages.min(3) {
            let mut xi = *x;
            for j in 0..tab.stages.min(3) {
                let aij = h * T::lit(tab.a[i][j]);
                for r in 0..NX {
                    xi[r] += aij * k[j * NX + r];
                }
            }
            st.f[i] = f(&xi, &mut st.fx[i], &mut st.fu[i]);
        }
        st
    }

    /// `dG/dK = I - h A (x) df/dx`, factorized into `m`; `false` if singular.
    fn newton_matrix<const NK: usize>(
        &self,
        tab: &Tableau,
        h: T,
        m: &mut SMatrix<T, NK, NK>,
        piv: &mut [usize; NK],
    ) -> bool {
        *m = SMatrix::identity();
        for i in 0..tab.stages.min(3) {
            for j in 0..tab.stages.min(3) {
                let aij = h * T::lit(tab.a[i][j]);
                for r in 0..NX {
                    for c in 0..NX {
                        m[(i * NX + r, j * NX + c)] -= aij * self.fx[i][(r, c)];
                    }
                }
            }
        }
        lu_factor(m, piv)
    }
}

/// The sensitivity of the state over `(x0, u)` during an interval: `sx = dx/dx0`, `su = dx/du`.
struct Sens<T: Real, const NX: usize, const NU: usize> {
    sx: SMatrix<T, NX, NX>,
    su: SMatrix<T, NX, NU>,
}

/// One substep of length `h` from `x`: the new state, and with `sens` the sensitivities
/// carried through it.
fn substep<T: Real, const NX: usize, const NU: usize, const NK: usize, F>(
    tab: &Tableau,
    (h, newton): (T, usize),
    x: &SVector<T, NX>,
    f: &mut F,
    sens: Option<&mut Sens<T, NX, NU>>,
) -> Result<SVector<T, NX>, IrkError>
where
    F: FnMut(&SVector<T, NX>, &mut SMatrix<T, NX, NX>, &mut SMatrix<T, NX, NU>) -> SVector<T, NX>,
{
    let s = tab.stages.min(3);
    let mut m = SMatrix::<T, NK, NK>::zeros();
    let mut piv = [0usize; NK];
    let (mut jx, mut ju) = (SMatrix::zeros(), SMatrix::zeros());
    let f0 = f(x, &mut jx, &mut ju);
    let mut k = SVector::<T, NK>::zeros();
    for i in 0..s {
        for r in 0..NX {
            k[i * NX + r] = f0[r];
        }
    }
    for _ in 0..newton {
        let st = Stages::at(tab, h, x, &k, f);
        if !st.newton_matrix(tab, h, &mut m, &mut piv) {
            return Err(IrkError::Singular);
        }
        let mut g = SVector::<T, NK>::zeros();
        for i in 0..s {
            for r in 0..NX {
                g[i * NX + r] = st.f[i][r] - k[i * NX + r];
            }
        }
        lu_solve(&m, &piv, &mut g);
        k += g;
    }
    if let Some(sens) = sens {
        let st = Stages::at(tab, h, x, &k, f);
        if !st.newton_matrix(tab, h, &mut m, &mut piv) {
            return Err(IrkError::Singular);
        }
        carry_sensitivities(tab, h, &st, (&m, &piv), sens);
    }
    let mut xn = *x;
    for i in 0..s {
        let hb = h * T::lit(tab.b[i]);
        for r in 0..NX {
            xn[r] += hb * k[i * NX + r];
        }
    }
    Ok(xn)
}

/// `S += h sum_i b_i dK_i`, column by column, with `(dG/dK) dK = df/dx(X_i) S + [0 df/du]`
/// (the implicit function theorem on `G(K, S) = 0`).
fn carry_sensitivities<T: Real, const NX: usize, const NU: usize, const NK: usize>(
    tab: &Tableau,
    h: T,
    st: &Stages<T, NX, NU>,
    (m, piv): (&SMatrix<T, NK, NK>, &[usize; NK]),
    sens: &mut Sens<T, NX, NU>,
) {
    let s = tab.stages.min(3);
    for c in 0..NX + NU {
        let mut rhs = SVector::<T, NK>::zeros();
        for i in 0..s {
            for r in 0..NX {
                let mut v = T::ZERO;
                for q in 0..NX {
                    let sq = if c < NX {
                        sens.sx[(q, c)]
                    } else {
                        sens.su[(q, c - NX)]
                    };
                    v += st.fx[i][(r, q)] * sq;
                }
                if c >= NX {
                    v += st.fu[i][(r, c - NX)];
                }
                rhs[i * NX + r] = v;
            }
        }
        lu_solve(m, piv, &mut rhs);
        for i in 0..s {
            let hb = h * T::lit(tab.b[i]);
            for r in 0..NX {
                let d = hb * rhs[i * NX + r];
                if c < NX {
                    sens.sx[(r, c)] += d;
                } else {
                    sens.su[(r, c - NX)] += d;
                }
            }
        }
    }
}

/// The implicit step over one interval: `F(x, u)`, and with `ab` its Jacobians
/// `a = dF/dx`, `b = dF/du`. `f(x, fx, fu)` returns `f(x, u, p)` at the state `x` (the
/// control and parameters fixed by the caller) and writes `fx = df/dx`, `fu = df/du`.
///
/// # Errors
/// [`IrkError`]; the outputs are then unspecified ([`irk_step_or_nan`] sets them to NaN).
pub fn irk_step<T: Real, const NX: usize, const NU: usize, const NK: usize, F>(
    irk: &Irk,
    x: &SVector<T, NX>,
    f: &mut F,
    ab: Option<(&mut SMatrix<T, NX, NX>, &mut SMatrix<T, NX, NU>)>,
) -> Result<SVector<T, NX>, IrkError>
where
    F: FnMut(&SVector<T, NX>, &mut SMatrix<T, NX, NX>, &mut SMatrix<T, NX, NU>) -> SVector<T, NX>,
{
    let tab = irk.tableau;
    if tab.stages == 0 || tab.stages > 3 || tab.stages * NX != NK {
        return Err(IrkError::Size);
    }
    let steps = irk.steps.max(1);
    let h = T::lit(irk.dt / steps as f64);
    let mut sens = Sens {
        sx: SMatrix::identity(),
        su: SMatrix::zeros(),
    };
    let want = ab.is_some();
    let mut xs = *x;
    for _ in 0..steps {
        xs = substep::<T, NX, NU, NK, F>(tab, (h, irk.newton), &xs, f, want.then_some(&mut sens))?;
    }
    let finite = xs.iter().all(|v| v.finite());
    if let Some((a, b)) = ab {
        *a = sens.sx;
        *b = sens.su;
        if !(finite && a.iter().chain(b.iter()).all(|v| v.finite())) {
            return Err(IrkError::NonFinite);
        }
    }
    if finite {
        Ok(xs)
    } else {
        Err(IrkError::NonFinite)
    }
}

/// [`irk_step`] for generated code: on any [`IrkError`] the state and both Jacobians are NaN
/// (a failed linearization to the RTI), never a panic.
pub fn irk_step_or_nan<T: Real, const NX: usize, const NU: usize, const NK: usize, F>(
    irk: &Irk,
    x: &SVector<T, NX>,
    f: &mut F,
    ab: Option<(&mut SMatrix<T, NX, NX>, &mut SMatrix<T, NX, NU>)>,
) -> SVector<T, NX>
where
    F: FnMut(&SVector<T, NX>, &mut SMatrix<T, NX, NX>, &mut SMatrix<T, NX, NU>) -> SVector<T, NX>,
{
    let nan = T::lit(f64::NAN);
    match ab {
        Some((a, b)) => match irk_step::<T, NX, NU, NK, F>(irk, x, f, Some((&mut *a, &mut *b))) {
            Ok(v) => v,
            Err(_) => {
                a.fill(nan);
                b.fill(nan);
                SVector::from_element(nan)
            }
        },
        None => irk_step::<T, NX, NU, NK, F>(irk, x, f, None).unwrap_or(SVector::from_element(nan)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lu_solves_a_system_that_needs_pivoting() {
        // A zero in the top-left corner: no LU without a row swap.
        let m0 = SMatrix::<f64, 3, 3>::new(0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 4.0);
        let x = SVector::<f64, 3>::new(1.0, -2.0, 0.5);
        let mut b = m0 * x;
        let (mut m, mut piv) = (m0, [0; 3]);
        assert!(lu_factor(&mut m, &mut piv));
        lu_solve(&m, &piv, &mut b);
        assert!((b - x).amax() < 1e-14, "{b} against {x}");
    }

    #[test]
    fn lu_flags_a_singular_matrix() {
        let mut m = SMatrix::<f64, 2, 2>::new(1.0, 2.0, 2.0, 4.0);
        assert!(!lu_factor(&mut m, &mut [0; 2]));
        let mut nan = SMatrix::<f32, 2, 2>::new(f32::NAN, 0.0, 0.0, 1.0);
        assert!(!lu_factor(&mut nan, &mut [0; 2]));
    }

    #[test]
    fn a_mismatched_stage_size_is_an_error_and_nan() {
        let irk = Irk {
            tableau: &GAUSS_LEGENDRE[1],
            steps: 1,
            newton: 2,
            dt: 0.1,
        };
        let mut f =
            |x: &SVector<f64, 1>, fx: &mut SMatrix<f64, 1, 1>, _: &mut SMatrix<f64, 1, 1>| {
                fx[(0, 0)] = -1.0;
                -x
            };
        let x = SVector::<f64, 1>::new(1.0);
        let r = irk_step::<f64, 1, 1, 3, _>(&irk, &x, &mut f, None);
        assert_eq!(r, Err(IrkError::Size));
        let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
        let v = irk_step_or_nan::<f64, 1, 1, 3, _>(&irk, &x, &mut f, Some((&mut a, &mut b)));
        assert!(v[0].is_nan() && a[(0, 0)].is_nan() && b[(0, 0)].is_nan());
    }

    #[test]
    fn a_singular_newton_matrix_gives_nan_not_a_panic() {
        // x' = x / (h a_11): the one-stage Newton matrix 1 - h a_11 df/dx is zero.
        let irk = Irk {
            tableau: &GAUSS_LEGENDRE[0],
            steps: 1,
            newton: 1,
            dt: 0.1,
        };
        let lam = 1.0 / (0.1 * 0.5);
        let mut f =
            |x: &SVector<f64, 1>, fx: &mut SMatrix<f64, 1, 1>, _: &mut SMatrix<f64, 1, 1>| {
                fx[(0, 0)] = lam;
                x * lam
            };
        let x = SVector::<f64, 1>::new(1.0);
        assert_eq!(
            irk_step::<f64, 1, 1, 1, _>(&irk, &x, &mut f, None),
            Err(IrkError::Singular)
        );
        assert!(irk_step_or_nan::<f64, 1, 1, 1, _>(&irk, &x, &mut f, None)[0].is_nan());
    }

    #[test]
    fn one_linear_stage_is_the_midpoint_rule_s_pade_form() {
        // x' = l x: one-stage Gauss is the implicit midpoint rule, x+ = (1 + z/2)/(1 - z/2) x
        // with z = h l, whatever l (A-stable: |x+| < |x| for l < 0).
        let irk = Irk {
            tableau: &GAUSS_LEGENDRE[0],
            steps: 1,
            newton: 1,
            dt: 0.01,
        };
        let l = -1000.0;
        let mut f =
            |x: &SVector<f64, 1>, fx: &mut SMatrix<f64, 1, 1>, fu: &mut SMatrix<f64, 1, 1>| {
                fx[(0, 0)] = l;
                fu[(0, 0)] = 0.0;
                x * l
            };
        let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
        let x = SVector::<f64, 1>::new(2.0);
        let xn = irk_step::<f64, 1, 1, 1, _>(&irk, &x, &mut f, Some((&mut a, &mut b)));
        let z = 0.01 * l;
        let r = (1.0 + z / 2.0) / (1.0 - z / 2.0);
        assert_eq!(xn.map(|v| (v[0] - 2.0 * r).abs() < 1e-13), Ok(true));
        assert!((a[(0, 0)] - r).abs() < 1e-13 && b[(0, 0)] == 0.0);
    }
}
