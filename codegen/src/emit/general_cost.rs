//! The general cost's functions (`functions::stage_cost`, `stage_cost_value`,
//! `terminal_cost`, `terminal_cost_value`), the general constraints' curvature
//! (`functions::constraints_hessian`, `terminal_constraints_hessian`, exact Hessian only)
//! and the `Model` methods that call them. Nothing for a model without them.

use proc_macro2::TokenStream;
use quote::quote;

use super::Emitter;
use super::body::{Uses, body};

impl Emitter<'_> {
    /// The general cost's four functions in `functions` (a model with general terms only).
    pub(super) fn general_cost_fns(&self, uses: &mut Uses) -> TokenStream {
        let Some(c) = &self.l.general_cost else {
            return quote!();
        };
        let one = quote!(SVector<Real, 1>);
        let stage = body(
            &c.stage,
            self.s,
            &["gx", "gu", "hxx", "hux", "huu"],
            Some(one.clone()),
            uses,
        );
        let stage_value = body(&c.stage_value, self.s, &[], Some(one.clone()), uses);
        let terminal = body(&c.terminal, self.s, &["gx", "hxx"], Some(one.clone()), uses);
        let terminal_value = body(&c.terminal_value, self.s, &[], Some(one), uses);
        quote! {
            /// The general stage cost `l(x, u, p)` (the sum of the `stage` terms; returned as
            /// a one-entry vector) with its gradient `gx`, `gu` and Hessian `hxx`, `hux`
            /// (`d2l/du dx`), `huu`.
            #[allow(unused_variables, unused_mut, unused_assignments, clippy::too_many_arguments)]
            #[inline(never)]
            pub fn stage_cost(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                gx: &mut SVector<Real, NX>,
                gu: &mut SVector<Real, NU>,
                hxx: &mut SMatrix<Real, NX, NX>,
                hux: &mut SMatrix<Real, NU, NX>,
                huu: &mut SMatrix<Real, NU, NU>,
            ) -> SVector<Real, 1> {
                #stage
            }

            /// [`stage_cost`]'s value alone.
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn stage_cost_value(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
            ) -> SVector<Real, 1> {
                #stage_value
            }

            /// The general terminal cost `l_N(x, p)` (the sum of the `terminal` terms) with
            /// its gradient `gx` and Hessian `hxx`.
            #[allow(unused_variables, unused_mut, unused_assignments)]
            #[inline(never)]
            pub fn terminal_cost(
                x: &SVector<Real, NX>,
                p: &SVector<Real, NP>,
                gx: &mut SVector<Real, NX>,
                hxx: &mut SMatrix<Real, NX, NX>,
            ) -> SVector<Real, 1> {
                #terminal
            }

            /// [`terminal_cost`]'s value alone.
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn terminal_cost_value(
                x: &SVector<Real, NX>,
                p: &SVector<Real, NP>,
            ) -> SVector<Real, 1> {
                #terminal_value
            }
        }
    }

    /// `functions::constraints_hessian` and `terminal_constraints_hessian` (exact Hessian,
    /// those the model has rows for).
    pub(super) fn constraints_hessian_fns(&self, uses: &mut Uses) -> TokenStream {
        // The runtime's rows: the model's, then any soft bounds' (linear, no curvature).
        let (ng, ngn) = (self.ng_qp(), self.ngn_qp());
        let stage = self.l.constraints_hessian.as_ref().map(|f| {
            let body = body(f, self.s, &["hxx", "hux", "huu"], None, uses);
            quote! {
                /// The general constraints' part of the Lagrangian Hessian: the Hessian of
                /// `mu' h(x, u, p)` over `(x, u)` as `hxx`, `hux`, `huu`.
                #[allow(unused_variables, unused_mut, unused_assignments)]
                #[inline(never)]
                pub fn constraints_hessian(
                    x: &SVector<Real, NX>,
                    u: &SVector<Real, NU>,
                    p: &SVector<Real, NP>,
                    mu: &SVector<Real, #ng>,
                    hxx: &mut SMatrix<Real, NX, NX>,
                    hux: &mut SMatrix<Real, NU, NX>,
                    huu: &mut SMatrix<Real, NU, NU>,
                ) {
                    #body
                }
            }
        });
        let terminal = self.l.terminal_constraints_hessian.as_ref().map(|f| {
            let body = body(f, self.s, &["hxx"], None, uses);
            quote! {
                /// The Hessian of `mu' h_N(x, p)` over `x` (terminal rows).
                #[allow(unused_variables, unused_mut, unused_assignments)]
                #[inline(never)]
                pub fn terminal_constraints_hessian(
                    x: &SVector<Real, NX>,
                    p: &SVector<Real, NP>,
                    mu: &SVector<Real, #ngn>,
                    hxx: &mut SMatrix<Real, NX, NX>,
                ) {
                    #body
                }
            }
        });
        quote!(#stage #terminal)
    }

    /// `GENERAL_COST` and the `Model` methods of the general cost (a model with general
    /// terms only; the trait's defaults otherwise).
    pub(super) fn model_general_cost(&self) -> TokenStream {
        if self.l.general_cost.is_none() {
            return quote!();
        }
        quote! {
            const GENERAL_COST: bool = true;

            fn stage_cost(
                &self,
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                gx: &mut SVector<Real, NX>,
                gu: &mut SVector<Real, NU>,
                hxx: &mut SMatrix<Real, NX, NX>,
                hux: &mut SMatrix<Real, NU, NX>,
                huu: &mut SMatrix<Real, NU, NU>,
            ) -> Real {
                functions::stage_cost(x, u, p, gx, gu, hxx, hux, huu).x
            }

            fn stage_cost_value(
                &self,
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
            ) -> Real {
                functions::stage_cost_value(x, u, p).x
            }

            fn terminal_cost(
                &self,
                x: &SVector<Real, NX>,
                p: &SVector<Real, NP>,
                gx: &mut SVector<Real, NX>,
                hxx: &mut SMatrix<Real, NX, NX>,
            ) -> Real {
                functions::terminal_cost(x, p, gx, hxx).x
            }

            fn terminal_cost_value(&self, x: &SVector<Real, NX>, p: &SVector<Real, NP>) -> Real {
                functions::terminal_cost_value(x, p).x
            }
        }
    }

    /// `Model::constraints_hessian` and `terminal_constraints_hessian`, those emitted.
    pub(super) fn model_constraints_hessian(&self) -> TokenStream {
        let (ng, ngn) = (self.ng_qp(), self.ngn_qp());
        let stage = self.l.constraints_hessian.as_ref().map(|_| {
            quote! {
                fn constraints_hessian(
                    &self,
                    x: &SVector<Real, NX>,
                    u: &SVector<Real, NU>,
                    p: &SVector<Real, NP>,
                    mu: &SVector<Real, #ng>,
                    hxx: &mut SMatrix<Real, NX, NX>,
                    hux: &mut SMatrix<Real, NU, NX>,
                    huu: &mut SMatrix<Real, NU, NU>,
                ) {
                    functions::constraints_hessian(x, u, p, mu, hxx, hux, huu)
                }
            }
        });
        let terminal = self.l.terminal_constraints_hessian.as_ref().map(|_| {
            quote! {
                fn terminal_constraints_hessian(
                    &self,
                    x: &SVector<Real, NX>,
                    p: &SVector<Real, NP>,
                    mu: &SVector<Real, #ngn>,
                    hxx: &mut SMatrix<Real, NX, NX>,
                ) {
                    functions::terminal_constraints_hessian(x, p, mu, hxx)
                }
            }
        });
        quote!(#stage #terminal)
    }
}
