//! # mpc-dsl: the symbolic core of mpcc
//!
//! A hash-consed graph of scalar expressions with construction-time simplification,
//! forward- and reverse-mode automatic differentiation that produces new expressions,
//! Jacobians and Hessians with their sparsity, an f64 interpreter, and lowering to
//! straight-line SSA code with every distinct subexpression computed once.
//!
//! ```
//! use mpc_dsl::{Graph, linalg::{quat_rotate, Vector}};
//!
//! let g = Graph::new();
//! let q = g.symbols("q", 4);                       // attitude quaternion (w, x, y, z)
//! let c = g.symbol("c");                           // collective thrust
//! let acc = quat_rotate(&q, &[g.zero(), g.zero(), c]).unwrap();
//!
//! let mut wrt = q.clone().into_vec();
//! wrt.push(c);
//! let jac = g.jacobian(&acc, &wrt).unwrap();        // 3 x 5, with sparsity
//! let program = g.compile(jac.values(), &wrt).unwrap();
//! let values = program.eval(&[1.0, 0.0, 0.0, 0.0, 9.81]).unwrap();
//! assert_eq!(values.len(), jac.nnz());
//! ```
//!
//! On top of the core, [`ocp`] describes a whole optimal control problem ([`Ocp`], built with
//! [`OcpBuilder`] and checked by [`Ocp::validate`]) and [`lang`] parses the same description
//! from `.mpc` text, with line/column diagnostics (grammar: `docs/mpc-language.md`).
//!
//! Expressions borrow the [`Graph`] they live in; build one model in one graph. Node indices
//! follow construction order and hashing never influences them, so the same model always
//! lowers to the same program.

#![forbid(unsafe_code)]

pub mod ad;
pub mod display;
pub mod error;
pub mod eval;
pub mod graph;
pub mod lang;
pub mod linalg;
pub mod models;
pub mod ocp;
pub mod ops;
pub mod program;

pub use ad::{Jacobian, Sparsity};
pub use error::{DslError, Result};
pub use graph::{Expr, ExprKind, Graph, IntoExpr};
pub use linalg::{Matrix, Vector};
pub use ocp::{Ocp, OcpBuilder, OcpError, OcpWarning, SolverChoices, ValidationErrors};
pub use ops::{BinaryOp, UnaryOp};
pub use program::{Instr, Operand, Program};
