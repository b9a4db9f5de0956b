//! The hash-consed expression graph and the [`Expr`] handle.
//!
//! A [`Graph`] is an arena of nodes in which every child has a smaller index than its parent,
//! so index order is a topological order. Building a node that already exists returns the
//! existing one (hash-consing), and a short list of local rewrite rules runs at construction
//! (see [`Graph::unary`] and [`Graph::binary`]). Node indices depend only on the order of
//! construction, never on hashing, so the same program always builds the same graph.

use core::cell::RefCell;
use core::hash::BuildHasher;
use std::rc::Rc;

use hashbrown::{DefaultHashBuilder, HashMap, HashTable};

use crate::error::{DslError, Result};
use crate::ops::{BinaryOp, UnaryOp, powi};

/// Index of a node in its graph.
pub(crate) type NodeId = u32;

/// One node. Twelve bytes: constants are stored as the two halves of their bit pattern so the
/// enum keeps 4-byte alignment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Node {
    Const([u32; 2]),
    Symbol(u32),
    Unary(UnaryOp, NodeId),
    PowI(NodeId, i32),
    Binary(BinaryOp, NodeId, NodeId),
}

impl Node {
    fn constant(value: f64) -> Node {
        // One canonical zero and one canonical NaN, so equal values share a node.
        let v = if value == 0.0 {
            0.0
        } else if value.is_nan() {
            f64::NAN
        } else {
            value
        };
        let bits = v.to_bits();
        Node::Const([(bits >> 32) as u32, bits as u32])
    }

    pub(crate) fn const_value(&self) -> Option<f64> {
        match *self {
            Node::Const([hi, lo]) => Some(f64::from_bits((u64::from(hi) << 32) | u64::from(lo))),
            _ => None,
        }
    }
}

#[derive(Default)]
pub(crate) struct Inner {
    pub(crate) nodes: Vec<Node>,
    table: HashTable<NodeId>,
    hasher: DefaultHashBuilder,
    pub(crate) symbol_names: Vec<Rc<str>>,
    symbol_lookup: HashMap<Rc<str>, NodeId>,
    /// Per node: whether it depends on no symbol (a constant, or an operation on constants
    /// that was not folded because its value is not finite).
    symbol_free: Vec<bool>,
}

impl Inner {
    fn intern(&mut self, node: Node) -> NodeId {
        let hash = self.hasher.hash_one(node);
        let nodes = &self.nodes;
        if let Some(&id) = self.table.find(hash, |&id| nodes[id as usize] == node) {
            return id;
        }
        let id =
            NodeId::try_from(self.nodes.len()).expect("expression graph is limited to 2^32 nodes");
        let free = |c: NodeId| self.symbol_free[c as usize];
        let symbol_free = match node {
            Node::Const(_) => true,
            Node::Symbol(_) => false,
            Node::Unary(_, a) | Node::PowI(a, _) => free(a),
            Node::Binary(_, a, b) => free(a) && free(b),
        };
        self.symbol_free.push(symbol_free);
        self.nodes.push(node);
        let (nodes, hasher) = (&self.nodes, &self.hasher);
        self.table
            .insert_unique(hash, id, |&i| hasher.hash_one(nodes[i as usize]));
        id
    }
}

/// Buckets behind a hashbrown table of the given capacity (7/8 load factor from 8 buckets on).
fn hash_buckets(capacity: usize) -> usize {
    match capacity {
        0 => 0,
        1..=7 => (capacity + 1).next_power_of_two(),
        _ => (capacity * 8 / 7).next_power_of_two(),
    }
}

/// An arena of hash-consed scalar expressions.
///
/// Create one per model (or per program run); every [`Expr`] borrows it. Expressions from
/// two different graphs cannot be combined.
///
/// ```
/// use mpc_dsl::Graph;
/// let g = Graph::new();
/// let x = g.symbol("x");
/// let y = g.symbol("y");
/// let f = (x * y).sin() + x;
/// assert_eq!(f, (x * y).sin() + x); // built twice, one node
/// assert_eq!(x + 0.0, x);           // simplified at construction
/// ```
#[derive(Default)]
pub struct Graph {
    pub(crate) inner: RefCell<Inner>,
}

impl core::fmt::Debug for Graph {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let inner = self.inner.borrow();
        f.debug_struct("Graph")
            .field("nodes", &inner.nodes.len())
            .field("symbols", &inner.symbol_names.len())
            .finish()
    }
}

/// A handle to a node of a [`Graph`]: cheap to copy, with arithmetic operators.
///
/// Two handles are equal exactly when they name the same node, which, thanks to hash-consing,
/// is when they were built from the same operations on the same operands.
#[derive(Clone, Copy)]
pub struct Expr<'g> {
    pub(crate) graph: &'g Graph,
    pub(crate) id: NodeId,
}

/// The structure of one node, as seen from outside the graph.
#[derive(Clone, Debug, PartialEq)]
pub enum ExprKind<'g> {
    /// A finite or non-finite constant.
    Constant(f64),
    /// A named symbol.
    Symbol(Rc<str>),
    /// A unary operation.
    Unary(UnaryOp, Expr<'g>),
    /// An integer power.
    PowI(Expr<'g>, i32),
    /// A binary operation.
    Binary(BinaryOp, Expr<'g>, Expr<'g>),
}

impl Graph {
    /// An empty graph.
    pub fn new() -> Graph {
        Graph::default()
    }

    /// Number of nodes built so far (including constants and symbols).
    pub fn len(&self) -> usize {
        self.inner.borrow().nodes.len()
    }

    /// Whether no node has been built yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes held by the graph's own tables (node arena, hash index and symbol names), by
    /// capacity. Used by the memory benchmark; an allocator-level count is the independent
    /// check.
    pub fn heap_bytes(&self) -> usize {
        let inner = self.inner.borrow();
        inner.nodes.capacity() * size_of::<Node>()
            + inner.symbol_free.capacity()
            + hash_buckets(inner.table.capacity()) * (size_of::<NodeId>() + 1)
            + inner
                .symbol_names
                .iter()
                .map(|s| s.len() + 2 * size_of::<usize>())
                .sum::<usize>()
            + inner.symbol_lookup.capacity() * (size_of::<(Rc<str>, NodeId)>() + 1)
    }

    /// The symbol called `name`. Asking twice for the same name returns the same symbol.
    pub fn symbol(&self, name: &str) -> Expr<'_> {
        let mut inner = self.inner.borrow_mut();
        if let Some(&id) = inner.symbol_lookup.get(name) {
            return self.wrap(id);
        }
        let index = inner.symbol_names.len() as u32;
        let name: Rc<str> = Rc::from(name);
        inner.symbol_names.push(name.clone());
        let id = inner.intern(Node::Symbol(index));
        inner.symbol_lookup.insert(name, id);
        self.wrap(id)
    }

    /// `n` symbols named `name[0]`, ..., `name[n-1]`.
    pub fn symbols(&self, name: &str, n: usize) -> crate::Vector<'_> {
        (0..n)
            .map(|i| self.symbol(&format!("{name}[{i}]")))
            .collect()
    }

    /// A constant. Fails for NaN and infinity, which no solver can use.
    pub fn constant(&self, value: f64) -> Result<Expr<'_>> {
        if value.is_finite() {
            Ok(self.constant_unchecked(value))
        } else {
            Err(DslError::NonFiniteConstant { value })
        }
    }

    /// A constant without the finiteness check. This is what arithmetic with `f64` operands
    /// uses; a non-finite constant built this way is reported with
    /// [`DslError::NonFiniteConstant`] when an output that depends on it is evaluated or
    /// lowered.
    pub fn constant_unchecked(&self, value: f64) -> Expr<'_> {
        let id = self.inner.borrow_mut().intern(Node::constant(value));
        self.wrap(id)
    }

    /// The constant 0.
    pub fn zero(&self) -> Expr<'_> {
        self.constant_unchecked(0.0)
    }

    /// The constant 1.
    pub fn one(&self) -> Expr<'_> {
        self.constant_unchecked(1.0)
    }

    pub(crate) fn wrap(&self, id: NodeId) -> Expr<'_> {
        Expr { graph: self, id }
    }

    pub(crate) fn node(&self, id: NodeId) -> Node {
        self.inner.borrow().nodes[id as usize]
    }

    fn const_of(&self, id: NodeId) -> Option<f64> {
        self.node(id).const_value()
    }

    fn is_const(&self, id: NodeId, value: f64) -> bool {
        self.const_of(id) == Some(value)
    }

    /// Whether node `id` is an operation on constants only that was kept because its value
    /// is not finite (`1/0`, `log(0)`): no rule may drop it (`0 * (1/0)` is NaN, not 0).
    fn is_non_finite_operation(&self, id: NodeId) -> bool {
        self.inner.borrow().symbol_free[id as usize] && self.const_of(id).is_none()
    }

    fn push(&self, node: Node) -> Expr<'_> {
        let id = self.inner.borrow_mut().intern(node);
        self.wrap(id)
    }

    /// Builds `op(a)`, folding constants and applying these rules:
    /// `-(-x) = x`; `-(a - b) = b - a` (exact in IEEE arithmetic, and keeps negations from
    /// piling up in adjoints); `|(-x)| = |x|`; `||x|| = |x|`.
    pub fn unary(&self, op: UnaryOp, a: Expr<'_>) -> Expr<'_> {
        self.check_same(a);
        if let Some(v) = self.const_of(a.id) {
            let r = op.apply(v);
            // Folding that would create NaN/inf (log(0), sqrt(-1)) keeps the operation, so
            // the problem stays visible in the model instead of becoming an opaque constant.
            if r.is_finite() || !v.is_finite() {
                return self.constant_unchecked(r);
            }
        }
        match (op, self.node(a.id)) {
            (UnaryOp::Neg, Node::Unary(UnaryOp::Neg, x)) => return self.wrap(x),
            (UnaryOp::Neg, Node::Binary(BinaryOp::Sub, x, y)) => {
                return self.push(Node::Binary(BinaryOp::Sub, y, x));
            }
            (UnaryOp::Abs, Node::Unary(UnaryOp::Neg | UnaryOp::Abs, x)) => {
                return self.unary(UnaryOp::Abs, self.wrap(x));
            }
            _ => {}
        }
        self.push(Node::Unary(op, a.id))
    }

    /// Builds `a^n` for an integer `n`: `a^0 = 1`, `a^1 = a`, constants fold.
    pub fn powi(&self, a: Expr<'_>, n: i32) -> Expr<'_> {
        self.check_same(a);
        match n {
            0 => return self.one(),
            1 => return self.wrap(a.id),
            _ => {}
        }
        if let Some(v) = self.const_of(a.id) {
            let r = powi(v, n);
            if r.is_finite() {
                return self.constant_unchecked(r);
            }
        }
        self.push(Node::PowI(a.id, n))
    }

    /// Builds `op(a, b)`, folding constants and applying these rules (each exact in real
    /// arithmetic; `0 * x = 0` and `x - x = 0` assume `x` finite, as every solver input is:
    /// the generated solver refuses non-finite states, controls and parameters, and
    /// `mpcc check` evaluates every function at the guess; `0 / x = 0` assumes `x != 0`
    /// besides). An operand that is an operation on constants only with a non-finite value
    /// (`1/0`, `sqrt(-1)`, kept unfolded) is never dropped by a rule, and `0 / 0` is not
    /// `0`: IEEE arithmetic gives NaN there, and so does the graph
    /// ([`Expr::is_non_finite_constant`] finds such nodes):
    ///
    /// - `x + 0 = 0 + x = x`, `x + (-y) = x - y`, `(-x) + y = y - x`;
    /// - `x - 0 = x`, `0 - x = -x`, `x - x = 0`, `x - (-y) = x + y`;
    /// - `x * 0 = 0`, `x * 1 = x`, `x * (-1) = -x`, `(-x) * (-y) = x * y`;
    /// - `0 / x = 0`, `x / 1 = x`, `x / (-1) = -x`;
    /// - `x^0 = 1`, `x^1 = x`, `x^0.5 = sqrt(x)`, `x^k = powi(x, k)` for an integer constant `k`;
    /// - `min(x, x) = max(x, x) = x`;
    /// - a constant operand of `+`, `*`, `min`, `max` is put first, so `x * 2` and `2 * x` are
    ///   one node. Non-constant operands keep the order they were given, so the output does
    ///   not depend on node numbering.
    pub fn binary(&self, op: BinaryOp, a: Expr<'_>, b: Expr<'_>) -> Expr<'_> {
        self.check_same(a);
        self.check_same(b);
        let (ca, cb) = (self.const_of(a.id), self.const_of(b.id));
        if let (Some(x), Some(y)) = (ca, cb) {
            let r = op.apply(x, y);
            if r.is_finite() || !(x.is_finite() && y.is_finite()) {
                return self.constant_unchecked(r);
            }
        }
        let (mut a, mut b) = (a.id, b.id);
        if op.is_commutative() && cb.is_some() && ca.is_none() {
            core::mem::swap(&mut a, &mut b);
        }
        let (na, nb) = (self.node(a), self.node(b));
        let (ca, cb) = (na.const_value(), nb.const_value());
        let neg_of = |n: Node| match n {
            Node::Unary(UnaryOp::Neg, x) => Some(x),
            _ => None,
        };
        match op {
            BinaryOp::Add => {
                if ca == Some(0.0) {
                    return self.wrap(b);
                }
                if let Some(y) = neg_of(nb) {
                    return self.binary(BinaryOp::Sub, self.wrap(a), self.wrap(y));
                }
                if let Some(x) = neg_of(na) {
                    return self.binary(BinaryOp::Sub, self.wrap(b), self.wrap(x));
                }
            }
            BinaryOp::Sub => {
                if cb == Some(0.0) {
                    return self.wrap(a);
                }
                if ca == Some(0.0) {
                    return self.unary(UnaryOp::Neg, self.wrap(b));
                }
                if a == b && !self.is_non_finite_operation(a) {
                    return self.zero();
                }
                if let Some(y) = neg_of(nb) {
                    return self.binary(BinaryOp::Add, self.wrap(a), self.wrap(y));
                }
            }
            BinaryOp::Mul => {
                if ca == Some(0.0) && !self.is_non_finite_operation(b) {
                    return self.zero();
                }
                if ca == Some(1.0) {
                    return self.wrap(b);
                }
                if ca == Some(-1.0) {
                    return self.unary(UnaryOp::Neg, self.wrap(b));
                }
                if let (Some(x), Some(y)) = (neg_of(na), neg_of(nb)) {
                    return self.binary(BinaryOp::Mul, self.wrap(x), self.wrap(y));
                }
            }
            BinaryOp::Div => {
                if ca == Some(0.0) && cb.is_none() && !self.is_non_finite_operation(b) {
                    return self.zero();
                }
                if cb == Some(1.0) {
                    return self.wrap(a);
                }
                if cb == Some(-1.0) {
                    return self.unary(UnaryOp::Neg, self.wrap(a));
                }
            }
            BinaryOp::Pow => {
                if let Some(e) = cb {
                    if e == 0.5 {
                        return self.unary(UnaryOp::Sqrt, self.wrap(a));
                    }
                    if e.fract() == 0.0 && e.abs() <= f64::from(i32::MAX) {
                        return self.powi(self.wrap(a), e as i32);
                    }
                }
            }
            BinaryOp::Min | BinaryOp::Max => {
                if a == b {
                    return self.wrap(a);
                }
            }
            BinaryOp::Atan2 => {}
        }
        self.push(Node::Binary(op, a, b))
    }

    #[track_caller]
    pub(crate) fn check_same(&self, e: Expr<'_>) {
        assert!(
            core::ptr::eq(self, e.graph),
            "expressions from two different mpc_dsl::Graph values were combined; \
             build a whole model in one graph"
        );
    }
}

impl<'g> Expr<'g> {
    /// The graph this expression lives in.
    pub fn graph(&self) -> &'g Graph {
        self.graph
    }

    /// The node's index in its graph: its position in construction order.
    pub fn index(&self) -> usize {
        self.id as usize
    }

    /// The structure of this node.
    pub fn kind(&self) -> ExprKind<'g> {
        let g = self.graph;
        match g.node(self.id) {
            n @ Node::Const(_) => ExprKind::Constant(n.const_value().unwrap_or(f64::NAN)),
            Node::Symbol(s) => ExprKind::Symbol(g.inner.borrow().symbol_names[s as usize].clone()),
            Node::Unary(op, a) => ExprKind::Unary(op, g.wrap(a)),
            Node::PowI(a, n) => ExprKind::PowI(g.wrap(a), n),
            Node::Binary(op, a, b) => ExprKind::Binary(op, g.wrap(a), g.wrap(b)),
        }
    }

    /// The value, if this is a constant.
    pub fn as_constant(&self) -> Option<f64> {
        self.graph.const_of(self.id)
    }

    /// The name, if this is a symbol.
    pub fn symbol_name(&self) -> Option<Rc<str>> {
        match self.graph.node(self.id) {
            Node::Symbol(s) => Some(self.graph.inner.borrow().symbol_names[s as usize].clone()),
            _ => None,
        }
    }

    /// Whether this is a symbol.
    pub fn is_symbol(&self) -> bool {
        matches!(self.graph.node(self.id), Node::Symbol(_))
    }

    /// Whether this is a constant expression whose value is not finite: a NaN or infinite
    /// constant, or an operation on constants only that was not folded because its value
    /// is not finite (`1/0`, `0/0`, `sqrt(-1)`, `log(0)`, `1e308 * 10`).
    pub fn is_non_finite_constant(&self) -> bool {
        match self.as_constant() {
            Some(v) => !v.is_finite(),
            None => self.graph.is_non_finite_operation(self.id),
        }
    }

    /// The IEEE value of an expression without symbols (`None` if it depends on one). This
    /// is how a non-finite constant expression (see
    /// [`is_non_finite_constant`](Self::is_non_finite_constant)) is shown to the user.
    pub fn constant_value(&self) -> Option<f64> {
        if let Some(v) = self.as_constant() {
            return Some(v);
        }
        if !self.graph.inner.borrow().symbol_free[self.id as usize] {
            return None;
        }
        match self.kind() {
            ExprKind::Constant(v) => Some(v),
            ExprKind::Symbol(_) => None,
            ExprKind::Unary(op, a) => Some(op.apply(a.constant_value()?)),
            ExprKind::PowI(a, n) => Some(powi(a.constant_value()?, n)),
            ExprKind::Binary(op, a, b) => Some(op.apply(a.constant_value()?, b.constant_value()?)),
        }
    }

    /// Whether this is the constant 0.
    pub fn is_zero(&self) -> bool {
        self.graph.is_const(self.id, 0.0)
    }

    fn un(self, op: UnaryOp) -> Expr<'g> {
        self.graph.unary(op, self)
    }

    /// `sqrt(self)`
    pub fn sqrt(self) -> Expr<'g> {
        self.un(UnaryOp::Sqrt)
    }
    /// `sin(self)`
    pub fn sin(self) -> Expr<'g> {
        self.un(UnaryOp::Sin)
    }
    /// `cos(self)`
    pub fn cos(self) -> Expr<'g> {
        self.un(UnaryOp::Cos)
    }
    /// `tan(self)`
    pub fn tan(self) -> Expr<'g> {
        self.un(UnaryOp::Tan)
    }
    /// `asin(self)`
    pub fn asin(self) -> Expr<'g> {
        self.un(UnaryOp::Asin)
    }
    /// `acos(self)`
    pub fn acos(self) -> Expr<'g> {
        self.un(UnaryOp::Acos)
    }
    /// `atan(self)`
    pub fn atan(self) -> Expr<'g> {
        self.un(UnaryOp::Atan)
    }
    /// `exp(self)`
    pub fn exp(self) -> Expr<'g> {
        self.un(UnaryOp::Exp)
    }
    /// Natural logarithm.
    pub fn ln(self) -> Expr<'g> {
        self.un(UnaryOp::Log)
    }
    /// `tanh(self)`
    pub fn tanh(self) -> Expr<'g> {
        self.un(UnaryOp::Tanh)
    }
    /// `|self|`; its derivative is `sign(self)`.
    pub fn abs(self) -> Expr<'g> {
        self.un(UnaryOp::Abs)
    }
    /// `sign(self)` (-1, 0, 1); its derivative is 0.
    pub fn sign(self) -> Expr<'g> {
        self.un(UnaryOp::Sign)
    }
    /// Heaviside step: 1 where `self >= 0`, else 0; its derivative is 0.
    pub fn step(self) -> Expr<'g> {
        self.un(UnaryOp::Step)
    }
    /// `self^n` for an integer `n`.
    pub fn powi(self, n: i32) -> Expr<'g> {
        self.graph.powi(self, n)
    }
    /// `self^2`
    pub fn square(self) -> Expr<'g> {
        self.powi(2)
    }
    /// `self^e` for a real exponent.
    pub fn pow(self, e: impl IntoExpr<'g>) -> Expr<'g> {
        let e = e.into_expr(self.graph);
        self.graph.binary(BinaryOp::Pow, self, e)
    }
    /// `atan2(self, x)`: the angle of the point `(x, self)`.
    pub fn atan2(self, x: impl IntoExpr<'g>) -> Expr<'g> {
        let x = x.into_expr(self.graph);
        self.graph.binary(BinaryOp::Atan2, self, x)
    }
    /// `min(self, other)`
    pub fn min(self, other: impl IntoExpr<'g>) -> Expr<'g> {
        let o = other.into_expr(self.graph);
        self.graph.binary(BinaryOp::Min, self, o)
    }
    /// `max(self, other)`
    pub fn max(self, other: impl IntoExpr<'g>) -> Expr<'g> {
        let o = other.into_expr(self.graph);
        self.graph.binary(BinaryOp::Max, self, o)
    }

    /// Smooth sign `x / sqrt(x^2 + eps^2)`: differentiable everywhere, within `eps` of
    /// [`sign`](Self::sign) away from zero. Use it where a derivative through a sign is needed.
    pub fn smooth_sign(self, eps: f64) -> Expr<'g> {
        self / (self.square() + eps * eps).sqrt()
    }

    /// Smooth step `(1 + tanh(x / eps)) / 2`: differentiable everywhere, within `eps` of
    /// [`step`](Self::step) a few `eps` away from zero.
    pub fn smooth_step(self, eps: f64) -> Expr<'g> {
        0.5 * ((self / eps).tanh() + 1.0)
    }

    /// Smooth absolute value `sqrt(x^2 + eps^2)`.
    pub fn smooth_abs(self, eps: f64) -> Expr<'g> {
        (self.square() + eps * eps).sqrt()
    }
}

impl PartialEq for Expr<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.id == other.id && core::ptr::eq(self.graph, other.graph)
    }
}
impl Eq for Expr<'_> {}

impl core::hash::Hash for Expr<'_> {
    fn hash<H: core::hash::Hasher>(&self, state: &mut H) {
        self.id.hash(state);
    }
}

impl PartialOrd for Expr<'_> {
    fn partial_cmp(&self, other: &Self) -> Option<core::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// Orders by construction index (graphs are not mixed).
impl Ord for Expr<'_> {
    fn cmp(&self, other: &Self) -> core::cmp::Ordering {
        self.id.cmp(&other.id)
    }
}

/// Something that can stand as an operand: an [`Expr`] or an `f64` constant.
pub trait IntoExpr<'g> {
    /// Converts into an expression of `graph`.
    fn into_expr(self, graph: &'g Graph) -> Expr<'g>;
}

impl<'g> IntoExpr<'g> for Expr<'g> {
    fn into_expr(self, _graph: &'g Graph) -> Expr<'g> {
        self
    }
}

impl<'g> IntoExpr<'g> for f64 {
    fn into_expr(self, graph: &'g Graph) -> Expr<'g> {
        graph.constant_unchecked(self)
    }
}

macro_rules! binop {
    ($Trait:ident, $method:ident, $Assign:ident, $assign:ident, $op:expr) => {
        impl<'g> core::ops::$Trait<Expr<'g>> for Expr<'g> {
            type Output = Expr<'g>;
            fn $method(self, rhs: Expr<'g>) -> Expr<'g> {
                self.graph.binary($op, self, rhs)
            }
        }
        impl<'g> core::ops::$Trait<f64> for Expr<'g> {
            type Output = Expr<'g>;
            fn $method(self, rhs: f64) -> Expr<'g> {
                self.graph
                    .binary($op, self, self.graph.constant_unchecked(rhs))
            }
        }
        impl<'g> core::ops::$Trait<Expr<'g>> for f64 {
            type Output = Expr<'g>;
            fn $method(self, rhs: Expr<'g>) -> Expr<'g> {
                rhs.graph
                    .binary($op, rhs.graph.constant_unchecked(self), rhs)
            }
        }
        impl<'g> core::ops::$Assign<Expr<'g>> for Expr<'g> {
            fn $assign(&mut self, rhs: Expr<'g>) {
                *self = self.graph.binary($op, *self, rhs);
            }
        }
        impl<'g> core::ops::$Assign<f64> for Expr<'g> {
            fn $assign(&mut self, rhs: f64) {
                *self = self
                    .graph
                    .binary($op, *self, self.graph.constant_unchecked(rhs));
            }
        }
    };
}

binop!(Add, add, AddAssign, add_assign, BinaryOp::Add);
binop!(Sub, sub, SubAssign, sub_assign, BinaryOp::Sub);
binop!(Mul, mul, MulAssign, mul_assign, BinaryOp::Mul);
binop!(Div, div, DivAssign, div_assign, BinaryOp::Div);

impl<'g> core::ops::Neg for Expr<'g> {
    type Output = Expr<'g>;
    fn neg(self) -> Expr<'g> {
        self.graph.unary(UnaryOp::Neg, self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_consing_shares_identical_nodes() {
        let g = Graph::new();
        let (x, y) = (g.symbol("x"), g.symbol("y"));
        let a = (x * y).sin() + x.exp();
        let n = g.len();
        let b = (x * y).sin() + x.exp();
        assert_eq!(a, b);
        assert_eq!(g.len(), n, "rebuilding an expression must not add nodes");
        assert_eq!(g.symbol("x"), x);
        assert_eq!(g.constant(2.5).unwrap(), g.constant(2.5).unwrap());
        assert_eq!(g.constant(0.0).unwrap(), g.constant(-0.0).unwrap());
        assert_ne!(x * y, y * x, "operand order of symbols is kept");
        assert_eq!(x * 2.0, 2.0 * x, "constants go first");
    }

    #[test]
    fn construction_time_simplification() {
        let g = Graph::new();
        let x = g.symbol("x");
        let y = g.symbol("y");
        assert_eq!(x + 0.0, x);
        assert_eq!(0.0 + x, x);
        assert_eq!(x - 0.0, x);
        assert_eq!(0.0 - x, -x);
        assert_eq!(x * 1.0, x);
        assert_eq!(1.0 * x, x);
        assert!((x * 0.0).is_zero());
        assert!((0.0 * x).is_zero());
        assert!((x - x).is_zero());
        assert_eq!(-(-x), x);
        assert_eq!(x / 1.0, x);
        assert!((0.0 / x).is_zero());
        assert_eq!(x * -1.0, -x);
        assert_eq!(x + (-y), x - y);
        assert_eq!((-x) + y, y - x);
        assert_eq!(x - (-y), x + y);
        assert_eq!(-(x - y), y - x);
        assert_eq!((-x) * (-y), x * y);
        assert_eq!(x.powi(1), x);
        assert_eq!(x.powi(0).as_constant(), Some(1.0));
        assert_eq!(x.pow(2.0), x.powi(2));
        assert_eq!(x.pow(0.5), x.sqrt());
        assert_eq!(x.min(x), x);
        assert_eq!((-x).abs(), x.abs());
        assert_eq!(x.abs().abs(), x.abs());
    }

    #[test]
    fn constant_folding() {
        let g = Graph::new();
        let two = g.constant(2.0).unwrap();
        let three = g.constant(3.0).unwrap();
        assert_eq!((two * three + 1.0).as_constant(), Some(7.0));
        assert_eq!(two.sin().as_constant(), Some(libm::sin(2.0)));
        assert_eq!(two.powi(-2).as_constant(), Some(0.25));
        assert_eq!(three.atan2(two).as_constant(), Some(libm::atan2(3.0, 2.0)));
        // Folding that would produce a non-finite value keeps the operation visible.
        let log0 = g.zero().ln();
        assert!(log0.as_constant().is_none());
        assert!((1.0 / g.zero()).as_constant().is_none());
    }

    #[test]
    fn non_finite_constant_expressions_are_never_folded_to_finite_values() {
        let g = Graph::new();
        let (zero, one, x) = (g.zero(), g.one(), g.symbol("x"));
        let inf = one / zero;
        let cases = [
            ("0/0", zero / zero),
            ("0*(1/0)", zero * inf),
            ("(1/0)*0", inf * zero),
            ("1/0", inf),
            ("sqrt(-1)", (-one).sqrt()),
            ("log(0)", zero.ln()),
            ("log(-1)", (-one).ln()),
            ("(-8)^(1/3)", g.constant_unchecked(-8.0).pow(1.0 / 3.0)),
            ("0^-1", zero.powi(-1)),
            ("(1/0)-(1/0)", inf - inf),
            ("0/(1/0 - 1/0)", zero / (inf - inf)),
            ("1e308*10", g.constant_unchecked(1e308) * 10.0),
            ("inf*0", g.constant_unchecked(f64::INFINITY) * 0.0),
        ];
        for (what, e) in cases {
            assert!(e.is_non_finite_constant(), "{what} must stay non-finite");
            let v = e.constant_value().expect("no symbol");
            assert!(!v.is_finite(), "{what} evaluates to {v}");
        }
        assert_eq!((zero / zero).constant_value().map(f64::is_nan), Some(true));
        // Finite constants and expressions of symbols are not non-finite constants.
        assert!(!(one + 2.0).is_non_finite_constant());
        assert!(!(x / zero).is_non_finite_constant());
        assert_eq!((x / zero).constant_value(), None);
        // The rules still apply to symbols (finite by the solver's contract).
        assert!((zero * x).is_zero() && (zero / x).is_zero() && (x - x).is_zero());
    }

    #[test]
    fn building_a_model_twice_adds_no_node() {
        let g = Graph::new();
        let m1 = crate::models::quadrotor_rates(&g).unwrap();
        let n = g.len();
        let m2 = crate::models::quadrotor_rates(&g).unwrap();
        assert_eq!(g.len(), n);
        assert_eq!(m1.xdot, m2.xdot);
    }

    #[test]
    #[should_panic(expected = "two different mpc_dsl::Graph")]
    fn mixing_graphs_is_caught() {
        let g1 = Graph::new();
        let g2 = Graph::new();
        let _ = g1.symbol("x") + g2.symbol("x");
    }

    #[test]
    fn node_is_twelve_bytes() {
        assert_eq!(size_of::<Node>(), 12);
    }
}
