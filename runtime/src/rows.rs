//! Interior-point state of a set of two-sided inequality rows `lo <= v <= hi`.
//!
//! Each present side has a slack and a multiplier:
//! `t_l = v - lo >= 0`, `t_u = hi - v >= 0`, `lam_l, lam_u >= 0`, complementarity
//! `t_l lam_l = t_u lam_u = mu`. An absent side (infinite bound) keeps `t = 1`, `lam = 0` and
//! takes no part in anything.

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
}

impl<T: Real, const K: usize> Rows<T, K> {
    pub const NEW: Self = {
        let z = crate::zeros::<T, K, 1>();
        let one = crate::filled::<T, K, 1>(T::ONE);
        Rows {
            lo: z,
            hi: z,
            has_lo: [false; K],
            has_hi: [false; K],
            tl: one,
            tu: one,
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
            self.lo[i] = if hl { l } else { T::ZERO };
            self.hi[i] = if hh { h } else { T::ZERO };
        }
        Ok(())
    }

    /// Number of present sides.
    pub fn count(&self) -> usize {
        self.has_lo
            .iter()
            .chain(&self.has_hi)
            .filter(|&&b| b)
            .count()
    }

    /// Starting slacks and multipliers for row values `v`: slack at least `floor`,
    /// multiplier `mu0 / slack`.
    pub fn init(&mut self, v: &SVector<T, K>, floor: T, mu0: T) {
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

    /// Primal residuals `v - lo - t_l` and `hi - v - t_u`; returns their largest magnitude.
    pub fn residuals(&mut self, v: &SVector<T, K>) -> T {
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

    /// `sum t lam` over present sides.
    pub fn complementarity(&self) -> T {
        let mut s = T::ZERO;
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
    pub fn sigma(&self) -> SVector<T, K> {
        let cap = T::SIGMA_MAX;
        let mut s = SVector::<T, K>::zeros();
        for i in 0..K {
            if self.has_lo[i] {
                s[i] += self.ll[i] / self.tl[i];
            }
            if self.has_hi[i] {
                s[i] += self.lu[i] / self.tu[i];
            }
            s[i] = s[i].min(cap);
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
    /// `w = -(lam_l - lam_u) + (rc_l + lam_l ri_l) / t_l - (rc_u + lam_u ri_u) / t_u`.
    pub fn gradient(&self, rhs: Rhs<T>) -> SVector<T, K> {
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

    /// Slack and multiplier directions for a change `dv` of the row values.
    pub fn direction(&mut self, dv: &SVector<T, K>, rhs: Rhs<T>) {
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

    /// Keeps the current direction as the predictor for the corrector's right-hand side.
    pub fn save_affine(&mut self) {
        self.atl = self.dtl;
        self.atu = self.dtu;
        self.all = self.dll;
        self.alu = self.dlu;
    }

    /// Largest step in `(0, alpha]` keeping every slack and multiplier nonnegative.
    pub fn max_step(&self, mut alpha: T) -> T {
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
