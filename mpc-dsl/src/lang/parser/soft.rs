//! The `soft` clause of a box bound: `v in [0, 6] soft l1 = 100, l2 = 10;`, each penalty a
//! constant scalar (broadcast) or one value per selected entry.

use super::{PResult, Parser, semantic, syntax};
use crate::lang::lexer::Tok;
use crate::ocp::Slack;

impl Parser<'_, '_> {
    /// After `soft`: the penalties of `n` bounded entries (`name` for messages). An absent
    /// penalty is zero; validation refuses both zero.
    pub(super) fn box_soft(&mut self, name: &str, n: usize) -> PResult<Vec<Slack>> {
        let mut slacks = vec![Slack { l1: 0.0, l2: 0.0 }; n];
        loop {
            let l1 = if self.eat_kw("l1") {
                true
            } else if self.eat_kw("l2") {
                false
            } else {
                return Err(syntax(
                    self.span(),
                    format!("expected `l1 = ...` or `l2 = ...`, found {}", self.found()),
                ));
            };
            self.expect(&Tok::Eq, "`=`")?;
            let what = if l1 {
                "the L1 penalty"
            } else {
                "the L2 penalty"
            };
            let (v, span) = self.const_values(what)?;
            let values = match v.len() {
                1 => vec![v[0]; n],
                k if k == n => v,
                k => {
                    return Err(semantic(
                        span,
                        format!("{what} has {k} entries but `{name}` selects {n}"),
                    ));
                }
            };
            for (s, v) in slacks.iter_mut().zip(values) {
                if l1 { s.l1 = v } else { s.l2 = v }
            }
            if self.peek() != Some(&Tok::Comma) {
                return Ok(slacks);
            }
            self.pos += 1;
        }
    }
}
