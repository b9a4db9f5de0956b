//! The C twins of the `Solver`'s run-time API (`run_time.rs`): the `Settings` struct with
//! `get_settings` / `set_settings`, the per-stage guesses, the slack penalties and the
//! read-outs. Each checks its pointers for NULL and alignment before it reads or writes,
//! and the solver checks the values; their C declarations are in
//! `codegen/templates/header.h.tera`.

use proc_macro2::TokenStream;
use quote::quote;

use super::c_abi::CAbi;

impl CAbi<'_> {
    /// `get_settings` and `set_settings` over [`settings_struct`]'s `Settings`.
    pub(super) fn settings_fns(&self) -> TokenStream {
        let (get, set) = (self.sym("get_settings"), self.sym("set_settings"));
        quote! {
            /// Copies the settings in use.
            ///
            /// # Safety
            /// `s` from `create`; `out` writable.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #get(s: *const Solver, out: *mut Settings) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                if !out.is_aligned() {
                    return ERR_ALIGN;
                }
                let Some(out) = (unsafe { out.as_mut() }) else { return ERR_NULL };
                *out = Settings::of(s.settings());
                0
            }

            /// Checks and replaces the settings (nothing changes on error).
            ///
            /// # Safety
            /// `s` from `create`; `settings` readable.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set(s: *mut Solver, settings: *const Settings) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                if !settings.is_aligned() {
                    return ERR_ALIGN;
                }
                let Some(c) = (unsafe { settings.as_ref() }) else { return ERR_NULL };
                match c.rti_settings() {
                    Some(r) => code(s.set_settings(&r)),
                    None => ERR_INPUT,
                }
            }
        }
    }

    /// `set_state_guess`, `set_control_guess` and `set_trajectory_guess`.
    pub(super) fn stage_guess_fns(&self) -> TokenStream {
        let (sx, su, st) = (
            self.sym("set_state_guess"),
            self.sym("set_control_guess"),
            self.sym("set_trajectory_guess"),
        );
        quote! {
            /// Sets the guess of state `stage` (0..N).
            ///
            /// # Safety
            /// `s` from `create`; `x` points to `NX_MODEL` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #sx(s: *mut Solver, stage: c_int, x: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                let x = match take::<NX_MODEL>(x) { Ok(v) => v, Err(e) => return e };
                let Ok(k) = usize::try_from(stage) else { return ERR_STAGE };
                code(s.set_state_guess(k, &x))
            }

            /// Sets the guess of control `stage` (0..N-1).
            ///
            /// # Safety
            /// `s` from `create`; `u` points to `NU` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #su(s: *mut Solver, stage: c_int, u: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                let u = match take::<NU>(u) { Ok(v) => v, Err(e) => return e };
                let Ok(k) = usize::try_from(stage) else { return ERR_STAGE };
                code(s.set_control_guess(k, &u))
            }

            /// Sets the whole trajectory guess.
            ///
            /// # Safety
            /// `s` from `create`; `x` points to `(N + 1) * NX_MODEL` values, `u` to `N * NU`.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #st(s: *mut Solver, x: *const Real, u: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                if let Err(e) = check(x).and(check(u)) {
                    return e;
                }
                // SAFETY: the caller guarantees the values; every offset is inside them.
                let xk = |k: usize| read::<NX_MODEL>(unsafe { x.add(k * NX_MODEL) });
                let uk = |k: usize| read::<NU>(unsafe { u.add(k * NU) });
                code(s.set_trajectory_guess_from(xk, uk))
            }
        }
    }

    /// `set_soft_penalties`, `get_soft_penalties` and the terminal pair.
    pub(super) fn soft_penalty_fns(&self) -> TokenStream {
        let (set, get, set_n, get_n) = (
            self.sym("set_soft_penalties"),
            self.sym("get_soft_penalties"),
            self.sym("set_terminal_soft_penalties"),
            self.sym("get_terminal_soft_penalties"),
        );
        quote! {
            /// Sets the stage rows' slack penalties.
            ///
            /// # Safety
            /// `s` from `create`; `l1`, `l2` point to `NG` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set(s: *mut Solver, l1: *const Real, l2: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                match (take::<NG>(l1), take::<NG>(l2)) {
                    (Ok(a), Ok(b)) => code(s.set_soft_penalties(&a, &b)),
                    (Err(e), _) | (_, Err(e)) => e,
                }
            }

            /// Copies the stage rows' slack penalties.
            ///
            /// # Safety
            /// `s` from `create`; `l1`, `l2` have room for `NG` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #get(s: *const Solver, l1: *mut Real, l2: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                let (a, b) = s.soft_penalties();
                put_pair(l1, l2, Some((a, b)))
            }

            /// Sets the terminal rows' slack penalties.
            ///
            /// # Safety
            /// `s` from `create`; `l1n`, `l2n` point to `NGN` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #set_n(s: *mut Solver, l1n: *const Real, l2n: *const Real) -> c_int {
                let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                match (take::<NGN>(l1n), take::<NGN>(l2n)) {
                    (Ok(a), Ok(b)) => code(s.set_terminal_soft_penalties(&a, &b)),
                    (Err(e), _) | (_, Err(e)) => e,
                }
            }

            /// Copies the terminal rows' slack penalties.
            ///
            /// # Safety
            /// `s` from `create`; `l1n`, `l2n` have room for `NGN` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #get_n(s: *const Solver, l1n: *mut Real, l2n: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                put_pair(l1n, l2n, Some(s.terminal_soft_penalties()))
            }
        }
    }

    /// `get_cost`, `get_kkt_residual` and `get_trajectory`.
    pub(super) fn scalar_read_outs(&self) -> TokenStream {
        let (cost, kkt, traj) = (
            self.sym("get_cost"),
            self.sym("get_kkt_residual"),
            self.sym("get_trajectory"),
        );
        quote! {
            /// Copies the objective at the current trajectory.
            ///
            /// # Safety
            /// `s` from `create`; `out` writable.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #cost(s: *const Solver, out: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                put::<1>(out, Some([s.cost()]))
            }

            /// Copies the NLP's KKT residual; `ERR_INPUT` where it is not known.
            ///
            /// # Safety
            /// `s` from `create`; `out` writable.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #kkt(s: *const Solver, out: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                match s.kkt_residual() {
                    Some(r) => put::<1>(out, Some([r])),
                    None => ERR_INPUT,
                }
            }

            /// Copies the predicted trajectory.
            ///
            /// # Safety
            /// `s` from `create`; `x` has room for `(N + 1) * NX_MODEL` values, `u` for
            /// `N * NU`.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #traj(s: *const Solver, x: *mut Real, u: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                for p in [x, u] {
                    if p.is_null() {
                        return ERR_NULL;
                    }
                    if !p.is_aligned() {
                        return ERR_ALIGN;
                    }
                }
                for k in 0..=N {
                    if let Some(v) = s.state(k) {
                        // SAFETY: the caller guarantees room for every stage.
                        write(unsafe { x.add(k * NX_MODEL) }, &v);
                    }
                }
                for k in 0..N {
                    if let Some(v) = s.control(k) {
                        // SAFETY: as above.
                        write(unsafe { u.add(k * NU) }, &v);
                    }
                }
                0
            }
        }
    }

    /// The slacks and multipliers, per stage: `get_slacks`, `get_terminal_slacks`,
    /// `get_dynamics_multipliers`, `get_control_bound_multipliers`,
    /// `get_state_bound_multipliers`, `get_constraint_multipliers` and
    /// `get_terminal_constraint_multipliers`.
    pub(super) fn stage_read_outs(&self) -> TokenStream {
        let (sl, sln) = (self.sym("get_slacks"), self.sym("get_terminal_slacks"));
        let per_stage = [
            ("get_dynamics_multipliers", quote!(NX_MODEL), quote!(dynamics_multipliers)),
            ("get_control_bound_multipliers", quote!(NU), quote!(control_bound_multipliers)),
            ("get_state_bound_multipliers", quote!(NX_MODEL), quote!(state_bound_multipliers)),
            ("get_constraint_multipliers", quote!(NG), quote!(constraint_multipliers)),
        ]
        .map(|(c, len, rs)| {
            let c = self.sym(c);
            quote! {
                /// C: see the header.
                ///
                /// # Safety
                /// `s` from `create`; `out` has room for the values.
                #[unsafe(no_mangle)]
                pub unsafe extern "C" fn #c(s: *const Solver, stage: c_int, out: *mut Real) -> c_int {
                    let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                    let v = usize::try_from(stage).ok().and_then(|k| s.#rs(k));
                    put::<#len>(out, v)
                }
            }
        });
        let lamn = self.sym("get_terminal_constraint_multipliers");
        quote! {
            /// Copies the slacks of stage `stage` (0..N-1).
            ///
            /// # Safety
            /// `s` from `create`; `sl`, `su` have room for `NG` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #sl(s: *const Solver, stage: c_int, sl: *mut Real, su: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                let v = usize::try_from(stage).ok().and_then(|k| s.slacks(k));
                put_pair(sl, su, v)
            }

            /// Copies the terminal slacks.
            ///
            /// # Safety
            /// `s` from `create`; `sl`, `su` have room for `NGN` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #sln(s: *const Solver, sl: *mut Real, su: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                put_pair(sl, su, Some(s.terminal_slacks()))
            }

            #(#per_stage)*

            /// Copies the terminal constraints' multipliers.
            ///
            /// # Safety
            /// `s` from `create`; `out` has room for `NGN` values.
            #[unsafe(no_mangle)]
            pub unsafe extern "C" fn #lamn(s: *const Solver, out: *mut Real) -> c_int {
                let Some(s) = (unsafe { s.as_ref() }) else { return ERR_NULL };
                put::<NGN>(out, Some(s.terminal_constraint_multipliers()))
            }
        }
    }
}

/// The private pointer checks of the run-time functions: `check` (NULL and alignment),
/// `take` (`K` values after the checks), `put` and `put_pair` (write after the checks, or
/// `ERR_STAGE` for a stage without values). With `K = 0` values NULL is allowed (a model
/// without general constraints).
pub(super) fn checked_io() -> TokenStream {
    quote! {
        /// `ERR_NULL` for NULL, `ERR_ALIGN` for a pointer not aligned to `Real`.
        fn check(p: *const Real) -> Result<(), c_int> {
            if p.is_null() {
                return Err(ERR_NULL);
            }
            if !p.is_aligned() {
                return Err(ERR_ALIGN);
            }
            Ok(())
        }

        /// `K` values at `p` after [`check`] (none, and no check, for `K = 0`).
        fn take<const K: usize>(p: *const Real) -> Result<[Real; K], c_int> {
            if K > 0 {
                check(p)?;
            }
            Ok(read::<K>(p))
        }

        /// Writes `v` to `p` after [`check`] (`K = 0`: nothing), `ERR_STAGE` for `None`.
        fn put<const K: usize>(p: *mut Real, v: Option<[Real; K]>) -> c_int {
            if K > 0 && let Err(e) = check(p) {
                return e;
            }
            match v {
                Some(v) => {
                    write(p, &v);
                    0
                }
                None => ERR_STAGE,
            }
        }

        /// [`put`] of a pair.
        fn put_pair<const K: usize>(a: *mut Real, b: *mut Real, v: Option<([Real; K], [Real; K])>) -> c_int {
            match v {
                Some((x, y)) => match put::<K>(a, Some(x)) {
                    0 => put::<K>(b, Some(y)),
                    e => e,
                },
                None if K > 0 && (check(a).is_err() || check(b).is_err()) => {
                    check(a).and(check(b)).err().unwrap_or(ERR_NULL)
                }
                None => ERR_STAGE,
            }
        }
    }
}

/// `struct Settings`, the `#[repr(C)]` settings of `get_settings` / `set_settings`: every
/// field of `RtiSettings` (booleans as 0 or 1, the QP method as 0 auto, 1 Riccati,
/// 2 condensed), with the conversions both ways.
pub(super) fn settings_struct() -> TokenStream {
    quote! {
        /// The settings as C sees them (see the header for each field).
        #[repr(C)]
        #[derive(Clone, Copy, Debug)]
        #[allow(missing_docs)]
        pub struct Settings {
            pub qp_max_iter: c_uint,
            pub qp_refine: c_uint,
            pub qp_tol_stat: Real,
            pub qp_tol_eq: Real,
            pub qp_tol_ineq: Real,
            pub qp_tol_comp: Real,
            pub qp_reg: Real,
            pub qp_mu0: Real,
            pub qp_warm_start: c_int,
            pub qp_warm_start_dual: c_int,
            pub qp_method: c_int,
            pub qp_polish: c_int,
            pub qp_warm_active_set: c_int,
            pub shift: c_int,
            pub sqp_max_iter: c_uint,
            pub sqp_tol: Real,
            pub sqp_kkt_tol: Real,
            pub sqp_loose_qps: c_int,
            pub sqp_exact_hessian: c_int,
            pub sqp_watchdog: c_uint,
            pub fallback_limit: c_uint,
        }

        impl Settings {
            fn of(r: &RtiSettings<Real>) -> Settings {
                let q = &r.qp;
                Settings {
                    qp_max_iter: q.max_iter,
                    qp_refine: q.refine,
                    qp_tol_stat: q.tol_stat,
                    qp_tol_eq: q.tol_eq,
                    qp_tol_ineq: q.tol_ineq,
                    qp_tol_comp: q.tol_comp,
                    qp_reg: q.reg,
                    qp_mu0: q.mu0,
                    qp_warm_start: c_int::from(q.warm_start),
                    qp_warm_start_dual: c_int::from(q.warm_start_dual),
                    qp_method: q.method as c_int,
                    qp_polish: c_int::from(q.polish),
                    qp_warm_active_set: c_int::from(q.warm_active_set),
                    shift: c_int::from(r.shift),
                    sqp_max_iter: r.sqp_max_iter,
                    sqp_tol: r.sqp_tol,
                    sqp_kkt_tol: r.sqp_kkt_tol,
                    sqp_loose_qps: c_int::from(r.sqp_loose_qps),
                    sqp_exact_hessian: c_int::from(r.sqp_exact_hessian),
                    sqp_watchdog: r.sqp_watchdog,
                    fallback_limit: r.fallback_limit,
                }
            }

            /// The runtime's settings; `None` for a flag not 0 or 1 or an unknown method
            /// (the values themselves are checked by `set_settings`).
            fn rti_settings(&self) -> Option<RtiSettings<Real>> {
                let flag = |v: c_int| match v {
                    0 => Some(false),
                    1 => Some(true),
                    _ => None,
                };
                let method = match self.qp_method {
                    0 => QpMethod::Auto,
                    1 => QpMethod::Riccati,
                    2 => QpMethod::Condensed,
                    _ => return None,
                };
                let qp = QpSettings {
                    max_iter: self.qp_max_iter,
                    tol_stat: self.qp_tol_stat,
                    tol_eq: self.qp_tol_eq,
                    tol_ineq: self.qp_tol_ineq,
                    tol_comp: self.qp_tol_comp,
                    reg: self.qp_reg,
                    warm_start: flag(self.qp_warm_start)?,
                    warm_start_dual: flag(self.qp_warm_start_dual)?,
                    mu0: self.qp_mu0,
                    refine: self.qp_refine,
                    method,
                    polish: flag(self.qp_polish)?,
                    warm_active_set: flag(self.qp_warm_active_set)?,
                };
                Some(RtiSettings {
                    qp,
                    shift: flag(self.shift)?,
                    sqp_max_iter: self.sqp_max_iter,
                    sqp_tol: self.sqp_tol,
                    sqp_kkt_tol: self.sqp_kkt_tol,
                    sqp_loose_qps: flag(self.sqp_loose_qps)?,
                    sqp_exact_hessian: flag(self.sqp_exact_hessian)?,
                    sqp_watchdog: self.sqp_watchdog,
                    fallback_limit: self.fallback_limit,
                })
            }
        }
    }
}

/// Construction in place: the `UNCONFIGURED` image that `create` and `Solver::init` copy
/// into the caller's memory, `Solver::init` (on a `MaybeUninit`: a `static`, a
/// `Box::new_uninit`) and, with the generated crate's `alloc` feature, `Solver::boxed`. The
/// `unsafe` they need stays in this module; no solver-sized temporary is built on the stack.
pub(super) fn in_place() -> TokenStream {
    quote! {
        /// Copied into the caller's memory by `create` and [`Solver::init`], so that no
        /// solver-sized temporary is built on the (possibly small) stack of the caller.
        static UNCONFIGURED: Solver = Solver::unconfigured();

        #[cfg(feature = "alloc")]
        extern crate alloc;

        impl Solver {
            /// Builds a configured solver in `slot` (a `static`, a `Box::new_uninit()`, any
            /// memory of the caller) and returns it: the unconfigured image is copied into
            /// it and configured there, so the stack holds no solver-sized temporary, which
            /// [`new`](Solver::new) (returned by value) does, for any horizon.
            pub fn init(slot: &mut core::mem::MaybeUninit<Solver>) -> &mut Solver {
                // SAFETY: `slot` is valid for the write of one `Solver` and does not overlap
                // the static; the copy initializes it completely.
                unsafe { core::ptr::copy_nonoverlapping(&UNCONFIGURED, slot.as_mut_ptr(), 1) };
                // SAFETY: initialized just above.
                let s = unsafe { slot.assume_init_mut() };
                // Cannot fail for a validated model; the solver stays unconfigured if it did.
                let _ = s.configure();
                s
            }

            /// A configured solver on the heap, built in place ([`init`](Solver::init) on
            /// `Box::new_uninit`): for any horizon, on any stack. Needs the crate's `alloc`
            /// feature.
            #[cfg(feature = "alloc")]
            pub fn boxed() -> alloc::boxed::Box<Solver> {
                let mut b = alloc::boxed::Box::<Solver>::new_uninit();
                Solver::init(&mut b);
                // SAFETY: `init` initialized it.
                unsafe { b.assume_init() }
            }
        }
    }
}
