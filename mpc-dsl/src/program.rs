//! Lowering a set of outputs to straight-line code: an ordered list of instructions in static
//! single assignment form, each distinct node computed once. This is what code generators emit.
//!
//! The graph is hash-consed, so structurally equal subexpressions already are one node;
//! lowering keeps exactly the nodes the outputs need. Instructions are numbered by a
//! depth-first post-order walk from the outputs (in output order, operands left to right), so
//! the program depends only on the outputs' structure, not on what else the graph holds or in
//! which order it was built: the same model gives the same program byte for byte.

use core::fmt;

use crate::error::{DslError, Result};
use crate::graph::{Expr, Graph, Node, NodeId};
use crate::ops::{BinaryOp, UnaryOp, powi};

/// An instruction operand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Operand {
    /// The program input at this position.
    Input(u32),
    /// A finite constant.
    Const(f64),
    /// The result of the instruction at this position.
    Temp(u32),
}

/// One instruction; its result is the temporary with the instruction's position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Instr {
    /// `op(a)`
    Unary(UnaryOp, Operand),
    /// `a^n`, evaluated by repeated squaring (see [`crate::ops::powi`]).
    PowI(Operand, i32),
    /// `op(a, b)`
    Binary(BinaryOp, Operand, Operand),
}

impl Instr {
    /// The operands, in order.
    pub fn operands(&self) -> impl Iterator<Item = Operand> {
        let (a, b) = match *self {
            Instr::Unary(_, a) | Instr::PowI(a, _) => (a, None),
            Instr::Binary(_, a, b) => (a, Some(b)),
        };
        core::iter::once(a).chain(b)
    }
}

/// Straight-line code computing some outputs from some inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    inputs: Vec<String>,
    instrs: Vec<Instr>,
    outputs: Vec<Operand>,
}

impl Graph {
    /// Lowers `outputs` to a [`Program`] over the symbols `inputs` (in that order).
    ///
    /// ```
    /// use mpc_dsl::Graph;
    /// let g = Graph::new();
    /// let (x, y) = (g.symbol("x"), g.symbol("y"));
    /// let s = (x * y).sin();
    /// let p = g.compile(&[s + x, s * y], &[x, y]).unwrap();
    /// assert_eq!(p.instrs().len(), 4); // x*y, sin, +, * : sin(x*y) computed once
    /// assert_eq!(p.eval(&[1.0, 2.0]).unwrap()[0], 2f64.sin() + 1.0);
    /// ```
    ///
    /// # Errors
    /// [`DslError::UnboundSymbol`] if an output uses a symbol not in `inputs`,
    /// [`DslError::NonFiniteConstant`] if it uses a NaN or infinite constant,
    /// [`DslError::NotASymbol`] / [`DslError::DuplicateInput`] for a bad input list.
    pub fn compile(&self, outputs: &[Expr<'_>], inputs: &[Expr<'_>]) -> Result<Program> {
        for &o in outputs {
            self.check_same(o);
        }
        let sym_idx = self.symbol_indices(inputs)?;
        let inner = self.inner.borrow();
        let mut input_pos = vec![u32::MAX; inner.symbol_names.len()];
        for (k, &s) in sym_idx.iter().enumerate() {
            input_pos[s as usize] = k as u32;
        }
        // Operand of every lowered node, indexed by node id; `None` = not lowered yet.
        let mut lowered: Vec<Option<Operand>> = vec![None; inner.nodes.len()];
        let mut instrs = Vec::new();
        let mut stack: Vec<(NodeId, bool)> = Vec::new();
        let mut out = Vec::with_capacity(outputs.len());
        for &o in outputs {
            stack.push((o.id, false));
            while let Some((n, expanded)) = stack.pop() {
                if lowered[n as usize].is_some() {
                    continue;
                }
                let node = inner.nodes[n as usize];
                if !expanded {
                    stack.push((n, true));
                    // Push operands in reverse so the first operand is lowered first.
                    let (first, second) = match node {
                        Node::Const(_) | Node::Symbol(_) => (None, None),
                        Node::Unary(_, a) | Node::PowI(a, _) => (Some(a), None),
                        Node::Binary(_, a, b) => (Some(a), Some(b)),
                    };
                    for c in [second, first].into_iter().flatten() {
                        if lowered[c as usize].is_none() {
                            stack.push((c, false));
                        }
                    }
                    continue;
                }
                let op = |c: NodeId| {
                    lowered[c as usize]
                        .unwrap_or_else(|| unreachable!("operands are lowered first"))
                };
                let operand = match node {
                    Node::Const(_) => {
                        let v = node.const_value().unwrap_or(f64::NAN);
                        if !v.is_finite() {
                            return Err(DslError::NonFiniteConstant { value: v });
                        }
                        Operand::Const(v)
                    }
                    Node::Symbol(s) => match input_pos[s as usize] {
                        u32::MAX => {
                            return Err(DslError::UnboundSymbol {
                                name: inner.symbol_names[s as usize].to_string(),
                            });
                        }
                        k => Operand::Input(k),
                    },
                    Node::Unary(u, a) => {
                        instrs.push(Instr::Unary(u, op(a)));
                        Operand::Temp(instrs.len() as u32 - 1)
                    }
                    Node::PowI(a, k) => {
                        instrs.push(Instr::PowI(op(a), k));
                        Operand::Temp(instrs.len() as u32 - 1)
                    }
                    Node::Binary(b, x, y) => {
                        instrs.push(Instr::Binary(b, op(x), op(y)));
                        Operand::Temp(instrs.len() as u32 - 1)
                    }
                };
                lowered[n as usize] = Some(operand);
            }
            out.push(lowered[o.id as usize].unwrap_or_else(|| unreachable!("output lowered")));
        }
        Ok(Program {
            inputs: sym_idx
                .iter()
                .map(|&s| inner.symbol_names[s as usize].to_string())
                .collect(),
            instrs,
            outputs: out,
        })
    }
}

impl Program {
    /// Names of the inputs, in order.
    pub fn inputs(&self) -> &[String] {
        &self.inputs
    }

    /// The instructions, in execution order.
    pub fn instrs(&self) -> &[Instr] {
        &self.instrs
    }

    /// Where each output is found.
    pub fn outputs(&self) -> &[Operand] {
        &self.outputs
    }

    /// The largest number of temporaries alive at once (a temporary dies after its last use
    /// by an instruction or output): the scratch memory a register-allocating emitter needs.
    pub fn max_live(&self) -> usize {
        let n = self.instrs.len();
        let mut last_use = vec![0usize; n];
        for (i, ins) in self.instrs.iter().enumerate() {
            last_use[i] = i;
            for o in ins.operands() {
                if let Operand::Temp(t) = o {
                    last_use[t as usize] = i;
                }
            }
        }
        for o in &self.outputs {
            if let Operand::Temp(t) = *o {
                last_use[t as usize] = n;
            }
        }
        // Sweep: +1 at definition, -1 after last use.
        let mut delta = vec![0i64; n + 2];
        for (i, &l) in last_use.iter().enumerate() {
            delta[i] += 1;
            delta[l + 1] -= 1;
        }
        let (mut live, mut best) = (0i64, 0i64);
        for d in delta {
            live += d;
            best = best.max(live);
        }
        best as usize
    }

    /// Evaluates the program.
    ///
    /// # Errors
    /// [`DslError::LengthMismatch`] if `inputs` does not have one value per input.
    pub fn eval(&self, inputs: &[f64]) -> Result<Vec<f64>> {
        let mut work = Vec::new();
        let mut out = vec![0.0; self.outputs.len()];
        self.eval_into(inputs, &mut work, &mut out)?;
        Ok(out)
    }

    /// Evaluates the program into `out`, reusing `work` as scratch (no allocation once `work`
    /// has grown to the number of instructions).
    ///
    /// # Errors
    /// [`DslError::LengthMismatch`] if `inputs` or `out` have the wrong length.
    pub fn eval_into(&self, inputs: &[f64], work: &mut Vec<f64>, out: &mut [f64]) -> Result<()> {
        if inputs.len() != self.inputs.len() {
            return Err(DslError::LengthMismatch {
                what: "program inputs",
                expected: self.inputs.len(),
                found: inputs.len(),
            });
        }
        if out.len() != self.outputs.len() {
            return Err(DslError::LengthMismatch {
                what: "program outputs",
                expected: self.outputs.len(),
                found: out.len(),
            });
        }
        work.clear();
        work.reserve(self.instrs.len());
        for ins in &self.instrs {
            let v = |o: Operand, work: &[f64]| match o {
                Operand::Input(k) => inputs[k as usize],
                Operand::Const(c) => c,
                Operand::Temp(t) => work[t as usize],
            };
            let r = match *ins {
                Instr::Unary(op, a) => op.apply(v(a, work)),
                Instr::PowI(a, n) => powi(v(a, work), n),
                Instr::Binary(op, a, b) => op.apply(v(a, work), v(b, work)),
            };
            work.push(r);
        }
        for (o, &src) in out.iter_mut().zip(&self.outputs) {
            *o = match src {
                Operand::Input(k) => inputs[k as usize],
                Operand::Const(c) => c,
                Operand::Temp(t) => work[t as usize],
            };
        }
        Ok(())
    }
}

impl fmt::Display for Operand {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Operand::Input(k) => write!(f, "in{k}"),
            // `{:?}` prints the shortest representation that round-trips.
            Operand::Const(c) => write!(f, "{c:?}"),
            Operand::Temp(t) => write!(f, "t{t}"),
        }
    }
}

/// One line per input, instruction and output:
///
/// ```text
/// in0 = x
/// t0 = in0 * in1
/// t1 = sin(t0)
/// out0 = t1
/// ```
impl fmt::Display for Program {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, name) in self.inputs.iter().enumerate() {
            writeln!(f, "in{k} = {name}")?;
        }
        for (i, ins) in self.instrs.iter().enumerate() {
            match *ins {
                Instr::Unary(UnaryOp::Neg, a) => writeln!(f, "t{i} = -{a}")?,
                Instr::Unary(op, a) => writeln!(f, "t{i} = {}({a})", op.name())?,
                Instr::PowI(a, n) => writeln!(f, "t{i} = {a}^{n}")?,
                Instr::Binary(op, a, b) if op.is_infix() => {
                    writeln!(f, "t{i} = {a} {} {b}", op.name())?
                }
                Instr::Binary(op, a, b) => writeln!(f, "t{i} = {}({a}, {b})", op.name())?,
            }
        }
        for (k, o) in self.outputs.iter().enumerate() {
            writeln!(f, "out{k} = {o}")?;
        }
        Ok(())
    }
}
