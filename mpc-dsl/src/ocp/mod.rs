//! The optimal control problem description ([`Ocp`]) and its Rust builder ([`OcpBuilder`]).
//!
//! Everything downstream (code generation, host-side tools) reads an [`Ocp`]. It holds
//! expressions of one [`Graph`]: states, controls and runtime parameters are symbols of that
//! graph, and dynamics, residuals, constraints and weights are expressions over them.
//!
//! # Conventions (what code generators must implement)
//!
//! - Stages `k = 0..N-1` carry `(x_k, u_k)`, the terminal stage `N` carries `x_N` only.
//!   `x_0` is fixed to the measured state at run time.
//! - Dynamics: [`Dynamics::Continuous`] `xdot = f(x, u, p)` discretized with the
//!   [`Integrator`] over `dt`, or [`Dynamics::Discrete`] `x_{k+1} = F(x_k, u_k, p)`.
//! - Objective: `sum_k 1/2 |r_k|^2_W` over every least-squares term (the factor 1/2 as in
//!   acados and QR-bench; it scales the whole objective and does not move the minimizer):
//!   state tracking `x_k - xref_k` with `Q` on `k < N`, control tracking `u_k - uref_k` with
//!   `R` on `k < N`, terminal tracking `x_N - xref_N` with `P`, nonlinear residuals
//!   `r(x, u, p)` with `W` on `k < N` or `r(x, p)` at `N`, and the input-rate term
//!   `u_k - u_{k-1}` with its weight on `k < N`, where `u_{-1}` is a runtime parameter (the
//!   control applied last). General terms ([`GeneralCost`]) add `l(x_k, u_k, p)` on `k < N`
//!   and `l_N(x_N, p)` at `N` to that, as they are.
//! - Parameters are [`ParamKind::Stage`] (one value per stage `0..=N`: references) or
//!   [`ParamKind::Global`] (one value for the whole horizon: masses, weights).
//! - Box bounds on controls hold on `k < N`; box bounds on states on `1 <= k <= N`.
//!   Infinite bounds mean "no bound". A bound may be soft ([`Bounds::soft`]): its violation
//!   is penalized like a soft general constraint's. General constraints `lh <= h(x, u, p) <= uh` hold on
//!   `k < N` ([`Stage::Path`]) or at `N` ([`Stage::Terminal`]); a soft one gets slacks with
//!   the given L1 and L2 penalties.

mod builder;
mod validate;

use crate::graph::{Expr, ExprKind, Graph};
use crate::linalg::{Matrix, Vector};

pub use builder::{Decl, OcpBuilder};
pub use validate::{OcpError, OcpWarning, ValidationErrors, symmetric_eigenvalues};

/// A named state, control or parameter: a scalar or a vector of symbols.
#[derive(Clone, Debug, PartialEq)]
pub struct Variable<'g> {
    /// Name as written by the author (`p`, `c`, `xref`).
    pub name: String,
    /// The symbols: one for a scalar (named `name`), `n` for a vector (named `name[i]`).
    pub symbols: Vector<'g>,
    /// Whether it was declared as a scalar.
    pub scalar: bool,
    /// Physical unit, free text (metadata).
    pub unit: Option<String>,
    /// Description (metadata).
    pub description: Option<String>,
    /// Initial guess (states and controls) or default value (parameters), one per symbol.
    /// `None` means zeros.
    pub start: Option<Vec<f64>>,
}

impl Variable<'_> {
    /// Number of scalar entries.
    pub fn len(&self) -> usize {
        self.symbols.len()
    }

    /// Whether it has no entry (never true for a valid problem).
    pub fn is_empty(&self) -> bool {
        self.symbols.is_empty()
    }
}

/// How a runtime parameter varies along the horizon.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    /// One value per stage `0..=N` (references).
    Stage,
    /// One value for the whole horizon (masses, weights).
    Global,
}

/// A runtime parameter: a [`Variable`] with its [`ParamKind`].
#[derive(Clone, Debug, PartialEq)]
pub struct Parameter<'g> {
    /// The symbols and metadata; `start` is the default value.
    pub var: Variable<'g>,
    /// Per stage or global.
    pub kind: ParamKind,
}

/// The discretization of continuous dynamics over one shooting interval.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Integrator {
    /// Classical Runge-Kutta 4 with this many equal substeps (at least 1).
    Rk4 {
        /// Number of substeps per interval.
        steps: usize,
    },
    /// Explicit Euler, one step (for tests).
    Euler,
    /// Implicit Runge-Kutta: collocation with `stages` stages ([`Collocation`]), `steps`
    /// equal substeps per interval, and a fixed number of `newton` iterations per substep (as
    /// acados' IRK: `sim_method_num_stages`, `sim_method_num_steps`,
    /// `sim_method_newton_iter`, `collocation_type`). The step has no closed-form expression:
    /// code generators emit a Newton solve ([`Ocp::discrete_map`] refuses it).
    Irk {
        /// Collocation stages, [`Integrator::IRK_MAX_STAGES`] at most.
        stages: usize,
        /// Substeps per interval (at least 1).
        steps: usize,
        /// Newton iterations per substep (at least 1).
        newton: usize,
        /// The collocation points.
        collocation: Collocation,
    },
}

/// The collocation points of an [`Integrator::Irk`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Collocation {
    /// Gauss-Legendre: order `2 s`, A-stable (acados' default).
    #[default]
    GaussLegendre,
    /// Radau IIA: order `2 s - 1`, L-stable (transients much faster than a step are damped
    /// out, not only kept bounded).
    RadauIia,
}

impl Integrator {
    /// The most collocation stages an [`Integrator::Irk`] may have.
    pub const IRK_MAX_STAGES: usize = 3;

    /// Gauss-Legendre collocation with `stages` stages, one substep and three Newton
    /// iterations (acados' defaults for `sim_method_num_steps` and `sim_method_newton_iter`).
    pub fn gauss_legendre(stages: usize) -> Integrator {
        Integrator::Irk {
            stages,
            steps: 1,
            newton: 3,
            collocation: Collocation::GaussLegendre,
        }
    }
}

/// The dynamics.
#[derive(Clone, Debug, PartialEq)]
pub enum Dynamics<'g> {
    /// `xdot = f(x, u, p)`, one expression per state entry (in state order).
    Continuous {
        /// Right-hand side.
        xdot: Vector<'g>,
        /// Discretization.
        integrator: Integrator,
    },
    /// `x_{k+1} = F(x_k, u_k, p)`, one expression per state entry.
    Discrete {
        /// The map.
        x_next: Vector<'g>,
    },
}

impl<'g> Dynamics<'g> {
    /// The expressions (`xdot` or `x_next`).
    pub fn exprs(&self) -> &Vector<'g> {
        match self {
            Dynamics::Continuous { xdot, .. } => xdot,
            Dynamics::Discrete { x_next } => x_next,
        }
    }
}

/// Horizon length and step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Horizon {
    /// Number of shooting intervals `N`.
    pub n: usize,
    /// Length of one interval in seconds.
    pub dt: f64,
}

/// Where a cost term or constraint applies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Stages `0..N-1` (functions of `x`, `u`, `p`).
    Path,
    /// Stage `N` (functions of `x`, `p` only).
    Terminal,
}

/// A weighted tracking term `1/2 |y - reference|^2_weight` where `y` is the state or the
/// control. The weight is a square matrix of expressions: constants when fixed at generation
/// time, or expressions of global parameters when set at run time.
#[derive(Clone, Debug, PartialEq)]
pub struct Tracking<'g> {
    /// Weight (`Q`, `R` or `P`).
    pub weight: Matrix<'g>,
    /// Reference: expressions of parameters and constants, one per entry of `y`.
    pub reference: Vector<'g>,
}

/// A nonlinear least-squares term `1/2 |r(x, u, p)|^2_W`.
#[derive(Clone, Debug, PartialEq)]
pub struct Residual<'g> {
    /// Name, used in messages and generated code.
    pub name: String,
    /// Path or terminal.
    pub stage: Stage,
    /// The residual `r`.
    pub residual: Vector<'g>,
    /// Weight `W` (square, size of `r`).
    pub weight: Matrix<'g>,
}

/// The input-rate term `1/2 |u_k - u_{k-1}|^2_W`, with `u_{-1} = prev`.
#[derive(Clone, Debug, PartialEq)]
pub struct InputRate<'g> {
    /// Weight (square, size of `u`).
    pub weight: Matrix<'g>,
    /// The control applied last: symbols of a parameter (usually global), one per control.
    pub prev: Vector<'g>,
}

/// A general cost term: a scalar expression added to the objective as it is (no factor 1/2,
/// no weight), `l(x_k, u_k, p)` on every stage `k < N` ([`Stage::Path`]) or `l_N(x_N, p)` at
/// `N` ([`Stage::Terminal`]). A barrier, an energy or time term, a cost on a nonlinear output.
#[derive(Clone, Debug, PartialEq)]
pub struct GeneralCost<'g> {
    /// Name, used in messages and generated code.
    pub name: String,
    /// Path or terminal.
    pub stage: Stage,
    /// The term's value.
    pub expr: Expr<'g>,
}

/// Every cost term.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Cost<'g> {
    /// `Q`, `xref` on `k < N`.
    pub state: Option<Tracking<'g>>,
    /// `R`, `uref` on `k < N`.
    pub control: Option<Tracking<'g>>,
    /// `P`, `xref` at `N`.
    pub terminal: Option<Tracking<'g>>,
    /// Nonlinear least-squares terms.
    pub residuals: Vec<Residual<'g>>,
    /// Input-rate term.
    pub input_rate: Option<InputRate<'g>>,
    /// General (not least-squares) terms, summed with the least squares.
    pub general: Vec<GeneralCost<'g>>,
}

impl<'g> Cost<'g> {
    /// The sum of the general terms at `stage` (`None` without any).
    pub fn general_sum(&self, stage: Stage) -> Option<Expr<'g>> {
        self.general
            .iter()
            .filter(|t| t.stage == stage)
            .map(|t| t.expr)
            .reduce(|a, b| a + b)
    }
}

/// Slack penalties of a soft constraint: `l1 * s + 1/2 l2 * s^2` per violated side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slack {
    /// Linear (exact-penalty) weight, `>= 0`.
    pub l1: f64,
    /// Quadratic weight, `>= 0`.
    pub l2: f64,
}

/// A general constraint `lower <= h(x, u, p) <= upper`.
#[derive(Clone, Debug, PartialEq)]
pub struct Constraint<'g> {
    /// Name, used in messages and generated code.
    pub name: String,
    /// Path or terminal.
    pub stage: Stage,
    /// The constraint function `h`.
    pub expr: Vector<'g>,
    /// Lower bounds (may be `-inf`), one per entry of `h`.
    pub lower: Vec<f64>,
    /// Upper bounds (may be `+inf`), one per entry of `h`.
    pub upper: Vec<f64>,
    /// `None` for a hard constraint.
    pub soft: Option<Slack>,
}

/// Component-wise box bounds, each hard or soft.
#[derive(Clone, Debug, PartialEq)]
pub struct Bounds {
    /// Lower bounds, `-inf` where unbounded.
    pub lower: Vec<f64>,
    /// Upper bounds, `+inf` where unbounded.
    pub upper: Vec<f64>,
    /// Per entry, `Some` for a soft bound with its slack penalties (`l1 s + 1/2 l2 s^2` on
    /// the violation `s` of either side), `None` for a hard one.
    pub soft: Vec<Option<Slack>>,
}

impl Bounds {
    /// `n` unbounded entries.
    pub fn unbounded(n: usize) -> Bounds {
        Bounds {
            lower: vec![f64::NEG_INFINITY; n],
            upper: vec![f64::INFINITY; n],
            soft: vec![None; n],
        }
    }

    /// The entries whose bound is soft, in order (acados' `idxsbx`/`idxsbu`).
    pub fn soft_entries(&self) -> Vec<usize> {
        (self.soft.iter().enumerate())
            .filter_map(|(i, s)| s.map(|_| i))
            .collect()
    }

    /// Indices with at least one finite side: the bounds a solver must enforce.
    pub fn active(&self) -> Vec<usize> {
        (0..self.lower.len())
            .filter(|&i| self.lower[i].is_finite() || self.upper[i].is_finite())
            .collect()
    }
}

/// A complete optimal control problem.
///
/// Equality compares expressions by node identity: two problems are equal when they were
/// built in the same [`Graph`] from the same operations (this is how the test of the two
/// front ends compares a parsed model with the builder's).
#[derive(Clone, Debug, PartialEq)]
pub struct Ocp<'g> {
    /// Name (used for generated crate and symbol names).
    pub name: String,
    /// States, in order; `x` is their concatenation.
    pub states: Vec<Variable<'g>>,
    /// Controls, in order; `u` is their concatenation.
    pub controls: Vec<Variable<'g>>,
    /// Runtime parameters, in order; `p` is their concatenation.
    pub parameters: Vec<Parameter<'g>>,
    /// Dynamics.
    pub dynamics: Dynamics<'g>,
    /// Horizon.
    pub horizon: Horizon,
    /// Objective.
    pub cost: Cost<'g>,
    /// Box bounds on `x` (stages `1..=N`), one entry per state entry.
    pub state_bounds: Bounds,
    /// Box bounds on `u` (stages `0..N`), one entry per control entry.
    pub control_bounds: Bounds,
    /// General constraints.
    pub constraints: Vec<Constraint<'g>>,
    /// Solver settings the model chooses (`solver { ... }` in a `.mpc` file).
    pub solver: SolverChoices,
}

/// Solver settings a model chooses for its generated solver (`solver { shift = off; }`);
/// `None` leaves the runtime's default. A generator's own option (`mpcc build --shift`)
/// wins over the model's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SolverChoices {
    /// The real-time iteration's shift of the trajectory (`RtiSettings::shift`).
    pub shift: Option<bool>,
}

fn concat<'g, 'a>(vars: impl Iterator<Item = &'a Variable<'g>>) -> Vector<'g>
where
    'g: 'a,
{
    vars.flat_map(|v| v.symbols.iter().copied()).collect()
}

impl<'g> Ocp<'g> {
    /// Starts a builder.
    pub fn builder(graph: &'g Graph, name: &str) -> OcpBuilder<'g> {
        OcpBuilder::new(graph, name)
    }

    /// The state vector `x` (all state symbols, in order).
    pub fn x(&self) -> Vector<'g> {
        concat(self.states.iter())
    }

    /// The control vector `u`.
    pub fn u(&self) -> Vector<'g> {
        concat(self.controls.iter())
    }

    /// The parameter vector `p`.
    pub fn p(&self) -> Vector<'g> {
        concat(self.parameters.iter().map(|p| &p.var))
    }

    /// Number of state entries.
    pub fn nx(&self) -> usize {
        self.states.iter().map(Variable::len).sum()
    }

    /// Number of control entries.
    pub fn nu(&self) -> usize {
        self.controls.iter().map(Variable::len).sum()
    }

    /// Number of parameter entries.
    pub fn np(&self) -> usize {
        self.parameters.iter().map(|p| p.var.len()).sum()
    }

    /// The right-hand side `f(x, u, p)` or the map `F(x, u, p)`.
    pub fn dynamics_exprs(&self) -> &Vector<'g> {
        self.dynamics.exprs()
    }

    /// Initial guess of `x` (zeros where none was given).
    pub fn x_guess(&self) -> Vec<f64> {
        starts(self.states.iter())
    }

    /// Initial guess of `u` (zeros where none was given).
    pub fn u_guess(&self) -> Vec<f64> {
        starts(self.controls.iter())
    }

    /// Default value of `p` (zeros where none was given).
    pub fn p_default(&self) -> Vec<f64> {
        starts(self.parameters.iter().map(|p| &p.var))
    }

    /// The state, control or parameter called `name`.
    pub fn variable(&self, name: &str) -> Option<&Variable<'g>> {
        self.states
            .iter()
            .chain(&self.controls)
            .chain(self.parameters.iter().map(|p| &p.var))
            .find(|v| v.name == name)
    }

    /// Checks the problem. `Ok` carries the warnings; `Err` carries every error found (and
    /// the warnings).
    ///
    /// # Errors
    /// [`ValidationErrors`] listing each [`OcpError`].
    pub fn validate(&self) -> Result<Vec<OcpWarning>, ValidationErrors> {
        validate::validate(self)
    }
}

fn starts<'a, 'g: 'a>(vars: impl Iterator<Item = &'a Variable<'g>>) -> Vec<f64> {
    vars.flat_map(|v| v.start.clone().unwrap_or_else(|| vec![0.0; v.len()]))
        .collect()
}

/// Calls `f` once for every distinct node reachable from `roots` (each node once, however
/// much the DAG shares). Used to collect symbols and constants.
pub(crate) fn visit<'g>(roots: &[Expr<'g>], mut f: impl FnMut(Expr<'g>, &ExprKind<'g>)) {
    let mut seen = std::collections::HashSet::new();
    let mut stack: Vec<Expr<'g>> = roots.to_vec();
    while let Some(e) = stack.pop() {
        if !seen.insert(e.index()) {
            continue;
        }
        let kind = e.kind();
        match &kind {
            ExprKind::Constant(_) | ExprKind::Symbol(_) => {}
            ExprKind::Unary(_, a) | ExprKind::PowI(a, _) => stack.push(*a),
            ExprKind::Binary(_, a, b) => {
                stack.push(*a);
                stack.push(*b);
            }
        }
        f(e, &kind);
    }
}

/// The symbols an expression list depends on, in first-seen order (deduplicated).
pub fn symbols_of<'g>(roots: &[Expr<'g>]) -> Vec<Expr<'g>> {
    let mut out = Vec::new();
    visit(roots, |e, k| {
        if matches!(k, ExprKind::Symbol(_)) {
            out.push(e);
        }
    });
    out.sort();
    out
}

/// Rebuilds `exprs` with every symbol in `from` replaced by the matching expression of `to`
/// (hash-consing and the construction-time rules apply to the rebuilt nodes).
///
/// # Errors
/// [`DslError::LengthMismatch`](crate::DslError::LengthMismatch) if `from` and `to` differ
/// in length.
pub fn substitute<'g>(
    exprs: &[Expr<'g>],
    from: &[Expr<'g>],
    to: &[Expr<'g>],
) -> crate::Result<Vector<'g>> {
    if from.len() != to.len() {
        return Err(crate::DslError::LengthMismatch {
            what: "substitute: replacements",
            expected: from.len(),
            found: to.len(),
        });
    }
    let mut memo: std::collections::HashMap<usize, Expr<'g>> =
        from.iter().zip(to).map(|(f, t)| (f.index(), *t)).collect();
    // Post-order over the DAG without recursion.
    let mut out = Vec::with_capacity(exprs.len());
    for &root in exprs {
        let mut stack = vec![(root, false)];
        while let Some((e, expanded)) = stack.pop() {
            if memo.contains_key(&e.index()) {
                continue;
            }
            let kind = e.kind();
            let children: Vec<Expr<'g>> = match &kind {
                ExprKind::Constant(_) | ExprKind::Symbol(_) => Vec::new(),
                ExprKind::Unary(_, a) | ExprKind::PowI(a, _) => vec![*a],
                ExprKind::Binary(_, a, b) => vec![*a, *b],
            };
            if !expanded && !children.is_empty() {
                stack.push((e, true));
                stack.extend(children.iter().rev().map(|&c| (c, false)));
                continue;
            }
            let m = |c: &Expr<'g>| memo.get(&c.index()).copied().unwrap_or(*c);
            let g = e.graph();
            let new = match &kind {
                ExprKind::Constant(_) | ExprKind::Symbol(_) => e,
                ExprKind::Unary(op, a) => g.unary(*op, m(a)),
                ExprKind::PowI(a, n) => g.powi(m(a), *n),
                ExprKind::Binary(op, a, b) => g.binary(*op, m(a), m(b)),
            };
            memo.insert(e.index(), new);
        }
        out.push(memo.get(&root.index()).copied().unwrap_or(root));
    }
    Ok(Vector::new(out))
}

impl<'g> Ocp<'g> {
    /// The discrete map `x_{k+1} = F(x_k, u_k, p)` over one interval `dt`: the integrator
    /// applied to continuous dynamics (fully expanded; hash-consing shares the stages), or
    /// the discrete map itself. Code generators that propagate sensitivities stage by stage
    /// use [`dynamics_exprs`](Self::dynamics_exprs) instead; this is the reference.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`](crate::DslError::DimensionMismatch) if the dynamics
    /// do not have one entry per state (validation reports that first);
    /// [`DslError::NoClosedForm`](crate::DslError::NoClosedForm) for [`Integrator::Irk`].
    pub fn discrete_map(&self) -> crate::Result<Vector<'g>> {
        let x = self.x();
        let f = self.dynamics.exprs();
        if f.len() != x.len() {
            return Err(crate::DslError::DimensionMismatch {
                op: "discrete_map",
                expected: format!("{} dynamics entries", x.len()),
                found: format!("{}", f.len()),
            });
        }
        let rhs = |at: &[Expr<'g>]| substitute(f, &x, at);
        match self.dynamics {
            Dynamics::Discrete { ref x_next } => Ok(x_next.clone()),
            Dynamics::Continuous {
                integrator: Integrator::Euler,
                ..
            } => x.add(&f.scale(self.horizon.dt)),
            Dynamics::Continuous {
                integrator: Integrator::Rk4 { steps },
                ..
            } => crate::models::rk4(&x, self.horizon.dt, steps, rhs),
            Dynamics::Continuous {
                integrator: Integrator::Irk { .. },
                ..
            } => Err(crate::DslError::NoClosedForm {
                what: "the discrete map of an irk (implicit) integrator",
            }),
        }
    }
}
