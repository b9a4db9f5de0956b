//! The generated API of soft state and control bounds (`lower/soft_bounds.rs` lowers them
//! to the last general rows). A model without soft bounds gets none of this, and its code is
//! that of the generator before the feature, byte for byte.
//!
//! With soft bounds, `NG` and `NGN` stay the model's own rows (what `set_constraint_bounds`,
//! `soft_penalties`, `slacks` and the multipliers take and give), `NG_QP` and `NGN_QP` are the
//! runtime's (the model's rows, then the soft bounds'), and the bounds' setters and getters
//! present the soft entries as bounds: `set_state_bounds` writes a soft entry's bound into its
//! rows (and leaves its box bound infinite), `state_bounds` reads it back from them.

use proc_macro2::TokenStream;
use quote::quote;

use super::c_abi::CAbi;
use super::{Emitter, ul};

impl Emitter<'_> {
    /// Whether the model has soft bounds.
    pub(super) fn has_soft_bounds(&self) -> bool {
        !self.l.soft_bounds.is_empty()
    }

    /// The runtime's stage row count: `NG`, or `NG_QP` with soft bounds.
    pub(super) fn ng_qp(&self) -> TokenStream {
        if self.has_soft_bounds() {
            quote!(NG_QP)
        } else {
            quote!(NG)
        }
    }

    /// The runtime's terminal row count: `NGN`, or `NGN_QP` with soft bounds.
    pub(super) fn ngn_qp(&self) -> TokenStream {
        if self.has_soft_bounds() {
            quote!(NGN_QP)
        } else {
            quote!(NGN)
        }
    }

    /// `[Real; NG]` from the runtime's rows `v` (an `SVector` or a reference to one):
    /// `v.into()`, or its first `NG` rows with soft bounds.
    pub(super) fn model_rows(&self, v: TokenStream) -> TokenStream {
        if self.has_soft_bounds() {
            quote!(take_rows(&#v, 0))
        } else {
            quote!(#v.into())
        }
    }

    /// With soft bounds: the constants `NG_QP`, `NGN_QP`, `NSBU`, `NSBX`,
    /// `SOFT_CONTROL_BOUNDS`, `SOFT_STATE_BOUNDS` and the private row helpers.
    pub(super) fn soft_bound_items(&self) -> TokenStream {
        if !self.has_soft_bounds() {
            return quote!();
        }
        let (l, sb) = (self.l, &self.l.soft_bounds);
        let (ng_qp, ngn_qp) = (ul(l.ng), ul(l.ngn));
        let (nsbu, nsbx) = (ul(sb.controls.len()), ul(sb.states.len()));
        let idx_u = sb.controls.iter().map(|&j| ul(j));
        let idx_x = sb.states.iter().map(|&j| ul(j));
        quote! {
            /// Stage rows of the QP: the model's `NG` general constraints, then one row per
            /// soft control bound and one per soft state bound.
            pub const NG_QP: usize = #ng_qp;
            /// Terminal rows of the QP: the model's `NGN`, then one per soft state bound.
            pub const NGN_QP: usize = #ngn_qp;
            /// Controls with a soft bound.
            pub const NSBU: usize = #nsbu;
            /// Model states with a soft bound.
            pub const NSBX: usize = #nsbx;
            /// The controls with a soft bound, in the order of
            /// [`Solver::control_bound_penalties`] (acados' `idxsbu`).
            pub const SOFT_CONTROL_BOUNDS: [usize; NSBU] = [#(#idx_u),*];
            /// The model states with a soft bound, in the order of
            /// [`Solver::state_bound_penalties`] (acados' `idxsbx`).
            pub const SOFT_STATE_BOUNDS: [usize; NSBX] = [#(#idx_x),*];

            /// `K` rows of `rows` from `first`.
            fn take_rows<const R: usize, const K: usize>(rows: &SVector<Real, R>, first: usize) -> [Real; K] {
                core::array::from_fn(|r| rows.get(first + r).copied().unwrap_or(0.0))
            }

            /// `rows` with `K` rows from `first` replaced by `v`.
            fn put_rows<const R: usize, const K: usize>(rows: &SVector<Real, R>, first: usize, v: &[Real; K]) -> SVector<Real, R> {
                let mut out = *rows;
                for (r, &e) in v.iter().enumerate() {
                    if let Some(o) = out.get_mut(first + r) {
                        *o = e;
                    }
                }
                out
            }

            /// `rows` with the rows from `first` set to the entries `idx` of `v` (the soft
            /// entries' bounds).
            fn soft_rows<const R: usize, const M: usize, const K: usize>(
                rows: &SVector<Real, R>,
                first: usize,
                v: &[Real; M],
                idx: &[usize; K],
            ) -> SVector<Real, R> {
                let picked: [Real; K] = core::array::from_fn(|r| {
                    idx.get(r).and_then(|&j| v.get(j)).copied().unwrap_or(0.0)
                });
                put_rows(rows, first, &picked)
            }

            /// `v` with the entries `idx` set to `fill` (a soft entry's box bound is
            /// infinite: its rows hold it).
            fn hard_entries<const M: usize, const K: usize>(v: &[Real; M], idx: &[usize; K], fill: Real) -> [Real; M] {
                let mut out = *v;
                for &j in idx {
                    if let Some(e) = out.get_mut(j) {
                        *e = fill;
                    }
                }
                out
            }

            /// The first `M` entries of `v`, the entries `idx` read from the rows of `rows`
            /// from `first` (a soft entry's bound).
            fn with_soft_rows<const V: usize, const R: usize, const M: usize, const K: usize>(
                v: &SVector<Real, V>,
                rows: &SVector<Real, R>,
                first: usize,
                idx: &[usize; K],
            ) -> [Real; M] {
                let mut out: [Real; M] = core::array::from_fn(|i| v.get(i).copied().unwrap_or(0.0));
                for (r, &j) in idx.iter().enumerate() {
                    if let (Some(o), Some(&e)) = (out.get_mut(j), rows.get(first + r)) {
                        *o = e;
                    }
                }
                out
            }

            /// Refuses a pair of penalties that are both zero: a soft bound's row would be
            /// hard, also at stage 0, where the measured state may violate it.
            fn some_penalty<const K: usize>(l1: &[Real; K], l2: &[Real; K]) -> Result<(), SetError> {
                if l1.iter().zip(l2).any(|(&a, &b)| a == 0.0 && b == 0.0) {
                    return Err(SetError::InvalidSetting);
                }
                Ok(())
            }
        }
    }
}

impl CAbi<'_> {
    /// With soft bounds: `<prefix>_set_control_bound_penalties`, `_get_control_bound_penalties`
    /// and the state pair, over the `Solver` methods of the same names.
    pub(super) fn soft_bound_penalty_fns(&self) -> TokenStream {
        if self.l.soft_bounds.is_empty() {
            return quote!();
        }
        let pairs = [("control", quote!(NSBU)), ("state", quote!(NSBX))];
        let fns = pairs.into_iter().map(|(kind, len)| {
            let (set_c, get_c) = (
                self.sym(&format!("set_{kind}_bound_penalties")),
                self.sym(&format!("get_{kind}_bound_penalties")),
            );
            let set = quote::format_ident!("set_{kind}_bound_penalties");
            let get = quote::format_ident!("{kind}_bound_penalties");
            quote! {
                /// C: see the header.
                ///
                /// # Safety
                /// `s` from `create`; `l1`, `l2` point to the soft bounds' values.
                #[unsafe(no_mangle)]
                pub unsafe extern "C" fn #set_c(s: *mut Solver, l1: *const Real, l2: *const Real) -> c_int {
                    let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                    match (take::<#len>(l1), take::<#len>(l2)) {
                        (Ok(a), Ok(b)) => code(s.#set(&a, &b)),
                        (Err(e), _) | (_, Err(e)) => e,
                    }
                }

                /// C: see the header.
                ///
                /// # Safety
                /// `s` from `create`; `l1`, `l2` have room for the soft bounds' values.
                #[unsafe(no_mangle)]
                pub unsafe extern "C" fn #get_c(s: *const Solver, l1: *mut Real, l2: *mut Real) -> c_int {
                    let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                    put_pair(l1, l2, Some(s.#get()))
                }
            }
        });
        quote!(#(#fns)*)
    }
}
