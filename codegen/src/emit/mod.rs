//! Rust emission: the lowered functions as straight-line `no_std` Rust, the `impl Model`,
//! the typed `Solver` wrapper and the C ABI module, built with `quote`, checked with
//! `syn::parse2` and formatted with `prettyplease`.
//!
//! [`items`] and [`ffi`] list the generated `src/lib.rs` in file order, one call per part;
//! each part is one short method named for what it emits (the model's functions in
//! `functions.rs`, the constants in `constants.rs`, the `Solver` in `solver.rs` and
//! `setters.rs`, the C ABI in `c_abi.rs`, a function's straight-line body in `body.rs`).
//! `docs/codegen.md` has the map ("Where to change what").

mod body;
mod c_abi;
mod c_run_time;
mod constants;
mod functions;
mod general_cost;
mod implicit;
mod run_time;
mod setters;
mod soft_bounds;
mod soft_bounds_api;
mod solver;

use proc_macro2::{Span, TokenStream};
use quote::quote;

use crate::error::CodegenError;
use crate::lower::{Lowered, RowBlock};
use crate::options::{Options, QpMethod, Scalar};
use c_abi::CAbi;

/// The model functions, the `Model` impl and the solver wrapper (everything but crate
/// attributes and the C ABI), in the order of the generated file.
pub(crate) fn items(l: &Lowered, opts: &Options) -> TokenStream {
    let e = Emitter::new(l, opts);
    let items = [
        e.imports(),
        e.dimensions(),
        e.soft_bound_items(),
        e.named_ranges(),
        e.model_data(),
        e.functions_module(),
        e.model_impl(),
        e.rti_type(),
        e.default_settings(),
        e.solver_struct(),
    ];
    let solver_methods = [
        e.construction(),
        e.settings_access(),
        e.settings_setter(),
        e.x0_setter(),
        e.param_setters(),
        e.named_param_setters(),
        e.bounds_api(),
        e.guess_setter(),
        e.stage_guess_setters(),
        e.penalty_api(),
        e.phases(),
        e.getters(),
        e.read_outs(),
    ];
    quote! {
        #(#items)*

        impl Solver {
            #(#solver_methods)*
        }
    }
}

/// The C ABI module, `pub mod ffi`, in the order of the generated file.
pub(crate) fn ffi(l: &Lowered, opts: &Options) -> TokenStream {
    let prefix = opts.crate_name(&l.name);
    let case = allow_case(&prefix);
    let c = CAbi::new(l, prefix);
    let items = [
        c_abi::error_codes(),
        c_abi::stats_struct(),
        c_run_time::settings_struct(),
        c_abi::conversions(),
        c_run_time::checked_io(),
        c_run_time::in_place(),
        c.memory(),
        c.x0_and_param_setters(),
        c.named_param_setters(),
        c.guess_setter(),
        c.bounds(),
        c.qp_max_iter_setter(),
        c.settings_fns(),
        c.stage_guess_fns(),
        c.soft_penalty_fns(),
        c.soft_bound_penalty_fns(),
        c.phases(),
        c.getters(),
        c.stats_getter(),
        c.scalar_read_outs(),
        c.stage_read_outs(),
    ];
    quote! {
        /// The C ABI (header: `include/<name>.h`). Every function returns a status code
        /// (0 or a positive [`RtiStatus`] on success, negative on a usage error), checks its
        /// pointers for NULL, and never panics or unwinds across the boundary. The solver
        /// lives in memory the caller provides (`memsize` / `memalign` bytes).
        #[allow(unsafe_code)]
        #case
        pub mod ffi {
            use super::*;
            use core::ffi::{c_int, c_uint, c_void};
            use mpc_runtime::{QpMethod, QpSettings};

            #(#items)*
        }
    }
}

/// What every emitter of the crate's items reads: the lowered model and the options.
struct Emitter<'a> {
    l: &'a Lowered,
    opts: &'a Options,
    /// The scalar type (`opts.scalar`).
    s: Scalar,
}

/// The QP solver's storage sizes of the generated solver (its `NC`, `NBX`, `NR`, `NH`).
struct Sizes {
    nc: usize,
    nbx: usize,
    nr: usize,
    nh: usize,
}

impl<'a> Emitter<'a> {
    fn new(l: &'a Lowered, opts: &'a Options) -> Emitter<'a> {
        Emitter {
            l,
            opts,
            s: opts.scalar,
        }
    }

    /// `NC` ([`condensing_storage`]), `NBX` and `NR` ([`bound_rows_and_riccati`]) and `NH`.
    fn sizes(&self) -> Sizes {
        let l = self.l;
        let nc = condensing_storage(l, self.opts);
        let (nbx, nr) = bound_rows_and_riccati(l, nc);
        // One stage Hessian in the QP when `J'WJ` is the same at every stage (and no exact
        // Hessian adds the dynamics' curvature, no general cost its Hessian, stage by stage).
        let nh = if l.constant_stage_residual_jacobians
            && l.dynamics_hessian.is_none()
            && l.general_cost.is_none()
        {
            1
        } else {
            l.n
        };
        Sizes { nc, nbx, nr, nh }
    }
}

/// An unsuffixed integer literal.
/// Whether rustc's `non_snake_case` lint takes `name` as snake case (its own rule: outer
/// underscores trimmed, no uppercase letter, no double underscore).
pub(crate) fn is_snake_case(name: &str) -> bool {
    let inner = name.trim_matches('_');
    !inner.chars().any(char::is_uppercase) && !inner.contains("__")
}

/// `#[allow(non_snake_case)]` for an item named from a user's name that is not snake case
/// (a control `F` gives `u0_F`), so that any legal identifier generates warning-free code;
/// nothing for a snake-case name, so the crates of such models are unchanged.
fn allow_case(name: &str) -> Option<TokenStream> {
    (!is_snake_case(name)).then(|| quote!(#[allow(non_snake_case)]))
}

fn ul(i: usize) -> proc_macro2::Literal {
    proc_macro2::Literal::usize_unsuffixed(i)
}

/// `f64` or `f32`.
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

/// An array literal of [`lit`]s.
fn lits(v: &[f64], s: Scalar) -> TokenStream {
    let items = v.iter().map(|&x| lit(x, s));
    quote!([#(#items),*])
}

/// `title`, then a table of `rows` (first row, end, what they are).
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

/// `text` as `#[doc]` attributes, one per line.
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
