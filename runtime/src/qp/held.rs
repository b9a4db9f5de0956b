//! The warm active set for QPs the Riccati recursion solves
//! ([`QpSettings::warm_active_set`](crate::QpSettings::warm_active_set); a condensed QP has
//! its own, in `condense.rs`).
//!
//! A real-time iteration's QPs change little from one control step to the next, and so do
//! the control bounds that hold in their solutions. Holding those controls on their bounds
//! (and no other row), the QP is an equality-constrained linear-quadratic problem: the
//! Riccati recursion with no barrier weight, the held controls' rows and columns of
//! `R~ = R + B'PB` replaced by the identity and their rows of `S~ = S + B'PA` by zeros, so
//! that `P` is the recursion's over the free controls alone. None of it depends on `x0`:
//! [`QpSolver::prepare`] factorizes it. The solve is then `1 + settings.refine` Newton
//! steps from zero with the held controls on their bounds (a backward and a forward vector
//! pass each; the held controls' steps are zero), which give the active-set QP's solution
//! and its dynamics multipliers. The bounds' multipliers follow from the controls'
//! stationarity, `mu = R u + S x + gu + B'pi` (`lam_l - lam_u`).
//!
//! The result is the QP's solution if the rows, set from it (held bounds at zero slack
//! with the multipliers `max(mu, 0)` on a lower bound and `max(-mu, 0)` on an upper one,
//! every other row free with its slack from the values and multiplier zero), meet the
//! interior point's own stopping test: its stationarity, dynamics and inequality residuals
//! within the tolerances (a held bound with a multiplier of the wrong sign shows in the
//! stationarity residual, a free row past its bound in the inequality residual;
//! complementarity is zero). One more Newton step is taken where the first misses (rounding
//! at tight tolerances); if that misses too, the interior point solves the QP from the
//! start, warm-started from the rows as set.
//!
//! The set is taken from each interior-point solution (the control bounds whose multiplier
//! exceeds their slack) only when no other row is active and the QP has no soft row;
//! otherwise there is no warm set until such a solution comes.

use super::polish::{Side, all_free, initial_sides};
use super::{Newton, OcpQp, QpInfo, QpSolution, QpSolver, QpStatus};
use crate::kernels::{mul, mul_sparse, tr_mul};
use crate::real::Real;

/// Active-set moves after a warm set that missed, at most (each one factorization), before
/// the interior point takes over.
const ITERATIONS: usize = 4;

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
    /// Whether the loaded QP has a soft row (the warm active set leaves such QPs to the
    /// interior point).
    fn any_soft(&self) -> bool {
        self.sg.iter().any(|s| s.any) || self.sgn.any
    }

    /// The preparation of the warm active set of the Riccati recursion: the stored set, less
    /// the bounds the QP no longer has, factorized. Returns whether the factorization
    /// succeeded (`false` also without Riccati storage or with soft rows).
    pub(super) fn prepare_held<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> bool {
        if NR != N || self.any_soft() {
            return false;
        }
        let (lower, upper) = self.present_active_set();
        self.factorize(qp, Newton::Held(&held(&lower, &upper)))
    }

    /// The solve on the warm active set that [`prepare_held`](Self::prepare_held)
    /// factorized (module docs). `Ok` with the solve's outcome, or `Err` with the active-set
    /// solves spent when the interior point must solve the QP (also for a non-finite `x0`,
    /// which it reports; nothing is changed then).
    #[inline(never)]
    pub(super) fn solve_held<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> Result<QpInfo<T>, u32> {
        if NR != N || !qp.x0.iter().all(|v| v.finite()) {
            return Err(0);
        }
        let (mut lower, mut upper) = self.stored_active_set();
        self.sol = QpSolution::NEW;
        if let Some(x) = self.sol.x.first_mut() {
            *x = qp.x0;
        }
        let mut solves = 0;
        // The sets of a point whose rows were not set (its set plainly missed, below): set
        // them if the solve ends there, for the interior point's warm start.
        let mut unset: Option<Sets<NU, N>> = None;
        for round in 0..=ITERATIONS {
            // Each round after the first moves the set and factorizes it.
            if round > 0 {
                let before = held(&lower, &upper);
                let sets = (lower, upper);
                if !self.move_held_set(qp, &mut lower, &mut upper) {
                    self.set_rows_if(qp, unset);
                    return Err(solves);
                }
                self.store_active_set(&lower, &upper);
                // The recursion runs backward: the stages after the last one whose held
                // controls changed keep their factorization (the last one's, on this QP).
                let now = held(&lower, &upper);
                let stages = (0..N)
                    .rev()
                    .find(|&k| now[k] != before[k])
                    .map_or(0, |k| k + 1);
                if !self.factorize_stages(qp, Newton::Held(&now), stages) {
                    self.act_valid = false;
                    self.set_rows_if(qp, unset.map(|_| sets));
                    return Err(solves);
                }
            }
            let fixed = held(&lower, &upper);
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
            let mut steps = 1 + self.settings.refine;
            for retry in [false, true] {
                solves += 1;
                for _ in 0..steps {
                    self.held_step(qp, &fixed);
                }
                // A free control past its bound by more than the retry's margin: the
                // residuals would miss by more than it too (the inequality residual is at
                // least that), and the set moves; they are not computed.
                if self.free_violation(&lower, &upper) > self.settings.tol_ineq * T::lit(1e4) {
                    unset = Some((lower, upper));
                    break;
                }
                unset = None;
                let res = self.hold_rows(qp, &lower, &upper);
                let st = &self.settings;
                let within = |f: T| {
                    res[0] <= st.tol_stat * f
                        && res[1] <= st.tol_eq * f
                        && res[2] <= st.tol_ineq * f
                };
                if within(T::ONE) {
                    self.dual_valid = true;
                    self.polished = false;
                    self.on_active_set = true;
                    return Ok(QpInfo {
                        status: QpStatus::Solved,
                        iterations: 0,
                        active_set_solves: solves,
                        res_stat: res[0],
                        res_eq: res[1],
                        res_ineq: res[2],
                        mu: T::ZERO,
                    });
                }
                // Rounding (tight tolerances on an ill-conditioned QP) leaves residuals near
                // the tolerances, and one more step mends them; a set that no longer holds
                // leaves a bound violated or a multiplier of the wrong sign, which it does
                // not: the set moves.
                if retry || !within(T::lit(1e4)) {
                    break;
                }
                steps = 1;
            }
        }
        self.set_rows_if(qp, unset);
        Err(solves)
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

    /// Sets the rows at the current point on `sets` (as [`hold_rows`](Self::hold_rows)), if
    /// given.
    fn set_rows_if<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
        sets: Option<Sets<NU, N>>,
    ) {
        if let Some((lower, upper)) = sets {
            self.hold_rows(qp, &lower, &upper);
        }
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
            let s = &qp.stages[k];
            let h = qp.h(k);
            let (x, u) = (self.sol.x[k], self.sol.u[k]);
            let mu = mul(&h.r, &u) + mul(&h.s, &x) + s.gu + tr_mul(&s.b, &self.sol.pi[k]);
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
    /// next solve: the control bounds whose multiplier exceeds their slack, if no other row
    /// is active by that rule and the QP has no soft row; else no warm set.
    pub(super) fn held_set_of_interior_point(&mut self) {
        if NR != N || self.any_soft() {
            self.act_valid = false;
            return;
        }
        let free = all_free(&*self.rxn)
            && all_free(&self.rgn)
            && self
                .rx
                .iter()
                .zip(&self.rg)
                .all(|(x, g)| all_free(&**x) && all_free(g));
        if !free {
            self.act_valid = false;
            return;
        }
        let (mut lower, mut upper) = ([[false; NU]; N], [[false; NU]; N]);
        for (k, r) in self.ru.iter().enumerate() {
            for (i, side) in initial_sides(r).iter().enumerate() {
                lower[k][i] = *side == Side::Lower;
                upper[k][i] = *side == Side::Upper;
            }
        }
        self.store_active_set(&lower, &upper);
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
        let fixed = held(&lower, &upper);
        assert!(fast.factorize(qp, Newton::Held(&fixed)));
        fast.sol = QpSolution::NEW;
        fast.sol.x[0] = qp.x0;
        for k in 0..6 {
            for i in 0..2 {
                if lower[k][i] {
                    fast.sol.u[k][i] = fast.ru[k].lo[i];
                } else if upper[k][i] {
                    fast.sol.u[k][i] = fast.ru[k].hi[i];
                }
            }
        }
        fast.held_step(qp, &fixed);
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

    /// After a move of the held set, the stages above the last changed one keep their
    /// factorization: refactorizing the others alone ends as a whole factorization does, bit
    /// for bit; leaving a changed stage out does not.
    #[test]
    fn a_move_refactorizes_the_changed_stages_alone() {
        let (qp, mut part) = qp_and_solver();
        let mut before = [[false; 2]; 6];
        before[4][1] = true;
        before[1][0] = true;
        assert!(part.factorize(&qp, Newton::Held(&before)));
        let mut after = before;
        after[2][1] = true;
        after[1][0] = false;
        let mut whole = part.clone();
        assert!(whole.factorize(&qp, Newton::Held(&after)));
        let mut short = part.clone();
        assert!(part.factorize_stages(&qp, Newton::Held(&after), 3));
        assert!(part.linv == whole.linv && part.wt == whole.wt && part.pn == whole.pn);
        // Stage 2 changed: refactorizing stages 1 and 0 alone is not the factorization.
        assert!(short.factorize_stages(&qp, Newton::Held(&after), 2));
        assert!(short.linv != whole.linv || short.wt != whole.wt);
    }
}
