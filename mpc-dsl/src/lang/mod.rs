//! The `.mpc` text front end: lexer ([`logos`]), hand-written recursive-descent parser that
//! elaborates straight into an [`Ocp`] through the [`OcpBuilder`](crate::ocp::OcpBuilder),
//! and diagnostics with file, line, column and a caret ([`ariadne`]).
//!
//! The grammar is in `docs/mpc-language.md`.
//!
//! ```
//! use mpc_dsl::Graph;
//! use mpc_dsl::lang::{parse, ParseOptions};
//!
//! let src = "model tiny;
//!            state x; control u;
//!            dynamics ode rk4 { der(x) = -x + u; }
//!            horizon N = 10, dt = 0.1;
//!            cost { Q = diag(1); R = diag(0.1); }";
//! let g = Graph::new();
//! let parsed = parse(&g, src, &ParseOptions::default()).unwrap();
//! assert_eq!(parsed.ocp.nx(), 1);
//!
//! let bad = "model tiny; state x; dynamics ode rk4 { der(x) = y; }";
//! let errors = parse(&g, bad, &ParseOptions::default()).unwrap_err();
//! let text = errors.render("tiny.mpc", bad);
//! assert!(text.contains("unknown name `y`"));
//! assert!(text.contains("tiny.mpc:1:50"));
//! ```

mod lexer;
mod parser;
mod value;

use core::fmt;

use ariadne::{CharSet, Config, IndexType, Label, Report, ReportKind, Source};
use thiserror::Error;

use crate::graph::Graph;
use crate::ocp::{Ocp, OcpError, OcpWarning};

pub use lexer::Span;

/// What kind of problem a [`Diagnostic`] reports.
#[derive(Clone, Debug, PartialEq)]
pub enum DiagnosticKind {
    /// The text does not follow the grammar (or cannot be tokenized).
    Syntax,
    /// A name is unknown, declared twice, or used where it does not fit.
    Name,
    /// Shapes or values do not fit (e.g. a vector where a scalar is needed).
    Semantic,
    /// The problem built from the text failed validation.
    Validation(OcpError),
    /// A warning from validation.
    Warning(OcpWarning),
}

/// One message about a place in the source.
#[derive(Clone, Debug, PartialEq, Error)]
#[error("{message}")]
pub struct Diagnostic {
    /// What kind of problem.
    pub kind: DiagnosticKind,
    /// Byte range in the source.
    pub span: Span,
    /// The message.
    pub message: String,
    /// A short label at the caret.
    pub label: String,
}

impl Diagnostic {
    /// A diagnostic of `kind` at `span` (an empty label: the caret says "here").
    pub fn new(kind: DiagnosticKind, span: Span, message: impl Into<String>) -> Self {
        Diagnostic {
            kind,
            span,
            message: message.into(),
            label: String::new(),
        }
    }

    /// Whether this is a warning.
    pub fn is_warning(&self) -> bool {
        matches!(self.kind, DiagnosticKind::Warning(_))
    }

    /// 1-based line and column (in characters) of the start of the span.
    pub fn line_col(&self, src: &str) -> (usize, usize) {
        line_col(src, self.span.start)
    }

    /// Renders with file name, line, column, the source line and a caret (no colours).
    pub fn render(&self, file: &str, src: &str) -> String {
        let span = clamp(src, &self.span);
        let kind = if self.is_warning() {
            ReportKind::Warning
        } else {
            ReportKind::Error
        };
        let label = if self.label.is_empty() {
            "here"
        } else {
            &self.label
        };
        let report = Report::build(kind, (file, span.clone()))
            .with_config(
                Config::default()
                    .with_color(false)
                    .with_char_set(CharSet::Ascii)
                    .with_index_type(IndexType::Byte),
            )
            .with_message(&self.message)
            .with_label(Label::new((file, span)).with_message(label))
            .finish();
        let mut out = Vec::new();
        let (line, col) = self.line_col(src);
        if report.write((file, Source::from(src)), &mut out).is_err() {
            return format!("{file}:{line}:{col}: {}", self.message);
        }
        String::from_utf8_lossy(&out).into_owned()
    }
}

fn clamp(src: &str, span: &Span) -> Span {
    let mut start = span.start.min(src.len());
    while !src.is_char_boundary(start) {
        start -= 1;
    }
    let mut end = span.end.clamp(start, src.len());
    while !src.is_char_boundary(end) {
        end += 1;
    }
    start..end
}

/// 1-based line and column (in characters) of byte offset `at`.
pub fn line_col(src: &str, at: usize) -> (usize, usize) {
    let at = clamp(src, &(at..at)).start;
    let before = &src[..at];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Every error found in a source (and the warnings), in source order.
#[derive(Clone, Debug, PartialEq, Error)]
pub struct Diagnostics {
    /// Errors and warnings.
    pub items: Vec<Diagnostic>,
}

impl Diagnostics {
    /// The errors only.
    pub fn errors(&self) -> impl Iterator<Item = &Diagnostic> {
        self.items.iter().filter(|d| !d.is_warning())
    }

    /// Renders every diagnostic (see [`Diagnostic::render`]).
    pub fn render(&self, file: &str, src: &str) -> String {
        self.items
            .iter()
            .map(|d| d.render(file, src))
            .collect::<Vec<_>>()
            .join("")
    }
}

impl fmt::Display for Diagnostics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.errors().count();
        write!(f, "{n} error(s)")?;
        for d in self.errors() {
            write!(f, "\n  - {}", d.message)?;
        }
        Ok(())
    }
}

/// Options of [`parse`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ParseOptions {
    /// Apply the `variant NAME { ... }` block of this name (its horizon replaces the
    /// default one, and the problem is named `model_NAME`).
    pub variant: Option<String>,
}

/// An item of the source that later checks (code generation, evaluation at the guess)
/// point at: see [`SourceMap`].
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Place {
    /// The name in `model NAME;`.
    Model,
    /// The name in the declaration of a state, control or parameter.
    Declaration(String),
    /// The right-hand side of `der(NAME) = ...` or `next(NAME) = ...`, by state name.
    Equation(String),
    /// The expression of a (terminal) residual, by name.
    Residual(String),
    /// The weight of a residual, by the residual's name.
    ResidualWeight(String),
    /// The expression of a general cost term (`stage NAME = ...;`, `terminal NAME = ...;`),
    /// by name.
    GeneralCost(String),
    /// The expression of a general constraint, by name.
    Constraint(String),
    /// The weight `Q`, `R`, `P` or, for the input-rate term, `rate`.
    Weight(String),
    /// The reference (`ref`) of `Q`, `R`, `P`, or the `prev` of `rate`.
    Reference(String),
}

/// Where the items of a parsed problem are written: a [`Place`] to its byte span.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SourceMap {
    places: std::collections::HashMap<Place, Span>,
}

impl SourceMap {
    /// The span of `place`, if the source has it.
    pub fn span(&self, place: &Place) -> Option<Span> {
        self.places.get(place).cloned()
    }

    pub(crate) fn insert(&mut self, place: Place, span: Span) {
        self.places.insert(place, span);
    }
}

/// A parsed and validated problem with its warnings.
#[derive(Debug)]
pub struct Parsed<'g> {
    /// The problem.
    pub ocp: Ocp<'g>,
    /// Warnings (validation warnings, with the place they refer to).
    pub warnings: Vec<Diagnostic>,
    /// Where its items are written, for later checks' diagnostics.
    pub source: SourceMap,
}

/// Parses `.mpc` source into an [`Ocp`] built in `graph`, and validates it.
///
/// # Errors
/// [`Diagnostics`] with every syntax, name, shape and validation error found.
pub fn parse<'g>(
    graph: &'g Graph,
    src: &str,
    options: &ParseOptions,
) -> Result<Parsed<'g>, Diagnostics> {
    parser::parse(graph, src, options)
}

/// Checks only that `src` parses and elaborates, in a throw-away graph; never panics. This
/// is what the fuzz target and the property tests call.
pub fn check_source(src: &str) -> Result<(), Diagnostics> {
    let g = Graph::new();
    parse(&g, src, &ParseOptions::default()).map(|_| ())
}
