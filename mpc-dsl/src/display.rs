//! Printing expressions in infix form, for error messages and debugging.
//!
//! Shared subexpressions print once per use, so a deep DAG can print very long; the output is
//! cut at [`MAX_CHARS`] characters with a trailing `…`.

use core::fmt::{self, Write};

use crate::graph::{Expr, Node};
use crate::ops::{BinaryOp, UnaryOp};

/// Longest printed form of one expression.
pub const MAX_CHARS: usize = 240;

struct Budget<'a, 'b> {
    out: &'a mut fmt::Formatter<'b>,
    left: usize,
    cut: bool,
}

impl Write for Budget<'_, '_> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        if self.cut {
            return Ok(());
        }
        let n = s.chars().count();
        if n <= self.left {
            self.left -= n;
            self.out.write_str(s)
        } else {
            let head: String = s.chars().take(self.left).collect();
            self.left = 0;
            self.cut = true;
            self.out.write_str(&head)?;
            self.out.write_char('…')
        }
    }
}

fn precedence(node: &Node) -> u8 {
    match node {
        Node::Binary(BinaryOp::Add | BinaryOp::Sub, ..) => 1,
        Node::Binary(BinaryOp::Mul | BinaryOp::Div, ..) => 2,
        Node::Unary(UnaryOp::Neg, _) => 3,
        Node::Const(_) if node.const_value().is_some_and(|v| v < 0.0) => 3,
        _ => 5,
    }
}

fn write_expr(e: Expr<'_>, w: &mut Budget<'_, '_>, min_prec: u8) -> fmt::Result {
    if w.cut {
        return Ok(());
    }
    let g = e.graph;
    let node = g.node(e.id);
    let prec = precedence(&node);
    let paren = prec < min_prec;
    if paren {
        w.write_char('(')?;
    }
    match node {
        Node::Const(_) => write!(w, "{}", node.const_value().unwrap_or(f64::NAN))?,
        Node::Symbol(s) => {
            let name = g.inner.borrow().symbol_names[s as usize].clone();
            w.write_str(&name)?;
        }
        Node::Unary(UnaryOp::Neg, a) => {
            w.write_char('-')?;
            write_expr(g.wrap(a), w, 4)?;
        }
        Node::Unary(op, a) => {
            write!(w, "{}(", op.name())?;
            write_expr(g.wrap(a), w, 0)?;
            w.write_char(')')?;
        }
        Node::PowI(a, n) => {
            write_expr(g.wrap(a), w, 5)?;
            write!(w, "^{n}")?;
        }
        Node::Binary(op, a, b) if op.is_infix() => {
            write_expr(g.wrap(a), w, prec)?;
            write!(w, " {} ", op.name())?;
            // Right operand of - and / binds tighter: a - (b + c), a / (b * c).
            write_expr(g.wrap(b), w, prec + 1)?;
        }
        Node::Binary(op, a, b) => {
            write!(w, "{}(", op.name())?;
            write_expr(g.wrap(a), w, 0)?;
            w.write_str(", ")?;
            write_expr(g.wrap(b), w, 0)?;
            w.write_char(')')?;
        }
    }
    if paren {
        w.write_char(')')?;
    }
    Ok(())
}

impl fmt::Display for Expr<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut w = Budget {
            out: f,
            left: MAX_CHARS,
            cut: false,
        };
        write_expr(*self, &mut w, 0)
    }
}

impl fmt::Debug for Expr<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Expr#{}({})", self.id, self)
    }
}

#[cfg(test)]
mod tests {
    use crate::Graph;

    #[test]
    fn prints_with_minimal_parentheses() {
        let g = Graph::new();
        let (x, y, z) = (g.symbol("x"), g.symbol("y"), g.symbol("z"));
        assert_eq!((x + y * z).to_string(), "x + y * z");
        assert_eq!(((x + y) * z).to_string(), "(x + y) * z");
        assert_eq!((x - (y + z)).to_string(), "x - (y + z)");
        assert_eq!((x / (y * z)).to_string(), "x / (y * z)");
        assert_eq!((-(x * y)).to_string(), "-(x * y)");
        assert_eq!((x + y).powi(3).to_string(), "(x + y)^3");
        assert_eq!(y.atan2(x).sin().to_string(), "sin(atan2(y, x))");
        assert_eq!((2.0 * x).to_string(), "2 * x");
    }

    #[test]
    fn long_output_is_cut() {
        let g = Graph::new();
        let mut e = g.symbol("a_rather_long_symbol_name");
        for _ in 0..12 {
            e = e * e + 1.0;
        }
        let s = e.to_string();
        assert!(s.ends_with('…'));
        assert_eq!(s.chars().count(), super::MAX_CHARS + 1);
    }
}
