//! Lowering the general constraints: path and terminal rows stacked with their bounds and
//! slack penalties (their functions are [`Builder::with_jacobian`](super::Builder)'s).

use mpc_dsl::ocp::Stage;
use mpc_dsl::{Expr, Ocp};

use super::RowBlock;

/// The general constraints of one kind (path or terminal), stacked: `h`, its bounds and
/// slack penalties (`0, 0` for a hard row) and what each block of rows is.
#[derive(Default)]
pub(super) struct StackedConstraints<'g> {
    pub(super) h: Vec<Expr<'g>>,
    pub(super) lower: Vec<f64>,
    pub(super) upper: Vec<f64>,
    pub(super) l1: Vec<f64>,
    pub(super) l2: Vec<f64>,
    pub(super) rows: Vec<RowBlock>,
}

impl<'g> StackedConstraints<'g> {
    pub(super) fn of(ocp: &Ocp<'g>, stage: Stage) -> StackedConstraints<'g> {
        let mut c = StackedConstraints::default();
        for k in ocp.constraints.iter().filter(|k| k.stage == stage) {
            let (pen1, pen2) = k.soft.map_or((0.0, 0.0), |s| (s.l1, s.l2));
            let what = match k.soft {
                Some(s) => format!("`{}` (soft, l1 = {:?}, l2 = {:?})", k.name, s.l1, s.l2),
                None => format!("`{}`", k.name),
            };
            c.rows.push(RowBlock {
                start: c.h.len(),
                len: k.expr.len(),
                what,
            });
            c.h.extend(k.expr.iter().copied());
            c.lower.extend_from_slice(&k.lower);
            c.upper.extend_from_slice(&k.upper);
            c.l1.extend(std::iter::repeat_n(pen1, k.expr.len()));
            c.l2.extend(std::iter::repeat_n(pen2, k.expr.len()));
        }
        c
    }
}
