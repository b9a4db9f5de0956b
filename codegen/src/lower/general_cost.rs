//! Lowering the general cost terms (`stage NAME = l;`, `terminal NAME = l;`): the sum of a
//! stage's terms with its gradient and Hessian over `(x, u)` (the runtime's
//! `Model::stage_cost`), the value alone (`stage_cost_value`), the same at the end over `x`;
//! and, with the exact Hessian, the general constraints' curvature `sum_i mu_i d2h_i`
//! (`Model::constraints_hessian`).

use mpc_dsl::ocp::Stage;
use mpc_dsl::{Expr, Ocp};

use super::{Arg, Builder, Function, Symbols, Target};
use crate::error::CodegenError;

/// The general cost's functions: `(l, gradient, Hessian)` and `l` alone, at the stages and at
/// the end (a zero where a stage has no term).
#[derive(Clone, Debug)]
pub struct GeneralCostFunctions {
    /// `l(x, u, p)` (returned), `gx`, `gu`, `hxx`, `hux`, `huu`.
    pub stage: Function,
    /// `l(x, u, p)` alone.
    pub stage_value: Function,
    /// `l_N(x, p)` (returned), `gx`, `hxx`.
    pub terminal: Function,
    /// `l_N(x, p)` alone.
    pub terminal_value: Function,
}

/// The general cost's functions, `None` for a model without general terms.
pub(super) fn general_cost<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
    b: &Builder<'g>,
) -> Result<Option<GeneralCostFunctions>, CodegenError> {
    if ocp.cost.general.is_empty() {
        return Ok(None);
    }
    let zero = v.g.zero();
    let l = ocp.cost.general_sum(Stage::Path).unwrap_or(zero);
    let ln = ocp.cost.general_sum(Stage::Terminal).unwrap_or(zero);
    let path_args = [Arg::X, Arg::U, Arg::P];
    let terminal_args = [Arg::X, Arg::P];
    let stage_out = value_gradient_hessian(v, l, true)?;
    let terminal_out = value_gradient_hessian(v, ln, false)?;
    Ok(Some(GeneralCostFunctions {
        stage: b.function("general stage cost", &path_args, stage_out)?,
        stage_value: b.function("general stage cost", &path_args, vec![(l, Target::Ret(0))])?,
        terminal: b.function("general terminal cost", &terminal_args, terminal_out)?,
        terminal_value: b.function(
            "general terminal cost",
            &terminal_args,
            vec![(ln, Target::Ret(0))],
        )?,
    }))
}

/// `l` (returned), its gradient (`gx`, and `gu` with `controls`) and its Hessian (`hxx`, and
/// `hux`, `huu` with `controls`) over the solver's states (and the controls).
fn value_gradient_hessian<'g>(
    v: &Symbols<'g>,
    l: Expr<'g>,
    controls: bool,
) -> Result<Vec<(Expr<'g>, Target)>, CodegenError> {
    let nx = v.x.len();
    let mut wrt = v.x.clone();
    if controls {
        wrt.extend(v.u.iter().copied());
    }
    let mut out = vec![(l, Target::Ret(0))];
    for (j, g) in v.g.gradient(l, &wrt)?.into_iter().enumerate() {
        if g.as_constant() == Some(0.0) {
            continue;
        }
        let t = if j < nx {
            Target::Mat("gx", j, 0)
        } else {
            Target::Mat("gu", j - nx, 0)
        };
        out.push((g, t));
    }
    out.extend(hessian_targets(v, l, &wrt)?);
    Ok(out)
}

/// The Hessian of the scalar `f` over `wrt` (the solver's states, then maybe the controls)
/// as `hxx`, `hux` (controls by states) and `huu`; the upper right block, `hux` transposed,
/// is left out.
pub(super) fn hessian_targets<'g>(
    v: &Symbols<'g>,
    f: Expr<'g>,
    wrt: &[Expr<'g>],
) -> Result<Vec<(Expr<'g>, Target)>, CodegenError> {
    let nx = v.x.len();
    let hess = v.g.hessian(f, wrt)?;
    let mut out = Vec::with_capacity(hess.nnz());
    for (i, j, e) in hess.iter() {
        let target = match (i < nx, j < nx) {
            (true, true) => Target::Mat("hxx", i, j),
            (false, true) => Target::Mat("hux", i - nx, j),
            (false, false) => Target::Mat("huu", i - nx, j - nx),
            (true, false) => continue,
        };
        out.push((e, target));
    }
    Ok(out)
}

/// The general constraints' part of the Lagrangian Hessian, the Hessian of `mu' h` over
/// `(x, u)` (stage rows, `hxx`, `hux`, `huu`) or over `x` (terminal rows, `hxx`), with the
/// multipliers `mu` new symbols (`$mu[i]`, `$mun[i]`). `None` without rows.
pub(super) fn constraints_hessian<'g>(
    v: &Symbols<'g>,
    h: &[Expr<'g>],
    stage: Stage,
) -> Result<Option<Function>, CodegenError> {
    if h.is_empty() {
        return Ok(None);
    }
    let prefix = match stage {
        Stage::Path => "$mu",
        Stage::Terminal => "$mun",
    };
    let mu: Vec<Expr<'g>> = (0..h.len())
        .map(|i| v.g.symbol(&format!("{prefix}[{i}]")))
        .collect();
    let mut lagrangian = v.g.zero();
    for (&e, &m) in h.iter().zip(&mu) {
        lagrangian += m * e;
    }
    let mut wrt = v.x.clone();
    let args: &[Arg] = match stage {
        Stage::Path => {
            wrt.extend(v.u.iter().copied());
            &[Arg::X, Arg::U, Arg::P, Arg::Mu]
        }
        Stage::Terminal => &[Arg::X, Arg::P, Arg::Mu],
    };
    let out = hessian_targets(v, lagrangian, &wrt)?;
    let b = Builder { mu, ..v.builder() };
    Ok(Some(b.function("constraints' Hessian", args, out)?))
}
