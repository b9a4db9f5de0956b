//! Errors of code generation.

use mpc_dsl::{DslError, ValidationErrors};

/// Why code generation failed. Every message says what to change in the model or options.
#[derive(Debug, thiserror::Error)]
pub enum CodegenError {
    /// The problem does not validate.
    #[error("the model does not validate:\n{0}")]
    Invalid(ValidationErrors),
    /// The problem has no entry of a required kind.
    #[error("the model has no {0}; a solver needs at least one")]
    Empty(&'static str),
    /// A function uses a symbol it may not depend on.
    #[error(
        "the {function} function uses `{symbol}`, but may only depend on {allowed}; \
         move that term to a stage function or make the parameter global"
    )]
    UnexpectedSymbol {
        /// Which function.
        function: &'static str,
        /// The symbol.
        symbol: String,
        /// What it may use.
        allowed: String,
    },
    /// The exact Hessian was asked for a model integrated by `irk`: the implicit step
    /// provides first-order sensitivities only.
    #[error(
        "the exact Hessian (`exact_hessian`, `--exact-hessian`) needs the second derivatives \
         of the integrator step, which the implicit `irk` integrator does not provide: \
         generate without the exact Hessian (Gauss-Newton), or integrate with `rk4(k)`"
    )]
    ExactHessianWithIrk,
    /// A feature of the model the generator does not handle.
    #[error("not supported by the code generator: {0}")]
    Unsupported(String),
    /// An invalid option.
    #[error("invalid option: {0}")]
    Option(String),
    /// An error of the symbolic layer.
    #[error(transparent)]
    Dsl(#[from] DslError),
    /// The emitted Rust does not parse (a bug of the generator: please report it).
    #[error("internal error: the generated Rust for `{what}` does not parse: {message}")]
    Emit {
        /// Which file.
        what: String,
        /// The parser's message.
        message: String,
    },
    /// Rendering the C header failed (a bug of the generator: please report it).
    #[error("internal error: rendering the C header failed: {0}")]
    Template(String),
    /// Reading the model or writing the output failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The `.mpc` file has errors (rendered with file, line, column and caret).
    #[error("{0}")]
    Parse(String),
    /// The model would not compile or evaluate (clashing names, functions not finite at the
    /// guess): see [`checks`](crate::checks).
    #[error(transparent)]
    Check(#[from] crate::checks::CheckErrors),
}
