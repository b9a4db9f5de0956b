//! The generated C ABI (`pub mod ffi`): status codes and the conversions every function
//! uses, then one `extern "C"` function per `Solver` method, named `<prefix>_<method>`
//! (`<prefix>` the crate name). Each checks its pointers, returns a status code and cannot
//! panic. Their C declarations are in `codegen/templates/header.h.tera`, which must follow.

use proc_macro2::{Ident, TokenStream};
use quote::{format_ident, quote};

use super::{allow_case, ul};
use crate::lower::{Lowered, Named};

/// The C ABI's emitter: the lowered model and the symbol prefix.
pub(super) struct CAbi<'a> {
    pub(super) l: &'a Lowered,
    prefix: String,
}

impl<'a> CAbi<'a> {
    pub(super) fn new(l: &'a Lowered, prefix: String) -> CAbi<'a> {
        CAbi { l, prefix }
    }

    /// The exported symbol `<prefix>_<name>`.
    pub(super) fn sym(&self, name: &str) -> Ident {
        format_ident!("{}_{}", self.prefix, name)
    }

    /// `memsize`, `memalign` and `create` (the solver in the caller's memory).
    pub(super) fn memory(&self) -> TokenStream {
        let (memsize, memalign, create) = (
            self.sym("memsize"),
            self.sym("memalign"),
            self.sym("create"),
        );
        quote! {
            /// Bytes of memory a solver needs.
            #[unsafe(no_mangle)]
            pub extern "C" fn #memsize() -> usize {
                core::mem::size_of::<Solver>()
            }

            /// Alignment, in bytes, the solver memory needs.
            #[unsafe(no_mangle)]
            pub extern "C" fn #memalign() -> usize {
                core::mem::align_of::<Solver>()
            }

            /// Builds a configured solver in `mem`; `*out` is written only on success.
            ///
            /// # Safety
            /// `mem` points to `size` writable bytes that outlive the solver; `out` is
            /// writable.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #create(mem: *mut c_void, size: usize, out: *mut *mut Solver) -> c_int {
                if mem.is_null() || out.is_null() {
                    return ERR_NULL;
                }
                if size < core::mem::size_of::<Solver>() {
                    return ERR_SIZE;
                }
                if !(mem as usize).is_multiple_of(core::mem::align_of::<Solver>()) {
                    return ERR_ALIGN;
                }
                let s = mem.cast::<Solver>();
                // SAFETY: `mem` is non-null, large enough and aligned (checked above) and
                // does not overlap the static.
                unsafe {
                    core::ptr::copy_nonoverlapping(&UNCONFIGURED, s, 1);
                    let r = code((*s).configure());
                    if r == 0 {
                        out.write(s);
                    }
                    r
                }
            }
        }
    }

    /// `set_x0`, `set_param` and `set_param_all`.
    pub(super) fn x0_and_param_setters(&self) -> TokenStream {
        let (set_x0, set_param, set_param_all) = (
            self.sym("set_x0"),
            self.sym("set_param"),
            self.sym("set_param_all"),
        );
        // A model without parameters takes NULL (a `NP > 0` test in the generated code
        // would be a comparison clippy calls absurd).
        let p_null = (self.l.np > 0).then(|| {
            quote! {
                if p.is_null() {
                    return ERR_NULL;
                }
            }
        });
        quote! {
            /// Sets the measured state (`NX_MODEL` values).
            ///
            /// # Safety
            /// `s` from `create`; `x0` points to `NX_MODEL` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set_x0(s: *mut Solver, x0: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                if x0.is_null() {
                    return ERR_NULL;
                }
                code(s.set_x0(&read::<NX_MODEL>(x0)))
            }

            /// Sets the parameters of one stage (`NP` values).
            ///
            /// # Safety
            /// `s` from `create`; `p` points to `NP` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set_param(s: *mut Solver, stage: c_int, p: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                #p_null
                let Ok(k) = usize::try_from(stage) else { return ERR_STAGE };
                code(s.set_param(k, &read::<NP>(p)))
            }

            /// Sets the parameters of every stage (`NP` values).
            ///
            /// # Safety
            /// `s` from `create`; `p` points to `NP` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set_param_all(s: *mut Solver, p: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                #p_null
                code(s.set_param_all(&read::<NP>(p)))
            }
        }
    }

    /// `<prefix>_set_<name>` per named parameter (with a `stage` argument for a per-stage
    /// one), over the `Solver`'s `set_<name>`.
    pub(super) fn named_param_setters(&self) -> TokenStream {
        let setters = self.l.params.iter().map(|v| self.named_param_setter(v));
        quote!(#(#setters)*)
    }

    fn named_param_setter(&self, v: &Named) -> TokenStream {
        let cfn = self.sym(&format!("set_{}", v.name));
        let rs = format_ident!("set_{}", v.name);
        let case = allow_case(&cfn.to_string());
        let len = ul(v.len);
        let value = if v.scalar {
            quote!(unsafe { *value })
        } else {
            quote!(&read::<#len>(value))
        };
        if v.per_stage {
            quote! {
                /// C: see the header.
                ///
                /// # Safety
                /// `s` from `create`; `value` points to the parameter's entries.
                #[unsafe(no_mangle)]
                #case
                pub unsafe extern "C" fn #cfn(s: *mut Solver, stage: c_int, value: *const Real) -> c_int {
                    let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                    if value.is_null() {
                        return ERR_NULL;
                    }
                    let Ok(k) = usize::try_from(stage) else { return ERR_STAGE };
                    code(s.#rs(k, #value))
                }
            }
        } else {
            quote! {
                /// C: see the header.
                ///
                /// # Safety
                /// `s` from `create`; `value` points to the parameter's entries.
                #[unsafe(no_mangle)]
                #case
                pub unsafe extern "C" fn #cfn(s: *mut Solver, value: *const Real) -> c_int {
                    let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                    if value.is_null() {
                        return ERR_NULL;
                    }
                    code(s.#rs(#value))
                }
            }
        }
    }

    /// `set_guess`.
    pub(super) fn guess_setter(&self) -> TokenStream {
        let set_guess = self.sym("set_guess");
        quote! {
            /// Sets the trajectory guess.
            ///
            /// # Safety
            /// `s` from `create`; `x` points to `NX_MODEL` values, `u` to `NU`.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set_guess(s: *mut Solver, x: *const Real, u: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                if x.is_null() || u.is_null() {
                    return ERR_NULL;
                }
                code(s.set_guess(&read::<NX_MODEL>(x), &read::<NU>(u)))
            }
        }
    }

    /// The bound setters and getters (`<prefix>_set_control_bounds`,
    /// `<prefix>_get_control_bounds` and the same for the state, constraint and terminal
    /// constraint bounds), each a pair over the `Solver` methods of
    /// [`bounds_api`](super::setters::bounds_api). NULL is refused unless the bounds have no
    /// entries (a model without general constraints).
    pub(super) fn bounds(&self) -> TokenStream {
        let l = self.l;
        let kinds = [
            ("control", quote!(NU), l.nu),
            ("state", quote!(NX_MODEL), l.nx_model),
            ("constraint", quote!(NG), l.soft_bounds.ng_model),
            ("terminal_constraint", quote!(NGN), l.soft_bounds.ngn_model),
        ];
        let fns = kinds
            .into_iter()
            .map(|(kind, len, entries)| self.bounds_pair(kind, &len, entries));
        quote!(#(#fns)*)
    }

    /// `<prefix>_set_<kind>_bounds` and `<prefix>_get_<kind>_bounds`.
    fn bounds_pair(&self, kind: &str, len: &TokenStream, entries: usize) -> TokenStream {
        let (set_c, get_c) = (
            self.sym(&format!("set_{kind}_bounds")),
            self.sym(&format!("get_{kind}_bounds")),
        );
        let (set, get) = (
            format_ident!("set_{kind}_bounds"),
            format_ident!("{kind}_bounds"),
        );
        let null = if entries > 0 {
            quote! {
                if lb.is_null() || ub.is_null() {
                    return ERR_NULL;
                }
            }
        } else {
            quote!()
        };
        quote! {
            /// C: see the header.
            ///
            /// # Safety
            /// `s` from `create`; `lb` and `ub` point to the bounds' entries.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set_c(s: *mut Solver, lb: *const Real, ub: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                #null
                code(s.#set(&read::<#len>(lb), &read::<#len>(ub)))
            }

            /// C: see the header.
            ///
            /// # Safety
            /// `s` from `create`; `lb` and `ub` have room for the bounds' entries.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #get_c(s: *const Solver, lb: *mut Real, ub: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                #null
                let (l, h) = s.#get();
                write(lb, &l);
                write(ub, &h);
                0
            }
        }
    }

    /// `set_qp_max_iter`.
    pub(super) fn qp_max_iter_setter(&self) -> TokenStream {
        let set_max_iter = self.sym("set_qp_max_iter");
        quote! {
            /// Sets the QP iteration limit (bounds the worst-case feedback time).
            ///
            /// # Safety
            /// `s` from `create`.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set_max_iter(s: *mut Solver, max_iter: c_uint) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                s.settings_mut().qp.max_iter = max_iter;
                0
            }
        }
    }

    /// `prepare`, `feedback` and `solve_sqp`.
    pub(super) fn phases(&self) -> TokenStream {
        let (prepare, feedback, solve_sqp) = (
            self.sym("prepare"),
            self.sym("feedback"),
            self.sym("solve_sqp"),
        );
        quote! {
            /// Preparation phase.
            ///
            /// # Safety
            /// `s` from `create`.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #prepare(s: *mut Solver) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                s.prepare();
                0
            }

            /// Feedback phase; returns the [`RtiStatus`].
            ///
            /// # Safety
            /// `s` from `create`.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #feedback(s: *mut Solver) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                s.feedback().status as c_int
            }

            /// Full SQP; returns the [`RtiStatus`].
            ///
            /// # Safety
            /// `s` from `create`.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #solve_sqp(s: *mut Solver) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                s.solve_sqp().status as c_int
            }
        }
    }

    /// `get_u0`, `get_control` and `get_state`.
    pub(super) fn getters(&self) -> TokenStream {
        let (get_u0, get_control, get_state) = (
            self.sym("get_u0"),
            self.sym("get_control"),
            self.sym("get_state"),
        );
        quote! {
            /// Copies the control of the last feedback (`NU` values).
            ///
            /// # Safety
            /// `s` from `create`; `u` has room for `NU` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #get_u0(s: *const Solver, u: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                if u.is_null() {
                    return ERR_NULL;
                }
                write(u, &s.u0());
                0
            }

            /// Copies control `stage < N` of the plan (`NU` values).
            ///
            /// # Safety
            /// `s` from `create`; `u` has room for `NU` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #get_control(s: *const Solver, stage: c_int, u: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                if u.is_null() {
                    return ERR_NULL;
                }
                let Some(v) = usize::try_from(stage).ok().and_then(|k| s.control(k)) else {
                    return ERR_STAGE;
                };
                write(u, &v);
                0
            }

            /// Copies state `stage <= N` of the plan (`NX_MODEL` values).
            ///
            /// # Safety
            /// `s` from `create`; `x` has room for `NX_MODEL` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #get_state(s: *const Solver, stage: c_int, x: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                if x.is_null() {
                    return ERR_NULL;
                }
                let Some(v) = usize::try_from(stage).ok().and_then(|k| s.state(k)) else {
                    return ERR_STAGE;
                };
                write(x, &v);
                0
            }
        }
    }

    /// `get_stats` (into [`stats_struct`]'s `Stats`).
    pub(super) fn stats_getter(&self) -> TokenStream {
        let get_stats = self.sym("get_stats");
        quote! {
            /// Copies the statistics of the last feedback / SQP solve (all zero before).
            ///
            /// # Safety
            /// `s` from `create`; `out` writable.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #get_stats(s: *const Solver, out: *mut Stats) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                let Some(out) = (unsafe { out.as_mut() }) else { return ERR_NULL };
                *out = match s.stats() {
                    Some(i) => Stats {
                        status: i.status as c_int,
                        qp_status: i.qp.status as c_int,
                        qp_iterations: i.qp.iterations,
                        sqp_iterations: i.sqp_iterations,
                        res_stat: i.qp.res_stat,
                        res_eq: i.qp.res_eq,
                        res_ineq: i.qp.res_ineq,
                        mu: i.qp.mu,
                        consecutive_failures: i.consecutive_failures,
                    },
                    None => Stats {
                        status: 0,
                        qp_status: 0,
                        qp_iterations: 0,
                        sqp_iterations: 0,
                        res_stat: 0.0,
                        res_eq: 0.0,
                        res_ineq: 0.0,
                        mu: 0.0,
                        consecutive_failures: 0,
                    },
                };
                0
            }
        }
    }
}

/// The status codes (`ERR_NULL` ... `ERR_INPUT`; the header repeats them).
pub(super) fn error_codes() -> TokenStream {
    quote! {
        /// A NULL pointer was passed.
        pub const ERR_NULL: c_int = -1;
        /// The memory given to `create` is too small.
        pub const ERR_SIZE: c_int = -2;
        /// The memory given to `create` is not aligned to `memalign`.
        pub const ERR_ALIGN: c_int = -3;
        /// A stage index is out of range.
        pub const ERR_STAGE: c_int = -4;
        /// An input value is NaN or infinite; nothing was changed.
        pub const ERR_NONFINITE: c_int = -5;
        /// A lower bound exceeds its upper bound.
        pub const ERR_BOUNDS: c_int = -6;
        /// Any other rejected input.
        pub const ERR_INPUT: c_int = -7;
    }
}

/// `struct Stats`, the `#[repr(C)]` statistics of `get_stats`.
pub(super) fn stats_struct() -> TokenStream {
    quote! {
        /// Statistics of the last feedback / SQP solve.
        #[repr(C)]
        #[derive(Clone, Copy, Debug)]
        pub struct Stats {
            /// [`RtiStatus`] as an integer.
            pub status: c_int,
            /// `QpStatus` of the last QP as an integer.
            pub qp_status: c_int,
            /// Interior-point iterations of the last QP.
            pub qp_iterations: c_uint,
            /// SQP iterations (1 per real-time iteration).
            pub sqp_iterations: c_uint,
            /// Stationarity residual of the last QP.
            pub res_stat: Real,
            /// Dynamics residual of the last QP.
            pub res_eq: Real,
            /// Inequality residual of the last QP.
            pub res_ineq: Real,
            /// Complementarity of the last QP.
            pub mu: Real,
            /// QP failures of `feedback` in a row (`RtiInfo::consecutive_failures`).
            pub consecutive_failures: c_uint,
        }
    }
}

/// The private conversions: `code` (a `SetError` to its status code), `read` and `write`
/// (`K` values from and to a C pointer).
pub(super) fn conversions() -> TokenStream {
    quote! {
        fn code(r: Result<(), SetError>) -> c_int {
            match r {
                Ok(()) => 0,
                Err(SetError::NonFinite) => ERR_NONFINITE,
                Err(SetError::StageOutOfRange) => ERR_STAGE,
                Err(SetError::CrossedBounds) => ERR_BOUNDS,
                #[allow(unreachable_patterns)]
                Err(_) => ERR_INPUT,
            }
        }

        /// Reads `K` values (the caller guarantees `K` readable values at `p`).
        fn read<const K: usize>(p: *const Real) -> [Real; K] {
            let mut out = [0.0; K];
            for (i, o) in out.iter_mut().enumerate() {
                // SAFETY: the caller of the exported function guarantees `K` values.
                *o = unsafe { p.add(i).read() };
            }
            out
        }

        fn write<const K: usize>(p: *mut Real, v: &[Real; K]) {
            for (i, &e) in v.iter().enumerate() {
                // SAFETY: the caller of the exported function guarantees room for `K`.
                unsafe { p.add(i).write(e) };
            }
        }
    }
}
