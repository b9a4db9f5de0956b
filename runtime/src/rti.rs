//! The real-time-iteration SQP solver (Gauss-Newton), and a full-SQP mode with a merit line
//! search for offline use.
//!
//! Each control step is [`Rti::prepare`] (before the state arrives: linearize every stage
//! around the current trajectory) and [`Rti::feedback`] (embed the measured state, solve one
//! QP, update the trajectory, return `u_0`). If the QP fails, the previous successful plan,
//! shifted by the number of steps since, is returned and the status says so; a non-finite
//! control is never returned, and non-finite inputs are rejected before they touch any state.
//!
//! General constraints `lg <= h(x, u, p) <= ug` can be softened row by row with
//! [`Rti::set_soft_penalties`] (L1 and L2 slack penalties, copied into every stage's QP by
//! [`Rti::prepare`]): a plan that must violate them (say, an initial state outside a state
//! constraint) is then still a solution, not an infeasible QP and a fallback. The full-SQP
//! merit function weights a soft row's violation by its penalties.
//!
//! General cost terms ([`Model::GENERAL_COST`]) add their gradients to the QP's and their
//! Hessians, projected onto the positive semidefinite cone ([`crate::convexify`]), to its
//! Hessians; the full SQP's exact steps use their exact Hessians.

use nalgebra::{SMatrix, SVector};

use crate::convexify::{project_psd, project_psd_terminal};
use crate::kernels::{mul, mul_mostly_zero_into, tr_mul, tr_mul_add_into};
use crate::model::Model;
use crate::qp::{OcpQp, QpHessian, QpInfo, QpSettings, QpSolver, QpStatus};
use crate::real::Real;

/// Step halvings of the full-SQP line search.
const MAX_HALVINGS: u32 = 12;

/// Settings of the SQP layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RtiSettings<T> {
    /// Settings of every QP solve.
    pub qp: QpSettings<T>,
    /// Shift the trajectory by one stage before each preparation (the last stage is repeated).
    /// Off, the previous solution is the next linearization point as it is. Default on: a
    /// closed loop whose plan changes along the horizon (a swing-up, a flip) needs it, and
    /// a set-point loop loses nothing by it (`docs/runtime.md`, "The shift"). Peers' RTI
    /// without a shift (acados' QR-bench runs) are mirrored by turning it off.
    pub shift: bool,
    /// Iteration limit of [`Rti::solve_sqp`].
    pub sqp_max_iter: u32,
    /// [`Rti::solve_sqp`] stops when the largest step entry is below this.
    pub sqp_tol: T,
    /// [`Rti::solve_sqp`] also stops, before solving another QP, at an iterate that meets
    /// the KKT conditions to this tolerance with the last QP's dynamics multipliers `pi`:
    /// every dynamics defect and, per entry of each state and control, the Lagrangian's
    /// gradient projected on the bounds (its natural residual, which holds the bounds'
    /// violation too) at most this, as CasADi's `sqpmethod` stops on `tol_pr` and `tol_du`
    /// (absolute, as theirs: scale it with the cost's weights).
    /// Checked where no general constraint has a bound (their multipliers are not kept);
    /// 0 turns it off. Default [`Real::SQP_TOL`].
    pub sqp_kkt_tol: T,
    /// [`Rti::solve_sqp`] solves its QPs by the interior point to 1e-3 and then the
    /// active-set polish, which ends on the exact solution once the interior point has the
    /// active set; a QP whose polish is refused, or that it does not handle (soft rows), is
    /// solved again to the QP tolerances, and so are the rest of that solve's. Default
    /// [`Real::SQP_LOOSE_QPS`]: on in f64, off in f32.
    pub sqp_loose_qps: bool,
    /// [`Rti::solve_sqp`] adds the dynamics' curvature `sum_i pi_i d2F_i/d(x, u)2` (and the
    /// general constraints' `sum_i mu_i d2h_i`, and a general cost's exact Hessian in place
    /// of its projection) to the Gauss-Newton Hessian of each stage (Newton steps on the
    /// Lagrangian, with the last QP's multipliers), where the model provides it
    /// ([`Model::EXACT_HESSIAN`]) and
    /// the QP keeps a Hessian per stage (`NH = N`). An iteration whose QP then fails is
    /// solved again with the Gauss-Newton Hessian; its steps are judged by the watchdog
    /// ([`sqp_watchdog`](Self::sqp_watchdog)), and once that has gone back (or without it), a
    /// step that does not decrease the merit function is dropped and the next iteration is
    /// Gauss-Newton's. Default on; without the model's Hessian it does nothing.
    pub sqp_exact_hessian: bool,
    /// Exact-Hessian steps of [`Rti::solve_sqp`] that the watchdog takes whole without their
    /// decreasing the merit function, in a row, before it goes back to the iterate before
    /// them and searches monotonically (see `solve_sqp`). 0: every step searches
    /// monotonically. Default 4.
    pub sqp_watchdog: u32,
    /// Escalation of failed real-time iterations: [`Rti::feedback`] reports
    /// [`RtiStatus::PlanExhausted`] instead of [`RtiStatus::UsedPreviousPlan`] from the
    /// `min(fallback_limit, N)`-th QP failure in a row on (see [`RtiStatus::PlanExhausted`]).
    /// At least 1; the default, `u32::MAX`, escalates once the last good plan is used up
    /// (the `N`-th failure in a row).
    pub fallback_limit: u32,
}

impl<T: Real> RtiSettings<T> {
    /// Defaults: QP defaults with the dual warm start on (each QP starts from the previous
    /// control step's multipliers) and the tolerances of a real-time iteration ([`Real::RTI_TOL`]
    /// for stationarity, feasibility and complementarity: 1e-6 in f64; f32 keeps its QP
    /// defaults) and no polish (one Gauss-Newton step's linearization error is far above what
    /// it corrects; on QR-bench A in f32 it would add 31 % to the feedback), the shift, 50 SQP
    /// iterations to `1e-6` (f64) / `1e-4` (f32). The full SQP ([`Rti::solve_sqp`]) solves its
    /// QPs at least to the QP solver's own defaults, polish included.
    pub const DEFAULT: Self = RtiSettings {
        qp: QpSettings {
            warm_start_dual: true,
            tol_stat: T::RTI_TOL,
            tol_eq: T::RTI_TOL,
            tol_ineq: T::RTI_TOL,
            tol_comp: T::RTI_TOL_COMP,
            polish: false,
            warm_active_set: true,
            ..QpSettings::DEFAULT
        },
        shift: true,
        sqp_max_iter: 50,
        sqp_tol: T::SQP_TOL,
        sqp_kkt_tol: T::SQP_TOL,
        sqp_loose_qps: T::SQP_LOOSE_QPS,
        sqp_exact_hessian: true,
        sqp_watchdog: 4,
        fallback_limit: u32::MAX,
    };

    /// Every setting zero (no QP iteration, no SQP iteration): [`Rti::unconfigured`]'s.
    pub(crate) const ZERO: Self = RtiSettings {
        qp: QpSettings::ZERO,
        shift: false,
        sqp_max_iter: 0,
        sqp_tol: T::ZERO,
        sqp_kkt_tol: T::ZERO,
        sqp_loose_qps: false,
        sqp_exact_hessian: false,
        sqp_watchdog: 0,
        fallback_limit: 0,
    };

    /// Checks the settings: every tolerance finite and non-negative, the QP's
    /// regularization finite and non-negative and its `mu0` finite and positive, the QP and
    /// SQP iteration limits and [`fallback_limit`](Self::fallback_limit) at least 1.
    ///
    /// # Errors
    /// [`SetError::NonFinite`] for a NaN or infinite tolerance, `reg` or `mu0` (checked
    /// first), [`SetError::InvalidSetting`] for any other value out of its range.
    pub fn validate(&self) -> Result<(), SetError> {
        let q = &self.qp;
        let reals = [
            q.tol_stat,
            q.tol_eq,
            q.tol_ineq,
            q.tol_comp,
            q.reg,
            q.mu0,
            self.sqp_tol,
            self.sqp_kkt_tol,
        ];
        if !reals.iter().all(|v| v.finite()) {
            return Err(SetError::NonFinite);
        }
        let non_negative = reals.iter().all(|&v| v >= T::ZERO);
        let counts = q.max_iter > 0 && self.sqp_max_iter > 0 && self.fallback_limit > 0;
        if !(non_negative && counts && q.mu0 > T::ZERO) {
            return Err(SetError::InvalidSetting);
        }
        Ok(())
    }
}

/// Outcome of a control step or a full SQP solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub enum RtiStatus {
    /// The QP was solved; the control comes from the new solution.
    Ok = 0,
    /// The QP failed (see [`RtiInfo::qp`]); the control comes from the previous plan.
    UsedPreviousPlan = 1,
    /// An input was NaN or infinite; nothing was changed.
    NonFiniteInput = 2,
    /// [`Rti::feedback`] was called without a [`Rti::prepare`] since the last feedback.
    NotPrepared = 3,
    /// The full SQP reached its iteration limit.
    MaxIterations = 4,
    /// The escalation of [`UsedPreviousPlan`](Self::UsedPreviousPlan): the QP failed for the
    /// `min(RtiSettings::fallback_limit, N)`-th time in a row (or more;
    /// [`RtiInfo::consecutive_failures`] counts them). The control is still the fallback's,
    /// control `min(j, N - 1)` of the last good plan at the `j`-th failure in a row: from
    /// the `N`-th failure on, that plan's last control again and again, which nothing
    /// re-plans. The caller should act (a safe mode, a hold, a reset of the guess); the next
    /// solved QP returns [`Ok`](Self::Ok) and resets the count.
    PlanExhausted = 5,
}

/// Status and statistics of the last call.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RtiInfo<T> {
    /// How the call ended.
    pub status: RtiStatus,
    /// The last QP solve.
    pub qp: QpInfo<T>,
    /// SQP iterations (1 for a real-time iteration): the QPs solved, where an iteration whose
    /// exact-Hessian QP failed and was solved again with Gauss-Newton's counts once.
    pub sqp_iterations: u32,
    /// The full SQP's watchdog went back to its reference ([`RtiSettings::sqp_watchdog`]):
    /// Newton's steps taken whole did not pay, and the rest of the solve searched
    /// monotonically.
    pub watchdog_returned: bool,
    /// QP failures of [`Rti::feedback`] in a row up to this call (0 after a solved QP or a
    /// converged [`Rti::solve_sqp`]); calls refused before a QP (`NonFiniteInput`,
    /// `NotPrepared`) do not count.
    pub consecutive_failures: u32,
}

impl<T: Real> RtiInfo<T> {
    /// Status `Ok`, no iteration, zero residuals: a placeholder before the first solve (its
    /// bits are all zero, so it keeps a solver in a `static` zero-filled).
    pub const EMPTY: Self = RtiInfo {
        status: RtiStatus::Ok,
        qp: QpInfo {
            status: QpStatus::Solved,
            iterations: 0,
            active_set_solves: 0,
            res_stat: T::ZERO,
            res_eq: T::ZERO,
            res_ineq: T::ZERO,
            mu: T::ZERO,
        },
        sqp_iterations: 0,
        watchdog_returned: false,
        consecutive_failures: 0,
    };
}

/// Why a setter refused its input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SetError {
    /// A value was NaN or infinite. A bound may be infinite on the side it relaxes (a lower
    /// bound `-inf`, an upper bound `+inf`); NaN and a lower bound `+inf` or an upper bound
    /// `-inf` (which nothing satisfies) are refused.
    NonFinite,
    /// The stage index is beyond the horizon.
    StageOutOfRange,
    /// A lower bound exceeds its upper bound.
    CrossedBounds,
    /// A soft-constraint penalty is negative.
    NegativePenalty,
    /// More states have a bound than the solver has state-bound rows (its `NBX`).
    TooManyStateBounds,
    /// A setting is out of its range ([`RtiSettings::validate`]).
    InvalidSetting,
    /// A weight's symmetric part is not positive semidefinite (a negative diagonal entry,
    /// or a negative eigenvalue): the cost would be unbounded below.
    NegativeWeight,
}

/// A real-time-iteration NMPC solver for model `M` with horizon `N`; `NC`, `NBX` and `NR`
/// size its QP solver ([`QpSolver`]). `NH` is the number of stage Hessians its QP keeps
/// ([`OcpQp`]): `N`, or `1` for a model with constant stage residual Jacobians
/// ([`Model::CONSTANT_STAGE_RESIDUAL_JACOBIANS`]), whose Gauss-Newton Hessian `J'WJ` is the
/// same at every stage (one weight `W` for all), and no general cost
/// ([`Model::GENERAL_COST`], whose Hessians differ from stage to stage). Other values fail
/// to compile.
#[derive(Clone, Debug)]
pub struct Rti<
    T: Real,
    M,
    const NX: usize,
    const NU: usize,
    const NP: usize,
    const NY: usize,
    const NYN: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NC: usize = 0,
    const NBX: usize = NX,
    const NR: usize = N,
    const NH: usize = N,
> {
    /// The model.
    pub model: M,
    /// Settings.
    pub settings: RtiSettings<T>,
    qp: OcpQp<T, NX, NU, NG, NGN, N, NH>,
    solver: QpSolver<T, NX, NU, NG, NGN, N, NC, NBX, NR>,
    x: [SVector<T, NX>; N],
    xn: SVector<T, NX>,
    u: [SVector<T, NU>; N],
    p: [SVector<T, NP>; N],
    pn: SVector<T, NP>,
    yref: [SVector<T, NY>; N],
    yref_n: SVector<T, NYN>,
    w: SMatrix<T, NY, NY>,
    wn: SMatrix<T, NYN, NYN>,
    /// Whether `w` / `wn` are diagonal (then `W J` is a row scaling, not a product).
    w_diag: bool,
    wn_diag: bool,
    lbx: SVector<T, NX>,
    ubx: SVector<T, NX>,
    lbu: SVector<T, NU>,
    ubu: SVector<T, NU>,
    lg: SVector<T, NG>,
    ug: SVector<T, NG>,
    lgn: SVector<T, NGN>,
    ugn: SVector<T, NGN>,
    l1: SVector<T, NG>,
    l2: SVector<T, NG>,
    l1n: SVector<T, NGN>,
    l2n: SVector<T, NGN>,
    /// Some penalty is positive (the merit function then evaluates the constraints).
    any_soft: bool,
    /// The Gauss-Newton terms `J'WJ` are those of the current weights; kept from one
    /// linearization to the next where the model's residual Jacobians are constant (the
    /// stages': [`Model::CONSTANT_STAGE_RESIDUAL_JACOBIANS`]; the terminal one:
    /// [`Model::CONSTANT_RESIDUAL_JACOBIANS`]).
    gn_current: bool,
    plan: [SVector<T, NU>; N],
    plan_age: usize,
    /// QP failures of `feedback` in a row ([`RtiInfo::consecutive_failures`]).
    failures: u32,
    prepared: bool,
    /// A feedback has moved time forward since the last shift.
    pending_shift: bool,
    // Trial trajectory of the line search.
    xt: [SVector<T, NX>; N],
    xnt: SVector<T, NX>,
    ut: [SVector<T, NU>; N],
    /// The full SQP's watchdog reference: the iterate before the first watched Newton step.
    /// Only the exact-Hessian SQP watches, and it needs a Hessian per stage (`NH = N`): a
    /// solver with one stage Hessian (`NH = 1`) pays for one stage; a Gauss-Newton solver with
    /// a Hessian per stage (nonlinear residuals) for an unused trajectory.
    xw: [SVector<T, NX>; NH],
    xnw: SVector<T, NX>,
    uw: [SVector<T, NU>; NH],
}

fn all_finite<T: Real, const R: usize, const C: usize>(m: &SMatrix<T, R, C>) -> bool {
    m.iter().all(|v| v.finite())
}

fn no_nan<T: Real, const R: usize>(v: &SVector<T, R>) -> bool {
    !v.iter().any(|x| x.nan())
}

fn not_crossed<T: Real, const R: usize>(lo: &SVector<T, R>, hi: &SVector<T, R>) -> bool {
    lo.iter().zip(hi.iter()).all(|(l, h)| l <= h)
}

/// Whether no lower bound is `+inf` and no upper bound `-inf`.
fn relaxing_infinities<T: Real, const R: usize>(lo: &SVector<T, R>, hi: &SVector<T, R>) -> bool {
    lo.iter().all(|&l| l.finite() || l < T::ZERO) && hi.iter().all(|&h| h.finite() || h > T::ZERO)
}

/// Two pairs of bounds: NaN anywhere, or an infinity on the side it does not relax, is
/// `NonFinite` (checked first), a lower bound above its upper bound is `CrossedBounds`.
fn check_bounds<T: Real, const A: usize, const B: usize>(
    la: &SVector<T, A>,
    ua: &SVector<T, A>,
    lb: &SVector<T, B>,
    ub: &SVector<T, B>,
) -> Result<(), SetError> {
    if !(no_nan(la) && no_nan(ua) && no_nan(lb) && no_nan(ub)) {
        return Err(SetError::NonFinite);
    }
    if !(relaxing_infinities(la, ua) && relaxing_infinities(lb, ub)) {
        return Err(SetError::NonFinite);
    }
    if !(not_crossed(la, ua) && not_crossed(lb, ub)) {
        return Err(SetError::CrossedBounds);
    }
    Ok(())
}

/// `W r` for a symmetric weight `W`, diagonal if `diag`: then a scaling of `r`'s entries.
#[inline(always)]
fn weighted<T: Real, const R: usize>(
    w: &SMatrix<T, R, R>,
    diag: bool,
    r: &SVector<T, R>,
) -> SVector<T, R> {
    if diag {
        SVector::from_fn(|i, _| w[(i, i)] * r[i])
    } else {
        mul(w, r)
    }
}

/// `(W J)' = J'W` for a symmetric weight `W` (the solver keeps the symmetric part), diagonal
/// if `diag`: then a scaling of `J`'s rows. Not inlined: its temporaries stay out of the frame
/// of [`Rti::linearize`]'s loop, which runs the model's functions (on a Cortex-M4F that frame
/// was 5.6 KB with them, the deepest of a control step).
#[inline(never)]
fn weighted_transpose<T: Real, const R: usize, const C: usize>(
    w: &SMatrix<T, R, R>,
    diag: bool,
    j: &SMatrix<T, R, C>,
) -> SMatrix<T, C, R> {
    // One array for both cases (the kernels' own would each take a slot in the frame). The
    // diagonal case is `scaled_transpose` written out here: through an in-place form of
    // that kernel it took 224 B more code, 650 more instructions per step and 40 B more
    // stack on the Cortex-M4F.
    let mut out = SMatrix::<T, C, R>::zeros();
    if diag {
        let (o, jd, wd) = (&mut out.data.0, &j.data.0, &w.data.0);
        for (r, (col, wcol)) in o.iter_mut().zip(wd).enumerate() {
            let d = wcol[r];
            for (oc, jcol) in col.iter_mut().zip(jd) {
                *oc = jcol[r] * d;
            }
        }
    } else {
        // Each entry 0 + its dot product: `tr_mul(j, w)`.
        tr_mul_add_into(&mut out, j, w);
    }
    out
}

/// Slack cost of constraint values `h` against `lo <= h <= hi` for the soft rows (penalties
/// `l1`, `l2`; rows with both zero are skipped): `l1 v + 1/2 l2 v^2` per violated side.
fn soft_penalty<T: Real, const K: usize>(
    h: &SVector<T, K>,
    lo: &SVector<T, K>,
    hi: &SVector<T, K>,
    l1: &SVector<T, K>,
    l2: &SVector<T, K>,
) -> T {
    let mut c = T::ZERO;
    for i in 0..K {
        if !(l1[i] > T::ZERO || l2[i] > T::ZERO) {
            continue;
        }
        // Absent bounds (at or beyond `Real::INF`) are never violated.
        let vl = if lo[i] > -T::INF {
            (lo[i] - h[i]).max(T::ZERO)
        } else {
            T::ZERO
        };
        let vu = if hi[i] < T::INF {
            (h[i] - hi[i]).max(T::ZERO)
        } else {
            T::ZERO
        };
        c += l1[i] * (vl + vu) + l2[i] * (vl * vl + vu * vu) * T::lit(0.5);
    }
    c
}

impl<
    T: Real,
    M: Model<T, NX, NU, NP, NY, NYN, NG, NGN>,
    const NX: usize,
    const NU: usize,
    const NP: usize,
    const NY: usize,
    const NYN: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NC: usize,
    const NBX: usize,
    const NR: usize,
    const NH: usize,
> Rti<T, M, NX, NU, NP, NY, NYN, NG, NGN, N, NC, NBX, NR, NH>
{
    /// A solver with zero trajectory, parameters, references and weights, no bounds and the
    /// default settings. `const`, so it can initialize a `static`.
    pub const fn new(model: M) -> Self {
        Self::build(model, false)
    }

    /// A solver with every field zero: the settings (no QP iteration), the bounds (every
    /// state and control fixed at 0), the weights. A `static` initialized with it is
    /// zero-filled memory (`.bss`) instead of an initial image of the whole solver in flash
    /// ([`new`](Self::new)'s infinite bounds and settings are not zeros). Unusable until
    /// configured: set the settings, the bounds
    /// ([`set_bounds`](Self::set_bounds), [`set_constraint_bounds`](Self::set_constraint_bounds)),
    /// the weights, parameters and guess; a generated `Solver::configure` does all of it.
    pub const fn unconfigured(model: M) -> Self {
        Self::build(model, true)
    }

    const fn build(model: M, zero: bool) -> Self {
        const {
            assert!(
                NH == N || (NH == 1 && M::CONSTANT_STAGE_RESIDUAL_JACOBIANS && !M::GENERAL_COST),
                "NH = 1 (one stage Hessian) needs a model with constant stage residual Jacobians \
                 and no general cost"
            )
        };
        let (lo, hi) = if zero {
            (T::ZERO, T::ZERO)
        } else {
            (T::NEG_INF, T::INF)
        };
        Rti {
            model,
            settings: if zero {
                RtiSettings::ZERO
            } else {
                RtiSettings::DEFAULT
            },
            qp: if zero { OcpQp::ZEROED } else { OcpQp::NEW },
            solver: if zero {
                QpSolver::ZEROED
            } else {
                QpSolver::NEW
            },
            x: [crate::zeros(); N],
            xn: crate::zeros(),
            u: [crate::zeros(); N],
            p: [crate::zeros(); N],
            pn: crate::zeros(),
            yref: [crate::zeros(); N],
            yref_n: crate::zeros(),
            w: crate::zeros(),
            wn: crate::zeros(),
            w_diag: !zero,
            wn_diag: !zero,
            lbx: crate::filled(lo),
            ubx: crate::filled(hi),
            lbu: crate::filled(lo),
            ubu: crate::filled(hi),
            lg: crate::filled(lo),
            ug: crate::filled(hi),
            lgn: crate::filled(lo),
            ugn: crate::filled(hi),
            l1: crate::zeros(),
            l2: crate::zeros(),
            l1n: crate::zeros(),
            l2n: crate::zeros(),
            any_soft: false,
            gn_current: false,
            plan: [crate::zeros(); N],
            plan_age: 0,
            failures: 0,
            prepared: false,
            pending_shift: false,
            xt: [crate::zeros(); N],
            xnt: crate::zeros(),
            ut: [crate::zeros(); N],
            xw: [crate::zeros(); NH],
            xnw: crate::zeros(),
            uw: [crate::zeros(); NH],
        }
    }

    /// Sets the stage weight `W` and terminal weight `W_N`. The cost `1/2 r'Wr` depends only
    /// on the symmetric part of `W`, which is what is kept (`(W + W') / 2`; a symmetric `W`
    /// is kept exactly).
    ///
    /// # Errors
    /// [`SetError::NonFinite`] if an entry is NaN or infinite (checked first),
    /// [`SetError::NegativeWeight`] if the symmetric part of `W` or `W_N` is not positive
    /// semidefinite (a negative diagonal entry; off the diagonal, a negative pivot of its
    /// `LDL'` factorization beyond rounding). Nothing changes on error.
    pub fn set_weights(
        &mut self,
        w: &SMatrix<T, NY, NY>,
        wn: &SMatrix<T, NYN, NYN>,
    ) -> Result<(), SetError> {
        if !(all_finite(w) && all_finite(wn)) {
            return Err(SetError::NonFinite);
        }
        if !(positive_semidefinite(w) && positive_semidefinite(wn)) {
            return Err(SetError::NegativeWeight);
        }
        // Weights equal to the current ones (a generated solver sets them again whenever a
        // stage-0 parameter changes) keep the Gauss-Newton terms.
        let changed = symmetric_part_into(&mut self.w, w) | symmetric_part_into(&mut self.wn, wn);
        self.w_diag = is_diagonal(w);
        self.wn_diag = is_diagonal(wn);
        if changed {
            self.gn_current = false;
        }
        Ok(())
    }

    /// Replaces the settings after checking them ([`RtiSettings::validate`]). The public
    /// [`settings`](Self::settings) field can be written directly too, without a check.
    ///
    /// # Errors
    /// [`SetError::NonFinite`], [`SetError::InvalidSetting`]; nothing changes then.
    pub fn set_settings(&mut self, settings: &RtiSettings<T>) -> Result<(), SetError> {
        settings.validate()?;
        self.settings = *settings;
        Ok(())
    }

    /// The weights in use, `(W, W_N)`: the symmetric parts of those
    /// [`set_weights`](Self::set_weights) last accepted.
    pub fn weights(&self) -> (&SMatrix<T, NY, NY>, &SMatrix<T, NYN, NYN>) {
        (&self.w, &self.wn)
    }

    /// Sets the residual reference of stage `k < N`.
    ///
    /// # Errors
    /// [`SetError::NonFinite`], [`SetError::StageOutOfRange`].
    pub fn set_reference(&mut self, k: usize, yref: &SVector<T, NY>) -> Result<(), SetError> {
        if !all_finite(yref) {
            return Err(SetError::NonFinite);
        }
        *self.yref.get_mut(k).ok_or(SetError::StageOutOfRange)? = *yref;
        Ok(())
    }

    /// Sets the terminal residual reference.
    ///
    /// # Errors
    /// [`SetError::NonFinite`].
    pub fn set_terminal_reference(&mut self, yref: &SVector<T, NYN>) -> Result<(), SetError> {
        if !all_finite(yref) {
            return Err(SetError::NonFinite);
        }
        self.yref_n = *yref;
        Ok(())
    }

    /// Sets the parameters of stage `k <= N` (`k = N` is the terminal stage).
    ///
    /// # Errors
    /// [`SetError::NonFinite`], [`SetError::StageOutOfRange`].
    pub fn set_param(&mut self, k: usize, p: &SVector<T, NP>) -> Result<(), SetError> {
        if !all_finite(p) {
            return Err(SetError::NonFinite);
        }
        if k == N {
            self.pn = *p;
        } else {
            *self.p.get_mut(k).ok_or(SetError::StageOutOfRange)? = *p;
        }
        Ok(())
    }

    /// Sets the parameters of every stage.
    ///
    /// # Errors
    /// [`SetError::NonFinite`].
    pub fn set_param_all(&mut self, p: &SVector<T, NP>) -> Result<(), SetError> {
        if !all_finite(p) {
            return Err(SetError::NonFinite);
        }
        self.p = [*p; N];
        self.pn = *p;
        Ok(())
    }

    /// Sets box bounds on the state (stages `1..=N`) and the control (stages `0..N`).
    /// Bounds at or beyond `Real::INF` in magnitude (or infinite) are absent. At most `NBX`
    /// states may have a bound (one side or both).
    ///
    /// # Errors
    /// [`SetError::NonFinite`] for NaN (or a lower bound `+inf`, an upper bound `-inf`),
    /// [`SetError::CrossedBounds`], [`SetError::TooManyStateBounds`] (checked in that order).
    /// Nothing changes on error.
    pub fn set_bounds(
        &mut self,
        lbx: &SVector<T, NX>,
        ubx: &SVector<T, NX>,
        lbu: &SVector<T, NU>,
        ubu: &SVector<T, NU>,
    ) -> Result<(), SetError> {
        check_bounds(lbx, ubx, lbu, ubu)?;
        let bounded = lbx
            .iter()
            .zip(ubx.iter())
            .filter(|&(&l, &h)| l > -T::INF || h < T::INF)
            .count();
        if bounded > NBX {
            return Err(SetError::TooManyStateBounds);
        }
        self.lbx = *lbx;
        self.ubx = *ubx;
        self.lbu = *lbu;
        self.ubu = *ubu;
        Ok(())
    }

    /// The box bounds in use, `(lbx, ubx, lbu, ubu)`, as [`set_bounds`](Self::set_bounds)
    /// last accepted them (zero for an [`unconfigured`](Self::unconfigured) solver,
    /// `-INF` and `INF`, no bounds, for [`new`](Self::new)'s).
    pub fn bounds(
        &self,
    ) -> (
        &SVector<T, NX>,
        &SVector<T, NX>,
        &SVector<T, NU>,
        &SVector<T, NU>,
    ) {
        (&self.lbx, &self.ubx, &self.lbu, &self.ubu)
    }

    /// The bounds of the general constraints in use, `(lg, ug, lgn, ugn)` (stage, then
    /// terminal rows), as [`set_constraint_bounds`](Self::set_constraint_bounds) last
    /// accepted them.
    pub fn constraint_bounds(
        &self,
    ) -> (
        &SVector<T, NG>,
        &SVector<T, NG>,
        &SVector<T, NGN>,
        &SVector<T, NGN>,
    ) {
        (&self.lg, &self.ug, &self.lgn, &self.ugn)
    }

    /// Sets the bounds of the general constraints (stage and terminal).
    ///
    /// # Errors
    /// [`SetError::NonFinite`] for NaN (or a lower bound `+inf`, an upper bound `-inf`),
    /// [`SetError::CrossedBounds`] (checked in that order). Nothing changes on error.
    pub fn set_constraint_bounds(
        &mut self,
        lg: &SVector<T, NG>,
        ug: &SVector<T, NG>,
        lgn: &SVector<T, NGN>,
        ugn: &SVector<T, NGN>,
    ) -> Result<(), SetError> {
        check_bounds(lg, ug, lgn, ugn)?;
        self.lg = *lg;
        self.ug = *ug;
        self.lgn = *lgn;
        self.ugn = *ugn;
        Ok(())
    }

    /// Sets the slack penalties of the general constraints: row `i` of the stage constraints
    /// costs `l1[i] (sl + su) + 1/2 l2[i] (sl^2 + su^2)` for slacks `sl, su >= 0` that relax
    /// `lg - sl <= h(x, u, p) <= ug + su` (likewise `l1n`, `l2n` for the terminal rows). A row
    /// with both penalties zero (the default) is hard; box bounds are always hard. The L1
    /// penalty is exact: a row whose constraint can be met is met when `l1` exceeds the
    /// row's multiplier. Applied to every stage by the next [`prepare`](Self::prepare) (or
    /// [`solve_sqp`](Self::solve_sqp)), whose merit function includes the penalties.
    ///
    /// # Errors
    /// [`SetError::NonFinite`] if a penalty is NaN or infinite (checked first),
    /// [`SetError::NegativePenalty`] if one is negative. Nothing changes on error.
    pub fn set_soft_penalties(
        &mut self,
        l1: &SVector<T, NG>,
        l2: &SVector<T, NG>,
        l1n: &SVector<T, NGN>,
        l2n: &SVector<T, NGN>,
    ) -> Result<(), SetError> {
        if !(all_finite(l1) && all_finite(l2) && all_finite(l1n) && all_finite(l2n)) {
            return Err(SetError::NonFinite);
        }
        let nonneg = |v: &[T]| v.iter().all(|x| *x >= T::ZERO);
        if !(nonneg(l1.as_slice())
            && nonneg(l2.as_slice())
            && nonneg(l1n.as_slice())
            && nonneg(l2n.as_slice()))
        {
            return Err(SetError::NegativePenalty);
        }
        self.l1 = *l1;
        self.l2 = *l2;
        self.l1n = *l1n;
        self.l2n = *l2n;
        let pos = |v: &[T]| v.iter().any(|x| *x > T::ZERO);
        self.any_soft =
            pos(l1.as_slice()) || pos(l2.as_slice()) || pos(l1n.as_slice()) || pos(l2n.as_slice());
        Ok(())
    }

    /// Sets the whole trajectory guess: `x_k` for every `k <= N` and `u_k` for every `k < N`.
    ///
    /// # Errors
    /// [`SetError::NonFinite`].
    pub fn set_guess(&mut self, x: &SVector<T, NX>, u: &SVector<T, NU>) -> Result<(), SetError> {
        if !(all_finite(x) && all_finite(u)) {
            return Err(SetError::NonFinite);
        }
        self.x = [*x; N];
        self.xn = *x;
        self.u = [*u; N];
        self.plan = [*u; N];
        Ok(())
    }

    /// Sets the guess of state `k <= N` (`k = N`: the terminal state), the linearization
    /// point of the next [`prepare`](Self::prepare) there.
    ///
    /// # Errors
    /// [`SetError::NonFinite`], [`SetError::StageOutOfRange`]; nothing changes then.
    pub fn set_state_guess(&mut self, k: usize, x: &SVector<T, NX>) -> Result<(), SetError> {
        if !all_finite(x) {
            return Err(SetError::NonFinite);
        }
        if k == N {
            self.xn = *x;
        } else {
            *self.x.get_mut(k).ok_or(SetError::StageOutOfRange)? = *x;
        }
        Ok(())
    }

    /// Sets the guess of control `k < N`, which is also control `k` of the plan that a failed
    /// QP falls back on.
    ///
    /// # Errors
    /// [`SetError::NonFinite`], [`SetError::StageOutOfRange`]; nothing changes then.
    pub fn set_control_guess(&mut self, k: usize, u: &SVector<T, NU>) -> Result<(), SetError> {
        if !all_finite(u) {
            return Err(SetError::NonFinite);
        }
        let (Some(uk), Some(pk)) = (self.u.get_mut(k), self.plan.get_mut(k)) else {
            return Err(SetError::StageOutOfRange);
        };
        *uk = *u;
        *pk = *u;
        Ok(())
    }

    /// Sets the whole trajectory guess stage by stage: `x[k]` for `k < N`, `xn` for `x_N`,
    /// `u[k]` for `k < N` (the controls also become the fallback plan).
    ///
    /// # Errors
    /// [`SetError::NonFinite`]; nothing changes then.
    pub fn set_trajectory_guess(
        &mut self,
        x: &[SVector<T, NX>; N],
        xn: &SVector<T, NX>,
        u: &[SVector<T, NU>; N],
    ) -> Result<(), SetError> {
        if !(x.iter().all(all_finite) && all_finite(xn) && u.iter().all(all_finite)) {
            return Err(SetError::NonFinite);
        }
        self.x = *x;
        self.xn = *xn;
        self.u = *u;
        self.plan = *u;
        Ok(())
    }

    /// The slack penalties in use, `(l1, l2, l1n, l2n)`, as
    /// [`set_soft_penalties`](Self::set_soft_penalties) last accepted them.
    pub fn soft_penalties(
        &self,
    ) -> (
        &SVector<T, NG>,
        &SVector<T, NG>,
        &SVector<T, NGN>,
        &SVector<T, NGN>,
    ) {
        (&self.l1, &self.l2, &self.l1n, &self.l2n)
    }

    /// The objective at the current trajectory: the least-squares cost
    /// `sum_k 1/2 |y_k - yref_k|^2_W + 1/2 |y_N - yref_N|^2_{W_N}`, the general cost terms
    /// `sum_k l(x_k, u_k, p_k) + l_N(x_N, p_N)` ([`Model::GENERAL_COST`]) plus the soft rows' slack
    /// cost at their violation (`l1 v + 1/2 l2 v^2` per violated side,
    /// [`set_soft_penalties`](Self::set_soft_penalties)). Evaluates the model at every stage.
    pub fn cost(&self) -> T {
        self.merit_parts().0
    }

    /// Lower and upper slacks `(sl, su)` of stage `k < N`'s general constraints in the last
    /// QP solution (zero for hard rows and absent sides): how far the plan violates them.
    pub fn slacks(&self, k: usize) -> Option<(SVector<T, NG>, SVector<T, NG>)> {
        self.solver.slacks(k)
    }

    /// Lower and upper slacks of the terminal general constraints ([`slacks`](Self::slacks)).
    pub fn terminal_slacks(&self) -> (SVector<T, NGN>, SVector<T, NGN>) {
        self.solver.terminal_slacks()
    }

    /// The multipliers `pi_k` of the dynamics `x_{k+1} = F(x_k, u_k, p_k)` (`k < N`) in the
    /// last QP solution; the Lagrangian adds `pi_k' (F(x_k, u_k, p_k) - x_{k+1})`.
    pub fn dynamics_multipliers(&self, k: usize) -> Option<&SVector<T, NX>> {
        self.solver.solution().pi.get(k)
    }

    /// The multipliers of stage `k < N`'s general constraints in the last QP (the terminal
    /// ones: [`terminal_constraint_multipliers`](Self::terminal_constraint_multipliers)):
    /// `lam_u - lam_l`, positive
    /// where the upper bound holds the row, negative where the lower one does; the
    /// Lagrangian adds `lam' h(x_k, u_k, p_k)`. The interior point's values: a QP solved on
    /// the warm active set or ended by the polish keeps those of the last interior-point
    /// solve (only QPs without an active general row are solved so; soft rows always go to
    /// the interior point).
    pub fn constraint_multipliers(&self, k: usize) -> Option<SVector<T, NG>> {
        self.solver.row_multipliers(k).map(|(l, u)| u - l)
    }

    /// The multipliers of the terminal general constraints, as
    /// [`constraint_multipliers`](Self::constraint_multipliers).
    pub fn terminal_constraint_multipliers(&self) -> SVector<T, NGN> {
        let (l, u) = self.solver.terminal_row_multipliers();
        u - l
    }

    /// The multipliers of the box bounds of control `k < N` in the last QP, `mu_u - mu_l`
    /// (positive on an upper bound that holds, negative on a lower one, zero where neither
    /// does): from the QP's stationarity in `u_k`, `mu = -(R du + S dx + g_u + B'pi_k +
    /// D'lam_g)`, at its solution (`lam_g` from
    /// [`constraint_multipliers`](Self::constraint_multipliers)).
    pub fn control_bound_multipliers(&self, k: usize) -> Option<SVector<T, NU>> {
        let (s, sol) = (self.qp.stages.get(k)?, self.solver.solution());
        let (dx, du, pi) = (sol.x.get(k)?, sol.u.get(k)?, sol.pi.get(k)?);
        let h = self.qp.h(k);
        let lam = self.constraint_multipliers(k)?;
        Some(-(h.r * du + h.s * dx + s.gu + tr_mul(&s.b, pi) + tr_mul(&s.d, &lam)))
    }

    /// The multipliers of the box bounds of state `k` (`1 <= k <= N`; `x_0` is fixed, not
    /// bounded) in the last QP, as
    /// [`control_bound_multipliers`](Self::control_bound_multipliers): `-(Q dx + S'du + g_x + A'pi_k - pi_{k-1} +
    /// C'lam_g)` (at `k = N`, the terminal Hessian and rows, no dynamics ahead).
    pub fn state_bound_multipliers(&self, k: usize) -> Option<SVector<T, NX>> {
        let sol = self.solver.solution();
        let prev = sol.pi.get(k.checked_sub(1)?)?;
        if k == N {
            let t = &self.qp.terminal;
            let lam = self.terminal_constraint_multipliers();
            return Some(-(t.q * sol.xn + t.gx - prev + tr_mul(&t.c, &lam)));
        }
        let (s, h) = (self.qp.stages.get(k)?, self.qp.h(k));
        let (dx, du, pi) = (sol.x.get(k)?, sol.u.get(k)?, sol.pi.get(k)?);
        let lam = self.constraint_multipliers(k)?;
        let r = h.q * dx + tr_mul(&h.s, du) + s.gx + tr_mul(&s.a, pi) - prev;
        Some(-(r + tr_mul(&s.c, &lam)))
    }

    /// Whether the last preparation condensed the QP ([`QpMethod`](crate::QpMethod)).
    pub fn condensed(&self) -> bool {
        self.solver.condensed()
    }

    /// The QP of the last preparation (for inspection, export and benchmarks).
    pub fn qp(&self) -> &OcpQp<T, NX, NU, NG, NGN, N, NH> {
        &self.qp
    }

    /// State `k <= N` of the current trajectory.
    pub fn state(&self, k: usize) -> Option<&SVector<T, NX>> {
        if k == N {
            Some(&self.xn)
        } else {
            self.x.get(k)
        }
    }

    /// Control `k < N` of the current trajectory.
    pub fn control(&self, k: usize) -> Option<&SVector<T, NU>> {
        self.u.get(k)
    }

    /// Shifts the trajectory one stage forward, repeating the last stage.
    fn shift(&mut self) {
        if N == 0 {
            return;
        }
        for k in 0..N - 1 {
            self.x[k] = self.x[k + 1];
            self.u[k] = self.u[k + 1];
        }
        self.x[N - 1] = self.xn;
        self.solver.shift_active_set();
        if M::EXACT_HESSIAN {
            self.solver.shift_multipliers();
        }
    }

    /// Preparation phase: linearizes dynamics, cost and constraints of every stage around the
    /// current trajectory (after shifting it by one stage if `settings.shift` and a feedback
    /// has happened since the last preparation), then does the QP's work that does not
    /// depend on the state ([`QpSolver::prepare`]: condensing, the first Newton system). Call
    /// it before the state measurement arrives; calling it again without a feedback in
    /// between only re-linearizes.
    pub fn prepare(&mut self) {
        if self.settings.shift && self.pending_shift {
            self.shift();
        }
        self.pending_shift = false;
        self.linearize();
        self.solver.settings = self.settings.qp;
        self.solver.prepare(&self.qp);
        self.prepared = true;
    }

    fn linearize(&mut self) {
        // With constant residual Jacobians, J'WJ changes only with the weights (a general
        // cost adds to it at every linearization: written again each time).
        let gn = M::GENERAL_COST || !(M::CONSTANT_STAGE_RESIDUAL_JACOBIANS && self.gn_current);
        let gn_terminal = M::GENERAL_COST || !(M::CONSTANT_RESIDUAL_JACOBIANS && self.gn_current);
        for k in 0..N {
            let (x, u, p) = (self.x[k], self.u[k], self.p[k]);
            let next = if k + 1 < N { self.x[k + 1] } else { self.xn };
            let s = &mut self.qp.stages[k];
            let fx = self.model.dynamics(&x, &u, &p, &mut s.a, &mut s.b);
            s.f = fx - next;
            let mut jx = SMatrix::<T, NY, NX>::zeros();
            let mut ju = SMatrix::<T, NY, NU>::zeros();
            let r = self.model.residual(&x, &u, &p, &mut jx, &mut ju) - self.yref[k];
            // The gradient J'(W r): `W r` first, then dot products down J's columns (no
            // `(WJ)'`, which only J'WJ below needs).
            let wr = weighted(&self.w, self.w_diag, &r);
            s.gx = tr_mul(&jx, &wr);
            s.gu = tr_mul(&ju, &wr);
            s.lbx = self.lbx - x;
            s.ubx = self.ubx - x;
            s.lbu = self.lbu - u;
            s.ubu = self.ubu - u;
            let h = self.model.constraints(&x, &u, &p, &mut s.c, &mut s.d);
            s.lg = self.lg - h;
            s.ug = self.ug - h;
            s.soft_l1 = self.l1;
            s.soft_l2 = self.l2;
            // One Hessian for all stages (`NH = 1`, constant Jacobians): stage 0's.
            if gn && (NH == N || k == 0) {
                // (WJ)' (a diagonal W scales J's rows), then J'WJ as (WJ)'J: the Jacobian on
                // the right, where its zeros are skipped (a residual that selects states and
                // controls is mostly zeros), written into the stage's Hessian in place.
                let wjxt = weighted_transpose(&self.w, self.w_diag, &jx);
                let wjut = weighted_transpose(&self.w, self.w_diag, &ju);
                let h = self.qp.h_mut(k);
                mul_mostly_zero_into(&mut h.q, &wjxt, &jx);
                mul_mostly_zero_into(&mut h.s, &wjut, &jx);
                mul_mostly_zero_into(&mut h.r, &wjut, &ju);
            }
            if M::GENERAL_COST {
                self.add_general_cost(k);
            }
        }
        self.linearize_terminal(gn_terminal);
        self.gn_current = true;
    }

    /// The terminal part of [`linearize`](Self::linearize). Not inlined: its temporaries
    /// would add to the stack frame of the stages' loop (1.4 KB on a Cortex-M4F).
    #[inline(never)]
    fn linearize_terminal(&mut self, gn: bool) {
        let (xn, pn) = (self.xn, self.pn);
        let t = &mut self.qp.terminal;
        let mut jx = SMatrix::<T, NYN, NX>::zeros();
        let r = self.model.terminal_residual(&xn, &pn, &mut jx) - self.yref_n;
        if gn {
            let wjxt = weighted_transpose(&self.wn, self.wn_diag, &jx);
            mul_mostly_zero_into(&mut t.q, &wjxt, &jx);
        }
        t.gx = tr_mul(&jx, &weighted(&self.wn, self.wn_diag, &r));
        t.lbx = self.lbx - xn;
        t.ubx = self.ubx - xn;
        let h = self.model.terminal_constraints(&xn, &pn, &mut t.c);
        t.lg = self.lgn - h;
        t.ug = self.ugn - h;
        t.soft_l1 = self.l1n;
        t.soft_l2 = self.l2n;
        if M::GENERAL_COST {
            self.add_general_terminal_cost();
        }
    }

    /// The general stage cost's gradient at stage `k < N` added to the QP's gradient, and its
    /// Hessian, projected onto the positive semidefinite cone
    /// ([`project_psd`](crate::convexify::project_psd)), added to the stage's Hessian (the
    /// Gauss-Newton terms of the least squares stay as they are). Not inlined: its
    /// temporaries stay out of the stages' loop.
    #[inline(never)]
    fn add_general_cost(&mut self, k: usize) {
        let (Some(x), Some(u), Some(p)) = (self.x.get(k), self.u.get(k), self.p.get(k)) else {
            return;
        };
        let mut gx = SVector::<T, NX>::zeros();
        let mut gu = SVector::<T, NU>::zeros();
        let mut c = QpHessian::<T, NX, NU>::NEW;
        self.model
            .stage_cost(x, u, p, &mut gx, &mut gu, &mut c.q, &mut c.s, &mut c.r);
        project_psd(&mut c);
        if let Some(s) = self.qp.stages.get_mut(k) {
            s.gx += gx;
            s.gu += gu;
        }
        let h = self.qp.h_mut(k);
        h.q += c.q;
        h.s += c.s;
        h.r += c.r;
    }

    /// The general terminal cost's gradient and projected Hessian added to the terminal QP
    /// ([`add_general_cost`](Self::add_general_cost)).
    #[inline(never)]
    fn add_general_terminal_cost(&mut self) {
        let mut gx = SVector::<T, NX>::zeros();
        let mut hxx = SMatrix::<T, NX, NX>::zeros();
        self.model
            .terminal_cost(&self.xn, &self.pn, &mut gx, &mut hxx);
        project_psd_terminal(&mut hxx);
        let t = &mut self.qp.terminal;
        t.gx += gx;
        t.q += hxx;
    }

    /// Feedback phase: embeds the measured state, solves the QP prepared by
    /// [`prepare`](Self::prepare), takes the full step and returns the control to apply.
    ///
    /// With a non-finite `x0` nothing changes and the status is `NonFiniteInput` (the
    /// returned control is then the next one of the current plan).
    pub fn feedback(&mut self, x0: &SVector<T, NX>) -> (SVector<T, NU>, RtiInfo<T>) {
        let fallback = self.fallback_control();
        let empty = QpInfo {
            status: QpStatus::NonFiniteInput,
            iterations: 0,
            active_set_solves: 0,
            res_stat: T::ZERO,
            res_eq: T::ZERO,
            res_ineq: T::ZERO,
            mu: T::ZERO,
        };
        if !all_finite(x0) {
            return (fallback, self.info(RtiStatus::NonFiniteInput, empty, 0));
        }
        if !self.prepared {
            return (fallback, self.info(RtiStatus::NotPrepared, empty, 0));
        }
        self.prepared = false;
        let x_lin0 = self.x.first().copied().unwrap_or(*x0);
        self.qp.x0 = x0 - x_lin0;
        // Settings changed since the preparation apply (the method was chosen there).
        self.solver.settings = self.settings.qp;
        let qp_info = self.solver.solve_prepared(&self.qp);
        if qp_info.status == QpStatus::Solved && self.step_is_finite() {
            self.apply_step(T::ONE);
            self.pin_x0(x0);
            self.plan = self.u;
            self.plan_age = 0;
            self.failures = 0;
            self.pending_shift = true;
            let u0 = self.u.first().copied().unwrap_or(fallback);
            (u0, self.info(RtiStatus::Ok, qp_info, 1))
        } else {
            // The paper's fallback: keep the last good plan and move along it.
            self.plan_age = (self.plan_age + 1).min(N.saturating_sub(1));
            self.failures = self.failures.saturating_add(1);
            let u = self.fallback_control();
            self.pending_shift = true;
            (u, self.info(self.fallback_status(), qp_info, 1))
        }
    }

    /// The status of a failed feedback: [`RtiStatus::PlanExhausted`] from the
    /// `min(fallback_limit, N)`-th failure in a row on, else `UsedPreviousPlan`.
    fn fallback_status(&self) -> RtiStatus {
        let limit = (self.settings.fallback_limit as usize).min(N);
        if self.failures as usize >= limit {
            RtiStatus::PlanExhausted
        } else {
            RtiStatus::UsedPreviousPlan
        }
    }

    fn info(&self, status: RtiStatus, qp: QpInfo<T>, sqp_iterations: u32) -> RtiInfo<T> {
        RtiInfo {
            status,
            qp,
            sqp_iterations,
            watchdog_returned: false,
            consecutive_failures: self.failures,
        }
    }

    /// The control of the current plan at its age (the first control if no QP has succeeded
    /// yet). Always finite: every stored control came from a finite, checked solution or a
    /// checked guess.
    fn fallback_control(&self) -> SVector<T, NU> {
        self.plan
            .get(self.plan_age)
            .or(self.plan.last())
            .copied()
            .unwrap_or_else(SVector::zeros)
    }

    fn step_is_finite(&self) -> bool {
        let sol = self.solver.solution();
        sol.x.iter().all(all_finite) && sol.u.iter().all(all_finite) && all_finite(&sol.xn)
    }

    /// `trajectory += alpha * step` of the last QP solution.
    fn apply_step(&mut self, alpha: T) {
        let sol = self.solver.solution();
        for k in 0..N {
            self.x[k] += sol.x[k] * alpha;
            self.u[k] += sol.u[k] * alpha;
        }
        self.xn += sol.xn * alpha;
    }

    /// The trial trajectory of the line search is the current one.
    fn save_trial(&mut self) {
        self.xt = self.x;
        self.ut = self.u;
        self.xnt = self.xn;
    }

    /// Back to the trial trajectory of the line search.
    fn restore_trial(&mut self) {
        self.x = self.xt;
        self.u = self.ut;
        self.xn = self.xnt;
    }

    /// The parts of the merit function `cost + penalty + nu * (sum |dynamics defect|_1)` at
    /// the current trajectory, `(cost + penalty, sum |dynamics defect|_1)`, where `penalty` is
    /// the soft rows' slack cost at their violation `v = max(lg - h, 0)`, `max(h - ug, 0)`:
    /// `l1 v + 1/2 l2 v^2` per side (the QP's objective at its optimal slacks; hard rows do
    /// not enter).
    fn merit_parts(&self) -> (T, T) {
        let mut cost = T::ZERO;
        let mut defect = T::ZERO;
        let mut jx = SMatrix::<T, NY, NX>::zeros();
        let mut ju = SMatrix::<T, NY, NU>::zeros();
        for k in 0..N {
            let (x, u, p) = (&self.x[k], &self.u[k], &self.p[k]);
            let next = if k + 1 < N { &self.x[k + 1] } else { &self.xn };
            let r = self.model.residual(x, u, p, &mut jx, &mut ju) - self.yref[k];
            cost += r.dot(&(self.w * r)) * T::lit(0.5);
            if M::GENERAL_COST {
                cost += self.model.stage_cost_value(x, u, p);
            }
            let d = self.model.dynamics_value(x, u, p) - next;
            defect += d.abs().sum();
            if self.any_soft {
                let mut cx = SMatrix::<T, NG, NX>::zeros();
                let mut cu = SMatrix::<T, NG, NU>::zeros();
                let h = self.model.constraints(x, u, p, &mut cx, &mut cu);
                cost += soft_penalty(&h, &self.lg, &self.ug, &self.l1, &self.l2);
            }
        }
        let mut jn = SMatrix::<T, NYN, NX>::zeros();
        let r = self.model.terminal_residual(&self.xn, &self.pn, &mut jn) - self.yref_n;
        cost += r.dot(&(self.wn * r)) * T::lit(0.5);
        if M::GENERAL_COST {
            cost += self.model.terminal_cost_value(&self.xn, &self.pn);
        }
        if self.any_soft {
            let mut cx = SMatrix::<T, NGN, NX>::zeros();
            let h = self.model.terminal_constraints(&self.xn, &self.pn, &mut cx);
            cost += soft_penalty(&h, &self.lgn, &self.ugn, &self.l1n, &self.l2n);
        }
        (cost, defect)
    }

    /// One QP of the full SQP ([`solve_sqp`](Self::solve_sqp)): with `loose`, by the
    /// interior point to `loose_settings` and the polish to `tight` (and `loose` turns off
    /// for the rest of the solve if the polish is refused), else to `tight`.
    fn solve_sqp_qp(
        &mut self,
        loose: &mut bool,
        loose_settings: &QpSettings<T>,
        tight: &QpSettings<T>,
    ) -> QpInfo<T> {
        let mut last = None;
        if *loose {
            self.solver.settings = *loose_settings;
            let info = self.solver.solve(&self.qp);
            // Polished to `tight`'s tolerances (the Riccati recursion's polish checks its
            // result against them).
            self.solver.settings = *tight;
            *loose = info.status == QpStatus::Solved && self.solver.polish(&self.qp);
            last = Some(info);
        }
        match last {
            Some(info) if *loose => info,
            _ => {
                self.solver.settings = *tight;
                self.solver.solve(&self.qp)
            }
        }
    }

    /// The largest KKT residual of the NLP at the iterate of the last linearization
    /// ([`prepare`](Self::prepare), or an iteration of [`solve_sqp`](Self::solve_sqp)), from
    /// its linearization in the QP data (a zero step) and the last QP's multipliers (`pi`,
    /// and the general rows' from the interior point): the initial-state and dynamics
    /// defects; for each state (but `x_0`, which is fixed) and control the natural residual
    /// `clamp(-r, lo, hi)` of the Lagrangian's gradient `r` (with the rows' term `C'lam`)
    /// against the step's bounds `lo <= 0 <= hi`: `|r|` away from the bounds, the distance to
    /// a bound that `r` pushes against (a bound multiplier `|r|` of the right sign is then
    /// complementary to it to that distance), and at least the violation of a violated
    /// bound; and for each side of a soft general row, with constraint value `c` (`h - lg`,
    /// `ug - h`), multiplier `lam >= 0` and slack `v = max(-c, 0)`, the natural residual
    /// `|lam - clamp(lam - c, 0, l1 + l2 v)|` of the penalized row (zero exactly where the
    /// row holds with `lam` complementary to it, or is violated by `v` with
    /// `lam = l1 + l2 v`, the slack's optimality). `None` where a hard general row has a
    /// bound (its multiplier is not kept by every QP path), or without stages.
    pub fn kkt_residual(&self) -> Option<T> {
        let pi = &self.solver.solution().pi;
        let t = &self.qp.terminal;
        if N == 0 || !self.rows_kkt_known() {
            return None;
        }
        // `max` passes over NaN: every term is checked to be finite first.
        let mut res = self.qp.x0.amax();
        let mut finite = all_finite(&self.qp.x0);
        let mut prev: Option<&SVector<T, NX>> = None;
        for (k, (s, pik)) in self.qp.stages.iter().zip(pi).enumerate() {
            let (ll, lu) = self.solver.row_multipliers(k)?;
            let lam = lu - ll;
            let ru = s.gu + tr_mul(&s.b, pik) + tr_mul(&s.d, &lam);
            finite &= all_finite(&s.f) && all_finite(&ru);
            res = res.max(s.f.amax()).max(natural(&ru, &s.lbu, &s.ubu));
            let rows = SoftRows {
                lo: &self.lg,
                hi: &self.ug,
                l1: &self.l1,
                l2: &self.l2,
            };
            res = res.max(rows.residual(&s.lg, &s.ug, &ll, &lu));
            if let Some(pp) = prev {
                let rx = s.gx + tr_mul(&s.a, pik) - pp + tr_mul(&s.c, &lam);
                finite &= all_finite(&rx);
                res = res.max(natural(&rx, &s.lbx, &s.ubx));
            }
            prev = Some(pik);
        }
        let (ll, lu) = self.solver.terminal_row_multipliers();
        let lam = lu - ll;
        let rxn = prev.map_or(t.gx, |pp| t.gx - pp) + tr_mul(&t.c, &lam);
        finite &= all_finite(&rxn);
        res = res.max(natural(&rxn, &t.lbx, &t.ubx));
        let rows = SoftRows {
            lo: &self.lgn,
            hi: &self.ugn,
            l1: &self.l1n,
            l2: &self.l2n,
        };
        res = res.max(rows.residual(&t.lg, &t.ug, &ll, &lu));
        (finite && res.finite()).then_some(res)
    }

    /// Whether every general row with a bound is soft ([`kkt_residual`](Self::kkt_residual)
    /// knows its multipliers: every QP path that solves soft rows, the interior point and
    /// the warm active set, sets them).
    fn rows_kkt_known(&self) -> bool {
        fn all_soft<T: Real, const K: usize>(
            lo: &SVector<T, K>,
            hi: &SVector<T, K>,
            l1: &SVector<T, K>,
            l2: &SVector<T, K>,
        ) -> bool {
            (0..K).all(|i| {
                let bounded = lo[i] > -T::INF || hi[i] < T::INF;
                !bounded || l1[i] > T::ZERO || l2[i] > T::ZERO
            })
        }
        all_soft(&self.lg, &self.ug, &self.l1, &self.l2)
            && all_soft(&self.lgn, &self.ugn, &self.l1n, &self.l2n)
    }

    /// Adds the curvature the Gauss-Newton Hessian leaves out to every stage's Hessian of the
    /// QP (`NH = N`), at the last QP's multipliers: the dynamics' `sum_i pi_i d2F_i/d(x, u)2`
    /// ([`Model::dynamics_hessian`]), the general constraints' `sum_i mu_i d2h_i`
    /// ([`Model::constraints_hessian`], terminal rows too) and, with a general cost
    /// ([`Model::GENERAL_COST`]), the difference between its exact Hessian and the projected
    /// one [`linearize`](Self::linearize) added. `Some(added)` where the QP's Hessian is
    /// then the Lagrangian's, `added` whether it changed (not for zero multipliers and a
    /// convex general cost: the Hessian is then the Lagrangian's as it is); `None` for
    /// non-finite multipliers.
    fn add_dynamics_curvature(&mut self) -> Option<bool> {
        let pi = &self.solver.solution().pi;
        if NH != N || !pi.iter().all(all_finite) {
            return None;
        }
        let mut added = false;
        if !pi.iter().all(|p| p.iter().all(|&v| v == T::ZERO)) {
            let mut c = QpHessian::<T, NX, NU>::NEW;
            for (k, pik) in pi.iter().enumerate() {
                let (Some(x), Some(u), Some(p)) = (self.x.get(k), self.u.get(k), self.p.get(k))
                else {
                    break;
                };
                self.model
                    .dynamics_hessian(x, u, p, pik, &mut c.q, &mut c.s, &mut c.r);
                let h = self.qp.h_mut(k);
                h.q += c.q;
                h.s += c.s;
                h.r += c.r;
            }
            added = true;
        }
        added |= self.add_constraint_curvature()?;
        if M::GENERAL_COST {
            added |= self.add_cost_curvature();
        }
        if added {
            // The next linearization writes the Gauss-Newton terms again.
            self.gn_current = false;
        }
        Some(added)
    }

    /// The general constraints' part of [`add_dynamics_curvature`](Self::add_dynamics_curvature):
    /// `sum_i mu_i d2h_i` at each stage and at the end, with the last QP's row multipliers.
    /// `Some(added)`; `None` for non-finite multipliers.
    #[inline(never)]
    fn add_constraint_curvature(&mut self) -> Option<bool> {
        if NG == 0 && NGN == 0 {
            return Some(false);
        }
        let mut added = false;
        let mut c = QpHessian::<T, NX, NU>::NEW;
        for k in 0..N {
            let mu = self.constraint_multipliers(k)?;
            if !all_finite(&mu) {
                return None;
            }
            if mu.iter().all(|&v| v == T::ZERO) {
                continue;
            }
            let (Some(x), Some(u), Some(p)) = (self.x.get(k), self.u.get(k), self.p.get(k)) else {
                break;
            };
            self.model
                .constraints_hessian(x, u, p, &mu, &mut c.q, &mut c.s, &mut c.r);
            // Linear rows (or the trait's default, zeros) add nothing, and leave the step as
            // it was without them.
            if !(is_zero(&c.q) && is_zero(&c.s) && is_zero(&c.r)) {
                let h = self.qp.h_mut(k);
                h.q += c.q;
                h.s += c.s;
                h.r += c.r;
                added = true;
            }
        }
        let mun = self.terminal_constraint_multipliers();
        if !all_finite(&mun) {
            return None;
        }
        if mun.iter().any(|&v| v != T::ZERO) {
            self.model
                .terminal_constraints_hessian(&self.xn, &self.pn, &mun, &mut c.q);
            if !is_zero(&c.q) {
                self.qp.terminal.q += c.q;
                added = true;
            }
        }
        Some(added)
    }

    /// The general cost's part of [`add_dynamics_curvature`](Self::add_dynamics_curvature):
    /// at every stage (and the end) whose cost Hessian the linearization projected, the
    /// exact Hessian minus the projected one. Whether any stage's changed.
    #[inline(never)]
    fn add_cost_curvature(&mut self) -> bool {
        let mut added = false;
        let mut gx = SVector::<T, NX>::zeros();
        let mut gu = SVector::<T, NU>::zeros();
        for k in 0..N {
            let (Some(x), Some(u), Some(p)) = (self.x.get(k), self.u.get(k), self.p.get(k)) else {
                break;
            };
            let mut c = QpHessian::<T, NX, NU>::NEW;
            self.model
                .stage_cost(x, u, p, &mut gx, &mut gu, &mut c.q, &mut c.s, &mut c.r);
            let exact = c;
            if project_psd(&mut c) {
                let h = self.qp.h_mut(k);
                h.q += exact.q - c.q;
                h.s += exact.s - c.s;
                h.r += exact.r - c.r;
                added = true;
            }
        }
        let mut hxx = SMatrix::<T, NX, NX>::zeros();
        self.model
            .terminal_cost(&self.xn, &self.pn, &mut gx, &mut hxx);
        let exact = hxx;
        if project_psd_terminal(&mut hxx) {
            self.qp.terminal.q += exact - hxx;
            added = true;
        }
        added
    }

    /// Full SQP from the current trajectory with `x_0` fixed to `x0`: Gauss-Newton steps, or
    /// exact-Hessian ones where the model provides the dynamics' Hessian
    /// ([`RtiSettings::sqp_exact_hessian`]), with a line search on an exact L1 merit function
    /// (`cost + soft-constraint penalties + nu |dynamics defects|_1`, `nu` twice the largest
    /// dynamics multiplier; exact-Hessian steps under a watchdog,
    /// [`RtiSettings::sqp_watchdog`]), until the iterate meets the KKT conditions to
    /// `settings.sqp_kkt_tol`, the largest entry of the QP step is below `settings.sqp_tol`,
    /// or `settings.sqp_max_iter` iterations. For offline planning and tests. The trajectory
    /// is left at the last accepted iterate (the watchdog's reference where its steps did not
    /// pay by the last iteration). Each QP is solved to at
    /// least the QP solver's default tolerances: with `settings.sqp_loose_qps` (on in f64) by
    /// the interior point to 1e-3 and then the active-set polish (exact once the interior
    /// point has the active set), or, where the polish is refused or does not apply (soft
    /// rows), to those tolerances directly.
    pub fn solve_sqp(&mut self, x0: &SVector<T, NX>) -> RtiInfo<T> {
        let empty = QpInfo {
            status: QpStatus::NonFiniteInput,
            iterations: 0,
            active_set_solves: 0,
            res_stat: T::ZERO,
            res_eq: T::ZERO,
            res_ineq: T::ZERO,
            mu: T::ZERO,
        };
        if !all_finite(x0) {
            return self.info(RtiStatus::NonFiniteInput, empty, 0);
        }
        let mut run = self.sqp_start(empty);
        for it in 0..self.settings.sqp_max_iter {
            if let Some(done) = self.sqp_iteration(&mut run, x0, it) {
                return done;
            }
        }
        if run.watch.is_some() {
            // Steps still watched at the limit (their QPs were not Newton's, so the watchdog
            // did not judge them): nothing got below the reference, which is kept.
            run.returned = true;
            self.restore_reference(x0);
        }
        self.sqp_info(
            RtiStatus::MaxIterations,
            run.last,
            self.settings.sqp_max_iter,
            run.returned,
        )
    }

    /// The full SQP's state before its first iteration ([`solve_sqp`](Self::solve_sqp)):
    /// its QPs' tolerances, whether its steps are exact-Hessian ones, nothing watched and
    /// nothing known of the merit yet.
    fn sqp_start(&self, empty: QpInfo<T>) -> SqpRun<T> {
        // The step test needs accurate steps: at least the QP solver's own tolerances.
        let mut tight = self.settings.qp;
        tight.tol_stat = tight.tol_stat.min(T::DEFAULT_TOL);
        tight.tol_eq = tight.tol_eq.min(T::DEFAULT_TOL);
        tight.tol_ineq = tight.tol_ineq.min(T::DEFAULT_TOL);
        tight.tol_comp = tight.tol_comp.min(T::DEFAULT_TOL_COMP);
        tight.polish |= T::DEFAULT_POLISH;
        // Exact steps for less: the interior point only to `SQP_LOOSE_QP_TOL`, then the
        // active-set polish with `tight`'s tolerances, which ends on the QP's exact solution
        // once the interior point has its active set. A QP whose polish is refused (or that
        // the polish does not handle: soft rows, the Riccati recursion in a solver with
        // condensing storage) is solved again to `tight`, and the rest of this solve goes
        // straight to `tight`.
        let mut loose_settings = tight;
        let lt = T::lit(SQP_LOOSE_QP_TOL);
        loose_settings.tol_stat = lt.max(tight.tol_stat);
        loose_settings.tol_eq = lt.max(tight.tol_eq);
        loose_settings.tol_ineq = lt.max(tight.tol_ineq);
        loose_settings.tol_comp = lt.max(tight.tol_comp);
        loose_settings.polish = false;
        let exact = M::EXACT_HESSIAN && NH == N && self.settings.sqp_exact_hessian;
        SqpRun {
            tight,
            loose_settings,
            loose: self.settings.sqp_loose_qps && !self.any_soft,
            exact,
            gauss_newton_next: false,
            watchdog_on: exact && self.settings.sqp_watchdog > 0,
            watch: None,
            returned: false,
            here: None,
            last: empty,
        }
    }

    /// Iteration `it` of the full SQP ([`solve_sqp`](Self::solve_sqp)): linearize, stop on
    /// the KKT conditions, solve the QP, stop on a short step, else move along the step (the
    /// watchdog's decision for a watched Newton step, the line search otherwise). `Some`
    /// with the outcome where the solve ends here.
    fn sqp_iteration(
        &mut self,
        run: &mut SqpRun<T>,
        x0: &SVector<T, NX>,
        it: u32,
    ) -> Option<RtiInfo<T>> {
        self.linearize();
        let x_lin0 = self.x.first().copied().unwrap_or(*x0);
        self.qp.x0 = x0 - x_lin0;
        // Converged on the KKT conditions with the last QP's multipliers: done without the
        // QP that would only confirm it (its step under `sqp_tol`).
        let kkt_tol = self.settings.sqp_kkt_tol;
        if it > 0 && kkt_tol > T::ZERO && self.kkt_residual().is_some_and(|r| r <= kkt_tol) {
            return Some(self.sqp_converged(run, it));
        }
        let Some(kind) = self.sqp_step(run) else {
            return Some(self.sqp_info(
                RtiStatus::UsedPreviousPlan,
                run.last,
                it + 1,
                run.returned,
            ));
        };
        let (step, nu) = self.step_length_and_nu();
        // The first state is pinned to x0 exactly; the line search moves the rest.
        self.pin_x0(x0);
        if step <= self.settings.sqp_tol {
            // Converged: the step is below the tolerance; taken whole, without a search.
            self.apply_step(T::ONE);
            self.pin_x0(x0);
            return Some(self.sqp_converged(run, it + 1));
        }
        // The merit's parts at the current iterate: those of the step accepted last (the
        // pinned first state has not moved since), else evaluated.
        let parts = match run.here.take() {
            Some(parts) => parts,
            None => self.merit_parts(),
        };
        let at = MeritAt {
            nu,
            parts,
            phi: parts.0 + nu * parts.1,
        };
        self.save_trial();
        if kind.newton && run.watchdog_on && self.watchdog(run, x0, it, &at) {
            return None;
        }
        self.search_and_step(run, x0, &at, kind);
        None
    }

    /// The full SQP's end at a converged iterate after `iterations` iterations: its controls
    /// are the plan.
    fn sqp_converged(&mut self, run: &SqpRun<T>, iterations: u32) -> RtiInfo<T> {
        self.plan = self.u;
        self.plan_age = 0;
        self.failures = 0;
        self.sqp_info(RtiStatus::Ok, run.last, iterations, run.returned)
    }

    /// The QP step of an SQP iteration: Newton's where the Hessian is the Lagrangian's
    /// (exact steps, but not right after an exact step that found no decrease), with
    /// Gauss-Newton's Hessian where the one with the dynamics' curvature fails. `None` where
    /// the QP is not solved or its step is not finite.
    fn sqp_step(&mut self, run: &mut SqpRun<T>) -> Option<SqpStep> {
        // A Newton step: the QP's Hessian is the Lagrangian's (`curved`: with the dynamics'
        // curvature added, not zero).
        let hessian = if run.exact && !run.gauss_newton_next {
            self.add_dynamics_curvature()
        } else {
            None
        };
        let mut kind = SqpStep {
            newton: hessian.is_some(),
            curved: hessian == Some(true),
        };
        run.gauss_newton_next = false;
        let loose_before = run.loose;
        run.last = self.solve_sqp_qp(&mut run.loose, &run.loose_settings, &run.tight);
        if kind.curved && (run.last.status != QpStatus::Solved || !self.step_is_finite()) {
            // The QP with the curvature is not convex where it must be (or broke down): this
            // iteration with Gauss-Newton's Hessian, which is.
            self.linearize();
            kind = SqpStep {
                newton: false,
                curved: false,
            };
            run.loose = loose_before;
            run.last = self.solve_sqp_qp(&mut run.loose, &run.loose_settings, &run.tight);
        }
        (run.last.status == QpStatus::Solved && self.step_is_finite()).then_some(kind)
    }

    /// The largest entry of the last QP's step, and the merit function's weight of the
    /// dynamics defects, `nu`: twice the largest dynamics multiplier, at least one.
    fn step_length_and_nu(&self) -> (T, T) {
        let sol = self.solver.solution();
        let mut step = sol.xn.amax();
        let mut nu = T::ONE;
        for k in 0..N {
            step = step.max(sol.x[k].amax()).max(sol.u[k].amax());
            nu = nu.max(sol.pi[k].amax() * T::lit(2.0));
        }
        (step, nu)
    }

    /// The watchdog's decision on a Newton step from the iterate saved as the trial
    /// (Chamberlain, Powell, Lemarechal and Pedersen, 1982): Newton's step is taken whole
    /// where it decreases the merit below the reference's (the current iterate's, or while
    /// steps are watched, the iterate before the first of them); up to `sqp_watchdog` steps
    /// in a row are taken whole without that (not in the last iteration, which could not
    /// come back), and if none of them gets there, the iteration goes back to the reference
    /// and searches monotonically from there on. Newton's whole steps converge where the
    /// monotone search crawls: from the hover guess, QR-bench A's first step takes 30
    /// iterations with it (most of them short steps), 7 with the watchdog (`mpcc bench --sqp
    /// [--sqp-watchdog 0]`: the most iterations in a step). `true` where it decided (the
    /// iteration is over), `false` where this step searches monotonically (the trajectory
    /// back at the trial).
    fn watchdog(
        &mut self,
        run: &mut SqpRun<T>,
        x0: &SVector<T, NX>,
        it: u32,
        at: &MeritAt<T>,
    ) -> bool {
        self.apply_step(T::ONE);
        self.pin_x0(x0);
        let parts = self.merit_parts();
        let phi = parts.0 + at.nu * parts.1;
        let (reference, phi_ref) = match run.watch {
            Some((r, _)) => (r, r.0 + at.nu * r.1),
            None => (at.parts, at.phi),
        };
        if phi.finite() && phi < phi_ref {
            // Below the reference: accepted, and the watch (if any) ends.
            run.watch = None;
            run.here = Some(parts);
            return true;
        }
        let relaxed = run.watch.map_or(0, |(_, n)| n);
        let last_iteration = it + 1 >= self.settings.sqp_max_iter;
        if phi.finite() && relaxed < self.settings.sqp_watchdog && !last_iteration {
            // Not below it: taken anyway, the iterate before it kept as the reference (the
            // first such step's).
            if run.watch.is_none() {
                self.keep_trial_as_reference();
            }
            run.watch = Some((reference, relaxed + 1));
            run.here = Some(parts);
            return true;
        }
        if run.watch.is_some() {
            // The watched steps did not bring the merit below the reference's: back to the
            // reference, and monotone searches for the rest of this solve.
            run.watchdog_on = false;
            run.returned = true;
            self.restore_reference(x0);
            run.watch = None;
            run.here = Some(reference);
            return true;
        }
        // Nothing watched: this step searches monotonically.
        self.restore_trial();
        false
    }

    /// The trial (the iterate before a watched step) becomes the watchdog's reference
    /// (`NH = N` there, [`watchdog`](Self::watchdog): the whole trajectory).
    fn keep_trial_as_reference(&mut self) {
        for (w, t) in self.xw.iter_mut().zip(&self.xt) {
            *w = *t;
        }
        for (w, t) in self.uw.iter_mut().zip(&self.ut) {
            *w = *t;
        }
        self.xnw = self.xnt;
    }

    /// The line search along the last QP's step from the trial
    /// ([`line_search`](Self::line_search)) and the move to the step length it chose; an
    /// exact-Hessian step without any decrease stays at the trial instead and has the next
    /// iteration take Gauss-Newton's Hessian.
    fn search_and_step(
        &mut self,
        run: &mut SqpRun<T>,
        x0: &SVector<T, NX>,
        at: &MeritAt<T>,
        kind: SqpStep,
    ) {
        let alpha = match self.line_search(x0, at, kind.newton) {
            Search::NoDecrease(_) if kind.curved => {
                // No decrease along the exact-Hessian step (not a descent direction of the
                // merit function where the Lagrangian is not convex): stay, and take the
                // next iteration with Gauss-Newton's Hessian.
                self.restore_trial();
                run.here = Some(at.parts);
                run.gauss_newton_next = true;
                return;
            }
            Search::Decrease(best) => {
                run.here = Some(best.parts);
                // A watch ends where a searched step, too, gets below its reference.
                if let Some(((c, d), _)) = run.watch
                    && best.phi < c + at.nu * d
                {
                    run.watch = None;
                }
                best.alpha
            }
            // No improvement at all (converged to rounding, or a poor direction): the
            // smallest step tried, so the iteration cannot stall on a stale linearization.
            Search::NoDecrease(shortest) => shortest,
        };
        self.restore_trial();
        self.apply_step(alpha);
        self.pin_x0(x0);
    }

    /// Backtracking from the trial along the last QP's step that keeps halving while the
    /// merit keeps improving: it takes the full step where that is best and damps the
    /// overshoot of Gauss-Newton steps that oscillate (a plain Armijo test accepts those and
    /// converges slowly). An exact-Hessian step (`newton`) that decreases the merit is taken
    /// whole (Newton's steps do not oscillate so; near the solution the full step is the
    /// best). The trajectory is left at the last step tried.
    fn line_search(&mut self, x0: &SVector<T, NX>, at: &MeritAt<T>, newton: bool) -> Search<T> {
        let mut best = SearchPoint {
            alpha: T::ZERO,
            phi: at.phi,
            parts: at.parts,
        };
        let mut alpha = T::ONE;
        for _ in 0..MAX_HALVINGS {
            self.restore_trial();
            self.apply_step(alpha);
            self.pin_x0(x0);
            let parts = self.merit_parts();
            let phi = parts.0 + at.nu * parts.1;
            if phi.finite() && phi < best.phi {
                best = SearchPoint { alpha, phi, parts };
                if newton {
                    break;
                }
            } else if best.alpha > T::ZERO {
                break;
            }
            alpha *= T::lit(0.5);
        }
        if best.alpha > T::ZERO {
            Search::Decrease(best)
        } else {
            Search::NoDecrease(alpha * T::lit(2.0))
        }
    }

    /// `x_0 = x0`: the trajectory's first state is the measured one.
    fn pin_x0(&mut self, x0: &SVector<T, NX>) {
        if let Some(x) = self.x.first_mut() {
            *x = *x0;
        }
    }

    /// The outcome of a full SQP solve ([`solve_sqp`](Self::solve_sqp)).
    fn sqp_info(
        &self,
        status: RtiStatus,
        qp: QpInfo<T>,
        sqp_iterations: u32,
        watchdog_returned: bool,
    ) -> RtiInfo<T> {
        RtiInfo {
            watchdog_returned,
            ..self.info(status, qp, sqp_iterations)
        }
    }

    /// Back to the watchdog's reference ([`solve_sqp`](Self::solve_sqp); `NH = N` there),
    /// `x_0` pinned to `x0`.
    fn restore_reference(&mut self, x0: &SVector<T, NX>) {
        for (x, w) in self.x.iter_mut().zip(&self.xw) {
            *x = *w;
        }
        for (u, w) in self.u.iter_mut().zip(&self.uw) {
            *u = *w;
        }
        self.xn = self.xnw;
        self.pin_x0(x0);
    }
}

/// Interior-point tolerance of the full SQP's QPs before their polish ([`Rti::solve_sqp`]).
/// On QR-bench's QPs the polish lands on the exact solution from it with 4 interior-point
/// iterations instead of 7 (`mpcc-condensed-polished` in `benches/runtime.rs`).
const SQP_LOOSE_QP_TOL: f64 = 1e-3;

/// The full SQP's state from one iteration to the next ([`Rti::solve_sqp`]).
struct SqpRun<T> {
    /// Every QP to at least the QP solver's own tolerances (and the polish's).
    tight: QpSettings<T>,
    /// The interior point's tolerances before the polish, with `loose`.
    loose_settings: QpSettings<T>,
    /// The QPs loosely by the interior point, then polished; off for the rest of the solve
    /// once a polish is refused.
    loose: bool,
    /// Exact-Hessian steps ([`RtiSettings::sqp_exact_hessian`], where the model has the
    /// dynamics' Hessian and a Hessian per stage).
    exact: bool,
    /// The next iteration with Gauss-Newton's Hessian: the last exact step found no decrease.
    gauss_newton_next: bool,
    /// The watchdog judges Newton's steps (off once it has gone back to its reference).
    watchdog_on: bool,
    /// The merit's parts at the watchdog's reference and the steps watched since.
    watch: Option<((T, T), u32)>,
    /// The watchdog went back to its reference.
    returned: bool,
    /// The merit's parts (cost, defects) at the current iterate, where known.
    here: Option<(T, T)>,
    /// The last QP's outcome.
    last: QpInfo<T>,
}

/// Which Hessian an SQP step's QP had ([`Rti::solve_sqp`]).
#[derive(Clone, Copy)]
struct SqpStep {
    /// The Lagrangian's: a Newton step.
    newton: bool,
    /// With the dynamics' curvature added (not zero).
    curved: bool,
}

/// The merit function at the current iterate of the full SQP: its weight of the dynamics
/// defects `nu`, its parts (cost, defects) and its value `phi`.
struct MeritAt<T> {
    nu: T,
    parts: (T, T),
    phi: T,
}

/// A point of the full SQP's line search: its step length, merit and the merit's parts.
#[derive(Clone, Copy)]
struct SearchPoint<T> {
    alpha: T,
    phi: T,
    parts: (T, T),
}

/// What the full SQP's line search found.
enum Search<T> {
    /// The best step tried, which decreases the merit.
    Decrease(SearchPoint<T>),
    /// No step tried decreased the merit; the shortest step tried.
    NoDecrease(T),
}

/// `out = m / 2 + m' / 2`, entry by entry (no temporaries: a Cortex-M4F's set-up took 3.5 KB
/// of stack for them); whether an entry changed (`!=`).
fn symmetric_part_into<T: Real, const R: usize>(
    out: &mut SMatrix<T, R, R>,
    m: &SMatrix<T, R, R>,
) -> bool {
    let half = T::lit(0.5);
    let md = &m.data.0;
    let mut changed = false;
    for (c, col) in out.data.0.iter_mut().enumerate() {
        for (r, o) in col.iter_mut().enumerate() {
            let v = md[c][r] * half + md[r][c] * half;
            changed |= v != *o;
            *o = v;
        }
    }
    changed
}

/// Whether every entry of `m` is zero.
fn is_zero<T: Real, const R: usize, const C: usize>(m: &SMatrix<T, R, C>) -> bool {
    m.iter().all(|&v| v == T::ZERO)
}

/// Whether every off-diagonal entry of `m` is zero.
fn is_diagonal<T: Real, const R: usize>(m: &SMatrix<T, R, R>) -> bool {
    m.iter()
        .enumerate()
        .all(|(idx, &v)| idx % R == idx / R || v == T::ZERO)
}

/// The natural residual `max_i |clamp(-r_i, lo_i, hi_i)|` of a gradient `r` against a step's
/// bounds `lo <= 0 <= hi` ([`Rti::kkt_residual`]).
fn natural<T: Real, const K: usize>(
    r: &SVector<T, K>,
    lo: &SVector<T, K>,
    hi: &SVector<T, K>,
) -> T {
    let mut m = T::ZERO;
    for i in 0..K {
        m = m.max((-r[i]).max(lo[i]).min(hi[i]).abs());
    }
    m
}

/// The bounds and penalties of general rows, for [`Rti::kkt_residual`].
struct SoftRows<'a, T: Real, const K: usize> {
    lo: &'a SVector<T, K>,
    hi: &'a SVector<T, K>,
    l1: &'a SVector<T, K>,
    l2: &'a SVector<T, K>,
}

impl<T: Real, const K: usize> SoftRows<'_, T, K> {
    /// The largest natural residual of the penalized rows from the QP's row data at a zero
    /// step (`qlo = lo - h`, `qhi = hi - h`) and the rows' multipliers. Absent sides (at or
    /// beyond `Real::INF` in the bounds) and rows without a penalty are skipped.
    fn residual(
        &self,
        qlo: &SVector<T, K>,
        qhi: &SVector<T, K>,
        ll: &SVector<T, K>,
        lu: &SVector<T, K>,
    ) -> T {
        let side = |c: T, lam: T, i: usize| {
            let cap = self.l1[i] + self.l2[i] * (-c).max(T::ZERO);
            (lam - (lam - c).max(T::ZERO).min(cap)).abs()
        };
        let mut m = T::ZERO;
        for i in 0..K {
            if !(self.l1[i] > T::ZERO || self.l2[i] > T::ZERO) {
                continue;
            }
            // A lower bound: `c = h - lo = -(lo - h)`; an upper one: `c = hi - h`.
            if self.lo[i] > -T::INF {
                m = m.max(side(-qlo[i], ll[i], i));
            }
            if self.hi[i] < T::INF {
                m = m.max(side(qhi[i], lu[i], i));
            }
        }
        m
    }
}

/// Whether the symmetric part of `m` is positive semidefinite: its diagonal non-negative
/// and, where it has off-diagonal entries, no pivot of its symmetric Gaussian elimination
/// below `-tol` and no zero pivot (within `tol`) with a non-zero column below it, where
/// `tol` is `R` times the largest diagonal entry times `Real::EPSILON`, times 100.
fn positive_semidefinite<T: Real, const R: usize>(m: &SMatrix<T, R, R>) -> bool {
    if !(0..R).all(|i| m[(i, i)] >= T::ZERO) {
        return false;
    }
    is_diagonal(m) || elimination_is_semidefinite(m)
}

/// The elimination of [`positive_semidefinite`] on `(m + m') / 2`, in its own frame (a copy
/// of the matrix) that only non-diagonal weights need.
#[inline(never)]
fn elimination_is_semidefinite<T: Real, const R: usize>(m: &SMatrix<T, R, R>) -> bool {
    let mut a = SMatrix::<T, R, R>::zeros();
    symmetric_part_into(&mut a, m);
    let big = (0..R).fold(T::ZERO, |b, i| b.max(a[(i, i)]));
    let tol = big * T::EPSILON * T::lit(100.0 * R as f64);
    for j in 0..R {
        let d = a[(j, j)];
        if d < -tol {
            return false;
        }
        if d <= tol {
            if (j + 1..R).any(|i| a[(i, j)].abs() > tol) {
                return false;
            }
            continue;
        }
        for i in j + 1..R {
            let l = a[(i, j)] / d;
            for c in j + 1..R {
                let v = a[(j, c)];
                a[(i, c)] -= l * v;
            }
        }
    }
    true
}
