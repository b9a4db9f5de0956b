//! The implicit (`irk`) integrator's functions: the ODE's right-hand side `ode` as
//! straight-line code, and `dynamics` / `dynamics_value` as calls of the runtime's
//! Gauss-Legendre step ([`mpc_runtime::implicit`]) around it. The Newton iterations, the LU
//! with partial pivoting and the sensitivities by the implicit function theorem live in the
//! runtime (generic over the scalar, `no_std`, no panic); what is emitted here is only the
//! glue and the settings.

use proc_macro2::TokenStream;
use quote::quote;

use super::body::{Uses, body};
use super::{Emitter, doc_lines, ul};
use crate::lower::IrkStep;

impl Emitter<'_> {
    /// `ode`, `IRK`, `NK`, `irk_step`, `dynamics` and `dynamics_value` of a model integrated
    /// by `irk`.
    pub(super) fn irk_fns(&self, irk: &IrkStep, uses: &mut Uses) -> TokenStream {
        let l = self.l;
        let ode = self.ode_fn(uses);
        let settings = self.irk_settings(irk);
        let doc = doc_lines(&format!(
            "Discrete dynamics over one interval ({} s, {}): returns `F(x, u, p)` and writes \
             `a = dF/dx`, `b = dF/du`. A singular Newton matrix or a non-finite step gives NaN \
             in every output (a failed linearization to the solver).{}",
            l.dt,
            l.discretization,
            augmented_doc(l.nx_model, l.nx),
        ));
        let (dyn_body, value_body) = if l.nx > l.nx_model {
            (augmented_step(true), augmented_step(false))
        } else {
            (
                quote!(irk_step(x, u, p, Some((a, b)))),
                quote!(irk_step(x, u, p, None)),
            )
        };
        quote! {
            #ode

            #settings

            #doc
            #[inline(never)]
            pub fn dynamics(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                a: &mut SMatrix<Real, NX, NX>,
                b: &mut SMatrix<Real, NX, NU>,
            ) -> SVector<Real, NX> {
                #dyn_body
            }

            /// [`dynamics`]'s `F(x, u, p)` alone, without the Jacobians (the full SQP's merit
            /// function): the same Newton iterations, no sensitivity solve.
            pub fn dynamics_value(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
            ) -> SVector<Real, NX> {
                #value_body
            }
        }
    }

    /// `ode`: the right-hand side and its Jacobians as straight-line code.
    fn ode_fn(&self, uses: &mut Uses) -> TokenStream {
        let rhs = body(
            &self.l.dynamics,
            self.s,
            &["fx", "fu"],
            Some(quote!(SVector<Real, NX_MODEL>)),
            uses,
        );
        quote! {
            /// The ODE's right-hand side `f(x, u, p)` with `fx = df/dx`, `fu = df/du`: what
            /// the implicit step evaluates at its collocation points.
            #[allow(unused_variables, unused_mut, unused_assignments)]
            #[inline(never)]
            pub fn ode(
                x: &SVector<Real, NX_MODEL>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                fx: &mut SMatrix<Real, NX_MODEL, NX_MODEL>,
                fu: &mut SMatrix<Real, NX_MODEL, NU>,
            ) -> SVector<Real, NX_MODEL> {
                #rhs
            }
        }
    }

    /// `IRK` (the method and its settings), `NK` and `irk_step`, the runtime's step of the
    /// model's states around `ode`.
    fn irk_settings(&self, irk: &IrkStep) -> TokenStream {
        let (steps, newton) = (ul(irk.steps), ul(irk.newton));
        let (method, order, tables) = if irk.radau {
            ("Radau IIA", 2 * irk.stages - 1, quote!(RADAU_IIA))
        } else {
            ("Gauss-Legendre", 2 * irk.stages, quote!(GAUSS_LEGENDRE))
        };
        let irk_doc = doc_lines(&format!(
            "The implicit integrator: {method} collocation with {} stage(s) (order {order}), \
             {} substep(s) per interval and {} Newton iteration(s) per substep.",
            irk.stages, irk.steps, irk.newton
        ));
        let table = ul(irk.stages.saturating_sub(1));
        let nk = ul(irk.stages * self.l.nx_model);
        let dt = self.l.dt;
        quote! {
            #irk_doc
            pub const IRK: mpc_runtime::implicit::Irk = mpc_runtime::implicit::Irk {
                tableau: &mpc_runtime::implicit::#tables[#table],
                steps: #steps,
                newton: #newton,
                dt: #dt,
            };

            /// Entries of the collocation stage vector: stages times `NX_MODEL`.
            pub const NK: usize = #nk;

            /// One implicit step of the model's states (NaN on failure).
            fn irk_step(
                x: &SVector<Real, NX_MODEL>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                ab: Option<(
                    &mut SMatrix<Real, NX_MODEL, NX_MODEL>,
                    &mut SMatrix<Real, NX_MODEL, NU>,
                )>,
            ) -> SVector<Real, NX_MODEL> {
                let mut f = |xs: &SVector<Real, NX_MODEL>,
                             fx: &mut SMatrix<Real, NX_MODEL, NX_MODEL>,
                             fu: &mut SMatrix<Real, NX_MODEL, NU>| ode(xs, u, p, fx, fu);
                mpc_runtime::implicit::irk_step_or_nan::<Real, NX_MODEL, NU, NK, _>(
                    &IRK, x, &mut f, ab,
                )
            }
        }
    }
}

/// The doc line on the input-rate states, if any.
fn augmented_doc(nx_model: usize, nx: usize) -> String {
    if nx > nx_model {
        format!(
            "\n\nStates {nx_model}..{nx} are the last applied control (`u_last+ = u`), for \
             the input-rate cost."
        )
    } else {
        String::new()
    }
}

/// The body of `dynamics` (with `jacobians`) or `dynamics_value` of a model with an
/// input-rate cost: the step of the model's states, then `u_last+ = u` (`b` is the identity
/// in those rows; the model's states do not depend on `u_last`).
fn augmented_step(jacobians: bool) -> TokenStream {
    let head = quote! {
        let xm = SVector::<Real, NX_MODEL>::from_fn(|i, _| x[i]);
        let mut r = SVector::<Real, NX>::zeros();
    };
    let tail = quote! {
        for i in 0..NU {
            r[NX_MODEL + i] = u[i];
        }
        r
    };
    if !jacobians {
        return quote! {
            #head
            let xn = irk_step(&xm, u, p, None);
            for i in 0..NX_MODEL {
                r[i] = xn[i];
            }
            #tail
        };
    }
    quote! {
        #head
        let mut am = SMatrix::<Real, NX_MODEL, NX_MODEL>::zeros();
        let mut bm = SMatrix::<Real, NX_MODEL, NU>::zeros();
        let xn = irk_step(&xm, u, p, Some((&mut am, &mut bm)));
        a.as_mut_slice().fill(0.0);
        b.as_mut_slice().fill(0.0);
        for i in 0..NX_MODEL {
            r[i] = xn[i];
            for j in 0..NX_MODEL {
                a[(i, j)] = am[(i, j)];
            }
            for j in 0..NU {
                b[(i, j)] = bm[(i, j)];
            }
        }
        for i in 0..NU {
            b[(NX_MODEL + i, i)] = 1.0;
        }
        #tail
    }
}
