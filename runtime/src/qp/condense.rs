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

use super::{Mat, OcpQp, QpMethod, QpSolver, Vect, condensing_pays, regularized_cholesky};
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
    /// `tri`; see [`block_cholesky`].
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

    /// `v <- (L L')^-1 v` with the factor of the last [`condensed_factorize`].
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
    /// the interior point's controls and multipliers. With `mu = H u + g` (the bounds'
    /// multipliers, `lam_l - lam_u`), an entry is fixed on its lower bound when the Newton
    /// step along it, `u_i - mu_i / H_ii`, falls below the bound, on its upper bound when it
    /// passes it, and free otherwise; the QP with the fixed entries as equalities is solved,
    /// and the sets are updated until they repeat. Returns whether the result, checked
    /// against every bound and the multipliers' signs, replaced the controls in `sol.u`.
    // Not inlined: its arrays stay out of the stack frame of a solve that does not polish.
    #[inline(never)]
    pub(super) fn condensed_polish(&mut self) -> bool {
        let n = NC.min(N);
        let mut v = self.sol.u;
        // The interior point's multipliers to start with.
        let mut mu = [Vect::<T, NU>::zeros(); N];
        for (m, r) in mu.iter_mut().zip(&self.ru) {
            *m = r.dual();
        }
        let (mut lower, mut upper) = ([[false; NU]; N], [[false; NU]; N]);
        let mut settled = false;
        for _ in 0..POLISH_ITERATIONS {
            // The active sets of this iterate.
            let mut changed = false;
            for k in 0..n {
                let r = &self.ru[k];
                for i in 0..NU {
                    let h = self.tri[k][k][(i, i)].max(T::EPSILON);
                    let step = v[k][i] - mu[k][i] / h;
                    let lo = r.has_lo[i] && step < r.lo[i];
                    let hi = !lo && r.has_hi[i] && step > r.hi[i];
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
            if !self.solve_on_active_set(&lower, &upper, &mut v) {
                return false;
            }
            settled = true;
            for (i, m) in mu.iter_mut().enumerate().take(n) {
                *m = self.hessian_row(i, &v) + self.gu0[i];
            }
        }
        // Accept if every bound holds and the fixed entries' multipliers have their signs.
        let tol = self.settings.tol_ineq.max(self.settings.tol_stat);
        for k in 0..n {
            let r = &self.ru[k];
            for i in 0..NU {
                let (x, m) = (v[k][i], mu[k][i]);
                let scale = T::ONE.max(x.abs());
                let ok = if lower[k][i] {
                    m >= -tol * T::ONE.max(m.abs())
                } else if upper[k][i] {
                    m <= tol * T::ONE.max(m.abs())
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
        self.sol.u = v;
        true
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
        let n = NC.min(N);
        let fixed = |k: usize, i: usize| lower[k][i] || upper[k][i];
        for i in 0..n {
            for j in 0..=i {
                let mut m = self.tri[j][i];
                for p in 0..NU {
                    for q in 0..NU {
                        if fixed(i, p) || fixed(j, q) {
                            m[(p, q)] = if i == j && p == q { T::ONE } else { T::ZERO };
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
        if !self.block_cholesky(true) {
            return false;
        }
        for _ in 0..2 {
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
