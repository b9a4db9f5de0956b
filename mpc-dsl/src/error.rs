//! Typed errors of the symbolic core.
//!
//! Every message names the offending item and says what to change, because the person reading
//! it is a model author, not the author of this crate.

use thiserror::Error;

/// Everything that can go wrong while building, differentiating, evaluating or lowering
/// expressions.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DslError {
    /// A symbol reached by an output has no value (evaluation) or is not in the input list
    /// (lowering to a [`Program`](crate::Program)).
    #[error(
        "symbol `{name}` has no value: bind it in the inputs you pass to evaluation, \
         or add it to the program's input list"
    )]
    UnboundSymbol {
        /// Name of the symbol.
        name: String,
    },

    /// A constant that is NaN or infinite is reachable from an output.
    #[error(
        "constant {value} is not finite: replace it with a finite number \
         (NaN and infinity cannot be evaluated or compiled into a solver)"
    )]
    NonFiniteConstant {
        /// The offending value.
        value: f64,
    },

    /// Operands of a vector or matrix helper have incompatible shapes.
    #[error("{op}: expected {expected}, found {found}; fix the shape of the operand")]
    DimensionMismatch {
        /// The helper that was called, e.g. `cross`.
        op: &'static str,
        /// The shape it needs, e.g. `two vectors of length 3`.
        expected: String,
        /// The shape it was given.
        found: String,
    },

    /// A helper that must create a constant was given only empty vectors, so it cannot tell
    /// which graph the result belongs to.
    #[error(
        "{op}: all operands are empty, so there is no graph to build the result in; \
         pass at least one element"
    )]
    Empty {
        /// The helper that was called.
        op: &'static str,
    },

    /// Derivatives, bindings and program inputs are taken with respect to symbols only.
    #[error(
        "`{expr}` is not a symbol: derivatives, bindings and program inputs must be symbols \
         created with Graph::symbol"
    )]
    NotASymbol {
        /// The expression, printed.
        expr: String,
    },

    /// The same symbol was listed twice as an input or differentiation variable.
    #[error("symbol `{name}` is listed twice as an input; list every input once")]
    DuplicateInput {
        /// Name of the symbol.
        name: String,
    },

    /// A numeric buffer or a seed vector has the wrong length.
    #[error("{what}: expected {expected} values, got {found}")]
    LengthMismatch {
        /// What the buffer is for.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Given length.
        found: usize,
    },

    /// An expression was asked of something that has none: the step of an implicit
    /// integrator is the solution of a nonlinear system, found by Newton iterations in
    /// generated code.
    #[error(
        "{what} has no closed-form expression: it is solved by Newton iterations in the \
         generated code; evaluate the generated dynamics instead"
    )]
    NoClosedForm {
        /// What was asked for.
        what: &'static str,
    },
}

/// Result type of this crate.
pub type Result<T, E = DslError> = core::result::Result<T, E>;
