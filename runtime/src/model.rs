//! The interface generated model code implements.

use nalgebra::{SMatrix, SVector};

use crate::real::Real;

/// A discrete-time optimal control model with a least-squares cost (and optionally general
/// cost terms), evaluated stage by stage.
///
/// Dimensions are const generics: `NX` states, `NU` controls, `NP` runtime parameters per
/// stage, `NY` stage residuals, `NYN` terminal residuals, `NG` general stage constraints,
/// `NGN` general terminal constraints. The cost is
/// `sum_k 1/2 |y(x_k, u_k, p_k) - yref_k|^2_W + 1/2 |y_N(x_N, p_N) - yref_N|^2_{W_N}`
/// (Gauss-Newton Hessian `J'WJ`), subject to `x_{k+1} = F(x_k, u_k, p_k)`, box bounds on `x`
/// and `u` and `lg <= h(x, u, p) <= ug` (hard, or soft with slack penalties: see
/// [`Rti::set_soft_penalties`](crate::Rti::set_soft_penalties)). A model with
/// [`GENERAL_COST`](Self::GENERAL_COST) adds general terms `l(x_k, u_k, p_k)` at every
/// stage and `l_N(x_N, p_N)` at the end ([`stage_cost`](Self::stage_cost),
/// [`terminal_cost`](Self::terminal_cost)), with their exact gradients and Hessians.
///
/// Every method writes its Jacobians into the given matrices and returns the value; none may
/// allocate or panic.
pub trait Model<
    T: Real,
    const NX: usize,
    const NU: usize,
    const NP: usize,
    const NY: usize,
    const NYN: usize,
    const NG: usize,
    const NGN: usize,
>
{
    /// The Jacobians of [`residual`](Self::residual) and
    /// [`terminal_residual`](Self::terminal_residual) are constants, the same at every
    /// `x`, `u`, `p` (residuals linear in `x` and `u`, as `x - xref`): the RTI then computes
    /// the Gauss-Newton terms `J'WJ` once per weight change instead of at every stage of every
    /// linearization. `false` (the default) is always correct; `true` for a residual whose
    /// Jacobians do change makes the QP's Hessians stale. The generator sets it from the
    /// symbolic Jacobians.
    const CONSTANT_RESIDUAL_JACOBIANS: bool = false;

    /// The Jacobians of [`residual`](Self::residual) alone are constants (the stage cost is
    /// linear least squares, the terminal one may not be: the probe model's, the probe's
    /// velocity at release). Then every stage has the same `J'WJ`, computed once per weight
    /// change, and the QP can keep one stage Hessian (`NH = 1`); the terminal `J'WJ` is
    /// computed at every linearization unless
    /// [`CONSTANT_RESIDUAL_JACOBIANS`](Self::CONSTANT_RESIDUAL_JACOBIANS) holds too. Defaults
    /// to that flag (constant Jacobians everywhere are constant at the stages); the same
    /// warning applies.
    const CONSTANT_STAGE_RESIDUAL_JACOBIANS: bool = Self::CONSTANT_RESIDUAL_JACOBIANS;

    /// `F(x, u, p)` with `A = dF/dx` and `B = dF/du`.
    fn dynamics(
        &self,
        x: &SVector<T, NX>,
        u: &SVector<T, NU>,
        p: &SVector<T, NP>,
        a: &mut SMatrix<T, NX, NX>,
        b: &mut SMatrix<T, NX, NU>,
    ) -> SVector<T, NX>;

    /// `F(x, u, p)` alone, for the full SQP's merit function. The default evaluates
    /// [`dynamics`](Self::dynamics) and drops the Jacobians; the generator emits the value
    /// without them (for QR-bench, 427 instructions a call against 3,022 with them).
    fn dynamics_value(
        &self,
        x: &SVector<T, NX>,
        u: &SVector<T, NU>,
        p: &SVector<T, NP>,
    ) -> SVector<T, NX> {
        let mut a = SMatrix::<T, NX, NX>::zeros();
        let mut b = SMatrix::<T, NX, NU>::zeros();
        self.dynamics(x, u, p, &mut a, &mut b)
    }

    /// The model implements [`dynamics_hessian`](Self::dynamics_hessian): the full SQP
    /// ([`Rti::solve_sqp`](crate::Rti::solve_sqp)) then adds the dynamics' curvature to the
    /// Gauss-Newton Hessian (exact-Hessian steps, in a solver with one Hessian per stage,
    /// `NH = N`). The generator sets it with its `exact_hessian` option.
    const EXACT_HESSIAN: bool = false;

    /// The dynamics' part of the Lagrangian Hessian: the Hessian of the scalar
    /// `pi' F(x, u, p)` over `(x, u)`, written as `hxx` (`NX x NX`), `hux` (`NU x NX`) and
    /// `huu` (`NU x NU`). `pi` are the multipliers of `x_{k+1} = F(x_k, u_k, p_k)` in the
    /// QP's sign convention (the Lagrangian adds `pi' (F - x_{k+1})`). Only called when
    /// [`EXACT_HESSIAN`](Self::EXACT_HESSIAN) holds; the default writes zeros.
    #[allow(clippy::too_many_arguments)]
    fn dynamics_hessian(
        &self,
        _x: &SVector<T, NX>,
        _u: &SVector<T, NU>,
        _p: &SVector<T, NP>,
        _pi: &SVector<T, NX>,
        hxx: &mut SMatrix<T, NX, NX>,
        hux: &mut SMatrix<T, NU, NX>,
        huu: &mut SMatrix<T, NU, NU>,
    ) {
        hxx.fill(T::ZERO);
        hux.fill(T::ZERO);
        huu.fill(T::ZERO);
    }

    /// Stage residual `y(x, u, p)` with its Jacobians.
    fn residual(
        &self,
        x: &SVector<T, NX>,
        u: &SVector<T, NU>,
        p: &SVector<T, NP>,
        jx: &mut SMatrix<T, NY, NX>,
        ju: &mut SMatrix<T, NY, NU>,
    ) -> SVector<T, NY>;

    /// Terminal residual `y_N(x, p)` with its Jacobian.
    fn terminal_residual(
        &self,
        x: &SVector<T, NX>,
        p: &SVector<T, NP>,
        jx: &mut SMatrix<T, NYN, NX>,
    ) -> SVector<T, NYN>;

    /// General stage constraints `h(x, u, p)` with their Jacobians (none by default).
    fn constraints(
        &self,
        _x: &SVector<T, NX>,
        _u: &SVector<T, NU>,
        _p: &SVector<T, NP>,
        cx: &mut SMatrix<T, NG, NX>,
        cu: &mut SMatrix<T, NG, NU>,
    ) -> SVector<T, NG> {
        cx.fill(T::ZERO);
        cu.fill(T::ZERO);
        SVector::zeros()
    }

    /// General terminal constraints `h_N(x, p)` with their Jacobian (none by default).
    fn terminal_constraints(
        &self,
        _x: &SVector<T, NX>,
        _p: &SVector<T, NP>,
        cx: &mut SMatrix<T, NGN, NX>,
    ) -> SVector<T, NGN> {
        cx.fill(T::ZERO);
        SVector::zeros()
    }

    /// The model has general cost terms ([`stage_cost`](Self::stage_cost),
    /// [`terminal_cost`](Self::terminal_cost)): the RTI adds their gradients to the QP's and
    /// their Hessians, projected onto the positive semidefinite cone, to its Hessians
    /// (which then differ from stage to stage: `NH = N`), and their values to the cost and
    /// the merit function. `false` (the default): the methods are not called and the solver
    /// runs exactly as without them.
    const GENERAL_COST: bool = false;

    /// The general stage cost `l(x, u, p)` with its gradient (`gx`, `gu`) and Hessian
    /// (`hxx`, `hux` = `d2l/du dx`, `huu`). Only called when
    /// [`GENERAL_COST`](Self::GENERAL_COST) holds; the default is zero.
    #[allow(clippy::too_many_arguments)]
    fn stage_cost(
        &self,
        _x: &SVector<T, NX>,
        _u: &SVector<T, NU>,
        _p: &SVector<T, NP>,
        gx: &mut SVector<T, NX>,
        gu: &mut SVector<T, NU>,
        hxx: &mut SMatrix<T, NX, NX>,
        hux: &mut SMatrix<T, NU, NX>,
        huu: &mut SMatrix<T, NU, NU>,
    ) -> T {
        gx.fill(T::ZERO);
        gu.fill(T::ZERO);
        hxx.fill(T::ZERO);
        hux.fill(T::ZERO);
        huu.fill(T::ZERO);
        T::ZERO
    }

    /// `l(x, u, p)` alone (the merit function and [`Rti::cost`](crate::Rti::cost)). The
    /// default evaluates [`stage_cost`](Self::stage_cost) and drops the derivatives.
    fn stage_cost_value(&self, x: &SVector<T, NX>, u: &SVector<T, NU>, p: &SVector<T, NP>) -> T {
        let (mut gx, mut gu) = (SVector::zeros(), SVector::zeros());
        let (mut hxx, mut hux, mut huu) = (SMatrix::zeros(), SMatrix::zeros(), SMatrix::zeros());
        self.stage_cost(x, u, p, &mut gx, &mut gu, &mut hxx, &mut hux, &mut huu)
    }

    /// The general terminal cost `l_N(x, p)` with its gradient and Hessian. Only called when
    /// [`GENERAL_COST`](Self::GENERAL_COST) holds; the default is zero.
    fn terminal_cost(
        &self,
        _x: &SVector<T, NX>,
        _p: &SVector<T, NP>,
        gx: &mut SVector<T, NX>,
        hxx: &mut SMatrix<T, NX, NX>,
    ) -> T {
        gx.fill(T::ZERO);
        hxx.fill(T::ZERO);
        T::ZERO
    }

    /// `l_N(x, p)` alone. The default evaluates [`terminal_cost`](Self::terminal_cost).
    fn terminal_cost_value(&self, x: &SVector<T, NX>, p: &SVector<T, NP>) -> T {
        let (mut gx, mut hxx) = (SVector::zeros(), SMatrix::zeros());
        self.terminal_cost(x, p, &mut gx, &mut hxx)
    }

    /// The general constraints' part of the Lagrangian Hessian: the Hessian of
    /// `mu' h(x, u, p)` over `(x, u)` (`mu` the rows' multipliers, `lam_u - lam_l`, as
    /// [`Rti::constraint_multipliers`](crate::Rti::constraint_multipliers)). Only called
    /// when [`EXACT_HESSIAN`](Self::EXACT_HESSIAN) holds; the default writes zeros (linear
    /// constraints, or a model that leaves their curvature out).
    #[allow(clippy::too_many_arguments)]
    fn constraints_hessian(
        &self,
        _x: &SVector<T, NX>,
        _u: &SVector<T, NU>,
        _p: &SVector<T, NP>,
        _mu: &SVector<T, NG>,
        hxx: &mut SMatrix<T, NX, NX>,
        hux: &mut SMatrix<T, NU, NX>,
        huu: &mut SMatrix<T, NU, NU>,
    ) {
        hxx.fill(T::ZERO);
        hux.fill(T::ZERO);
        huu.fill(T::ZERO);
    }

    /// The Hessian of `mu' h_N(x, p)` over `x` (terminal rows), as
    /// [`constraints_hessian`](Self::constraints_hessian).
    fn terminal_constraints_hessian(
        &self,
        _x: &SVector<T, NX>,
        _p: &SVector<T, NP>,
        _mu: &SVector<T, NGN>,
        hxx: &mut SMatrix<T, NX, NX>,
    ) {
        hxx.fill(T::ZERO);
    }
}
