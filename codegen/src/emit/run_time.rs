//! The `Solver`'s run-time API beyond a control step: validated settings, per-stage warm
//! starts, the soft rows' penalties, the read-outs (cost, KKT residual, slacks, multipliers,
//! the whole predicted trajectory) and construction in place. Each method checks its input
//! and changes nothing when it refuses it; the runtime's `Rti` does the work.

use proc_macro2::TokenStream;
use quote::quote;

use super::{Emitter, ul};

impl Emitter<'_> {
    /// `set_settings`: the settings, checked (`settings_mut` writes them unchecked).
    pub(super) fn settings_setter(&self) -> TokenStream {
        quote! {
            /// Replaces the settings after checking them ([`RtiSettings::validate`]: finite,
            /// non-negative tolerances, iteration limits and `fallback_limit` at least 1).
            /// [`settings_mut`](Self::settings_mut) writes them without a check.
            ///
            /// # Errors
            /// [`SetError::NonFinite`], [`SetError::InvalidSetting`]; nothing changes then.
            pub fn set_settings(&mut self, settings: &RtiSettings<Real>) -> Result<(), SetError> {
                self.rti.set_settings(settings)
            }
        }
    }

    /// The per-stage warm start: `set_state_guess`, `set_control_guess` and
    /// `set_trajectory_guess`, over the private `augmented_guess`.
    pub(super) fn stage_guess_setters(&self) -> TokenStream {
        let n1 = ul(self.l.n + 1);
        let aug = self.augmented_guess();
        quote! {
            #aug

            /// Sets the guess of model state `k <= N` (the states an input-rate cost appends
            /// keep theirs): the linearization point of the next [`prepare`](Self::prepare).
            ///
            /// # Errors
            /// [`SetError::NonFinite`], [`SetError::StageOutOfRange`]; nothing changes then.
            pub fn set_state_guess(&mut self, k: usize, x: &[Real; NX_MODEL]) -> Result<(), SetError> {
                let xa = self.augmented_guess(k, x, None).ok_or(SetError::StageOutOfRange)?;
                self.rti.set_state_guess(k, &xa)
            }

            /// Sets the guess of control `k < N` (also control `k` of the plan a failed QP
            /// falls back on).
            ///
            /// # Errors
            /// [`SetError::NonFinite`], [`SetError::StageOutOfRange`]; nothing changes then.
            pub fn set_control_guess(&mut self, k: usize, u: &[Real; NU]) -> Result<(), SetError> {
                self.rti.set_control_guess(k, &SVector::from(*u))
            }

            /// Sets the whole trajectory guess: model states `x[0..=N]` and controls
            /// `u[0..N]` (with an input-rate cost, the appended states of stage `k >= 1` are
            /// `u[k - 1]`).
            ///
            /// # Errors
            /// [`SetError::NonFinite`]; nothing changes then.
            pub fn set_trajectory_guess(
                &mut self,
                x: &[[Real; NX_MODEL]; #n1],
                u: &[[Real; NU]; N],
            ) -> Result<(), SetError> {
                self.set_trajectory_guess_from(|k| x[k], |k| u[k])
            }

            /// [`set_trajectory_guess`](Self::set_trajectory_guess) from functions of the
            /// stage, called for `k <= N` (states) and `k < N` (controls), twice each (a
            /// check of every value, then the copy): no trajectory-sized temporary.
            ///
            /// # Errors
            /// [`SetError::NonFinite`]; nothing changes then.
            pub fn set_trajectory_guess_from(
                &mut self,
                x: impl Fn(usize) -> [Real; NX_MODEL],
                u: impl Fn(usize) -> [Real; NU],
            ) -> Result<(), SetError> {
                let finite = |v: &[Real]| v.iter().all(|e| e.is_finite());
                if !((0..=N).all(|k| finite(&x(k))) && (0..N).all(|k| finite(&u(k)))) {
                    return Err(SetError::NonFinite);
                }
                for k in 0..=N {
                    let before = k.checked_sub(1).map(&u);
                    if let Some(xa) = self.augmented_guess(k, &x(k), before.as_ref()) {
                        self.rti.set_state_guess(k, &xa)?;
                    }
                }
                for k in 0..N {
                    self.rti.set_control_guess(k, &SVector::from(u(k)))?;
                }
                Ok(())
            }
        }
    }

    /// The private `augmented_guess(k, x, u_before)`: state `k`'s guess with model part `x`,
    /// the appended input-rate states `u_before` where given, else as they are.
    fn augmented_guess(&self) -> TokenStream {
        let l = self.l;
        let u_last = l.u_prev.as_ref().map(|_| {
            let g = (0..l.nu).map(|i| {
                let (xi, i) = (ul(l.nx_model + i), ul(i));
                quote!(xa[#xi] = u[#i];)
            });
            quote! {
                if let Some(u) = u_before {
                    #(#g)*
                }
            }
        });
        let unused = if u_last.is_none() {
            quote!(let _ = u_before;)
        } else {
            quote!()
        };
        quote! {
            fn augmented_guess(
                &self,
                k: usize,
                x: &[Real; NX_MODEL],
                u_before: Option<&[Real; NU]>,
            ) -> Option<SVector<Real, NX>> {
                let mut xa = *self.rti.state(k)?;
                for (i, &e) in x.iter().enumerate() {
                    xa[i] = e;
                }
                #unused
                #u_last
                Some(xa)
            }
        }
    }

    /// The soft rows' penalties: `set_soft_penalties`, `soft_penalties` and their terminal
    /// twins.
    pub(super) fn soft_penalty_api(&self) -> TokenStream {
        quote! {
            /// Sets the slack penalties of the general constraints at every stage `k < N`:
            /// row `i` costs `l1[i] (sl + su) + 1/2 l2[i] (sl^2 + su^2)` for the slacks that
            /// relax it; both zero makes it hard (the terminal rows keep theirs). Applies
            /// from the next [`prepare`](Self::prepare).
            ///
            /// # Errors
            /// [`SetError::NonFinite`], [`SetError::NegativePenalty`]; nothing changes then.
            pub fn set_soft_penalties(&mut self, l1: &[Real; NG], l2: &[Real; NG]) -> Result<(), SetError> {
                let (_, _, l1n, l2n) = self.rti.soft_penalties();
                let (l1n, l2n) = (*l1n, *l2n);
                self.rti.set_soft_penalties(&SVector::from(*l1), &SVector::from(*l2), &l1n, &l2n)
            }

            /// The stage rows' slack penalties in use, `(l1, l2)`.
            pub fn soft_penalties(&self) -> ([Real; NG], [Real; NG]) {
                let (l1, l2, _, _) = self.rti.soft_penalties();
                ((*l1).into(), (*l2).into())
            }

            /// Sets the slack penalties of the terminal constraints, as
            /// [`set_soft_penalties`](Self::set_soft_penalties).
            ///
            /// # Errors
            /// [`SetError::NonFinite`], [`SetError::NegativePenalty`]; nothing changes then.
            pub fn set_terminal_soft_penalties(&mut self, l1n: &[Real; NGN], l2n: &[Real; NGN]) -> Result<(), SetError> {
                let (l1, l2, _, _) = self.rti.soft_penalties();
                let (l1, l2) = (*l1, *l2);
                self.rti.set_soft_penalties(&l1, &l2, &SVector::from(*l1n), &SVector::from(*l2n))
            }

            /// The terminal rows' slack penalties in use, `(l1n, l2n)`.
            pub fn terminal_soft_penalties(&self) -> ([Real; NGN], [Real; NGN]) {
                let (_, _, l1n, l2n) = self.rti.soft_penalties();
                ((*l1n).into(), (*l2n).into())
            }
        }
    }

    /// `control_bound_multipliers` and `state_bound_multipliers` (with soft bounds,
    /// `soft_bounds_api::soft_bound_multipliers`).
    fn bound_multipliers(&self) -> TokenStream {
        if self.has_soft_bounds() {
            return super::soft_bounds_api::soft_bound_multipliers();
        }
        quote! {
            /// The control bounds' multipliers of stage `k < N` in the last QP
            /// (`mu_u - mu_l`: positive on an upper bound, negative on a lower one).
            pub fn control_bound_multipliers(&self, k: usize) -> Option<[Real; NU]> {
                self.rti.control_bound_multipliers(k).map(Into::into)
            }

            /// The model-state bounds' multipliers of stage `1 <= k <= N` in the last QP
            /// (signs as [`control_bound_multipliers`](Self::control_bound_multipliers)).
            pub fn state_bound_multipliers(&self, k: usize) -> Option<[Real; NX_MODEL]> {
                self.rti.state_bound_multipliers(k).map(|v| core::array::from_fn(|i| v[i]))
            }
        }
    }

    /// The read-outs: `cost`, `kkt_residual`, the slacks, the multipliers and `trajectory`.
    pub(super) fn read_outs(&self) -> TokenStream {
        let n1 = ul(self.l.n + 1);
        let (sl, su) = (self.model_rows(quote!(l)), self.model_rows(quote!(u)));
        let lam = if self.has_soft_bounds() {
            quote!(|v| take_rows(&v, 0))
        } else {
            quote!(Into::into)
        };
        let lam_n = self.model_rows(quote!(self.rti.terminal_constraint_multipliers()));
        let bound_multipliers = self.bound_multipliers();
        // The doc of a model without general terms as it was (its crate is unchanged).
        let cost_doc = if self.l.general_cost.is_some() {
            quote! {
                /// The objective at the current trajectory: least-squares cost, the general
                /// cost terms and the soft rows' slack cost
                /// ([`Rti::cost`](mpc_runtime::Rti::cost)).
            }
        } else {
            quote! {
                /// The objective at the current trajectory: least-squares cost plus the soft
                /// rows' slack cost ([`Rti::cost`](mpc_runtime::Rti::cost)).
            }
        };
        quote! {
            #cost_doc
            pub fn cost(&self) -> Real {
                self.rti.cost()
            }

            /// The NLP's KKT residual at the last linearization with the last QP's
            /// multipliers ([`Rti::kkt_residual`](mpc_runtime::Rti::kkt_residual)); `None`
            /// where a hard general row has a bound. The last QP's own residuals are in
            /// [`stats`](Self::stats).
            pub fn kkt_residual(&self) -> Option<Real> {
                self.rti.kkt_residual()
            }

            /// Lower and upper slacks `(sl, su)` of stage `k < N`'s general constraints in
            /// the last QP (zero for hard rows).
            pub fn slacks(&self, k: usize) -> Option<([Real; NG], [Real; NG])> {
                self.rti.slacks(k).map(|(l, u)| (#sl, #su))
            }

            /// Lower and upper slacks of the terminal constraints in the last QP.
            pub fn terminal_slacks(&self) -> ([Real; NGN], [Real; NGN]) {
                let (l, u) = self.rti.terminal_slacks();
                (#sl, #su)
            }

            /// The dynamics multipliers `pi_k` (`k < N`, model states) of the last QP.
            pub fn dynamics_multipliers(&self, k: usize) -> Option<[Real; NX_MODEL]> {
                self.rti.dynamics_multipliers(k).map(|v| core::array::from_fn(|i| v[i]))
            }

            #bound_multipliers

            /// The general constraints' multipliers of stage `k < N` in the last QP
            /// (`lam_u - lam_l`; the interior point's, see
            /// [`Rti::constraint_multipliers`](mpc_runtime::Rti::constraint_multipliers)).
            pub fn constraint_multipliers(&self, k: usize) -> Option<[Real; NG]> {
                self.rti.constraint_multipliers(k).map(#lam)
            }

            /// The terminal constraints' multipliers in the last QP.
            pub fn terminal_constraint_multipliers(&self) -> [Real; NGN] {
                #lam_n
            }

            /// Copies the whole predicted trajectory: model states `x[0..=N]` and controls
            /// `u[0..N]`.
            pub fn trajectory(&self, x: &mut [[Real; NX_MODEL]; #n1], u: &mut [[Real; NU]; N]) {
                for (k, xk) in x.iter_mut().enumerate() {
                    if let Some(v) = self.state(k) {
                        *xk = v;
                    }
                }
                for (k, uk) in u.iter_mut().enumerate() {
                    if let Some(v) = self.control(k) {
                        *uk = v;
                    }
                }
            }
        }
    }
}
