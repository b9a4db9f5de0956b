//! The generated `Solver`: its struct, construction (`unconfigured`, `configure`, `new`),
//! settings access, the real-time iteration's phases and the getters. Its setters are in
//! `setters.rs`.

use proc_macro2::TokenStream;
use quote::{format_ident, quote};

use super::{Emitter, allow_case, doc_lines, doc_text, ul};
use crate::lower::Named;

impl Emitter<'_> {
    /// `struct Solver` (the runtime solver, the parameters of every stage, the measured
    /// state, the last control and outcome) and its `impl Default`.
    pub(super) fn solver_struct(&self) -> TokenStream {
        let l = self.l;
        let doc = doc_lines(&format!(
            "The NMPC solver of `{}`: horizon {}, {} s per interval, one real-time \
             iteration per control step.\n\n\
             Each step: [`prepare`](Self::prepare) (before the state arrives), \
             [`set_x0`](Self::set_x0), [`feedback`](Self::feedback), then apply \
             [`u0`](Self::u0). Parameters have named setters, and the bounds run-time setters \
             ([`set_control_bounds`](Self::set_control_bounds) and its kin); \
             [`solve_sqp`](Self::solve_sqp) \
             iterates to convergence for offline use. No heap, no panics: it can live in a \
             `static` ([`unconfigured`](Self::unconfigured) is `const`, then \
             [`configure`](Self::configure)).",
            l.name, l.n, l.dt
        ));
        let n1 = ul(l.n + 1);
        quote! {
            #doc
            #[derive(Clone, Debug)]
            pub struct Solver {
                rti: Rti,
                p: [SVector<Real, NP>; #n1],
                x0: SVector<Real, NX_MODEL>,
                u0: SVector<Real, NU>,
                /// The last feedback's or SQP solve's outcome, valid once `solved` (not an
                /// `Option`: its `None` is not zero bits, see [`unconfigured`](Self::unconfigured)).
                info: RtiInfo<Real>,
                solved: bool,
            }

            impl Default for Solver {
                fn default() -> Self {
                    Self::new()
                }
            }
        }
    }

    /// `unconfigured` (all zero bits, `const`), `configure` (loads the generated defaults)
    /// and `new` (both).
    pub(super) fn construction(&self) -> TokenStream {
        let n1 = ul(self.l.n + 1);
        let soft_penalties = self.soft_penalties_call();
        quote! {
            /// A solver with every field zero (settings, weights, bounds, parameters), `const`
            /// so it can initialize a `static`, which is then zero-filled memory (`.bss`), not
            /// an image of the solver in flash; call [`configure`](Self::configure) before use.
            pub const fn unconfigured() -> Self {
                Solver {
                    rti: Rti::unconfigured(Model),
                    p: [P_ZERO; #n1],
                    x0: X0,
                    u0: U_ZERO,
                    info: RtiInfo::EMPTY,
                    solved: false,
                }
            }

            /// Loads the generated defaults: settings, parameters, weights, bounds, slack
            /// penalties and the initial guess.
            ///
            /// # Errors
            /// A [`SetError`] if a generated constant were rejected (never, for a model
            /// that validated).
            pub fn configure(&mut self) -> Result<(), SetError> {
                self.rti.settings = default_settings();
                self.set_param_all(&P_DEFAULT)?;
                self.rti.set_bounds(
                    &SVector::from(LBX),
                    &SVector::from(UBX),
                    &SVector::from(LBU),
                    &SVector::from(UBU),
                )?;
                self.rti.set_constraint_bounds(
                    &SVector::from(LG),
                    &SVector::from(UG),
                    &SVector::from(LGN),
                    &SVector::from(UGN),
                )?;
                #soft_penalties
                self.rti.set_guess(&SVector::from(X_GUESS), &SVector::from(U_GUESS))?;
                self.x0 = self.rti.state(0).map_or(X0, |x| x.fixed_rows::<NX_MODEL>(0).into_owned());
                self.u0 = U0;
                self.info = RtiInfo::EMPTY;
                self.solved = false;
                Ok(())
            }

            /// A configured solver ([`unconfigured`](Self::unconfigured) +
            /// [`configure`](Self::configure)).
            pub fn new() -> Self {
                let mut s = Self::unconfigured();
                // Cannot fail for a validated model (the test suite of the generator checks
                // it); if it ever did, the solver would stay unconfigured, not panic.
                let _ = s.configure();
                s
            }
        }
    }

    /// `configure`'s `set_soft_penalties` call, for a model with a soft constraint only.
    fn soft_penalties_call(&self) -> TokenStream {
        let l = self.l;
        let any_soft = (l.l1.iter().chain(&l.l2).chain(&l.l1n).chain(&l.l2n)).any(|&v| v > 0.0);
        if !any_soft {
            return quote!();
        }
        quote! {
            self.rti.set_soft_penalties(
                &SVector::from(L1),
                &SVector::from(L2),
                &SVector::from(L1N),
                &SVector::from(L2N),
            )?;
        }
    }

    /// `settings`, `settings_mut` and `rti`.
    pub(super) fn settings_access(&self) -> TokenStream {
        quote! {
            /// The settings (QP tolerances, iteration limits, shift).
            pub fn settings(&self) -> &RtiSettings<Real> {
                &self.rti.settings
            }

            /// The settings, to change in place, unchecked: [`set_settings`](Self::set_settings)
            /// validates them.
            pub fn settings_mut(&mut self) -> &mut RtiSettings<Real> {
                &mut self.rti.settings
            }

            /// The runtime solver (trajectory, QP data).
            pub fn rti(&self) -> &Rti {
                &self.rti
            }
        }
    }

    /// The private `x0_aug` (the measured state, augmented for an input-rate cost), then the
    /// phases: `prepare`, `feedback`, `solve_sqp`.
    pub(super) fn phases(&self) -> TokenStream {
        let x0_u_last = self.x0_u_last();
        let u_prev_update = self.u_prev_update();
        quote! {
            fn x0_aug(&self) -> SVector<Real, NX> {
                let mut x = SVector::<Real, NX>::zeros();
                for i in 0..NX_MODEL {
                    x[i] = self.x0[i];
                }
                #x0_u_last
                x
            }

            /// Preparation phase: linearizes every stage around the current trajectory.
            pub fn prepare(&mut self) {
                self.rti.prepare();
            }

            /// Feedback phase: solves the QP from the state of [`set_x0`](Self::set_x0) and
            /// stores the control ([`u0`](Self::u0)). If the QP fails, the control comes
            /// from the previous plan and the status says so; it is never NaN.
            pub fn feedback(&mut self) -> RtiInfo<Real> {
                let x0 = self.x0_aug();
                let (u, info) = self.rti.feedback(&x0);
                self.u0 = u;
                self.info = info;
                self.solved = true;
                #u_prev_update
                info
            }

            /// Full SQP from the state of [`set_x0`](Self::set_x0) to convergence (offline
            /// planning, tests); [`u0`](Self::u0) is then the first control of the solution.
            pub fn solve_sqp(&mut self) -> RtiInfo<Real> {
                let x0 = self.x0_aug();
                let info = self.rti.solve_sqp(&x0);
                if let Some(u) = self.rti.control(0).filter(|u| u.iter().all(|e| e.is_finite())) {
                    self.u0 = *u;
                }
                self.info = info;
                self.solved = true;
                info
            }
        }
    }

    /// With an input-rate cost, `x0_aug`'s last applied control: the `u_prev` parameter of
    /// stage 0.
    fn x0_u_last(&self) -> TokenStream {
        let Some(idx) = &self.l.u_prev else {
            return quote!();
        };
        let pairs = idx.iter().enumerate().map(|(i, &pi)| {
            let (xi, pi) = (ul(self.l.nx_model + i), ul(pi));
            quote!(x[#xi] = self.p[0][#pi];)
        });
        quote!(#(#pairs)*)
    }

    /// With an input-rate cost, `feedback`'s update of the `u_prev` parameter to the control
    /// it returned (and of the weights, if they read it).
    fn u_prev_update(&self) -> TokenStream {
        let Some(idx) = &self.l.u_prev else {
            return quote!();
        };
        let upd = idx.iter().enumerate().map(|(i, &pi)| {
            let (i, pi) = (ul(i), ul(pi));
            quote!(p[#pi] = u[#i];)
        });
        // Only the u_prev entries change: the weights are evaluated again only if they read them.
        let weights_again = if self.l.weights_use_u_prev {
            quote! {
                let p0 = self.p[0];
                let _ = self.update_weights(&p0);
            }
        } else {
            quote!()
        };
        quote! {
            // The control just returned is the one applied next: it becomes
            // `u_{-1}` of the input-rate cost of the next step.
            if u.iter().all(|e| e.is_finite()) {
                for k in 0..=N {
                    let mut p = self.p[k];
                    #(#upd)*
                    if self.rti.set_param(k, &p).is_ok() {
                        self.p[k] = p;
                    }
                }
                #weights_again
            }
        }
    }

    /// `u0`, one `u0_<name>` per control, `control(k)`, `state(k)` and `stats`.
    pub(super) fn getters(&self) -> TokenStream {
        let named = self.l.controls.iter().map(control_getter);
        quote! {
            /// The control of the last feedback (or SQP solve).
            pub fn u0(&self) -> [Real; NU] {
                self.u0.into()
            }

            #(#named)*

            /// Control `k < N` of the current plan.
            pub fn control(&self, k: usize) -> Option<[Real; NU]> {
                self.rti.control(k).map(|u| (*u).into())
            }

            /// Model state `k <= N` of the current plan.
            pub fn state(&self, k: usize) -> Option<[Real; NX_MODEL]> {
                self.rti.state(k).map(|x| {
                    let mut out = [0.0; NX_MODEL];
                    for (i, o) in out.iter_mut().enumerate() {
                        *o = x[i];
                    }
                    out
                })
            }

            /// Status and statistics of the last feedback or SQP solve (`None` before the
            /// first).
            pub fn stats(&self) -> Option<RtiInfo<Real>> {
                self.solved.then_some(self.info)
            }
        }
    }
}

/// `u0_<name>`: control `v` of the last feedback (a `Real`, or an array for a vector).
fn control_getter(v: &Named) -> TokenStream {
    let name = format_ident!("u0_{}", v.name);
    let case = allow_case(&name.to_string());
    let (off, len) = (ul(v.offset), ul(v.len));
    let described = if v.doc.is_empty() {
        String::new()
    } else {
        format!(" ({})", doc_text(&v.doc))
    };
    let d = doc_lines(&format!(
        "Control `{}` of the last feedback{described}.",
        v.name
    ));
    if v.scalar {
        quote! {
            #d
            #case
            pub fn #name(&self) -> Real {
                self.u0[#off]
            }
        }
    } else {
        quote! {
            #d
            #case
            pub fn #name(&self) -> [Real; #len] {
                let mut out = [0.0; #len];
                for (i, o) in out.iter_mut().enumerate() {
                    *o = self.u0[#off + i];
                }
                out
            }
        }
    }
}
