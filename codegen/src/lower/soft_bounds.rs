//! Soft state and control bounds lowered to soft general rows (the runtime's box bounds are
//! hard): a soft bound on `u_j` is the stage row `h = u_j` (`k < N`), a soft bound on `x_j`
//! the stage row `h = x_j` and the terminal row `h_N = x_j`. The rows come after the model's
//! own general constraints (stage: the controls', then the states'; terminal: the states'),
//! and the entries' box bounds become infinite.
//!
//! Stage rows hold at every `k < N` with the same bounds, so a state's row also holds at
//! `k = 0`, where a state bound does not: there `x_0` is the measured state, fixed in the QP,
//! so that row's slack is the constant violation of the measured state and its penalty a
//! constant of the objective; the plan (`x_1..x_N`, `u`) is that of the bound on `1..=N`.
//! This is why a soft bound may not have both penalties zero (a hard row at `k = 0` would
//! make every measured state outside the bound infeasible), at generation and at run time.

use mpc_dsl::Ocp;
use mpc_dsl::ocp::{Bounds, Slack};

use super::RowBlock;
use super::constraints::StackedConstraints;

/// Where the soft bounds' rows are, for the generated API.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SoftBounds {
    /// The controls with a soft bound, in order (stage rows `ng_model..ng_model + len`).
    pub controls: Vec<usize>,
    /// The model states with a soft bound, in order (stage rows after the controls',
    /// terminal rows `ngn_model..`).
    pub states: Vec<usize>,
    /// The model's own stage constraint rows (before the soft bounds').
    pub ng_model: usize,
    /// The model's own terminal constraint rows.
    pub ngn_model: usize,
}

impl SoftBounds {
    /// Whether the model has no soft bound (then the generated code is that of a model
    /// without the feature, byte for byte).
    pub fn is_empty(&self) -> bool {
        self.controls.is_empty() && self.states.is_empty()
    }
}

/// Appends the soft bounds' rows to the stacked `path` and `terminal` constraints.
pub(super) fn append_soft_bounds<'g>(
    ocp: &Ocp<'g>,
    path: &mut StackedConstraints<'g>,
    terminal: &mut StackedConstraints<'g>,
) -> SoftBounds {
    let soft = SoftBounds {
        controls: ocp.control_bounds.soft_entries(),
        states: ocp.state_bounds.soft_entries(),
        ng_model: path.h.len(),
        ngn_model: terminal.h.len(),
    };
    let (x, u) = (ocp.x(), ocp.u());
    for &j in &soft.controls {
        push_row(path, &ocp.control_bounds, j, u[j]);
    }
    for &j in &soft.states {
        push_row(path, &ocp.state_bounds, j, x[j]);
        push_row(terminal, &ocp.state_bounds, j, x[j]);
    }
    soft
}

/// One row `lower_j <= s <= upper_j` with entry `j`'s penalties.
fn push_row<'g>(c: &mut StackedConstraints<'g>, b: &Bounds, j: usize, s: mpc_dsl::Expr<'g>) {
    let Slack { l1, l2 } = b.soft[j].unwrap_or(Slack { l1: 0.0, l2: 0.0 });
    c.rows.push(RowBlock {
        start: c.h.len(),
        len: 1,
        what: format!("soft bound on `{s}` (l1 = {l1:?}, l2 = {l2:?})"),
    });
    c.h.push(s);
    c.lower.push(b.lower[j]);
    c.upper.push(b.upper[j]);
    c.l1.push(l1);
    c.l2.push(l2);
}

/// `lower`, `upper` with the soft entries' bounds removed (infinite): the hard box bounds.
pub(super) fn hard_only(b: &Bounds, lower: &mut [f64], upper: &mut [f64]) {
    for j in b.soft_entries() {
        if let (Some(l), Some(u)) = (lower.get_mut(j), upper.get_mut(j)) {
            *l = f64::NEG_INFINITY;
            *u = f64::INFINITY;
        }
    }
}
