//! Rust emission: the lowered functions as straight-line `no_std` Rust, the `impl Model`,
//! the typed `Solver` wrapper and the C ABI module, built with `quote`, checked with
//! `syn::parse2` and formatted with `prettyplease`.

use proc_macro2::{Ident, Span, TokenStream};
use quote::{format_ident, quote};

use mpc_dsl::ops::{BinaryOp, UnaryOp};
use mpc_dsl::{Instr, Operand};

use crate::error::CodegenError;
use crate::lower::{Arg, Function, Lowered, Named, RowBlock, Target};
use crate::options::{Options, QpMethod, Scalar};

/// Which helpers the emitted functions call.
#[derive(Default)]
struct Uses {
    sign: bool,
    step: bool,
    powi: bool,
}

/// An unsuffixed integer literal.
fn ul(i: usize) -> proc_macro2::Literal {
    proc_macro2::Literal::usize_unsuffixed(i)
}

fn real_ty(s: Scalar) -> TokenStream {
    match s {
        Scalar::F64 => quote!(f64),
        Scalar::F32 => quote!(f32),
    }
}

/// A float literal (shortest representation that round-trips in the scalar type); infinite
/// values become `Real::INFINITY` / `Real::NEG_INFINITY`.
pub(crate) fn lit(v: f64, s: Scalar) -> TokenStream {
    if v == f64::INFINITY {
        return quote!(Real::INFINITY);
    }
    if v == f64::NEG_INFINITY {
        return quote!(Real::NEG_INFINITY);
    }
    let a = v.abs();
    let text = match s {
        Scalar::F64 => format!("{a:?}"),
        Scalar::F32 => format!("{:?}", a as f32),
    };
    let l = syn::LitFloat::new(&text, Span::call_site());
    if v.is_sign_negative() && v != 0.0 {
        quote!(-#l)
    } else {
        quote!(#l)
    }
}

fn lits(v: &[f64], s: Scalar) -> TokenStream {
    let items = v.iter().map(|&x| lit(x, s));
    quote!([#(#items),*])
}

fn operand(o: Operand, f: &Function, s: Scalar, slots: &[usize]) -> TokenStream {
    match o {
        Operand::Input(k) => {
            let (arg, i) = f.inputs[k as usize];
            let name = match arg {
                Arg::X => quote!(x),
                Arg::U => quote!(u),
                Arg::P => quote!(p),
                Arg::Pi => quote!(pi),
            };
            let i = ul(i);
            quote!(#name[#i])
        }
        Operand::Const(c) => lit(c, s),
        Operand::Temp(t) => {
            let id = format_ident!("t{}", slots[t as usize]);
            quote!(#id)
        }
    }
}

fn libm_fn(name: &str, s: Scalar) -> TokenStream {
    let id = match s {
        Scalar::F64 => format_ident!("{}", name),
        Scalar::F32 => format_ident!("{}f", name),
    };
    quote!(libm::#id)
}

/// The statements computing `f` and writing its outputs: temporaries, then zeroing (a slice
/// fill, which compiles to a memset; nalgebra's `Matrix::fill` is an element loop) of
/// every output matrix and the writes of its nonzero entries, then the returned vector.
fn body(
    f: &Function,
    s: Scalar,
    mats: &[&str],
    ret: Option<TokenStream>,
    uses: &mut Uses,
) -> TokenStream {
    // Register allocation: a temporary's variable is reused once its last reader has run,
    // so a function declares about as many variables as values are live at once (not one
    // per instruction: thousands of nested `let` scopes make LLVM's debug-info pass recurse
    // too deep). Outputs are written as soon as they are computed.
    let instrs = f.program.instrs();
    let n = instrs.len();
    let mut last_use = vec![0usize; n];
    for (i, ins) in instrs.iter().enumerate() {
        last_use[i] = i;
        for o in ins.operands() {
            if let Operand::Temp(t) = o {
                last_use[t as usize] = i;
            }
        }
    }
    let mut writes_at: Vec<Vec<(Operand, Target)>> = vec![Vec::new(); n];
    let mut late = Vec::new();
    for (o, t) in f.program.outputs().iter().zip(&f.outputs) {
        match *o {
            Operand::Const(0.0) => {} // zeros are already there
            Operand::Temp(k) => writes_at[k as usize].push((*o, *t)),
            _ => late.push((*o, *t)),
        }
    }
    let mut slots = vec![0usize; n];
    let mut free: Vec<usize> = Vec::new();
    let mut nslots = 0usize;
    for (i, ins) in instrs.iter().enumerate() {
        let mut seen = [u32::MAX; 2];
        for (k, o) in ins.operands().enumerate() {
            if let Operand::Temp(t) = o {
                if last_use[t as usize] == i && !seen.contains(&t) {
                    free.push(slots[t as usize]);
                }
                seen[k] = t;
            }
        }
        slots[i] = free.pop().unwrap_or_else(|| {
            nslots += 1;
            nslots - 1
        });
        if last_use[i] == i {
            // Read by no later instruction (an output only): free after its writes.
            free.push(slots[i]);
        }
    }
    let write = |o: Operand, t: Target| {
        let v = operand(o, f, s, &slots);
        match t {
            Target::Ret(i) => {
                let i = ul(i);
                quote!(r[#i] = #v;)
            }
            Target::Mat(m, i, j) => {
                let m = format_ident!("{}", m);
                let (i, j) = (ul(i), ul(j));
                quote!(#m[(#i, #j)] = #v;)
            }
        }
    };
    let mut stmts = Vec::with_capacity(n);
    for (i, ins) in instrs.iter().enumerate() {
        let t = format_ident!("t{}", slots[i]);
        let e = match *ins {
            Instr::Unary(op, a) => {
                let a = operand(a, f, s, &slots);
                match op {
                    UnaryOp::Neg => quote!(-#a),
                    UnaryOp::Sign => {
                        uses.sign = true;
                        quote!(sign(#a))
                    }
                    UnaryOp::Step => {
                        uses.step = true;
                        quote!(step(#a))
                    }
                    UnaryOp::Abs => {
                        let m = libm_fn("fabs", s);
                        quote!(#m(#a))
                    }
                    other => {
                        let m = libm_fn(other.name(), s);
                        quote!(#m(#a))
                    }
                }
            }
            Instr::PowI(a, n) => {
                uses.powi = true;
                let a = operand(a, f, s, &slots);
                let n = proc_macro2::Literal::i32_unsuffixed(n);
                quote!(powi(#a, #n))
            }
            Instr::Binary(op, a, b) => {
                let (a, b) = (operand(a, f, s, &slots), operand(b, f, s, &slots));
                match op {
                    BinaryOp::Add => quote!(#a + #b),
                    BinaryOp::Sub => quote!(#a - #b),
                    BinaryOp::Mul => quote!(#a * #b),
                    BinaryOp::Div => quote!(#a / #b),
                    BinaryOp::Pow => {
                        let m = libm_fn("pow", s);
                        quote!(#m(#a, #b))
                    }
                    BinaryOp::Atan2 => {
                        let m = libm_fn("atan2", s);
                        quote!(#m(#a, #b))
                    }
                    BinaryOp::Min => {
                        let m = libm_fn("fmin", s);
                        quote!(#m(#a, #b))
                    }
                    BinaryOp::Max => {
                        let m = libm_fn("fmax", s);
                        quote!(#m(#a, #b))
                    }
                }
            }
        };
        stmts.push(quote!(#t = #e;));
        for &(o, tg) in &writes_at[i] {
            stmts.push(write(o, tg));
        }
    }
    let late: Vec<_> = late.into_iter().map(|(o, t)| write(o, t)).collect();
    let decls = (0..nslots).map(|k| {
        let t = format_ident!("t{}", k);
        quote!(let mut #t: Real;)
    });
    let fills = mats.iter().map(|m| {
        let m = format_ident!("{}", m);
        quote!(#m.as_mut_slice().fill(0.0);)
    });
    match ret {
        Some(ty) => quote! {
            #(#fills)*
            let mut r = <#ty>::zeros();
            #(#decls)*
            #(#stmts)*
            #(#late)*
            r
        },
        None => quote! {
            #(#fills)*
            #(#decls)*
            #(#stmts)*
            #(#late)*
        },
    }
}

fn rows_doc(title: &str, rows: &[RowBlock]) -> String {
    let mut s = format!("{title}\n\n| rows | term |\n| --- | --- |\n");
    for r in rows {
        s.push_str(&format!(
            "| {}..{} | {} |\n",
            r.start,
            r.start + r.len,
            r.what
        ));
    }
    s
}

/// User text from the model (descriptions, units) for a doc comment: `[` and `]` escaped,
/// so that `[m]` renders as written instead of being read as an intra-doc link. Brackets
/// inside a code span (`` `p[0]` ``) are left alone: Markdown shows them as they are there,
/// and would show the backslash too.
fn doc_text(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(c) = rest.chars().next() {
        if c == '`' {
            // A code span: a run of backticks up to the next run of the same length.
            let run = rest.len() - rest.trim_start_matches('`').len();
            let (ticks, after) = rest.split_at(run);
            let close = after
                .match_indices(ticks)
                .find(|&(i, _)| !after[..i].ends_with('`') && !after[i + run..].starts_with('`'));
            let end = close.map_or(run, |(i, _)| run + i + run);
            out.push_str(&rest[..end]);
            rest = &rest[end..];
            continue;
        }
        if c == '[' || c == ']' {
            out.push('\\');
        }
        out.push(c);
        rest = &rest[c.len_utf8()..];
    }
    out
}

fn doc_lines(text: &str) -> TokenStream {
    let lines = text.lines().map(|l| {
        let l = format!(" {l}");
        quote!(#[doc = #l])
    });
    quote!(#(#lines)*)
}

/// `NC` of the generated solver: `N` when it is to condense, which it is only when asked
/// ([`QpOptions::method`](crate::QpOptions::method) `Condensed`), `0` otherwise.
///
/// `Auto` gives the Riccati recursion: every generated solver's real-time iteration solves
/// its QPs on the warm active set, so that a step costs one factorization whichever the
/// method, and condensing's (a backward recursion of about the same cost for `P_k`, the
/// products that build the dense Hessian, and its Cholesky factorization) is the dearer
/// (QR-bench A in `docs/codegen.md`). Condensing pays where the interior point does the
/// work (the warm active set off), and gives the shorter feedback phase.
fn condensing_storage(l: &Lowered, opts: &Options) -> usize {
    match opts.qp.method.unwrap_or(QpMethod::Auto) {
        QpMethod::Condensed => l.n,
        QpMethod::Riccati | QpMethod::Auto => 0,
    }
}

/// `NBX` of the generated solver: the states with a bound, as the runtime sees them (below
/// `Real::INF` in magnitude).
pub(crate) fn state_bound_rows(l: &Lowered) -> usize {
    let inf = <f64 as mpc_runtime::Real>::INF;
    l.lbx
        .iter()
        .zip(&l.ubx)
        .filter(|&(&lo, &hi)| lo > -inf || hi < inf)
        .count()
}

/// `NBX` ([`state_bound_rows`]) and `NR` of the generated solver: `NR` is `0` when it
/// condenses (`nc = N`) and nothing but control bounds could stop it, `N` otherwise.
fn bound_rows_and_riccati(l: &Lowered, nc: usize) -> (usize, usize) {
    let nbx = state_bound_rows(l);
    let dense_only = nc == l.n && nbx == 0 && l.ng == 0 && l.ngn == 0;
    (nbx, if dense_only { 0 } else { l.n })
}

/// The `Solver`'s run-time bounds: setters and getters for the control and model-state box
/// bounds and the general constraints' stage and terminal rows. A setter goes through
/// `Rti::set_bounds` / `Rti::set_constraint_bounds` with the other bounds as they are, so it
/// checks everything before it changes anything.
fn bounds_api() -> TokenStream {
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

/// Upper-case constant name for a model name.
fn const_name(prefix: &str, name: &str) -> Ident {
    format_ident!("{}_{}", prefix, name.to_uppercase())
}

/// The model functions, the `Model` impl and the solver wrapper (everything but crate
/// attributes and the C ABI).
pub(crate) fn items(l: &Lowered, opts: &Options) -> TokenStream {
    let s = opts.scalar;
    let real = real_ty(s);
    let mut uses = Uses::default();
    let (nxm_raw, nu_raw) = (l.nx_model, l.nu);
    let (nx, nxm, nu, np, ny, nyn, ng, ngn, n) = (
        ul(l.nx),
        ul(l.nx_model),
        ul(l.nu),
        ul(l.np),
        ul(l.ny),
        ul(l.nyn),
        ul(l.ng),
        ul(l.ngn),
        ul(l.n),
    );
    let dt = lit(l.dt, s);

    // ---- straight-line functions ----
    let dyn_body = body(
        &l.dynamics,
        s,
        &["a", "b"],
        Some(quote!(SVector<Real, NX>)),
        &mut uses,
    );
    let dynv_body = body(
        &l.dynamics_value,
        s,
        &[],
        Some(quote!(SVector<Real, NX>)),
        &mut uses,
    );
    let (hess_fn, hess_impl) = match &l.dynamics_hessian {
        Some(f) => {
            let b = body(f, s, &["hxx", "hux", "huu"], None, &mut uses);
            (
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
                        #b
                    }
                },
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
                },
            )
        }
        None => (quote!(), quote!()),
    };
    let dyn_doc = doc_lines(&format!(
        "Discrete dynamics over one interval ({} s, {}): returns `F(x, u, p)` and writes \
         `a = dF/dx`, `b = dF/du`.{}",
        l.dt,
        l.discretization,
        if l.nx > l.nx_model {
            format!(
                "\n\nStates {}..{} are the last applied control (`u_last+ = u`), for the \
                 input-rate cost.",
                l.nx_model, l.nx
            )
        } else {
            String::new()
        }
    ));
    let res_body = body(
        &l.residual,
        s,
        &["jx", "ju"],
        Some(quote!(SVector<Real, NY>)),
        &mut uses,
    );
    let res_doc = doc_lines(&rows_doc(
        "Stage residual `y(x, u, p)` (cost `1/2 |y|^2_W`) with `jx = dy/dx`, `ju = dy/du`.",
        &l.residual_rows,
    ));
    let resn_body = body(
        &l.terminal_residual,
        s,
        &["jx"],
        Some(quote!(SVector<Real, NYN>)),
        &mut uses,
    );
    let resn_doc = doc_lines(&rows_doc(
        "Terminal residual `y_N(x, p)` (cost `1/2 |y_N|^2_{W_N}`) with `jx = dy_N/dx`.",
        &l.terminal_residual_rows,
    ));
    let w_body = body(&l.weights, s, &["w", "wn"], None, &mut uses);
    let con = match &l.constraints {
        Some(f) => {
            let b = body(
                f,
                s,
                &["cx", "cu"],
                Some(quote!(SVector<Real, NG>)),
                &mut uses,
            );
            let d = doc_lines(&rows_doc(
                "Stage constraints `h(x, u, p)` (`lg <= h <= ug`) with `cx = dh/dx`, `cu = dh/du`.",
                &l.constraint_rows,
            ));
            quote! {
                #d
                #[allow(unused_variables, unused_mut, unused_assignments)]
                pub fn constraints(
                    x: &SVector<Real, NX>,
                    u: &SVector<Real, NU>,
                    p: &SVector<Real, NP>,
                    cx: &mut SMatrix<Real, NG, NX>,
                    cu: &mut SMatrix<Real, NG, NU>,
                ) -> SVector<Real, NG> {
                    #b
                }
            }
        }
        None => quote!(),
    };
    let con_n = match &l.terminal_constraints {
        Some(f) => {
            let b = body(f, s, &["cx"], Some(quote!(SVector<Real, NGN>)), &mut uses);
            let d = doc_lines(&rows_doc(
                "Terminal constraints `h_N(x, p)` with `cx = dh_N/dx`.",
                &l.terminal_constraint_rows,
            ));
            quote! {
                #d
                #[allow(unused_variables, unused_mut, unused_assignments)]
                pub fn terminal_constraints(
                    x: &SVector<Real, NX>,
                    p: &SVector<Real, NP>,
                    cx: &mut SMatrix<Real, NGN, NX>,
                ) -> SVector<Real, NGN> {
                    #b
                }
            }
        }
        None => quote!(),
    };
    let zero = lit(0.0, s);
    let one = lit(1.0, s);
    let mut helpers = Vec::new();
    if uses.sign {
        helpers.push(quote! {
            /// `sign(x)`: -1, 0 or 1 (0 for NaN), as in `mpc_dsl::ops`.
            #[inline(always)]
            fn sign(x: Real) -> Real {
                if x > #zero { #one } else if x < #zero { -#one } else { #zero }
            }
        });
    }
    if uses.step {
        helpers.push(quote! {
            /// Heaviside step: 1 for `x >= 0`, else 0.
            #[inline(always)]
            fn step(x: Real) -> Real {
                if x >= #zero { #one } else { #zero }
            }
        });
    }
    if uses.powi {
        helpers.push(quote! {
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
        });
    }

    let con_impl = if l.constraints.is_some() {
        quote! {
            fn constraints(
                &self,
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                cx: &mut SMatrix<Real, NG, NX>,
                cu: &mut SMatrix<Real, NG, NU>,
            ) -> SVector<Real, NG> {
                functions::constraints(x, u, p, cx, cu)
            }
        }
    } else {
        quote!()
    };
    let con_n_impl = if l.terminal_constraints.is_some() {
        quote! {
            fn terminal_constraints(
                &self,
                x: &SVector<Real, NX>,
                p: &SVector<Real, NP>,
                cx: &mut SMatrix<Real, NGN, NX>,
            ) -> SVector<Real, NGN> {
                functions::terminal_constraints(x, p, cx)
            }
        }
    } else {
        quote!()
    };

    // ---- constant data ----
    let x_guess = lits(&l.x_guess, s);
    let u_guess = lits(&l.u_guess, s);
    let p_default = lits(&l.p_default, s);
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
    let any_soft =
        l.l1.iter()
            .chain(&l.l2)
            .chain(&l.l1n)
            .chain(&l.l2n)
            .any(|&v| v > 0.0);
    let soft_call = if any_soft {
        quote! {
            self.rti.set_soft_penalties(
                &SVector::from(L1),
                &SVector::from(L2),
                &SVector::from(L1N),
                &SVector::from(L2N),
            )?;
        }
    } else {
        quote!()
    };

    // ---- named ranges and setters ----
    let mut named_consts = Vec::new();
    let range_const = |prefix: &str, v: &Named, what: &str| {
        let c = const_name(prefix, &v.name);
        let (a, b) = (ul(v.offset), ul(v.offset + v.len));
        let d = doc_lines(&format!(
            "Entries of {what} `{}` {}{}.",
            v.name,
            if v.doc.is_empty() { "" } else { ": " },
            doc_text(&v.doc)
        ));
        quote!(#d pub const #c: core::ops::Range<usize> = #a..#b;)
    };
    for v in &l.states {
        named_consts.push(range_const("STATE", v, "the state"));
    }
    for v in &l.controls {
        named_consts.push(range_const("CONTROL", v, "the control"));
    }
    for v in &l.params {
        named_consts.push(range_const("PARAM", v, "the parameter vector"));
    }
    let mut setters = Vec::new();
    for v in &l.params {
        let set = format_ident!("set_{}", v.name);
        let set_all = format_ident!("set_{}_all", v.name);
        let off = ul(v.offset);
        let len = ul(v.len);
        let (arg_ty, copy) = if v.scalar {
            (quote!(Real), quote!(p[#off] = value;))
        } else {
            (
                quote!(&[Real; #len]),
                quote! {
                    for (i, &e) in value.iter().enumerate() {
                        p[#off + i] = e;
                    }
                },
            )
        };
        let finite = if v.scalar {
            quote!(value.is_finite())
        } else {
            quote!(value.iter().all(|e| e.is_finite()))
        };
        let doc_txt = if v.doc.is_empty() {
            String::new()
        } else {
            format!(" ({})", doc_text(&v.doc))
        };
        if v.per_stage {
            let d = doc_lines(&format!(
                "Sets parameter `{}`{doc_txt} at stage `k <= N`.\n\n# Errors\n\
                 [`SetError::NonFinite`], [`SetError::StageOutOfRange`]; nothing changes then.",
                v.name
            ));
            let d_all = doc_lines(&format!(
                "Sets parameter `{}`{doc_txt} at every stage `0..=N`.\n\n# Errors\n\
                 [`SetError::NonFinite`]; nothing changes then.",
                v.name
            ));
            setters.push(quote! {
                #d
                pub fn #set(&mut self, k: usize, value: #arg_ty) -> Result<(), SetError> {
                    if !(#finite) {
                        return Err(SetError::NonFinite);
                    }
                    let mut p = *self.p.get(k).ok_or(SetError::StageOutOfRange)?;
                    #copy
                    self.set_param(k, &p.into())
                }
                #d_all
                pub fn #set_all(&mut self, value: #arg_ty) -> Result<(), SetError> {
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
            });
        } else {
            let d = doc_lines(&format!(
                "Sets global parameter `{}`{doc_txt} (every stage; the weights are \
                 re-evaluated).\n\n# Errors\n[`SetError::NonFinite`]; nothing changes then.",
                v.name
            ));
            setters.push(quote! {
                #d
                pub fn #set(&mut self, value: #arg_ty) -> Result<(), SetError> {
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
            });
        }
    }
    let mut getters = Vec::new();
    for v in &l.controls {
        let name = format_ident!("u0_{}", v.name);
        let off = ul(v.offset);
        let len = ul(v.len);
        let d = doc_lines(&format!(
            "Control `{}` of the last feedback{}.",
            v.name,
            if v.doc.is_empty() {
                String::new()
            } else {
                format!(" ({})", doc_text(&v.doc))
            }
        ));
        if v.scalar {
            getters.push(quote! {
                #d
                pub fn #name(&self) -> Real {
                    self.u0[#off]
                }
            });
        } else {
            getters.push(quote! {
                #d
                pub fn #name(&self) -> [Real; #len] {
                    let mut out = [0.0; #len];
                    for (i, o) in out.iter_mut().enumerate() {
                        *o = self.u0[#off + i];
                    }
                    out
                }
            });
        }
    }
    // Only the u_prev entries change: the weights are evaluated again only if they read them.
    let weights_again = if l.weights_use_u_prev {
        quote!(let _ = self.update_weights();)
    } else {
        quote!()
    };
    let (x0_aug, rate_update, guess_aug) = match &l.u_prev {
        Some(idx) => {
            let pairs = idx.iter().enumerate().map(|(i, &pi)| {
                let (xi, pi) = (ul(nxm_raw + i), ul(pi));
                quote!(x[#xi] = self.p[0][#pi];)
            });
            let upd = idx.iter().enumerate().map(|(i, &pi)| {
                let (i, pi) = (ul(i), ul(pi));
                quote!(p[#pi] = u[#i];)
            });
            let g = (0..nu_raw).map(|i| {
                let (xi, i) = (ul(nxm_raw + i), ul(i));
                quote!(xa[#xi] = u[#i];)
            });
            (
                quote!(#(#pairs)*),
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
                },
                quote!(#(#g)*),
            )
        }
        None => (quote!(), quote!(), quote!()),
    };
    let helpers_mod = quote!(#(#helpers)*);
    let bounds = bounds_api();
    let settings = {
        let mut fields = Vec::new();
        if let Some(m) = opts.qp.max_iter {
            let m = proc_macro2::Literal::u32_unsuffixed(m);
            fields.push(quote!(s.qp.max_iter = #m;));
        }
        if let Some(t) = opts.qp.tol {
            let t = lit(t, s);
            fields.push(quote! {
                s.qp.tol_stat = #t;
                s.qp.tol_eq = #t;
                s.qp.tol_ineq = #t;
            });
        }
        if let Some(t) = opts.qp.tol_comp {
            let t = lit(t, s);
            fields.push(quote!(s.qp.tol_comp = #t;));
        }
        if let Some(b) = opts.qp.warm_start_dual {
            fields.push(quote!(s.qp.warm_start_dual = #b;));
        }
        if let Some(b) = opts.shift {
            fields.push(quote!(s.shift = #b;));
        }
        if opts.qp.method == Some(QpMethod::Condensed) {
            fields.push(quote!(s.qp.method = mpc_runtime::QpMethod::Condensed;));
        }
        if opts.qp.method == Some(QpMethod::Riccati) {
            fields.push(quote!(s.qp.method = mpc_runtime::QpMethod::Riccati;));
        }
        if fields.is_empty() {
            quote!(RtiSettings::DEFAULT)
        } else {
            quote! {
                let mut s = RtiSettings::DEFAULT;
                #(#fields)*
                s
            }
        }
    };
    let n1 = ul(l.n + 1);
    let nc_raw = condensing_storage(l, opts);
    let nc = ul(nc_raw);
    let (nbx_raw, nr_raw) = bound_rows_and_riccati(l, nc_raw);
    let (nbx, nr) = (ul(nbx_raw), ul(nr_raw));
    let constant_jacobians = l.constant_residual_jacobians;
    let constant_stage_jacobians = l.constant_stage_residual_jacobians;
    // One stage Hessian in the QP when `J'WJ` is the same at every stage (and no exact
    // Hessian adds the dynamics' curvature stage by stage).
    let nh = if constant_stage_jacobians && l.dynamics_hessian.is_none() {
        ul(1)
    } else {
        n.clone()
    };
    let model_name = &l.name;
    let solver_doc = doc_lines(&format!(
        "The NMPC solver of `{model_name}`: horizon {n}, {} s per interval, one real-time \
         iteration per control step.\n\n\
         Each step: [`prepare`](Self::prepare) (before the state arrives), \
         [`set_x0`](Self::set_x0), [`feedback`](Self::feedback), then apply \
         [`u0`](Self::u0). Parameters have named setters, and the bounds run-time setters \
         ([`set_control_bounds`](Self::set_control_bounds) and its kin); \
         [`solve_sqp`](Self::solve_sqp) \
         iterates to convergence for offline use. No heap, no panics: it can live in a \
         `static` ([`unconfigured`](Self::unconfigured) is `const`, then \
         [`configure`](Self::configure)).",
        l.dt
    ));
    quote! {
        use mpc_runtime::nalgebra::{SMatrix, SVector};
        pub use mpc_runtime::{RtiInfo, RtiSettings, RtiStatus, SetError};

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

        #(#named_consts)*

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
        pub const LG: [Real; NG] = #lg;
        /// Stage constraint upper bounds.
        pub const UG: [Real; NG] = #ug;
        /// Terminal constraint lower bounds.
        pub const LGN: [Real; NGN] = #lgn;
        /// Terminal constraint upper bounds.
        pub const UGN: [Real; NGN] = #ugn;
        /// L1 slack penalties of the stage constraints (0 with `L2` 0: hard).
        pub const L1: [Real; NG] = #l1;
        /// L2 slack penalties of the stage constraints.
        pub const L2: [Real; NG] = #l2;
        /// L1 slack penalties of the terminal constraints.
        pub const L1N: [Real; NGN] = #l1n;
        /// L2 slack penalties of the terminal constraints.
        pub const L2N: [Real; NGN] = #l2n;

        /// The model functions as straight-line code (every distinct subexpression once).
        pub mod functions {
            use super::*;

            #helpers_mod

            #dyn_doc
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
                #dyn_body
            }

            /// [`dynamics`]'s `F(x, u, p)` alone, without the Jacobians (the full SQP's merit
            /// function).
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn dynamics_value(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
            ) -> SVector<Real, NX> {
                #dynv_body
            }

            #hess_fn

            #res_doc
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn residual(
                x: &SVector<Real, NX>,
                u: &SVector<Real, NU>,
                p: &SVector<Real, NP>,
                jx: &mut SMatrix<Real, NY, NX>,
                ju: &mut SMatrix<Real, NY, NU>,
            ) -> SVector<Real, NY> {
                #res_body
            }

            #resn_doc
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn terminal_residual(
                x: &SVector<Real, NX>,
                p: &SVector<Real, NP>,
                jx: &mut SMatrix<Real, NYN, NX>,
            ) -> SVector<Real, NYN> {
                #resn_body
            }

            /// The weights `W` (stage, block-diagonal in the residual's blocks) and `W_N`
            /// (terminal) from the parameters (only global ones may appear).
            #[allow(unused_variables, unused_mut, unused_assignments)]
            pub fn weights(
                p: &SVector<Real, NP>,
                w: &mut SMatrix<Real, NY, NY>,
                wn: &mut SMatrix<Real, NYN, NYN>,
            ) {
                #w_body
            }

            #con
            #con_n
        }

        /// The model, as the runtime's solver evaluates it.
        #[derive(Clone, Copy, Debug, Default)]
        pub struct Model;

        impl mpc_runtime::Model<Real, NX, NU, NP, NY, NYN, NG, NGN> for Model {
            const CONSTANT_RESIDUAL_JACOBIANS: bool = #constant_jacobians;
            const CONSTANT_STAGE_RESIDUAL_JACOBIANS: bool = #constant_stage_jacobians;
            #hess_impl

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

            #con_impl
            #con_n_impl
        }

        /// The runtime solver this crate instantiates.
        pub type Rti =
            mpc_runtime::Rti<Real, Model, NX, NU, NP, NY, NYN, NG, NGN, N, NC, NBX, NR, NH>;

        const P_ZERO: SVector<Real, NP> =
            SVector::from_array_storage(mpc_runtime::nalgebra::ArrayStorage([[0.0; NP]]));
        const U_ZERO: SVector<Real, NU> =
            SVector::from_array_storage(mpc_runtime::nalgebra::ArrayStorage([[0.0; NU]]));
        const X0: SVector<Real, NX_MODEL> = SVector::from_array_storage(
            mpc_runtime::nalgebra::ArrayStorage([[0.0; NX_MODEL]]),
        );
        const U0: SVector<Real, NU> =
            SVector::from_array_storage(mpc_runtime::nalgebra::ArrayStorage([U_GUESS]));

        /// The settings this solver was generated with.
        pub fn default_settings() -> RtiSettings<Real> {
            #settings
        }

        #solver_doc
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

        impl Solver {
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
                #soft_call
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

            /// The settings (QP tolerances, iteration limits, shift).
            pub fn settings(&self) -> &RtiSettings<Real> {
                &self.rti.settings
            }

            /// The settings, to change.
            pub fn settings_mut(&mut self) -> &mut RtiSettings<Real> {
                &mut self.rti.settings
            }

            /// The runtime solver (trajectory, QP data).
            pub fn rti(&self) -> &Rti {
                &self.rti
            }

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

            /// Sets the whole parameter vector of stage `k <= N`.
            ///
            /// # Errors
            /// [`SetError::NonFinite`], [`SetError::StageOutOfRange`]; nothing changes then.
            pub fn set_param(&mut self, k: usize, p: &[Real; NP]) -> Result<(), SetError> {
                let v = SVector::from(*p);
                let slot = self.p.get_mut(k).ok_or(SetError::StageOutOfRange)?;
                self.rti.set_param(k, &v)?;
                *slot = v;
                if k == 0 {
                    self.update_weights()?;
                }
                Ok(())
            }

            /// Sets the parameter vector of every stage.
            ///
            /// # Errors
            /// [`SetError::NonFinite`]; nothing changes then.
            pub fn set_param_all(&mut self, p: &[Real; NP]) -> Result<(), SetError> {
                let v = SVector::from(*p);
                self.rti.set_param_all(&v)?;
                self.p = [v; #n1];
                self.update_weights()
            }

            /// The parameters of stage `k <= N`.
            pub fn param(&self, k: usize) -> Option<[Real; NP]> {
                self.p.get(k).map(|p| (*p).into())
            }

            fn update_weights(&mut self) -> Result<(), SetError> {
                let mut w = SMatrix::<Real, NY, NY>::zeros();
                let mut wn = SMatrix::<Real, NYN, NYN>::zeros();
                functions::weights(&self.p[0], &mut w, &mut wn);
                self.rti.set_weights(&w, &wn)
            }

            #(#setters)*

            #bounds

            /// Sets the trajectory guess: `x` at every stage, `u` at every stage.
            ///
            /// # Errors
            /// [`SetError::NonFinite`]; nothing changes then.
            pub fn set_guess(&mut self, x: &[Real; NX_MODEL], u: &[Real; NU]) -> Result<(), SetError> {
                let mut xa = SVector::<Real, NX>::zeros();
                for (i, &e) in x.iter().enumerate() {
                    xa[i] = e;
                }
                #guess_aug
                self.rti.set_guess(&xa, &SVector::from(*u))
            }

            fn x0_aug(&self) -> SVector<Real, NX> {
                let mut x = SVector::<Real, NX>::zeros();
                for i in 0..NX_MODEL {
                    x[i] = self.x0[i];
                }
                #x0_aug
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
                #rate_update
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

            /// The control of the last feedback (or SQP solve).
            pub fn u0(&self) -> [Real; NU] {
                self.u0.into()
            }

            #(#getters)*

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

/// The C ABI's bound setters and getters (`<prefix>_set_control_bounds`,
/// `<prefix>_get_control_bounds` and the same for the state, constraint and terminal
/// constraint bounds), each a pair over the `Solver` methods of [`bounds_api`]. NULL is
/// refused unless the bounds have no entries (a model without general constraints).
fn ffi_bounds_api(pre: &str, l: &Lowered) -> TokenStream {
    let kinds = [
        ("control", quote!(NU), l.nu),
        ("state", quote!(NX_MODEL), l.nx_model),
        ("constraint", quote!(NG), l.ng),
        ("terminal_constraint", quote!(NGN), l.ngn),
    ];
    let fns = kinds.into_iter().map(|(kind, len, entries)| {
        let (set_c, get_c) = (
            format_ident!("{pre}_set_{kind}_bounds"),
            format_ident!("{pre}_get_{kind}_bounds"),
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
    });
    quote!(#(#fns)*)
}

/// The C ABI module.
pub(crate) fn ffi(l: &Lowered, opts: &Options) -> TokenStream {
    let pre = opts.crate_name(&l.name);
    let f = |s: &str| format_ident!("{}_{}", pre, s);
    let (memsize, memalign, create) = (f("memsize"), f("memalign"), f("create"));
    let (set_x0, set_param, set_param_all, set_guess) = (
        f("set_x0"),
        f("set_param"),
        f("set_param_all"),
        f("set_guess"),
    );
    let (prepare, feedback, solve_sqp) = (f("prepare"), f("feedback"), f("solve_sqp"));
    let (get_u0, get_control, get_state, get_stats, set_max_iter) = (
        f("get_u0"),
        f("get_control"),
        f("get_state"),
        f("get_stats"),
        f("set_qp_max_iter"),
    );
    let bounds = ffi_bounds_api(&pre, l);
    let mut named = Vec::new();
    for v in &l.params {
        let cfn = f(&format!("set_{}", v.name));
        let rs = format_ident!("set_{}", v.name);
        let len = ul(v.len);
        let value = if v.scalar {
            quote!(unsafe { *value })
        } else {
            quote!(&read::<#len>(value))
        };
        if v.per_stage {
            named.push(quote! {
                /// C: see the header.
                ///
                /// # Safety
                /// `s` from `create`; `value` points to the parameter's entries.
                #[unsafe(no_mangle)]
                pub unsafe extern "C" fn #cfn(s: *mut Solver, stage: c_int, value: *const Real) -> c_int {
                    let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                    if value.is_null() {
                        return ERR_NULL;
                    }
                    let Ok(k) = usize::try_from(stage) else { return ERR_STAGE };
                    code(s.#rs(k, #value))
                }
            });
        } else {
            named.push(quote! {
                /// C: see the header.
                ///
                /// # Safety
                /// `s` from `create`; `value` points to the parameter's entries.
                #[unsafe(no_mangle)]
                pub unsafe extern "C" fn #cfn(s: *mut Solver, value: *const Real) -> c_int {
                    let Some(s) = (unsafe { s.as_mut() }) else { return ERR_NULL };
                    if value.is_null() {
                        return ERR_NULL;
                    }
                    code(s.#rs(#value))
                }
            });
        }
    }
    quote! {
        /// The C ABI (header: `include/<name>.h`). Every function returns a status code
        /// (0 or a positive [`RtiStatus`] on success, negative on a usage error), checks its
        /// pointers for NULL, and never panics or unwinds across the boundary. The solver
        /// lives in memory the caller provides (`memsize` / `memalign` bytes).
        #[allow(unsafe_code)]
        pub mod ffi {
            use super::*;
            use core::ffi::{c_int, c_uint, c_void};

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
            }

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
                /// Copied into the caller's memory, so that no solver-sized temporary is
                /// built on the (possibly small) stack of the caller.
                static UNCONFIGURED: Solver = Solver::unconfigured();
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
                if p.is_null() && NP > 0 {
                    return ERR_NULL;
                }
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
                if p.is_null() && NP > 0 {
                    return ERR_NULL;
                }
                code(s.set_param_all(&read::<NP>(p)))
            }

            #(#named)*

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

            #bounds

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
                    },
                };
                0
            }
        }
    }
}

/// Parses and pretty-prints a whole file.
pub(crate) fn format_file(
    what: &str,
    tokens: TokenStream,
    rustfmt_skip: bool,
) -> Result<String, CodegenError> {
    let mut file: syn::File = syn::parse2(tokens).map_err(|e| CodegenError::Emit {
        what: what.to_string(),
        message: e.to_string(),
    })?;
    // The output is formatted by prettyplease; tell rustfmt (`cargo fmt` of a workspace
    // that contains a generated crate) to leave it as it is.
    for item in file.items.iter_mut().filter(|_| rustfmt_skip) {
        if let Some(attrs) = item_attrs(item) {
            attrs.insert(0, syn::parse_quote!(#[rustfmt::skip]));
        }
    }
    Ok(prettyplease::unparse(&file))
}

fn item_attrs(item: &mut syn::Item) -> Option<&mut Vec<syn::Attribute>> {
    use syn::Item;
    Some(match item {
        Item::Const(i) => &mut i.attrs,
        Item::Enum(i) => &mut i.attrs,
        Item::ExternCrate(i) => &mut i.attrs,
        Item::Fn(i) => &mut i.attrs,
        Item::Impl(i) => &mut i.attrs,
        Item::Mod(i) => &mut i.attrs,
        Item::Static(i) => &mut i.attrs,
        Item::Struct(i) => &mut i.attrs,
        Item::Type(i) => &mut i.attrs,
        Item::Use(i) => &mut i.attrs,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::doc_text;
    use crate::{Options, generate, generate_module};
    use mpc_dsl::Graph;
    use mpc_dsl::lang::{ParseOptions, parse};

    /// Units and descriptions with brackets, on a state, a control and both kinds of
    /// parameter (the range constants, the setters and the getter copy them into docs).
    const BRACKETS: &str = r#"
model bracket_docs;
state x[2]  unit "m"   doc "position [m] along `e[0]`";
control u   unit "N"   doc "force [N]";
param a global doc "gain [1/s]" default 1;
param r[2] stage unit "m" doc "reference" default [0, 0];
dynamics ode rk4(1) { der(x) = [x[1], a * u]; }
horizon N = 5, dt = 0.1;
cost {
    Q = diag(1, 1) ref r;
    R = diag(1);
}
"#;

    #[test]
    fn doc_text_escapes_brackets_outside_code_spans() {
        assert_eq!(doc_text("position [m]"), r"position \[m\]");
        assert_eq!(doc_text("[m/s^2] and [rad]"), r"\[m/s^2\] and \[rad\]");
        assert_eq!(doc_text("entry `p[0]` [m]"), r"entry `p[0]` \[m\]");
        assert_eq!(doc_text("``a`[0]`` [s]"), r"``a`[0]`` \[s\]");
        // An unclosed backtick is literal text: the brackets after it are escaped.
        assert_eq!(doc_text("a ` b [s]"), r"a ` b \[s\]");
        assert_eq!(doc_text("no brackets"), "no brackets");
    }

    /// The doc comment lines (`///`, `//!`) of emitted code that contain `needle`.
    fn doc_lines_with<'a>(code: &'a str, needle: &str) -> Vec<&'a str> {
        code.lines()
            .map(str::trim_start)
            .filter(|l| (l.starts_with("///") || l.starts_with("//!")) && l.contains(needle))
            .collect()
    }

    /// A model's units and descriptions reach the generated docs with `[` and `]` escaped:
    /// rustdoc would read `[m]` as an intra-doc link to an item `m` (and warn that there is
    /// none). Both the crate (`generate`) and the module for `include!` (`generate_module`).
    #[test]
    fn brackets_in_model_docs_are_escaped_in_the_emitted_docs() {
        let g = Graph::new();
        let parsed = match parse(&g, BRACKETS, &ParseOptions::default()) {
            Ok(p) => p,
            Err(d) => panic!("{}", d.render("test.mpc", BRACKETS)),
        };
        let opts = Options::new();
        let krate = generate(&parsed.ocp, &opts).unwrap();
        let lib = krate
            .files
            .iter()
            .find(|(p, _)| p.ends_with("src/lib.rs"))
            .map(|(_, c)| c.clone())
            .expect("a src/lib.rs");
        let module = generate_module(&parsed.ocp, "bracket_docs", &opts).unwrap();
        for (what, code) in [("crate", lib.as_str()), ("module", module.as_str())] {
            for (escaped, count) in [
                (r"position \[m\] along `e[0]` \[m\]", 1),
                (r"(force \[N\] \[N\])", 1),
                (r"(gain \[1/s\])", 1),
                (r"(reference \[m\])", 2),
            ] {
                assert_eq!(
                    doc_lines_with(code, escaped).len(),
                    count,
                    "{what}: `{escaped}` in {count} doc lines"
                );
            }
            for raw in ["[m]", "[N]", "[1/s]"] {
                let unescaped: Vec<_> = doc_lines_with(code, raw)
                    .into_iter()
                    .filter(|l| l.replace(r"\[", "").contains(raw))
                    .collect();
                assert!(
                    unescaped.is_empty(),
                    "{what}: unescaped {raw}: {unescaped:?}"
                );
            }
        }
    }
}
