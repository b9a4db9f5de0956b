//! The generated `functions` module (one straight-line function per lowered model function,
//! and the helpers they call) and the `Model` impl that calls them.

use proc_macro2::TokenStream;
use quote::quote;

use super::body::{Uses, body};
use super::{Emitter, doc_lines, lit, rows_doc};
use crate::options::Scalar;

impl Emitter<'_> {
    /// `pub mod functions`: the helpers the bodies call, then dynamics, dynamics value,
    /// dynamics Hessian (exact Hessian only), residual, terminal residual, weights,
    /// constraints and terminal constraints (when the model has them), the general cost's
    /// and the constraints' Hessians (`general_cost.rs`, those the model has).
    pub(super) fn functions_module(&self) -> TokenStream {
        let mut uses = Uses::default();
        let fns = [
            self.dynamics_fn(&mut uses),
            self.dynamics_value_fn(&mut uses),
            self.dynamics_hessian_fn(&mut uses),
            self.residual_fn(&mut uses),
            self.terminal_residual_fn(&mut uses),
            self.weights_fn(&mut uses),
            self.constraints_fn(&mut uses),
            self.terminal_constraints_fn(&mut uses),
            self.general_cost_fns(&mut uses),
            self.constraints_hessian_fns(&mut uses),
        ];
        let helpers = helpers(&uses, self.s);
        quote! {
            /// The model functions as straight-line code (every distinct subexpression once).
            pub mod functions {
                use super::*;

                #helpers

                #(#fns)*
            }
        }
    }

    /// `functions::dynamics`: `F(x, u, p)`, `a = dF/dx`, `b = dF/du`.
    fn dynamics_fn(&self, uses: &mut Uses) -> TokenStream {
        let l = self.l;
        if let Some(irk) = &l.irk {
            // `ode`, the step's settings, `dynamics` and `dynamics_value` (`implicit.rs`).
            return self.irk_fns(irk, uses);
        }
        let body = body(
            &l.dynamics,
            self.s,
            &["a", "b"],
            Some(quote!(SVector<Real, NX>)),
            uses,
        );
        let augmented = if l.nx > l.nx_model {
            format!(
                "\n\nStates {}..{} are the last applied control (`u_last+ = u`), for the \
                 input-rate cost.",
                l.nx_model, l.nx
            )
        } else {
            String::new()
        };
        let doc = doc_lines(&format!(
            "Discrete dynamics over one interval ({} s, {}): returns `F(x, u, p)` and writes \
             `a = dF/dx`, `b = dF/du`.{augmented}",
            l.dt, l.discretization,
        ));
        quote! {
            #doc
            #[allow(unused_variables, unused_mut, unused_assignments)]
            // Thousands of instructions for one call site (the linearization): inlined, it
            // only grows the code (by 516 B on the Cortex-M4F).
            #[inline(never)]
            pub fn dynamics(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                a: &mut SMatrix<Real, NX, NX>,
                b: &mut SMatrix<Real, NX, NU>,
            ) -> SVector<Real, NX> {
                #body
            }
        }
    }

    /// `functions::dynamics_value`: `F(x, u, p)` alone.
    fn dynamics_value_fn(&self, uses: &mut Uses) -> TokenStream {
        if self.l.irk.is_some() {
            // Emitted with `dynamics` by `irk_fns`.
            return quote!();
        }
        let body = body(
            &self.l.dynamics_value,
            self.s,
            &[],
            Some(quote!(SVector<Real, NX>)),
            uses,
        );
        quote! {
            /// [`dynamics`]'s `F(x, u, p)` alone, without the Jacobians (the full SQP's merit
            /// function).
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn dynamics_value(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
            ) -> SVector<Real, NX> {
                #body
            }
        }
    }

    /// `functions::dynamics_hessian` (exact Hessian only): the Hessian of `pi' F`.
    fn dynamics_hessian_fn(&self, uses: &mut Uses) -> TokenStream {
        let Some(f) = &self.l.dynamics_hessian else {
            return quote!();
        };
        let body = body(f, self.s, &["hxx", "hux", "huu"], None, uses);
        quote! {
            /// The dynamics' part of the Lagrangian Hessian: writes the Hessian of
            /// `pi' F(x, u, p)` over `(x, u)` as `hxx` (states), `hux` (controls by
            /// states) and `huu` (controls).
            #[allow(unused_variables, unused_mut, unused_assignments)]
            #[inline(never)]
            pub fn dynamics_hessian(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                pi: &SVector<Real, NX>,
                hxx: &mut SMatrix<Real, NX, NX>,
                hux: &mut SMatrix<Real, NU, NX>,
                huu: &mut SMatrix<Real, NU, NU>,
            ) {
                #body
            }
        }
    }

    /// `functions::residual`: the stage residual and its Jacobians, with a table of its rows.
    fn residual_fn(&self, uses: &mut Uses) -> TokenStream {
        let body = body(
            &self.l.residual,
            self.s,
            &["jx", "ju"],
            Some(quote!(SVector<Real, NY>)),
            uses,
        );
        let doc = doc_lines(&rows_doc(
            "Stage residual `y(x, u, p)` (cost `1/2 |y|^2_W`) with `jx = dy/dx`, `ju = dy/du`.",
            &self.l.residual_rows,
        ));
        quote! {
            #doc
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn residual(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                jx: &mut SMatrix<Real, NY, NX>,
                ju: &mut SMatrix<Real, NY, NU>,
            ) -> SVector<Real, NY> {
                #body
            }
        }
    }

    /// `functions::terminal_residual`: the terminal residual and its Jacobian.
    fn terminal_residual_fn(&self, uses: &mut Uses) -> TokenStream {
        let body = body(
            &self.l.terminal_residual,
            self.s,
            &["jx"],
            Some(quote!(SVector<Real, NYN>)),
            uses,
        );
        let doc = doc_lines(&rows_doc(
            "Terminal residual `y_N(x, p)` (cost `1/2 |y_N|^2_{W_N}`) with `jx = dy_N/dx`.",
            &self.l.terminal_residual_rows,
        ));
        quote! {
            #doc
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn terminal_residual(
                x: &SVector<Real, NX>,
                p: &SVector<Real, NP>,
                jx: &mut SMatrix<Real, NYN, NX>,
            ) -> SVector<Real, NYN> {
                #body
            }
        }
    }

    /// `functions::weights`: `W` and `W_N` from the parameters.
    fn weights_fn(&self, uses: &mut Uses) -> TokenStream {
        let body = body(&self.l.weights, self.s, &["w", "wn"], None, uses);
        quote! {
            /// The weights `W` (stage, block-diagonal in the residual's blocks) and `W_N`
            /// (terminal) from the parameters (only global ones may appear).
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn weights(
                p: &SVector<Real, NP>,
                w: &mut SMatrix<Real, NY, NY>,
                wn: &mut SMatrix<Real, NYN, NYN>,
            ) {
                #body
            }
        }
    }

    /// `functions::constraints` (a model with stage constraints only).
    fn constraints_fn(&self, uses: &mut Uses) -> TokenStream {
        let Some(f) = &self.l.constraints else {
            return quote!();
        };
        let ng = self.ng_qp();
        let body = body(
            f,
            self.s,
            &["cx", "cu"],
            Some(quote!(SVector<Real, #ng>)),
            uses,
        );
        let doc = doc_lines(&rows_doc(
            "Stage constraints `h(x, u, p)` (`lg <= h <= ug`) with `cx = dh/dx`, `cu = dh/du`.",
            &self.l.constraint_rows,
        ));
        quote! {
            #doc
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn constraints(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                cx: &mut SMatrix<Real, #ng, NX>,
                cu: &mut SMatrix<Real, #ng, NU>,
            ) -> SVector<Real, #ng> {
                #body
            }
        }
    }

    /// `functions::terminal_constraints` (a model with terminal constraints only).
    fn terminal_constraints_fn(&self, uses: &mut Uses) -> TokenStream {
        let Some(f) = &self.l.terminal_constraints else {
            return quote!();
        };
        let ngn = self.ngn_qp();
        let body = body(f, self.s, &["cx"], Some(quote!(SVector<Real, #ngn>)), uses);
        let doc = doc_lines(&rows_doc(
            "Terminal constraints `h_N(x, p)` with `cx = dh_N/dx`.",
            &self.l.terminal_constraint_rows,
        ));
        quote! {
            #doc
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn terminal_constraints(
                x: &SVector<Real, NX>,
                p: &SVector<Real, NP>,
                cx: &mut SMatrix<Real, #ngn, NX>,
            ) -> SVector<Real, #ngn> {
                #body
            }
        }
    }

    /// `struct Model` and its `impl mpc_runtime::Model`, each method a call of its function
    /// in `functions`.
    pub(super) fn model_impl(&self) -> TokenStream {
        let constant_jacobians = self.l.constant_residual_jacobians;
        let constant_stage_jacobians = self.l.constant_stage_residual_jacobians;
        let hessian = self.model_dynamics_hessian();
        let constraints = self.model_constraints();
        let general_cost = self.model_general_cost();
        let constraints_hessian = self.model_constraints_hessian();
        let (ng, ngn) = (self.ng_qp(), self.ngn_qp());
        quote! {
            /// The model, as the runtime's solver evaluates it.
            #[derive(Clone, Copy, Debug, Default)]
            pub struct Model;

            impl mpc_runtime::Model<Real, NX, NU, NP, NY, NYN, #ng, #ngn> for Model {
                const CONSTANT_RESIDUAL_JACOBIANS: bool = #constant_jacobians;
                const CONSTANT_STAGE_RESIDUAL_JACOBIANS: bool = #constant_stage_jacobians;
                #hessian

                fn dynamics(
                    &self,
                    x: &SVector<Real, NX>,
                    u: &SVector<Real, NU>,
                    p: &SVector<Real, NP>,
                    a: &mut SMatrix<Real, NX, NX>,
                    b: &mut SMatrix<Real, NX, NU>,
                ) -> SVector<Real, NX> {
                    functions::dynamics(x, u, p, a, b)
                }

                fn dynamics_value(
                    &self,
                    x: &SVector<Real, NX>,
                    u: &SVector<Real, NU>,
                    p: &SVector<Real, NP>,
                ) -> SVector<Real, NX> {
                    functions::dynamics_value(x, u, p)
                }

                fn residual(
                    &self,
                    x: &SVector<Real, NX>,
                    u: &SVector<Real, NU>,
                    p: &SVector<Real, NP>,
                    jx: &mut SMatrix<Real, NY, NX>,
                    ju: &mut SMatrix<Real, NY, NU>,
                ) -> SVector<Real, NY> {
                    functions::residual(x, u, p, jx, ju)
                }

                fn terminal_residual(
                    &self,
                    x: &SVector<Real, NX>,
                    p: &SVector<Real, NP>,
                    jx: &mut SMatrix<Real, NYN, NX>,
                ) -> SVector<Real, NYN> {
                    functions::terminal_residual(x, p, jx)
                }

                #constraints
                #general_cost
                #constraints_hessian
            }
        }
    }

    /// `EXACT_HESSIAN` and `Model::dynamics_hessian` (exact Hessian only; the trait's
    /// defaults otherwise).
    fn model_dynamics_hessian(&self) -> TokenStream {
        if self.l.dynamics_hessian.is_none() {
            return quote!();
        }
        quote! {
            const EXACT_HESSIAN: bool = true;

            fn dynamics_hessian(
                &self,
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                pi: &SVector<Real, NX>,
                hxx: &mut SMatrix<Real, NX, NX>,
                hux: &mut SMatrix<Real, NU, NX>,
                huu: &mut SMatrix<Real, NU, NU>,
            ) {
                functions::dynamics_hessian(x, u, p, pi, hxx, hux, huu)
            }
        }
    }

    /// `Model::constraints` and `Model::terminal_constraints`, those the model has.
    fn model_constraints(&self) -> TokenStream {
        let (ng, ngn) = (self.ng_qp(), self.ngn_qp());
        let stage = self.l.constraints.as_ref().map(|_| {
            quote! {
                fn constraints(
                    &self,
                    x: &SVector<Real, NX>,
                    u: &SVector<Real, NU>,
                    p: &SVector<Real, NP>,
                    cx: &mut SMatrix<Real, #ng, NX>,
                    cu: &mut SMatrix<Real, #ng, NU>,
                ) -> SVector<Real, #ng> {
                    functions::constraints(x, u, p, cx, cu)
                }
            }
        });
        let terminal = self.l.terminal_constraints.as_ref().map(|_| {
            quote! {
                fn terminal_constraints(
                    &self,
                    x: &SVector<Real, NX>,
                    p: &SVector<Real, NP>,
                    cx: &mut SMatrix<Real, #ngn, NX>,
                ) -> SVector<Real, #ngn> {
                    functions::terminal_constraints(x, p, cx)
                }
            }
        });
        quote!(#stage #terminal)
    }
}

/// The helpers the emitted bodies call (`sign`, `step`, `powi`), only those they do.
fn helpers(uses: &Uses, s: Scalar) -> TokenStream {
    let zero = lit(0.0, s);
    let one = lit(1.0, s);
    let sign = uses.sign.then(|| {
        quote! {
            /// `sign(x)`: -1, 0 or 1 (0 for NaN), as in `mpc_dsl::ops`.
            #[inline(always)]
            fn sign(x: Real) -> Real {
                if x > #zero { #one } else if x < #zero { -#one } else { #zero }
            }
        }
    });
    let step = uses.step.then(|| {
        quote! {
            /// Heaviside step: 1 for `x >= 0`, else 0.
            #[inline(always)]
            fn step(x: Real) -> Real {
                if x >= #zero { #one } else { #zero }
            }
        }
    });
    let powi = uses.powi.then(|| {
        quote! {
            /// `x^n` by repeated squaring: the multiplications of `mpc_dsl::ops::powi`, in
            /// the same order, so host evaluation and generated code agree bit for bit.
            #[inline(always)]
            fn powi(x: Real, n: i32) -> Real {
                let mut base = x;
                let mut e = n.unsigned_abs();
                let mut acc = #one;
                let mut first = true;
                while e > 0 {
                    if e & 1 == 1 {
                        acc = if first { base } else { acc * base };
                        first = false;
                    }
                    e >>= 1;
                    if e > 0 {
                        base *= base;
                    }
                }
                if n < 0 { #one / acc } else { acc }
            }
        }
    });
    quote!(#sign #step #powi)
}
