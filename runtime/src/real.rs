//! The scalar type of a solver: `f32` or `f64`.

use nalgebra::RealField;

/// A floating-point scalar the solver runs in. Implemented for `f32` and `f64`; math goes
/// through `libm` (nalgebra's `libm` feature), so it works without `std`.
pub trait Real: RealField + Copy + Default + PartialOrd {
    /// 0
    const ZERO: Self;
    /// 1
    const ONE: Self;
    /// Machine epsilon.
    const EPSILON: Self;
    /// A large finite value standing for "no bound" (bounds beyond it are treated as absent).
    const INF: Self;
    /// `-INF`.
    const NEG_INF: Self;
    /// Default tolerance of the QP solver for this precision (stationarity and feasibility).
    const DEFAULT_TOL: Self;
    /// Default tolerance on the average complementarity. A bound with multiplier `lambda` ends
    /// about `mu / lambda` from where it should be, so this is tighter than `DEFAULT_TOL`.
    const DEFAULT_TOL_COMP: Self;
    /// QP tolerance (stationarity, feasibility, complementarity) of a real-time iteration: one
    /// Gauss-Newton step's linearization error is far above it, so solving each QP tighter only
    /// costs iterations (f64: 1e-6 instead of 1e-8/1e-10 changes the QR-bench closed loop by
    /// 2.4e-7 and needs 41 % fewer QP iterations).
    const RTI_TOL: Self;
    /// Complementarity tolerance of a real-time iteration (f64 1e-6; f32 its QP default).
    const RTI_TOL_COMP: Self;
    /// Default diagonal regularization of the Riccati factorization for this precision.
    const DEFAULT_REG: Self;
    /// Largest barrier weight `lam / t` the QP solver puts on a constraint row.
    const SIGMA_MAX: Self;
    /// Default step tolerance of the full SQP.
    const SQP_TOL: Self;
    /// Default initial complementarity of the QP solver.
    const DEFAULT_MU0: Self;
    /// Default iterative-refinement steps per Newton solve: none in f64, one in f32, where the
    /// Riccati matrices lose the accuracy it recovers.
    const DEFAULT_REFINE: u32;
    /// Default of [`QpSettings::polish`](crate::QpSettings::polish): on in f32, where the
    /// interior point's complementarity tolerance leaves weakly active bounds about
    /// `mu / lam` off, off in f64.
    const DEFAULT_POLISH: bool;
    /// Default of [`RtiSettings::sqp_loose_qps`](crate::RtiSettings::sqp_loose_qps): whether
    /// the full SQP solves its QPs by the interior point to 1e-3 and then the polish: in f64
    /// (QR-bench A: 24 % fewer instructions per step, the same closed loop to 1e-11 m), not
    /// in f32, where it costs SQP iterations (A: 11.91 per step instead of 10.74, B: 9.35
    /// instead of 7.88).
    const SQP_LOOSE_QPS: bool;

    /// Conversion from an `f64` literal (rounding for `f32`).
    fn lit(v: f64) -> Self;
    /// Conversion to `f64`.
    fn to_f64(self) -> f64;
    /// Whether the value is neither NaN nor infinite.
    fn finite(self) -> bool;
    /// Whether the value is NaN.
    fn nan(self) -> bool;
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f64::EPSILON;
    const INF: Self = 1e20;
    const NEG_INF: Self = -1e20;
    const DEFAULT_TOL: Self = 1e-8;
    const DEFAULT_TOL_COMP: Self = 1e-10;
    const RTI_TOL: Self = 1e-6;
    const RTI_TOL_COMP: Self = 1e-6;
    const DEFAULT_REG: Self = 1e-10;
    const SIGMA_MAX: Self = 3e23;
    const SQP_TOL: Self = 1e-6;
    const DEFAULT_MU0: Self = 100.0;
    const DEFAULT_REFINE: u32 = 0;
    const DEFAULT_POLISH: bool = false;
    const SQP_LOOSE_QPS: bool = true;

    #[inline]
    fn lit(v: f64) -> Self {
        v
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }
    #[inline]
    fn nan(self) -> bool {
        self.is_nan()
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f32::EPSILON;
    const INF: Self = 1e20;
    const NEG_INF: Self = -1e20;
    const DEFAULT_TOL: Self = 1e-5;
    const DEFAULT_TOL_COMP: Self = 1e-4;
    const RTI_TOL: Self = 1e-5;
    const RTI_TOL_COMP: Self = 1e-4;
    const DEFAULT_REG: Self = 1e-6;
    const SIGMA_MAX: Self = 1e8;
    const SQP_TOL: Self = 1e-4;
    const DEFAULT_MU0: Self = 100.0;
    const DEFAULT_REFINE: u32 = 1;
    const DEFAULT_POLISH: bool = true;
    const SQP_LOOSE_QPS: bool = false;

    #[inline]
    fn lit(v: f64) -> Self {
        v as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }
    #[inline]
    fn nan(self) -> bool {
        self.is_nan()
    }
}
