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
    let (ad, bd) = (&a.data.0, &b.data.0);
    let mut out = [[T::ZERO; R]; C];
    for j in 0..C {
        for k in 0..K {
            let bkj = bd[j][k];
            for i in 0..R {
                out[j][i] += ad[k][i] * bkj;
            }
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
            let mut s = T::ZERO;
            for k in 0..K {
                s += ad[i][k] * bd[j][k];
            }
            out[j][i] = s;
        }
    }
    SMatrix::from_array_storage(nalgebra::ArrayStorage(out))
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
        assert!((tr_mul(&a, &c) - a.transpose() * c).amax() < 1e-12);
        assert_eq!(mul(&SMatrix::<f64, 0, 4>::zeros(), &b).shape(), (0, 2));
    }
}
