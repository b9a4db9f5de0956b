//! The projection of a general cost's stage Hessian onto the positive semidefinite cone
//! (acados' `PROJECT` regularization), so that the QP of a real-time iteration stays convex.
//!
//! A stage Hessian over `(x, u)` is kept as its blocks (`Q`, `S`, `R` of a [`QpHessian`]):
//! the `(NX + NU)`-square matrix cannot be a fixed-size matrix on stable Rust (no arithmetic
//! on const generics), so the eigendecomposition (cyclic Jacobi rotations, no allocation, no
//! `unsafe`) reads and writes the blocks through the matrix's indices.

use nalgebra::SMatrix;

use crate::qp::QpHessian;
use crate::real::Real;

/// Jacobi sweeps at most (each zeroes every off-diagonal entry once; a symmetric matrix of
/// a few dozen rows converges in well under 15).
const MAX_SWEEPS: u32 = 30;

/// The floor of a clipped eigenvalue, relative to the largest eigenvalue's magnitude (at
/// least 1): `1e-6 max(1, max |lambda|)`. Only negative eigenvalues are raised to it.
pub const PROJECTION_FLOOR: f64 = 1e-6;

/// A symmetric stage Hessian read and written by the index of the stacked `(x, u)`.
fn sym_get<T: Real, const NX: usize, const NU: usize>(
    h: &QpHessian<T, NX, NU>,
    i: usize,
    j: usize,
) -> T {
    match (i < NX, j < NX) {
        (true, true) => h.q[(i, j)],
        (false, true) => h.s[(i - NX, j)],
        (true, false) => h.s[(j - NX, i)],
        (false, false) => h.r[(i - NX, j - NX)],
    }
}

/// Writes entry `(i, j)` and its mirror `(j, i)`.
fn sym_set<T: Real, const NX: usize, const NU: usize>(
    h: &mut QpHessian<T, NX, NU>,
    i: usize,
    j: usize,
    v: T,
) {
    match (i < NX, j < NX) {
        (true, true) => {
            h.q[(i, j)] = v;
            h.q[(j, i)] = v;
        }
        (false, true) => h.s[(i - NX, j)] = v,
        (true, false) => h.s[(j - NX, i)] = v,
        (false, false) => {
            h.r[(i - NX, j - NX)] = v;
            h.r[(j - NX, i - NX)] = v;
        }
    }
}

/// A square `(NX + NU)` matrix (not symmetric: the eigenvectors) in four blocks.
struct Square<T: Real, const NX: usize, const NU: usize> {
    xx: SMatrix<T, NX, NX>,
    xu: SMatrix<T, NX, NU>,
    ux: SMatrix<T, NU, NX>,
    uu: SMatrix<T, NU, NU>,
}

impl<T: Real, const NX: usize, const NU: usize> Square<T, NX, NU> {
    fn identity() -> Self {
        Square {
            xx: SMatrix::identity(),
            xu: SMatrix::zeros(),
            ux: SMatrix::zeros(),
            uu: SMatrix::identity(),
        }
    }

    fn get(&self, i: usize, j: usize) -> T {
        match (i < NX, j < NX) {
            (true, true) => self.xx[(i, j)],
            (true, false) => self.xu[(i, j - NX)],
            (false, true) => self.ux[(i - NX, j)],
            (false, false) => self.uu[(i - NX, j - NX)],
        }
    }

    fn set(&mut self, i: usize, j: usize, v: T) {
        match (i < NX, j < NX) {
            (true, true) => self.xx[(i, j)] = v,
            (true, false) => self.xu[(i, j - NX)] = v,
            (false, true) => self.ux[(i - NX, j)] = v,
            (false, false) => self.uu[(i - NX, j - NX)] = v,
        }
    }
}

/// Projects the symmetric stage Hessian `h` (its blocks `q`, `s`, `r`; `q` and `r`
/// symmetric) onto the positive semidefinite cone: `h = V diag(lambda) V'` by Jacobi
/// rotations, each negative `lambda` raised to the floor ([`PROJECTION_FLOOR`]) and `h`
/// rebuilt from them. A matrix with no negative eigenvalue is left exactly as it is (so a
/// convex cost is not perturbed by rounding). Returns whether `h` changed. A non-finite `h`
/// is left as it is (the QP reports it).
pub fn project_psd<T: Real, const NX: usize, const NU: usize>(
    h: &mut QpHessian<T, NX, NU>,
) -> bool {
    let n = NX + NU;
    let finite =
        h.q.iter()
            .chain(h.s.iter())
            .chain(h.r.iter())
            .all(|v| v.finite());
    if n == 0 || !finite {
        return false;
    }
    let mut a = *h;
    let mut v = Square::<T, NX, NU>::identity();
    jacobi(&mut a, &mut v);
    let (mut min, mut big) = (T::ZERO, T::ONE);
    for i in 0..n {
        let l = sym_get(&a, i, i);
        min = min.min(l);
        big = big.max(l.abs());
    }
    if min >= T::ZERO {
        return false;
    }
    let floor = T::lit(PROJECTION_FLOOR) * big;
    for i in 0..n {
        for j in 0..=i {
            let mut e = T::ZERO;
            for k in 0..n {
                let l = sym_get(&a, k, k);
                let l = if l < T::ZERO { floor } else { l };
                e += v.get(i, k) * l * v.get(j, k);
            }
            sym_set(h, i, j, e);
        }
    }
    true
}

/// Cyclic Jacobi rotations on the symmetric `a` until its off-diagonal part is negligible
/// (relative to its diagonal, to the scalar's precision); `v` accumulates the rotations, so
/// `a_in = v a_out v'` with `a_out` diagonal.
fn jacobi<T: Real, const NX: usize, const NU: usize>(
    a: &mut QpHessian<T, NX, NU>,
    v: &mut Square<T, NX, NU>,
) {
    let n = NX + NU;
    let tol = T::EPSILON * T::EPSILON;
    for _ in 0..MAX_SWEEPS {
        let (mut off, mut diag) = (T::ZERO, T::ZERO);
        for i in 0..n {
            for j in 0..n {
                let e = sym_get(a, i, j);
                if i == j {
                    diag += e * e;
                } else {
                    off += e * e;
                }
            }
        }
        if off <= tol * diag || off == T::ZERO {
            return;
        }
        for p in 0..n {
            for q in p + 1..n {
                rotate(a, v, p, q);
            }
        }
    }
}

/// The Jacobi rotation in the plane `(p, q)` that zeroes `a[(p, q)]`.
fn rotate<T: Real, const NX: usize, const NU: usize>(
    a: &mut QpHessian<T, NX, NU>,
    v: &mut Square<T, NX, NU>,
    p: usize,
    q: usize,
) {
    let apq = sym_get(a, p, q);
    if apq == T::ZERO {
        return;
    }
    let (app, aqq) = (sym_get(a, p, p), sym_get(a, q, q));
    let theta = (aqq - app) / (apq * T::lit(2.0));
    let t = if theta == T::ZERO {
        T::ONE
    } else {
        let t = T::ONE / (theta.abs() + (theta * theta + T::ONE).sqrt());
        if theta < T::ZERO { -t } else { t }
    };
    let c = T::ONE / (t * t + T::ONE).sqrt();
    let s = t * c;
    for k in 0..NX + NU {
        if k == p || k == q {
            continue;
        }
        let (akp, akq) = (sym_get(a, k, p), sym_get(a, k, q));
        sym_set(a, k, p, c * akp - s * akq);
        sym_set(a, k, q, s * akp + c * akq);
    }
    sym_set(a, p, p, app - t * apq);
    sym_set(a, q, q, aqq + t * apq);
    sym_set(a, p, q, T::ZERO);
    for k in 0..NX + NU {
        let (vkp, vkq) = (v.get(k, p), v.get(k, q));
        v.set(k, p, c * vkp - s * vkq);
        v.set(k, q, s * vkp + c * vkq);
    }
}

/// Projects a terminal Hessian (`NX x NX`, symmetric) as [`project_psd`] does a stage's.
pub fn project_psd_terminal<T: Real, const NX: usize>(q: &mut SMatrix<T, NX, NX>) -> bool {
    let mut h = QpHessian::<T, NX, 0> {
        q: *q,
        s: SMatrix::zeros(),
        r: SMatrix::zeros(),
    };
    let changed = project_psd(&mut h);
    *q = h.q;
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `V diag V'` rebuilt from a projection of a 3x3 (two states, one control) matrix with
    /// one negative eigenvalue: the result's eigenvalues are the input's with that one
    /// raised to the floor (checked by the characteristic polynomial's coefficients).
    #[test]
    fn projection_clips_the_negative_eigenvalue() {
        // Eigenvalues 3, 1, -2 of R D R' with an orthogonal R (a rotation about (1, 1, 1)).
        let (c, s) = (0.6f64, 0.8f64);
        let w = 1.0 / 3.0f64.sqrt();
        let axis = [w, w, w];
        let mut rot = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                let kron = if i == j { 1.0 } else { 0.0 };
                let cross = match (i, j) {
                    (0, 1) => -axis[2],
                    (0, 2) => axis[1],
                    (1, 0) => axis[2],
                    (1, 2) => -axis[0],
                    (2, 0) => -axis[1],
                    (2, 1) => axis[0],
                    _ => 0.0,
                };
                rot[i][j] = c * kron + s * cross + (1.0 - c) * axis[i] * axis[j];
            }
        }
        let d = [3.0, 1.0, -2.0];
        let m = |i: usize, j: usize| (0..3).map(|k| rot[i][k] * d[k] * rot[j][k]).sum::<f64>();
        let mut h = QpHessian::<f64, 2, 1> {
            q: SMatrix::from_fn(m),
            s: SMatrix::from_fn(|_, j| m(2, j)),
            r: SMatrix::from_fn(|_, _| m(2, 2)),
        };
        assert!(project_psd(&mut h));
        let p = |i: usize, j: usize| sym_get(&h, i, j);
        let floor = PROJECTION_FLOOR * 3.0;
        let want = |i: usize, j: usize| {
            let dd = [3.0, 1.0, floor];
            (0..3).map(|k| rot[i][k] * dd[k] * rot[j][k]).sum::<f64>()
        };
        for i in 0..3 {
            for j in 0..3 {
                assert!((p(i, j) - want(i, j)).abs() < 1e-12, "({i},{j})");
            }
        }
    }

    /// In f32: a 2x2 (one state, one control) with eigenvalues 2 and -1 becomes the one with
    /// 2 and the floor, to f32's precision.
    #[test]
    fn projection_in_f32() {
        // R diag(2, -1) R' with R the rotation by 30 degrees.
        let (c, s) = (0.75f32.sqrt(), 0.5f32);
        let m = |d0: f32, d1: f32| {
            let a = c * c * d0 + s * s * d1;
            let b = c * s * (d0 - d1);
            let e = s * s * d0 + c * c * d1;
            (a, b, e)
        };
        let (a, b, e) = m(2.0, -1.0);
        let mut h = QpHessian::<f32, 1, 1> {
            q: SMatrix::from_element(a),
            s: SMatrix::from_element(b),
            r: SMatrix::from_element(e),
        };
        assert!(project_psd(&mut h));
        let (wa, wb, we) = m(2.0, PROJECTION_FLOOR as f32 * 2.0);
        assert!((h.q[(0, 0)] - wa).abs() < 1e-5, "{h:?}");
        assert!((h.s[(0, 0)] - wb).abs() < 1e-5, "{h:?}");
        assert!((h.r[(0, 0)] - we).abs() < 1e-5, "{h:?}");
    }

    /// A positive semidefinite matrix is left bit for bit.
    #[test]
    fn psd_matrix_is_untouched() {
        let mut h = QpHessian::<f64, 2, 1> {
            q: SMatrix::from_row_slice(&[2.0, 0.5, 0.5, 1.0]),
            s: SMatrix::from_row_slice(&[0.1, 0.2]),
            r: SMatrix::from_row_slice(&[0.7]),
        };
        let before = h;
        assert!(!project_psd(&mut h));
        assert_eq!((h.q, h.s, h.r), (before.q, before.s, before.r));
    }
}
