//! Products of small fixed-size matrices for the solver's hot loops, over nalgebra's array
//! storage (column-major `[[T; R]; C]`), with loop bounds that are the const dimensions so the
//! compiler unrolls and vectorizes them. Each entry is `sum_k a_ik b_kj` with k increasing.

use nalgebra::SMatrix;

use crate::real::Real;

/// `a * b`.
#[inline(always)]
pub(crate) fn mul<T: Real, const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) -> SMatrix<T, R, C> {
    mul_impl::<T, R, K, C, false>(a, b)
}

/// `a * b`, skipping the zero entries of `b`: the same result as [`mul`] for finite `a` (a
/// skipped term would add an exact zero), at the cost of the nonzeros of `b`. For model
/// Jacobians (`A`, `B`, residual and constraint Jacobians), whose structural zeros the
/// generated code leaves at exactly zero. With 256-bit vectors (AVX) the test per entry
/// costs more than the column update it saves, and the product is dense.
#[inline(always)]
pub(crate) fn mul_sparse<T: Real, const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) -> SMatrix<T, R, C> {
    mul_impl::<T, R, K, C, { !cfg!(target_feature = "avx") }>(a, b)
}

/// `y += x a`, four entries at a time written out, then the rest: no loop the compiler has
/// to unroll, so the kernels stay compact and fast at every optimization level (at
/// `opt-level = "s"`, which unrolls nothing, a loop of four would cost its counter per
/// entry).
#[inline(always)]
fn axpy<T: Real, const R: usize>(y: &mut [T; R], x: &[T; R], a: T) {
    let (y4, yr) = y.as_chunks_mut::<4>();
    let (x4, xr) = x.as_chunks::<4>();
    for (y, x) in y4.iter_mut().zip(x4) {
        y[0] += x[0] * a;
        y[1] += x[1] * a;
        y[2] += x[2] * a;
        y[3] += x[3] * a;
    }
    for (y, &x) in yr.iter_mut().zip(xr) {
        *y += x * a;
    }
}

/// `sum_k x_k y_k`, summed in order (`k` increasing), four terms at a time written out.
#[inline(always)]
fn dot<T: Real, const K: usize>(x: &[T; K], y: &[T; K]) -> T {
    let (x4, xr) = x.as_chunks::<4>();
    let (y4, yr) = y.as_chunks::<4>();
    let mut s = T::ZERO;
    for (x, y) in x4.iter().zip(y4) {
        s += x[0] * y[0];
        s += x[1] * y[1];
        s += x[2] * y[2];
        s += x[3] * y[3];
    }
    for (&x, &y) in xr.iter().zip(yr) {
        s += x * y;
    }
    s
}

/// `out = a * b`, skipping the zero entries of `b` (as [`mul_sparse`]) except with AVX,
/// written in place: each column is summed in a local array and stored once, so no
/// matrix-sized temporary is copied (for the stage matrices, up to `NX x NX`).
#[inline(always)]
pub(crate) fn mul_sparse_into<T: Real, const R: usize, const K: usize, const C: usize>(
    out: &mut SMatrix<T, R, C>,
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) {
    mul_sparse_into_impl::<T, R, K, C, false, { !cfg!(target_feature = "avx") }>(out, a, b);
}

/// `out = a * b` skipping every zero entry of `b`, with AVX too: for a `b` that is mostly
/// zeros (a residual Jacobian that selects states and controls), where the skipped column
/// updates outweigh the test per entry at any vector width.
#[inline(always)]
pub(crate) fn mul_mostly_zero_into<T: Real, const R: usize, const K: usize, const C: usize>(
    out: &mut SMatrix<T, R, C>,
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) {
    mul_sparse_into_impl::<T, R, K, C, false, true>(out, a, b);
}

/// `out += a * b`, as [`mul_sparse_into`] (each column's terms added to it in order).
#[inline(always)]
pub(crate) fn mul_sparse_add_into<T: Real, const R: usize, const K: usize, const C: usize>(
    out: &mut SMatrix<T, R, C>,
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) {
    mul_sparse_into_impl::<T, R, K, C, true, { !cfg!(target_feature = "avx") }>(out, a, b);
}

#[inline(always)]
fn mul_sparse_into_impl<
    T: Real,
    const R: usize,
    const K: usize,
    const C: usize,
    const ADD: bool,
    const SKIP: bool,
>(
    out: &mut SMatrix<T, R, C>,
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) {
    let (ad, bd) = (&a.data.0, &b.data.0);
    for (o, bcol) in out.data.0.iter_mut().zip(bd) {
        let mut col = if ADD { *o } else { [T::ZERO; R] };
        for (&bkj, acol) in bcol.iter().zip(ad) {
            if SKIP && bkj == T::ZERO {
                continue;
            }
            axpy(&mut col, acol, bkj);
        }
        *o = col;
    }
}

/// `out += a' * b`, each entry's dot product (summed in order) added to it.
#[inline(always)]
pub(crate) fn tr_mul_add_into<T: Real, const K: usize, const R: usize, const C: usize>(
    out: &mut SMatrix<T, R, C>,
    a: &SMatrix<T, K, R>,
    b: &SMatrix<T, K, C>,
) {
    let (ad, bd) = (&a.data.0, &b.data.0);
    for (o, bcol) in out.data.0.iter_mut().zip(bd) {
        for (oi, acol) in o.iter_mut().zip(ad) {
            *oi += dot(acol, bcol);
        }
    }
}

/// `m <- (m + m') / 2` in place: each pair of entries is replaced by its mean, computed as
/// `(a + b) * 0.5` (the same bits as the out-of-place formula).
#[inline(always)]
#[allow(clippy::needless_range_loop)] // the pairs (i, j), (j, i): an index pattern
pub(crate) fn symmetrize<T: Real, const K: usize>(m: &mut SMatrix<T, K, K>) {
    let d = &mut m.data.0;
    for j in 0..K {
        for i in j + 1..K {
            let v = (d[j][i] + d[i][j]) * T::lit(0.5);
            d[j][i] = v;
            d[i][j] = v;
        }
    }
}

/// `(diag(w) m)' = m' diag(w)`: row `i` of `m` scaled by `w_i`, transposed, in one pass.
#[inline(always)]
pub(crate) fn scaled_transpose<T: Real, const K: usize, const C: usize>(
    w: &SMatrix<T, K, 1>,
    m: &SMatrix<T, K, C>,
) -> SMatrix<T, C, K> {
    let md = &m.data.0;
    let mut out = [[T::ZERO; C]; K];
    for (i, o) in out.iter_mut().enumerate() {
        let d = w[i];
        for (j, oj) in o.iter_mut().enumerate() {
            *oj = md[j][i] * d;
        }
    }
    SMatrix::from_array_storage(nalgebra::ArrayStorage(out))
}

/// `a * b` column by column (axpy form), skipping zero entries of `b` if `SKIP`.
#[inline(always)]
fn mul_impl<T: Real, const R: usize, const K: usize, const C: usize, const SKIP: bool>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) -> SMatrix<T, R, C> {
    let (ad, bd) = (&a.data.0, &b.data.0);
    let mut out = [[T::ZERO; R]; C];
    for j in 0..C {
        for k in 0..K {
            let bkj = bd[j][k];
            if SKIP && bkj == T::ZERO {
                continue;
            }
            axpy(&mut out[j], &ad[k], bkj);
        }
    }
    SMatrix::from_array_storage(nalgebra::ArrayStorage(out))
}

/// `a' * b`.
#[inline(always)]
pub(crate) fn tr_mul<T: Real, const K: usize, const R: usize, const C: usize>(
    a: &SMatrix<T, K, R>,
    b: &SMatrix<T, K, C>,
) -> SMatrix<T, R, C> {
    let (ad, bd) = (&a.data.0, &b.data.0);
    let mut out = [[T::ZERO; R]; C];
    for j in 0..C {
        for i in 0..R {
            out[j][i] = dot(&ad[i], &bd[j]);
        }
    }
    SMatrix::from_array_storage(nalgebra::ArrayStorage(out))
}

/// `a * b'`.
#[inline(always)]
pub(crate) fn mul_tr<T: Real, const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, C, K>,
) -> SMatrix<T, R, C> {
    let (ad, bd) = (&a.data.0, &b.data.0);
    let mut out = [[T::ZERO; R]; C];
    for j in 0..C {
        for k in 0..K {
            axpy(&mut out[j], &ad[k], bd[k][j]);
        }
    }
    SMatrix::from_array_storage(nalgebra::ArrayStorage(out))
}

/// `acc -= sum_k a_k b_k'` over the pairs of blocks of `a` and `b`.
#[inline(always)]
pub(crate) fn sub_mul_tr_sum<T: Real, const R: usize, const K: usize, const C: usize>(
    acc: &mut SMatrix<T, R, C>,
    a: &[SMatrix<T, R, K>],
    b: &[SMatrix<T, C, K>],
) {
    let mut out = acc.data.0;
    for (am, bm) in a.iter().zip(b) {
        let (ad, bd) = (&am.data.0, &bm.data.0);
        for k in 0..K {
            for j in 0..C {
                // `y + x (-b)` is `y - x b`, bit for bit.
                axpy(&mut out[j], &ad[k], -bd[k][j]);
            }
        }
    }
    acc.data.0 = out;
}

/// `acc += sign * sum_k a_k v_k` over the pairs of blocks of `a` and vectors of `v`.
#[inline(always)]
pub(crate) fn add_mul_sum<T: Real, const R: usize, const K: usize>(
    acc: &mut SMatrix<T, R, 1>,
    sign: T,
    a: &[SMatrix<T, R, K>],
    v: &[SMatrix<T, K, 1>],
) {
    let mut out = [T::ZERO; R];
    for (am, vm) in a.iter().zip(v) {
        let (ad, vd) = (&am.data.0, &vm.data.0[0]);
        for k in 0..K {
            axpy(&mut out, &ad[k], vd[k]);
        }
    }
    for i in 0..R {
        acc[i] += sign * out[i];
    }
}

/// Inverse of a lower-triangular matrix with a nonzero diagonal (a Cholesky factor), by
/// forward substitution column by column.
pub(crate) fn lower_inverse<T: Real, const K: usize>(l: &SMatrix<T, K, K>) -> SMatrix<T, K, K> {
    let mut inv = SMatrix::<T, K, K>::zeros();
    for j in 0..K {
        inv[(j, j)] = T::ONE / l[(j, j)];
        for i in j + 1..K {
            let mut acc = T::ZERO;
            for k in j..i {
                acc += l[(i, k)] * inv[(k, j)];
            }
            inv[(i, j)] = -acc / l[(i, i)];
        }
    }
    inv
}

/// `m += diag(w)`.
#[inline(always)]
pub(crate) fn add_diagonal<T: Real, const K: usize>(
    m: &mut SMatrix<T, K, K>,
    w: &SMatrix<T, K, 1>,
) {
    for i in 0..K {
        m[(i, i)] += w[i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn match_nalgebra() {
        let a = SMatrix::<f64, 3, 4>::from_fn(|i, j| (i * 7 + j * 3) as f64 * 0.37 - 1.0);
        let b = SMatrix::<f64, 4, 2>::from_fn(|i, j| (i * 5 + j * 11) as f64 * 0.21 - 2.0);
        let c = SMatrix::<f64, 3, 2>::from_fn(|i, j| (i + 2 * j) as f64 * 1.3 - 0.5);
        assert!((mul(&a, &b) - a * b).amax() < 1e-12);
        let mut sparse = b;
        sparse[(1, 0)] = 0.0;
        sparse[(3, 1)] = 0.0;
        assert_eq!(mul_sparse(&a, &sparse), mul(&a, &sparse));
        assert!((mul_sparse(&a, &sparse) - a * sparse).amax() < 1e-12);
        let mut into = SMatrix::<f64, 3, 2>::repeat(7.0);
        mul_sparse_into(&mut into, &a, &sparse);
        assert_eq!(into, mul(&a, &sparse));
        let mut mz = SMatrix::<f64, 3, 2>::repeat(-3.0);
        mul_mostly_zero_into(&mut mz, &a, &sparse);
        assert_eq!(mz, into);
        mul_sparse_add_into(&mut into, &a, &b);
        assert!((into - a * sparse - a * b).amax() < 1e-12);
        let mut acc = SMatrix::<f64, 4, 2>::repeat(-1.0);
        tr_mul_add_into(&mut acc, &a, &c);
        assert!((acc - SMatrix::repeat(-1.0) - a.transpose() * c).amax() < 1e-12);
        let w =
            SMatrix::<f64, 4, 4>::from_diagonal(&SMatrix::<f64, 4, 1>::new(1.0, -2.0, 0.5, 3.0));
        assert!((scaled_transpose(&w.diagonal(), &b) - (w * b).transpose()).amax() < 1e-12);
        let mut sq4 = SMatrix::<f64, 4, 4>::repeat(0.5);
        add_diagonal(&mut sq4, &w.diagonal());
        assert_eq!(sq4, SMatrix::repeat(0.5) + w);
        let mut sq = SMatrix::<f64, 3, 3>::from_fn(|i, j| (i * 3 + j) as f64 * 0.3 - 1.0);
        let want = (sq + sq.transpose()) * 0.5;
        symmetrize(&mut sq);
        assert_eq!(sq, want);
        assert!((tr_mul(&a, &c) - a.transpose() * c).amax() < 1e-12);
        let d = SMatrix::<f64, 2, 4>::from_fn(|i, j| (3 * i + j) as f64 * 0.7 - 1.1);
        assert!((mul_tr(&a, &d) - a * d.transpose()).amax() < 1e-12);
        let (a2, d2) = (a * 0.5 + SMatrix::repeat(0.1), d * -1.5);
        let mut acc = SMatrix::<f64, 3, 2>::repeat(2.0);
        sub_mul_tr_sum(&mut acc, &[a, a2], &[d, d2]);
        let expect = SMatrix::<f64, 3, 2>::repeat(2.0) - a * d.transpose() - a2 * d2.transpose();
        assert!((acc - expect).amax() < 1e-12);
        let (v1, v2) = (
            SMatrix::<f64, 4, 1>::new(1.0, -2.0, 0.5, 3.0),
            SMatrix::repeat(0.25),
        );
        let mut acc = SMatrix::<f64, 3, 1>::new(1.0, 2.0, 3.0);
        add_mul_sum(&mut acc, -1.0, &[a, a2], &[v1, v2]);
        let expect = SMatrix::<f64, 3, 1>::new(1.0, 2.0, 3.0) - a * v1 - a2 * v2;
        assert!((acc - expect).amax() < 1e-12);
        assert_eq!(mul(&SMatrix::<f64, 0, 4>::zeros(), &b).shape(), (0, 2));
    }

    #[test]
    fn lower_inverse_inverts() {
        let l = SMatrix::<f64, 4, 4>::from_fn(|i, j| {
            if i == j {
                1.5 + i as f64
            } else if i > j {
                0.3 * (i + 2 * j) as f64 - 0.4
            } else {
                0.0
            }
        });
        let err = (lower_inverse(&l) * l - SMatrix::<f64, 4, 4>::identity()).amax();
        assert!(err < 1e-14, "{err}");
    }
}
