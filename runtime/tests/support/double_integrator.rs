//! A double integrator with a general constraint, for the RTI tests.

use mpc_runtime::{Model, Real};
use nalgebra::{SMatrix, SVector};

/// Double integrator `x = (p, v)`, `u = a`, exact discretization; `y = (x, u)`; a general
/// constraint `p + v`.
#[derive(Clone, Copy, Debug)]
pub struct DoubleIntegrator {
    pub dt: f64,
}

impl<T: Real> Model<T, 2, 1, 0, 3, 2, 1, 0> for DoubleIntegrator {
    fn dynamics(
        &self,
        x: &SVector<T, 2>,
        u: &SVector<T, 1>,
        _p: &SVector<T, 0>,
        a: &mut SMatrix<T, 2, 2>,
        b: &mut SMatrix<T, 2, 1>,
    ) -> SVector<T, 2> {
        let h = T::lit(self.dt);
        *a = SMatrix::from_row_slice(&[T::ONE, h, T::ZERO, T::ONE]);
        *b = SMatrix::from_column_slice(&[h * h * T::lit(0.5), h]);
        *a * x + *b * u
    }
    fn residual(
        &self,
        x: &SVector<T, 2>,
        u: &SVector<T, 1>,
        _p: &SVector<T, 0>,
        jx: &mut SMatrix<T, 3, 2>,
        ju: &mut SMatrix<T, 3, 1>,
    ) -> SVector<T, 3> {
        *jx = SMatrix::from_row_slice(&[T::ONE, T::ZERO, T::ZERO, T::ONE, T::ZERO, T::ZERO]);
        *ju = SMatrix::from_column_slice(&[T::ZERO, T::ZERO, T::ONE]);
        SVector::from_column_slice(&[x[0], x[1], u[0]])
    }
    fn terminal_residual(
        &self,
        x: &SVector<T, 2>,
        _p: &SVector<T, 0>,
        jx: &mut SMatrix<T, 2, 2>,
    ) -> SVector<T, 2> {
        *jx = SMatrix::identity();
        *x
    }
    fn constraints(
        &self,
        x: &SVector<T, 2>,
        _u: &SVector<T, 1>,
        _p: &SVector<T, 0>,
        cx: &mut SMatrix<T, 1, 2>,
        cu: &mut SMatrix<T, 1, 1>,
    ) -> SVector<T, 1> {
        *cx = SMatrix::from_row_slice(&[T::ONE, T::ONE]);
        *cu = SMatrix::zeros();
        SVector::from_column_slice(&[x[0] + x[1]])
    }
}
