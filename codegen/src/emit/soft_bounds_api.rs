//! The `Solver` methods of a model with soft bounds (`soft_bounds.rs` has the constants and
//! helpers): the bounds' setters and getters in place of `setters::bounds_api`'s, the
//! general rows' penalties over the model's own rows, and the soft bounds' penalties.

use proc_macro2::TokenStream;
use quote::quote;

use super::Emitter;

impl Emitter<'_> {
    /// The bounds API: `setters::bounds_api` without soft bounds.
    pub(super) fn bounds_api(&self) -> TokenStream {
        if !self.has_soft_bounds() {
            return super::setters::bounds_api();
        }
        let (u, x, g) = (
            soft_control_bounds(),
            soft_state_bounds(),
            model_row_bounds(),
        );
        quote!(#u #x #g)
    }

    /// The general rows' penalties (`run_time::soft_penalty_api` without soft bounds), and
    /// with soft bounds those of the soft bounds too.
    pub(super) fn penalty_api(&self) -> TokenStream {
        if !self.has_soft_bounds() {
            return self.soft_penalty_api();
        }
        let (rows, bounds) = (model_row_penalties(), bound_penalties());
        quote!(#rows #bounds)
    }
}

/// `control_bound_multipliers` and `state_bound_multipliers` with soft entries: a soft
/// entry's is its row's (`lam_u - lam_l`, the sign convention of the box bounds'), the box
/// bound's being zero.
pub(super) fn soft_bound_multipliers() -> TokenStream {
    quote! {
        /// The control bounds' multipliers of stage `k < N` in the last QP
        /// (`mu_u - mu_l`: positive on an upper bound, negative on a lower one; a soft
        /// bound's is its row's, `l1 + l2 s` where it is violated by `s`).
        pub fn control_bound_multipliers(&self, k: usize) -> Option<[Real; NU]> {
            let rows = self.rti.constraint_multipliers(k)?;
            let v = self.rti.control_bound_multipliers(k)?;
            Some(with_soft_rows(&v, &rows, NG, &SOFT_CONTROL_BOUNDS))
        }

        /// The model-state bounds' multipliers of stage `1 <= k <= N` in the last QP
        /// (signs as [`control_bound_multipliers`](Self::control_bound_multipliers); a soft
        /// bound's is its row's).
        pub fn state_bound_multipliers(&self, k: usize) -> Option<[Real; NX_MODEL]> {
            let v = self.rti.state_bound_multipliers(k)?;
            Some(if k < N {
                let rows = self.rti.constraint_multipliers(k)?;
                with_soft_rows(&v, &rows, NG + NSBU, &SOFT_STATE_BOUNDS)
            } else {
                let rows = self.rti.terminal_constraint_multipliers();
                with_soft_rows(&v, &rows, NGN, &SOFT_STATE_BOUNDS)
            })
        }
    }
}

/// `set_control_bounds` and `control_bounds` with soft entries: the soft entries' bounds
/// live in their rows (`NG..NG + NSBU`). The rows are set first and put back if the box
/// bounds are refused, so a refused call changes nothing.
fn soft_control_bounds() -> TokenStream {
    quote! {
        /// Sets the control bounds `lb <= u_k <= ub` of every stage `k < N`; the soft ones
        /// ([`SOFT_CONTROL_BOUNDS`]) keep their penalties.
        ///
        /// # Errors
        /// [`SetError::NonFinite`] (NaN, a lower bound `+inf`, an upper `-inf`),
        /// [`SetError::CrossedBounds`]; nothing changes then.
        pub fn set_control_bounds(&mut self, lb: &[Real; NU], ub: &[Real; NU]) -> Result<(), SetError> {
            let (lbx, ubx, _, _) = self.rti.bounds();
            let (lbx, ubx) = (*lbx, *ubx);
            let lbu = SVector::from(hard_entries(lb, &SOFT_CONTROL_BOUNDS, Real::NEG_INFINITY));
            let ubu = SVector::from(hard_entries(ub, &SOFT_CONTROL_BOUNDS, Real::INFINITY));
            let (lg, ug, lgn, ugn) = self.rti.constraint_bounds();
            let (lg, ug, lgn, ugn) = (*lg, *ug, *lgn, *ugn);
            self.rti.set_constraint_bounds(
                &soft_rows(&lg, NG, lb, &SOFT_CONTROL_BOUNDS),
                &soft_rows(&ug, NG, ub, &SOFT_CONTROL_BOUNDS),
                &lgn,
                &ugn,
            )?;
            let r = self.rti.set_bounds(&lbx, &ubx, &lbu, &ubu);
            if r.is_err() {
                let _ = self.rti.set_constraint_bounds(&lg, &ug, &lgn, &ugn);
            }
            r
        }

        /// The control bounds in use, `(lb, ub)` (infinite where unbounded; a soft entry's
        /// from its row).
        pub fn control_bounds(&self) -> ([Real; NU], [Real; NU]) {
            let (_, _, lbu, ubu) = self.rti.bounds();
            let (lg, ug, _, _) = self.rti.constraint_bounds();
            (
                with_soft_rows(lbu, lg, NG, &SOFT_CONTROL_BOUNDS),
                with_soft_rows(ubu, ug, NG, &SOFT_CONTROL_BOUNDS),
            )
        }
    }
}

/// `set_state_bounds` and `state_bounds` with soft entries: their bounds live in the stage
/// rows `NG + NSBU..` and the terminal rows `NGN..`.
fn soft_state_bounds() -> TokenStream {
    quote! {
        /// Sets the bounds `lb <= x_k <= ub` of the model states at stages `1..=N` (the
        /// measured `x_0` is not bounded); the soft ones ([`SOFT_STATE_BOUNDS`]) keep their
        /// penalties, and the states an input-rate cost appends keep their bounds.
        ///
        /// # Errors
        /// [`SetError::NonFinite`], [`SetError::CrossedBounds`];
        /// [`SetError::TooManyStateBounds`] if more hard state bounds would have a finite
        /// side than the solver has state-bound rows, [`NBX`]; nothing changes then.
        pub fn set_state_bounds(&mut self, lb: &[Real; NX_MODEL], ub: &[Real; NX_MODEL]) -> Result<(), SetError> {
            let (lbx, ubx, lbu, ubu) = self.rti.bounds();
            let model = |new: &[Real; NX_MODEL], old: &SVector<Real, NX>, fill: Real| {
                let hard = hard_entries(new, &SOFT_STATE_BOUNDS, fill);
                SVector::<Real, NX>::from_fn(|i, _| hard.get(i).copied().unwrap_or(old[i]))
            };
            let (lbx, ubx) = (model(lb, lbx, Real::NEG_INFINITY), model(ub, ubx, Real::INFINITY));
            let (lbu, ubu) = (*lbu, *ubu);
            let (lg, ug, lgn, ugn) = self.rti.constraint_bounds();
            let (lg, ug, lgn, ugn) = (*lg, *ug, *lgn, *ugn);
            self.rti.set_constraint_bounds(
                &soft_rows(&lg, NG + NSBU, lb, &SOFT_STATE_BOUNDS),
                &soft_rows(&ug, NG + NSBU, ub, &SOFT_STATE_BOUNDS),
                &soft_rows(&lgn, NGN, lb, &SOFT_STATE_BOUNDS),
                &soft_rows(&ugn, NGN, ub, &SOFT_STATE_BOUNDS),
            )?;
            let r = self.rti.set_bounds(&lbx, &ubx, &lbu, &ubu);
            if r.is_err() {
                let _ = self.rti.set_constraint_bounds(&lg, &ug, &lgn, &ugn);
            }
            r
        }

        /// The model-state bounds in use, `(lb, ub)` (infinite where unbounded; a soft
        /// entry's from its rows).
        pub fn state_bounds(&self) -> ([Real; NX_MODEL], [Real; NX_MODEL]) {
            let (lbx, ubx, _, _) = self.rti.bounds();
            let (lg, ug, _, _) = self.rti.constraint_bounds();
            (
                with_soft_rows(lbx, lg, NG + NSBU, &SOFT_STATE_BOUNDS),
                with_soft_rows(ubx, ug, NG + NSBU, &SOFT_STATE_BOUNDS),
            )
        }
    }
}

/// `set_constraint_bounds`, `constraint_bounds` and the terminal pair over the model's own
/// rows (the soft bounds' rows keep theirs).
fn model_row_bounds() -> TokenStream {
    quote! {
        /// Sets the bounds `lg <= h(x_k, u_k, p_k) <= ug` of the model's general constraints
        /// at every stage `k < N` (soft rows keep their penalties; the soft bounds' rows are
        /// set by [`set_state_bounds`](Self::set_state_bounds) and
        /// [`set_control_bounds`](Self::set_control_bounds)). It applies from the next
        /// [`prepare`](Self::prepare) or [`solve_sqp`](Self::solve_sqp).
        ///
        /// # Errors
        /// [`SetError::NonFinite`], [`SetError::CrossedBounds`]; nothing changes then.
        pub fn set_constraint_bounds(&mut self, lg: &[Real; NG], ug: &[Real; NG]) -> Result<(), SetError> {
            let (lg0, ug0, lgn, ugn) = self.rti.constraint_bounds();
            let (lg0, ug0, lgn, ugn) = (put_rows(lg0, 0, lg), put_rows(ug0, 0, ug), *lgn, *ugn);
            self.rti.set_constraint_bounds(&lg0, &ug0, &lgn, &ugn)
        }

        /// The model's stage constraint bounds in use, `(lg, ug)`.
        pub fn constraint_bounds(&self) -> ([Real; NG], [Real; NG]) {
            let (lg, ug, _, _) = self.rti.constraint_bounds();
            (take_rows(lg, 0), take_rows(ug, 0))
        }

        /// Sets the bounds `lgn <= h_N(x_N, p_N) <= ugn` of the model's terminal
        /// constraints (soft rows keep their penalties).
        ///
        /// # Errors
        /// [`SetError::NonFinite`], [`SetError::CrossedBounds`]; nothing changes then.
        pub fn set_terminal_constraint_bounds(&mut self, lgn: &[Real; NGN], ugn: &[Real; NGN]) -> Result<(), SetError> {
            let (lg, ug, lgn0, ugn0) = self.rti.constraint_bounds();
            let (lg, ug, lgn0, ugn0) = (*lg, *ug, put_rows(lgn0, 0, lgn), put_rows(ugn0, 0, ugn));
            self.rti.set_constraint_bounds(&lg, &ug, &lgn0, &ugn0)
        }

        /// The model's terminal constraint bounds in use, `(lgn, ugn)`.
        pub fn terminal_constraint_bounds(&self) -> ([Real; NGN], [Real; NGN]) {
            let (_, _, lgn, ugn) = self.rti.constraint_bounds();
            (take_rows(lgn, 0), take_rows(ugn, 0))
        }
    }
}

/// `set_soft_penalties`, `soft_penalties` and the terminal pair over the model's own rows.
fn model_row_penalties() -> TokenStream {
    quote! {
        /// Sets the slack penalties of the model's general constraints at every stage
        /// `k < N`: row `i` costs `l1[i] (sl + su) + 1/2 l2[i] (sl^2 + su^2)` for the slacks
        /// that relax it; both zero makes it hard. The soft bounds keep theirs
        /// ([`set_state_bound_penalties`](Self::set_state_bound_penalties)). Applies from
        /// the next [`prepare`](Self::prepare).
        ///
        /// # Errors
        /// [`SetError::NonFinite`], [`SetError::NegativePenalty`]; nothing changes then.
        pub fn set_soft_penalties(&mut self, l1: &[Real; NG], l2: &[Real; NG]) -> Result<(), SetError> {
            let (a, b, an, bn) = self.rti.soft_penalties();
            let (a, b, an, bn) = (put_rows(a, 0, l1), put_rows(b, 0, l2), *an, *bn);
            self.rti.set_soft_penalties(&a, &b, &an, &bn)
        }

        /// The model's stage rows' slack penalties in use, `(l1, l2)`.
        pub fn soft_penalties(&self) -> ([Real; NG], [Real; NG]) {
            let (l1, l2, _, _) = self.rti.soft_penalties();
            (take_rows(l1, 0), take_rows(l2, 0))
        }

        /// Sets the slack penalties of the model's terminal constraints, as
        /// [`set_soft_penalties`](Self::set_soft_penalties).
        ///
        /// # Errors
        /// [`SetError::NonFinite`], [`SetError::NegativePenalty`]; nothing changes then.
        pub fn set_terminal_soft_penalties(&mut self, l1n: &[Real; NGN], l2n: &[Real; NGN]) -> Result<(), SetError> {
            let (a, b, an, bn) = self.rti.soft_penalties();
            let (a, b, an, bn) = (*a, *b, put_rows(an, 0, l1n), put_rows(bn, 0, l2n));
            self.rti.set_soft_penalties(&a, &b, &an, &bn)
        }

        /// The model's terminal rows' slack penalties in use, `(l1n, l2n)`.
        pub fn terminal_soft_penalties(&self) -> ([Real; NGN], [Real; NGN]) {
            let (_, _, l1n, l2n) = self.rti.soft_penalties();
            (take_rows(l1n, 0), take_rows(l2n, 0))
        }
    }
}

/// The soft bounds' penalties: `set_control_bound_penalties`, `control_bound_penalties`,
/// `set_state_bound_penalties` (stage and terminal rows together), `state_bound_penalties`.
fn bound_penalties() -> TokenStream {
    quote! {
        /// Sets the penalties of the soft control bounds: entry `i` is control
        /// [`SOFT_CONTROL_BOUNDS`]`[i]`, whose violation `s` of either side costs
        /// `l1[i] s + 1/2 l2[i] s^2` at every stage `k < N`. Applies from the next
        /// [`prepare`](Self::prepare).
        ///
        /// # Errors
        /// [`SetError::NonFinite`], [`SetError::NegativePenalty`], and
        /// [`SetError::InvalidSetting`] for an entry with both penalties zero (a soft bound
        /// stays soft); nothing changes then.
        pub fn set_control_bound_penalties(&mut self, l1: &[Real; NSBU], l2: &[Real; NSBU]) -> Result<(), SetError> {
            some_penalty(l1, l2)?;
            let (a, b, an, bn) = self.rti.soft_penalties();
            let (a, b, an, bn) = (put_rows(a, NG, l1), put_rows(b, NG, l2), *an, *bn);
            self.rti.set_soft_penalties(&a, &b, &an, &bn)
        }

        /// The soft control bounds' penalties in use, `(l1, l2)`, in the order of
        /// [`SOFT_CONTROL_BOUNDS`].
        pub fn control_bound_penalties(&self) -> ([Real; NSBU], [Real; NSBU]) {
            let (l1, l2, _, _) = self.rti.soft_penalties();
            (take_rows(l1, NG), take_rows(l2, NG))
        }

        /// Sets the penalties of the soft state bounds: entry `i` is state
        /// [`SOFT_STATE_BOUNDS`]`[i]`, whose violation `s` costs `l1[i] s + 1/2 l2[i] s^2` at
        /// every stage `1..=N` (at stage 0 the measured state's violation is a constant of
        /// the objective). Applies from the next [`prepare`](Self::prepare).
        ///
        /// # Errors
        /// As [`set_control_bound_penalties`](Self::set_control_bound_penalties).
        pub fn set_state_bound_penalties(&mut self, l1: &[Real; NSBX], l2: &[Real; NSBX]) -> Result<(), SetError> {
            some_penalty(l1, l2)?;
            let (a, b, an, bn) = self.rti.soft_penalties();
            let (a, b) = (put_rows(a, NG + NSBU, l1), put_rows(b, NG + NSBU, l2));
            let (an, bn) = (put_rows(an, NGN, l1), put_rows(bn, NGN, l2));
            self.rti.set_soft_penalties(&a, &b, &an, &bn)
        }

        /// The soft state bounds' penalties in use, `(l1, l2)`, in the order of
        /// [`SOFT_STATE_BOUNDS`].
        pub fn state_bound_penalties(&self) -> ([Real; NSBX], [Real; NSBX]) {
            let (l1, l2, _, _) = self.rti.soft_penalties();
            (take_rows(l1, NG + NSBU), take_rows(l2, NG + NSBU))
        }
    }
}
