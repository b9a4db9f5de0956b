//! Checks that refuse, before any code is emitted, a model whose generated crate would not
//! compile or whose functions would not evaluate:
//!
//! - [`names`]: identifiers the generated crate and C header derive from the model's names
//!   (`set_<param>`, `u0_<control>`, `STATE_<NAME>`, `<model>_set_<param>`, the crate name)
//!   that clash with the generated API's own names or with each other, and Rust keywords;
//! - [`guess`]: every function the solver calls (the model's expressions, then the lowered
//!   integrator step, residuals, constraints, weights and their derivatives), evaluated at
//!   the initial guess and the parameter defaults, must be finite.
//!
//! Each [`Problem`] names a [`Place`] of the `.mpc` source, so `mpcc check` and `mpcc build`
//! report it with file, line and column ([`CheckErrors::diagnostics`]).

pub mod guess;
pub mod names;

use core::fmt;

use mpc_dsl::Ocp;
use mpc_dsl::lang::{Diagnostic, DiagnosticKind, Diagnostics, Place, SourceMap};

use crate::error::CodegenError;
use crate::lower::{Lowered, lower_with};
use crate::options::Options;

/// One problem found by the checks: where in the model, and what to change.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// The item of the source it is about (`None`: not in the source, e.g. `--name`).
    pub place: Option<Place>,
    /// [`DiagnosticKind::Name`] for names, [`DiagnosticKind::Semantic`] for values.
    pub kind: DiagnosticKind,
    /// What is wrong and what to change.
    pub message: String,
    /// A short label at the caret.
    pub label: String,
}

/// Every problem found by [`check`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub struct CheckErrors {
    /// The problems, names first.
    pub problems: Vec<Problem>,
}

impl fmt::Display for CheckErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} error(s) in the model:", self.problems.len())?;
        for p in &self.problems {
            write!(f, "\n  - {}", p.message)?;
        }
        Ok(())
    }
}

impl CheckErrors {
    /// The problems as diagnostics located with `source` (at the start of the file when
    /// their place is not in it).
    pub fn diagnostics(&self, source: &SourceMap) -> Diagnostics {
        let items = self
            .problems
            .iter()
            .map(|p| {
                let span = p.place.as_ref().and_then(|pl| source.span(pl));
                let mut d = Diagnostic::new(p.kind.clone(), span.unwrap_or(0..0), &p.message);
                d.label.clone_from(&p.label);
                d
            })
            .collect();
        Diagnostics { items }
    }
}

/// Lowers `ocp` as [`generate`](crate::generate) does (with `opts.exact_hessian`) and runs
/// every check; the lowered problem when all pass.
///
/// # Errors
/// [`CodegenError::Check`] with every problem found, or the errors of
/// [`lower_with`].
pub fn check(ocp: &Ocp<'_>, opts: &Options) -> Result<Lowered, CodegenError> {
    let mut problems = names::check(ocp, opts);
    let l = lower_with(ocp, opts.exact_hessian)?;
    problems.extend(guess::check(ocp, &l));
    if problems.is_empty() {
        Ok(l)
    } else {
        Err(CodegenError::Check(CheckErrors { problems }))
    }
}

#[cfg(test)]
mod tests {
    use mpc_dsl::Graph;
    use mpc_dsl::lang::{ParseOptions, parse};

    use super::*;

    /// The rendered problems of `src` (empty if it passes), and their line:column.
    fn problems(src: &str, opts: &Options) -> (String, Vec<(usize, usize)>) {
        let g = Graph::new();
        let parsed = parse(&g, src, &ParseOptions::default()).expect("parses");
        match check(&parsed.ocp, opts) {
            Ok(_) => (String::new(), Vec::new()),
            Err(CodegenError::Check(c)) => {
                let d = c.diagnostics(&parsed.source);
                let at = d.items.iter().map(|i| i.line_col(src)).collect();
                (d.render("m.mpc", src), at)
            }
            Err(e) => panic!("{e}"),
        }
    }

    /// A model with extra declarations `decls` (line 2) and dynamics `rhs` for `der(x)`.
    fn model(decls: &str, rhs: &str, extra: &str) -> String {
        format!(
            "model m;\n{decls}\nstate x; control u;\n\
             dynamics ode rk4 {{ der(x) = {rhs}; }}\nhorizon N = 5, dt = 0.1;\n\
             cost {{ Q = diag(1); R = diag(1); }}\n{extra}"
        )
    }

    #[test]
    fn names_that_clash_with_the_generated_api_are_located_errors() {
        let opts = Options::new();
        for (decl, ident) in [
            ("param x0 global;", "set_x0"),
            ("param guess global;", "set_guess"),
            ("param param_all global;", "set_param_all"),
            ("param param stage;", "set_param"),
            ("param control_bounds global;", "set_control_bounds"),
            ("param qp_max_iter global;", "set_qp_max_iter"),
        ] {
            let (text, at) = problems(&model(decl, "u", ""), &opts);
            assert!(
                text.contains(&format!("would generate `{ident}`")),
                "{decl}: {text}"
            );
            assert!(text.contains("rename the"), "{text}");
            assert_eq!(at, vec![(2, decl.find(' ').unwrap() + 2)], "{decl}: {text}");
        }
    }

    #[test]
    fn names_that_clash_with_each_other_or_are_keywords_are_located_errors() {
        let opts = Options::new();
        let (text, at) = problems(&model("param a stage; param a_all global;", "u", ""), &opts);
        assert!(
            text.contains("`set_a_all`, as does stage parameter `a`"),
            "{text}"
        );
        assert_eq!(at, vec![(2, 22)]);
        let (text, at) = problems(&model("param a global; param A global;", "u", ""), &opts);
        assert!(text.contains("`PARAM_A`, as does parameter `a`"), "{text}");
        assert_eq!(at, vec![(2, 23)]);
        let (text, at) = problems(&model("param type global;", "u", ""), &opts);
        assert!(text.contains("`type` is a Rust keyword"), "{text}");
        assert_eq!(at, vec![(2, 7)]);
        let (text, at) = problems(
            &model("", "u", "").replace("model m;", "model core;"),
            &opts,
        );
        assert!(text.contains("crate name `core`"), "{text}");
        assert_eq!(at, vec![(1, 7)]);
        // With `--name`, the model's name is not at fault.
        let named = Options {
            crate_name: Some("libm".into()),
            ..Options::new()
        };
        let (text, _) = problems(&model("", "u", ""), &named);
        assert!(text.contains("pass another `--name`"), "{text}");
    }

    #[test]
    fn functions_not_finite_at_the_guess_are_located_errors() {
        let opts = Options::new();
        let (text, at) = problems(&model("param F global default 2;", "F/x + u", ""), &opts);
        assert!(
            text.contains("the dynamics (right-hand side) is not finite"),
            "{text}"
        );
        assert!(
            text.contains("der(x) = inf") && text.contains("x = 0") && text.contains("F = 2"),
            "{text}"
        );
        assert!(text.contains("stages 0..4"), "{text}");
        assert_eq!(at, vec![(4, 29)]);
        let (text, _) = problems(&model("", "sqrt(x - 1) + u", ""), &opts);
        assert!(text.contains("der(x) = NaN"), "{text}");
        let (text, at) = problems(
            &model("", "u", "constraints { pos: 0 <= log(x) <= 1; }\n"),
            &opts,
        );
        assert!(
            text.contains("constraint `pos` is not finite") && text.contains("row 0 = -inf"),
            "{text}"
        );
        assert_eq!(at, vec![(7, 25)]);
        let src = model(
            "",
            "u",
            "cost { terminal residual e = [1 / x] weight diag(1); }\n",
        );
        let (text, _) = problems(&src, &opts);
        assert!(
            text.contains("residual `e`") && text.contains("stage 5"),
            "{text}"
        );
    }

    #[test]
    fn a_jacobian_not_finite_at_the_guess_is_located_at_its_equation() {
        // sqrt(x) is 0 at x = 0, its derivative is not.
        let (text, at) = problems(&model("", "sqrt(x) + u", ""), &Options::new());
        assert!(
            text.contains("the dynamics step (integrator) is not finite"),
            "{text}"
        );
        assert!(
            text.contains("of its matrix `a`") && text.contains("= inf"),
            "{text}"
        );
        assert_eq!(at, vec![(4, 29)]);
        // A guess where it is defined passes.
        let src = model("", "sqrt(x) + u", "").replace("state x;", "state x guess 1;");
        assert_eq!(problems(&src, &Options::new()).0, "");
        // With the implicit integrator: the right-hand side's Jacobian `fx`.
        let src = model("", "sqrt(x) + u", "").replace("ode rk4", "ode irk(stages = 1)");
        let (text, at) = problems(&src, &Options::new());
        assert!(
            text.contains("right-hand side or its Jacobian (for the irk step) is not finite")
                && text.contains("of its matrix `fx`"),
            "{text}"
        );
        assert_eq!(at, vec![(4, 41)]);
    }
}
