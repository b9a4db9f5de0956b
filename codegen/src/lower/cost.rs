//! Lowering the cost: the stage and terminal residuals with their Jacobians, and the
//! block-diagonal weights as a function of the global parameters.

use mpc_dsl::ocp::{ParamKind, Stage};
use mpc_dsl::{Expr, Graph, Matrix, Ocp};

use super::{Arg, Builder, Function, RowBlock, Symbols, Target};
use crate::error::CodegenError;

/// Residual terms stacked into one residual: its rows, their weights (blocks of the
/// block-diagonal weight) and what each block of rows is.
#[derive(Default)]
pub(super) struct Stacked<'g> {
    pub(super) y: Vec<Expr<'g>>,
    pub(super) weights: Vec<Matrix<'g>>,
    pub(super) rows: Vec<RowBlock>,
}

impl<'g> Stacked<'g> {
    fn push(&mut self, r: &[Expr<'g>], weight: &Matrix<'g>, what: String) {
        self.rows.push(RowBlock {
            start: self.y.len(),
            len: r.len(),
            what,
        });
        self.y.extend_from_slice(r);
        self.weights.push(weight.clone());
    }
}

/// The cost, lowered.
pub(super) struct Cost<'g> {
    pub(super) stage: Stacked<'g>,
    pub(super) terminal: Stacked<'g>,
    pub(super) residual: Function,
    pub(super) terminal_residual: Function,
    /// Every entry of both residuals' Jacobians is a constant.
    pub(super) constant_jacobians: bool,
    /// Every entry of the stage residual's Jacobians is a constant.
    pub(super) constant_stage_jacobians: bool,
    pub(super) weights: Function,
    /// The weights' outputs (`w`, then `wn`), for [`weights_read_u_prev`].
    pub(super) weight_outputs: Vec<(Expr<'g>, Target)>,
}

/// The stage and terminal residuals with their Jacobians, and the weights.
pub(super) fn lower_cost<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
    b: &Builder<'g>,
) -> Result<Cost<'g>, CodegenError> {
    let stage = stage_residual(ocp, v)?;
    let terminal = terminal_residual(ocp, v)?;
    let (residual, constant_stage_jacobians) =
        b.with_jacobian("residual", &stage.y, "jx", Some("ju"))?;
    let (terminal_residual, constant_terminal_jacobians) =
        b.with_jacobian("terminal residual", &terminal.y, "jx", None)?;
    let weight_outputs = weight_outputs(v.g, &stage, &terminal);
    let weights = weights_function(ocp, v, b, &weight_outputs)?;
    Ok(Cost {
        stage,
        terminal,
        residual,
        terminal_residual,
        constant_jacobians: constant_stage_jacobians && constant_terminal_jacobians,
        constant_stage_jacobians,
        weights,
        weight_outputs,
    })
}

/// The stage residual `(x - xref, u - uref, r(x, u, p), u - u_last)`, the terms the model
/// has.
pub(super) fn stage_residual<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
) -> Result<Stacked<'g>, CodegenError> {
    let c = &ocp.cost;
    let mut y = Stacked::default();
    if let Some(t) = &c.state {
        y.push(&v.xm.sub(&t.reference)?, &t.weight, "x - xref (Q)".into());
    }
    if let Some(t) = &c.control {
        y.push(&v.u.sub(&t.reference)?, &t.weight, "u - uref (R)".into());
    }
    for r in c.residuals.iter().filter(|r| r.stage == Stage::Path) {
        y.push(&r.residual, &r.weight, format!("residual `{}` (W)", r.name));
    }
    if let Some(r) = &c.input_rate {
        y.push(
            &v.u.sub(&v.u_last)?,
            &r.weight,
            "u - u_last: input rate (u_last = u_{-1} at stage 0)".into(),
        );
    }
    Ok(y)
}

/// The terminal residual `(x_N - xref_N, r_N(x, p))`, the terms the model has.
pub(super) fn terminal_residual<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
) -> Result<Stacked<'g>, CodegenError> {
    let c = &ocp.cost;
    let mut yn = Stacked::default();
    if let Some(t) = &c.terminal {
        yn.push(
            &v.xm.sub(&t.reference)?,
            &t.weight,
            "x_N - xref_N (P)".into(),
        );
    }
    for r in c.residuals.iter().filter(|r| r.stage == Stage::Terminal) {
        let what = format!("terminal residual `{}` (W)", r.name);
        yn.push(&r.residual, &r.weight, what);
    }
    Ok(yn)
}

/// The entries of the block-diagonal weights `W` (`w`) and `W_N` (`wn`).
pub(super) fn weight_outputs<'g>(
    g: &'g Graph,
    stage: &Stacked<'g>,
    terminal: &Stacked<'g>,
) -> Vec<(Expr<'g>, Target)> {
    let w = block_diag(g, &stage.weights.iter().collect::<Vec<_>>());
    let wn = block_diag(g, &terminal.weights.iter().collect::<Vec<_>>());
    let (ny, nyn) = (stage.y.len(), terminal.y.len());
    let mut out = Vec::new();
    for i in 0..ny {
        for j in 0..ny {
            out.push((w[(i, j)], Target::Mat("w", i, j)));
        }
    }
    for i in 0..nyn {
        for j in 0..nyn {
            out.push((wn[(i, j)], Target::Mat("wn", i, j)));
        }
    }
    out
}

/// The symbols of the global parameters.
pub(super) fn global_params<'g>(ocp: &Ocp<'g>) -> Vec<Expr<'g>> {
    (ocp.parameters.iter())
        .filter(|q| q.kind == ParamKind::Global)
        .flat_map(|q| q.var.symbols.iter().copied())
        .collect()
}

/// `weights`, a function of the parameters.
///
/// # Errors
/// [`CodegenError::UnexpectedSymbol`] for a weight that uses anything but constants and
/// global parameters (compiled over those first, for that clear error).
pub(super) fn weights_function<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
    b: &Builder<'g>,
    wout: &[(Expr<'g>, Target)],
) -> Result<Function, CodegenError> {
    Builder::over_params(v.g, global_params(ocp))
        .function("weights", &[Arg::P], wout.to_vec())
        .map_err(|e| match e {
            CodegenError::UnexpectedSymbol { symbol, .. } => CodegenError::UnexpectedSymbol {
                function: "weights",
                symbol,
                allowed: "constants and global parameters".into(),
            },
            other => other,
        })?;
    b.function("weights", &[Arg::P], wout.to_vec())
}

/// Whether the weights read the input-rate term's `u_{-1}` (the parameter entries `idx`):
/// they do if they do not compile over the global parameters without them. If not, the
/// automatic `u_prev` update after each feedback need not re-evaluate them.
pub(super) fn weights_read_u_prev<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
    idx: &[usize],
    wout: Vec<(Expr<'g>, Target)>,
) -> bool {
    let without: Vec<Expr<'g>> = global_params(ocp)
        .into_iter()
        .filter(|s| !idx.iter().any(|&i| v.p.get(i) == Some(s)))
        .collect();
    Builder::over_params(v.g, without)
        .function("weights", &[Arg::P], wout)
        .is_err()
}

/// Stacks `blocks` of square weights into one block-diagonal matrix.
pub(super) fn block_diag<'g>(g: &'g Graph, blocks: &[&Matrix<'g>]) -> Matrix<'g> {
    let n: usize = blocks.iter().map(|b| b.nrows()).sum();
    let mut data = vec![g.zero(); n * n];
    let mut off = 0;
    for b in blocks {
        for i in 0..b.nrows() {
            for j in 0..b.ncols() {
                data[(off + i) * n + off + j] = b[(i, j)];
            }
        }
        off += b.nrows();
    }
    Matrix::from_row_major(n, n, data).unwrap_or_else(|_| Matrix::zeros(g, n, n))
}
