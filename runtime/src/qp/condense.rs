//! Full condensing: the states are eliminated through the dynamics, leaving a dense QP in the
//! controls `u = (u_0, ..., u_{N-1})`,
//!
//! ```text
//! min 1/2 u'H u + (gc + xc x0)' u   s.t.  lbu_k <= u_k <= ubu_k,
//! ```
//!
//! solved by the same interior-point iteration, whose Newton systems are then one dense block
//! Cholesky factorization of `H + Sigma` each. `H`, `gc` and `xc` depend on the stage data
//! only, so they are built in [`QpSolver::prepare`], before `x0` is known.
//!
//! `H` comes from a backward recursion over the tail cost `T_k(x_k, u_k, ..., u_{N-1})`, the
//! cost from stage `k` on with the dynamics substituted. Its Hessian by `x_k` is `P_k`, its
//! cross term with `u_j` is `X_{k,j}`, its gradient by `x_k` is `p_k`; with
//! `x_{k+1} = A x_k + B u_k + f` (stage `k`'s data):
//!
//! ```text
//! P_N = Q_N,  p_N = gx_N
//! H_kk = R_k + B'P_{k+1}B,        H_jk = X_{k+1,j}'B          (j > k)
//! X_kk = S_k' + A'P_{k+1}B,       X_kj = A'X_{k+1,j}          (j > k)
//! gc_k = gu_k + B'(p_{k+1} + P_{k+1} f),   gc_j += X_{k+1,j}'f   (j > k)
//! p_k = gx_k + A'(p_{k+1} + P_{k+1} f),    P_k = Q_k + A'P_{k+1}A
//! ```
//!
//! and `xc_j = X_{0,j}'` (stored transposed). That is `O(N^2 NX^2 NU + N NX^3)` once per
//! QP, less where `A` and `B` have zeros (the products skip them). After the iteration the
//! states follow from the dynamics and the dynamics multipliers from the state
//! stationarity conditions (there are no state bounds), backwards.

use super::{
    Mat, OcpQp, QpInfo, QpMethod, QpSolver, QpStatus, Vect, condensing_pays, regularized_cholesky,
};
use crate::kernels::{
    add_mul_sum, lower_inverse, mul, mul_sparse, mul_sparse_add_into, mul_sparse_into, mul_tr,
    sub_mul_tr_sum, symmetrize, tr_mul, tr_mul_add_into,
};
use crate::real::Real;
use crate::rows::Rhs;

/// Active-set iterations of the polish at most (each one factorization).
const POLISH_ITERATIONS: usize = 4;

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
    /// Whether the next solve of `qp` condenses: storage for it (`NC = N`), the method (any,
    /// without Riccati storage), and no inequality other than control bounds.
    pub(super) fn condensing_applies<const NH: usize>(
        &self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> bool {
        if NC != N || N == 0 {
            return false;
        }
        // Without Riccati storage (`NR = 0`) there is no other method.
        match self.settings.method {
            _ if NR != N => {}
            QpMethod::Riccati => return false,
            QpMethod::Condensed => {}
            QpMethod::Auto => {
                if !condensing_pays(NX, NU, N) {
                    return false;
                }
            }
        }
        fn free<T: Real, const K: usize>(lo: &Vect<T, K>, hi: &Vect<T, K>) -> bool {
            lo.iter().all(|&l| l <= -T::INF) && hi.iter().all(|&h| h >= T::INF)
        }
        let stages = qp
            .stages
            .iter()
            .enumerate()
            .all(|(k, s)| (k == 0 || free(&s.lbx, &s.ubx)) && free(&s.lg, &s.ug));
        let t = &qp.terminal;
        stages && free(&t.lbx, &t.ubx) && free(&t.lg, &t.ug)
    }

    /// Builds `H` (on and above the diagonal of `tri`), `gc`, `xc` (module docs). Returns
    /// `false` (and the Riccati recursion is used) if `NC != N`.
    pub(super) fn condense<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> bool {
        if NC != N {
            return false;
        }
        let t = &qp.terminal;
        let mut p = (t.q + t.q.transpose()) * T::lit(0.5);
        let mut pv = t.gx;
        // Every product with `A` or `B` has it on the right (`mul_sparse` skips its zeros):
        // `A'M = (M'A)'` with `P` symmetric, and `xc` holds `X'`.
        for k in (0..NC).rev() {
            let Some(s) = qp.stages.get(k) else {
                return false;
            };
            let h = qp.h(k);
            let pb = mul_sparse(&p, &s.b);
            let pbt = pb.transpose();
            let pf = pv + mul(&p, &s.f);
            self.tri[k][k] = h.r + mul_sparse(&pbt, &s.b);
            for j in k + 1..NC {
                mul_sparse_into(&mut self.tri[k][j], &self.xc[j], &s.b);
                self.gc[j] += mul(&self.xc[j], &s.f);
                let x = self.xc[j];
                mul_sparse_into(&mut self.xc[j], &x, &s.a);
            }
            self.gc[k] = s.gu + tr_mul(&s.b, &pf);
            self.xc[k] = h.s + mul_sparse(&pbt, &s.a);
            if k > 0 {
                pv = s.gx + tr_mul(&s.a, &pf);
                let pat = mul_sparse(&p, &s.a).transpose();
                mul_sparse_into(&mut p, &pat, &s.a);
                p += h.q;
                symmetrize(&mut p);
            }
        }
        true
    }

    /// The condensed gradient at this `x0`, into `gu0`.
    pub(super) fn condensed_gradient<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) {
        for k in 0..NC.min(N) {
            self.gu0[k] = self.gc[k] + mul(&self.xc[k], &qp.x0);
        }
    }

    /// `sum_j H_ij v_j` for block row `i` (`H_ij`, `i > j`, is stored at `tri[j][i]`, and
    /// `H_ij = H_ji'` above the diagonal).
    fn hessian_row(&self, i: usize, v: &[Vect<T, NU>; N]) -> Vect<T, NU> {
        let mut h = Vect::<T, NU>::zeros();
        for (row, vj) in self.tri.iter().zip(v).take(i) {
            mul_sparse_add_into(&mut h, &row[i], vj);
        }
        mul_sparse_add_into(&mut h, &self.tri[i][i], &v[i]);
        for (hji, vj) in self.tri[i].iter().zip(v).skip(i + 1) {
            tr_mul_add_into(&mut h, hji, vj);
        }
        h
    }

    /// Residuals of the condensed QP: `[stationarity, 0, inequality, sum t lam]` (the
    /// dynamics hold by construction), with `H u + g` in `hu`. Stationarity is relative to the
    /// largest of its terms, `H u`, `g` and the bound multipliers, when that exceeds 1 (as the
    /// Riccati recursion's is to its terms, of which `H u` and `g` are sums).
    pub(super) fn condensed_residuals(&mut self) -> [T; 4] {
        let (mut rs, mut ri, mut comp, mut scale) = (T::ZERO, T::ZERO, T::ZERO, T::ONE);
        for i in 0..NC.min(N) {
            let hv = self.hessian_row(i, &self.sol.u);
            let h = hv + self.gu0[i];
            self.hu[i] = h;
            let ud = self.ru[i].dual();
            rs = rs.max((h - ud).amax());
            scale = scale.max(hv.amax()).max(self.gu0[i].amax()).max(ud.amax());
            ri = ri.max(self.ru[i].residuals(&self.sol.u[i], None));
            comp += self.ru[i].complementarity();
        }
        [rs / scale, T::ZERO, ri, comp]
    }

    /// Block Cholesky factorization `L L' = H + Sigma` into `ld` and below the diagonal of
    /// `tri`; see [`block_cholesky`](Self::block_cholesky).
    pub(super) fn condensed_factorize(&mut self) -> bool {
        for j in 0..NC.min(N) {
            self.ld[j] = self.tri[j][j] + Mat::from_diagonal(&self.ru[j].sigma(None));
        }
        self.block_cholesky(false)
    }

    /// In-place block Cholesky factorization of the symmetric matrix whose diagonal blocks
    /// are in `ld` and whose blocks below them are `H`'s (above the diagonal of `tri`) or,
    /// if `below_in_tri`, already below the diagonal of `tri`; each diagonal block
    /// regularized as in the Riccati recursion. The factor replaces them: `L_ij` below the
    /// diagonal of `tri`, the diagonal blocks inverted (`ld[j] = L_jj^-1`), so that every later
    /// use is a product. `H` itself is kept.
    fn block_cholesky(&mut self, below_in_tri: bool) -> bool {
        let n = NC.min(N);
        for j in 0..n {
            let mut d = self.ld[j];
            let lj = &self.tri[j][..j];
            sub_mul_tr_sum(&mut d, lj, lj);
            let Some(chol) = regularized_cholesky(d, self.settings.reg) else {
                return false;
            };
            let inv = lower_inverse(&chol.unpack());
            if !inv.iter().all(|v| v.finite()) {
                return false;
            }
            for i in j + 1..n {
                let mut m = if below_in_tri {
                    self.tri[i][j]
                } else {
                    self.tri[j][i]
                };
                sub_mul_tr_sum(&mut m, &self.tri[i][..j], &self.tri[j][..j]);
                // L_ij L_jj' = M.
                self.tri[i][j] = mul_tr(&m, &inv);
            }
            self.ld[j] = inv;
        }
        true
    }

    /// `v <- (L L')^-1 v` with the factor of the last
    /// [`condensed_factorize`](Self::condensed_factorize).
    fn condensed_solve(&self, v: &mut [Vect<T, NU>; N]) {
        let n = NC.min(N);
        for i in 0..n {
            let mut y = v[i];
            add_mul_sum(&mut y, -T::ONE, &self.tri[i][..i], &v[..i]);
            v[i] = mul(&self.ld[i], &y);
        }
        for i in (0..n).rev() {
            let mut y = v[i];
            for (lk, vk) in self.tri.iter().zip(v.iter()).skip(i + 1) {
                y -= tr_mul(&lk[i], vk);
            }
            v[i] = tr_mul(&self.ld[i], &y);
        }
    }

    /// Newton direction of the condensed QP: `(H + Sigma) du = -(H u + g + bound terms)`,
    /// with `settings.refine` steps of iterative refinement against `H` itself.
    pub(super) fn condensed_direction(&mut self, rhs: Rhs<T>) {
        let n = NC.min(N);
        let mut sig = [Vect::<T, NU>::zeros(); N];
        let rows = self
            .gut
            .iter_mut()
            .zip(&mut sig)
            .zip(&self.ru)
            .zip(&self.hu);
        for (((g, sg), r), h) in rows {
            *g = *h + r.gradient(rhs, None);
            *sg = r.sigma(None);
        }
        let mut du = self.gut;
        self.condensed_solve(&mut du);
        for d in du.iter_mut() {
            *d = -*d;
        }
        for _ in 0..self.settings.refine {
            let mut r = self.gut;
            for (i, ri) in r.iter_mut().enumerate().take(n) {
                *ri += self.hessian_row(i, &du) + sig[i].component_mul(&du[i]);
            }
            self.condensed_solve(&mut r);
            for (d, c) in du.iter_mut().zip(&r) {
                *d -= *c;
            }
        }
        for ((d, r), dk) in self.du.iter_mut().zip(self.ru.iter_mut()).zip(&du) {
            *d = *dk;
            r.direction(dk, rhs, None);
        }
    }

    /// Active-set polish ([`QpSettings::polish`](super::QpSettings::polish)): primal-dual
    /// active-set iterations (a semismooth Newton method for the bound-constrained QP) from
    /// the interior point's controls and multipliers (see
    /// [`active_set_iterations`](Self::active_set_iterations)). Returns whether the result,
    /// checked against every bound and the multipliers' signs, replaced the controls in
    /// `sol.u`; its active set is then the one a warm active set starts from.
    // Not inlined: its arrays stay out of the stack frame of a solve that does not polish.
    #[inline(never)]
    pub(super) fn condensed_polish(&mut self) -> bool {
        let mut v = self.sol.u;
        // The interior point's multipliers to start with.
        let mut mu = [Vect::<T, NU>::zeros(); N];
        for (m, r) in mu.iter_mut().zip(&self.ru) {
            *m = r.dual();
        }
        let (mut lower, mut upper) = ([[false; NU]; N], [[false; NU]; N]);
        if self
            .active_set_iterations(&mut v, &mut mu, &mut lower, &mut upper, false)
            .is_err()
        {
            return false;
        }
        self.sol.u = v;
        self.store_active_set(&lower, &upper);
        true
    }

    /// Primal-dual active-set iterations from `v` with multipliers `mu = H v + g` (the
    /// bounds' multipliers, `lam_l - lam_u`): an entry is fixed on its lower bound when the
    /// Newton step along it, `v_i - mu_i / H_ii`, falls below the bound, on its upper bound
    /// when it passes it, and free otherwise; the QP with the fixed entries as equalities is
    /// solved, and the sets are updated until they repeat, at most `POLISH_ITERATIONS`
    /// times. `settled`: `v` already solves the QP on the sets passed in. `Ok` with the
    /// number of solves if the end point is optimal
    /// ([`active_set_optimal`](Self::active_set_optimal)), else `Err` with it.
    fn active_set_iterations(
        &mut self,
        v: &mut [Vect<T, NU>; N],
        mu: &mut [Vect<T, NU>; N],
        lower: &mut [[bool; NU]; N],
        upper: &mut [[bool; NU]; N],
        mut settled: bool,
    ) -> Result<u32, u32> {
        let n = NC.min(N);
        let mut solves = 0;
        for _ in 0..POLISH_ITERATIONS {
            // The active sets of this iterate.
            let mut changed = false;
            for k in 0..n {
                let r = &self.ru[k];
                for i in 0..NU {
                    let (lo, hi) = self.crossed_bounds(k, i, v[k][i], mu[k][i]);
                    changed |= lo != lower[k][i] || hi != upper[k][i];
                    (lower[k][i], upper[k][i]) = (lo, hi);
                    if lo {
                        v[k][i] = r.lo[i];
                    } else if hi {
                        v[k][i] = r.hi[i];
                    }
                }
            }
            if !changed && settled {
                break;
            }
            solves += 1;
            if !self.solve_on_active_set(lower, upper, v) {
                return Err(solves);
            }
            settled = true;
            for (i, m) in mu.iter_mut().enumerate().take(n) {
                *m = self.hessian_row(i, v) + self.gu0[i];
            }
        }
        if self.active_set_optimal(v, mu, lower, upper) {
            Ok(solves)
        } else {
            Err(solves)
        }
    }

    /// Whether `v`, with the entries in `lower` / `upper` on their bounds and multipliers
    /// `mu = H v + g`, solves the condensed QP to the tolerances: every free entry within its
    /// bounds, and the fixed entries' multipliers of their signs (an entry whose bounds
    /// coincide takes either). Stationarity on the free entries is the solve's.
    fn active_set_optimal(
        &self,
        v: &[Vect<T, NU>; N],
        mu: &[Vect<T, NU>; N],
        lower: &[[bool; NU]; N],
        upper: &[[bool; NU]; N],
    ) -> bool {
        let tol = self.settings.tol_ineq.max(self.settings.tol_stat);
        for k in 0..NC.min(N) {
            let r = &self.ru[k];
            for i in 0..NU {
                let (x, m) = (v[k][i], mu[k][i]);
                let scale = T::ONE.max(x.abs());
                let pinned = r.has_lo[i] && r.has_hi[i] && r.hi[i] <= r.lo[i];
                let ok = if lower[k][i] {
                    pinned || m >= -tol * T::ONE.max(m.abs())
                } else if upper[k][i] {
                    pinned || m <= tol * T::ONE.max(m.abs())
                } else {
                    x.finite()
                        && (!r.has_lo[i] || x >= r.lo[i] - tol * scale)
                        && (!r.has_hi[i] || x <= r.hi[i] + tol * scale)
                };
                if !ok {
                    return false;
                }
            }
        }
        true
    }

    /// Keeps `lower` / `upper` as the active set a warm start begins from.
    pub(super) fn store_active_set(&mut self, lower: &[[bool; NU]; N], upper: &[[bool; NU]; N]) {
        (self.act_lo, self.act_hi) = (*lower, *upper);
        self.act_valid = true;
    }

    /// The stored active set.
    pub(super) fn stored_active_set(&self) -> ([[bool; NU]; N], [[bool; NU]; N]) {
        (self.act_lo, self.act_hi)
    }

    /// The stored active set less the bounds the loaded QP does not have (a bound that is
    /// both takes the lower side), stored again and returned.
    pub(super) fn present_active_set(&mut self) -> ([[bool; NU]; N], [[bool; NU]; N]) {
        let (mut lower, mut upper) = self.stored_active_set();
        for (k, r) in self.ru.iter().enumerate() {
            for i in 0..NU {
                lower[k][i] &= r.has_lo[i];
                upper[k][i] &= !lower[k][i] && r.has_hi[i];
            }
        }
        self.store_active_set(&lower, &upper);
        (lower, upper)
    }

    /// The active set of an interior-point solution, by the polish's rule (the Newton step
    /// `u_i - mu_i / H_ii` along each entry crosses a bound), stored for a warm start.
    pub(super) fn active_set_of_interior_point(&mut self) {
        let (mut lower, mut upper) = ([[false; NU]; N], [[false; NU]; N]);
        for k in 0..NC.min(N) {
            let mu = self.ru[k].dual();
            for i in 0..NU {
                (lower[k][i], upper[k][i]) = self.crossed_bounds(k, i, self.sol.u[k][i], mu[i]);
            }
        }
        self.store_active_set(&lower, &upper);
    }

    /// Whether the Newton step along entry `i` of stage `k` from `v` with multiplier `mu`,
    /// `v - mu / H_ii`, falls below its lower bound or (else) passes its upper bound: the
    /// active-set rule of the polish and the warm active set.
    fn crossed_bounds(&self, k: usize, i: usize, v: T, mu: T) -> (bool, bool) {
        let r = &self.ru[k];
        let h = self.tri[k][k][(i, i)].max(T::EPSILON);
        let step = v - mu / h;
        let lo = r.has_lo[i] && step < r.lo[i];
        (lo, !lo && r.has_hi[i] && step > r.hi[i])
    }

    /// Moves the stored active set (control bounds, and the state bounds and general rows
    /// of the Riccati recursion's) one stage forward (the last stage's is repeated), as a
    /// real-time iteration that shifts its trajectory does.
    pub fn shift_active_set(&mut self) {
        for k in 1..N {
            self.act_lo[k - 1] = self.act_lo[k];
            self.act_hi[k - 1] = self.act_hi[k];
        }
        self.act_rows.shift();
    }

    /// The preparation of a warm active set: the stored set, less the bounds the QP no
    /// longer has, kept and factorized. Returns whether the factorization succeeded.
    pub(super) fn prepare_active_set(&mut self) -> bool {
        let (lower, upper) = self.present_active_set();
        self.factorize_on_active_set(&lower, &upper)
    }

    /// The solve from the warm active set that [`prepare_active_set`] factorized: the QP on
    /// that set by substitution (`1 + settings.refine` Newton steps), kept if optimal, else
    /// primal-dual active-set iterations from it. `Ok` with the solve's outcome, or `Err`
    /// with the active-set solves spent when the interior point must solve the QP (also for a
    /// non-finite `x0`, which it reports).
    ///
    /// [`prepare_active_set`]: Self::prepare_active_set
    #[inline(never)]
    pub(super) fn solve_on_warm_active_set<const NH: usize>(
        &mut self,
        qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>,
    ) -> Result<QpInfo<T>, u32> {
        if !qp.x0.iter().all(|v| v.finite()) {
            return Err(0);
        }
        let n = NC.min(N);
        self.condensed_gradient(qp);
        let (mut lower, mut upper) = self.stored_active_set();
        let mut v = [Vect::<T, NU>::zeros(); N];
        for k in 0..n {
            let r = &self.ru[k];
            for i in 0..NU {
                if lower[k][i] {
                    v[k][i] = r.lo[i];
                } else if upper[k][i] {
                    v[k][i] = r.hi[i];
                }
            }
        }
        if !self.newton_on_active_set(&lower, &upper, &mut v, 1 + self.settings.refine) {
            return Err(1);
        }
        let mut mu = [Vect::<T, NU>::zeros(); N];
        self.active_set_multipliers(&v, &mut mu);
        let mut solves = 1;
        if !self.active_set_optimal(&v, &mu, &lower, &upper) {
            solves += self
                .active_set_iterations(&mut v, &mut mu, &mut lower, &mut upper, true)
                .map_err(|n| n + 1)?;
        }
        // The residuals to the tolerances: one more refinement step where rounding left them
        // above (ill-conditioned QPs at tight tolerances), else the interior point.
        let (mut stat, mut ineq) = self.active_set_residuals(&v, &mu, &lower, &upper);
        let (tol_stat, tol_ineq) = (self.settings.tol_stat, self.settings.tol_ineq);
        if stat > tol_stat || ineq > tol_ineq {
            if !self.newton_on_active_set(&lower, &upper, &mut v, 1) {
                return Err(solves);
            }
            self.active_set_multipliers(&v, &mut mu);
            (stat, ineq) = self.active_set_residuals(&v, &mu, &lower, &upper);
            if stat > tol_stat
                || ineq > tol_ineq
                || !self.active_set_optimal(&v, &mu, &lower, &upper)
            {
                return Err(solves);
            }
        }
        // The exact solution: its slacks and multipliers for the next solve's warm start.
        for k in 0..n {
            self.ru[k].hold(&v[k], &mu[k], &lower[k], &upper[k]);
        }
        self.sol.u = v;
        self.hu = mu;
        self.store_active_set(&lower, &upper);
        self.dual_valid = true;
        self.polished = false;
        self.on_active_set = true;
        self.expand(qp);
        Ok(QpInfo {
            status: QpStatus::Solved,
            iterations: 0,
            active_set_solves: solves,
            res_stat: stat,
            res_eq: T::ZERO,
            res_ineq: ineq,
            mu: T::ZERO,
        })
    }

    /// `mu = H v + g`.
    fn active_set_multipliers(&self, v: &[Vect<T, NU>; N], mu: &mut [Vect<T, NU>; N]) {
        for (i, m) in mu.iter_mut().enumerate().take(NC.min(N)) {
            *m = self.hessian_row(i, v) + self.gu0[i];
        }
    }

    /// The stationarity residual of `v` on the sets (`mu` on the free entries, relative to
    /// the largest of `H v`, `g` and the fixed entries' multipliers when that exceeds 1, as
    /// the interior point's) and its inequality residual (the free entries' bound
    /// violations).
    fn active_set_residuals(
        &self,
        v: &[Vect<T, NU>; N],
        mu: &[Vect<T, NU>; N],
        lower: &[[bool; NU]; N],
        upper: &[[bool; NU]; N],
    ) -> (T, T) {
        let (mut stat, mut ineq, mut scale) = (T::ZERO, T::ZERO, T::ONE);
        for k in 0..NC.min(N) {
            let r = &self.ru[k];
            for i in 0..NU {
                let (x, m, g) = (v[k][i], mu[k][i], self.gu0[k][i]);
                scale = scale.max((m - g).abs()).max(g.abs());
                if lower[k][i] || upper[k][i] {
                    scale = scale.max(m.abs());
                } else {
                    stat = stat.max(m.abs());
                    if r.has_lo[i] {
                        ineq = ineq.max(r.lo[i] - x);
                    }
                    if r.has_hi[i] {
                        ineq = ineq.max(x - r.hi[i]);
                    }
                }
            }
        }
        (stat / scale, ineq)
    }

    /// Whether the last solution, from an active set, is optimal to the current settings'
    /// tolerances (its multipliers are in `hu`).
    pub(super) fn active_set_solution_optimal(&self) -> bool {
        let (lower, upper) = self.stored_active_set();
        let (stat, ineq) = self.active_set_residuals(&self.sol.u, &self.hu, &lower, &upper);
        stat <= self.settings.tol_stat
            && ineq <= self.settings.tol_ineq
            && self.active_set_optimal(&self.sol.u, &self.hu, &lower, &upper)
    }

    /// Solves `H v + g = 0` on the free entries with the fixed ones (`lower`, `upper`, already
    /// at their bounds in `v`) held: a block Cholesky factorization of `H` with the fixed rows
    /// and columns replaced by the identity, then two Newton steps (the second one is
    /// iterative refinement).
    fn solve_on_active_set(
        &mut self,
        lower: &[[bool; NU]; N],
        upper: &[[bool; NU]; N],
        v: &mut [Vect<T, NU>; N],
    ) -> bool {
        self.factorize_on_active_set(lower, upper) && self.newton_on_active_set(lower, upper, v, 2)
    }

    /// The block Cholesky factorization of `H` with the rows and columns of the fixed entries
    /// (`lower`, `upper`) replaced by the identity.
    fn factorize_on_active_set(
        &mut self,
        lower: &[[bool; NU]; N],
        upper: &[[bool; NU]; N],
    ) -> bool {
        let n = NC.min(N);
        let fixed = |k: usize, i: usize| lower[k][i] || upper[k][i];
        let mut any = [false; N];
        for (a, (l, u)) in any.iter_mut().zip(lower.iter().zip(upper)) {
            *a = l.iter().chain(u).any(|&b| b);
        }
        for i in 0..n {
            for j in 0..=i {
                let mut m = self.tri[j][i];
                // A block of two stages without a fixed entry is copied as it is (the common
                // case: no bound active).
                if any[i] || any[j] {
                    for p in 0..NU {
                        for q in 0..NU {
                            if fixed(i, p) || fixed(j, q) {
                                m[(p, q)] = if i == j && p == q { T::ONE } else { T::ZERO };
                            }
                        }
                    }
                }
                if i == j {
                    self.ld[i] = m;
                } else {
                    self.tri[i][j] = m;
                }
            }
        }
        self.block_cholesky(true)
    }

    /// `steps` Newton steps `v <- v - F^-1 r` on the free entries with the factor `F` of
    /// [`factorize_on_active_set`](Self::factorize_on_active_set) (`r = H v + g` on the free
    /// entries, zero on the fixed ones; from the second on, iterative refinement). Returns
    /// whether `v` is finite.
    fn newton_on_active_set(
        &self,
        lower: &[[bool; NU]; N],
        upper: &[[bool; NU]; N],
        v: &mut [Vect<T, NU>; N],
        steps: u32,
    ) -> bool {
        let n = NC.min(N);
        let fixed = |k: usize, i: usize| lower[k][i] || upper[k][i];
        for _ in 0..steps {
            let mut r = [Vect::<T, NU>::zeros(); N];
            for (i, ri) in r.iter_mut().enumerate().take(n) {
                let g = self.hessian_row(i, v) + self.gu0[i];
                for p in 0..NU {
                    ri[p] = if fixed(i, p) { T::ZERO } else { g[p] };
                }
            }
            self.condensed_solve(&mut r);
            for (vk, rk) in v.iter_mut().zip(&r) {
                *vk -= *rk;
            }
        }
        v.iter().all(|x| x.iter().all(|e| e.finite()))
    }

    /// States from the dynamics and dynamics multipliers from the state stationarity
    /// conditions, for the controls of the condensed solve.
    pub(super) fn expand<const NH: usize>(&mut self, qp: &OcpQp<T, NX, NU, NG, NGN, N, NH>) {
        let mut x = qp.x0;
        for k in 0..N {
            let s = &qp.stages[k];
            self.sol.x[k] = x;
            x = mul(&s.a, &x) + mul(&s.b, &self.sol.u[k]) + s.f;
        }
        self.sol.xn = x;
        let t = &qp.terminal;
        let mut pi = mul(&t.q, &x) + t.gx;
        for k in (0..N).rev() {
            self.sol.pi[k] = pi;
            if k > 0 {
                let s = &qp.stages[k];
                let h = qp.h(k);
                let (xk, uk) = (&self.sol.x[k], &self.sol.u[k]);
                pi = mul(&h.q, xk) + tr_mul(&h.s, uk) + s.gx + tr_mul(&s.a, &pi);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn condensing_pays_for_short_horizons_only() {
        // QR-bench A and B, N = 40 (NX = 10, NU = 4); the multiply-add counts by hand:
        // A 40^3 = 64,000 <= 6 * 10 * 3,200 = 192,000; B 512,000 > 384,000.
        assert!(condensing_pays(10, 4, 10));
        assert!(!condensing_pays(10, 4, 20));
        assert!(!condensing_pays(10, 4, 40));
        assert!(condensing_pays(2, 1, 5));
        assert!(!condensing_pays(10, 4, 1000));
        // No overflow panic for absurd dimensions (the products saturate).
        let _ = condensing_pays(usize::MAX, usize::MAX, usize::MAX);
    }
}
