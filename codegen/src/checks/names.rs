//! The identifiers the generated crate and C header derive from the model's names, the
//! generated API's own names they must not clash with (one list per namespace, kept equal to
//! what `emit/` produces by the test below), and the check.
//!
//! Derived identifiers (see `emit/setters.rs`, `emit/solver.rs`, `emit/constants.rs`,
//! `emit/c_abi.rs` and `templates/header.h.tera`):
//!
//! | from | Rust | C |
//! |---|---|---|
//! | parameter `n` | `Solver::set_n` (and `set_n_all` per stage), `PARAM_N` | `<crate>_set_n`, `<CRATE>_PARAM_N` |
//! | control `n` | `Solver::u0_n`, `CONTROL_N` | `<CRATE>_CONTROL_N` |
//! | state `n` | `STATE_N` | `<CRATE>_STATE_N` |
//! | model `m` | crate `m` (or `--name`) | prefix `m_` of every symbol |

use std::collections::HashMap;

use mpc_dsl::Ocp;
use mpc_dsl::lang::{DiagnosticKind, Place};
use mpc_dsl::ocp::ParamKind;

use super::Problem;
use crate::options::Options;

/// Methods of the generated `Solver` whose names do not come from the model.
pub const SOLVER_METHODS: &[&str] = &[
    "unconfigured",
    "configure",
    "new",
    "settings",
    "settings_mut",
    "set_settings",
    "rti",
    "set_x0",
    "set_param",
    "set_param_all",
    "param",
    "update_weights",
    "soft_penalties",
    "set_soft_penalties",
    "terminal_soft_penalties",
    "set_terminal_soft_penalties",
    "control_bound_penalties",
    "set_control_bound_penalties",
    "state_bound_penalties",
    "set_state_bound_penalties",
    "set_control_bounds",
    "control_bounds",
    "set_state_bounds",
    "state_bounds",
    "set_constraint_bounds",
    "constraint_bounds",
    "set_terminal_constraint_bounds",
    "terminal_constraint_bounds",
    "set_guess",
    "set_state_guess",
    "set_control_guess",
    "set_trajectory_guess",
    "set_trajectory_guess_from",
    "augmented_guess",
    "prepare",
    "feedback",
    "solve_sqp",
    "u0",
    "control",
    "state",
    "stats",
    "cost",
    "kkt_residual",
    "trajectory",
    "slacks",
    "terminal_slacks",
    "dynamics_multipliers",
    "control_bound_multipliers",
    "state_bound_multipliers",
    "constraint_multipliers",
    "terminal_constraint_multipliers",
    "x0_aug",
];

/// Functions of the C ABI whose names do not come from the model, without the
/// `<crate>_` prefix.
pub const C_FUNCTIONS: &[&str] = &[
    "memsize",
    "memalign",
    "create",
    "set_x0",
    "set_param",
    "set_param_all",
    "set_guess",
    "set_control_bounds",
    "get_control_bounds",
    "set_state_bounds",
    "get_state_bounds",
    "set_constraint_bounds",
    "get_constraint_bounds",
    "set_terminal_constraint_bounds",
    "get_terminal_constraint_bounds",
    "set_qp_max_iter",
    "get_settings",
    "set_settings",
    "set_state_guess",
    "set_control_guess",
    "set_trajectory_guess",
    "get_soft_penalties",
    "set_soft_penalties",
    "get_terminal_soft_penalties",
    "set_terminal_soft_penalties",
    "get_control_bound_penalties",
    "set_control_bound_penalties",
    "get_state_bound_penalties",
    "set_state_bound_penalties",
    "prepare",
    "feedback",
    "solve_sqp",
    "get_u0",
    "get_control",
    "get_state",
    "get_stats",
    "get_cost",
    "get_kkt_residual",
    "get_trajectory",
    "get_slacks",
    "get_terminal_slacks",
    "get_dynamics_multipliers",
    "get_control_bound_multipliers",
    "get_state_bound_multipliers",
    "get_constraint_multipliers",
    "get_terminal_constraint_multipliers",
];

/// Constants of the generated crate whose names do not come from the model (the C header's
/// macros are these and the status and error codes, all prefixed with `<CRATE>_`).
pub const CONSTANTS: &[&str] = &[
    "N",
    "NX",
    "NX_MODEL",
    "NU",
    "NP",
    "NY",
    "NYN",
    "NG",
    "NGN",
    "NG_QP",
    "NGN_QP",
    "NSBU",
    "NSBX",
    "SOFT_CONTROL_BOUNDS",
    "SOFT_STATE_BOUNDS",
    "NC",
    "NBX",
    "NR",
    "NH",
    "DT",
    "X_GUESS",
    "U_GUESS",
    "P_DEFAULT",
    "P_ZERO",
    "U_ZERO",
    "X0",
    "U0",
    "LBX",
    "UBX",
    "LBU",
    "UBU",
    "LG",
    "UG",
    "LGN",
    "UGN",
    "L1",
    "L2",
    "L1N",
    "L2N",
];

/// Crate names that would clash with a crate the generated one depends on or with the
/// standard library.
pub const RESERVED_CRATE_NAMES: &[&str] = &[
    "core",
    "std",
    "alloc",
    "proc_macro",
    "test",
    "libm",
    "mpc_runtime",
];

/// Rust's strict and reserved keywords (edition 2024) and `_`: refused as names.
pub const RUST_KEYWORDS: &[&str] = &[
    "_", "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum",
    "extern", "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod",
    "move", "mut", "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait",
    "true", "type", "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final",
    "macro", "override", "priv", "typeof", "unsized", "virtual", "yield", "try",
];

/// A namespace of the generated code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Space {
    /// Methods of `Solver`.
    Method,
    /// C functions, without the `<crate>_` prefix.
    CFunction,
    /// Rust constants and C macros (without the `<CRATE>_` prefix).
    Constant,
}

impl Space {
    /// The generated API's own names in this namespace.
    pub fn fixed(self) -> &'static [&'static str] {
        match self {
            Space::Method => SOLVER_METHODS,
            Space::CFunction => C_FUNCTIONS,
            Space::Constant => CONSTANTS,
        }
    }
}

/// One identifier derived from a declared name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Derived {
    /// Its namespace.
    pub space: Space,
    /// The identifier (without the C prefix).
    pub ident: String,
    /// The declared name it comes from.
    pub owner: String,
    /// What the owner is (`parameter`, `stage parameter`, `control`, `state`).
    pub what: &'static str,
}

/// Every identifier the generated code derives from the model's declared names, in
/// declaration order (states, controls, parameters).
pub fn derived(ocp: &Ocp<'_>) -> Vec<Derived> {
    let mut out = Vec::new();
    let mut push = |space, ident: String, owner: &str, what| {
        out.push(Derived {
            space,
            ident,
            owner: owner.to_owned(),
            what,
        });
    };
    for v in &ocp.states {
        push(
            Space::Constant,
            format!("STATE_{}", v.name.to_uppercase()),
            &v.name,
            "state",
        );
    }
    for v in &ocp.controls {
        let up = v.name.to_uppercase();
        push(Space::Constant, format!("CONTROL_{up}"), &v.name, "control");
        push(Space::Method, format!("u0_{}", v.name), &v.name, "control");
    }
    for p in &ocp.parameters {
        let (n, stage) = (&p.var.name, p.kind == ParamKind::Stage);
        let what = if stage {
            "stage parameter"
        } else {
            "parameter"
        };
        push(
            Space::Constant,
            format!("PARAM_{}", n.to_uppercase()),
            n,
            what,
        );
        push(Space::Method, format!("set_{n}"), n, what);
        push(Space::CFunction, format!("set_{n}"), n, what);
        if stage {
            push(Space::Method, format!("set_{n}_all"), n, what);
        }
    }
    out
}

fn name_problem(place: Option<Place>, message: String, label: &str) -> Problem {
    Problem {
        place,
        kind: DiagnosticKind::Name,
        message,
        label: label.to_owned(),
    }
}

/// Every name problem of `ocp` generated with `opts`: keywords, the crate name, and derived
/// identifiers that clash with the generated API or with each other.
pub fn check(ocp: &Ocp<'_>, opts: &Options) -> Vec<Problem> {
    let mut problems = Vec::new();
    let declared = (ocp.states.iter().map(|v| (&v.name, "state")))
        .chain(ocp.controls.iter().map(|v| (&v.name, "control")))
        .chain(ocp.parameters.iter().map(|p| (&p.var.name, "parameter")));
    for (name, what) in declared {
        if RUST_KEYWORDS.contains(&name.as_str()) {
            problems.push(name_problem(
                Some(Place::Declaration(name.clone())),
                format!(
                    "{what} `{name}` is a Rust keyword, which the generated crate cannot use \
                     as a name; rename the {what}"
                ),
                "a Rust keyword",
            ));
        }
    }
    problems.extend(crate_name(ocp, opts));
    problems.extend(clashes(ocp));
    problems
}

/// The crate name (the model's, or `--name`): a valid identifier, no keyword, no reserved
/// crate name.
fn crate_name(ocp: &Ocp<'_>, opts: &Options) -> Option<Problem> {
    let name = opts.crate_name(&ocp.name);
    // A `--name` that is no identifier (or a keyword) is the generator's option error.
    let reason = if opts.crate_name.is_none() && RUST_KEYWORDS.contains(&name.as_str()) {
        "is a Rust keyword"
    } else if RESERVED_CRATE_NAMES.contains(&name.as_str()) {
        "is the name of a crate the generated one depends on (or of the standard library)"
    } else {
        return None;
    };
    let (place, fix) = match &opts.crate_name {
        None => (Some(Place::Model), "rename the model (or pass `--name`)"),
        Some(_) => (None, "pass another `--name`"),
    };
    Some(name_problem(
        place,
        format!("the crate name `{name}` {reason}; {fix}"),
        "the crate name",
    ))
}

/// Derived identifiers equal to the generated API's own names or to each other's.
fn clashes(ocp: &Ocp<'_>) -> Vec<Problem> {
    let mut problems = Vec::new();
    let mut seen: HashMap<(Space, &str), &Derived> = HashMap::new();
    let all = derived(ocp);
    let mut reported = std::collections::HashSet::new();
    for d in &all {
        // One problem per declaration: renaming it fixes every clash of its identifiers.
        if reported.contains(&d.owner) {
            continue;
        }
        let before = problems.len();
        clash(d, &seen, &mut problems);
        if problems.len() > before {
            reported.insert(d.owner.clone());
        } else {
            seen.entry((d.space, d.ident.as_str())).or_insert(d);
        }
    }
    problems
}

/// The clash of `d` with the generated API or an earlier identifier in `seen`, if any.
fn clash(d: &Derived, seen: &HashMap<(Space, &str), &Derived>, problems: &mut Vec<Problem>) {
    let place = Some(Place::Declaration(d.owner.clone()));
    let (what, owner, ident) = (d.what, &d.owner, &d.ident);
    if d.space.fixed().contains(&ident.as_str()) {
        problems.push(name_problem(
            place,
            format!(
                "{what} `{owner}` would generate `{ident}`, a name the generated solver \
                 already uses for its own API ({}); rename the {what}",
                space_words(d.space)
            ),
            "clashes with the generated API",
        ));
    } else if let Some(first) = seen.get(&(d.space, ident.as_str()))
        && first.owner != *owner
    {
        problems.push(name_problem(
            place,
            format!(
                "{what} `{owner}` would generate `{ident}`, as does {} `{}`; rename one of \
                 them",
                first.what, first.owner
            ),
            "clashes with another name",
        ));
    }
}

fn space_words(space: Space) -> &'static str {
    match space {
        Space::Method => "a `Solver` method",
        Space::CFunction => "a C function",
        Space::Constant => "a constant",
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use mpc_dsl::Graph;
    use mpc_dsl::lang::{ParseOptions, parse};

    use super::*;

    /// Names of every derived form: scalar and vector states and controls, stage and global
    /// parameters, a soft constraint, soft bounds and an input-rate term (which add code
    /// paths).
    const MODEL: &str = "model names;\nstate s; state v[2];\ncontrol c; control w[2];\n\
        param r[2] stage; param g global default 1; param up[3] global;\n\
        dynamics ode rk4 { der(s) = v[0] + c; der(v) = w * g; }\nhorizon N = 4, dt = 0.1;\n\
        cost { Q = diag(1, 1, 1) ref [r, 0]; R = diag(1, 1, 1); rate = diag(1, 1, 1) prev up; }\n\
        constraints { c in [-1, 1] soft l1 = 1; s in [-2, 2] soft l2 = 1;\n\
        k: -1 <= s + c <= 1 soft l1 = 1; terminal e: -1 <= s <= 1; }\n";

    /// The generated crate's `Solver` methods, C functions (without the prefix) and
    /// top-level constants, each with its number of definitions.
    fn emitted(src: &str, opts: &Options) -> [Vec<String>; 3] {
        let g = Graph::new();
        let parsed = parse(&g, src, &ParseOptions::default()).unwrap();
        let files = crate::generate(&parsed.ocp, opts).unwrap();
        let lib: syn::File = syn::parse_str(files.file("src/lib.rs").unwrap()).unwrap();
        let (mut methods, mut c_fns, mut consts) = (Vec::new(), Vec::new(), Vec::new());
        for item in &lib.items {
            match item {
                syn::Item::Impl(i) if i.trait_.is_none() => {
                    methods.extend(i.items.iter().filter_map(|it| match it {
                        syn::ImplItem::Fn(f) => Some(f.sig.ident.to_string()),
                        _ => None,
                    }));
                }
                syn::Item::Const(c) => consts.push(c.ident.to_string()),
                syn::Item::Mod(m) if m.ident == "ffi" => {
                    let items = m.content.iter().flat_map(|(_, items)| items);
                    c_fns.extend(items.filter_map(|it| match it {
                        syn::Item::Fn(f) if f.sig.abi.is_some() => {
                            Some(f.sig.ident.to_string()["names_".len()..].to_owned())
                        }
                        _ => None,
                    }));
                }
                _ => {}
            }
        }
        [methods, c_fns, consts]
    }

    #[test]
    fn the_header_defines_each_name_once_and_its_functions_are_listed() {
        let g = Graph::new();
        let ocp = parse(&g, MODEL, &ParseOptions::default()).unwrap().ocp;
        let files = crate::generate(&ocp, &Options::new()).unwrap();
        let header = files.file("include/names.h").unwrap();
        let macros: Vec<&str> = (header.lines())
            .filter_map(|l| l.strip_prefix("#define NAMES_"))
            .filter_map(|l| l.split_whitespace().next())
            .collect();
        let unique: BTreeSet<&str> = macros.iter().copied().collect();
        assert_eq!(unique.len(), macros.len(), "{macros:?}");
        let derived = derived(&ocp);
        for d in derived.iter().filter(|d| d.space == Space::Constant) {
            assert!(
                unique.contains(d.ident.as_str()),
                "{} not in the header",
                d.ident
            );
        }
        let functions: BTreeSet<&str> = (header.lines())
            .filter_map(|l| l.split_once(" names_"))
            .filter_map(|(_, rest)| rest.split_once('(').map(|(name, _)| name))
            .collect();
        let ours: BTreeSet<&str> = (derived.iter())
            .filter(|d| d.space == Space::CFunction)
            .map(|d| d.ident.as_str())
            .collect();
        let fixed: BTreeSet<&str> = functions.difference(&ours).copied().collect();
        assert_eq!(fixed, C_FUNCTIONS.iter().copied().collect());
    }

    #[test]
    fn the_lists_are_exactly_the_generated_api_own_names() {
        let mut opts = Options::new();
        opts.exact_hessian = true;
        let [methods, c_fns, consts] = emitted(MODEL, &opts);
        let g = Graph::new();
        let ocp = parse(&g, MODEL, &ParseOptions::default()).unwrap().ocp;
        let derived = derived(&ocp);
        for (space, names) in [
            (Space::Method, &methods),
            (Space::CFunction, &c_fns),
            (Space::Constant, &consts),
        ] {
            let unique: BTreeSet<&str> = names.iter().map(String::as_str).collect();
            assert_eq!(
                unique.len(),
                names.len(),
                "a name is defined twice: {names:?}"
            );
            let ours: BTreeSet<&str> = (derived.iter())
                .filter(|d| d.space == space)
                .map(|d| d.ident.as_str())
                .collect();
            assert!(
                ours.is_subset(&unique),
                "{space:?}: {ours:?} not all in {unique:?}"
            );
            let fixed: BTreeSet<&str> = unique.difference(&ours).copied().collect();
            let listed: BTreeSet<&str> = space.fixed().iter().copied().collect();
            assert_eq!(
                fixed, listed,
                "{space:?}: the emitter's own names differ from the list in checks/names.rs; \
                 update the list"
            );
        }
    }
}
