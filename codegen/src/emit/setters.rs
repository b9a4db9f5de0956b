//! The `Solver`'s setters: the measured state, the parameter vectors, one setter per named
//! parameter, the run-time bounds and the trajectory guess. Every setter checks its input
//! (NaN/inf, stage range, crossed bounds) and changes nothing when it refuses it.
//!
//! To add a setter: a function here that returns its `pub fn` (with its doc), called from
//! [`items`](super::items) where it belongs in the `impl Solver`, and, for C callers, its
//! `extern "C"` twin on `CAbi` (`c_abi.rs`), listed in [`ffi`](super::ffi), and its
//! declaration in `codegen/templates/header.h.tera` (`docs/codegen.md`, "Where to change
//! what").

use proc_macro2::TokenStream;
use quote::{format_ident, quote};

use super::{Emitter, allow_case, doc_lines, doc_text, ul};
use crate::lower::Named;

impl Emitter<'_> {
    /// `set_x0`: the measured state.
    pub(super) fn x0_setter(&self) -> TokenStream {
        quote! {
            /// Sets the measured state used by the next [`feedback`](Self::feedback).
            ///
            /// # Errors
            /// [`SetError::NonFinite`]; the previous state is kept then.
            pub fn set_x0(&mut self, x0: &[Real; NX_MODEL]) -> Result<(), SetError> {
                if !x0.iter().all(|e| e.is_finite()) {
                    return Err(SetError::NonFinite);
                }
                self.x0 = SVector::from(*x0);
                Ok(())
            }
        }
    }

    /// `set_param`, `set_param_all`, `param` (whole parameter vectors) and the private
    /// `update_weights` they call.
    pub(super) fn param_setters(&self) -> TokenStream {
        let n1 = ul(self.l.n + 1);
        quote! {
            /// Sets the whole parameter vector of stage `k <= N`. At stage 0 the weights
            /// are evaluated from it and checked first.
            ///
            /// # Errors
            /// [`SetError::NonFinite`], [`SetError::StageOutOfRange`],
            /// [`SetError::NegativeWeight`] (stage 0: the weights it gives are not positive
            /// semidefinite); nothing changes then.
            pub fn set_param(&mut self, k: usize, p: &[Real; NP]) -> Result<(), SetError> {
                let v = SVector::from(*p);
                if !p.iter().all(|e| e.is_finite()) {
                    return Err(SetError::NonFinite);
                }
                if k > N {
                    return Err(SetError::StageOutOfRange);
                }
                if k == 0 {
                    self.update_weights(&v)?;
                }
                self.rti.set_param(k, &v)?;
                self.p[k] = v;
                Ok(())
            }

            /// Sets the parameter vector of every stage (the weights checked first).
            ///
            /// # Errors
            /// [`SetError::NonFinite`], [`SetError::NegativeWeight`]; nothing changes then.
            pub fn set_param_all(&mut self, p: &[Real; NP]) -> Result<(), SetError> {
                let v = SVector::from(*p);
                if !p.iter().all(|e| e.is_finite()) {
                    return Err(SetError::NonFinite);
                }
                self.update_weights(&v)?;
                self.rti.set_param_all(&v)?;
                self.p = [v; #n1];
                Ok(())
            }

            /// The parameters of stage `k <= N`.
            pub fn param(&self, k: usize) -> Option<[Real; NP]> {
                self.p.get(k).map(|p| (*p).into())
            }

            /// The weights from stage-0 parameters `p0`, set (checked: nothing changes if
            /// they are refused).
            fn update_weights(&mut self, p0: &SVector<Real, NP>) -> Result<(), SetError> {
                let mut w = SMatrix::<Real, NY, NY>::zeros();
                let mut wn = SMatrix::<Real, NYN, NYN>::zeros();
                functions::weights(p0, &mut w, &mut wn);
                self.rti.set_weights(&w, &wn)
            }
        }
    }

    /// One setter per named parameter, in the model's order: `set_<name>(k, ..)` and
    /// `set_<name>_all(..)` for a per-stage one, `set_<name>(..)` for a global one.
    pub(super) fn named_param_setters(&self) -> TokenStream {
        let setters = self.l.params.iter().map(|v| {
            let value = ParamValue::of(v);
            if v.per_stage {
                stage_param_setters(v, &value)
            } else {
                global_param_setter(v, &value)
            }
        });
        quote!(#(#setters)*)
    }

    /// `set_guess`: the trajectory guess (with an input-rate cost, the guess of the last
    /// applied control is `u`).
    pub(super) fn guess_setter(&self) -> TokenStream {
        let u_last = self.l.u_prev.as_ref().map(|_| {
            let g = (0..self.l.nu).map(|i| {
                let (xi, i) = (ul(self.l.nx_model + i), ul(i));
                quote!(xa[#xi] = u[#i];)
            });
            quote!(#(#g)*)
        });
        quote! {
            /// Sets the trajectory guess: `x` at every stage, `u` at every stage.
            ///
            /// # Errors
            /// [`SetError::NonFinite`]; nothing changes then.
            pub fn set_guess(&mut self, x: &[Real; NX_MODEL], u: &[Real; NU]) -> Result<(), SetError> {
                let mut xa = SVector::<Real, NX>::zeros();
                for (i, &e) in x.iter().enumerate() {
                    xa[i] = e;
                }
                #u_last
                self.rti.set_guess(&xa, &SVector::from(*u))
            }
        }
    }
}

/// How a named parameter's setter takes its value and copies it into a parameter vector
/// `p`: a `Real` for a scalar, an array for a vector.
struct ParamValue {
    /// The argument's type.
    ty: TokenStream,
    /// The statements copying `value` into `p`.
    copy: TokenStream,
    /// The check that `value` is finite.
    finite: TokenStream,
    /// The parameter's description for the setter's doc (` (..)`, or empty).
    doc: String,
}

impl ParamValue {
    fn of(v: &Named) -> ParamValue {
        let (off, len) = (ul(v.offset), ul(v.len));
        let (ty, copy, finite) = if v.scalar {
            (
                quote!(Real),
                quote!(p[#off] = value;),
                quote!(value.is_finite()),
            )
        } else {
            (
                quote!(&[Real; #len]),
                quote! {
                    for (i, &e) in value.iter().enumerate() {
                        p[#off + i] = e;
                    }
                },
                quote!(value.iter().all(|e| e.is_finite())),
            )
        };
        let doc = if v.doc.is_empty() {
            String::new()
        } else {
            format!(" ({})", doc_text(&v.doc))
        };
        ParamValue {
            ty,
            copy,
            finite,
            doc,
        }
    }
}

/// `set_<name>(k, value)` and `set_<name>_all(value)` for a per-stage parameter.
fn stage_param_setters(v: &Named, value: &ParamValue) -> TokenStream {
    let set = format_ident!("set_{}", v.name);
    let set_all = format_ident!("set_{}_all", v.name);
    let (case, case_all) = (
        allow_case(&set.to_string()),
        allow_case(&set_all.to_string()),
    );
    let ParamValue {
        ty, copy, finite, ..
    } = value;
    let d = doc_lines(&format!(
        "Sets parameter `{}`{} at stage `k <= N`.\n\n# Errors\n\
         [`SetError::NonFinite`], [`SetError::StageOutOfRange`], [`SetError::NegativeWeight`] \
         (weights from it not positive semidefinite); nothing changes then.",
        v.name, value.doc
    ));
    let d_all = doc_lines(&format!(
        "Sets parameter `{}`{} at every stage `0..=N`.\n\n# Errors\n\
         [`SetError::NonFinite`]; nothing changes then.",
        v.name, value.doc
    ));
    quote! {
        #d
        #case
        pub fn #set(&mut self, k: usize, value: #ty) -> Result<(), SetError> {
            if !(#finite) {
                return Err(SetError::NonFinite);
            }
            let mut p = *self.p.get(k).ok_or(SetError::StageOutOfRange)?;
            #copy
            self.set_param(k, &p.into())
        }
        #d_all
        #case_all
        pub fn #set_all(&mut self, value: #ty) -> Result<(), SetError> {
            if !(#finite) {
                return Err(SetError::NonFinite);
            }
            for k in 0..=N {
                let mut p = self.p[k];
                #copy
                self.set_param(k, &p.into())?;
            }
            Ok(())
        }
    }
}

/// `set_<name>(value)` for a global parameter: every stage, only its own entries.
fn global_param_setter(v: &Named, value: &ParamValue) -> TokenStream {
    let set = format_ident!("set_{}", v.name);
    let case = allow_case(&set.to_string());
    let ParamValue {
        ty, copy, finite, ..
    } = value;
    let d = doc_lines(&format!(
        "Sets global parameter `{}`{} (every stage; the weights are \
         re-evaluated and checked first).\n\n# Errors\n[`SetError::NonFinite`], \
         [`SetError::NegativeWeight`] (the weights from it are not positive semidefinite); \
         nothing changes then.",
        v.name, value.doc
    ));
    quote! {
        #d
        #case
        pub fn #set(&mut self, value: #ty) -> Result<(), SetError> {
            if !(#finite) {
                return Err(SetError::NonFinite);
            }
            // Only this parameter's entries change; per-stage ones are kept.
            for k in 0..=N {
                let mut p = self.p[k];
                #copy
                self.set_param(k, &p.into())?;
            }
            Ok(())
        }
    }
}

/// The `Solver`'s run-time bounds: setters and getters for the control and model-state box
/// bounds and the general constraints' stage and terminal rows. A setter goes through
/// `Rti::set_bounds` / `Rti::set_constraint_bounds` with the other bounds as they are, so it
/// checks everything before it changes anything.
pub(super) fn bounds_api() -> TokenStream {
    let takes_effect = "It applies from the next [`prepare`](Self::prepare) or \
        [`solve_sqp`](Self::solve_sqp): a [`feedback`](Self::feedback) solves the QP of the \
        last preparation, with the bounds it had.";
    let errors = "`Real::INFINITY` (`-Real::INFINITY` below) means unbounded.\n\n# Errors\n\
        [`SetError::NonFinite`] for NaN, a lower bound `+inf` or an upper bound `-inf`; \
        [`SetError::CrossedBounds`] if a lower bound exceeds its upper bound";
    let nothing = "Nothing changes on error.";
    let doc = |what: &str, extra: &str| {
        doc_lines(&format!(
            "{what} {takes_effect}\n\n{errors}{extra}. {nothing}"
        ))
    };
    let set_u = doc(
        "Sets the control bounds `lb <= u_k <= ub` of every stage `k < N`.",
        "",
    );
    let set_x = doc(
        "Sets the bounds `lb <= x_k <= ub` of the model states at stages `1..=N` (the \
         measured `x_0` is not bounded); the states an input-rate cost appends keep theirs.",
        ";\n[`SetError::TooManyStateBounds`] if more states would have a bound (either side \
         finite) than the solver has state-bound rows, [`NBX`] (the states the model file \
         bounds: none for a model without state bounds)",
    );
    let set_g = doc(
        "Sets the bounds `lg <= h(x_k, u_k, p_k) <= ug` of the general constraints at every \
         stage `k < N` (soft rows keep their penalties).",
        "",
    );
    let set_gn = doc(
        "Sets the bounds `lgn <= h_N(x_N, p_N) <= ugn` of the terminal constraints (soft rows \
         keep their penalties).",
        "",
    );
    quote! {
        #set_u
        pub fn set_control_bounds(&mut self, lb: &[Real; NU], ub: &[Real; NU]) -> Result<(), SetError> {
            let (lbx, ubx, _, _) = self.rti.bounds();
            let (lbx, ubx) = (*lbx, *ubx);
            self.rti.set_bounds(&lbx, &ubx, &SVector::from(*lb), &SVector::from(*ub))
        }

        /// The control bounds in use, `(lb, ub)` (infinite where unbounded).
        pub fn control_bounds(&self) -> ([Real; NU], [Real; NU]) {
            let (_, _, lbu, ubu) = self.rti.bounds();
            ((*lbu).into(), (*ubu).into())
        }

        #set_x
        pub fn set_state_bounds(&mut self, lb: &[Real; NX_MODEL], ub: &[Real; NX_MODEL]) -> Result<(), SetError> {
            let (lbx, ubx, lbu, ubu) = self.rti.bounds();
            let model = |new: &[Real; NX_MODEL], old: &SVector<Real, NX>| {
                SVector::<Real, NX>::from_fn(|i, _| new.get(i).copied().unwrap_or(old[i]))
            };
            let (lbx, ubx, lbu, ubu) = (model(lb, lbx), model(ub, ubx), *lbu, *ubu);
            self.rti.set_bounds(&lbx, &ubx, &lbu, &ubu)
        }

        /// The model-state bounds in use, `(lb, ub)` (infinite where unbounded).
        pub fn state_bounds(&self) -> ([Real; NX_MODEL], [Real; NX_MODEL]) {
            let (lbx, ubx, _, _) = self.rti.bounds();
            (
                core::array::from_fn(|i| lbx[i]),
                core::array::from_fn(|i| ubx[i]),
            )
        }

        #set_g
        pub fn set_constraint_bounds(&mut self, lg: &[Real; NG], ug: &[Real; NG]) -> Result<(), SetError> {
            let (_, _, lgn, ugn) = self.rti.constraint_bounds();
            let (lgn, ugn) = (*lgn, *ugn);
            self.rti.set_constraint_bounds(&SVector::from(*lg), &SVector::from(*ug), &lgn, &ugn)
        }

        /// The stage constraint bounds in use, `(lg, ug)` (infinite where unbounded).
        pub fn constraint_bounds(&self) -> ([Real; NG], [Real; NG]) {
            let (lg, ug, _, _) = self.rti.constraint_bounds();
            ((*lg).into(), (*ug).into())
        }

        #set_gn
        pub fn set_terminal_constraint_bounds(&mut self, lgn: &[Real; NGN], ugn: &[Real; NGN]) -> Result<(), SetError> {
            let (lg, ug, _, _) = self.rti.constraint_bounds();
            let (lg, ug) = (*lg, *ug);
            self.rti.set_constraint_bounds(&lg, &ug, &SVector::from(*lgn), &SVector::from(*ugn))
        }

        /// The terminal constraint bounds in use, `(lgn, ugn)` (infinite where unbounded).
        pub fn terminal_constraint_bounds(&self) -> ([Real; NGN], [Real; NGN]) {
            let (_, _, lgn, ugn) = self.rti.constraint_bounds();
            ((*lgn).into(), (*ugn).into())
        }
    }
}
