//! The generated crate's constants: the imports, the scalar type and dimensions, the named
//! index ranges, the model's data (guesses, defaults, bounds, slack penalties), the runtime
//! solver type and the settings the crate was generated with.

use proc_macro2::{Ident, TokenStream};
use quote::{format_ident, quote};

use super::{Emitter, doc_lines, doc_text, lit, lits, real_ty, ul};
use crate::lower::Named;
use crate::options::QpMethod;

impl Emitter<'_> {
    /// The `use`s every later item relies on.
    pub(super) fn imports(&self) -> TokenStream {
        quote! {
            use mpc_runtime::nalgebra::{SMatrix, SVector};
            pub use mpc_runtime::{RtiInfo, RtiSettings, RtiStatus, SetError};
        }
    }

    /// `Real` and the dimensions: `NX_MODEL`, `NX`, `NU`, `NP`, `NY`, `NYN`, `NG`, `NGN`,
    /// `N`, the QP solver's storage (`NC`, `NBX`, `NR`, `NH`) and `DT`.
    pub(super) fn dimensions(&self) -> TokenStream {
        let l = self.l;
        let real = real_ty(self.s);
        let (nx, nxm, nu, np) = (ul(l.nx), ul(l.nx_model), ul(l.nu), ul(l.np));
        let (ng, ngn) = (ul(l.soft_bounds.ng_model), ul(l.soft_bounds.ngn_model));
        let (ny, nyn, n) = (ul(l.ny), ul(l.nyn), ul(l.n));
        let sizes = self.sizes();
        let (nc, nbx, nr, nh) = (ul(sizes.nc), ul(sizes.nbx), ul(sizes.nr), ul(sizes.nh));
        let dt = lit(l.dt, self.s);
        quote! {
            /// The scalar type of this solver.
            pub type Real = #real;
            /// States of the model.
            pub const NX_MODEL: usize = #nxm;
            /// States of the solver (model states, then the last control for an input-rate cost).
            pub const NX: usize = #nx;
            /// Controls.
            pub const NU: usize = #nu;
            /// Parameters per stage.
            pub const NP: usize = #np;
            /// Stage residual rows.
            pub const NY: usize = #ny;
            /// Terminal residual rows.
            pub const NYN: usize = #nyn;
            /// Stage general constraint rows.
            pub const NG: usize = #ng;
            /// Terminal general constraint rows.
            pub const NGN: usize = #ngn;
            /// Horizon (shooting intervals).
            pub const N: usize = #n;
            /// Condensing storage of the QP solver: `N` (QPs with control bounds only are
            /// condensed) or `0` (Riccati recursion only).
            pub const NC: usize = #nc;
            /// State-bound rows of the QP solver per stage: the states with a bound.
            pub const NBX: usize = #nbx;
            /// Riccati storage of the QP solver: `N`, or `0` for a solver that condenses every
            /// QP (`NC = N`, no state bounds, no general constraints), which then has no Riccati
            /// recursion (and ignores a `QpMethod::Riccati` setting).
            pub const NR: usize = #nr;
            /// Stage Hessians in the QP: `1` when the stage residual Jacobians are constants (the
            /// Gauss-Newton Hessian `J'WJ` is then the same at every stage, and the solver was not
            /// generated with the exact Hessian), `N` otherwise.
            pub const NH: usize = #nh;
            /// Interval length in seconds.
            pub const DT: Real = #dt;
        }
    }

    /// One `Range<usize>` constant per named state (`STATE_P`), control (`CONTROL_W`) and
    /// parameter (`PARAM_XREF`).
    pub(super) fn named_ranges(&self) -> TokenStream {
        let l = self.l;
        let states = l
            .states
            .iter()
            .map(|v| range_const("STATE", v, "the state"));
        let controls = l
            .controls
            .iter()
            .map(|v| range_const("CONTROL", v, "the control"));
        let params = (l.params.iter()).map(|v| range_const("PARAM", v, "the parameter vector"));
        quote!(#(#states)* #(#controls)* #(#params)*)
    }

    /// The model's data: initial guesses, parameter defaults, bounds and slack penalties.
    pub(super) fn model_data(&self) -> TokenStream {
        let (l, s) = (self.l, self.s);
        let (x_guess, u_guess, p_default) = (
            lits(&l.x_guess, s),
            lits(&l.u_guess, s),
            lits(&l.p_default, s),
        );
        let (lbx, ubx, lbu, ubu) = (
            lits(&l.lbx, s),
            lits(&l.ubx, s),
            lits(&l.lbu, s),
            lits(&l.ubu, s),
        );
        let (lg, ug, lgn, ugn) = (
            lits(&l.lg, s),
            lits(&l.ug, s),
            lits(&l.lgn, s),
            lits(&l.ugn, s),
        );
        let (l1, l2, l1n, l2n) = (
            lits(&l.l1, s),
            lits(&l.l2, s),
            lits(&l.l1n, s),
            lits(&l.l2n, s),
        );
        let (ng, ngn) = (self.ng_qp(), self.ngn_qp());
        quote! {
            /// Initial guess of the solver state.
            pub const X_GUESS: [Real; NX] = #x_guess;
            /// Initial guess of the control.
            pub const U_GUESS: [Real; NU] = #u_guess;
            /// Default parameter values.
            pub const P_DEFAULT: [Real; NP] = #p_default;
            /// State lower bounds (stages `1..=N`; infinite = none).
            pub const LBX: [Real; NX] = #lbx;
            /// State upper bounds.
            pub const UBX: [Real; NX] = #ubx;
            /// Control lower bounds.
            pub const LBU: [Real; NU] = #lbu;
            /// Control upper bounds.
            pub const UBU: [Real; NU] = #ubu;
            /// Stage constraint lower bounds.
            pub const LG: [Real; #ng] = #lg;
            /// Stage constraint upper bounds.
            pub const UG: [Real; #ng] = #ug;
            /// Terminal constraint lower bounds.
            pub const LGN: [Real; #ngn] = #lgn;
            /// Terminal constraint upper bounds.
            pub const UGN: [Real; #ngn] = #ugn;
            /// L1 slack penalties of the stage constraints (0 with `L2` 0: hard).
            pub const L1: [Real; #ng] = #l1;
            /// L2 slack penalties of the stage constraints.
            pub const L2: [Real; #ng] = #l2;
            /// L1 slack penalties of the terminal constraints.
            pub const L1N: [Real; #ngn] = #l1n;
            /// L2 slack penalties of the terminal constraints.
            pub const L2N: [Real; #ngn] = #l2n;
        }
    }

    /// `type Rti` (the runtime solver with this crate's dimensions) and the `const` vectors
    /// that `Solver::unconfigured` and `configure` start from.
    pub(super) fn rti_type(&self) -> TokenStream {
        let (ng, ngn) = (self.ng_qp(), self.ngn_qp());
        quote! {
            /// The runtime solver this crate instantiates.
            pub type Rti =
                mpc_runtime::Rti<Real, Model, NX, NU, NP, NY, NYN, #ng, #ngn, N, NC, NBX, NR, NH>;

            const P_ZERO: SVector<Real, NP> =
                SVector::from_array_storage(mpc_runtime::nalgebra::ArrayStorage([[0.0; NP]]));
            const U_ZERO: SVector<Real, NU> =
                SVector::from_array_storage(mpc_runtime::nalgebra::ArrayStorage([[0.0; NU]]));
            const X0: SVector<Real, NX_MODEL> = SVector::from_array_storage(
                mpc_runtime::nalgebra::ArrayStorage([[0.0; NX_MODEL]]),
            );
            const U0: SVector<Real, NU> =
                SVector::from_array_storage(mpc_runtime::nalgebra::ArrayStorage([U_GUESS]));
        }
    }

    /// `default_settings()`: the runtime's defaults with the generation options' QP settings
    /// and shift.
    pub(super) fn default_settings(&self) -> TokenStream {
        let fields = self.settings_fields();
        let settings = if fields.is_empty() {
            quote!(RtiSettings::DEFAULT)
        } else {
            quote! {
                let mut s = RtiSettings::DEFAULT;
                #(#fields)*
                s
            }
        };
        quote! {
            /// The settings this solver was generated with.
            pub fn default_settings() -> RtiSettings<Real> {
                #settings
            }
        }
    }

    /// One assignment to `s` (the settings) per option given.
    fn settings_fields(&self) -> Vec<TokenStream> {
        let (qp, s) = (&self.opts.qp, self.s);
        let mut fields = Vec::new();
        if let Some(m) = qp.max_iter {
            let m = proc_macro2::Literal::u32_unsuffixed(m);
            fields.push(quote!(s.qp.max_iter = #m;));
        }
        if let Some(t) = qp.tol {
            let t = lit(t, s);
            fields.push(quote! {
                s.qp.tol_stat = #t;
                s.qp.tol_eq = #t;
                s.qp.tol_ineq = #t;
            });
        }
        if let Some(t) = qp.tol_comp {
            let t = lit(t, s);
            fields.push(quote!(s.qp.tol_comp = #t;));
        }
        if let Some(b) = qp.warm_start_dual {
            fields.push(quote!(s.qp.warm_start_dual = #b;));
        }
        // The generator's option wins over the model's choice.
        if let Some(b) = self.opts.shift.or(self.l.shift) {
            fields.push(quote!(s.shift = #b;));
        }
        match qp.method {
            Some(QpMethod::Condensed) => {
                fields.push(quote!(s.qp.method = mpc_runtime::QpMethod::Condensed;));
            }
            Some(QpMethod::Riccati) => {
                fields.push(quote!(s.qp.method = mpc_runtime::QpMethod::Riccati;));
            }
            Some(QpMethod::Auto) | None => {}
        }
        fields
    }
}

/// Upper-case constant name for a model name.
fn const_name(prefix: &str, name: &str) -> Ident {
    format_ident!("{}_{}", prefix, name.to_uppercase())
}

/// `<PREFIX>_<NAME>: Range<usize>`, the entries of `v` in its vector (`what`).
fn range_const(prefix: &str, v: &Named, what: &str) -> TokenStream {
    let c = const_name(prefix, &v.name);
    let (a, b) = (ul(v.offset), ul(v.offset + v.len));
    let d = doc_lines(&format!(
        "Entries of {what} `{}` {}{}.",
        v.name,
        if v.doc.is_empty() { "" } else { ": " },
        doc_text(&v.doc)
    ));
    quote!(#d pub const #c: core::ops::Range<usize> = #a..#b;)
}
