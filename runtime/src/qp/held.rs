//! The warm active set for QPs the Riccati recursion solves
//! ([`QpSettings::warm_active_set`](crate::QpSettings::warm_active_set); a condensed QP has
//! its own, in `condense.rs`).
//!
//! A real-time iteration's QPs change little from one control step to the next, and so do
//! the bounds and rows that hold in their solutions. The set holds control bounds, and rows
//! ([`Hold`]: state bounds by slot and general rows, at the stages and the terminal stage):
//! each free (force zero), held at a bound (the row equals it; a soft row's slack is zero
//! and its force between 0 and `l1`) or, a soft row, violated (slack `s > 0`, force
//! `l1 + l2 s`: a linear and a quadratic term of the row). On that set the QP is an
//! equality-constrained linear-quadratic problem plus the violated rows' penalties:
//!
//! - Held controls drop out of the Riccati recursion (their rows and columns of
//!   `R~ = R + B'PB` replaced by the identity, their rows of `S~ = S + B'PA` by zeros).
//! - A violated soft row adds `l2 a a'` to the Hessian along it (`a` its row `[C D]`, `e_j`
//!   for a state bound), as a barrier weight would; its force is exact in one step.
//! - A held row gets the penalty weight `w = 1 / sqrt(eps)` (the polish's), which makes the
//!   factorization that of the KKT system regularized by `-1/w` in the row's multiplier `y`;
//!   each Newton step adds the gradient `a (w (c - b) - y)` and updates `y -= w (c - b +
//!   a'dz)` (iterative refinement of the unregularized system: the error of `y` contracts by
//!   about `1 / (1 + w s)` a step, `s` the smallest eigenvalue of the held rows' Schur
//!   complement).
//!
//! None of it depends on `x0`: [`QpSolver::prepare`] factorizes it (the recursion with no
//! barrier weight otherwise). The solve is then `1 + settings.refine` Newton steps from zero
//! with the held controls on their bounds, one more where rows are held (a backward and a
//! forward vector pass each; the held controls' steps are zero), which give the active-set
//! QP's solution, its dynamics multipliers and the held rows' multipliers. The bounds'
//! multipliers follow from the controls' stationarity, `mu = R u + S x + gu + B'pi - D'y`.
//!
//! The result is the QP's solution if the rows, set from it, meet the interior point's own
//! stopping test: its stationarity, dynamics and inequality residuals within the
//! tolerances. Held sides are set at zero slack with the multipliers `max(mu, 0)` on a lower
//! side and `max(-mu, 0)` on an upper one; a violated soft side with its violation as slack
//! and the force `l1 + l2 s` as multiplier; every other side free with its slack from the
//! values and multiplier zero; a soft side's slack multiplier is `max(l1 - lam, 0)`. So a
//! held side with a multiplier of the wrong sign (or, soft, above `l1`), or a violated one
//! whose force is below `l1`, shows in the stationarity residual, a held side off its bound
//! or a free one past it in the inequality residual; complementarity is zero. Where only
//! control bounds are held and no row is soft the residuals come from one pass that leaves
//! out the rows' zero terms (`hold_rows`); otherwise from the interior point's `residuals`
//! and `stationarity`.
//! One more Newton step (with held rows, up to [`ROW_RETRIES`] more pairs) is taken where
//! the first misses by less than 1e4 times the tolerances (rounding, or the penalty's
//! contraction); otherwise the set moves (up to [`ITERATIONS`] times, one factorization
//! each): a control or row held with the wrong sign is freed, a free one past a bound is
//! held on it, a held soft row whose force passed `l1` becomes violated, a violated one
//! whose slack would be negative is held (with `l1 = 0`: free, and a free one past its bound
//! violated). If that ends nowhere, the interior point solves the QP from the start,
//! warm-started from the rows as set.
//!
//! A move that only adds control bounds, with no row held or soft, is taken without
//! refactorizing when that is cheaper (the Schur complement of the added bounds): the
//! solution on the factorized set `F` plus forces `d_l` (gradients) on the added controls
//! `l` is the solution on the new set when the forces hold those controls on their bounds.
//! With `M_jl` the response of control `j` to a unit gradient on control `l` (one backward
//! pass from `l`'s stage and one forward pass to the last stage with such a bound, on the
//! factorization of `F`), the forces solve `M d = b - u` (`-M` is positive definite where
//! the new set's reduced Hessian is; its Cholesky factor is checked), and their response is
//! one more pair of passes. From the last set's solution that is the whole solve; a further
//! Newton step (the retry, or iterative refinement) is a step on `F`, then the same
//! correction. Up to 8 bounds are held so in one solve, while their passes cost less than
//! refactorizing the stages up to the last one that changed (one stage's factorization
//! counted as 10 stages of passes; about 14 in callgrind on QR-bench:
//! `runtime/examples/cold_qp.rs`). A move may also free bounds held so: their forces, `-mu`
//! from the controls' stationarity, are cancelled by one more pair of passes before the
//! correction. A move that frees a bound the factorization holds refactorizes, and so does
//! a move of a row (the whole recursion; a move of control bounds alone refactorizes the
//! stages up to the last one that changed).
//!
//! The set is taken from each interior-point solution: the control bounds, state bounds and
//! general rows whose multiplier exceeds their slack, a soft side among them violated where
//! its slack exceeds the slack's multiplier (or it has no `l1`). [`QpSolver::shift_active_set`]
//! moves it, rows included, with the trajectory.

use super::polish::{Side, initial_sides};
use super::{Newton, OcpQp, QpInfo, QpSolution, QpSolver, QpStatus, Vect};
use crate::kernels::{mul, mul_sparse, tr_mul};
use crate::real::Real;
use crate::rows::{Rows, Soft};
use nalgebra::{SMatrix, SVector};

/// Active-set moves after a warm set that missed, at most (each one factorization), before
/// the interior point takes over.
const ITERATIONS: usize = 4;

/// Retries (one more pair of steps each) of a solve that holds rows, where the residuals
/// are near the tolerances: the penalty iteration contracts slowly in f32 or on nearly
/// dependent rows.
const ROW_RETRIES: usize = 3;

/// Bounds held through the Schur complement on top of the factorized set in one solve, at
/// most (module docs); a move past it refactorizes.
const COLUMNS: usize = 8;

/// What factorizing one stage of the recursion costs, in stages of a unit response's
/// passes (`forced`): a move holds its bounds through the Schur complement when their
/// responses cost less than refactorizing the stages up to the last one that changed.
const STAGE_FACTORIZATION: usize = 10;

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
    /// Whether the loaded QP has a soft row (its rows are then set and judged by the
    /// general residuals).
    fn any_soft(&self) -> bool {
        (NG > 0 && self.sg.iter().any(|s| s.any)) || (NGN > 0 && self.sgn.any)
    }

    /// The preparation of the warm active set of the Riccati recursion: the stored set, less
    /// the bounds and rows the QP no longer has, factorized. Returns whether the
    /// factorization succeeded (`false` also without Riccati storage).
    pub(super) fn prepare_held<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> bool {
        if NR != N {
            return false;
        }
        let (lower, upper) = self.present_active_set();
        let rows = self.present_rows();
        self.factorize(qp, Newton::Held(&held(&lower, &upper), &rows))
    }

    /// The solve on the warm active set that [`prepare_held`](Self::prepare_held)
    /// factorized (module docs). `Ok` with the solve's outcome, or `Err` with the active-set
    /// solves spent when the interior point must solve the QP (also for a non-finite `x0`,
    /// which it reports; nothing is changed then).
    // Over 80 lines: one loop of moves and solves whose state (the sets, the factorized
    // set, the Schur columns, the rows' multipliers) is shared by every branch.
    #[inline(never)]
    pub(super) fn solve_held<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> Result<QpInfo<T>, u32> {
        if NR != N || !qp.x0.iter().all(|v| v.finite()) {
            return Err(0);
        }
        let (mut lower, mut upper) = self.stored_active_set();
        let mut rows = self.act_rows;
        // The held rows' multipliers, refined by each step (module docs).
        let mut y = RowVals::ZERO;
        self.rows_on = rows.any() || self.any_soft();
        self.sol = QpSolution::NEW;
        if let Some(x) = self.sol.x.first_mut() {
            *x = qp.x0;
        }
        // The set the recursion is factorized on, and the bounds held on top of it through
        // the Schur complement (module docs).
        let mut factored = held(&lower, &upper);
        let mut cols = Columns::<T>::new();
        let mut solves = 0;
        // The sets of a point whose rows were not set (its set plainly missed, below): set
        // them if the solve ends there, for the interior point's warm start.
        let mut unset: Option<Sets<NU, N>> = None;
        for round in 0..=ITERATIONS {
            // Each round after the first moves the set, and holds the bounds it adds through
            // the Schur complement or factorizes the new set.
            let mut schur = false;
            if round > 0 {
                let before = held(&lower, &upper);
                let sets = (lower, upper);
                let rows_before = rows;
                let moved = self.move_held_set(qp, &mut lower, &mut upper);
                if !(self.move_held_rows(qp, &mut rows, &mut y) || moved) {
                    self.set_rows_if(qp, unset, &rows, &y);
                    return Err(solves);
                }
                self.store_active_set(&lower, &upper);
                self.act_rows = rows;
                self.rows_on = rows.any() || self.any_soft();
                let now = held(&lower, &upper);
                // Bounds added through the Schur complement only where no row is held (the
                // rows' penalty iteration would have to run through it).
                schur =
                    !self.rows_on && self.hold_by_columns(qp, &factored, &before, &now, &mut cols);
                if !schur {
                    // The recursion runs backward: the stages after the last one whose held
                    // controls changed keep their factorization (the last one's, on this
                    // QP); a row that moved refactorizes the whole.
                    let stages = if rows == rows_before {
                        (0..N)
                            .rev()
                            .find(|&k| now[k] != factored[k])
                            .map_or(0, |k| k + 1)
                    } else {
                        N
                    };
                    if !self.factorize_stages(qp, Newton::Held(&now, &rows), stages) {
                        self.act_valid = false;
                        self.set_rows_if(qp, unset.map(|_| sets), &rows_before, &y);
                        return Err(solves);
                    }
                    factored = now;
                    cols = Columns::new();
                }
            }
            // On a new factorization the solve starts from zero with the held controls on
            // their bounds; through the Schur complement, from the last set's solution.
            if !schur {
                self.held_controls_on_bounds(&lower, &upper);
            }
            // Held rows: one more step (the first gives their multipliers to the penalty's
            // precision, the second to rounding), and more retries where that leaves them
            // near the tolerances (a slow contraction: f32, nearly dependent rows).
            let penalized = rows.any_held();
            let mut steps = 1 + self.settings.refine + u32::from(penalized);
            let retries = if penalized { ROW_RETRIES } else { 1 };
            for retry in 0..=retries {
                solves += 1;
                if schur {
                    // The last set's solution plus the bounds' forces is the new set's; each
                    // further step is a Newton step on the factorized set, corrected so.
                    if retry == 0 {
                        self.correct(qp, &factored, &lower, &cols);
                    }
                    for _ in 0..steps - 1 {
                        self.held_step(qp, &factored);
                        self.correct(qp, &factored, &lower, &cols);
                    }
                } else {
                    for _ in 0..steps {
                        self.held_step_rows(qp, &factored, &rows, &mut y);
                    }
                }
                // A free control past its bound by more than the retry's margin: the
                // residuals would miss by more than it too (the inequality residual is at
                // least that), and the set moves; they are not computed.
                if self.free_violation(&lower, &upper) > self.settings.tol_ineq * T::lit(1e4) {
                    unset = Some((lower, upper));
                    break;
                }
                unset = None;
                let res = self.hold_all(qp, &lower, &upper, &rows, &y);
                let st = &self.settings;
                let within = |f: T| {
                    res[0] <= st.tol_stat * f
                        && res[1] <= st.tol_eq * f
                        && res[2] <= st.tol_ineq * f
                };
                if within(T::ONE) {
                    return Ok(self.solved_on_held_set(&res, solves));
                }
                // Rounding (tight tolerances on an ill-conditioned QP) leaves residuals near
                // the tolerances, and one more step mends them; a set that no longer holds
                // leaves a bound violated or a multiplier of the wrong sign, which it does
                // not: the set moves.
                if retry == retries || !within(T::lit(1e4)) {
                    break;
                }
                steps = if schur || penalized { 2 } else { 1 };
            }
        }
        self.set_rows_if(qp, unset, &rows, &y);
        Err(solves)
    }

    /// The held controls on their bounds: the start of a solve on a new factorization
    /// ([`solve_held`](Self::solve_held)).
    #[inline]
    fn held_controls_on_bounds(&mut self, lower: &[[bool; NU]; N], upper: &[[bool; NU]; N]) {
        for (k, u) in self.sol.u.iter_mut().enumerate() {
            let r = &self.ru[k];
            for i in 0..NU {
                if lower[k][i] {
                    u[i] = r.lo[i];
                } else if upper[k][i] {
                    u[i] = r.hi[i];
                }
            }
        }
    }

    /// The outcome of a solve on the warm active set whose residuals `res` met the
    /// tolerances after `solves` active-set solves ([`solve_held`](Self::solve_held)).
    #[inline]
    fn solved_on_held_set(&mut self, res: &[T; 4], solves: u32) -> QpInfo<T> {
        self.dual_valid = true;
        self.polished = false;
        self.on_active_set = true;
        QpInfo {
            status: QpStatus::Solved,
            iterations: 0,
            active_set_solves: solves,
            res_stat: res[0],
            res_eq: res[1],
            res_ineq: res[2],
            mu: T::ZERO,
        }
    }

    /// Takes a move through the Schur complement (module docs), on top of the factorized set
    /// `fixed` and the bounds `cols` already holds so (together the set `before`): when the
    /// move to `now` frees none of `fixed`'s bounds, holds no more than [`COLUMNS`] so in
    /// all, and its passes cost less than refactorizing the stages up to the last one that
    /// changed. The bounds it adds get their unit responses (`M`'s new entries); the columns
    /// it frees are released, their forces (`-mu`, from the controls' stationarity at the
    /// current point) cancelled by one more pair of passes, and dropped from `M`; `-M` is
    /// factorized. Returns whether it did (`cols` and the point are unchanged otherwise).
    fn hold_by_columns<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        fixed: &[[bool; NU]; N],
        before: &[[bool; NU]; N],
        now: &[[bool; NU]; N],
        cols: &mut Columns<T>,
    ) -> bool {
        // The columns that stay, in order, then the added ones.
        let mut next = Columns::new();
        let mut kept = [0usize; COLUMNS];
        let mut released = None;
        for (j, &(k, i)) in cols.at.iter().enumerate().take(cols.n) {
            if now[k][i] {
                if let (Some(at), Some(slot)) = (next.at.get_mut(next.n), kept.get_mut(next.n)) {
                    (*at, *slot) = ((k, i), j);
                }
                next.n += 1;
                next.top = next.top.max(k);
            } else {
                released = Some(released.map_or(k, |t: usize| t.max(k)));
            }
        }
        let stay = next.n;
        let mut changed = 0;
        for k in 0..N {
            for i in 0..NU {
                if fixed[k][i] && !now[k][i] {
                    return false;
                }
                if now[k][i] != fixed[k][i] {
                    changed = k + 1;
                }
                if now[k][i] && !before[k][i] {
                    let Some(at) = next.at.get_mut(next.n) else {
                        return false;
                    };
                    *at = (k, i);
                    next.n += 1;
                    next.top = next.top.max(k);
                }
            }
        }
        let added = next.at.get(stay..next.n).unwrap_or(&[]);
        // A unit response runs back from its stage and forward to the last column's; the
        // release back from the last freed column and forward over the horizon.
        let passes: usize = added.iter().map(|&(k, _)| k + 2 + next.top).sum::<usize>()
            + released.map_or(0, |t| t + 1 + N);
        if (added.is_empty() && released.is_none()) || passes >= STAGE_FACTORIZATION * changed {
            return false;
        }
        // The kept columns' entries of `M` (all of it where none is freed), then the added
        // ones' responses.
        if released.is_none() {
            next.m = cols.m;
        } else {
            for (j, &cj) in kept.iter().enumerate().take(stay) {
                for (l, &cl) in kept.iter().enumerate().take(stay) {
                    next.m[(j, l)] = cols.m[(cj, cl)];
                }
            }
        }
        for l in stay..next.n {
            let Some(&(k, i)) = next.at.get(l) else {
                return false;
            };
            self.forced(qp, fixed, &[((k, i), T::ONE)], next.top);
            for (j, &(kj, ij)) in next.at.iter().enumerate().take(l + 1) {
                let m = self.du[kj][ij];
                next.m[(j, l)] = m;
                next.m[(l, j)] = m;
            }
        }
        // `M` is negative definite where the QP on the new set has a positive definite
        // reduced Hessian; else (or on rounding that breaks it) the stages are
        // refactorized.
        let Some(chol) = nalgebra::Cholesky::new(-next.m) else {
            return false;
        };
        next.chol = Some(chol);
        if released.is_some() {
            // The freed columns' forces, cancelled: the gradient `mu` on each.
            let mut forces = [((0, 0), T::ZERO); COLUMNS];
            let freed = cols.at.iter().take(cols.n).filter(|&&(k, i)| !now[k][i]);
            for (f, &(k, i)) in forces.iter_mut().zip(freed) {
                *f = ((k, i), self.control_multipliers(qp, k)[i]);
            }
            self.forced(qp, fixed, forces.get(..cols.n - stay).unwrap_or(&[]), N);
            self.take_forced_step();
        }
        *cols = next;
        true
    }

    /// The step from the current point (a solution on the factorized set `fixed` with the
    /// forces that hold `cols` on their bounds, up to the bounds a move added) to the
    /// solution on the set with `cols` held: the forces' increments `d` from `M d = b - u`
    /// at `cols`, and their response (module docs).
    fn correct<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        fixed: &[[bool; NU]; N],
        lower: &[[bool; NU]; N],
        cols: &Columns<T>,
    ) {
        let Some(chol) = &cols.chol else {
            return;
        };
        let mut r = SVector::<T, COLUMNS>::zeros();
        for (rj, &(k, i)) in r.iter_mut().zip(cols.at.iter().take(cols.n)) {
            let (b, ru) = (&self.ru[k], self.sol.u[k][i]);
            *rj = ru - if lower[k][i] { b.lo[i] } else { b.hi[i] };
        }
        // -M d = u - b.
        let d = chol.solve(&r);
        let mut forces = [((0, 0), T::ZERO); COLUMNS];
        for (f, (&at, &dj)) in forces.iter_mut().zip(cols.at.iter().zip(d.iter())) {
            *f = (at, dj);
        }
        self.forced(qp, fixed, forces.get(..cols.n).unwrap_or(&[]), N);
        self.take_forced_step();
    }

    /// Adds the response [`forced`](Self::forced) left over the whole horizon to the point.
    fn take_forced_step(&mut self) {
        for k in 0..N {
            if k > 0 {
                self.sol.x[k] += self.dx[k];
            }
            self.sol.u[k] += self.du[k];
            self.sol.pi[k] += self.pi_new[k];
        }
        self.sol.xn += self.dxn;
    }

    /// The response of the linear-quadratic problem on the factorized set `fixed` to
    /// `forces`, gradients on single controls (stage, control) and nothing else (no other
    /// gradient, no dynamics residual, the initial state fixed): the Riccati solve of
    /// [`lq_solve`](Self::lq_solve) with the terms that are zero left out, its backward pass
    /// from the forces' last stage `top` (above it everything is zero) and its forward pass
    /// to stage `upto` (`du`, `dx`); with `upto` at `N`, over the whole horizon with the
    /// dynamics multipliers (`pi_new`) and `dxn`.
    fn forced<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        fixed: &[[bool; NU]; N],
        forces: &[((usize, usize), T)],
        upto: usize,
    ) {
        let full = upto >= N;
        let top = forces.iter().map(|&((k, _), _)| k).max().unwrap_or(0);
        let mut pv = Vect::<T, NX>::zeros();
        for k in (0..N.min(top + 1)).rev() {
            let s = &qp.stages[k];
            self.pvn[k] = pv;
            let mut g = tr_mul(&s.b, &pv);
            for &((_, i), v) in forces.iter().filter(|&&((kf, _), _)| kf == k) {
                if let Some(gi) = g.get_mut(i) {
                    *gi += v;
                }
            }
            let mut y = mul(&self.linv[k], &g);
            if let Some(held) = fixed.get(k) {
                for (yi, _) in y.iter_mut().zip(held).filter(|(_, h)| **h) {
                    *yi = T::ZERO;
                }
            }
            self.kv[k] = y;
            if k > 0 {
                pv = tr_mul(&s.a, &pv) - mul(&self.wt[k], &y);
            }
        }
        let mut dx = Vect::<T, NX>::zeros();
        for k in 0..N.min(upto + 1) {
            let s = &qp.stages[k];
            self.dx[k] = dx;
            let mut v = tr_mul(&self.wt[k], &dx);
            if k <= top {
                v += self.kv[k];
            }
            let du = -tr_mul(&self.linv[k], &v);
            self.du[k] = du;
            if k < upto {
                let next = mul_sparse(&s.a, &dx) + mul_sparse(&s.b, &du);
                if full {
                    let mut p = mul(&self.pn[k], &next);
                    if k <= top {
                        p += self.pvn[k];
                    }
                    self.pi_new[k] = p;
                }
                dx = next;
            }
        }
        if full {
            self.dxn = dx;
        }
    }

    /// The controls' stationarity at stage `k` of the current point, `mu = R u + S x + gu +
    /// B'pi`: a held bound's multiplier (`lam_l - lam_u`), minus the force on a column.
    fn control_multipliers<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        k: usize,
    ) -> Vect<T, NU> {
        let (s, h) = (&qp.stages[k], qp.h(k));
        let (x, u) = (self.sol.x[k], self.sol.u[k]);
        let mu = mul(&h.r, &u) + mul(&h.s, &x) + s.gu + tr_mul(&s.b, &self.sol.pi[k]);
        // With rows set on the held set, their forces `D'(lam_l - lam_u)` too.
        if NG > 0 && self.rows_on {
            mu - tr_mul(&s.d, &self.rg[k].dual())
        } else {
            mu
        }
    }

    /// The largest violation of a bound by a control that `lower` / `upper` leave free.
    fn free_violation(&self, lower: &[[bool; NU]; N], upper: &[[bool; NU]; N]) -> T {
        let mut m = T::ZERO;
        for (k, (u, r)) in self.sol.u.iter().zip(&self.ru).enumerate() {
            for i in 0..NU {
                if lower[k][i] || upper[k][i] {
                    continue;
                }
                if r.has_lo[i] {
                    m = m.max(r.lo[i] - u[i]);
                }
                if r.has_hi[i] {
                    m = m.max(u[i] - r.hi[i]);
                }
            }
        }
        m
    }

    /// Sets the rows at the current point on `sets` and `rows` (as
    /// [`hold_all`](Self::hold_all)), if given.
    fn set_rows_if<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        sets: Option<Sets<NU, N>>,
        rows: &Holds<NBX, NG, NGN, N>,
        y: &RowVals<T, NBX, NG, NGN, N>,
    ) {
        if let Some((lower, upper)) = sets {
            self.hold_all(qp, &lower, &upper, rows, y);
        }
    }

    /// Sets every row from the current point and returns the interior point's residuals
    /// there (`[stationarity, dynamics, inequality, 0]`): by
    /// [`hold_rows`](Self::hold_rows) where only control bounds are held and no row is
    /// soft, else by [`hold_rows_general`](Self::hold_rows_general).
    fn hold_all<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        lower: &[[bool; NU]; N],
        upper: &[[bool; NU]; N],
        rows: &Holds<NBX, NG, NGN, N>,
        y: &RowVals<T, NBX, NG, NGN, N>,
    ) -> [T; 4] {
        if self.rows_on {
            self.hold_rows_general(qp, lower, upper, rows, y)
        } else {
            self.hold_rows(qp, lower, upper)
        }
    }

    /// Sets every row from the current point on the held set (module docs: held rows at
    /// zero slack with their multipliers `y`, violated soft rows with the violation as
    /// slack and the force `l1 + l2 s`, free rows with multiplier zero; the control bounds
    /// as [`hold_rows`](Self::hold_rows) does, their multipliers from the controls'
    /// stationarity with the rows' forces) and returns the interior point's own residuals
    /// there, [`residuals`](Self::residuals) and [`stationarity`](Self::stationarity):
    /// `[stationarity, dynamics, inequality, 0]` (complementarity is zero).
    fn hold_rows_general<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        lower: &[[bool; NU]; N],
        upper: &[[bool; NU]; N],
        rows: &Holds<NBX, NG, NGN, N>,
        y: &RowVals<T, NBX, NG, NGN, N>,
    ) -> [T; 4] {
        for k in 0..N {
            let s = &qp.stages[k];
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            if NBX > 0 {
                let v = self.rx[k].gather(&x);
                set_rows(&mut self.rx[k], None, &rows.x[k], &v, &y.x[k]);
            }
            if NG > 0 {
                let v = mul(&s.c, &x) + mul(&s.d, &u);
                set_rows(
                    &mut self.rg[k],
                    Some(&mut self.sg[k]),
                    &rows.g[k],
                    &v,
                    &y.g[k],
                );
            }
            let mu = self.control_multipliers(qp, k);
            self.ru[k].hold(&u, &mu, &lower[k], &upper[k]);
        }
        let xn = self.sol.xn;
        if NBX > 0 {
            let v = self.rxn.gather(&xn);
            set_rows(&mut self.rxn, None, &rows.xn, &v, &y.xn);
        }
        if NGN > 0 {
            let v = mul(&qp.terminal.c, &xn);
            set_rows(&mut self.rgn, Some(&mut self.sgn), &rows.gn, &v, &y.gn);
        }
        let mut res = self.residuals(qp);
        res[0] = self.stationarity(qp);
        res[3] = T::ZERO;
        res
    }

    /// One Newton step on the held set with the rows as `rows` holds them (module docs):
    /// [`held_step`](Self::held_step) where no row is held or soft; else its gradients plus
    /// each row's term (a held row's penalty `w (c - b) - y`, a violated soft side's force
    /// `l1 + l2 s` with its sign) in the factorization that weighs them so, and the held
    /// rows' multipliers updated, `y -= w (c - b + a'dz)`.
    // Over 80 lines: `held_step`'s passes with each of the four row sets' terms (stage and
    // terminal state bounds and general rows) added in place, which splitting would only
    // spread over helpers taking the whole state.
    fn held_step_rows<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        fixed: &[[bool; NU]; N],
        rows: &Holds<NBX, NG, NGN, N>,
        y: &mut RowVals<T, NBX, NG, NGN, N>,
    ) {
        if !self.rows_on {
            self.held_step(qp, fixed);
            return;
        }
        let w = penalty::<T>();
        let mut wr = RowVals::<T, NBX, NG, NGN, N>::ZERO;
        for k in 0..N {
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            let next = if k + 1 < N {
                self.sol.x[k + 1]
            } else {
                self.sol.xn
            };
            self.rbt[k] = mul_sparse(&s.a, &x) + mul_sparse(&s.b, &u) + s.f - next;
            let mut gx = mul_sparse(&h.q, &x) + tr_mul(&h.s, &u) + s.gx;
            let mut gu = mul_sparse(&h.r, &u) + mul_sparse(&h.s, &x) + s.gu;
            if NBX > 0 {
                let v = self.rx[k].gather(&x);
                let (gc, r) = row_terms(&self.rx[k], None, &rows.x[k], &v, &y.x[k], w);
                gx += self.rx[k].scatter(&gc);
                wr.x[k] = r;
            }
            if NG > 0 {
                let v = mul(&s.c, &x) + mul(&s.d, &u);
                let sg = Some(&self.sg[k]);
                let (gc, r) = row_terms(&self.rg[k], sg, &rows.g[k], &v, &y.g[k], w);
                gx += tr_mul(&s.c, &gc);
                gu += tr_mul(&s.d, &gc);
                wr.g[k] = r;
            }
            (self.gxt[k], self.gut[k]) = (gx, gu);
        }
        let t = &qp.terminal;
        let xn = self.sol.xn;
        let mut gn = mul(&t.q, &xn) + t.gx;
        if NBX > 0 {
            let v = self.rxn.gather(&xn);
            let (gc, r) = row_terms(&self.rxn, None, &rows.xn, &v, &y.xn, w);
            gn += self.rxn.scatter(&gc);
            wr.xn = r;
        }
        if NGN > 0 {
            let v = mul(&t.c, &xn);
            let (gc, r) = row_terms(&self.rgn, Some(&self.sgn), &rows.gn, &v, &y.gn, w);
            gn += tr_mul(&t.c, &gc);
            wr.gn = r;
        }
        self.gnt = gn;
        self.lq_solve(qp, Some(fixed));
        for k in 0..N {
            let s = &qp.stages[k];
            let (dx, du) = (self.dx[k], self.du[k]);
            if k > 0 {
                self.sol.x[k] += dx;
            }
            self.sol.u[k] += du;
            self.sol.pi[k] = self.pi_new[k];
            if NBX > 0 {
                let da = self.rx[k].gather(&dx);
                update_duals(&rows.x[k], &mut y.x[k], &wr.x[k], &da, w);
            }
            if NG > 0 {
                let da = mul(&s.c, &dx) + mul(&s.d, &du);
                update_duals(&rows.g[k], &mut y.g[k], &wr.g[k], &da, w);
            }
        }
        let dxn = self.dxn;
        self.sol.xn += dxn;
        if NBX > 0 {
            let da = self.rxn.gather(&dxn);
            update_duals(&rows.xn, &mut y.xn, &wr.xn, &da, w);
        }
        if NGN > 0 {
            let da = mul(&t.c, &dxn);
            update_duals(&rows.gn, &mut y.gn, &wr.gn, &da, w);
        }
    }

    /// A move of the held rows from the current point (module docs): a held row whose
    /// multiplier has the wrong sign is freed, a held soft one whose force passed `l1` is
    /// violated, a violated one whose slack would be negative is held (freed with `l1 =
    /// 0`), a free row past its bound is held (violated with `l1 = 0`). Returns whether a
    /// row moved.
    fn move_held_rows<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        rows: &mut Holds<NBX, NG, NGN, N>,
        y: &mut RowVals<T, NBX, NG, NGN, N>,
    ) -> bool {
        if Holds::<NBX, NG, NGN, N>::NONE {
            return false;
        }
        let tol = self.settings.tol_ineq.max(self.settings.tol_stat);
        let mut moved = false;
        for k in 0..N {
            let s = &qp.stages[k];
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            if NBX > 0 {
                let v = self.rx[k].gather(&x);
                moved |= move_rows(&self.rx[k], None, &mut rows.x[k], &v, &mut y.x[k], tol);
            }
            if NG > 0 {
                let v = mul(&s.c, &x) + mul(&s.d, &u);
                let sg = Some(&self.sg[k]);
                moved |= move_rows(&self.rg[k], sg, &mut rows.g[k], &v, &mut y.g[k], tol);
            }
        }
        let xn = self.sol.xn;
        if NBX > 0 {
            let v = self.rxn.gather(&xn);
            moved |= move_rows(&self.rxn, None, &mut rows.xn, &v, &mut y.xn, tol);
        }
        if NGN > 0 {
            let v = mul(&qp.terminal.c, &xn);
            moved |= move_rows(&self.rgn, Some(&self.sgn), &mut rows.gn, &v, &mut y.gn, tol);
        }
        moved
    }

    /// The stored rows less the sides the loaded QP no longer has (a violated side that is
    /// no longer soft is held), stored again and returned.
    fn present_rows(&mut self) -> Holds<NBX, NG, NGN, N> {
        if Holds::<NBX, NG, NGN, N>::NONE {
            return Holds::FREE;
        }
        let mut rows = self.act_rows;
        for k in 0..N {
            present(&self.rx[k], None, &mut rows.x[k]);
            present(&self.rg[k], Some(&self.sg[k]), &mut rows.g[k]);
        }
        present(&self.rxn, None, &mut rows.xn);
        present(&self.rgn, Some(&self.sgn), &mut rows.gn);
        self.act_rows = rows;
        rows
    }

    /// A primal-dual active-set move from the current point on the held set: a held control
    /// whose multiplier `mu = R u + S x + gu + B'pi` has the wrong sign is freed, a free one
    /// past a bound is held on it. Returns `false` if nothing moved (the miss is a state
    /// bound's or a general row's, or rounding's), or a control would be held on a bound
    /// the QP lacks.
    fn move_held_set<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        lower: &mut [[bool; NU]; N],
        upper: &mut [[bool; NU]; N],
    ) -> bool {
        let tol = self.settings.tol_ineq.max(self.settings.tol_stat);
        let mut moved = false;
        for k in 0..N {
            let (mu, u) = (self.control_multipliers(qp, k), self.sol.u[k]);
            let r = &self.ru[k];
            for i in 0..NU {
                let (m, v) = (mu[i], u[i]);
                let (lo, hi) = (&mut lower[k][i], &mut upper[k][i]);
                let pinned = r.has_lo[i] && r.has_hi[i] && r.hi[i] <= r.lo[i];
                let scale = T::ONE.max(m.abs());
                if (*lo && m < -tol * scale && !pinned) || (*hi && m > tol * scale && !pinned) {
                    (*lo, *hi) = (false, false);
                    moved = true;
                } else if !*lo && !*hi {
                    let vs = tol * T::ONE.max(v.abs());
                    if r.has_lo[i] && v < r.lo[i] - vs {
                        *lo = true;
                        moved = true;
                    } else if r.has_hi[i] && v > r.hi[i] + vs {
                        *hi = true;
                        moved = true;
                    }
                }
            }
        }
        moved
    }

    /// One Newton step of the QP on the held set from the current point: the gradients and
    /// dynamics residuals there, the Riccati solve with the held controls' steps zero, and
    /// the update (the dynamics multipliers are the solve's).
    fn held_step<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        fixed: &[[bool; NU]; N],
    ) {
        for k in 0..N {
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            let next = if k + 1 < N {
                self.sol.x[k + 1]
            } else {
                self.sol.xn
            };
            // From the start (states after x0 zero, controls zero unless held) most of `x`
            // and `u` are zeros, which the sparse products skip.
            self.rbt[k] = mul_sparse(&s.a, &x) + mul_sparse(&s.b, &u) + s.f - next;
            self.gxt[k] = mul_sparse(&h.q, &x) + tr_mul(&h.s, &u) + s.gx;
            self.gut[k] = mul_sparse(&h.r, &u) + mul_sparse(&h.s, &x) + s.gu;
        }
        let t = &qp.terminal;
        self.gnt = mul(&t.q, &self.sol.xn) + t.gx;
        self.lq_solve(qp, Some(fixed));
        for k in 0..N {
            if k > 0 {
                self.sol.x[k] += self.dx[k];
            }
            self.sol.u[k] += self.du[k];
            self.sol.pi[k] = self.pi_new[k];
        }
        self.sol.xn += self.dxn;
    }

    /// Sets every row from the current point as the module docs say and returns the
    /// interior point's residuals there: `[stationarity, dynamics, inequality, 0]`.
    ///
    /// The same figures as [`residuals`](Self::residuals) then
    /// [`stationarity`](Self::stationarity), bit for bit, in one pass that leaves out what
    /// the rows as set make zero: every row but the control bounds is free (multiplier
    /// zero, so `C'`, `D'` and the state bounds add nothing to stationarity), there is no
    /// soft row (the warm active set refuses them), and complementarity is zero. The
    /// bounds' multipliers `mu = R u + S x + gu + B'pi` are those stationarity uses.
    fn hold_rows<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        lower: &[[bool; NU]; N],
        upper: &[[bool; NU]; N],
    ) -> [T; 4] {
        let (mut re, mut ri, mut rs, mut gscale) = (T::ZERO, T::ZERO, T::ZERO, T::ONE);
        for k in 0..N {
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (x, u, pi) = (self.sol.x[k], self.sol.u[k], self.sol.pi[k]);
            let next = if k + 1 < N {
                self.sol.x[k + 1]
            } else {
                self.sol.xn
            };
            let rb = mul_sparse(&s.a, &x) + mul_sparse(&s.b, &u) + s.f - next;
            re = re.max(rb.amax());
            self.rb[k] = rb;
            let hu = mul(&h.r, &u) + mul(&h.s, &x) + s.gu;
            let bpi = tr_mul(&s.b, &pi);
            let mu = hu + bpi;
            self.hu[k] = hu;
            let ru = &mut self.ru[k];
            ru.hold(&u, &mu, &lower[k], &upper[k]);
            let ud = ru.dual();
            ri = ri.max(ru.residuals(&u, None));
            rs = rs.max((mu - ud).amax());
            gscale = gscale.max(hu.amax()).max(bpi.amax()).max(ud.amax());
            self.rx[k].hold_free(&x);
            ri = ri.max(self.rx[k].residuals(&x));
            if NG > 0 {
                let g = mul(&s.c, &x) + mul(&s.d, &u);
                self.rg[k].hold_free(&g);
                ri = ri.max(self.rg[k].residuals(&g, None));
            }
            if k > 0 {
                let hx = mul(&h.q, &x) + tr_mul(&h.s, &u) + s.gx;
                let api = tr_mul(&s.a, &pi);
                let prev = self.sol.pi[k - 1];
                rs = rs.max((hx + api - prev).amax());
                gscale = gscale.max(hx.amax()).max(api.amax()).max(prev.amax());
                self.hx[k] = hx;
            }
        }
        let t = &qp.terminal;
        let xn = self.sol.xn;
        self.rxn.hold_free(&xn);
        ri = ri.max(self.rxn.residuals(&xn));
        if NGN > 0 {
            let g = mul(&t.c, &xn);
            self.rgn.hold_free(&g);
            ri = ri.max(self.rgn.residuals(&g, None));
        }
        let hxn = mul(&t.q, &xn) + t.gx;
        self.hxn = hxn;
        gscale = gscale.max(hxn.amax());
        if let Some(last) = self.sol.pi.last() {
            rs = rs.max((hxn - last).amax());
            gscale = gscale.max(last.amax());
        }
        self.soft_stat = [T::ZERO; 2];
        [rs / gscale, re, ri, T::ZERO]
    }

    /// Whether the last solution, from the warm active set, meets the current settings'
    /// tolerances (the rows hold it).
    pub(super) fn held_solution_optimal<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> bool {
        let mut res = self.residuals(qp);
        res[0] = self.stationarity(qp);
        let st = &self.settings;
        res[0] <= st.tol_stat && res[1] <= st.tol_eq && res[2] <= st.tol_ineq
    }

    /// Stores the active set of an interior-point solution of the Riccati recursion for the
    /// next solve: the control bounds, state bounds and general rows whose multiplier
    /// exceeds their slack, a soft one violated where its slack exceeds the slack's
    /// multiplier (or it has no `l1`).
    pub(super) fn held_set_of_interior_point(&mut self) {
        if NR != N {
            self.act_valid = false;
            return;
        }
        let mut rows = Holds::FREE;
        for k in 0..N {
            rows.x[k] = holds_of(&self.rx[k], None);
            rows.g[k] = holds_of(&self.rg[k], Some(&self.sg[k]));
        }
        rows.xn = holds_of(&self.rxn, None);
        rows.gn = holds_of(&self.rgn, Some(&self.sgn));
        let (mut lower, mut upper) = ([[false; NU]; N], [[false; NU]; N]);
        for (k, r) in self.ru.iter().enumerate() {
            for (i, side) in initial_sides(r).iter().enumerate() {
                lower[k][i] = *side == Side::Lower;
                upper[k][i] = *side == Side::Upper;
            }
        }
        self.store_active_set(&lower, &upper);
        self.act_rows = rows;
    }
}

/// Where the warm active set holds a row (a state bound, a general row; a side of it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Hold {
    /// Free: force zero.
    Free,
    /// Held at its lower bound (the row equals it, a soft row's slack zero): force `y >= 0`
    /// (`lam_l`, at most `l1` for a soft row).
    Lower,
    /// Held at its upper bound: force `y <= 0` (`-lam_u`).
    Upper,
    /// A soft row past its lower bound by the slack `s > 0`: force `l1 + l2 s`.
    OverLower,
    /// A soft row past its upper bound.
    OverUpper,
}

/// The rows of a warm active set, per row set of each stage and the terminal ones (state
/// bounds by slot).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Holds<const NBX: usize, const NG: usize, const NGN: usize, const N: usize> {
    pub x: [[Hold; NBX]; N],
    pub g: [[Hold; NG]; N],
    pub xn: [Hold; NBX],
    pub gn: [Hold; NGN],
}

impl<const NBX: usize, const NG: usize, const NGN: usize, const N: usize> Holds<NBX, NG, NGN, N> {
    /// Every row free.
    pub const FREE: Self = Holds {
        x: [[Hold::Free; NBX]; N],
        g: [[Hold::Free; NG]; N],
        xn: [Hold::Free; NBX],
        gn: [Hold::Free; NGN],
    };

    /// The solver has no row (no state-bound slot, no general row): every method is then
    /// trivial, and skipped (QR-bench's solvers).
    const NONE: bool = NBX == 0 && NG == 0 && NGN == 0;

    /// Every hold, stage by stage.
    fn all(&self) -> impl Iterator<Item = &Hold> {
        self.x
            .iter()
            .flatten()
            .chain(self.g.iter().flatten())
            .chain(&self.xn)
            .chain(&self.gn)
    }

    /// Some row is not free.
    pub fn any(&self) -> bool {
        !Self::NONE && self.all().any(|h| *h != Hold::Free)
    }

    /// Some row is held at a bound (its multiplier comes from the penalty iteration).
    fn any_held(&self) -> bool {
        !Self::NONE && self.all().any(|h| matches!(h, Hold::Lower | Hold::Upper))
    }

    /// Moves the rows one stage forward (the last stage's repeated), as
    /// [`QpSolver::shift_active_set`] does the control bounds.
    pub fn shift(&mut self) {
        for k in 1..N {
            self.x[k - 1] = self.x[k];
            self.g[k - 1] = self.g[k];
        }
    }
}

/// Values per row of the warm active set (the held rows' multipliers `lam_l - lam_u`, or the
/// penalty terms of a step).
#[derive(Clone, Copy)]
pub(super) struct RowVals<
    T: Real,
    const NBX: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
> {
    x: [Vect<T, NBX>; N],
    g: [Vect<T, NG>; N],
    xn: Vect<T, NBX>,
    gn: Vect<T, NGN>,
}

impl<T: Real, const NBX: usize, const NG: usize, const NGN: usize, const N: usize>
    RowVals<T, NBX, NG, NGN, N>
{
    const ZERO: Self = RowVals {
        x: [crate::zeros(); N],
        g: [crate::zeros(); N],
        xn: crate::zeros(),
        gn: crate::zeros(),
    };
}

/// The penalty weight `w = 1 / sqrt(eps)` of a held row in the factorization (the polish's):
/// the factorization is then the KKT system's regularized by `-1/w` in the rows'
/// multipliers, and each step contracts the multipliers' error by about `1 / (1 + w s)`,
/// `s` the smallest eigenvalue of the held rows' Schur complement.
fn penalty<T: Real>() -> T {
    T::ONE / T::EPSILON.sqrt()
}

/// The weights the warm active set's rows add to the Hessian along them: [`penalty`] on a
/// held row, `l2` on a violated soft side, none on a free row.
pub(super) fn held_weights<T: Real, const K: usize>(
    holds: &[Hold; K],
    soft: Option<&Soft<T, K>>,
) -> Vect<T, K> {
    let mut v = Vect::<T, K>::zeros();
    for (i, h) in holds.iter().enumerate() {
        v[i] = match h {
            Hold::Free => T::ZERO,
            Hold::Lower | Hold::Upper => penalty(),
            Hold::OverLower | Hold::OverUpper => soft.map_or(T::ZERO, |s| s.z2[i]),
        };
    }
    v
}

/// Each row's gradient coefficient at the values `v` (the gradient is `a` times it): a held
/// row's `w (v - b) - y`, a violated soft side's `-(l1 + l2 (lo - v))` or `l1 + l2 (v -
/// hi)`; and the held rows' `w (v - b)` (for the multipliers' update).
fn row_terms<T: Real, const K: usize>(
    r: &Rows<T, K>,
    soft: Option<&Soft<T, K>>,
    holds: &[Hold; K],
    v: &Vect<T, K>,
    y: &Vect<T, K>,
    w: T,
) -> (Vect<T, K>, Vect<T, K>) {
    let (mut gc, mut wr) = (Vect::<T, K>::zeros(), Vect::<T, K>::zeros());
    for (i, h) in holds.iter().enumerate() {
        let (z1, z2) = soft.map_or((T::ZERO, T::ZERO), |s| (s.z1[i], s.z2[i]));
        match h {
            Hold::Free => {}
            Hold::Lower | Hold::Upper => {
                let b = if *h == Hold::Lower { r.lo[i] } else { r.hi[i] };
                wr[i] = w * (v[i] - b);
                gc[i] = wr[i] - y[i];
            }
            Hold::OverLower => gc[i] = z2 * (v[i] - r.lo[i]) - z1,
            Hold::OverUpper => gc[i] = z1 + z2 * (v[i] - r.hi[i]),
        }
    }
    (gc, wr)
}

/// The held rows' multipliers after a step that moved them by `da`: `y -= w (v - b) + w da`.
fn update_duals<T: Real, const K: usize>(
    holds: &[Hold; K],
    y: &mut Vect<T, K>,
    wr: &Vect<T, K>,
    da: &Vect<T, K>,
    w: T,
) {
    for (i, h) in holds.iter().enumerate() {
        if matches!(h, Hold::Lower | Hold::Upper) {
            y[i] -= wr[i] + w * da[i];
        }
    }
}

/// Sets the rows (and their soft slacks) of an exact solution at the values `v` on the
/// holds: a held row's multiplier `y` (both sides of an equality row), a violated side's
/// force `l1 + l2 s`, zero on a free row ([`Rows::hold`], [`Soft::hold`]).
fn set_rows<T: Real, const K: usize>(
    r: &mut Rows<T, K>,
    soft: Option<&mut Soft<T, K>>,
    holds: &[Hold; K],
    v: &Vect<T, K>,
    y: &Vect<T, K>,
) {
    let mut mu = Vect::<T, K>::zeros();
    let (mut lower, mut upper) = ([false; K], [false; K]);
    let (mut over_l, mut over_u) = ([false; K], [false; K]);
    for (i, h) in holds.iter().enumerate() {
        let (z1, z2) = soft
            .as_ref()
            .map_or((T::ZERO, T::ZERO), |s| (s.z1[i], s.z2[i]));
        let pinned = r.has_lo[i] && r.has_hi[i] && r.hi[i] <= r.lo[i];
        match h {
            Hold::Free => {}
            Hold::Lower | Hold::Upper => {
                mu[i] = y[i];
                lower[i] = *h == Hold::Lower || pinned;
                upper[i] = *h == Hold::Upper || pinned;
            }
            Hold::OverLower => {
                mu[i] = z1 + z2 * (r.lo[i] - v[i]);
                (lower[i], over_l[i]) = (true, true);
            }
            Hold::OverUpper => {
                mu[i] = -(z1 + z2 * (v[i] - r.hi[i]));
                (upper[i], over_u[i]) = (true, true);
            }
        }
    }
    r.hold(v, &mu, &lower, &upper);
    // A held or violated side's slack is zero whatever `v` (`Rows::hold` takes it from `v`,
    // which a held control meets exactly): a row off its bound shows in the inequality
    // residual.
    for i in 0..K {
        if lower[i] && r.has_lo[i] {
            r.tl[i] = T::ZERO;
        }
        if upper[i] && r.has_hi[i] {
            r.tu[i] = T::ZERO;
        }
    }
    if let Some(sf) = soft {
        sf.hold(r, v, &over_l, &over_u);
    }
}

/// The move of one row set (see [`QpSolver::move_held_rows`]); returns whether a row
/// moved. A row that becomes held starts from the multiplier `0`, or `l1` (with its sign)
/// coming from violated.
fn move_rows<T: Real, const K: usize>(
    r: &Rows<T, K>,
    soft: Option<&Soft<T, K>>,
    holds: &mut [Hold; K],
    v: &Vect<T, K>,
    y: &mut Vect<T, K>,
    tol: T,
) -> bool {
    let mut moved = false;
    for (i, h) in holds.iter_mut().enumerate() {
        let (on_l, on_u, z1) =
            soft.map_or((false, false, T::ZERO), |s| (s.on_l[i], s.on_u[i], s.z1[i]));
        let (yi, vi) = (y[i], v[i]);
        let (ys, vs) = (tol * T::ONE.max(yi.abs()), tol * T::ONE.max(vi.abs()));
        let pinned = r.has_lo[i] && r.has_hi[i] && r.hi[i] <= r.lo[i];
        let has_l1 = z1 > T::ZERO;
        let (new, start) = match *h {
            Hold::Lower if on_l && yi > z1 + ys => (Hold::OverLower, T::ZERO),
            Hold::Upper if on_u && -yi > z1 + ys => (Hold::OverUpper, T::ZERO),
            Hold::Lower if yi < -ys && !pinned => (Hold::Free, T::ZERO),
            Hold::Upper if yi > ys && !pinned => (Hold::Free, T::ZERO),
            Hold::OverLower if vi > r.lo[i] + vs => {
                (if has_l1 { Hold::Lower } else { Hold::Free }, z1)
            }
            Hold::OverUpper if vi < r.hi[i] - vs => {
                (if has_l1 { Hold::Upper } else { Hold::Free }, -z1)
            }
            Hold::Free if r.has_lo[i] && vi < r.lo[i] - vs => (
                if on_l && !has_l1 {
                    Hold::OverLower
                } else {
                    Hold::Lower
                },
                T::ZERO,
            ),
            Hold::Free if r.has_hi[i] && vi > r.hi[i] + vs => (
                if on_u && !has_l1 {
                    Hold::OverUpper
                } else {
                    Hold::Upper
                },
                T::ZERO,
            ),
            same => (same, yi),
        };
        if new != *h {
            *h = new;
            y[i] = start;
            moved = true;
        }
    }
    moved
}

/// `holds` less the sides the rows no longer have: a violated side that is no longer soft
/// is held, a held side that is gone is free.
fn present<T: Real, const K: usize>(
    r: &Rows<T, K>,
    soft: Option<&Soft<T, K>>,
    holds: &mut [Hold; K],
) {
    for (i, h) in holds.iter_mut().enumerate() {
        let (on_l, on_u) = soft.map_or((false, false), |s| (s.on_l[i], s.on_u[i]));
        *h = match *h {
            Hold::Lower | Hold::OverLower if !r.has_lo[i] => Hold::Free,
            Hold::Upper | Hold::OverUpper if !r.has_hi[i] => Hold::Free,
            Hold::OverLower if !on_l => Hold::Lower,
            Hold::OverUpper if !on_u => Hold::Upper,
            same => same,
        };
    }
}

/// The holds of an interior-point solution's rows: the sides whose multiplier exceeds their
/// slack ([`initial_sides`]), a soft side violated where its slack exceeds the slack's
/// multiplier or it has no `l1`.
fn holds_of<T: Real, const K: usize>(r: &Rows<T, K>, soft: Option<&Soft<T, K>>) -> [Hold; K] {
    let mut holds = [Hold::Free; K];
    for (i, (h, side)) in holds.iter_mut().zip(initial_sides(r)).enumerate() {
        let over = |on: bool, s: T, m: T, z1: T| on && (s > m || z1 <= T::ZERO);
        *h = match (side, soft) {
            (Side::Lower, Some(sf)) if over(sf.on_l[i], sf.sl[i], sf.ml[i], sf.z1[i]) => {
                Hold::OverLower
            }
            (Side::Upper, Some(sf)) if over(sf.on_u[i], sf.su[i], sf.mu[i], sf.z1[i]) => {
                Hold::OverUpper
            }
            (Side::Lower, _) => Hold::Lower,
            (Side::Upper, _) => Hold::Upper,
            (Side::Free, _) => Hold::Free,
        };
    }
    holds
}

/// Bounds held through the Schur complement on top of the factorized set: their stages
/// and controls, `M` (the control responses at them to unit gradients on them, on the
/// factorized set; the identity's negative where unused) and the Cholesky factor of `-M`.
#[derive(Clone)]
struct Columns<T: Real> {
    n: usize,
    at: [(usize, usize); COLUMNS],
    /// The last stage with a column.
    top: usize,
    m: SMatrix<T, COLUMNS, COLUMNS>,
    chol: Option<nalgebra::Cholesky<T, nalgebra::Const<COLUMNS>>>,
}

impl<T: Real> Columns<T> {
    fn new() -> Self {
        Self {
            n: 0,
            at: [(0, 0); COLUMNS],
            top: 0,
            m: -SMatrix::identity(),
            chol: None,
        }
    }
}

/// A held set: the controls held on their lower bounds, and on their upper ones.
type Sets<const NU: usize, const N: usize> = ([[bool; NU]; N], [[bool; NU]; N]);

/// The held entries: on either bound.
fn held<const NU: usize, const N: usize>(
    lower: &[[bool; NU]; N],
    upper: &[[bool; NU]; N],
) -> [[bool; NU]; N] {
    let mut h = [[false; NU]; N];
    for k in 0..N {
        for i in 0..NU {
            h[k][i] = lower[k][i] || upper[k][i];
        }
    }
    h
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use nalgebra::{SMatrix, SVector};

    /// A deterministic QP of 6 stages (3 states, 2 controls, control bounds) with data from
    /// a small congruential generator, and its solver with the bounds loaded.
    fn qp_and_solver() -> (OcpQp<f64, 3, 2, 0, 0, 6, 6>, QpSolver<f64, 3, 2, 0, 0, 6>) {
        let mut seed = 12345u64;
        let mut draw = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut qp = OcpQp::<f64, 3, 2, 0, 0, 6, 6>::NEW;
        for (s, h) in qp.stages.iter_mut().zip(qp.hessians.iter_mut()) {
            s.a = SMatrix::from_fn(|i, j| f64::from(u8::from(i == j)) + 0.3 * draw());
            s.b = SMatrix::from_fn(|_, _| draw());
            s.f = SVector::from_fn(|_, _| draw());
            s.gx = SVector::from_fn(|_, _| draw());
            s.gu = SVector::from_fn(|_, _| draw());
            s.lbu = SVector::repeat(-0.2);
            s.ubu = SVector::repeat(0.3);
            let m = SMatrix::<f64, 5, 5>::from_fn(|_, _| draw());
            let w = m * m.transpose() + SMatrix::<f64, 5, 5>::identity() * 0.1;
            h.q = w.fixed_view::<3, 3>(0, 0).into();
            h.s = w.fixed_view::<2, 3>(3, 0).into();
            h.r = w.fixed_view::<2, 2>(3, 3).into();
        }
        qp.terminal.q = SMatrix::identity() * 2.0;
        let mut solver = QpSolver::<f64, 3, 2, 0, 0, 6>::NEW;
        assert!(solver.check_stages(&qp) && solver.load_bounds(&qp).is_ok());
        (qp, solver)
    }

    /// A QP of 6 stages (3 states, 2 controls) with control and state bounds and one general
    /// row per stage and at the end, from the same kind of draws, and its solver loaded.
    fn qp_with_rows() -> (OcpQp<f64, 3, 2, 1, 1, 6, 6>, QpSolver<f64, 3, 2, 1, 1, 6>) {
        let (base, _) = qp_and_solver();
        let mut qp = OcpQp::<f64, 3, 2, 1, 1, 6, 6>::NEW;
        qp.hessians = base.hessians;
        for (k, (s, b)) in qp.stages.iter_mut().zip(&base.stages).enumerate() {
            let t = k as f64;
            (s.a, s.b, s.f, s.gx, s.gu) = (b.a, b.b, b.f, b.gx, b.gu);
            (s.lbu, s.ubu) = (b.lbu, b.ubu);
            s.lbx = SVector::repeat(-0.05 - 0.01 * t);
            s.ubx = SVector::repeat(0.4);
            s.c = SMatrix::from_fn(|_, j| 0.5 - 0.3 * j as f64 + 0.1 * t);
            s.d = SMatrix::from_fn(|_, j| 0.2 + 0.4 * j as f64);
            s.lg = SVector::repeat(-0.1);
            s.ug = SVector::repeat(0.05);
        }
        qp.x0 = SVector::from([0.3, -0.2, 0.1]);
        qp.terminal.q = base.terminal.q;
        qp.terminal.lbx = SVector::repeat(-0.05);
        qp.terminal.ubx = SVector::repeat(0.1);
        qp.terminal.c = SMatrix::from_fn(|_, j| 1.0 - 0.5 * j as f64);
        qp.terminal.lg = SVector::repeat(-0.02);
        qp.terminal.ug = SVector::repeat(0.02);
        let mut solver = QpSolver::<f64, 3, 2, 1, 1, 6>::NEW;
        assert!(solver.check_stages(&qp) && solver.load_bounds(&qp).is_ok());
        (qp, solver)
    }

    /// `hold_rows` returns what the interior point's `residuals` and `stationarity` give with
    /// the rows set as the module docs say (held bounds with the multipliers `max(+-mu, 0)`,
    /// every other row free), bit for bit, sets the rows so and leaves the same scratch: on
    /// a QP with state bounds and general rows, at a point on a held set that violates some
    /// of them and holds a bound whose multiplier has the wrong sign. The QP's gradients and
    /// terminal weight are scaled in turn, so that the stationarity's scale (the largest of
    /// its terms, at least 1) comes from more than one term.
    #[test]
    fn hold_rows_gives_the_interior_points_residuals_bit_for_bit() {
        let cases: [(f64, f64, f64, f64); 5] = [
            (8.0, 8.0, 1.0, 1.0),
            (1.0, 1e3, 1.0, 1.0),
            (1e3, 1.0, 1.0, 1.0),
            (1.0, 1.0, 1e3, 1.0),
            (1.0, 1.0, 1.0, 1e3),
        ];
        let mut scales = std::vec::Vec::new();
        for (sgx, sgu, sq, sgn) in cases {
            let (mut qp, _) = qp_with_rows();
            for s in qp.stages.iter_mut() {
                s.gx *= sgx;
                s.gu *= sgu;
            }
            qp.terminal.q *= sq;
            qp.terminal.gx = SVector::from([0.2, -0.1, 0.3]) * sgn;
            scales.push(hold_rows_matches_at_a_missed_set(&qp));
        }
        // The stationarity's scale was above 1 in every case, set by more than one term
        // (`A'pi` and the terminal `H y + g`: in a solution on a held set the multipliers and
        // gradients grow together, so no case isolates each term).
        assert!(!scales.contains(&7), "{scales:?}");
        scales.sort_unstable();
        scales.dedup();
        assert!(scales.len() >= 2, "{scales:?}");
    }

    /// The check of [`hold_rows_gives_the_interior_points_residuals_bit_for_bit`] on one QP;
    /// returns which term set the stationarity's scale (0: `hu`, 1: `B'pi`, 2: `hx`, 3:
    /// `A'pi`, 4: `pi_{k-1}`, 5: `hxn`, 6: the last `pi`, 7: none above 1).
    fn hold_rows_matches_at_a_missed_set(qp: &OcpQp<f64, 3, 2, 1, 1, 6, 6>) -> u8 {
        let mut fast = QpSolver::<f64, 3, 2, 1, 1, 6>::NEW;
        assert!(fast.check_stages(qp) && fast.load_bounds(qp).is_ok());
        let (mut lower, mut upper) = ([[false; 2]; 6], [[false; 2]; 6]);
        lower[1][0] = true;
        upper[3][1] = true;
        lower[4][1] = true;
        fast.sol = solved_on(qp, &fast, &lower, &upper);
        let mut slow = fast.clone();
        let got = fast.hold_rows(qp, &lower, &upper);
        let mut terms = [0.0f64; 8];
        terms[7] = 1.0;
        for k in 0..6 {
            let (s, h) = (&qp.stages[k], qp.h(k));
            let (x, u) = (slow.sol.x[k], slow.sol.u[k]);
            let bpi = tr_mul(&s.b, &slow.sol.pi[k]);
            let mu = mul(&h.r, &u) + mul(&h.s, &x) + s.gu + bpi;
            slow.ru[k].hold(&u, &mu, &lower[k], &upper[k]);
            slow.rx[k].hold_free(&x);
            slow.rg[k].hold_free(&(mul(&s.c, &x) + mul(&s.d, &u)));
            terms[1] = terms[1].max(bpi.amax());
            if k > 0 {
                terms[3] = terms[3].max(tr_mul(&s.a, &slow.sol.pi[k]).amax());
                terms[4] = terms[4].max(slow.sol.pi[k - 1].amax());
            }
        }
        let xn = slow.sol.xn;
        slow.rxn.hold_free(&xn);
        slow.rgn.hold_free(&mul(&qp.terminal.c, &xn));
        let mut want = slow.residuals(qp);
        want[0] = slow.stationarity(qp);
        want[3] = 0.0;
        assert_eq!(got, want);
        // The rows as set, their residuals included: every field the same.
        let same = |a: &dyn core::fmt::Debug, b: &dyn core::fmt::Debug| {
            std::format!("{a:?}") == std::format!("{b:?}")
        };
        for k in 0..6 {
            assert!(same(&fast.ru[k], &slow.ru[k]), "stage {k}");
            assert!(same(&fast.rx[k], &slow.rx[k]), "stage {k}");
            assert!(same(&fast.rg[k], &slow.rg[k]), "stage {k}");
        }
        assert!(same(&fast.rxn, &slow.rxn) && same(&fast.rgn, &slow.rgn));
        // The same scratch: dynamics residuals, `H y + g` (no state's at stage 0), no soft
        // terms.
        assert_eq!(fast.rb, slow.rb);
        assert_eq!(fast.hu, slow.hu);
        assert_eq!(fast.hx[1..], slow.hx[1..]);
        assert_eq!((fast.hxn, fast.soft_stat), (slow.hxn, slow.soft_stat));
        // Not a trivial point: rows violated and a held multiplier of the wrong sign.
        assert!(got[0] > 1e-6 && got[2] > 1e-3, "{got:?}");
        let mu = |k: usize| {
            let (s, h) = (&qp.stages[k], qp.h(k));
            let (x, u) = (fast.sol.x[k], fast.sol.u[k]);
            mul(&h.r, &u) + mul(&h.s, &x) + s.gu + tr_mul(&s.b, &fast.sol.pi[k])
        };
        let wrong = (0..6).any(|k| {
            (0..2).any(|i| (lower[k][i] && mu(k)[i] < 0.0) || (upper[k][i] && mu(k)[i] > 0.0))
        });
        assert!(wrong);
        terms[0] = fast.hu.iter().fold(0.0, |m, v| m.max(v.amax()));
        terms[2] = fast.hx[1..].iter().fold(0.0, |m, v| m.max(v.amax()));
        terms[5] = fast.hxn.amax();
        terms[6] = fast.sol.pi[5].amax();
        let top = terms.iter().cloned().fold(0.0, f64::max);
        terms.iter().position(|&t| t == top).unwrap_or(7) as u8
    }

    /// The solution on the held set `lower` / `upper`, from a factorization on it (one
    /// Newton step from zero with the held controls on their bounds): the plain route the
    /// Schur complement must agree with.
    fn solved_on<const NG: usize, const NGN: usize>(
        qp: &OcpQp<f64, 3, 2, NG, NGN, 6, 6>,
        solver: &QpSolver<f64, 3, 2, NG, NGN, 6>,
        lower: &[[bool; 2]; 6],
        upper: &[[bool; 2]; 6],
    ) -> QpSolution<f64, 3, 2, 6> {
        let mut plain = solver.clone();
        let now = held(lower, upper);
        assert!(plain.factorize(qp, Newton::Held(&now, &Holds::FREE)));
        plain.sol = QpSolution::NEW;
        plain.sol.x[0] = qp.x0;
        for k in 0..6 {
            for i in 0..2 {
                if lower[k][i] {
                    plain.sol.u[k][i] = plain.ru[k].lo[i];
                } else if upper[k][i] {
                    plain.sol.u[k][i] = plain.ru[k].hi[i];
                }
            }
        }
        plain.held_step(qp, &now);
        plain.sol
    }

    /// The largest difference between two solutions, relative to the larger entry (at
    /// least 1).
    fn gap(a: &QpSolution<f64, 3, 2, 6>, b: &QpSolution<f64, 3, 2, 6>) -> f64 {
        let mut d: f64 = (a.xn - b.xn).amax();
        let mut m: f64 = a.xn.amax().max(1.0);
        for k in 0..6 {
            d = d.max((a.x[k] - b.x[k]).amax());
            d = d.max((a.u[k] - b.u[k]).amax());
            d = d.max((a.pi[k] - b.pi[k]).amax());
            m = m.max(a.x[k].amax()).max(a.u[k].amax()).max(a.pi[k].amax());
        }
        d / m
    }

    /// Moves through the Schur complement on top of the factorized set give the solution
    /// that a factorization on the new set gives (states, controls and dynamics multipliers
    /// to 1e-12): two moves that add bounds on both sides (the second on top of the first's
    /// columns), one that frees a column and adds a bound, one that only frees a column;
    /// the added controls end on their bounds. A move that frees a bound the factorization
    /// holds, or that would hold more than `COLUMNS` so, is left to a refactorization.
    #[test]
    fn a_move_through_the_schur_complement_solves_the_new_set() {
        let (mut qp, mut solver) = qp_and_solver();
        qp.x0 = SVector::from([0.4, -0.3, 0.2]);
        let (mut lower, mut upper) = ([[false; 2]; 6], [[false; 2]; 6]);
        lower[1][0] = true;
        let factored = held(&lower, &upper);
        solver.sol = solved_on(&qp, &solver, &lower, &upper);
        assert!(solver.factorize(&qp, Newton::Held(&factored, &Holds::FREE)));
        let mut cols = Columns::new();
        // Each move: the bounds it adds (stage, control, lower), the columns it frees, and
        // the columns after it.
        type Move<'a> = (&'a [(usize, usize, bool)], &'a [(usize, usize)], usize);
        let moves: [Move; 4] = [
            (&[(3, 1, false), (4, 1, true)], &[], 2),
            (&[(0, 0, false), (5, 0, true)], &[], 4),
            (&[(2, 1, false)], &[(4, 1)], 4),
            (&[], &[(0, 0)], 3),
        ];
        for (round, (added, freed, n)) in moves.iter().enumerate() {
            let before = held(&lower, &upper);
            // The added controls' distances to their bounds: all off before (not a trivial
            // move), all on after.
            let off = |s: &QpSolver<f64, 3, 2, 0, 0, 6>| -> std::vec::Vec<f64> {
                added
                    .iter()
                    .map(|&(k, i, lo)| (s.sol.u[k][i] - if lo { -0.2 } else { 0.3 }).abs())
                    .collect()
            };
            let far = off(&solver);
            assert!(far.iter().all(|&d| d > 1e-2), "move {round}: {far:?}");
            for &(k, i, lo) in added.iter() {
                if lo {
                    lower[k][i] = true;
                } else {
                    upper[k][i] = true;
                }
            }
            for &(k, i) in freed.iter() {
                (lower[k][i], upper[k][i]) = (false, false);
            }
            let now = held(&lower, &upper);
            assert!(solver.hold_by_columns(&qp, &factored, &before, &now, &mut cols));
            assert_eq!(cols.n, *n);
            solver.correct(&qp, &factored, &lower, &cols);
            let near = off(&solver);
            assert!(near.iter().all(|&d| d < 1e-14), "move {round}: {near:?}");
            // One step of each route from zero lands within the QP's rounding (up to 2e-10
            // here: a second step moves either by that much); a second step of each (plain:
            // on the new factorization; here: on the old one, then the correction) brings
            // them together to 1e-14.
            let want = solved_on(&qp, &solver, &lower, &upper);
            let g = gap(&solver.sol, &want);
            assert!(g < 1e-9, "move {round}: {g:e}");
            let mut plain = solver.clone();
            assert!(plain.factorize(&qp, Newton::Held(&now, &Holds::FREE)));
            plain.sol = want;
            plain.held_step(&qp, &now);
            let mut refined = solver.clone();
            refined.held_step(&qp, &factored);
            refined.correct(&qp, &factored, &lower, &cols);
            let g = gap(&refined.sol, &plain.sol);
            assert!(g < 1e-14, "move {round}, refined: {g:e}");
        }
        let res = solver.hold_rows(&qp, &lower, &upper);
        // The dynamics hold to rounding.
        assert!(res[1] < 1e-13, "{res:?}");
        // A Newton step on the new set (as a retry or iterative refinement takes): a step on
        // the factorized set, then the correction. From a point off the solution (states,
        // the controls no bound holds and the multipliers moved; the dynamics violated), it
        // is the step of a factorization on the new set (to 1e-12), and lands on the
        // solution (to the rounding of a step that long: 5e-11 either way).
        let want = solver.sol;
        let now = held(&lower, &upper);
        for (k, held) in now.iter().enumerate() {
            if k > 0 {
                solver.sol.x[k] += SVector::from([0.05, -0.02, 0.01 * k as f64]);
            }
            for (u, _) in solver.sol.u[k].iter_mut().zip(held).filter(|(_, h)| !**h) {
                *u += 0.03;
            }
            solver.sol.pi[k] *= 1.5;
        }
        solver.sol.xn *= 0.5;
        assert!(gap(&solver.sol, &want) > 1e-2);
        let mut plain = solver.clone();
        assert!(plain.factorize(&qp, Newton::Held(&now, &Holds::FREE)));
        plain.held_step(&qp, &now);
        solver.held_step(&qp, &factored);
        solver.correct(&qp, &factored, &lower, &cols);
        let g = gap(&solver.sol, &plain.sol);
        assert!(g < 1e-12, "step: {g:e}");
        let g = gap(&solver.sol, &want);
        assert!(g < 1e-9, "step: {g:e}");
        // Freeing a bound the factorization holds: refactorized.
        let before = held(&lower, &upper);
        let mut now = before;
        now[1][0] = false;
        now[2][0] = true;
        let mut c = cols.clone();
        assert!(!solver.hold_by_columns(&qp, &factored, &before, &now, &mut c));
        assert_eq!(c.n, 3);
        // More than `COLUMNS` in all: refactorized.
        let mut now = before;
        for row in now.iter_mut() {
            *row = [true; 2];
        }
        assert!(!solver.hold_by_columns(&qp, &factored, &before, &now, &mut cols.clone()));
    }

    /// After a move of the held set, the stages above the last changed one keep their
    /// factorization: refactorizing the others alone ends as a whole factorization does, bit
    /// for bit; leaving a changed stage out does not.
    #[test]
    fn a_move_refactorizes_the_changed_stages_alone() {
        let (qp, mut part) = qp_and_solver();
        let mut before = [[false; 2]; 6];
        before[4][1] = true;
        before[1][0] = true;
        assert!(part.factorize(&qp, Newton::Held(&before, &Holds::FREE)));
        let mut after = before;
        after[2][1] = true;
        after[1][0] = false;
        let mut whole = part.clone();
        assert!(whole.factorize(&qp, Newton::Held(&after, &Holds::FREE)));
        let mut short = part.clone();
        assert!(part.factorize_stages(&qp, Newton::Held(&after, &Holds::FREE), 3));
        assert!(part.linv == whole.linv && part.wt == whole.wt && part.pn == whole.pn);
        // Stage 2 changed: refactorizing stages 1 and 0 alone is not the factorization.
        assert!(short.factorize_stages(&qp, Newton::Held(&after, &Holds::FREE), 2));
        assert!(short.linv != whole.linv || short.wt != whole.wt);
    }
}
