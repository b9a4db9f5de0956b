//! Graph traversal and the f64 interpreter.

use crate::error::{DslError, Result};
use crate::graph::{Expr, Graph, Node, NodeId};
use crate::ops::powi;

impl Node {
    /// Children of the node, in operand order.
    #[inline]
    pub(crate) fn children(&self) -> impl Iterator<Item = NodeId> {
        let (a, b) = match *self {
            Node::Const(_) | Node::Symbol(_) => (None, None),
            Node::Unary(_, a) | Node::PowI(a, _) => (Some(a), None),
            Node::Binary(_, a, b) => (Some(a), Some(b)),
        };
        a.into_iter().chain(b)
    }
}

impl Graph {
    /// All nodes reachable from `roots`, in increasing index order (a topological order:
    /// children come before parents).
    pub(crate) fn cone(&self, roots: &[NodeId]) -> Vec<NodeId> {
        let inner = self.inner.borrow();
        let nodes = &inner.nodes;
        let mut seen = vec![false; nodes.len()];
        let mut stack: Vec<NodeId> = Vec::new();
        let mut out = Vec::new();
        for &r in roots {
            if !seen[r as usize] {
                seen[r as usize] = true;
                stack.push(r);
            }
            while let Some(n) = stack.pop() {
                out.push(n);
                for c in nodes[n as usize].children() {
                    if !seen[c as usize] {
                        seen[c as usize] = true;
                        stack.push(c);
                    }
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// Checks that every `e` is a symbol of this graph and that none repeats; returns their
    /// symbol indices.
    pub(crate) fn symbol_indices(&self, exprs: &[Expr<'_>]) -> Result<Vec<u32>> {
        let mut seen = vec![false; self.inner.borrow().symbol_names.len()];
        let mut out = Vec::with_capacity(exprs.len());
        for &e in exprs {
            self.check_same(e);
            match self.node(e.id) {
                Node::Symbol(s) => {
                    if std::mem::replace(&mut seen[s as usize], true) {
                        return Err(DslError::DuplicateInput {
                            name: self.inner.borrow().symbol_names[s as usize].to_string(),
                        });
                    }
                    out.push(s);
                }
                _ => {
                    return Err(DslError::NotASymbol {
                        expr: e.to_string(),
                    });
                }
            }
        }
        Ok(out)
    }

    /// Evaluates `outputs` with the symbols set to the values in `bindings`.
    ///
    /// This walks the graph node by node; it is the reference the compiled
    /// [`Program`](crate::Program) and generated code are checked against.
    ///
    /// # Errors
    /// [`DslError::UnboundSymbol`] if an output depends on a symbol without a value,
    /// [`DslError::NonFiniteConstant`] if it depends on a NaN or infinite constant,
    /// [`DslError::NotASymbol`] / [`DslError::DuplicateInput`] for a bad binding.
    ///
    /// ```
    /// use mpc_dsl::Graph;
    /// let g = Graph::new();
    /// let (x, y) = (g.symbol("x"), g.symbol("y"));
    /// let v = g.eval(&[x * y + 1.0], &[(x, 2.0), (y, 3.0)]).unwrap();
    /// assert_eq!(v, vec![7.0]);
    /// ```
    pub fn eval(&self, outputs: &[Expr<'_>], bindings: &[(Expr<'_>, f64)]) -> Result<Vec<f64>> {
        for &o in outputs {
            self.check_same(o);
        }
        let syms: Vec<Expr<'_>> = bindings.iter().map(|&(e, _)| e).collect();
        let indices = self.symbol_indices(&syms)?;
        let mut sym_value = vec![None; self.inner.borrow().symbol_names.len()];
        for (&s, &(_, v)) in indices.iter().zip(bindings) {
            sym_value[s as usize] = Some(v);
        }
        let roots: Vec<NodeId> = outputs.iter().map(|o| o.id).collect();
        let order = self.cone(&roots);
        let inner = self.inner.borrow();
        let mut value = vec![0.0f64; inner.nodes.len()];
        for &n in &order {
            value[n as usize] = match inner.nodes[n as usize] {
                node @ Node::Const(_) => {
                    let v = node.const_value().unwrap_or(f64::NAN);
                    if !v.is_finite() {
                        return Err(DslError::NonFiniteConstant { value: v });
                    }
                    v
                }
                Node::Symbol(s) => {
                    sym_value[s as usize].ok_or_else(|| DslError::UnboundSymbol {
                        name: inner.symbol_names[s as usize].to_string(),
                    })?
                }
                Node::Unary(op, a) => op.apply(value[a as usize]),
                Node::PowI(a, k) => powi(value[a as usize], k),
                Node::Binary(op, a, b) => op.apply(value[a as usize], value[b as usize]),
            };
        }
        Ok(roots.iter().map(|&r| value[r as usize]).collect())
    }
}

#[cfg(test)]
mod tests {
    use crate::{DslError, Graph};

    #[test]
    fn unbound_symbol_is_named() {
        let g = Graph::new();
        let (x, y) = (g.symbol("x"), g.symbol("thrust"));
        let err = g.eval(&[x + y], &[(x, 1.0)]).unwrap_err();
        assert_eq!(
            err,
            DslError::UnboundSymbol {
                name: "thrust".into()
            }
        );
        assert!(err.to_string().contains("`thrust`"));
    }

    #[test]
    fn non_finite_constant_is_reported() {
        let g = Graph::new();
        let x = g.symbol("x");
        assert!(g.constant(f64::INFINITY).is_err());
        let bad = x * f64::NAN;
        let err = g.eval(&[bad], &[(x, 1.0)]).unwrap_err();
        assert!(matches!(err, DslError::NonFiniteConstant { value } if value.is_nan()));
        // Unrelated outputs are not affected.
        assert_eq!(g.eval(&[x + 1.0], &[(x, 1.0)]).unwrap(), vec![2.0]);
    }

    #[test]
    fn bindings_must_be_distinct_symbols() {
        let g = Graph::new();
        let x = g.symbol("x");
        assert!(matches!(
            g.eval(&[x], &[(x + 1.0, 1.0)]),
            Err(DslError::NotASymbol { .. })
        ));
        assert!(matches!(
            g.eval(&[x], &[(x, 1.0), (x, 2.0)]),
            Err(DslError::DuplicateInput { .. })
        ));
    }
}
