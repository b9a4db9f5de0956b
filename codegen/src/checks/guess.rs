//! Evaluation at the initial guess: every function the solver calls must be finite at the
//! model's guess (`x`, `u`) and parameter defaults (`p`), the values the generated solver
//! starts from. The parameter defaults are the same at every stage, so the path functions
//! are evaluated once for the stages `0..N-1` and the terminal ones once for stage `N`.
//!
//! First the model's own expressions (dynamics' right-hand side, residuals, constraints,
//! weights, references), each located at its `.mpc` expression; then, when those are
//! finite, the lowered functions the solver really calls (the integrator step with its
//! intermediate stages, and every Jacobian and Hessian), located at the equation, residual or
//! constraint of the offending row. For the implicit `irk` integrator that is the right-hand
//! side with `df/dx` and `df/du` at the guess: its Newton iterates are not evaluated here.

use mpc_dsl::lang::{DiagnosticKind, Place};
use mpc_dsl::ocp::{Dynamics, Stage, symbols_of};
use mpc_dsl::{Expr, Ocp};

use super::Problem;
use crate::lower::{Arg, Function, Lowered, RowBlock, Target};

/// Where a path or terminal function is evaluated, in words.
fn stages(stage: Stage, n: usize) -> String {
    match stage {
        Stage::Path => format!("stages 0..{} (the same guess and defaults at each)", n - 1),
        Stage::Terminal => format!("stage {n}"),
    }
}

/// One expression of the model to evaluate.
struct Item<'g> {
    function: String,
    output: String,
    place: Place,
    stage: Stage,
    expr: Expr<'g>,
}

/// Every problem: the model's expressions first; the lowered functions only if those pass.
pub fn check(ocp: &Ocp<'_>, l: &Lowered) -> Vec<Problem> {
    let source = source_problems(ocp);
    if !source.is_empty() {
        return source;
    }
    lowered_problems(ocp, l)
}

/// The values of the state, control and parameter symbols: guess and defaults.
fn bindings<'g>(ocp: &Ocp<'g>) -> Vec<(Expr<'g>, f64)> {
    let syms = ocp.x().to_vec().into_iter();
    let syms = syms.chain(ocp.u().to_vec()).chain(ocp.p().to_vec());
    let values = ocp.x_guess().into_iter();
    let values = values.chain(ocp.u_guess()).chain(ocp.p_default());
    syms.zip(values).collect()
}

fn source_problems(ocp: &Ocp<'_>) -> Vec<Problem> {
    let items = source_items(ocp);
    let b = bindings(ocp);
    let Some(g) = items.first().map(|i| i.expr.graph()) else {
        return Vec::new();
    };
    let exprs: Vec<Expr<'_>> = items.iter().map(|i| i.expr).collect();
    // Validation refused unbound symbols and non-finite constants: this cannot fail.
    let Ok(values) = g.eval(&exprs, &b) else {
        return Vec::new();
    };
    let mut problems: Vec<Problem> = Vec::new();
    for (item, v) in items.iter().zip(values) {
        if v.is_finite()
            || problems
                .iter()
                .any(|p| p.place.as_ref() == Some(&item.place))
        {
            continue;
        }
        let inputs = symbols_of(&[item.expr])
            .iter()
            .filter_map(|s| b.iter().find(|(e, _)| e == s))
            .map(|(e, v)| format!("{e} = {v}"))
            .collect::<Vec<_>>();
        problems.push(problem(
            item.place.clone(),
            &item.function,
            &format!("{} = {v}", item.output),
            &stages(item.stage, ocp.horizon.n),
            &inputs.join(", "),
        ));
    }
    problems
}

fn problem(place: Place, function: &str, output: &str, stages: &str, inputs: &str) -> Problem {
    let inputs = if inputs.is_empty() {
        "no state, control or parameter".to_owned()
    } else {
        inputs.to_owned()
    };
    Problem {
        place: Some(place),
        kind: DiagnosticKind::Semantic,
        message: format!(
            "{function} is not finite at the initial guess and the parameter defaults, at \
             {stages}: {output} with {inputs}; the solver would fail at every step. Make the \
             expression defined there (a division by zero, or sqrt, log or a power outside \
             its domain?) or give a `guess` or `default` where it is"
        ),
        label: "not finite at the guess".to_owned(),
    }
}

/// Entry `i` of a variable: `x` for a scalar, `p[i]` for a vector.
fn entry(name: &str, scalar: bool, i: usize) -> String {
    if scalar {
        name.to_owned()
    } else {
        format!("{name}[{i}]")
    }
}

/// The model's expressions with their function, output and place.
fn source_items<'g>(ocp: &Ocp<'g>) -> Vec<Item<'g>> {
    let mut items = Vec::new();
    let (kw, function) = match ocp.dynamics {
        Dynamics::Continuous { .. } => ("der", "the dynamics (right-hand side)"),
        Dynamics::Discrete { .. } => ("next", "the dynamics"),
    };
    let mut row = ocp.dynamics_exprs().iter();
    for v in &ocp.states {
        for (i, &e) in row.by_ref().take(v.len()).enumerate() {
            items.push(Item {
                function: function.to_owned(),
                output: format!("{kw}({})", entry(&v.name, v.scalar, i)),
                place: Place::Equation(v.name.clone()),
                stage: Stage::Path,
                expr: e,
            });
        }
    }
    for r in &ocp.cost.residuals {
        for (i, &e) in r.residual.iter().enumerate() {
            items.push(Item {
                function: format!("residual `{}`", r.name),
                output: format!("row {i}"),
                place: Place::Residual(r.name.clone()),
                stage: r.stage,
                expr: e,
            });
        }
        for (i, &e) in r.weight.as_row_major().iter().enumerate() {
            let n = r.weight.ncols();
            items.push(Item {
                function: format!("the weight of residual `{}`", r.name),
                output: format!("entry ({}, {})", i / n, i % n),
                place: Place::ResidualWeight(r.name.clone()),
                stage: r.stage,
                expr: e,
            });
        }
    }
    for t in &ocp.cost.general {
        items.push(Item {
            function: format!("cost term `{}`", t.name),
            output: "its value".to_owned(),
            place: Place::GeneralCost(t.name.clone()),
            stage: t.stage,
            expr: t.expr,
        });
    }
    for k in &ocp.constraints {
        for (i, &e) in k.expr.iter().enumerate() {
            items.push(Item {
                function: format!("constraint `{}`", k.name),
                output: format!("row {i}"),
                place: Place::Constraint(k.name.clone()),
                stage: k.stage,
                expr: e,
            });
        }
    }
    tracking_items(ocp, &mut items);
    items
}

/// The tracking weights and references and the input-rate weight.
fn tracking_items<'g>(ocp: &Ocp<'g>, items: &mut Vec<Item<'g>>) {
    let c = &ocp.cost;
    let terms = [
        ("Q", Stage::Path, c.state.as_ref()),
        ("R", Stage::Path, c.control.as_ref()),
        ("P", Stage::Terminal, c.terminal.as_ref()),
    ];
    let rate = c.input_rate.as_ref().map(|r| ("rate", &r.weight));
    let weights = (terms.iter())
        .filter_map(|(n, s, t)| t.map(|t| (*n, *s, &t.weight)))
        .chain(rate.map(|(n, w)| (n, Stage::Path, w)));
    for (name, stage, w) in weights {
        for (i, &e) in w.as_row_major().iter().enumerate() {
            items.push(Item {
                function: format!("the weight {name}"),
                output: format!("entry ({}, {})", i / w.ncols(), i % w.ncols()),
                place: Place::Weight(name.to_owned()),
                stage,
                expr: e,
            });
        }
    }
    for (name, stage, t) in terms {
        for (i, &e) in t.iter().flat_map(|t| t.reference.iter()).enumerate() {
            items.push(Item {
                function: format!("the reference of {name}"),
                output: format!("entry {i}"),
                place: Place::Reference(name.to_owned()),
                stage,
                expr: e,
            });
        }
    }
}

/// The lowered functions, with their stage and how to locate a row of their outputs.
fn lowered_problems(ocp: &Ocp<'_>, l: &Lowered) -> Vec<Problem> {
    let path = Stage::Path;
    let term = Stage::Terminal;
    let dyn_rows = |i: usize| dynamics_place(ocp, i);
    let res = |i: usize| block_place(&l.residual_rows, i, false);
    let res_n = |i: usize| block_place(&l.terminal_residual_rows, i, false);
    let con = |i: usize| block_place(&l.constraint_rows, i, true);
    let con_n = |i: usize| block_place(&l.terminal_constraint_rows, i, true);
    let weight = |m: &str, i: usize| match m {
        "wn" => res_n(i),
        _ => res(i),
    };
    type Locate<'a> = Box<dyn Fn(&str, usize) -> Option<Place> + 'a>;
    let mut functions: Vec<(&str, Stage, &Function, Locate<'_>)> = vec![
        (
            if l.irk.is_some() {
                "the dynamics' right-hand side or its Jacobian (for the irk step)"
            } else {
                "the dynamics step (integrator)"
            },
            path,
            &l.dynamics,
            Box::new(|_, i| dyn_rows(i)),
        ),
        ("the residual", path, &l.residual, Box::new(|_, i| res(i))),
        (
            "the terminal residual",
            term,
            &l.terminal_residual,
            Box::new(|_, i| res_n(i)),
        ),
        ("the weights", path, &l.weights, Box::new(weight)),
    ];
    if let Some(f) = &l.dynamics_hessian {
        functions.push(("the dynamics' Hessian", path, f, Box::new(|_, _| None)));
    }
    // The general terms' derivatives, located at the first term of their stage.
    let first_term = |stage: Stage| {
        (ocp.cost.general.iter())
            .find(|t| t.stage == stage)
            .map(|t| Place::GeneralCost(t.name.clone()))
    };
    if let Some(c) = &l.general_cost {
        let (at, at_n) = (first_term(path), first_term(term));
        functions.push((
            "the general stage cost's derivatives",
            path,
            &c.stage,
            Box::new(move |_, _| at.clone()),
        ));
        functions.push((
            "the general terminal cost's derivatives",
            term,
            &c.terminal,
            Box::new(move |_, _| at_n.clone()),
        ));
    }
    if let Some(f) = &l.constraints {
        functions.push(("the constraints", path, f, Box::new(|_, i| con(i))));
    }
    if let Some(f) = &l.terminal_constraints {
        functions.push((
            "the terminal constraints",
            term,
            f,
            Box::new(|_, i| con_n(i)),
        ));
    }
    let mut problems = Vec::new();
    for (what, stage, f, locate) in functions {
        let Some((target, value)) = first_non_finite(f, l) else {
            continue;
        };
        let (output, row) = match target {
            Target::Ret(i) => (format!("output row {i}"), ("", i)),
            Target::Mat(m, i, j) => (format!("entry ({i}, {j}) of its matrix `{m}`"), (m, i)),
        };
        let place = locate(row.0, row.1).unwrap_or(Place::Model);
        let inputs = inputs_text(ocp, l);
        let output = format!("{output} = {value}");
        problems.push(problem(place, what, &output, &stages(stage, l.n), &inputs));
    }
    problems
}

/// The first output of `f` that is not finite at the guess, and its value.
fn first_non_finite(f: &Function, l: &Lowered) -> Option<(Target, f64)> {
    let inputs: Vec<f64> = (f.inputs.iter())
        .map(|&(arg, i)| match arg {
            Arg::X => l.x_guess[i],
            Arg::U => l.u_guess[i],
            Arg::P => l.p_default[i],
            // The multipliers are not known before solving: 1 hides nothing.
            Arg::Pi | Arg::Mu => 1.0,
        })
        .collect();
    let values = f.program.eval(&inputs).ok()?;
    (values.iter().zip(&f.outputs))
        .find(|(v, _)| !v.is_finite())
        .map(|(&v, &t)| (t, v))
}

/// The values of every state, control and parameter, named.
fn inputs_text(ocp: &Ocp<'_>, l: &Lowered) -> String {
    let names = (ocp.x().iter().chain(ocp.u().iter()).chain(ocp.p().iter()))
        .map(ToString::to_string)
        .collect::<Vec<_>>();
    let values = (l.x_guess.iter().take(l.nx_model))
        .chain(&l.u_guess)
        .chain(&l.p_default);
    (names.iter().zip(values))
        .map(|(n, v)| format!("{n} = {v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The equation of row `i` of the dynamics (none for the input-rate term's rows).
fn dynamics_place(ocp: &Ocp<'_>, i: usize) -> Option<Place> {
    let mut start = 0;
    for v in &ocp.states {
        if i < start + v.len() {
            return Some(Place::Equation(v.name.clone()));
        }
        start += v.len();
    }
    Some(Place::Weight("rate".into()))
}

/// The residual or constraint of row `i`, from the row blocks' descriptions.
fn block_place(blocks: &[RowBlock], i: usize, constraint: bool) -> Option<Place> {
    let b = blocks
        .iter()
        .find(|b| (b.start..b.start + b.len).contains(&i))?;
    if let Some(name) = b.what.split('`').nth(1) {
        return Some(if constraint {
            Place::Constraint(name.to_owned())
        } else {
            Place::Residual(name.to_owned())
        });
    }
    ["Q", "R", "P"]
        .into_iter()
        .find(|w| b.what.contains(&format!("({w})")))
        .map_or(Some(Place::Weight("rate".into())), |w| {
            Some(Place::Reference(w.to_owned()))
        })
}
