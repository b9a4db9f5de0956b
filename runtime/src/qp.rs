//! The structured OCP-QP and its primal-dual interior-point solver.
//!
//! ```text
//! min  sum_{k<N} ( 1/2 x_k'Q_k x_k + u_k'S_k x_k + 1/2 u_k'R_k u_k + gx_k'x_k + gu_k'u_k )
//!        + 1/2 x_N'Q_N x_N + gx_N'x_N
//! s.t. x_0 = x0 (given)
//!      x_{k+1} = A_k x_k + B_k u_k + f_k
//!      lbx_k <= x_k <= ubx_k (k >= 1),  lbu_k <= u_k <= ubu_k
//!      lg_k <= C_k x_k + D_k u_k <= ug_k,  lg_N <= C_N x_N <= ug_N
//! ```
//!
//! Bounds at or beyond `Real::INF` in magnitude are absent. The method is Mehrotra's
//! predictor-corrector; each Newton system is a linear-quadratic problem with the Hessian
//! `H + G' diag(lam/t) G`, solved by a backward Riccati recursion (Cholesky of
//! `R + B'PB`, `O(N (nx + nu)^3)`), factorized once per iteration and solved twice.
//!
//! # Soft general constraints
//!
//! A general-constraint row `i` (stage or terminal) with penalties `soft_l1[i] > 0` or
//! `soft_l2[i] > 0` is soft: each of its present sides gets a slack,
//!
//! ```text
//! min ... + sum_i ( l1_i (sl_i + su_i) + 1/2 l2_i (sl_i^2 + su_i^2) )
//! s.t. lg_i - sl_i <= C_i x + D_i u <= ug_i + su_i,   sl_i, su_i >= 0
//! ```
//!
//! so the QP is feasible whatever the soft rows' bounds (the L1 term is an exact penalty: a
//! row whose multiplier would stay below `l1` is met exactly when it can be). Rows with both
//! penalties zero are hard, as are the box bounds. The slacks are eliminated row by row
//! inside each Newton system (they are separable), which only changes the diagonal weight
//! and the gradient the row contributes to `C' D C`, so the Riccati recursion is unchanged;
//! their stationarity, feasibility and complementarity enter the residuals and the stopping
//! test. [`QpSolver::slacks`] and [`QpSolver::terminal_slacks`] return them. With no soft row
//! the arithmetic is that of the hard solver.

use nalgebra::{SMatrix, SVector};

use crate::kernels::{
    add_diagonal, lower_inverse, mul, mul_sparse, mul_sparse_add_into, mul_tr, scaled_transpose,
    sub_mul_tr_sum, symmetrize, tr_mul,
};
use crate::real::Real;
use crate::rows::{BoundError, Rhs, Rows, Soft, SubRows};

mod condense;
mod held;
mod polish;

use held::{Hold, Holds};
use polish::{ActiveSet, Side, Weight, weights};

type Mat<T, const R: usize, const C: usize> = SMatrix<T, R, C>;
type Vect<T, const R: usize> = SVector<T, R>;

/// The corrector's complementarity target is at least this times the (relative) stationarity
/// residual: driving complementarity to zero ahead of stationarity leaves the iteration on the
/// boundary, where the Newton systems are too ill-conditioned to repair stationarity (it
/// stalled on some random QPs at tight tolerances).
const MU_PER_STATIONARITY: f64 = 1e-2;

/// Smallest slack and multiplier of a dual warm start.
const WARM_T_FLOOR: f64 = 1e-1;
const WARM_LAM_FLOOR: f64 = 1e-4;

/// Iterations without primal progress after which a QP is declared infeasible.
const STALL_LIMIT: u32 = 10;

/// The cost Hessian of a stage `k < N` (in [`OcpQp::hessians`]).
#[derive(Clone, Copy, Debug)]
pub struct QpHessian<T: Real, const NX: usize, const NU: usize> {
    /// State Hessian `Q`.
    pub q: Mat<T, NX, NX>,
    /// Cross term `S` (`u'S x`).
    pub s: Mat<T, NU, NX>,
    /// Control Hessian `R`.
    pub r: Mat<T, NU, NU>,
}

impl<T: Real, const NX: usize, const NU: usize> QpHessian<T, NX, NU> {
    /// All zeros.
    pub const NEW: Self = QpHessian {
        q: crate::zeros(),
        s: crate::zeros(),
        r: crate::zeros(),
    };
}

/// Data of one stage `k < N` but its Hessian ([`QpHessian`], in [`OcpQp::hessians`]).
#[derive(Clone, Copy, Debug)]
pub struct QpStage<T: Real, const NX: usize, const NU: usize, const NG: usize> {
    /// State gradient.
    pub gx: Vect<T, NX>,
    /// Control gradient.
    pub gu: Vect<T, NU>,
    /// Dynamics `A`.
    pub a: Mat<T, NX, NX>,
    /// Dynamics `B`.
    pub b: Mat<T, NX, NU>,
    /// Dynamics offset `f`.
    pub f: Vect<T, NX>,
    /// State lower bound (ignored at stage 0, where the state is fixed).
    pub lbx: Vect<T, NX>,
    /// State upper bound (ignored at stage 0).
    pub ubx: Vect<T, NX>,
    /// Control lower bound.
    pub lbu: Vect<T, NU>,
    /// Control upper bound.
    pub ubu: Vect<T, NU>,
    /// General constraint matrix on the state.
    pub c: Mat<T, NG, NX>,
    /// General constraint matrix on the control.
    pub d: Mat<T, NG, NU>,
    /// General constraint lower bound.
    pub lg: Vect<T, NG>,
    /// General constraint upper bound.
    pub ug: Vect<T, NG>,
    /// Linear (L1, exact) penalty per general-constraint row on each side's slack; must be
    /// finite and `>= 0`. A row is soft where this or [`soft_l2`](Self::soft_l2) is positive.
    pub soft_l1: Vect<T, NG>,
    /// Quadratic (L2) penalty `1/2 l2 s^2` per general-constraint row on each side's slack;
    /// finite and `>= 0`. Both zero (the default): the row is hard.
    pub soft_l2: Vect<T, NG>,
}

/// Data of the terminal stage `N`.
#[derive(Clone, Copy, Debug)]
pub struct QpTerminal<T: Real, const NX: usize, const NGN: usize> {
    /// Terminal Hessian.
    pub q: Mat<T, NX, NX>,
    /// Terminal gradient.
    pub gx: Vect<T, NX>,
    /// Terminal state lower bound.
    pub lbx: Vect<T, NX>,
    /// Terminal state upper bound.
    pub ubx: Vect<T, NX>,
    /// Terminal general constraint matrix.
    pub c: Mat<T, NGN, NX>,
    /// Terminal general constraint lower bound.
    pub lg: Vect<T, NGN>,
    /// Terminal general constraint upper bound.
    pub ug: Vect<T, NGN>,
    /// Linear (L1) slack penalty per terminal general-constraint row (see
    /// [`QpStage::soft_l1`]).
    pub soft_l1: Vect<T, NGN>,
    /// Quadratic (L2) slack penalty per terminal general-constraint row (see
    /// [`QpStage::soft_l2`]).
    pub soft_l2: Vect<T, NGN>,
}

impl<T: Real, const NX: usize, const NU: usize, const NG: usize> QpStage<T, NX, NU, NG> {
    /// All zeros, bounds absent, general constraints hard (zero penalties).
    pub const NEW: Self = QpStage {
        gx: crate::zeros(),
        gu: crate::zeros(),
        a: crate::zeros(),
        b: crate::zeros(),
        f: crate::zeros(),
        lbx: crate::filled(T::NEG_INF),
        ubx: crate::filled(T::INF),
        lbu: crate::filled(T::NEG_INF),
        ubu: crate::filled(T::INF),
        c: crate::zeros(),
        d: crate::zeros(),
        lg: crate::filled(T::NEG_INF),
        ug: crate::filled(T::INF),
        soft_l1: crate::zeros(),
        soft_l2: crate::zeros(),
    };
}

impl<T: Real, const NX: usize, const NGN: usize> QpTerminal<T, NX, NGN> {
    /// All zeros, bounds absent, general constraints hard.
    pub const NEW: Self = QpTerminal {
        q: crate::zeros(),
        gx: crate::zeros(),
        lbx: crate::filled(T::NEG_INF),
        ubx: crate::filled(T::INF),
        c: crate::zeros(),
        lg: crate::filled(T::NEG_INF),
        ug: crate::filled(T::INF),
        soft_l1: crate::zeros(),
        soft_l2: crate::zeros(),
    };
}

/// A whole OCP-QP.
///
/// `NH` is `N`, a Hessian per stage, or `1`: one Hessian for every stage `k < N`, a cost that
/// does not change along the horizon (a least-squares cost with one weight and Jacobians that
/// are constants, as `x - xref`, gives one). With `1` the QP's data is smaller by `N - 1`
/// Hessians (`(N - 1)(NX + NU)^2` numbers); the arithmetic is that of `N` copies. Other values
/// fail to compile.
#[derive(Clone, Copy, Debug)]
pub struct OcpQp<
    T: Real,
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NH: usize = N,
> {
    /// The fixed initial state.
    pub x0: Vect<T, NX>,
    /// Stages `0..N`.
    pub stages: [QpStage<T, NX, NU, NG>; N],
    /// The Hessians of stages `0..N`: stage `k`'s is `hessians[k]` (`NH = N`) or
    /// `hessians[0]` (`NH = 1`).
    pub hessians: [QpHessian<T, NX, NU>; NH],
    /// Stage `N`.
    pub terminal: QpTerminal<T, NX, NGN>,
}

impl<
    T: Real,
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NH: usize,
> OcpQp<T, NX, NU, NG, NGN, N, NH>
{
    /// All zeros, bounds absent.
    pub const NEW: Self = OcpQp {
        x0: crate::zeros(),
        stages: [QpStage::NEW; N],
        hessians: {
            assert!(NH == N || NH == 1, "NH must be N or 1");
            [QpHessian::NEW; NH]
        },
        terminal: QpTerminal::NEW,
    };

    /// The Hessian of stage `k < N`, `None` beyond.
    pub fn hessian(&self, k: usize) -> Option<&QpHessian<T, NX, NU>> {
        if k < N {
            self.hessians.get(Self::slot(k))
        } else {
            None
        }
    }

    /// The index in [`hessians`](Self::hessians) of stage `k`'s Hessian.
    const fn slot(k: usize) -> usize {
        const { assert!(NH == N || NH == 1, "NH must be N or 1") };
        if NH == N { k } else { 0 }
    }

    /// The Hessian of stage `k < N` (the solver's loops run to `N`).
    pub(crate) fn h(&self, k: usize) -> &QpHessian<T, NX, NU> {
        &self.hessians[Self::slot(k)]
    }

    /// The Hessian of stage `k < N`, to write.
    pub(crate) fn h_mut(&mut self, k: usize) -> &mut QpHessian<T, NX, NU> {
        &mut self.hessians[Self::slot(k)]
    }

    /// All zeros, the bounds too (every variable fixed at 0): zero-filled memory in a
    /// `static`, for a QP whose every field is written before it is solved (the RTI's).
    pub(crate) const ZEROED: Self = {
        let mut qp = Self::NEW;
        let z = crate::zeros();
        let mut k = 0;
        while k < N {
            let s = &mut qp.stages[k];
            (s.lbx, s.ubx, s.lbu, s.ubu) = (z, z, crate::zeros(), crate::zeros());
            (s.lg, s.ug) = (crate::zeros(), crate::zeros());
            k += 1;
        }
        let t = &mut qp.terminal;
        (t.lbx, t.ubx, t.lg, t.ug) = (z, z, crate::zeros(), crate::zeros());
        qp
    };
}

impl<
    T: Real,
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NH: usize,
> Default for OcpQp<T, NX, NU, NG, NGN, N, NH>
{
    fn default() -> Self {
        Self::NEW
    }
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QpSettings<T> {
    /// Iteration limit (bounds the worst-case time).
    pub max_iter: u32,
    /// Tolerance on the stationarity residual (infinity norm, relative to the largest of the
    /// terms that make it up when that exceeds 1).
    pub tol_stat: T,
    /// Tolerance on the dynamics residual.
    pub tol_eq: T,
    /// Tolerance on the inequality residual.
    pub tol_ineq: T,
    /// Tolerance on the average complementarity `t'lam / m`.
    pub tol_comp: T,
    /// Diagonal regularization added to `R + B'PB` before its Cholesky factorization.
    pub reg: T,
    /// Start from the previous primal solution instead of zero.
    pub warm_start: bool,
    /// Start from the previous solve's multipliers (bounds and dynamics) when it succeeded.
    /// Real-time iterations solve one QP per control step whose active set rarely changes;
    /// there this cuts the iterations to a few.
    pub warm_start_dual: bool,
    /// Initial complementarity `t lam` of every inequality.
    pub mu0: T,
    /// Iterative-refinement steps per Newton solve (each costs one Riccati back-substitution,
    /// not a factorization); recovers accuracy the Riccati matrices lose to large barrier
    /// terms, which matters in `f32`.
    pub refine: u32,
    /// How the Newton systems are solved: Riccati recursion or condensing (see [`QpMethod`]).
    pub method: QpMethod,
    /// After a QP is solved, refine the solution by active-set iterations started from the
    /// interior point's (each solves the QP with the rows taken as active held as equalities
    /// and the others dropped, one factorization each: a primal-dual active-set method, at
    /// most 4 iterations, for a condensed QP; a primal one, at most 50, for the Riccati
    /// recursion), and keep the result if it satisfies every bound and its multipliers have
    /// the right signs (else the interior point's; see [`QpSolver::polished`]). Active rows
    /// end on their values; the residuals reported stay the interior point's. With the
    /// Riccati recursion, a solve stopped by the iteration limit is polished too, and if
    /// the polish is kept the status is `Solved` with the polish's residuals
    /// (complementarity zero); so is one whose Newton system broke down after its first
    /// iteration ([`QpStatus::NumericalError`]), even with this setting off. QPs with soft
    /// rows are not polished, nor are QPs solved by the Riccati recursion in a solver with
    /// condensing storage (`NC = N`). Default: [`Real::DEFAULT_POLISH`].
    pub polish: bool,
    /// Start from the last solve's active set (which control bounds, and with the Riccati
    /// recursion which rows, held).
    /// [`QpSolver::prepare`] factorizes the QP with those entries held on their bounds,
    /// which does not depend on `x0`: the condensed Hessian, or the Riccati recursion with
    /// the held controls eliminated and no barrier weights. [`QpSolver::solve_prepared`]
    /// then solves the QP on that set by substitution (for the Riccati recursion, one
    /// backward and one forward vector pass per step) and keeps the result if it is the
    /// QP's solution (every bound and row holds and the held entries' multipliers have
    /// their signs, to the tolerances). Otherwise primal-dual active-set iterations start
    /// from it (at most 4, one factorization each), and if they do not end on the
    /// solution either, the interior point solves the QP. A real-time iteration's QPs
    /// change little from one control step to the next, so the set usually holds and the
    /// feedback is a few products. The solution is exact where the set holds;
    /// [`QpInfo::iterations`] is then 0 and [`QpInfo::active_set_solves`] counts the
    /// solves. A solver's first QP (none solved since it was built) starts from the empty
    /// set: the unconstrained solution, then the active-set iterations. With the Riccati
    /// recursion the set also holds state bounds and general rows, hard and soft: each
    /// free, held at a bound, or (soft) violated, with its penalty in the factorization
    /// (`held.rs`). Default: off
    /// ([`RtiSettings::DEFAULT`](crate::RtiSettings) turns it on).
    pub warm_active_set: bool,
}

/// Whether condensing a QP with these dimensions is estimated cheaper per interior-point
/// iteration than the Riccati recursion: `(N NU)^3 / 6 <= N (2 NX^3 + 3 NX^2 NU)`
/// multiply-adds (dense Cholesky against the recursion's products). The rule of
/// [`QpMethod::Auto`] in a solver with both storages. The code generator gives condensing
/// storage only when asked (`mpcc build --qp-method condensed`): on the warm active set a
/// step costs one factorization, and the recursion's is the cheaper.
pub const fn condensing_pays(nx: usize, nu: usize, n: usize) -> bool {
    let (nx, nu, n) = (nx as u128, nu as u128, n as u128);
    let nz = n.saturating_mul(nu);
    let dense = nz.saturating_mul(nz).saturating_mul(nz);
    let cubic = nx.saturating_mul(nx).saturating_mul(nx);
    let mixed = nx.saturating_mul(nx).saturating_mul(nu);
    let riccati = cubic
        .saturating_mul(2)
        .saturating_add(mixed.saturating_mul(3))
        .saturating_mul(n)
        .saturating_mul(6);
    dense <= riccati
}

/// How [`QpSolver`] solves its Newton systems.
///
/// Condensing eliminates the states through the dynamics once per QP, in
/// [`QpSolver::prepare`] (it does not depend on `x0`): what is left is a dense QP in the
/// `N * NU` controls with box bounds, whose Newton systems are one dense Cholesky
/// factorization each, `O((N NU)^3)` against the Riccati recursion's `O(N (NX + NU)^3)`.
/// For short horizons with few controls (QR-bench: `N = 10`, `NU = 4`) that is several times
/// cheaper per iteration, and the feedback phase does no work on states until the solution
/// is known. It applies when the solver has condensing storage (`NC = N`) and the QP has no
/// state bounds (beyond stage 0, which `x0` fixes) and no general constraints; otherwise the
/// Riccati recursion is used whatever the setting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub enum QpMethod {
    /// Condensing when it applies and [`condensing_pays`]; the Riccati recursion otherwise.
    Auto = 0,
    /// Always the Riccati recursion.
    Riccati = 1,
    /// Condensing whenever it applies.
    Condensed = 2,
}

impl<T: Real> QpSettings<T> {
    /// Defaults for the precision: tolerances `Real::DEFAULT_TOL`, 50 iterations.
    pub const DEFAULT: Self = QpSettings {
        max_iter: 50,
        tol_stat: T::DEFAULT_TOL,
        tol_eq: T::DEFAULT_TOL,
        tol_ineq: T::DEFAULT_TOL,
        tol_comp: T::DEFAULT_TOL_COMP,
        reg: T::DEFAULT_REG,
        warm_start: false,
        warm_start_dual: false,
        mu0: T::DEFAULT_MU0,
        refine: T::DEFAULT_REFINE,
        method: QpMethod::Auto,
        polish: T::DEFAULT_POLISH,
        warm_active_set: false,
    };

    /// Every setting zero (`max_iter` 0): the settings of a zero-filled solver
    /// ([`QpSolver::ZEROED`]) until real ones are set.
    pub(crate) const ZERO: Self = QpSettings {
        max_iter: 0,
        tol_stat: T::ZERO,
        tol_eq: T::ZERO,
        tol_ineq: T::ZERO,
        tol_comp: T::ZERO,
        reg: T::ZERO,
        warm_start: false,
        warm_start_dual: false,
        mu0: T::ZERO,
        refine: 0,
        method: QpMethod::Auto,
        polish: false,
        warm_active_set: false,
    };
}

impl<T: Real> Default for QpSettings<T> {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Outcome of a QP solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub enum QpStatus {
    /// All residuals below tolerance.
    Solved = 0,
    /// The iteration limit was reached first.
    MaxIterations = 1,
    /// The constraints cannot be met (crossed bounds, or multipliers diverging).
    Infeasible = 2,
    /// The input contains NaN or infinite data (other than absent bounds), or a negative
    /// soft-constraint penalty.
    NonFiniteInput = 3,
    /// The Newton system could not be factorized even with increased regularization (and,
    /// with the Riccati recursion after the first iteration, the polish did not solve the
    /// QP on the interior point's active set; see [`QpSettings::polish`]).
    NumericalError = 4,
    /// A stage bounds more states than the solver has state-bound rows (`NBX` of
    /// [`QpSolver`]).
    TooManyStateBounds = 5,
}

/// Status and residuals of the last solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QpInfo<T> {
    /// How the solve ended.
    pub status: QpStatus,
    /// Interior-point iterations taken (0 when the warm active set or the active-set
    /// iterations after it solved the QP: [`QpSettings::warm_active_set`]).
    pub iterations: u32,
    /// Solves on an active set before the interior point ([`QpSettings::warm_active_set`]):
    /// 1 when the last solve's set held, more for each active-set iteration after it, 0
    /// without a warm active set.
    pub active_set_solves: u32,
    /// Stationarity residual (infinity norm).
    pub res_stat: T,
    /// Dynamics residual.
    pub res_eq: T,
    /// Inequality residual.
    pub res_ineq: T,
    /// Average complementarity.
    pub mu: T,
}

/// Primal and dual solution.
#[derive(Clone, Copy, Debug)]
pub struct QpSolution<T: Real, const NX: usize, const NU: usize, const N: usize> {
    /// States `x_0..x_{N-1}` (`x_0` is the given initial state).
    pub x: [Vect<T, NX>; N],
    /// Terminal state `x_N`.
    pub xn: Vect<T, NX>,
    /// Controls `u_0..u_{N-1}`.
    pub u: [Vect<T, NU>; N],
    /// Multipliers of the dynamics `x_{k+1} = A_k x_k + B_k u_k + f_k`.
    pub pi: [Vect<T, NX>; N],
}

impl<T: Real, const NX: usize, const NU: usize, const N: usize> QpSolution<T, NX, NU, N> {
    /// All zeros.
    pub const NEW: Self = QpSolution {
        x: [crate::zeros(); N],
        xn: crate::zeros(),
        u: [crate::zeros(); N],
        pi: [crate::zeros(); N],
    };

    /// State `k` for `k <= N`.
    pub fn state(&self, k: usize) -> Option<&Vect<T, NX>> {
        if k == N {
            Some(&self.xn)
        } else {
            self.x.get(k)
        }
    }
}

/// Interior-point and Riccati workspace for one QP size. Holds everything; never allocates.
///
/// The sizes beyond the QP's: `NC` is `0` (no condensing storage) or `N` (see [`QpMethod`]);
/// `NBX <= NX` is the number of state-bound rows per stage, taken by the states with a finite
/// bound in order (a stage bounding more is refused with
/// [`QpStatus::TooManyStateBounds`]); `NR` is `N`, or `0` for a solver without the Riccati
/// recursion's storage, which condenses every QP and needs `NC = N`, `NBX = 0` and no general
/// constraints. Other values fail to compile.
#[derive(Clone, Debug)]
pub struct QpSolver<
    T: Real,
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NC: usize = 0,
    const NBX: usize = NX,
    const NR: usize = N,
> {
    /// Settings used by [`solve`](Self::solve).
    pub settings: QpSettings<T>,
    sol: QpSolution<T, NX, NU, N>,
    rx: [SubRows<T, NX, NBX>; N],
    ru: [Rows<T, NU>; N],
    rg: [Rows<T, NG>; N],
    rxn: SubRows<T, NX, NBX>,
    rgn: Rows<T, NGN>,
    /// Slacks of the soft general-constraint rows.
    sg: [Soft<T, NG>; N],
    sgn: Soft<T, NGN>,
    /// Dynamics residuals `A x + B u + f - x_next`.
    rb: [Vect<T, NX>; NR],
    /// The soft rows' stationarity residual and the largest of its terms.
    soft_stat: [T; 2],
    /// `H y + g` per stage (without the inequality terms).
    hx: [Vect<T, NX>; NR],
    hu: [Vect<T, NU>; N],
    hxn: Vect<T, NX>,
    /// Riccati: `P_{k+1}`, `p_{k+1}`, `L^-1` for the Cholesky factor `L` of `R~ = R + B'PB`,
    /// `W' = S~'L^-T` for `S~ = S + B'PA`, and the feedforward term `y` (see
    /// [`lq_solve`](Self::lq_solve)).
    pn: [Mat<T, NX, NX>; NR],
    pvn: [Vect<T, NX>; NR],
    linv: [Mat<T, NU, NU>; NR],
    wt: [Mat<T, NX, NU>; NR],
    kv: [Vect<T, NU>; NR],
    /// Right-hand side of the linear-quadratic subproblem: reduced gradients and dynamics
    /// residuals.
    gxt: [Vect<T, NX>; NR],
    gut: [Vect<T, NU>; N],
    gnt: Vect<T, NX>,
    rbt: [Vect<T, NX>; NR],
    /// The same right-hand side as first built (iterative refinement overwrites the above).
    gx0: [Vect<T, NX>; NR],
    gu0: [Vect<T, NU>; N],
    gn0: Vect<T, NX>,
    /// Newton direction and new dynamics multipliers.
    dx: [Vect<T, NX>; NR],
    dxn: Vect<T, NX>,
    du: [Vect<T, NU>; N],
    pi_new: [Vect<T, NX>; NR],
    last_alpha: T,
    /// The multipliers of the last solve are a solution's (usable for a dual warm start).
    dual_valid: bool,
    /// The last [`prepare`](Self::prepare) condensed the QP (see [`condense`]).
    condensed: bool,
    /// The last solution is the polished one.
    polished: bool,
    /// The last [`prepare`](Self::prepare) started the iteration and factorized its first
    /// Newton system, with the settings `prefactor_settings`; the next solve uses it.
    prefactored: bool,
    prefactor_settings: QpSettings<T>,
    /// The control bounds held in the last solution (lower, upper), valid when `act_valid`
    /// ([`QpSettings::warm_active_set`]).
    act_lo: [[bool; NU]; N],
    act_hi: [[bool; NU]; N],
    act_valid: bool,
    /// The rows held in the last solution, with the control bounds above (Riccati
    /// recursion only).
    act_rows: Holds<NBX, NG, NGN, N>,
    /// The warm active set's solve holds rows or has soft ones: its rows are set and
    /// judged by the interior point's general residuals (`held.rs`).
    rows_on: bool,
    /// A solve has been attempted since the solver was built (before it, a warm active set
    /// starts from the empty set).
    solved_before: bool,
    /// The last [`prepare`](Self::prepare) factorized the condensed Hessian, or the Riccati
    /// recursion, on the stored active set (with the settings `prefactor_settings`); the
    /// next solve starts there.
    guessed: bool,
    /// The last solution came from an active set and is exact (a condensed QP's multipliers
    /// `H u + g` are in `hu`; the Riccati recursion's rows hold its slacks and multipliers).
    on_active_set: bool,
    /// Condensed Hessian and the Cholesky factor of `H + Sigma`, sharing one array of blocks:
    /// `H_ij` (`i >= j`) at `[j][i]`, on and above the diagonal, and the factor's `L_ij`
    /// (`i > j`) at `[i][j]`, below it; the factor's diagonal blocks apart (`ld`: `L_ii^-1`).
    /// The gradient at `x0 = 0` and its derivative by `x0` (`g = gc + xc x0`).
    tri: [[Mat<T, NU, NU>; NC]; NC],
    ld: [Mat<T, NU, NU>; NC],
    gc: [Vect<T, NU>; NC],
    xc: [Mat<T, NU, NX>; NC],
}

impl<
    T: Real,
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NC: usize,
    const NBX: usize,
    const NR: usize,
> Default for QpSolver<T, NX, NU, NG, NGN, N, NC, NBX, NR>
{
    fn default() -> Self {
        Self::NEW
    }
}

/// Which Newton system a Riccati factorization is of.
#[derive(Clone, Copy)]
enum Newton<
    'a,
    T: Real,
    const NBX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
> {
    /// The interior point's: each row with its barrier weight.
    Interior,
    /// The polish's: the rows of its active set with its penalty weight, the others none.
    Polish(&'a ActiveSet<T, NBX, NU, NG, NGN, N>),
    /// The warm active set's: the held controls (`true`) eliminated, and the rows as
    /// [`Holds`] says (held ones with the penalty weight, violated soft ones with their
    /// `l2`, the others none).
    Held(&'a [[bool; NU]; N], &'a Holds<NBX, NG, NGN, N>),
}

impl<
    'a,
    T: Real,
    const NBX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
> Newton<'a, T, NBX, NU, NG, NGN, N>
{
    /// The weights of the row set that `sides` picks from the polish's active set, and
    /// `holds` from the warm active set's rows (`None`: the controls, eliminated instead).
    fn weight<const K: usize>(
        self,
        sides: impl FnOnce(&'a ActiveSet<T, NBX, NU, NG, NGN, N>) -> &'a [Side; K],
        holds: impl FnOnce(&'a Holds<NBX, NG, NGN, N>) -> Option<&'a [Hold; K]>,
    ) -> Weight<'a, T, K> {
        match self {
            Newton::Interior => Weight::Barrier,
            Newton::Polish(a) => Weight::Active(sides(a), a.w),
            Newton::Held(_, h) => holds(h).map_or(Weight::Zero, Weight::Held),
        }
    }
}

/// Cholesky factorization of the symmetric part of `m` plus `reg` on the diagonal; when that
/// fails, up to three retries with a thousand times more, scaled by each diagonal entry.
fn regularized_cholesky<T: Real, const K: usize>(
    m: Mat<T, K, K>,
    reg: T,
) -> Option<nalgebra::Cholesky<T, nalgebra::Const<K>>> {
    let sym = (m + m.transpose()) * T::lit(0.5);
    let mut reg = reg;
    for attempt in 0..4 {
        let mut m = sym;
        for i in 0..K {
            // First attempt: the plain regularization. Retries scale it with each diagonal
            // entry, which rescues the end game, where barrier terms of active bounds dwarf
            // everything else and rounding breaks definiteness.
            let d = m[(i, i)];
            m[(i, i)] = if attempt == 0 {
                d + reg
            } else {
                d + reg * d.abs().max(T::ONE)
            };
        }
        if let Some(chol) = nalgebra::Cholesky::new(m) {
            return Some(chol);
        }
        reg = (reg * T::lit(1e3)).max(T::EPSILON * T::lit(1e3));
    }
    None
}

/// Every entry is finite: `v * 0` is `0` for finite `v` and NaN otherwise, so the sums are
/// `0` exactly when all are (one branch-free pass; this check runs on every QP's data). Eight
/// independent sums, so the pass vectorizes (one sum would be a chain of dependent adds).
fn finite_mat<T: Real, const R: usize, const C: usize>(m: &Mat<T, R, C>) -> bool {
    let (chunks, rest) = m.as_slice().as_chunks::<8>();
    let mut acc = [T::ZERO; 8];
    for c in chunks {
        for (a, &v) in acc.iter_mut().zip(c) {
            *a += v * T::ZERO;
        }
    }
    for (a, &v) in acc.iter_mut().zip(rest) {
        *a += v * T::ZERO;
    }
    acc.iter().fold(T::ZERO, |s, &a| s + a) == T::ZERO
}

fn no_nan<T: Real, const R: usize>(v: &Vect<T, R>) -> bool {
    !v.as_slice().iter().any(|x| x.nan())
}

/// Soft-constraint penalties are finite and nonnegative.
fn penalties_ok<T: Real, const R: usize>(v: &Vect<T, R>) -> bool {
    v.as_slice().iter().all(|x| x.finite() && *x >= T::ZERO)
}

impl<
    T: Real,
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NC: usize,
    const NBX: usize,
    const NR: usize,
> QpSolver<T, NX, NU, NG, NGN, N, NC, NBX, NR>
{
    /// A solver with default settings; usable in a `static`. `NC`, `NBX` and `NR` as in the
    /// type's docs; other values fail to compile.
    pub const NEW: Self = QpSolver {
        settings: QpSettings::DEFAULT,
        sol: QpSolution::NEW,
        rx: [SubRows::NEW; N],
        ru: [Rows::NEW; N],
        rg: [Rows::NEW; N],
        rxn: SubRows::NEW,
        rgn: Rows::NEW,
        sg: [Soft::NEW; N],
        sgn: Soft::NEW,
        rb: [crate::zeros(); NR],
        soft_stat: [T::ZERO; 2],
        hx: [crate::zeros(); NR],
        hu: [crate::zeros(); N],
        hxn: crate::zeros(),
        pn: [crate::zeros(); NR],
        pvn: [crate::zeros(); NR],
        linv: [crate::zeros(); NR],
        wt: [crate::zeros(); NR],
        kv: [crate::zeros(); NR],
        gxt: [crate::zeros(); NR],
        gut: [crate::zeros(); N],
        gnt: crate::zeros(),
        rbt: [crate::zeros(); NR],
        gx0: [crate::zeros(); NR],
        gu0: [crate::zeros(); N],
        gn0: crate::zeros(),
        dx: [crate::zeros(); NR],
        dxn: crate::zeros(),
        du: [crate::zeros(); N],
        pi_new: [crate::zeros(); NR],
        last_alpha: T::ZERO,
        dual_valid: false,
        condensed: {
            assert!(NC == 0 || NC == N, "NC must be 0 or N");
            assert!(NR == 0 || NR == N, "NR must be 0 or N");
            assert!(
                NR == N || (NC == N && NBX == 0 && NG == 0 && NGN == 0),
                "NR = 0 (no Riccati storage) needs NC = N, NBX = 0 and no general constraints"
            );
            false
        },
        polished: false,
        prefactored: false,
        prefactor_settings: QpSettings::ZERO,
        act_lo: [[false; NU]; N],
        act_hi: [[false; NU]; N],
        act_valid: false,
        act_rows: Holds::FREE,
        rows_on: false,
        solved_before: false,
        guessed: false,
        on_active_set: false,
        tri: [[crate::zeros(); NC]; NC],
        ld: [crate::zeros(); NC],
        gc: [crate::zeros(); NC],
        xc: [crate::zeros(); NC],
    };

    /// [`NEW`](Self::NEW) with every setting zero (`max_iter` 0; set [`settings`](Self::settings)
    /// before solving): all of it zero bits, so a `static` of it is zero-filled memory (`.bss`)
    /// rather than an initial image in flash.
    pub(crate) const ZEROED: Self = QpSolver {
        settings: QpSettings::ZERO,
        ..Self::NEW
    };

    /// Whether the last [`prepare`](Self::prepare) condensed the QP (see [`QpMethod`]).
    pub fn condensed(&self) -> bool {
        self.condensed
    }

    /// Whether the iteration works on the condensed QP: always without Riccati storage
    /// (`NR = 0`; the QP is condensed before the iteration starts), which leaves the Riccati
    /// recursion out of such a build.
    fn dense(&self) -> bool {
        NR != N || self.condensed
    }

    /// Step length of the last interior-point iteration.
    pub fn last_step_length(&self) -> T {
        self.last_alpha
    }

    /// Moves the dynamics multipliers of the last solution one stage forward (the last
    /// stage's kept), as [`Rti`](crate::Rti) shifts its trajectory: the full SQP's
    /// exact Hessian evaluates them at the shifted stages.
    pub(crate) fn shift_multipliers(&mut self) {
        for k in 1..N {
            self.sol.pi[k - 1] = self.sol.pi[k];
        }
    }

    /// The last solution (primal and dynamics multipliers).
    pub fn solution(&self) -> &QpSolution<T, NX, NU, N> {
        &self.sol
    }

    /// Lower and upper slacks `(sl, su)` of stage `k < N`'s general constraints in the last
    /// solution (zero for hard rows and absent sides); `None` for `k >= N`.
    pub fn slacks(&self, k: usize) -> Option<(Vect<T, NG>, Vect<T, NG>)> {
        self.sg.get(k).map(|s| (s.sl, s.su))
    }

    /// Lower and upper slacks `(sl, su)` of the terminal general constraints in the last
    /// solution (zero for hard rows and absent sides).
    pub fn terminal_slacks(&self) -> (Vect<T, NGN>, Vect<T, NGN>) {
        (self.sgn.sl, self.sgn.su)
    }

    /// Lower and upper multipliers `(lam_l, lam_u)` of stage `k < N`'s general constraints
    /// as the last interior-point solve left them (zero on absent sides).
    pub(crate) fn row_multipliers(&self, k: usize) -> Option<(Vect<T, NG>, Vect<T, NG>)> {
        self.rg.get(k).map(|r| (r.ll, r.lu))
    }

    /// [`row_multipliers`](Self::row_multipliers) of the terminal general constraints.
    pub(crate) fn terminal_row_multipliers(&self) -> (Vect<T, NGN>, Vect<T, NGN>) {
        (self.rgn.ll, self.rgn.lu)
    }

    /// Sets the primal starting point used when `settings.warm_start` is on.
    pub fn set_initial_guess(&mut self, guess: &QpSolution<T, NX, NU, N>) {
        self.sol = *guess;
        // The starting point `prepare` built came from the guess it replaces.
        self.prefactored = false;
    }

    fn check_input<const NH: usize>(&self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) -> bool {
        qp.x0.iter().all(|v| v.finite()) && self.check_stages(qp)
    }

    /// Whether the stage and terminal data (all but `x0`) are finite and the penalties
    /// non-negative.
    fn check_stages<const NH: usize>(&self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) -> bool {
        for h in &qp.hessians {
            if !(finite_mat(&h.q) && finite_mat(&h.s) && finite_mat(&h.r)) {
                return false;
            }
        }
        for s in &qp.stages {
            let mats = finite_mat(&s.gx)
                && finite_mat(&s.gu)
                && finite_mat(&s.a)
                && finite_mat(&s.b)
                && finite_mat(&s.f)
                && finite_mat(&s.c)
                && finite_mat(&s.d);
            let bounds = no_nan(&s.lbx)
                && no_nan(&s.ubx)
                && no_nan(&s.lbu)
                && no_nan(&s.ubu)
                && no_nan(&s.lg)
                && no_nan(&s.ug);
            if !(mats && bounds && penalties_ok(&s.soft_l1) && penalties_ok(&s.soft_l2)) {
                return false;
            }
        }
        let t = &qp.terminal;
        finite_mat(&t.q)
            && finite_mat(&t.gx)
            && finite_mat(&t.c)
            && no_nan(&t.lbx)
            && no_nan(&t.ubx)
            && no_nan(&t.lg)
            && no_nan(&t.ug)
            && penalties_ok(&t.soft_l1)
            && penalties_ok(&t.soft_l2)
    }

    fn load_bounds<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> Result<(), BoundError> {
        for (k, s) in qp.stages.iter().enumerate() {
            if let (Some(rx), Some(ru), Some(rg)) =
                (self.rx.get_mut(k), self.ru.get_mut(k), self.rg.get_mut(k))
            {
                rx.set_bounds(&s.lbx, &s.ubx, k > 0)?;
                ru.set_bounds(&s.lbu, &s.ubu, true)?;
                rg.set_bounds(&s.lg, &s.ug, true)?;
                if let Some(sg) = self.sg.get_mut(k) {
                    sg.load(&s.soft_l1, &s.soft_l2, rg);
                }
            }
        }
        let t = &qp.terminal;
        self.rxn.set_bounds(&t.lbx, &t.ubx, true)?;
        self.rgn.set_bounds(&t.lg, &t.ug, true)?;
        self.sgn.load(&t.soft_l1, &t.soft_l2, &self.rgn);
        Ok(())
    }

    fn info(&self, status: QpStatus, iterations: u32, res: [T; 4]) -> QpInfo<T> {
        QpInfo {
            status,
            iterations,
            active_set_solves: 0,
            res_stat: res[0],
            res_eq: res[1],
            res_ineq: res[2],
            mu: res[3],
        }
    }

    /// Solves `qp`: [`prepare`](Self::prepare) then [`solve_prepared`](Self::solve_prepared).
    /// The solution is available from [`solution`](Self::solution) whatever the status (for a
    /// status other than `Solved` it is the last iterate).
    pub fn solve<const NH: usize>(&mut self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) -> QpInfo<T> {
        self.prepare(qp);
        self.solve_prepared(qp)
    }

    /// The part of a solve that does not depend on `x0`: condenses `qp` when
    /// [`QpMethod`] says so, then builds the interior point's starting point and factorizes
    /// its first Newton system (neither depends on `x0` unless stage 0 has general rows with
    /// a bound; then that is left to the solve). With [`QpSettings::warm_active_set`] and a
    /// stored active set, a condensed QP's Hessian is factorized on that set instead, and
    /// the interior point's start is left to the solve, which needs it only where the set
    /// misses. A real-time iteration calls it in its preparation phase, before the state is
    /// measured.
    ///
    /// The QP's data are checked and its bounds loaded here too, so that
    /// [`solve_prepared`](Self::solve_prepared) checks only `x0`; data that fail the check
    /// are not prepared, and `solve_prepared` then reports them.
    pub fn prepare<const NH: usize>(&mut self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) {
        self.prefactored = false;
        self.guessed = false;
        self.condensed = self.condensing_applies(qp)
            && self.check_stages(qp)
            && self.load_bounds(qp).is_ok()
            && self.condense(qp);
        let ready =
            self.condensed || (NR == N && self.check_stages(qp) && self.load_bounds(qp).is_ok());
        // The last solve's active set, factorized: the solve starts there (and the interior
        // point, if it is needed, from scratch).
        // A solver's first QP has no last active set: it starts from the empty one (the
        // unconstrained solution, then active-set moves).
        if ready && self.settings.warm_active_set && !self.act_valid && !self.solved_before {
            self.store_active_set(&[[false; NU]; N], &[[false; NU]; N]);
        }
        if ready && self.settings.warm_active_set && self.act_valid {
            self.guessed = if self.condensed {
                self.prepare_active_set()
            } else {
                self.prepare_held(qp)
            };
            self.prefactor_settings = self.settings;
            if self.guessed {
                return;
            }
        }
        // The interior point's starting point and its first Newton system depend on `x0`
        // only through stage 0's general rows: without them both are built here.
        if ready && self.rg.first().is_none_or(|r| r.count() == 0) {
            self.start(qp);
            self.prefactored = self.factorize(qp, Newton::Interior);
            self.prefactor_settings = self.settings;
        }
    }

    /// Solves `qp` with the work of the last [`prepare`](Self::prepare), which must have been
    /// given the same QP except for `x0` ([`solve`](Self::solve) is the safe call). Settings
    /// changed since, or an initial guess set since, leave the prepared factorization unused
    /// (the solve starts from scratch, on the prepared condensed QP if there is one). Without
    /// a `prepare` since the last solve, a QP the Riccati recursion solves is solved whole.
    pub fn solve_prepared<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> QpInfo<T> {
        self.on_active_set = false;
        self.solved_before = true;
        let guessed = core::mem::replace(&mut self.guessed, false)
            && self.prefactor_settings == self.settings;
        let mut solves = 0;
        if guessed {
            let warm = if self.condensed {
                self.solve_on_warm_active_set(qp)
            } else {
                self.solve_held(qp)
            };
            match warm {
                Ok(info) => return info,
                // Where rows were held, their multipliers come from a penalty iteration that
                // did not settle (a soft row's may be far beyond its `l1`): the interior point
                // starts afresh rather than from them.
                Err(n) => {
                    solves = n;
                    if self.rows_on {
                        self.dual_valid = false;
                    }
                }
            }
        }
        let mut info = self.iterate(qp);
        info.active_set_solves = solves;
        let polish = self.settings.polish && info.status == QpStatus::Solved;
        if self.condensed && info.status != QpStatus::NonFiniteInput {
            if polish {
                self.polished = self.condensed_polish();
            }
            if info.status == QpStatus::Solved {
                if !self.polished && self.settings.warm_active_set {
                    self.active_set_of_interior_point();
                }
            } else {
                self.act_valid = false;
            }
            self.expand(qp);
            return info;
        }
        // The warm active set of the Riccati recursion, for the next solve.
        if self.settings.warm_active_set {
            if info.status == QpStatus::Solved {
                self.held_set_of_interior_point();
            } else {
                self.act_valid = false;
            }
        }
        // Not for solvers with condensing storage, whose QPs are condensed but when a state
        // bound or general row appears: that keeps this polish (11 KB of code on a
        // Cortex-M4F, which has 1 KB to spare under its 64 KiB target) out of their builds.
        // An interior point stopped by the iteration limit is polished too: a polish that
        // is kept meets the tolerances with exact complementarity, so the QP is solved.
        // So is one whose Newton system broke down after some iterations, whatever the
        // polish setting: at tight tolerances the barrier weights of active rows reach
        // 1e15 and more, and rounding in the Riccati recursion (`P = ... - W'W`) can leave
        // `R + B'PB` indefinite, while the active set is long settled. The polish solves
        // the QP on that set without barrier weights.
        let limit = info.status == QpStatus::MaxIterations;
        let broke = info.status == QpStatus::NumericalError && info.iterations > 0;
        if NC == 0
            && ((self.settings.polish && (polish || limit)) || broke)
            && let Some([res_stat, res_eq, res_ineq]) = self.riccati_polish(qp)
        {
            self.polished = true;
            if limit || broke {
                return QpInfo {
                    status: QpStatus::Solved,
                    res_stat,
                    res_eq,
                    res_ineq,
                    mu: T::ZERO,
                    ..info
                };
            }
        }
        info
    }

    /// Polishes the last solve's solution of `qp` (which must be the QP solved, and the solve
    /// must have returned [`QpStatus::Solved`]) with the current settings, as [`QpSettings::polish`] does at the end of a solve, whatever that
    /// setting: for an interior point stopped early on purpose and polished to tighter
    /// tolerances than it ran to (the polish of a QP solved by the Riccati recursion keeps
    /// its result only if it meets the tolerances). Returns whether the polish was kept
    /// ([`polished`](Self::polished)); if not, the solution is the interior point's. QPs
    /// with soft rows, and QPs solved by the Riccati recursion in a solver with condensing
    /// storage, are not polished.
    pub fn polish<const NH: usize>(&mut self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) -> bool {
        self.polished = false;
        // A solution from the warm active set is exact: it only needs checking against
        // these settings' tolerances.
        if self.on_active_set {
            self.polished = if self.condensed {
                self.active_set_solution_optimal()
            } else {
                self.held_solution_optimal(qp)
            };
            if self.polished {
                return true;
            }
        }
        if self.condensed {
            self.polished = self.condensed_polish();
            self.expand(qp);
        } else if NC == 0 {
            self.polished = self.riccati_polish(qp).is_some();
        }
        self.polished
    }

    /// Whether the last solve's solution is the polished one ([`QpSettings::polish`]).
    pub fn polished(&self) -> bool {
        self.polished
    }

    /// The interior point's starting point: the primal start (the previous solution with
    /// [`QpSettings::warm_start`], else zero; `x_0 = x0`), and each row's slacks and
    /// multipliers (from the previous solve's with a valid dual warm start). Only stage 0's
    /// general rows depend on `x0`.
    fn start<const NH: usize>(&mut self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) {
        let dual_warm = self.settings.warm_start_dual && self.dual_valid;
        if !self.settings.warm_start {
            let pi = self.sol.pi;
            self.sol = QpSolution::NEW;
            if dual_warm {
                self.sol.pi = pi;
            }
        }
        if let Some(x) = self.sol.x.first_mut() {
            *x = qp.x0;
        }
        let floor = T::ONE;
        let mu0 = self.settings.mu0;
        let (t_floor, lam_floor) = (T::lit(WARM_T_FLOOR), T::lit(WARM_LAM_FLOOR));
        for k in 0..N {
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            let s = &qp.stages[k];
            let g = s.c * x + s.d * u;
            if dual_warm {
                self.rx[k].warm_init(&x, t_floor, lam_floor);
                self.ru[k].warm_init(&u, t_floor, lam_floor);
                self.rg[k].warm_init(&g, t_floor, lam_floor);
                self.sg[k].warm_init(&mut self.rg[k], &g, t_floor, lam_floor);
            } else {
                self.rx[k].init(&x, floor, mu0);
                self.ru[k].init(&u, floor, mu0);
                self.rg[k].init(&g, floor, mu0);
                self.sg[k].init(&mut self.rg[k], &g, floor, mu0);
            }
        }
        let xn = self.sol.xn;
        let gn = qp.terminal.c * xn;
        if dual_warm {
            self.rxn.warm_init(&xn, t_floor, lam_floor);
            self.rgn.warm_init(&gn, t_floor, lam_floor);
            self.sgn.warm_init(&mut self.rgn, &gn, t_floor, lam_floor);
        } else {
            self.rxn.init(&xn, floor, mu0);
            self.rgn.init(&gn, floor, mu0);
            self.sgn.init(&mut self.rgn, &gn, floor, mu0);
        }
    }

    /// The interior-point iteration: the input checked (or `prepare`'s checks and first
    /// factorization used), the start, then a stop test and Mehrotra's predictor-corrector
    /// step per iteration, up to the iteration limit.
    fn iterate<const NH: usize>(&mut self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) -> QpInfo<T> {
        self.polished = false;
        let pre = match self.check_and_load(qp) {
            Ok(pre) => pre,
            Err(status) => return self.info(status, 0, [T::ZERO; 4]),
        };
        let m_real = T::lit(self.inequality_count().max(1) as f64);

        if pre {
            if let Some(x) = self.sol.x.first_mut() {
                *x = qp.x0;
            }
        } else {
            self.start(qp);
        }
        self.dual_valid = false;
        if self.dense() {
            self.condensed_gradient(qp);
        }

        let st = self.settings;
        let diverge = T::lit(1e12).min(T::ONE / (T::EPSILON * T::EPSILON));
        let mut res;
        // Primal infeasibility of the previous iteration and how many iterations in a row it
        // has not decreased (`stop_test`).
        let mut progress = (T::INF, 0u32);
        // The Riccati recursion's stationarity residual costs about as much as the others; it
        // is computed in the first iteration, when the others would let the iteration stop,
        // and when it ends. In between, its estimate: a step of length alpha shrinks it by
        // (1 - alpha), as it is linear in the variables and the Newton step zeroes it.
        let mut stat = T::INF;
        for iter in 0..st.max_iter {
            res = self.residuals(qp);
            let mu = res[3] / m_real;
            res[3] = mu;
            if !self.dense() {
                let others = res[1] <= st.tol_eq && res[2] <= st.tol_ineq && mu <= st.tol_comp;
                res[0] = if iter == 0 || others {
                    self.stationarity(qp)
                } else {
                    stat
                };
            }
            stat = res[0];
            if let Some(status) = self.stop_test(&st, &res, &mut progress, diverge) {
                return if status == QpStatus::Solved {
                    self.dual_valid = true;
                    self.info(status, iter, res)
                } else {
                    self.info(status, iter, self.exact(qp, res))
                };
            }
            // The first Newton system does not depend on `x0`: `prepare` may have factorized it.
            let factorized = (pre && iter == 0) || self.factorize(qp, Newton::Interior);
            if !factorized {
                return self.info(QpStatus::NumericalError, iter, self.exact(qp, res));
            }
            let alpha = self.predictor_corrector(qp, st.tol_comp, res[0], mu, m_real);
            stat *= T::ONE - alpha;
        }
        res = self.residuals(qp);
        res = self.exact(qp, res);
        res[3] /= m_real;
        let status = if res[0] <= st.tol_stat
            && res[1] <= st.tol_eq
            && res[2] <= st.tol_ineq
            && res[3] <= st.tol_comp
        {
            QpStatus::Solved
        } else {
            QpStatus::MaxIterations
        };
        self.dual_valid = status == QpStatus::Solved;
        self.info(status, st.max_iter, res)
    }

    /// The checks before the interior point ([`iterate`](Self::iterate)): after a `prepare`
    /// (which checked the rest and loaded the bounds) only `x0`'s; else the whole input's,
    /// with the bounds loaded and, without Riccati storage, the QP condensed. `Ok(true)`
    /// where `prepare` started the iteration and factorized its first Newton system with the
    /// current settings; the status to return otherwise.
    fn check_and_load<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> Result<bool, QpStatus> {
        let pre = core::mem::replace(&mut self.prefactored, false)
            && self.prefactor_settings == self.settings;
        if self.condensed || pre {
            if !qp.x0.iter().all(|v| v.finite()) {
                return Err(QpStatus::NonFiniteInput);
            }
            return Ok(pre);
        }
        if !self.check_input(qp) {
            return Err(QpStatus::NonFiniteInput);
        }
        match self.load_bounds(qp) {
            Ok(()) => {}
            Err(BoundError::TooMany) => return Err(QpStatus::TooManyStateBounds),
            Err(_) => return Err(QpStatus::Infeasible),
        }
        // Without Riccati storage every QP is condensed (the solver's dimensions allow no
        // other inequality than control bounds): this one had no `prepare`.
        if NR != N {
            self.condensed = self.condense(qp);
            if !self.condensed {
                return Err(QpStatus::NumericalError);
            }
        }
        Ok(pre)
    }

    /// The number of inequality sides the interior point holds (slacks and multipliers),
    /// by which its complementarity is averaged.
    fn inequality_count(&self) -> usize {
        self.rx.iter().map(|r| r.count()).sum::<usize>()
            + self.ru.iter().map(Rows::count).sum::<usize>()
            + self.rg.iter().map(Rows::count).sum::<usize>()
            + self.sg.iter().map(Soft::count).sum::<usize>()
            + self.rxn.count()
            + self.rgn.count()
            + self.sgn.count()
    }

    /// The interior point's stop test at residuals `res` (`res[3]`: the average
    /// complementarity): `Solved` where they meet the tolerances; `Infeasible` where one is
    /// not finite, the primal residual above its tolerance has not decreased for
    /// `STALL_LIMIT` iterations in a row (`progress`: the last primal residual and that
    /// count; a feasible problem's shrinks by (1 - alpha) every iteration, one stuck for many
    /// iterations means the constraints cannot be met), or a multiplier beyond `diverge`;
    /// `None` to go on.
    #[inline]
    fn stop_test(
        &self,
        st: &QpSettings<T>,
        res: &[T; 4],
        progress: &mut (T, u32),
        diverge: T,
    ) -> Option<QpStatus> {
        if !res.iter().all(|r| r.finite()) {
            return Some(QpStatus::Infeasible);
        }
        let (prev_primal, stalled) = progress;
        let primal = res[1].max(res[2]);
        if primal > st.tol_eq.max(st.tol_ineq) && primal >= T::lit(0.99) * *prev_primal {
            *stalled += 1;
            if *stalled >= STALL_LIMIT {
                return Some(QpStatus::Infeasible);
            }
        } else {
            *stalled = 0;
        }
        *prev_primal = primal;
        if res[0] <= st.tol_stat
            && res[1] <= st.tol_eq
            && res[2] <= st.tol_ineq
            && res[3] <= st.tol_comp
        {
            return Some(QpStatus::Solved);
        }
        if self.max_multiplier() > diverge {
            return Some(QpStatus::Infeasible);
        }
        None
    }

    /// Mehrotra's predictor-corrector step on the factorized Newton system, at
    /// stationarity residual `res_stat` and average complementarity `mu` over `m_real`
    /// inequality sides; the step length taken.
    #[inline]
    fn predictor_corrector<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        tol_comp: T,
        res_stat: T,
        mu: T,
        m_real: T,
    ) -> T {
        // Predictor.
        self.newton_direction(qp, Rhs::Affine);
        self.save_affine();
        let alpha_aff = self.max_step(T::ONE);
        let mu_aff = self.complementarity_after(alpha_aff) / m_real;
        let ratio = if mu > T::ZERO { mu_aff / mu } else { T::ZERO };
        let sigma = ratio * ratio * ratio;
        // Corrector. Its complementarity target never goes below a tenth of the tolerance:
        // driving slacks further down only buries them in rounding noise (in f32 that breaks
        // the iteration), and is not needed to stop. Nor below a fraction of the
        // stationarity residual, except for a condensed QP: there that residual holds what
        // the Riccati recursion sees as the dynamics residual (the change of x0 above all),
        // relative to fewer terms, and the floor only holds complementarity back while
        // Newton steps remove it (one more iteration per QP on QR-bench); with control
        // bounds alone the Newton systems stay well conditioned near the boundary (the
        // random QPs against clarabel).
        let stat_floor = if self.dense() {
            T::ZERO
        } else {
            res_stat * T::lit(MU_PER_STATIONARITY)
        };
        let target = (sigma * mu).max(tol_comp * T::lit(0.1)).max(stat_floor);
        // When the predictor is blocked almost at once, its second-order term is a poor
        // prediction and can be huge; leaving it out (plain centering) stops the cycling
        // Mehrotra's method is known for on such steps.
        let weight = if alpha_aff < T::lit(0.1) {
            T::ZERO
        } else {
            T::ONE
        };
        self.newton_direction(qp, Rhs::Corrector(target, weight));
        let tau = T::lit(0.995);
        let alpha = (tau * self.max_step(T::lit(1e30))).min(T::ONE);
        self.last_alpha = alpha;
        self.take_step(alpha);
        alpha
    }

    /// `res` from [`residuals`](Self::residuals) with the stationarity residual computed
    /// (the condensed QP's is part of them).
    fn exact<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        mut res: [T; 4],
    ) -> [T; 4] {
        if !self.dense() {
            res[0] = self.stationarity(qp);
        }
        res
    }

    fn max_multiplier(&self) -> T {
        if self.dense() {
            return self
                .ru
                .iter()
                .fold(T::ZERO, |m, r| m.max(r.max_multiplier()));
        }
        let mut m = self
            .rxn
            .max_multiplier()
            .max(self.rgn.max_multiplier())
            .max(self.sgn.max_multiplier());
        for k in 0..N {
            m = m
                .max(self.rx[k].max_multiplier())
                .max(self.ru[k].max_multiplier())
                .max(self.rg[k].max_multiplier())
                .max(self.sg[k].max_multiplier());
        }
        m
    }

    /// Computes the residuals but stationarity, and `H y + g`; returns
    /// `[0, dynamics, inequality, sum t lam]` (for a condensed QP, stationarity in place of the
    /// 0; otherwise see [`stationarity`](Self::stationarity), which needs this call first).
    /// Soft rows' slacks enter the inequality residual and `s m` the complementarity. The
    /// dynamics and inequality residuals are absolute.
    fn residuals<const NH: usize>(&mut self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) -> [T; 4] {
        if self.dense() {
            return self.condensed_residuals();
        }
        let (mut re, mut ri, mut comp) = (T::ZERO, T::ZERO, T::ZERO);
        let mut soft = [T::ZERO; 2];
        for k in 0..N {
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            let xnext = if k + 1 < N {
                self.sol.x[k + 1]
            } else {
                self.sol.xn
            };
            self.rb[k] = mul_sparse(&s.a, &x) + mul_sparse(&s.b, &u) + s.f - xnext;
            re = re.max(self.rb[k].amax());
            self.hx[k] = mul(&h.q, &x) + tr_mul(&h.s, &u) + s.gx;
            self.hu[k] = mul(&h.r, &u) + mul(&h.s, &x) + s.gu;
            ri = ri
                .max(self.rx[k].residuals(&x))
                .max(self.ru[k].residuals(&u, None));
            comp += self.rx[k].complementarity() + self.ru[k].complementarity();
            if NG > 0 {
                let g = mul(&s.c, &x) + mul(&s.d, &u);
                ri = ri.max(self.rg[k].residuals(&g, Some(&self.sg[k])));
                comp += self.rg[k].complementarity() + self.sg[k].complementarity();
                let (r, scale) = self.sg[k].residuals(&self.rg[k]);
                soft = [soft[0].max(r), soft[1].max(scale)];
            }
        }
        let t = &qp.terminal;
        let xn = self.sol.xn;
        self.hxn = mul(&t.q, &xn) + t.gx;
        ri = ri.max(self.rxn.residuals(&xn));
        comp += self.rxn.complementarity();
        if NGN > 0 {
            ri = ri.max(self.rgn.residuals(&mul(&t.c, &xn), Some(&self.sgn)));
            comp += self.rgn.complementarity() + self.sgn.complementarity();
            let (r, scale) = self.sgn.residuals(&self.rgn);
            soft = [soft[0].max(r), soft[1].max(scale)];
        }
        self.soft_stat = soft;
        [T::ZERO, re, ri, comp]
    }

    /// The stationarity residual at the point of the last [`residuals`](Self::residuals)
    /// call, relative to the largest of its terms (`H y + g`, `A'pi`, `B'pi`, `pi`, the bound
    /// multipliers, and for soft rows the slack penalty terms and multipliers) when that
    /// exceeds 1: rounding makes it no smaller than about `eps` times that. Soft rows'
    /// stationarity `l1 + l2 s - lam - m` is part of it. Only computed when the other
    /// residuals would let the iteration stop (or it ends): it costs about as much as they do.
    fn stationarity<const NH: usize>(&self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) -> T {
        let [mut rs, soft_scale] = self.soft_stat;
        let mut gscale = soft_scale.max(T::ONE);
        for k in 0..N {
            let s = &qp.stages[k];
            gscale = gscale.max(self.hu[k].amax());
            // Stationarity with the current multipliers, and the size of its terms.
            let gd = self.rg[k].dual();
            let bpi = tr_mul(&s.b, &self.sol.pi[k]);
            let ud = self.ru[k].dual();
            let dgd = tr_mul(&s.d, &gd);
            let su = self.hu[k] + bpi - ud - dgd;
            rs = rs.max(su.amax());
            gscale = gscale.max(bpi.amax()).max(ud.amax()).max(dgd.amax());
            if k > 0 {
                let api = tr_mul(&s.a, &self.sol.pi[k]);
                let xd = self.rx[k].dual();
                let cgd = tr_mul(&s.c, &gd);
                let sx = self.hx[k] + api - self.sol.pi[k - 1] - xd - cgd;
                rs = rs.max(sx.amax());
                gscale = gscale
                    .max(self.hx[k].amax())
                    .max(api.amax())
                    .max(self.sol.pi[k - 1].amax())
                    .max(xd.amax())
                    .max(cgd.amax());
            }
        }
        let t = &qp.terminal;
        gscale = gscale.max(self.hxn.amax());
        if N > 0 {
            let (xd, cgd) = (self.rxn.dual(), tr_mul(&t.c, &self.rgn.dual()));
            let sx = self.hxn - self.sol.pi[N - 1] - xd - cgd;
            rs = rs.max(sx.amax());
            gscale = gscale
                .max(self.sol.pi[N - 1].amax())
                .max(xd.amax())
                .max(cgd.amax());
        }
        rs / gscale
    }

    /// Backward Riccati factorization of the Newton system's Hessian (`mode`: the interior
    /// point's, each row with its barrier weight `sigma`; the polish's, the rows of its
    /// active set with its penalty weight, the others none; or the warm active set's).
    fn factorize<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        mode: Newton<'_, T, NBX, NU, NG, NGN, N>,
    ) -> bool {
        if self.dense() {
            return N == 0 || self.condensed_factorize();
        }
        self.factorize_stages(qp, mode, N)
    }

    /// The Riccati factorization of stages `stages - 1` down to 0 (and of the terminal
    /// stage if `stages == N`), from `P_stages` as the last factorization left it. A
    /// factorization whose `mode` and QP differ from the last one's only at those stages
    /// ends as a whole one would, bit for bit: the recursion runs backward, and stage `k`
    /// reads only `P_{k+1}`.
    // Over 80 lines: the terminal stage and the backward loop share the in-place storage of
    // `P` (each stage reads its successor's and overwrites it), which one body keeps visible.
    fn factorize_stages<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        mode: Newton<'_, T, NBX, NU, NG, NGN, N>,
        stages: usize,
    ) -> bool {
        // P_N = Q_N + Sigma_xN + C_N' Sigma_gN C_N, built in place in pn[N - 1].
        if stages >= N
            && let Some(last) = self.pn.last_mut()
        {
            let t = &qp.terminal;
            *last = t.q;
            add_diagonal(
                last,
                &self.rxn.scatter(&weights(
                    &self.rxn,
                    None,
                    mode.weight(|a| &a.xn, |h| Some(&h.xn)),
                )),
            );
            if NGN > 0 {
                let sg = weights(
                    &self.rgn,
                    Some(&self.sgn),
                    mode.weight(|a| &a.gn, |h| Some(&h.gn)),
                );
                mul_sparse_add_into(last, &scaled_transpose(&sg, &t.c), &t.c);
            }
            symmetrize(last);
        }
        // P_{k+1} is read in pn[k] by stage k, which builds P_k in pn[k - 1].
        for k in (0..stages.min(N)).rev() {
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (done, rest) = self.pn.split_at_mut(k);
            let Some(p) = rest.first() else {
                return false;
            };
            // Products with A and B on the right, where their zeros are skipped: with P
            // symmetric, B'PB = (PB)'B, A'PB = (PA)'B, A'PA = (PA)'A.
            let pb = mul_sparse(p, &s.b);
            let mut rbar = h.r;
            add_diagonal(
                &mut rbar,
                &weights(&self.ru[k], None, mode.weight(|a| &a.u[k], |_| None)),
            );
            mul_sparse_add_into(&mut rbar, &pb.transpose(), &s.b);
            // S~' = S' + C' Sigma_g D + A'PB, transposed, so that every product with it
            // runs down its columns.
            let mut sbt = h.s.transpose();
            let cts = if NG > 0 {
                let w = weights(
                    &self.rg[k],
                    Some(&self.sg[k]),
                    mode.weight(|a| &a.g[k], |h| h.g.get(k)),
                );
                mul_sparse_add_into(&mut rbar, &scaled_transpose(&w, &s.d), &s.d);
                let cts = scaled_transpose(&w, &s.c);
                mul_sparse_add_into(&mut sbt, &cts, &s.d);
                Some(cts)
            } else {
                None
            };
            // A'P, for P_k and S~ (the first stage needs only S~: (PB)'A, transposed).
            let atp = if k > 0 {
                let atp = mul_sparse(p, &s.a).transpose();
                mul_sparse_add_into(&mut sbt, &atp, &s.b);
                Some(atp)
            } else {
                sbt += mul_sparse(&pb.transpose(), &s.a).transpose();
                None
            };
            // Held controls drop out: their rows and columns of R~ become the identity and
            // their rows of S~ zero, so P_k is the recursion's over the free controls.
            if let Newton::Held(held, _) = mode
                && let Some(held) = held.get(k)
            {
                for (i, _) in held.iter().enumerate().filter(|(_, h)| **h) {
                    rbar.row_mut(i).fill(T::ZERO);
                    rbar.column_mut(i).fill(T::ZERO);
                    rbar[(i, i)] = T::ONE;
                    sbt.column_mut(i).fill(T::ZERO);
                }
            }
            let Some(chol) = regularized_cholesky(rbar, self.settings.reg) else {
                return false;
            };
            // R~ = L L'. Stored: L^-1 and W' = S~'L^-T, so that the gain is K = -L^-T W and
            // S~'R~^-1 S~ = W'W.
            let linv = lower_inverse(&chol.unpack());
            let wt = mul_tr(&sbt, &linv);
            if !finite_mat(&wt) || !finite_mat(&linv) {
                return false;
            }
            self.linv[k] = linv;
            self.wt[k] = wt;
            if let (Some(pk), Some(atp)) = (done.last_mut(), atp) {
                // P_k = Q + Sigma_x + C' Sigma_g C + A'PA - W'W.
                *pk = h.q;
                add_diagonal(
                    pk,
                    &self.rx[k].scatter(&weights(
                        &self.rx[k],
                        None,
                        mode.weight(|a| &a.x[k], |h| h.x.get(k)),
                    )),
                );
                if let Some(cts) = cts {
                    mul_sparse_add_into(pk, &cts, &s.c);
                }
                mul_sparse_add_into(pk, &atp, &s.a);
                sub_mul_tr_sum(pk, &[wt], &[wt]);
                symmetrize(pk);
            }
        }
        true
    }

    /// Solves the Newton system for the given complementarity right-hand side and sets the
    /// direction of every variable: reduced gradient, Riccati solve, `settings.refine` steps
    /// of iterative refinement, then slack and multiplier directions.
    fn newton_direction<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        rhs: Rhs<T>,
    ) {
        if N == 0 {
            return;
        }
        if self.dense() {
            self.condensed_direction(rhs);
            return;
        }
        let t = &qp.terminal;
        self.gnt = self.hxn
            + self.rxn.gradient(rhs)
            + tr_mul(&t.c, &self.rgn.gradient(rhs, Some(&self.sgn)));
        for k in 0..N {
            let s = &qp.stages[k];
            let wg = self.rg[k].gradient(rhs, Some(&self.sg[k]));
            self.gut[k] = self.hu[k] + self.ru[k].gradient(rhs, None) + tr_mul(&s.d, &wg);
            self.gxt[k] = self.hx[k] + self.rx[k].gradient(rhs) + tr_mul(&s.c, &wg);
            self.rbt[k] = self.rb[k];
        }
        self.gx0 = self.gxt;
        self.gu0 = self.gut;
        self.gn0 = self.gnt;
        self.lq_solve(qp, None);
        for _ in 0..self.settings.refine {
            self.refine(qp);
        }
        for k in 0..N {
            let s = &qp.stages[k];
            let (dx, du) = (self.dx[k], self.du[k]);
            self.rx[k].direction(&dx, rhs);
            self.ru[k].direction(&du, rhs, None);
            self.rg[k].direction(&(s.c * dx + s.d * du), rhs, Some(&mut self.sg[k]));
        }
        let dxn = self.dxn;
        self.rxn.direction(&dxn, rhs);
        self.rgn.direction(&(t.c * dxn), rhs, Some(&mut self.sgn));
    }

    /// Riccati solve of the linear-quadratic problem with gradients `gxt`, `gut`, `gnt`, and
    /// dynamics residuals `rbt`, using the factorization of the last
    /// [`factorize`](Self::factorize) call; writes `dx`, `du`, `dxn` and `pi_new`.
    fn lq_solve<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        held: Option<&[[bool; NU]; N]>,
    ) {
        // With R~ = L L' and W' = S~'L^-T (`factorize`), the feedforward control
        // -R~^-1 (g~ + B'(P rb + p)) is -L^-T y for y = L^-1 (g~ + B'(P rb + p)), kept in `kv`,
        // and the control is du = K dx - L^-T y = -L^-T (W dx + y). A held control's `y` is
        // zero: with its rows of L and W those of the identity and zero, its `du` is zero.
        let mut pv = self.gnt;
        for k in (0..N).rev() {
            let s = &qp.stages[k];
            self.pvn[k] = pv;
            let pb = mul(&self.pn[k], &self.rbt[k]) + pv;
            let mut y = mul(&self.linv[k], &(self.gut[k] + tr_mul(&s.b, &pb)));
            if let Some(held) = held.and_then(|h| h.get(k)) {
                for (yi, _) in y.iter_mut().zip(held).filter(|(_, h)| **h) {
                    *yi = T::ZERO;
                }
            }
            self.kv[k] = y;
            if k > 0 {
                pv = self.gxt[k] + tr_mul(&s.a, &pb) - mul(&self.wt[k], &y);
            }
        }
        let mut dx = Vect::<T, NX>::zeros();
        for k in 0..N {
            let s = &qp.stages[k];
            self.dx[k] = dx;
            let du = -tr_mul(&self.linv[k], &(tr_mul(&self.wt[k], &dx) + self.kv[k]));
            self.du[k] = du;
            let next = mul_sparse(&s.a, &dx) + mul_sparse(&s.b, &du) + self.rbt[k];
            self.pi_new[k] = mul(&self.pn[k], &next) + self.pvn[k];
            dx = next;
        }
        self.dxn = dx;
    }

    /// One step of iterative refinement: the residual of the Newton system at the current
    /// direction is computed from the stage data (not from the Riccati matrices, which lose
    /// precision when barrier terms are large), and the correction is solved with the same
    /// factorization.
    fn refine<const NH: usize>(&mut self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) {
        let t = &qp.terminal;
        let (dx0, du0, dxn0, pi0) = (self.dx, self.du, self.dxn, self.pi_new);
        // Residuals of H~ d + g~ + [A'; B'] pi_k - [pi_{k-1}; 0] and A dx + B du + rb - dx+.
        for k in 0..N {
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (dx, du) = (dx0[k], du0[k]);
            let next = if k + 1 < N { dx0[k + 1] } else { dxn0 };
            let wg = self.rg[k]
                .sigma(Some(&self.sg[k]))
                .component_mul(&(s.c * dx + s.d * du));
            self.gut[k] = h.r * du
                + h.s * dx
                + self.ru[k].sigma(None).component_mul(&du)
                + tr_mul(&s.d, &wg)
                + self.gu0[k]
                + tr_mul(&s.b, &pi0[k]);
            if k > 0 {
                self.gxt[k] = h.q * dx
                    + tr_mul(&h.s, &du)
                    + self.rx[k].sigma().component_mul(&dx)
                    + tr_mul(&s.c, &wg)
                    + self.gx0[k]
                    + tr_mul(&s.a, &pi0[k])
                    - pi0[k - 1];
            }
            self.rbt[k] = s.a * dx + s.b * du + self.rb[k] - next;
        }
        let wgn = self.rgn.sigma(Some(&self.sgn)).component_mul(&(t.c * dxn0));
        self.gnt =
            t.q * dxn0 + self.rxn.sigma().component_mul(&dxn0) + tr_mul(&t.c, &wgn) + self.gn0
                - pi0[N - 1];
        self.lq_solve(qp, None);
        for k in 0..N {
            self.dx[k] += dx0[k];
            self.du[k] += du0[k];
            self.pi_new[k] += pi0[k];
        }
        self.dxn += dxn0;
    }

    fn save_affine(&mut self) {
        if self.dense() {
            self.ru.iter_mut().for_each(Rows::save_affine);
            return;
        }
        for k in 0..N {
            self.rx[k].save_affine();
            self.ru[k].save_affine();
            self.rg[k].save_affine();
            self.sg[k].save_affine();
        }
        self.rxn.save_affine();
        self.rgn.save_affine();
        self.sgn.save_affine();
    }

    fn max_step(&self, mut alpha: T) -> T {
        if self.dense() {
            return self.ru.iter().fold(alpha, |a, r| r.max_step(a));
        }
        for k in 0..N {
            alpha = self.rx[k].max_step(alpha);
            alpha = self.ru[k].max_step(alpha);
            alpha = self.rg[k].max_step(alpha);
            alpha = self.sg[k].max_step(alpha);
        }
        alpha = self.rxn.max_step(alpha);
        alpha = self.rgn.max_step(alpha);
        self.sgn.max_step(alpha)
    }

    fn complementarity_after(&self, alpha: T) -> T {
        if self.dense() {
            return self
                .ru
                .iter()
                .fold(T::ZERO, |s, r| s + r.complementarity_after(alpha));
        }
        let mut s = self.rxn.complementarity_after(alpha)
            + self.rgn.complementarity_after(alpha)
            + self.sgn.complementarity_after(alpha);
        for k in 0..N {
            s += self.rx[k].complementarity_after(alpha)
                + self.ru[k].complementarity_after(alpha)
                + self.rg[k].complementarity_after(alpha)
                + self.sg[k].complementarity_after(alpha);
        }
        s
    }

    fn take_step(&mut self, alpha: T) {
        if self.dense() {
            // Only the controls and their bounds: states and dynamics multipliers follow
            // from them at the end (`expand`).
            for k in 0..N {
                self.sol.u[k] += self.du[k] * alpha;
                self.ru[k].update(alpha);
            }
            return;
        }
        for k in 0..N {
            if k > 0 {
                self.sol.x[k] += self.dx[k] * alpha;
            }
            self.sol.u[k] += self.du[k] * alpha;
            self.sol.pi[k] += (self.pi_new[k] - self.sol.pi[k]) * alpha;
            self.rx[k].update(alpha);
            self.ru[k].update(alpha);
            self.rg[k].update(alpha);
            self.sg[k].update(alpha);
        }
        self.sol.xn += self.dxn * alpha;
        self.rxn.update(alpha);
        self.rgn.update(alpha);
        self.sgn.update(alpha);
    }
}
