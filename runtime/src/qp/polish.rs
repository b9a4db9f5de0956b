//! Active-set polish of a solution of the Riccati recursion
//! ([`QpSettings::polish`](super::QpSettings::polish)), for QPs with state bounds and general
//! constraints (a condensed QP has its own, on the control bounds alone: see `condense.rs`).
//!
//! An interior point stops with every active row about `mu / lam` off its bound; in `f32`,
//! whose complementarity tolerance is `1e-4`, a weakly active row can be off by `1e-2`. The
//! polish takes the rows whose multiplier exceeds their slack as the active set and solves
//! the QP with those rows held as equalities and the others dropped,
//!
//! ```text
//! min 1/2 z'H z + g'z   s.t. dynamics,  a_i'z = b_i  (i active)
//! ```
//!
//! by iterative refinement on its KKT system with the Riccati recursion: each active row gets
//! the penalty weight `w = 1 / delta` in the Newton system's Hessian (`delta = sqrt(eps)`),
//! which makes the factorization that of the KKT system regularized by `-delta I` in the
//! multipliers' block, `H dz + A'(pi) - a'dy = -r_s`, `a'dz + delta dy = -r_a`; the
//! residuals `r_s` (stationarity), `r_a` (the active rows' distance to their bounds) and the
//! dynamics residual are those of the unregularized system, so the iteration converges to
//! its solution, with the multipliers `y` of the active rows (up to 10 steps per
//! factorization and 20 more on the final set, until the residuals are a hundredth of the
//! tolerances: the contraction is slow where active rows are nearly dependent).
//!
//! The active set is then corrected as in a primal active-set method started from the
//! interior point, which is feasible to the tolerance: if the solution on the active set
//! violates a free row, the step from the current point stops where the first such row
//! becomes active, and that row is added; else the whole step is taken and the active row
//! whose multiplier has the most wrong sign is freed. Each correction is one factorization,
//! at most 50. (A primal-dual active-set method, which moves every disagreeing row at once,
//! cycled on random QPs with general rows.) The result replaces the interior point's only
//! if no row disagrees beyond the tolerance and its stationarity and dynamics residuals
//! meet the tolerances; else the interior point's solution is kept. QPs with soft rows are
//! not polished.

use super::held::{Hold, held_weights};
use super::{Newton, OcpQp, QpSolution, QpSolver, Vect};
use crate::kernels::tr_mul;
use crate::real::Real;
use crate::rows::{Rows, Soft};

/// Active-set corrections at most (each one factorization).
const ROUNDS: usize = 50;

/// Refinement steps per round (each one Riccati solve with the round's factorization); the
/// contraction per step is about `delta / (delta + s)`, `s` the smallest eigenvalue of the
/// active rows' Schur complement: slow on nearly dependent rows.
const REFINE_STEPS: usize = 10;

/// Refinement steps on the final active set.
const FINAL_STEPS: usize = 20;

/// Which side of a row the polish holds as an equality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Side {
    Free,
    Lower,
    Upper,
}

/// The polish's active set, per row set of each stage, and the penalty weight of an active
/// row in the factorization.
pub(super) struct ActiveSet<
    T: Real,
    const NBX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
> {
    pub x: [[Side; NBX]; N],
    pub u: [[Side; NU]; N],
    pub g: [[Side; NG]; N],
    pub xn: [Side; NBX],
    pub gn: [Side; NGN],
    pub w: T,
}

/// A row: its row set (stage `k`'s state bounds, control bounds, general rows, or the
/// terminal ones) and its index (a state-bound row's slot).
#[derive(Clone, Copy, Debug)]
enum Row {
    X(usize, usize),
    U(usize, usize),
    G(usize, usize),
    Xn(usize),
    Gn(usize),
}

impl<T: Real, const NBX: usize, const NU: usize, const NG: usize, const NGN: usize, const N: usize>
    ActiveSet<T, NBX, NU, NG, NGN, N>
{
    /// Puts `row` on `side`, its multiplier at zero.
    fn set(&mut self, y: &mut Duals<T, NBX, NU, NG, NGN, N>, row: Row, side: Side) {
        let (sides, yv): (Option<&mut Side>, Option<&mut T>) = match row {
            Row::X(k, i) => (
                self.x.get_mut(k).and_then(|s| s.get_mut(i)),
                y.x.get_mut(k).and_then(|v| v.get_mut(i)),
            ),
            Row::U(k, i) => (
                self.u.get_mut(k).and_then(|s| s.get_mut(i)),
                y.u.get_mut(k).and_then(|v| v.get_mut(i)),
            ),
            Row::G(k, i) => (
                self.g.get_mut(k).and_then(|s| s.get_mut(i)),
                y.g.get_mut(k).and_then(|v| v.get_mut(i)),
            ),
            Row::Xn(i) => (self.xn.get_mut(i), y.xn.get_mut(i)),
            Row::Gn(i) => (self.gn.get_mut(i), y.gn.get_mut(i)),
        };
        if let (Some(s), Some(v)) = (sides, yv) {
            *s = side;
            *v = T::ZERO;
        }
    }
}

/// The step in `[0, 1]` from row values `v0` to `v1` at which the first free row that `v1`
/// violates (beyond `tol` relative to `max(1, |v1|)`) reaches its bound, with the row's
/// index and side; `(1, None)` if `v1` violates none.
fn ratio<T: Real, const K: usize>(
    r: &Rows<T, K>,
    sides: &[Side; K],
    v0: &Vect<T, K>,
    v1: &Vect<T, K>,
    tol: T,
) -> (T, Option<(usize, Side)>) {
    let mut best = (T::ONE, None);
    for (i, side) in sides.iter().enumerate() {
        if *side != Side::Free {
            continue;
        }
        let (a, b) = (v0[i], v1[i]);
        let slack = tol * T::ONE.max(b.abs());
        // Distance to the bound at v0 (0 if already past it) over the distance travelled.
        let step = |room: T, travel: T| {
            if travel > T::ZERO {
                (room.max(T::ZERO) / travel).min(T::ONE)
            } else {
                T::ZERO
            }
        };
        let hit = if r.has_lo[i] && b < r.lo[i] - slack {
            Some((step(a - r.lo[i], a - b), Side::Lower))
        } else if r.has_hi[i] && b > r.hi[i] + slack {
            Some((step(r.hi[i] - a, b - a), Side::Upper))
        } else {
            None
        };
        if let Some((alpha, side)) = hit
            && (best.1.is_none() || alpha < best.0)
        {
            best = (alpha, Some((i, side)));
        }
    }
    best
}

/// Multipliers of the active rows (`lam_l - lam_u`, zero on free rows), or other values per
/// row.
#[derive(Clone, Copy)]
struct Duals<
    T: Real,
    const NBX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
> {
    x: [Vect<T, NBX>; N],
    u: [Vect<T, NU>; N],
    g: [Vect<T, NG>; N],
    xn: Vect<T, NBX>,
    gn: Vect<T, NGN>,
}

impl<T: Real, const NBX: usize, const NU: usize, const NG: usize, const NGN: usize, const N: usize>
    Duals<T, NBX, NU, NG, NGN, N>
{
    const ZERO: Self = Duals {
        x: [crate::zeros(); N],
        u: [crate::zeros(); N],
        g: [crate::zeros(); N],
        xn: crate::zeros(),
        gn: crate::zeros(),
    };
}

/// `v` on the active rows, zero on the free ones.
fn on<T: Real, const K: usize>(sides: &[Side; K], v: &Vect<T, K>) -> Vect<T, K> {
    let mut a = *v;
    for (ai, side) in a.iter_mut().zip(sides) {
        if *side == Side::Free {
            *ai = T::ZERO;
        }
    }
    a
}

/// The weights a row set adds to the Newton system's Hessian along its rows.
#[derive(Clone, Copy)]
pub(super) enum Weight<'a, T, const K: usize> {
    /// The interior point's barrier weights.
    Barrier,
    /// The polish's: `w` on the active rows, none on the others.
    Active(&'a [Side; K], T),
    /// The warm active set's rows ([`Hold`]): the penalty weight on the held ones, a
    /// violated soft side's `l2`, none on the others.
    Held(&'a [Hold; K]),
    /// None.
    Zero,
}

/// The weights a row set adds to the Hessian along its rows ([`Weight`]).
pub(super) fn weights<T: Real, const K: usize>(
    rows: &Rows<T, K>,
    soft: Option<&Soft<T, K>>,
    weight: Weight<'_, T, K>,
) -> Vect<T, K> {
    match weight {
        Weight::Barrier => rows.sigma(soft),
        Weight::Zero => Vect::zeros(),
        Weight::Held(holds) => held_weights(holds, soft),
        Weight::Active(sides, w) => {
            let mut v = Vect::<T, K>::zeros();
            for (vi, side) in v.iter_mut().zip(sides) {
                if *side != Side::Free {
                    *vi = w;
                }
            }
            v
        }
    }
}

/// The interior point's active sides: those whose multiplier exceeds their slack.
pub(super) fn initial_sides<T: Real, const K: usize>(r: &Rows<T, K>) -> [Side; K] {
    let mut sides = [Side::Free; K];
    for (i, side) in sides.iter_mut().enumerate() {
        let lower = r.has_lo[i] && r.ll[i] > r.tl[i];
        let upper = r.has_hi[i] && r.lu[i] > r.tu[i];
        *side = match (lower, upper) {
            (true, true) if r.lu[i] > r.ll[i] => Side::Upper,
            (true, _) => Side::Lower,
            (false, true) => Side::Upper,
            (false, false) => Side::Free,
        };
    }
    sides
}

/// Distance of the active rows' values `v` from their bounds (zero on free rows).
fn gaps<T: Real, const K: usize>(r: &Rows<T, K>, sides: &[Side; K], v: &Vect<T, K>) -> Vect<T, K> {
    let mut d = Vect::<T, K>::zeros();
    for (i, side) in sides.iter().enumerate() {
        d[i] = match side {
            Side::Free => T::ZERO,
            Side::Lower => v[i] - r.lo[i],
            Side::Upper => v[i] - r.hi[i],
        };
    }
    d
}

/// How far a row is from agreeing with its place in the active set, relative to
/// `max(1, |.|)`: an active row's multiplier of the wrong sign, a free row's violation of a
/// bound by its value `v` (with the side it violates); zero if it agrees.
fn disagreement<T: Real, const K: usize>(
    r: &Rows<T, K>,
    side: Side,
    i: usize,
    y: &Vect<T, K>,
    v: &Vect<T, K>,
) -> (T, Side) {
    let (yi, vi) = (y[i], v[i]);
    let (ys, vs) = (T::ONE.max(yi.abs()), T::ONE.max(vi.abs()));
    match side {
        Side::Lower if yi < T::ZERO => (-yi / ys, Side::Free),
        Side::Upper if yi > T::ZERO => (yi / ys, Side::Free),
        Side::Free if r.has_lo[i] && vi < r.lo[i] => ((r.lo[i] - vi) / vs, Side::Lower),
        Side::Free if r.has_hi[i] && vi > r.hi[i] => ((vi - r.hi[i]) / vs, Side::Upper),
        same => (T::ZERO, same),
    }
}

/// Moves the rows whose [`disagreement`] exceeds `tol` and is at least `at_least` to where
/// it says (a freed row's multiplier set to zero); returns the largest disagreement over
/// the rows (moved or not) and whether any row moved.
fn update_sides<T: Real, const K: usize>(
    r: &Rows<T, K>,
    sides: &mut [Side; K],
    y: &mut Vect<T, K>,
    v: &Vect<T, K>,
    tol: T,
    at_least: T,
) -> (T, bool) {
    let (mut worst, mut moved) = (T::ZERO, false);
    for i in 0..K {
        let Some(side) = sides.get_mut(i) else {
            break;
        };
        let (d, new) = disagreement(r, *side, i, y, v);
        worst = worst.max(d);
        if d > tol && d >= at_least {
            *side = new;
            y[i] = T::ZERO;
            moved = true;
        }
    }
    (worst, moved)
}

/// How far the values `v` are outside the rows' bounds, at most.
fn violation<T: Real, const K: usize>(r: &Rows<T, K>, v: &Vect<T, K>) -> T {
    let mut m = T::ZERO;
    for i in 0..K {
        if r.has_lo[i] {
            m = m.max(r.lo[i] - v[i]);
        }
        if r.has_hi[i] {
            m = m.max(v[i] - r.hi[i]);
        }
    }
    m
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
    /// The polish of the module docs after a solve by the Riccati recursion; if its result
    /// replaced the solution in `sol`, returns its stationarity (relative) and dynamics
    /// residuals and its largest bound violation.
    // Not inlined: its arrays stay out of the stack frame of a solve that does not polish.
    #[inline(never)]
    pub(super) fn riccati_polish<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> Option<[T; 3]> {
        if N == 0 || self.sg.iter().any(|s| s.any) || self.sgn.any {
            return None;
        }
        let w = T::ONE / T::EPSILON.sqrt();
        let mut act = ActiveSet {
            x: [[Side::Free; NBX]; N],
            u: [[Side::Free; NU]; N],
            g: [[Side::Free; NG]; N],
            xn: initial_sides(&*self.rxn),
            gn: initial_sides(&self.rgn),
            w,
        };
        let mut y = Duals::ZERO;
        y.xn = on(&act.xn, &self.rxn.rows_dual());
        y.gn = on(&act.gn, &self.rgn.dual());
        for k in 0..N {
            act.x[k] = initial_sides(&*self.rx[k]);
            act.u[k] = initial_sides(&self.ru[k]);
            act.g[k] = initial_sides(&self.rg[k]);
            y.x[k] = on(&act.x[k], &self.rx[k].rows_dual());
            y.u[k] = on(&act.u[k], &self.ru[k].dual());
            y.g[k] = on(&act.g[k], &self.rg[k].dual());
        }
        let interior = self.sol;
        let tol = self.settings.tol_ineq.max(self.settings.tol_stat);
        let mut settled = false;
        // A primal active-set method from the interior point (feasible to the tolerance):
        // each round solves the QP on the active set; if the step there would violate a
        // free row, it stops where the first one becomes active and adds it; else it takes
        // the whole step and frees the active row whose multiplier is the most wrong, if
        // any (moving many rows at once, as a primal-dual active-set method does, cycled on
        // random QPs with general rows).
        let mut cur = self.sol;
        for _ in 0..ROUNDS {
            if !self.factorize(qp, Newton::Polish(&act)) {
                break;
            }
            self.refine_on(qp, &act, &mut y, REFINE_STEPS);
            let (alpha, hit) = self.blocking(qp, &cur, &act, tol);
            if let Some((row, side)) = hit {
                self.blend(&cur, alpha);
                act.set(&mut y, row, side);
                cur = self.sol;
                continue;
            }
            cur = self.sol;
            let worst = self.move_rows(qp, &mut act, &mut y, tol, T::INF).0;
            if worst <= tol {
                settled = true;
                break;
            }
            self.move_rows(qp, &mut act, &mut y, tol, worst);
        }
        if settled {
            // The refinement contracts slowly where active rows are nearly dependent: more
            // steps on the final active set (no factorization), which must still agree.
            self.refine_on(qp, &act, &mut y, FINAL_STEPS);
            settled = self.move_rows(qp, &mut act, &mut y, tol, T::INF).0 <= tol;
        }
        let (stat, eq) = self.polish_residuals(qp, &y);
        let ineq = self.bound_violation(qp);
        let ok = settled
            && stat <= self.settings.tol_stat
            && eq <= self.settings.tol_eq
            && self.sol.x.iter().all(|x| x.iter().all(|v| v.finite()))
            && self.sol.u.iter().all(|u| u.iter().all(|v| v.finite()))
            && self.sol.xn.iter().all(|v| v.finite());
        if !ok {
            self.sol = interior;
            return None;
        }
        Some([stat, eq, ineq])
    }

    /// The largest violation of a bound or general-constraint side at the current point.
    fn bound_violation<const NH: usize>(&self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) -> T {
        let mut m = T::ZERO;
        for k in 0..N {
            let s = &qp.stages[k];
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            m = m
                .max(violation(&self.rx[k], &self.rx[k].gather(&x)))
                .max(violation(&self.ru[k], &u))
                .max(violation(&self.rg[k], &(s.c * x + s.d * u)));
        }
        let xn = self.sol.xn;
        m.max(violation(&self.rxn, &self.rxn.gather(&xn)))
            .max(violation(&self.rgn, &(qp.terminal.c * xn)))
    }

    /// The ratio test of the primal active-set method: over every free row, the step from
    /// `cur` to the solution in `sol` at which the first row the solution violates becomes
    /// active, and that row.
    fn blocking<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        cur: &QpSolution<T, NX, NU, N>,
        act: &ActiveSet<T, NBX, NU, NG, NGN, N>,
        tol: T,
    ) -> (T, Option<(Row, Side)>) {
        let mut best: (T, Option<(Row, Side)>) = (T::ONE, None);
        let mut take = |(alpha, hit): (T, Option<(usize, Side)>), row: &dyn Fn(usize) -> Row| {
            if let Some((i, side)) = hit
                && (best.1.is_none() || alpha < best.0)
            {
                best = (alpha, Some((row(i), side)));
            }
        };
        for k in 0..N {
            let s = &qp.stages[k];
            let (x0, u0, x1, u1) = (cur.x[k], cur.u[k], self.sol.x[k], self.sol.u[k]);
            let rx = &self.rx[k];
            take(
                ratio(rx, &act.x[k], &rx.gather(&x0), &rx.gather(&x1), tol),
                &|i| Row::X(k, i),
            );
            take(ratio(&self.ru[k], &act.u[k], &u0, &u1, tol), &|i| {
                Row::U(k, i)
            });
            let (g0, g1) = (s.c * x0 + s.d * u0, s.c * x1 + s.d * u1);
            take(ratio(&self.rg[k], &act.g[k], &g0, &g1, tol), &|i| {
                Row::G(k, i)
            });
        }
        let c = &qp.terminal.c;
        let (x0, x1) = (cur.xn, self.sol.xn);
        let rxn = &self.rxn;
        take(
            ratio(rxn, &act.xn, &rxn.gather(&x0), &rxn.gather(&x1), tol),
            &Row::Xn,
        );
        take(
            ratio(&self.rgn, &act.gn, &(c * x0), &(c * x1), tol),
            &Row::Gn,
        );
        best
    }

    /// `sol <- cur + alpha (sol - cur)` (states, controls, dynamics multipliers).
    fn blend(&mut self, cur: &QpSolution<T, NX, NU, N>, alpha: T) {
        let mix = |a: T, b: T| a + (b - a) * alpha;
        for (s, c) in self.sol.x.iter_mut().zip(&cur.x) {
            *s = c.zip_map(s, mix);
        }
        for (s, c) in self.sol.u.iter_mut().zip(&cur.u) {
            *s = c.zip_map(s, mix);
        }
        for (s, c) in self.sol.pi.iter_mut().zip(&cur.pi) {
            *s = c.zip_map(s, mix);
        }
        self.sol.xn = cur.xn.zip_map(&self.sol.xn, mix);
    }

    /// Up to `steps` refinement steps, stopping once the KKT residuals of the active-set QP
    /// (stationarity, dynamics, the active rows' distance to their bounds) are below a
    /// hundredth of the tolerances (checked after every other step: a check costs about
    /// half a step).
    fn refine_on<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        act: &ActiveSet<T, NBX, NU, NG, NGN, N>,
        y: &mut Duals<T, NBX, NU, NG, NGN, N>,
        steps: usize,
    ) {
        let f = T::lit(0.01);
        let st = self.settings;
        for i in 0..steps {
            self.polish_step(qp, act, y);
            if i % 2 == 1 {
                let (stat, eq) = self.polish_residuals(qp, y);
                if stat <= st.tol_stat * f
                    && eq <= st.tol_eq * f
                    && self.active_gap(qp, act) <= st.tol_ineq * f
                {
                    break;
                }
            }
        }
    }

    /// The largest distance of an active row from its bound.
    fn active_gap<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        act: &ActiveSet<T, NBX, NU, NG, NGN, N>,
    ) -> T {
        let mut m = T::ZERO;
        for k in 0..N {
            let s = &qp.stages[k];
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            m = m
                .max(gaps(&self.rx[k], &act.x[k], &self.rx[k].gather(&x)).amax())
                .max(gaps(&self.ru[k], &act.u[k], &u).amax())
                .max(gaps(&self.rg[k], &act.g[k], &(s.c * x + s.d * u)).amax());
        }
        let xn = self.sol.xn;
        m.max(gaps(&self.rxn, &act.xn, &self.rxn.gather(&xn)).amax())
            .max(gaps(&self.rgn, &act.gn, &(qp.terminal.c * xn)).amax())
    }

    /// One refinement step: the residuals of the active-set QP's KKT system at the current
    /// point, the Riccati solve of the regularized system for the correction, and the
    /// update of states, controls, dynamics multipliers and the active rows' multipliers.
    fn polish_step<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        act: &ActiveSet<T, NBX, NU, NG, NGN, N>,
        y: &mut Duals<T, NBX, NU, NG, NGN, N>,
    ) {
        let w = act.w;
        // The right-hand side: the stationarity residual H z + g + (dynamics)'pi - a'y plus
        // a' w r_a, and the dynamics residual; the solve gives the corrections of z and pi.
        let mut wr = Duals::<T, NBX, NU, NG, NGN, N>::ZERO;
        for k in 0..N {
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            let xnext = if k + 1 < N {
                self.sol.x[k + 1]
            } else {
                self.sol.xn
            };
            self.rbt[k] = s.a * x + s.b * u + s.f - xnext;
            wr.x[k] = gaps(&self.rx[k], &act.x[k], &self.rx[k].gather(&x)) * w;
            wr.u[k] = gaps(&self.ru[k], &act.u[k], &u) * w;
            wr.g[k] = gaps(&self.rg[k], &act.g[k], &(s.c * x + s.d * u)) * w;
            let tg = wr.g[k] - y.g[k];
            let pi = self.sol.pi[k];
            self.gut[k] =
                h.r * u + h.s * x + s.gu + wr.u[k] - y.u[k] + tr_mul(&s.d, &tg) + tr_mul(&s.b, &pi);
            if k > 0 {
                let rx = &self.rx[k];
                self.gxt[k] = h.q * x + tr_mul(&h.s, &u) + s.gx + rx.scatter(&wr.x[k])
                    - rx.scatter(&y.x[k])
                    + tr_mul(&s.c, &tg)
                    + tr_mul(&s.a, &pi)
                    - self.sol.pi[k - 1];
            }
        }
        let t = &qp.terminal;
        let xn = self.sol.xn;
        wr.xn = gaps(&self.rxn, &act.xn, &self.rxn.gather(&xn)) * w;
        wr.gn = gaps(&self.rgn, &act.gn, &(t.c * xn)) * w;
        let tg = wr.gn - y.gn;
        let prev = self.sol.pi.last().copied().unwrap_or_else(Vect::zeros);
        self.gnt = t.q * xn + t.gx + self.rxn.scatter(&wr.xn) - self.rxn.scatter(&y.xn)
            + tr_mul(&t.c, &tg)
            - prev;
        self.lq_solve(qp, None);
        // The corrections, and the active rows' multipliers' dy = -w (r_a + a'dz): from the
        // residual and the correction rather than from the rows at the new point, whose
        // rounding `w` would amplify.
        for k in 0..N {
            let s = &qp.stages[k];
            let (dx, du) = (self.dx[k], self.du[k]);
            if k > 0 {
                self.sol.x[k] += dx;
            }
            self.sol.u[k] += du;
            y.x[k] -= wr.x[k] + on(&act.x[k], &self.rx[k].gather(&dx)) * w;
            y.u[k] -= wr.u[k] + on(&act.u[k], &du) * w;
            y.g[k] -= wr.g[k] + on(&act.g[k], &(s.c * dx + s.d * du)) * w;
        }
        let dxn = self.dxn;
        self.sol.xn += dxn;
        y.xn -= wr.xn + on(&act.xn, &self.rxn.gather(&dxn)) * w;
        y.gn -= wr.gn + on(&act.gn, &(t.c * dxn)) * w;
        for (pi, dpi) in self.sol.pi.iter_mut().zip(&self.pi_new) {
            *pi += *dpi;
        }
    }

    /// [`update_sides`] over every row set: the largest disagreement and whether a row moved.
    fn move_rows<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        act: &mut ActiveSet<T, NBX, NU, NG, NGN, N>,
        y: &mut Duals<T, NBX, NU, NG, NGN, N>,
        tol: T,
        at_least: T,
    ) -> (T, bool) {
        let (mut worst, mut moved) = (T::ZERO, false);
        let mut add = |(w, m): (T, bool)| {
            worst = worst.max(w);
            moved |= m;
        };
        for k in 0..N {
            let s = &qp.stages[k];
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            add(update_sides(
                &self.rx[k],
                &mut act.x[k],
                &mut y.x[k],
                &self.rx[k].gather(&x),
                tol,
                at_least,
            ));
            add(update_sides(
                &self.ru[k],
                &mut act.u[k],
                &mut y.u[k],
                &u,
                tol,
                at_least,
            ));
            let vg = s.c * x + s.d * u;
            add(update_sides(
                &self.rg[k],
                &mut act.g[k],
                &mut y.g[k],
                &vg,
                tol,
                at_least,
            ));
        }
        let xn = self.sol.xn;
        add(update_sides(
            &self.rxn,
            &mut act.xn,
            &mut y.xn,
            &self.rxn.gather(&xn),
            tol,
            at_least,
        ));
        let vg = qp.terminal.c * xn;
        add(update_sides(
            &self.rgn,
            &mut act.gn,
            &mut y.gn,
            &vg,
            tol,
            at_least,
        ));
        (worst, moved)
    }

    /// Stationarity (relative to its largest term when that exceeds 1, as in the interior
    /// point's residuals) and dynamics residual of the active-set QP at the current point.
    fn polish_residuals<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        y: &Duals<T, NBX, NU, NG, NGN, N>,
    ) -> (T, T) {
        let (mut rs, mut re, mut scale) = (T::ZERO, T::ZERO, T::ONE);
        for k in 0..N {
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (x, u, pi) = (self.sol.x[k], self.sol.u[k], self.sol.pi[k]);
            let xnext = if k + 1 < N {
                self.sol.x[k + 1]
            } else {
                self.sol.xn
            };
            re = re.max((s.a * x + s.b * u + s.f - xnext).amax());
            let hu = h.r * u + h.s * x + s.gu;
            let (bpi, dy) = (tr_mul(&s.b, &pi), tr_mul(&s.d, &y.g[k]));
            rs = rs.max((hu + bpi - y.u[k] - dy).amax());
            scale = scale
                .max(hu.amax())
                .max(bpi.amax())
                .max(y.u[k].amax())
                .max(dy.amax());
            if k > 0 {
                let hx = h.q * x + tr_mul(&h.s, &u) + s.gx;
                let (api, cy) = (tr_mul(&s.a, &pi), tr_mul(&s.c, &y.g[k]));
                let prev = self.sol.pi[k - 1];
                let yx = self.rx[k].scatter(&y.x[k]);
                rs = rs.max((hx + api - prev - yx - cy).amax());
                scale = scale
                    .max(hx.amax())
                    .max(api.amax())
                    .max(prev.amax())
                    .max(yx.amax())
                    .max(cy.amax());
            }
        }
        let t = &qp.terminal;
        let xn = self.sol.xn;
        let hxn = t.q * xn + t.gx;
        let cy = tr_mul(&t.c, &y.gn);
        let prev = self.sol.pi.last().copied().unwrap_or_else(Vect::zeros);
        let yxn = self.rxn.scatter(&y.xn);
        rs = rs.max((hxn - prev - yxn - cy).amax());
        scale = scale
            .max(hxn.amax())
            .max(prev.amax())
            .max(yxn.amax())
            .max(cy.amax());
        (rs / scale, re)
    }
}
