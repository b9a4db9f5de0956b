//! Automatic differentiation on the graph: every derivative is a new expression in the same
//! graph, so it can be simplified, differentiated again, evaluated or lowered to code.
//!
//! One table of local partial derivatives (`partial`) serves both modes:
//!
//! - forward mode ([`Graph::jvp`]): one sweep in topological order per direction, computing
//!   `J v`;
//! - reverse mode ([`Graph::vjp`], [`Graph::gradient`]): one sweep in reverse topological
//!   order, computing `J' w`. Each node is visited once and adds at most two multiply-adds
//!   per operand, so the derivative graph is linear in the size of the original graph, however
//!   much the original shares subexpressions.
//!
//! Only nodes that depend on a differentiation variable take part ("active" nodes): no
//! derivative nodes are built for parameters or constants.

use crate::error::{DslError, Result};
use crate::graph::{Expr, Graph, Node, NodeId};
use crate::linalg::Matrix;
use crate::ops::{BinaryOp, UnaryOp};

const NONE: u32 = u32::MAX;

/// How a derivative flows through one edge: `d parent = ± (d child) * factor`, with the
/// division and unit cases kept apart so that no `1/b`, `-x` or `x*1` node is built for them.
#[derive(Clone, Copy)]
enum Factor<'g> {
    /// Multiply by 1.
    Unit,
    /// Multiply by the expression.
    Mul(Expr<'g>),
    /// Divide by the expression.
    Div(Expr<'g>),
}

/// One edge's local derivative: a factor and a sign.
#[derive(Clone, Copy)]
struct Local<'g> {
    factor: Factor<'g>,
    negate: bool,
}

impl<'g> Local<'g> {
    fn plus(factor: Factor<'g>) -> Option<Local<'g>> {
        Some(Local {
            factor,
            negate: false,
        })
    }

    fn minus(factor: Factor<'g>) -> Option<Local<'g>> {
        Some(Local {
            factor,
            negate: true,
        })
    }

    /// The magnitude of this edge's contribution for an incoming derivative `d` (reverse:
    /// an adjoint; forward: a tangent). The sign is applied when accumulating.
    fn apply(self, d: Expr<'g>) -> Expr<'g> {
        match self.factor {
            Factor::Unit => d,
            Factor::Mul(p) => d * p,
            Factor::Div(q) => d / q,
        }
    }
}

/// Adds `± term` to an accumulator slot (`NONE` = zero so far).
fn accumulate<'g>(g: &'g Graph, slot: &mut u32, term: Expr<'g>, negate: bool) {
    *slot = match (*slot, negate) {
        (NONE, false) => term.id,
        (NONE, true) => (-term).id,
        (s, false) => (g.wrap(s) + term).id,
        (s, true) => (g.wrap(s) - term).id,
    };
}

/// The local derivative of node `f` with respect to its operand number `which` (0 or 1), or
/// `None` where it is identically zero. This is the one derivative table of the crate.
fn partial<'g>(g: &'g Graph, f: Expr<'g>, which: usize) -> Option<Local<'g>> {
    use Factor::{Div, Mul, Unit};
    let w = |id: NodeId| g.wrap(id);
    match g.node(f.id) {
        Node::Const(_) | Node::Symbol(_) => None,
        Node::Unary(op, a) => {
            let a = w(a);
            match op {
                UnaryOp::Neg => Local::minus(Unit),
                // d sqrt(a) = 1 / (2 sqrt(a))
                UnaryOp::Sqrt => Local::plus(Mul(0.5 / f)),
                UnaryOp::Sin => Local::plus(Mul(a.cos())),
                UnaryOp::Cos => Local::minus(Mul(a.sin())),
                // d tan(a) = 1 + tan(a)^2
                UnaryOp::Tan => Local::plus(Mul(1.0 + f.square())),
                // d asin(a) = 1 / sqrt(1 - a^2); d acos(a) = -1 / sqrt(1 - a^2)
                UnaryOp::Asin => Local::plus(Div((1.0 - a.square()).sqrt())),
                UnaryOp::Acos => Local::minus(Div((1.0 - a.square()).sqrt())),
                UnaryOp::Atan => Local::plus(Div(1.0 + a.square())),
                UnaryOp::Exp => Local::plus(Mul(f)),
                UnaryOp::Log => Local::plus(Div(a)),
                // d tanh(a) = 1 - tanh(a)^2
                UnaryOp::Tanh => Local::plus(Mul(1.0 - f.square())),
                UnaryOp::Abs => Local::plus(Mul(a.sign())),
                UnaryOp::Sign | UnaryOp::Step => None,
            }
        }
        Node::PowI(a, k) => Local::plus(Mul(f64::from(k) * w(a).powi(k - 1))),
        Node::Binary(op, a, b) => {
            let (a, b) = (w(a), w(b));
            match (op, which) {
                (BinaryOp::Add, _) | (BinaryOp::Sub, 0) => Local::plus(Unit),
                (BinaryOp::Sub, _) => Local::minus(Unit),
                (BinaryOp::Mul, 0) => Local::plus(Mul(b)),
                (BinaryOp::Mul, _) => Local::plus(Mul(a)),
                // d(a/b) = da / b - (a/b) db / b
                (BinaryOp::Div, 0) => Local::plus(Div(b)),
                (BinaryOp::Div, _) => Local::minus(Mul(f / b)),
                // d(a^b) = b a^(b-1) da + a^b ln(a) db
                (BinaryOp::Pow, 0) => Local::plus(Mul(b * a.pow(b - 1.0))),
                (BinaryOp::Pow, _) => Local::plus(Mul(f * a.ln())),
                // atan2(y, x): dy x / (x^2 + y^2) - dx y / (x^2 + y^2)
                (BinaryOp::Atan2, 0) => Local::plus(Mul(b / (a.square() + b.square()))),
                (BinaryOp::Atan2, _) => Local::minus(Mul(a / (a.square() + b.square()))),
                // min(a, b) follows a where a <= b; max(a, b) follows a where a >= b.
                (BinaryOp::Min, 0) => Local::plus(Mul((b - a).step())),
                (BinaryOp::Min, _) => Local::plus(Mul(1.0 - (b - a).step())),
                (BinaryOp::Max, 0) => Local::plus(Mul((a - b).step())),
                (BinaryOp::Max, _) => Local::plus(Mul(1.0 - (a - b).step())),
            }
        }
    }
}

/// Nodes reachable from some roots, with the subset that depends on the variables.
struct Tape {
    order: Vec<NodeId>,
    active: Vec<bool>,
}

impl Graph {
    fn tape(&self, roots: &[NodeId], wrt: &[NodeId]) -> Tape {
        let order = self.cone(roots);
        let mut active = vec![false; self.len()];
        for &v in wrt {
            active[v as usize] = true;
        }
        let inner = self.inner.borrow();
        for &n in &order {
            if !active[n as usize] {
                active[n as usize] = inner.nodes[n as usize]
                    .children()
                    .any(|c| active[c as usize]);
            }
        }
        Tape { order, active }
    }

    fn check_all(&self, exprs: &[Expr<'_>]) {
        for &e in exprs {
            self.check_same(e);
        }
    }

    fn wrt_ids(&self, wrt: &[Expr<'_>]) -> Result<Vec<NodeId>> {
        self.symbol_indices(wrt)?;
        Ok(wrt.iter().map(|e| e.id).collect())
    }

    /// Forward sweep: tangents of all active nodes given the tangents of the variables.
    /// `tangent` is indexed by node id and must be `NONE` everywhere on entry except at the
    /// variables; on exit it holds tangents for the active nodes of the tape.
    fn forward_sweep(&self, tape: &Tape, tangent: &mut [u32]) {
        for &n in &tape.order {
            if !tape.active[n as usize] || tangent[n as usize] != NONE {
                continue;
            }
            let f = self.wrap(n);
            let node = self.node(n);
            let mut acc = NONE;
            for (i, c) in node.children().enumerate() {
                let t = tangent[c as usize];
                if t == NONE {
                    continue;
                }
                if let Some(local) = partial(self, f, i) {
                    accumulate(self, &mut acc, local.apply(self.wrap(t)), local.negate);
                }
            }
            tangent[n as usize] = acc;
        }
    }

    /// Reverse sweep: adjoints of all active nodes given seeds on some nodes. `adjoint` is
    /// indexed by node id and holds the seeds on entry.
    fn reverse_sweep(&self, tape: &Tape, adjoint: &mut [u32]) {
        for &n in tape.order.iter().rev() {
            let a = adjoint[n as usize];
            if a == NONE {
                continue;
            }
            let f = self.wrap(n);
            let node = self.node(n);
            for (i, c) in node.children().enumerate() {
                if !tape.active[c as usize] {
                    continue;
                }
                if let Some(local) = partial(self, f, i) {
                    let term = local.apply(self.wrap(a));
                    accumulate(self, &mut adjoint[c as usize], term, local.negate);
                }
            }
        }
    }

    /// Forward mode: the directional derivative `J v` of `outputs` with respect to the
    /// symbols `wrt` along `direction` (one expression per symbol).
    ///
    /// ```
    /// use mpc_dsl::Graph;
    /// let g = Graph::new();
    /// let (x, y) = (g.symbol("x"), g.symbol("y"));
    /// let d = g.jvp(&[x * y], &[x, y], &[g.one(), g.zero()]).unwrap();
    /// assert_eq!(d[0], y);
    /// ```
    ///
    /// # Errors
    /// [`DslError::NotASymbol`] or [`DslError::DuplicateInput`] for a bad `wrt`,
    /// [`DslError::LengthMismatch`] if `direction` and `wrt` differ in length.
    pub fn jvp<'g>(
        &'g self,
        outputs: &[Expr<'g>],
        wrt: &[Expr<'g>],
        direction: &[Expr<'g>],
    ) -> Result<Vec<Expr<'g>>> {
        self.check_all(outputs);
        self.check_all(direction);
        let vars = self.wrt_ids(wrt)?;
        if direction.len() != wrt.len() {
            return Err(DslError::LengthMismatch {
                what: "jvp direction (one entry per variable)",
                expected: wrt.len(),
                found: direction.len(),
            });
        }
        let roots: Vec<NodeId> = outputs.iter().map(|o| o.id).collect();
        let tape = self.tape(&roots, &vars);
        let mut tangent = vec![NONE; self.len()];
        for (&v, d) in vars.iter().zip(direction) {
            if !d.is_zero() {
                tangent[v as usize] = d.id;
            }
        }
        self.forward_sweep(&tape, &mut tangent);
        Ok(roots
            .iter()
            .map(|&r| match tangent[r as usize] {
                NONE => self.zero(),
                t => self.wrap(t),
            })
            .collect())
    }

    /// Reverse mode: the Jacobian-transpose-vector product `J' w` of `outputs` with respect
    /// to the symbols `wrt`, for a weight `w` per output.
    ///
    /// # Errors
    /// As [`jvp`](Self::jvp), with `weights` checked against `outputs`.
    pub fn vjp<'g>(
        &'g self,
        outputs: &[Expr<'g>],
        wrt: &[Expr<'g>],
        weights: &[Expr<'g>],
    ) -> Result<Vec<Expr<'g>>> {
        self.check_all(outputs);
        self.check_all(weights);
        let vars = self.wrt_ids(wrt)?;
        if weights.len() != outputs.len() {
            return Err(DslError::LengthMismatch {
                what: "vjp weights (one entry per output)",
                expected: outputs.len(),
                found: weights.len(),
            });
        }
        let roots: Vec<NodeId> = outputs.iter().map(|o| o.id).collect();
        let tape = self.tape(&roots, &vars);
        let mut adjoint = vec![NONE; self.len()];
        for (&r, &w) in roots.iter().zip(weights) {
            if !tape.active[r as usize] || w.is_zero() {
                continue;
            }
            accumulate(self, &mut adjoint[r as usize], w, false);
        }
        self.reverse_sweep(&tape, &mut adjoint);
        Ok(vars
            .iter()
            .map(|&v| match adjoint[v as usize] {
                NONE => self.zero(),
                a => self.wrap(a),
            })
            .collect())
    }

    /// The gradient of a scalar `f` with respect to the symbols `wrt` (one reverse sweep).
    ///
    /// ```
    /// use mpc_dsl::Graph;
    /// let g = Graph::new();
    /// let (x, y) = (g.symbol("x"), g.symbol("y"));
    /// let grad = g.gradient(x * y + x.sin(), &[x, y]).unwrap();
    /// assert_eq!(grad, vec![x.cos() + y, x]);
    /// ```
    ///
    /// # Errors
    /// [`DslError::NotASymbol`] or [`DslError::DuplicateInput`] for a bad `wrt`.
    pub fn gradient<'g>(&'g self, f: Expr<'g>, wrt: &[Expr<'g>]) -> Result<Vec<Expr<'g>>> {
        self.vjp(&[f], wrt, &[self.one()])
    }

    /// The Jacobian of `outputs` with respect to the symbols `wrt`, with its sparsity pattern.
    ///
    /// Uses one reverse sweep per output or one forward sweep per variable, whichever is
    /// fewer. An entry is structurally zero when the output does not depend on the variable
    /// or its derivative simplifies to the constant 0.
    ///
    /// # Errors
    /// [`DslError::NotASymbol`] or [`DslError::DuplicateInput`] for a bad `wrt`.
    pub fn jacobian<'g>(&'g self, outputs: &[Expr<'g>], wrt: &[Expr<'g>]) -> Result<Jacobian<'g>> {
        self.check_all(outputs);
        let vars = self.wrt_ids(wrt)?;
        let (m, n) = (outputs.len(), vars.len());
        let roots: Vec<NodeId> = outputs.iter().map(|o| o.id).collect();
        let tape = self.tape(&roots, &vars);
        let mut entries: Vec<(usize, usize, Expr<'g>)> = Vec::new();
        if m <= n {
            let mut adjoint = vec![NONE; self.len()];
            for (i, &r) in roots.iter().enumerate() {
                if !tape.active[r as usize] {
                    continue;
                }
                adjoint.fill(NONE);
                adjoint[r as usize] = self.one().id;
                self.reverse_sweep(&tape, &mut adjoint);
                for (j, &v) in vars.iter().enumerate() {
                    let a = adjoint[v as usize];
                    if a != NONE && !self.wrap(a).is_zero() {
                        entries.push((i, j, self.wrap(a)));
                    }
                }
            }
        } else {
            let mut tangent = vec![NONE; self.len()];
            for (j, &v) in vars.iter().enumerate() {
                tangent.fill(NONE);
                tangent[v as usize] = self.one().id;
                self.forward_sweep(&tape, &mut tangent);
                for (i, &r) in roots.iter().enumerate() {
                    let t = tangent[r as usize];
                    if t != NONE && !self.wrap(t).is_zero() {
                        entries.push((i, j, self.wrap(t)));
                    }
                }
            }
            entries.sort_by_key(|&(i, j, _)| (i, j));
        }
        Ok(Jacobian::from_sorted_entries(self, m, n, entries))
    }

    /// The Hessian of a scalar `f` with respect to the symbols `wrt` (the Jacobian of its
    /// gradient), made exactly symmetric: entry `(i, j)` and `(j, i)` are the same expression,
    /// taken from the lower triangle.
    ///
    /// # Errors
    /// [`DslError::NotASymbol`] or [`DslError::DuplicateInput`] for a bad `wrt`.
    pub fn hessian<'g>(&'g self, f: Expr<'g>, wrt: &[Expr<'g>]) -> Result<Jacobian<'g>> {
        let grad = self.gradient(f, wrt)?;
        let jac = self.jacobian(&grad, wrt)?;
        let n = wrt.len();
        let mut entries = Vec::with_capacity(jac.nnz());
        for (i, j, e) in jac.iter() {
            if j <= i {
                entries.push((i, j, e));
                if j < i {
                    entries.push((j, i, e));
                }
            } else if jac.get(j, i).is_none() {
                // Mathematically symmetric, but the lower entry simplified to zero while this
                // one did not: keep it on both sides rather than lose it.
                entries.push((i, j, e));
                entries.push((j, i, e));
            }
        }
        entries.sort_by_key(|&(i, j, _)| (i, j));
        entries.dedup_by_key(|&mut (i, j, _)| (i, j));
        Ok(Jacobian::from_sorted_entries(self, n, n, entries))
    }

    /// Hessian-vector product `H v` of a scalar `f` (forward mode over the reverse-mode
    /// gradient: one extra sweep, no Hessian is formed).
    ///
    /// # Errors
    /// As [`jvp`](Self::jvp).
    pub fn hvp<'g>(
        &'g self,
        f: Expr<'g>,
        wrt: &[Expr<'g>],
        v: &[Expr<'g>],
    ) -> Result<Vec<Expr<'g>>> {
        let grad = self.gradient(f, wrt)?;
        self.jvp(&grad, wrt, v)
    }
}

/// A sparsity pattern in compressed sparse row form.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Sparsity {
    nrows: usize,
    ncols: usize,
    row_ptr: Vec<usize>,
    col_idx: Vec<usize>,
}

impl Sparsity {
    /// Number of rows.
    pub fn nrows(&self) -> usize {
        self.nrows
    }
    /// Number of columns.
    pub fn ncols(&self) -> usize {
        self.ncols
    }
    /// Number of structural nonzeros.
    pub fn nnz(&self) -> usize {
        self.col_idx.len()
    }
    /// Row pointers: the nonzeros of row `i` are at positions `row_ptr[i]..row_ptr[i + 1]`.
    pub fn row_ptr(&self) -> &[usize] {
        &self.row_ptr
    }
    /// Column index of each nonzero, row by row, increasing within a row.
    pub fn col_idx(&self) -> &[usize] {
        &self.col_idx
    }
    /// Whether `(row, col)` is a structural nonzero.
    pub fn contains(&self, row: usize, col: usize) -> bool {
        self.position(row, col).is_some()
    }
    /// Position of `(row, col)` among the nonzeros.
    pub fn position(&self, row: usize, col: usize) -> Option<usize> {
        if row >= self.nrows {
            return None;
        }
        let (lo, hi) = (self.row_ptr[row], self.row_ptr[row + 1]);
        self.col_idx[lo..hi]
            .binary_search(&col)
            .ok()
            .map(|k| lo + k)
    }
    /// The nonzeros as `(row, col)`, row by row.
    pub fn iter(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..self.nrows)
            .flat_map(move |i| (self.row_ptr[i]..self.row_ptr[i + 1]).map(move |k| (i, k)))
            .map(|(i, k)| (i, self.col_idx[k]))
    }
}

/// A sparse matrix of expressions (a Jacobian or Hessian): a [`Sparsity`] and one expression
/// per structural nonzero.
#[derive(Clone, Debug)]
pub struct Jacobian<'g> {
    graph: &'g Graph,
    sparsity: Sparsity,
    values: Vec<Expr<'g>>,
}

impl<'g> Jacobian<'g> {
    fn from_sorted_entries(
        graph: &'g Graph,
        nrows: usize,
        ncols: usize,
        entries: Vec<(usize, usize, Expr<'g>)>,
    ) -> Jacobian<'g> {
        let mut row_ptr = vec![0; nrows + 1];
        for &(i, _, _) in &entries {
            row_ptr[i + 1] += 1;
        }
        for i in 0..nrows {
            row_ptr[i + 1] += row_ptr[i];
        }
        let col_idx = entries.iter().map(|&(_, j, _)| j).collect();
        let values = entries.into_iter().map(|(_, _, e)| e).collect();
        Jacobian {
            graph,
            sparsity: Sparsity {
                nrows,
                ncols,
                row_ptr,
                col_idx,
            },
            values,
        }
    }

    /// Number of rows (outputs).
    pub fn nrows(&self) -> usize {
        self.sparsity.nrows
    }
    /// Number of columns (variables).
    pub fn ncols(&self) -> usize {
        self.sparsity.ncols
    }
    /// Number of structural nonzeros.
    pub fn nnz(&self) -> usize {
        self.values.len()
    }
    /// The sparsity pattern.
    pub fn sparsity(&self) -> &Sparsity {
        &self.sparsity
    }
    /// The nonzero expressions, in the order of [`Sparsity::iter`].
    pub fn values(&self) -> &[Expr<'g>] {
        &self.values
    }
    /// The entry at `(row, col)`, or `None` if it is structurally zero.
    pub fn get(&self, row: usize, col: usize) -> Option<Expr<'g>> {
        self.sparsity.position(row, col).map(|k| self.values[k])
    }
    /// The nonzeros as `(row, col, expression)`.
    pub fn iter(&self) -> impl Iterator<Item = (usize, usize, Expr<'g>)> + '_ {
        self.sparsity
            .iter()
            .zip(&self.values)
            .map(|((i, j), &e)| (i, j, e))
    }
    /// The dense matrix, with the constant 0 at structural zeros.
    pub fn to_dense(&self) -> Matrix<'g> {
        let (m, n) = (self.nrows(), self.ncols());
        let mut data = vec![self.graph.zero(); m * n];
        for (i, j, e) in self.iter() {
            data[i * n + j] = e;
        }
        Matrix::from_row_major(m, n, data)
            .unwrap_or_else(|_| unreachable!("buffer has exactly m * n entries"))
    }
}
