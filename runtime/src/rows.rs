//! Interior-point state of a set of two-sided inequality rows `lo <= v <= hi`.
//!
//! Each present side has a slack and a multiplier:
//! `t_l = v - lo >= 0`, `t_u = hi - v >= 0`, `lam_l, lam_u >= 0`, complementarity
//! `t_l lam_l = t_u lam_u = mu`. An absent side (infinite bound) takes no part in anything;
//! its multiplier and directions are 0 (its slack 1 once a solve has set it). A set of rows
//! without any present side is skipped by every method.

use nalgebra::SVector;

use crate::real::Real;

/// Which complementarity right-hand side a Newton direction uses.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Rhs<T> {
    /// Predictor: `t lam`.
    Affine,
    /// Mehrotra corrector: `t lam + w dt_aff dlam_aff - sigma mu` with target `sigma mu` and
    /// weight `w` of the second-order term.
    Corrector(T, T),
}

/// Rows of one kind at one stage.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rows<T: Real, const K: usize> {
    pub lo: SVector<T, K>,
    pub hi: SVector<T, K>,
    pub has_lo: [bool; K],
    pub has_hi: [bool; K],
    /// Some side is present (else every method below is a no-op or returns zeros, without
    /// a pass over the rows: stages without state bounds are the common case).
    any: bool,
    /// Slacks, multipliers or directions may hold values of sides present before; cleared
    /// once when no side is left (not at every solve: 16 KB written per QP on QR-bench B).
    dirty: bool,
    pub tl: SVector<T, K>,
    pub tu: SVector<T, K>,
    pub ll: SVector<T, K>,
    pub lu: SVector<T, K>,
    ri_l: SVector<T, K>,
    ri_u: SVector<T, K>,
    pub dtl: SVector<T, K>,
    pub dtu: SVector<T, K>,
    pub dll: SVector<T, K>,
    pub dlu: SVector<T, K>,
    atl: SVector<T, K>,
    atu: SVector<T, K>,
    all: SVector<T, K>,
    alu: SVector<T, K>,
}

/// Why a set of bounds cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BoundError {
    NotANumber,
    Crossed,
    /// More entries with a bound than [`SubRows`] has slots.
    TooMany,
}

impl<T: Real, const K: usize> Rows<T, K> {
    /// All zeros (no bounds): every solve sets the slacks and multipliers before using them
    /// (`init`, `warm_init`), and zero bits keep a solver in a `static` out of flash.
    pub const NEW: Self = {
        let z = crate::zeros::<T, K, 1>();
        Rows {
            lo: z,
            hi: z,
            has_lo: [false; K],
            has_hi: [false; K],
            any: false,
            dirty: false,
            tl: z,
            tu: z,
            ll: z,
            lu: z,
            ri_l: z,
            ri_u: z,
            dtl: z,
            dtu: z,
            dll: z,
            dlu: z,
            atl: z,
            atu: z,
            all: z,
            alu: z,
        }
    };

    /// Copies bounds in; `active = false` disables every row (stage 0's state bounds).
    pub fn set_bounds(
        &mut self,
        lo: &SVector<T, K>,
        hi: &SVector<T, K>,
        active: bool,
    ) -> Result<(), BoundError> {
        self.any = false;
        for i in 0..K {
            let (l, h) = (lo[i], hi[i]);
            if l.nan() || h.nan() {
                return Err(BoundError::NotANumber);
            }
            let hl = active && l > -T::INF;
            let hh = active && h < T::INF;
            if hl && hh && l > h {
                return Err(BoundError::Crossed);
            }
            self.has_lo[i] = hl;
            self.has_hi[i] = hh;
            self.any |= hl || hh;
            self.lo[i] = if hl { l } else { T::ZERO };
            self.hi[i] = if hh { h } else { T::ZERO };
        }
        Ok(())
    }

    /// Number of present sides.
    pub fn count(&self) -> usize {
        if !self.any {
            return 0;
        }
        self.has_lo
            .iter()
            .chain(&self.has_hi)
            .filter(|&&b| b)
            .count()
    }

    /// Starting slacks and multipliers for row values `v`: slack at least `floor`,
    /// multiplier `mu0 / slack`.
    pub fn init(&mut self, v: &SVector<T, K>, floor: T, mu0: T) {
        if !self.any {
            self.clear();
            return;
        }
        self.dirty = true;
        for i in 0..K {
            if self.has_lo[i] {
                self.tl[i] = (v[i] - self.lo[i]).max(floor);
                self.ll[i] = mu0 / self.tl[i];
            } else {
                self.tl[i] = T::ONE;
                self.ll[i] = T::ZERO;
            }
            if self.has_hi[i] {
                self.tu[i] = (self.hi[i] - v[i]).max(floor);
                self.lu[i] = mu0 / self.tu[i];
            } else {
                self.tu[i] = T::ONE;
                self.lu[i] = T::ZERO;
            }
        }
    }

    /// Warm start from the multipliers of the previous solve: slacks from the row values
    /// (at least `t_floor`), multipliers kept (at least `lam_floor`).
    pub fn warm_init(&mut self, v: &SVector<T, K>, t_floor: T, lam_floor: T) {
        if !self.any {
            self.clear();
            return;
        }
        self.dirty = true;
        for i in 0..K {
            if self.has_lo[i] {
                self.tl[i] = (v[i] - self.lo[i]).max(t_floor);
                self.ll[i] = self.ll[i].max(lam_floor);
            } else {
                self.tl[i] = T::ONE;
                self.ll[i] = T::ZERO;
            }
            if self.has_hi[i] {
                self.tu[i] = (self.hi[i] - v[i]).max(t_floor);
                self.lu[i] = self.lu[i].max(lam_floor);
            } else {
                self.tu[i] = T::ONE;
                self.lu[i] = T::ZERO;
            }
        }
    }

    /// The rows of an exact solution `v` on an active set, with the bounds' multipliers
    /// `mu` (`lam_l - lam_u`): slacks from `v` (zero on the held bounds), multipliers
    /// `max(mu, 0)` on the held lower bounds and `max(-mu, 0)` on the held upper ones, zero on
    /// the others (a dual warm start floors them).
    pub fn hold(
        &mut self,
        v: &SVector<T, K>,
        mu: &SVector<T, K>,
        lower: &[bool; K],
        upper: &[bool; K],
    ) {
        if !self.any {
            self.clear();
            return;
        }
        self.dirty = true;
        for i in 0..K {
            (self.tl[i], self.ll[i]) = if self.has_lo[i] {
                let lam = if lower[i] {
                    mu[i].max(T::ZERO)
                } else {
                    T::ZERO
                };
                ((v[i] - self.lo[i]).max(T::ZERO), lam)
            } else {
                (T::ONE, T::ZERO)
            };
            (self.tu[i], self.lu[i]) = if self.has_hi[i] {
                let lam = if upper[i] {
                    (-mu[i]).max(T::ZERO)
                } else {
                    T::ZERO
                };
                ((self.hi[i] - v[i]).max(T::ZERO), lam)
            } else {
                (T::ONE, T::ZERO)
            };
        }
    }

    /// [`hold`](Self::hold) with no side held: slacks from the values `v`, multipliers zero.
    pub fn hold_free(&mut self, v: &SVector<T, K>) {
        self.hold(v, &SVector::zeros(), &[false; K], &[false; K]);
    }

    /// Every side absent: slacks 1, multipliers, residuals and directions 0 (nothing to do
    /// if no side has been started since the last clear, or ever).
    fn clear(&mut self) {
        if !self.dirty {
            return;
        }
        self.dirty = false;
        let (z, one) = (SVector::<T, K>::zeros(), SVector::<T, K>::repeat(T::ONE));
        (self.tl, self.tu, self.ll, self.lu) = (one, one, z, z);
        (self.ri_l, self.ri_u) = (z, z);
        (self.dtl, self.dtu, self.dll, self.dlu) = (z, z, z, z);
    }

    /// Primal residuals `v - lo - t_l` and `hi - v - t_u` (plus the slack `s_l` / `s_u` of a
    /// soft side); returns their largest magnitude.
    #[inline]
    pub fn residuals(&mut self, v: &SVector<T, K>, soft: Option<&Soft<T, K>>) -> T {
        if !self.any {
            return T::ZERO;
        }
        match soft {
            Some(sf) if sf.any => self.residuals_soft(v, sf),
            _ => self.residuals_hard(v),
        }
    }

    fn residuals_hard(&mut self, v: &SVector<T, K>) -> T {
        let mut m = T::ZERO;
        for i in 0..K {
            self.ri_l[i] = if self.has_lo[i] {
                v[i] - self.lo[i] - self.tl[i]
            } else {
                T::ZERO
            };
            self.ri_u[i] = if self.has_hi[i] {
                self.hi[i] - v[i] - self.tu[i]
            } else {
                T::ZERO
            };
            m = m.max(self.ri_l[i].abs()).max(self.ri_u[i].abs());
        }
        m
    }

    fn residuals_soft(&mut self, v: &SVector<T, K>, sf: &Soft<T, K>) -> T {
        let mut m = T::ZERO;
        for i in 0..K {
            self.ri_l[i] = if self.has_lo[i] {
                v[i] - self.lo[i] - self.tl[i]
            } else {
                T::ZERO
            };
            self.ri_u[i] = if self.has_hi[i] {
                self.hi[i] - v[i] - self.tu[i]
            } else {
                T::ZERO
            };
            if sf.on_l[i] {
                self.ri_l[i] += sf.sl[i];
            }
            if sf.on_u[i] {
                self.ri_u[i] += sf.su[i];
            }
            m = m.max(self.ri_l[i].abs()).max(self.ri_u[i].abs());
        }
        m
    }

    /// `sum t lam` over present sides.
    pub fn complementarity(&self) -> T {
        let mut s = T::ZERO;
        if !self.any {
            return s;
        }
        for i in 0..K {
            if self.has_lo[i] {
                s += self.tl[i] * self.ll[i];
            }
            if self.has_hi[i] {
                s += self.tu[i] * self.lu[i];
            }
        }
        s
    }

    /// `lam_l - lam_u`: the rows' force in the stationarity condition (enters as `-a (..)`).
    pub fn dual(&self) -> SVector<T, K> {
        self.ll - self.lu
    }

    /// Diagonal `lam_l / t_l + lam_u / t_u` added to the Hessian along each row, capped at
    /// `Real::SIGMA_MAX` so the Riccati recursion stays finite and meaningful in the precision
    /// (a row with that much weight is pinned to its bound anyway).
    ///
    /// A soft side's slack is eliminated: its weight `sig = lam / t` becomes
    /// `sig zs / (zs + sig)` with `zs = z2 + m / s` (the series connection of the row's
    /// barrier and the slack's penalty-plus-barrier), see [`Soft`].
    pub fn sigma(&self, soft: Option<&Soft<T, K>>) -> SVector<T, K> {
        let cap = T::SIGMA_MAX;
        let mut s = SVector::<T, K>::zeros();
        if !self.any {
            return s;
        }
        match soft {
            Some(sf) if sf.any => {
                for i in 0..K {
                    if self.has_lo[i] {
                        let sig = self.ll[i] / self.tl[i];
                        s[i] += if sf.on_l[i] {
                            let (zs, frac) = sf.series_l(i, sig);
                            zs * frac
                        } else {
                            sig
                        };
                    }
                    if self.has_hi[i] {
                        let sig = self.lu[i] / self.tu[i];
                        s[i] += if sf.on_u[i] {
                            let (zs, frac) = sf.series_u(i, sig);
                            zs * frac
                        } else {
                            sig
                        };
                    }
                    s[i] = s[i].min(cap);
                }
            }
            _ => {
                for i in 0..K {
                    if self.has_lo[i] {
                        s[i] += self.ll[i] / self.tl[i];
                    }
                    if self.has_hi[i] {
                        s[i] += self.lu[i] / self.tu[i];
                    }
                    s[i] = s[i].min(cap);
                }
            }
        }
        s
    }

    fn rc(&self, rhs: Rhs<T>, i: usize) -> (T, T) {
        let (cl, cu) = (self.tl[i] * self.ll[i], self.tu[i] * self.lu[i]);
        match rhs {
            Rhs::Affine => (cl, cu),
            Rhs::Corrector(target, w) => (
                cl + w * self.atl[i] * self.all[i] - target,
                cu + w * self.atu[i] * self.alu[i] - target,
            ),
        }
    }

    /// The rows' part of the reduced gradient: `g~ += a w` with
    /// `w = -(lam_l - lam_u) + (rc_l + lam_l ri_l) / t_l - (rc_u + lam_u ri_u) / t_u`,
    /// plus, for a soft side, the eliminated slack's share `sig b / den` (lower) or
    /// `-sig b / den` (upper), see [`Soft`].
    #[inline]
    pub fn gradient(&self, rhs: Rhs<T>, soft: Option<&Soft<T, K>>) -> SVector<T, K> {
        if !self.any {
            return SVector::zeros();
        }
        match soft {
            Some(sf) if sf.any => self.gradient_soft(rhs, sf),
            _ => self.gradient_hard(rhs),
        }
    }

    fn gradient_hard(&self, rhs: Rhs<T>) -> SVector<T, K> {
        let mut w = SVector::<T, K>::zeros();
        for i in 0..K {
            let (cl, cu) = self.rc(rhs, i);
            if self.has_lo[i] {
                w[i] += -self.ll[i] + (cl + self.ll[i] * self.ri_l[i]) / self.tl[i];
            }
            if self.has_hi[i] {
                w[i] += self.lu[i] - (cu + self.lu[i] * self.ri_u[i]) / self.tu[i];
            }
        }
        w
    }

    fn gradient_soft(&self, rhs: Rhs<T>, sf: &Soft<T, K>) -> SVector<T, K> {
        let mut w = SVector::<T, K>::zeros();
        for i in 0..K {
            let (cl, cu) = self.rc(rhs, i);
            if self.has_lo[i] {
                let el = (cl + self.ll[i] * self.ri_l[i]) / self.tl[i];
                w[i] += -self.ll[i] + el;
                if sf.on_l[i] {
                    let sig = self.ll[i] / self.tl[i];
                    let (_, frac) = sf.series_l(i, sig);
                    w[i] += frac * sf.b_l(rhs, i, el);
                }
            }
            if self.has_hi[i] {
                let eu = (cu + self.lu[i] * self.ri_u[i]) / self.tu[i];
                w[i] += self.lu[i] - eu;
                if sf.on_u[i] {
                    let sig = self.lu[i] / self.tu[i];
                    let (_, frac) = sf.series_u(i, sig);
                    w[i] -= frac * sf.b_u(rhs, i, eu);
                }
            }
        }
        w
    }

    /// Slack and multiplier directions for a change `dv` of the row values (and those of the
    /// soft slacks, recovered from `dv`).
    #[inline]
    pub fn direction(&mut self, dv: &SVector<T, K>, rhs: Rhs<T>, soft: Option<&mut Soft<T, K>>) {
        if !self.any {
            return;
        }
        match soft {
            Some(sf) if sf.any => self.direction_soft(dv, rhs, sf),
            _ => self.direction_hard(dv, rhs),
        }
    }

    fn direction_hard(&mut self, dv: &SVector<T, K>, rhs: Rhs<T>) {
        for i in 0..K {
            let (cl, cu) = self.rc(rhs, i);
            if self.has_lo[i] {
                self.dtl[i] = dv[i] + self.ri_l[i];
                self.dll[i] = -(cl + self.ll[i] * self.dtl[i]) / self.tl[i];
            } else {
                self.dtl[i] = T::ZERO;
                self.dll[i] = T::ZERO;
            }
            if self.has_hi[i] {
                self.dtu[i] = -dv[i] + self.ri_u[i];
                self.dlu[i] = -(cu + self.lu[i] * self.dtu[i]) / self.tu[i];
            } else {
                self.dtu[i] = T::ZERO;
                self.dlu[i] = T::ZERO;
            }
        }
    }

    fn direction_soft(&mut self, dv: &SVector<T, K>, rhs: Rhs<T>, sf: &mut Soft<T, K>) {
        for i in 0..K {
            let (cl, cu) = self.rc(rhs, i);
            if self.has_lo[i] {
                self.dtl[i] = dv[i] + self.ri_l[i];
                if sf.on_l[i] {
                    // ds = (b - sig dv) / den, then the row slack moves with it.
                    let sig = self.ll[i] / self.tl[i];
                    let el = (cl + self.ll[i] * self.ri_l[i]) / self.tl[i];
                    let (zs, _) = sf.series_l(i, sig);
                    let ds = (sf.b_l(rhs, i, el) - sig * dv[i]) / (zs + sig);
                    sf.set_direction_l(rhs, i, ds);
                    self.dtl[i] += ds;
                }
                self.dll[i] = -(cl + self.ll[i] * self.dtl[i]) / self.tl[i];
            } else {
                self.dtl[i] = T::ZERO;
                self.dll[i] = T::ZERO;
            }
            if self.has_hi[i] {
                self.dtu[i] = -dv[i] + self.ri_u[i];
                if sf.on_u[i] {
                    let sig = self.lu[i] / self.tu[i];
                    let eu = (cu + self.lu[i] * self.ri_u[i]) / self.tu[i];
                    let (zs, _) = sf.series_u(i, sig);
                    let ds = (sf.b_u(rhs, i, eu) + sig * dv[i]) / (zs + sig);
                    sf.set_direction_u(rhs, i, ds);
                    self.dtu[i] += ds;
                }
                self.dlu[i] = -(cu + self.lu[i] * self.dtu[i]) / self.tu[i];
            } else {
                self.dtu[i] = T::ZERO;
                self.dlu[i] = T::ZERO;
            }
        }
    }

    /// Keeps the current direction as the predictor for the corrector's right-hand side.
    pub fn save_affine(&mut self) {
        self.atl = self.dtl;
        self.atu = self.dtu;
        self.all = self.dll;
        self.alu = self.dlu;
    }

    /// Largest step in `(0, alpha]` keeping every slack and multiplier nonnegative.
    pub fn max_step(&self, mut alpha: T) -> T {
        if !self.any {
            return alpha;
        }
        let pairs = [
            (&self.tl, &self.dtl, &self.has_lo),
            (&self.ll, &self.dll, &self.has_lo),
            (&self.tu, &self.dtu, &self.has_hi),
            (&self.lu, &self.dlu, &self.has_hi),
        ];
        for (v, d, has) in pairs {
            for i in 0..K {
                if has[i] && d[i] < T::ZERO {
                    alpha = alpha.min(-v[i] / d[i]);
                }
            }
        }
        alpha
    }

    /// `sum (t + alpha dt)(lam + alpha dlam)` over present sides.
    pub fn complementarity_after(&self, alpha: T) -> T {
        let mut s = T::ZERO;
        if !self.any {
            return s;
        }
        for i in 0..K {
            if self.has_lo[i] {
                s += (self.tl[i] + alpha * self.dtl[i]) * (self.ll[i] + alpha * self.dll[i]);
            }
            if self.has_hi[i] {
                s += (self.tu[i] + alpha * self.dtu[i]) * (self.lu[i] + alpha * self.dlu[i]);
            }
        }
        s
    }

    /// Takes the step.
    pub fn update(&mut self, alpha: T) {
        if !self.any {
            return;
        }
        for i in 0..K {
            if self.has_lo[i] {
                self.tl[i] += alpha * self.dtl[i];
                self.ll[i] += alpha * self.dll[i];
            }
            if self.has_hi[i] {
                self.tu[i] += alpha * self.dtu[i];
                self.lu[i] += alpha * self.dlu[i];
            }
        }
    }

    /// Largest multiplier (divergence check).
    pub fn max_multiplier(&self) -> T {
        let mut m = T::ZERO;
        for i in 0..K {
            m = m.max(self.ll[i]).max(self.lu[i]);
        }
        m
    }
}

/// Bound rows on some entries of an `NV`-vector (a stage's state, whose bounds come as
/// `NV`-vectors with infinite entries where there is none): slot `j < K` bounds entry
/// `idx[j]`. With `K = NV` slot `j` is entry `j`. With fewer slots, the entries with a
/// finite bound take the first `len` slots, in order, and the other slots have no side. The
/// [`Rows`] methods on values and directions take and give `NV`-vectors here; the others,
/// and the fields, are the slots' ([`Deref`](core::ops::Deref)).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SubRows<T: Real, const NV: usize, const K: usize> {
    rows: Rows<T, K>,
    idx: [u8; K],
    /// Slots in use (with `K < NV`, which is then at most 256).
    len: u8,
}

impl<T: Real, const NV: usize, const K: usize> core::ops::Deref for SubRows<T, NV, K> {
    type Target = Rows<T, K>;
    fn deref(&self) -> &Rows<T, K> {
        &self.rows
    }
}

impl<T: Real, const NV: usize, const K: usize> core::ops::DerefMut for SubRows<T, NV, K> {
    fn deref_mut(&mut self) -> &mut Rows<T, K> {
        &mut self.rows
    }
}

impl<T: Real, const NV: usize, const K: usize> SubRows<T, NV, K> {
    /// No bounds. `K` is at most `NV`, and an `NV` above 256 needs `K = NV` (slots are
    /// numbered in bytes); anything else fails to compile.
    pub const NEW: Self = {
        assert!(K <= NV, "NBX must not exceed NX");
        assert!(K == NV || NV <= 256, "NBX < NX needs NX <= 256");
        SubRows {
            rows: Rows::NEW,
            idx: [0; K],
            len: 0,
        }
    };

    /// Copies the bounds of the entries in; `active = false` disables every row. An entry
    /// has a row if either bound is finite.
    pub fn set_bounds(
        &mut self,
        lo: &SVector<T, NV>,
        hi: &SVector<T, NV>,
        active: bool,
    ) -> Result<(), BoundError> {
        if K == NV {
            return self
                .rows
                .set_bounds(&self.gather(lo), &self.gather(hi), active);
        }
        let mut sl = SVector::<T, K>::repeat(-T::INF);
        let mut sh = SVector::<T, K>::repeat(T::INF);
        let (mut idx, mut len) = ([0u8; K], 0usize);
        for i in 0..NV {
            let (l, h) = (lo[i], hi[i]);
            if l.nan() || h.nan() {
                return Err(BoundError::NotANumber);
            }
            if active && (l > -T::INF || h < T::INF) {
                let (Some(slot), Ok(i8)) = (idx.get_mut(len), u8::try_from(i)) else {
                    return Err(BoundError::TooMany);
                };
                *slot = i8;
                (sl[len], sh[len]) = (l, h);
                len += 1;
            }
        }
        self.rows.set_bounds(&sl, &sh, true)?;
        // `len <= K < NV <= 256` here: it fits.
        (self.idx, self.len) = (idx, u8::try_from(len).unwrap_or(u8::MAX));
        Ok(())
    }

    /// The entry of each slot in use (with `K < NV`).
    fn slots(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.idx
            .iter()
            .take(usize::from(self.len))
            .enumerate()
            .map(|(j, &i)| (j, usize::from(i)))
    }

    /// The slots' values of `v` (zero in the slots not in use).
    pub fn gather(&self, v: &SVector<T, NV>) -> SVector<T, K> {
        if K == NV {
            return SVector::from_fn(|j, _| v[j]);
        }
        let mut s = SVector::<T, K>::zeros();
        for (j, i) in self.slots() {
            s[j] = v[i];
        }
        s
    }

    /// The `NV`-vector with the slots' values `w` on their entries, zero elsewhere.
    pub fn scatter(&self, w: &SVector<T, K>) -> SVector<T, NV> {
        if K == NV {
            return SVector::from_fn(|i, _| w[i]);
        }
        let mut v = SVector::<T, NV>::zeros();
        for (j, i) in self.slots() {
            v[i] = w[j];
        }
        v
    }

    /// [`Rows::init`] for entry values `v`.
    pub fn init(&mut self, v: &SVector<T, NV>, floor: T, mu0: T) {
        let s = self.gather(v);
        self.rows.init(&s, floor, mu0);
    }

    /// [`Rows::warm_init`] for entry values `v`.
    pub fn warm_init(&mut self, v: &SVector<T, NV>, t_floor: T, lam_floor: T) {
        let s = self.gather(v);
        self.rows.warm_init(&s, t_floor, lam_floor);
    }

    /// [`Rows::hold_free`] for entry values `v`.
    pub fn hold_free(&mut self, v: &SVector<T, NV>) {
        let s = self.gather(v);
        self.rows.hold_free(&s);
    }

    /// [`Rows::residuals`] for entry values `v`.
    pub fn residuals(&mut self, v: &SVector<T, NV>) -> T {
        if !self.rows.any {
            return T::ZERO;
        }
        let s = self.gather(v);
        self.rows.residuals(&s, None)
    }

    /// [`Rows::dual`] of the slots.
    pub fn rows_dual(&self) -> SVector<T, K> {
        self.rows.dual()
    }

    /// [`Rows::dual`] on the entries.
    pub fn dual(&self) -> SVector<T, NV> {
        if !self.rows.any {
            return SVector::zeros();
        }
        self.scatter(&self.rows.dual())
    }

    /// [`Rows::sigma`] on the entries.
    pub fn sigma(&self) -> SVector<T, NV> {
        if !self.rows.any {
            return SVector::zeros();
        }
        self.scatter(&self.rows.sigma(None))
    }

    /// [`Rows::gradient`] on the entries.
    pub fn gradient(&self, rhs: Rhs<T>) -> SVector<T, NV> {
        if !self.rows.any {
            return SVector::zeros();
        }
        self.scatter(&self.rows.gradient(rhs, None))
    }

    /// [`Rows::direction`] for a change `dv` of the entries.
    pub fn direction(&mut self, dv: &SVector<T, NV>, rhs: Rhs<T>) {
        if !self.rows.any {
            return;
        }
        let s = self.gather(dv);
        self.rows.direction(&s, rhs, None);
    }
}

/// Slacks of soft rows (general constraints only), kept beside their [`Rows`].
///
/// A soft side has a slack `s >= 0` that relaxes it, `v - lo + s_l - t_l = 0` (lower) or
/// `hi - v + s_u - t_u = 0` (upper), costs `z1 s + 1/2 z2 s^2`, and has its own
/// multiplier `m >= 0` with complementarity `s m = mu` (the slack is its own interior-point
/// slack: its bound is zero). Stationarity in `s` is `r = z1 + z2 s - lam - m = 0`.
///
/// Where `z1 = 0` the bound `s >= 0` is redundant (a negative slack would tighten the row and
/// cost more), and it is left out: the slack is free, `m = 0`, and there is no
/// complementarity pair. Kept, it would be weakly active (`s = m = 0`) at every satisfied
/// side and pin the slack only to `sqrt(mu / z2)`; free, `s = lam / z2` exactly.
///
/// Each slack appears only in its side's two inequalities, so its Newton equations are
/// eliminated row by row. For the lower side, with `sig = lam / t`, `e = (rc + lam ri) / t`
/// (the hard row's terms) and `zs = z2 + m / s`:
///
/// ```text
/// ds = (b - sig dv) / (zs + sig),  b = -r - e - rc_s / s
/// ```
///
/// (upper side: `ds = (b + sig dv) / (zs + sig)`; a free slack has `zs = z2` and no `rc_s`). Substituted back, the row keeps its form
/// in the Riccati recursion with the weight `sig zs / (zs + sig)` instead of `sig` and the
/// extra gradient `sig b / (zs + sig)` (upper: its negative), as in HPIPM.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Soft<T: Real, const K: usize> {
    /// Some side is soft (otherwise every method is a no-op and [`Rows`] runs its hard path).
    pub any: bool,
    pub on_l: [bool; K],
    pub on_u: [bool; K],
    /// The side's slack is bounded (`s >= 0` with multiplier `m`): `z1 > 0`.
    bd_l: [bool; K],
    bd_u: [bool; K],
    pub z1: SVector<T, K>,
    pub z2: SVector<T, K>,
    pub sl: SVector<T, K>,
    pub su: SVector<T, K>,
    pub ml: SVector<T, K>,
    pub mu: SVector<T, K>,
    rl: SVector<T, K>,
    ru: SVector<T, K>,
    dsl: SVector<T, K>,
    dsu: SVector<T, K>,
    dml: SVector<T, K>,
    dmu: SVector<T, K>,
    asl: SVector<T, K>,
    asu: SVector<T, K>,
    aml: SVector<T, K>,
    amu: SVector<T, K>,
}

impl<T: Real, const K: usize> Soft<T, K> {
    pub const NEW: Self = {
        let z = crate::zeros::<T, K, 1>();
        Soft {
            any: false,
            on_l: [false; K],
            on_u: [false; K],
            bd_l: [false; K],
            bd_u: [false; K],
            z1: z,
            z2: z,
            sl: z,
            su: z,
            ml: z,
            mu: z,
            rl: z,
            ru: z,
            dsl: z,
            dsu: z,
            dml: z,
            dmu: z,
            asl: z,
            asu: z,
            aml: z,
            amu: z,
        }
    };

    /// Takes the penalties (validated by the caller: finite, nonnegative); a row is soft where
    /// either is positive, and each of its present sides gets a slack.
    #[inline]
    pub fn load(&mut self, l1: &SVector<T, K>, l2: &SVector<T, K>, rows: &Rows<T, K>) {
        self.any = false;
        for i in 0..K {
            let soft = l1[i] > T::ZERO || l2[i] > T::ZERO;
            self.on_l[i] = soft && rows.has_lo[i];
            self.on_u[i] = soft && rows.has_hi[i];
            self.any |= self.on_l[i] || self.on_u[i];
            self.bd_l[i] = self.on_l[i] && l1[i] > T::ZERO;
            self.bd_u[i] = self.on_u[i] && l1[i] > T::ZERO;
            self.z1[i] = if soft { l1[i] } else { T::ZERO };
            self.z2[i] = if soft { l2[i] } else { T::ZERO };
            if !self.on_l[i] {
                self.sl[i] = T::ZERO;
            }
            if !self.bd_l[i] {
                self.ml[i] = T::ZERO;
                self.dml[i] = T::ZERO;
            }
            if !self.on_u[i] {
                self.su[i] = T::ZERO;
            }
            if !self.bd_u[i] {
                self.mu[i] = T::ZERO;
                self.dmu[i] = T::ZERO;
            }
        }
    }

    /// Number of bounded soft slacks (each adds one complementarity pair).
    #[inline]
    pub fn count(&self) -> usize {
        self.bd_l.iter().chain(&self.bd_u).filter(|&&b| b).count()
    }

    /// `(zs, sig / (zs + sig))` of the lower side of row `i`: `zs = z2 + m / s` (`z2` for a
    /// free slack).
    #[inline]
    pub fn series_l(&self, i: usize, sig: T) -> (T, T) {
        let zs = if self.bd_l[i] {
            self.z2[i] + self.ml[i] / self.sl[i]
        } else {
            self.z2[i]
        };
        (zs, sig / (zs + sig))
    }

    /// [`series_l`](Self::series_l) of the upper side.
    #[inline]
    pub fn series_u(&self, i: usize, sig: T) -> (T, T) {
        let zs = if self.bd_u[i] {
            self.z2[i] + self.mu[i] / self.su[i]
        } else {
            self.z2[i]
        };
        (zs, sig / (zs + sig))
    }

    fn rc(rhs: Rhs<T>, s: T, m: T, a_s: T, a_m: T) -> T {
        match rhs {
            Rhs::Affine => s * m,
            Rhs::Corrector(target, w) => s * m + w * a_s * a_m - target,
        }
    }

    /// `b = -r - e - rc_s / s` of the lower side of row `i` (`-r - e` for a free slack), `e`
    /// being the row's own term.
    #[inline]
    pub fn b_l(&self, rhs: Rhs<T>, i: usize, e: T) -> T {
        if self.bd_l[i] {
            let c = Self::rc(rhs, self.sl[i], self.ml[i], self.asl[i], self.aml[i]);
            -self.rl[i] - e - c / self.sl[i]
        } else {
            -self.rl[i] - e
        }
    }

    /// [`b_l`](Self::b_l) of the upper side.
    #[inline]
    pub fn b_u(&self, rhs: Rhs<T>, i: usize, e: T) -> T {
        if self.bd_u[i] {
            let c = Self::rc(rhs, self.su[i], self.mu[i], self.asu[i], self.amu[i]);
            -self.ru[i] - e - c / self.su[i]
        } else {
            -self.ru[i] - e
        }
    }

    /// Sets the lower slack's direction and its multiplier's.
    #[inline]
    pub fn set_direction_l(&mut self, rhs: Rhs<T>, i: usize, ds: T) {
        self.dsl[i] = ds;
        if self.bd_l[i] {
            let c = Self::rc(rhs, self.sl[i], self.ml[i], self.asl[i], self.aml[i]);
            self.dml[i] = -(c + self.ml[i] * ds) / self.sl[i];
        }
    }

    /// Sets the upper slack's direction and its multiplier's.
    #[inline]
    pub fn set_direction_u(&mut self, rhs: Rhs<T>, i: usize, ds: T) {
        self.dsu[i] = ds;
        if self.bd_u[i] {
            let c = Self::rc(rhs, self.su[i], self.mu[i], self.asu[i], self.amu[i]);
            self.dmu[i] = -(c + self.mu[i] * ds) / self.su[i];
        }
    }

    /// Starting slack of a side with row value `v`, bound `lo` (for the upper side pass
    /// `-v`, `-hi`): it covers the violation, `s = max(floor, lo - v + floor)` (bounded) or
    /// `max(0, lo - v + floor)` (free), so the row slack `t = v - lo + s` is at least `floor`.
    fn start(bounded: bool, v: T, lo: T, floor: T) -> T {
        let cover = lo - v + floor;
        if bounded {
            floor.max(cover)
        } else {
            cover.max(T::ZERO)
        }
    }

    /// Cold start after [`Rows::init`]: slacks from [`start`](Self::start), row slacks
    /// `t = v - lo + s` (at least `floor`), multipliers `mu0 / slack`.
    #[inline]
    pub fn init(&mut self, rows: &mut Rows<T, K>, v: &SVector<T, K>, floor: T, mu0: T) {
        if K == 0 || !self.any {
            return;
        }
        for i in 0..K {
            if self.on_l[i] {
                self.sl[i] = Self::start(self.bd_l[i], v[i], rows.lo[i], floor);
                rows.tl[i] = (v[i] - rows.lo[i] + self.sl[i]).max(floor);
                rows.ll[i] = mu0 / rows.tl[i];
                if self.bd_l[i] {
                    self.ml[i] = mu0 / self.sl[i];
                }
            }
            if self.on_u[i] {
                self.su[i] = Self::start(self.bd_u[i], -v[i], -rows.hi[i], floor);
                rows.tu[i] = (rows.hi[i] - v[i] + self.su[i]).max(floor);
                rows.lu[i] = mu0 / rows.tu[i];
                if self.bd_u[i] {
                    self.mu[i] = mu0 / self.su[i];
                }
            }
        }
    }

    /// Warm start after [`Rows::warm_init`]: slacks as in [`init`](Self::init) with
    /// `t_floor`, multipliers kept (at least `lam_floor`).
    #[inline]
    pub fn warm_init(
        &mut self,
        rows: &mut Rows<T, K>,
        v: &SVector<T, K>,
        t_floor: T,
        lam_floor: T,
    ) {
        if K == 0 || !self.any {
            return;
        }
        for i in 0..K {
            if self.on_l[i] {
                self.sl[i] = Self::start(self.bd_l[i], v[i], rows.lo[i], t_floor);
                rows.tl[i] = (v[i] - rows.lo[i] + self.sl[i]).max(t_floor);
                if self.bd_l[i] {
                    self.ml[i] = self.ml[i].max(lam_floor);
                }
            }
            if self.on_u[i] {
                self.su[i] = Self::start(self.bd_u[i], -v[i], -rows.hi[i], t_floor);
                rows.tu[i] = (rows.hi[i] - v[i] + self.su[i]).max(t_floor);
                if self.bd_u[i] {
                    self.mu[i] = self.mu[i].max(lam_floor);
                }
            }
        }
    }

    /// The slacks of an exact solution on a warm active set, after [`Rows::hold`] set the
    /// rows at the values `v`: a violated side (`over_l` / `over_u`) takes the violation as
    /// its slack and multiplier zero; any other side slack zero and the multiplier
    /// `max(l1 - lam, 0)`. A held side whose force passed `l1`, or a violated one whose
    /// force is below it, shows in the slacks' stationarity (`residuals`).
    pub fn hold(
        &mut self,
        rows: &Rows<T, K>,
        v: &SVector<T, K>,
        over_l: &[bool; K],
        over_u: &[bool; K],
    ) {
        if !self.any {
            return;
        }
        for i in 0..K {
            if self.on_l[i] {
                self.sl[i] = if over_l[i] {
                    (rows.lo[i] - v[i]).max(T::ZERO)
                } else {
                    T::ZERO
                };
                self.ml[i] = if self.bd_l[i] {
                    (self.z1[i] - rows.ll[i]).max(T::ZERO)
                } else {
                    T::ZERO
                };
            }
            if self.on_u[i] {
                self.su[i] = if over_u[i] {
                    (v[i] - rows.hi[i]).max(T::ZERO)
                } else {
                    T::ZERO
                };
                self.mu[i] = if self.bd_u[i] {
                    (self.z1[i] - rows.lu[i]).max(T::ZERO)
                } else {
                    T::ZERO
                };
            }
        }
    }

    /// Stationarity in the slacks, `z1 + z2 s - lam - m`, with the rows' multipliers; returns
    /// its largest magnitude and the largest of its terms.
    #[inline]
    pub fn residuals(&mut self, rows: &Rows<T, K>) -> (T, T) {
        let (mut r, mut scale) = (T::ZERO, T::ZERO);
        if K == 0 || !self.any {
            return (r, scale);
        }
        for i in 0..K {
            if self.on_l[i] {
                let q = self.z2[i] * self.sl[i];
                self.rl[i] = self.z1[i] + q - rows.ll[i] - self.ml[i];
                r = r.max(self.rl[i].abs());
                scale = scale.max(self.z1[i]).max(q).max(rows.ll[i]).max(self.ml[i]);
            }
            if self.on_u[i] {
                let q = self.z2[i] * self.su[i];
                self.ru[i] = self.z1[i] + q - rows.lu[i] - self.mu[i];
                r = r.max(self.ru[i].abs());
                scale = scale.max(self.z1[i]).max(q).max(rows.lu[i]).max(self.mu[i]);
            }
        }
        (r, scale)
    }

    /// `sum s m` over bounded soft slacks.
    #[inline]
    pub fn complementarity(&self) -> T {
        self.complementarity_after(T::ZERO)
    }

    /// `sum (s + alpha ds)(m + alpha dm)` over bounded soft slacks.
    #[inline]
    pub fn complementarity_after(&self, alpha: T) -> T {
        let mut c = T::ZERO;
        if K == 0 || !self.any {
            return c;
        }
        for i in 0..K {
            if self.bd_l[i] {
                c += (self.sl[i] + alpha * self.dsl[i]) * (self.ml[i] + alpha * self.dml[i]);
            }
            if self.bd_u[i] {
                c += (self.su[i] + alpha * self.dsu[i]) * (self.mu[i] + alpha * self.dmu[i]);
            }
        }
        c
    }

    /// Largest step in `(0, alpha]` keeping every bounded soft slack and its multiplier
    /// nonnegative.
    #[inline]
    pub fn max_step(&self, mut alpha: T) -> T {
        if K == 0 || !self.any {
            return alpha;
        }
        let pairs = [
            (&self.sl, &self.dsl, &self.bd_l),
            (&self.ml, &self.dml, &self.bd_l),
            (&self.su, &self.dsu, &self.bd_u),
            (&self.mu, &self.dmu, &self.bd_u),
        ];
        for (v, d, on) in pairs {
            for i in 0..K {
                if on[i] && d[i] < T::ZERO {
                    alpha = alpha.min(-v[i] / d[i]);
                }
            }
        }
        alpha
    }

    /// Keeps the current direction as the predictor.
    #[inline]
    pub fn save_affine(&mut self) {
        if K == 0 || !self.any {
            return;
        }
        self.asl = self.dsl;
        self.asu = self.dsu;
        self.aml = self.dml;
        self.amu = self.dmu;
    }

    /// Takes the step.
    #[inline]
    pub fn update(&mut self, alpha: T) {
        if K == 0 || !self.any {
            return;
        }
        for i in 0..K {
            if self.on_l[i] {
                self.sl[i] += alpha * self.dsl[i];
                self.ml[i] += alpha * self.dml[i];
            }
            if self.on_u[i] {
                self.su[i] += alpha * self.dsu[i];
                self.mu[i] += alpha * self.dmu[i];
            }
        }
    }

    /// Largest slack multiplier (divergence check).
    #[inline]
    pub fn max_multiplier(&self) -> T {
        let mut m = T::ZERO;
        if K == 0 || !self.any {
            return m;
        }
        for i in 0..K {
            m = m.max(self.ml[i]).max(self.mu[i]);
        }
        m
    }
}
