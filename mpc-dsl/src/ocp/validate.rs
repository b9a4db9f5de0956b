//! Validation of an [`Ocp`]: every check runs and every failure is collected.

use std::collections::{HashMap, HashSet};
use std::fmt;

use thiserror::Error;

use crate::graph::{Expr, ExprKind};
use crate::linalg::Matrix;

use super::{Bounds, Dynamics, Integrator, Ocp, ParamKind, Stage, Tracking, visit};

/// One validation error. Each message names the offending item and says what to change.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum OcpError {
    /// An expression uses a symbol that is no declared state, control or parameter.
    #[error(
        "unknown symbol `{name}` in {item}: declare it as a state, control or parameter \
         (or fix the spelling)"
    )]
    UnknownSymbol {
        /// Where it was used.
        item: String,
        /// The symbol.
        name: String,
    },
    /// Two declarations (or a declaration and a named term) share a name.
    #[error("duplicate name `{name}`: it is declared more than once; rename one of them")]
    DuplicateName {
        /// The name.
        name: String,
    },
    /// Shapes do not fit.
    #[error("{item} is {found} but {expected}")]
    DimensionMismatch {
        /// The item, e.g. `Q`.
        item: String,
        /// What it is, e.g. `9x9`.
        found: String,
        /// What it must be, e.g. `the state has 10 entries`.
        expected: String,
    },
    /// A fixed weight is not symmetric.
    #[error(
        "weight {item} is not symmetric: entry ({i},{j}) = {a} but ({j},{i}) = {b}; \
         a least-squares weight must equal its transpose"
    )]
    NotSymmetric {
        /// The weight, e.g. `Q`.
        item: String,
        /// Row.
        i: usize,
        /// Column.
        j: usize,
        /// Entry `(i, j)`, printed.
        a: String,
        /// Entry `(j, i)`, printed.
        b: String,
    },
    /// A fixed weight has a negative eigenvalue.
    #[error(
        "weight {item} is not positive semidefinite: its smallest eigenvalue is {eigenvalue:e}; \
         use non-negative diagonal entries or a Gram matrix"
    )]
    NotPsd {
        /// The weight.
        item: String,
        /// The smallest eigenvalue.
        eigenvalue: f64,
    },
    /// A lower bound lies above its upper bound.
    #[error("{item}: lower bound {lower} is above upper bound {upper}")]
    BoundsCrossed {
        /// The bounded entry, e.g. `bound on c` or `constraint tilt[0]`.
        item: String,
        /// Lower bound.
        lower: f64,
        /// Upper bound.
        upper: f64,
    },
    /// A constant is NaN or infinite where a finite number is needed.
    #[error("{item}: constant {value} is not finite; replace it with a finite number")]
    NonFinite {
        /// Where.
        item: String,
        /// The value.
        value: f64,
    },
    /// `N = 0`.
    #[error("horizon N = 0: the horizon needs at least one interval")]
    ZeroHorizon,
    /// `dt <= 0` (or not finite).
    #[error("horizon dt = {dt}: the step must be a positive finite number of seconds")]
    NonPositiveDt {
        /// The step.
        dt: f64,
    },
    /// RK4 with zero substeps.
    #[error("integrator rk4 with 0 substeps: use at least 1")]
    ZeroSubsteps,
    /// An `irk` integrator with a number of stages it does not have a tableau for.
    #[error(
        "integrator irk with {stages} stages: collocation is available with 1, 2 or 3 stages \
         (Gauss-Legendre: order 2, 4, 6; Radau IIA: order 1, 3, 5)"
    )]
    IrkStages {
        /// The stages asked for.
        stages: usize,
    },
    /// An `irk` integrator with zero substeps or zero Newton iterations.
    #[error("integrator irk with 0 {what}: use at least 1")]
    IrkZero {
        /// `substeps` or `Newton iterations`.
        what: &'static str,
    },
    /// Something required is missing.
    #[error("no {what} given: the problem needs one")]
    Missing {
        /// What.
        what: String,
    },
    /// Something given twice that may be given once.
    #[error("{what} given twice: give it once")]
    Duplicate {
        /// What.
        what: String,
    },
    /// A box bound names something that is not a state or control entry.
    #[error("{item}: `{name}` is not a state or control entry; box bounds apply to those only")]
    NotAVariable {
        /// Where.
        item: String,
        /// What was given.
        name: String,
    },
    /// An expression depends on a symbol it may not depend on (a control in a terminal
    /// term, a state or control in a weight or reference).
    #[error("{item} depends on `{name}`, {reason}")]
    IllegalDependence {
        /// Where.
        item: String,
        /// The symbol.
        name: String,
        /// Why it is not allowed.
        reason: String,
    },
    /// A variable with zero entries.
    #[error("`{name}` has 0 entries: give it at least one")]
    EmptyVariable {
        /// The name.
        name: String,
    },
    /// A negative slack penalty.
    #[error("{item}: slack penalty {value} is negative; penalties must be >= 0")]
    NegativePenalty {
        /// Where.
        item: String,
        /// The value.
        value: f64,
    },
    /// A soft box bound whose penalties are both zero (it would be a hard bound).
    #[error(
        "{item}: soft with l1 = 0 and l2 = 0 penalizes nothing; give a positive penalty, \
         or drop `soft` for a hard bound"
    )]
    ZeroPenalties {
        /// The bounded entry, e.g. `soft state bound on `v``.
        item: String,
    },
    /// A soft box bound on an entry with no finite bound.
    #[error("{item}: soft on an entry without a finite bound; give a finite lower or upper bound")]
    SoftUnbounded {
        /// The bounded entry.
        item: String,
    },
}

impl OcpError {
    /// The declared name this error is about, when it is about one (used by the `.mpc` front
    /// end to point at the declaration).
    pub fn culprit(&self) -> Option<&str> {
        match self {
            OcpError::UnknownSymbol { name, .. }
            | OcpError::DuplicateName { name }
            | OcpError::EmptyVariable { name } => Some(name),
            OcpError::DimensionMismatch { item, .. }
            | OcpError::NotSymmetric { item, .. }
            | OcpError::NotPsd { item, .. }
            | OcpError::BoundsCrossed { item, .. }
            | OcpError::NonFinite { item, .. }
            | OcpError::IllegalDependence { item, .. }
            | OcpError::NegativePenalty { item, .. }
            | OcpError::ZeroPenalties { item }
            | OcpError::SoftUnbounded { item }
            | OcpError::NotAVariable { item, .. } => Some(item),
            _ => None,
        }
    }
}

/// A problem that does not stop code generation but is probably a mistake.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum OcpWarning {
    /// A control entry does not appear in the dynamics.
    #[error(
        "the dynamics do not depend on control `{name}`: it cannot influence the state \
         (remove it, or check the dynamics)"
    )]
    UnusedControl {
        /// The control entry's symbol name.
        name: String,
    },
}

/// Every error found by [`Ocp::validate`], with the warnings.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationErrors {
    /// The errors, in the order found.
    pub errors: Vec<OcpError>,
    /// The warnings.
    pub warnings: Vec<OcpWarning>,
}

impl fmt::Display for ValidationErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} error(s) in the problem:", self.errors.len())?;
        for e in &self.errors {
            write!(f, "\n  - {e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ValidationErrors {}

/// Symbol roles.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Role {
    State,
    Control,
    StageParam,
    GlobalParam,
}

struct Checker<'a, 'g> {
    roles: HashMap<usize, Role>,
    errors: Vec<OcpError>,
    ocp: &'a Ocp<'g>,
}

impl<'g> Checker<'_, 'g> {
    /// Checks symbols and constants of `exprs`; `allowed` says which roles may appear.
    fn exprs(&mut self, item: &str, exprs: &[Expr<'g>], allowed: &[Role], reason: &str) {
        let mut found = Vec::new();
        visit(exprs, |e, k| match k {
            ExprKind::Constant(v) if !v.is_finite() => {
                found.push(OcpError::NonFinite {
                    item: item.to_owned(),
                    value: *v,
                });
            }
            ExprKind::Unary(..) | ExprKind::PowI(..) | ExprKind::Binary(..)
                if e.is_non_finite_constant() =>
            {
                found.push(OcpError::NonFinite {
                    item: item.to_owned(),
                    value: e.constant_value().unwrap_or(f64::NAN),
                });
            }
            ExprKind::Symbol(name) => match self.roles.get(&e.index()) {
                None => found.push(OcpError::UnknownSymbol {
                    item: item.to_owned(),
                    name: name.to_string(),
                }),
                Some(r) if !allowed.contains(r) => found.push(OcpError::IllegalDependence {
                    item: item.to_owned(),
                    name: name.to_string(),
                    reason: reason.to_owned(),
                }),
                _ => {}
            },
            _ => {}
        });
        // Deterministic order: sort by message.
        found.sort_by_key(ToString::to_string);
        found.dedup();
        self.errors.extend(found);
    }

    fn len(&mut self, item: &str, found: usize, expected: usize, what: &str) -> bool {
        if found != expected {
            self.errors.push(OcpError::DimensionMismatch {
                item: item.to_owned(),
                found: format!("of length {found}"),
                expected: format!("{what} has {expected} entries"),
            });
            return false;
        }
        true
    }

    fn weight(&mut self, item: &str, w: &Matrix<'g>, n: usize, what: &str) {
        if w.nrows() != n || w.ncols() != n {
            self.errors.push(OcpError::DimensionMismatch {
                item: item.to_owned(),
                found: format!("{}x{}", w.nrows(), w.ncols()),
                expected: format!("{what} has {n} entries"),
            });
            return;
        }
        let n_before = self.errors.len();
        self.exprs(
            item,
            w.as_row_major(),
            &[Role::GlobalParam],
            "but a weight may depend on global parameters only",
        );
        if self.errors.len() != n_before {
            return;
        }
        // Structural symmetry for every weight; numeric PSD for fixed ones.
        let mut values = Vec::with_capacity(n * n);
        for i in 0..n {
            for j in 0..n {
                let (a, b) = (w[(i, j)], w[(j, i)]);
                if j > i && a != b {
                    self.errors.push(OcpError::NotSymmetric {
                        item: item.to_owned(),
                        i,
                        j,
                        a: a.to_string(),
                        b: b.to_string(),
                    });
                    return;
                }
                values.push(a.as_constant());
            }
        }
        if let Some(values) = values.into_iter().collect::<Option<Vec<f64>>>() {
            let eig = symmetric_eigenvalues(&values, n);
            let scale = eig.iter().fold(1.0f64, |m, e| m.max(e.abs()));
            if let Some(&min) = eig.iter().min_by(|a, b| a.total_cmp(b))
                && min < -1e-12 * scale
            {
                self.errors.push(OcpError::NotPsd {
                    item: item.to_owned(),
                    eigenvalue: min,
                });
            }
        }
    }

    fn bounds(&mut self, what: &str, b: &Bounds, names: &[String]) {
        for (i, (&l, &h)) in b.lower.iter().zip(&b.upper).enumerate() {
            let name = names
                .get(i)
                .cloned()
                .unwrap_or_else(|| format!("entry {i}"));
            self.bound_pair(&format!("{what} on `{name}`"), l, h);
        }
    }

    fn bound_pair(&mut self, item: &str, l: f64, h: f64) {
        if l.is_nan() || l == f64::INFINITY {
            self.errors.push(OcpError::NonFinite {
                item: format!("{item} (lower)"),
                value: l,
            });
        } else if h.is_nan() || h == f64::NEG_INFINITY {
            self.errors.push(OcpError::NonFinite {
                item: format!("{item} (upper)"),
                value: h,
            });
        } else if l > h {
            self.errors.push(OcpError::BoundsCrossed {
                item: item.to_owned(),
                lower: l,
                upper: h,
            });
        }
    }

    fn tracking(&mut self, item: &str, t: &Tracking<'g>, n: usize, what: &str, wname: &str) {
        self.weight(wname, &t.weight, n, what);
        let ref_item = format!("reference of {wname}");
        if self.len(&ref_item, t.reference.len(), n, what) {
            self.exprs(
                &ref_item,
                &t.reference,
                &[Role::StageParam, Role::GlobalParam],
                "but a reference may depend on parameters only",
            );
        }
        let _ = item;
    }
}

fn names(vars: &[super::Variable<'_>]) -> Vec<String> {
    vars.iter()
        .flat_map(|v| v.symbols.iter().map(|s| s.to_string()))
        .collect()
}

/// The roles a path term's expressions may depend on.
const PATH_ROLES: [Role; 4] = [
    Role::State,
    Role::Control,
    Role::StageParam,
    Role::GlobalParam,
];

/// The roles a terminal term's expressions may depend on, and why no other.
const TERMINAL_ROLES: [Role; 3] = [Role::State, Role::StageParam, Role::GlobalParam];
const TERMINAL_REASON: &str = "but a terminal term sees x_N and parameters only (there is no u_N)";

/// The roles a term at `stage` may depend on, and why no other.
fn stage_roles(stage: Stage) -> (&'static [Role], &'static str) {
    match stage {
        Stage::Path => (&PATH_ROLES, ""),
        Stage::Terminal => (&TERMINAL_ROLES, TERMINAL_REASON),
    }
}

pub(super) fn validate(ocp: &Ocp<'_>) -> Result<Vec<OcpWarning>, ValidationErrors> {
    let mut c = Checker {
        roles: HashMap::new(),
        errors: Vec::new(),
        ocp,
    };
    let declared = c.declarations();
    c.term_names(&declared);
    c.horizon_and_dynamics();
    c.costs();
    c.box_bounds();
    for k in &ocp.constraints {
        c.constraint(k);
    }
    let warnings = c.unused_controls();
    if c.errors.is_empty() {
        Ok(warnings)
    } else {
        Err(ValidationErrors {
            errors: c.errors,
            warnings,
        })
    }
}

impl<'g> Checker<'_, 'g> {
    /// Declarations: names, sizes, starting values; records each symbol's role. The names
    /// declared.
    fn declarations(&mut self) -> HashSet<String> {
        let ocp = self.ocp;
        let mut seen = HashSet::new();
        let params = ocp.parameters.iter().map(|p| {
            let role = match p.kind {
                ParamKind::Stage => Role::StageParam,
                ParamKind::Global => Role::GlobalParam,
            };
            (&p.var, role)
        });
        let all: Vec<_> = ocp
            .states
            .iter()
            .map(|v| (v, Role::State))
            .chain(ocp.controls.iter().map(|v| (v, Role::Control)))
            .chain(params)
            .collect();
        for &(v, role) in &all {
            if !seen.insert(v.name.clone()) {
                self.errors.push(OcpError::DuplicateName {
                    name: v.name.clone(),
                });
            }
            if v.is_empty() {
                self.errors.push(OcpError::EmptyVariable {
                    name: v.name.clone(),
                });
            }
            for s in &v.symbols {
                self.roles.insert(s.index(), role);
            }
            self.starting_value(v, role);
        }
        seen
    }

    /// A variable's initial guess (states, controls) or default value (parameters): its
    /// length and finiteness.
    fn starting_value(&mut self, v: &super::Variable<'g>, role: Role) {
        let Some(start) = &v.start else {
            return;
        };
        let what = if matches!(role, Role::State | Role::Control) {
            "initial guess of"
        } else {
            "default value of"
        };
        let item = format!("{what} `{}`", v.name);
        if start.len() != v.len() {
            self.errors.push(OcpError::DimensionMismatch {
                item,
                found: format!("of length {}", start.len()),
                expected: format!("`{}` has {} entries", v.name, v.len()),
            });
        } else if let Some(&bad) = start.iter().find(|s| !s.is_finite()) {
            self.errors.push(OcpError::NonFinite { item, value: bad });
        }
    }

    /// The names of residuals, general cost terms and constraints: unique, and none a
    /// declaration's.
    fn term_names(&mut self, declared: &HashSet<String>) {
        let ocp = self.ocp;
        let mut term_names = HashSet::new();
        for n in ocp
            .cost
            .residuals
            .iter()
            .map(|r| &r.name)
            .chain(ocp.cost.general.iter().map(|t| &t.name))
            .chain(ocp.constraints.iter().map(|c| &c.name))
        {
            if !term_names.insert(n.clone()) || declared.contains(n) {
                self.errors
                    .push(OcpError::DuplicateName { name: n.clone() });
            }
        }
    }

    /// The horizon, the integrator's substeps and the dynamics' length and symbols.
    fn horizon_and_dynamics(&mut self) {
        let ocp = self.ocp;
        if ocp.horizon.n == 0 {
            self.errors.push(OcpError::ZeroHorizon);
        }
        if !(ocp.horizon.dt.is_finite() && ocp.horizon.dt > 0.0) {
            self.errors
                .push(OcpError::NonPositiveDt { dt: ocp.horizon.dt });
        }
        let dyn_exprs = ocp.dynamics.exprs();
        if let Dynamics::Continuous {
            integrator: Integrator::Rk4 { steps: 0 },
            ..
        } = ocp.dynamics
        {
            self.errors.push(OcpError::ZeroSubsteps);
        }
        if let Dynamics::Continuous {
            integrator:
                Integrator::Irk {
                    stages,
                    steps,
                    newton,
                    ..
                },
            ..
        } = ocp.dynamics
        {
            if !(1..=Integrator::IRK_MAX_STAGES).contains(&stages) {
                self.errors.push(OcpError::IrkStages { stages });
            }
            if steps == 0 {
                self.errors.push(OcpError::IrkZero { what: "substeps" });
            }
            if newton == 0 {
                self.errors.push(OcpError::IrkZero {
                    what: "Newton iterations",
                });
            }
        }
        if self.len("the dynamics", dyn_exprs.len(), ocp.nx(), "the state") {
            self.exprs("the dynamics", dyn_exprs, &PATH_ROLES, "");
        }
    }

    /// The cost terms: tracking terms, residuals, general terms and the input-rate term.
    fn costs(&mut self) {
        let ocp = self.ocp;
        let (nx, nu) = (ocp.nx(), ocp.nu());
        if let Some(t) = &ocp.cost.state {
            self.tracking("state cost", t, nx, "the state", "Q");
        }
        if let Some(t) = &ocp.cost.control {
            self.tracking("control cost", t, nu, "the control", "R");
        }
        if let Some(t) = &ocp.cost.terminal {
            self.tracking("terminal cost", t, nx, "the state", "P");
        }
        for r in &ocp.cost.residuals {
            let item = format!("residual `{}`", r.name);
            let (roles, reason) = stage_roles(r.stage);
            self.exprs(&item, &r.residual, roles, reason);
            self.weight(
                &format!("weight of {item}"),
                &r.weight,
                r.residual.len(),
                "the residual",
            );
        }
        for t in &ocp.cost.general {
            let (roles, reason) = stage_roles(t.stage);
            self.exprs(&format!("cost term `{}`", t.name), &[t.expr], roles, reason);
        }
        if let Some(rate) = &ocp.cost.input_rate {
            self.weight("input-rate weight", &rate.weight, nu, "the control");
            if self.len(
                "previous control of the input-rate cost",
                rate.prev.len(),
                nu,
                "the control",
            ) {
                self.exprs(
                    "previous control of the input-rate cost",
                    &rate.prev,
                    &[Role::GlobalParam, Role::StageParam],
                    "but u_{-1} must be a runtime parameter",
                );
            }
        }
    }

    /// The state and control bounds: their pairs and lengths.
    fn box_bounds(&mut self) {
        let ocp = self.ocp;
        let (nx, nu) = (ocp.nx(), ocp.nu());
        self.bounds("state bound", &ocp.state_bounds, &names(&ocp.states));
        self.bounds("control bound", &ocp.control_bounds, &names(&ocp.controls));
        if ocp.state_bounds.lower.len() != nx || ocp.state_bounds.upper.len() != nx {
            self.len(
                "state bounds",
                ocp.state_bounds.lower.len(),
                nx,
                "the state",
            );
        }
        if ocp.control_bounds.lower.len() != nu || ocp.control_bounds.upper.len() != nu {
            self.len(
                "control bounds",
                ocp.control_bounds.lower.len(),
                nu,
                "the control",
            );
        }
        self.soft_bounds("state", &ocp.state_bounds, &names(&ocp.states));
        self.soft_bounds("control", &ocp.control_bounds, &names(&ocp.controls));
    }

    /// The soft entries of state or control bounds (`what`): one slack per entry, finite
    /// non-negative penalties not both zero, and a finite bound to soften.
    fn soft_bounds(&mut self, what: &str, b: &Bounds, names: &[String]) {
        if b.soft.len() != b.lower.len() {
            self.len(
                &format!("{what} bound slacks"),
                b.soft.len(),
                b.lower.len(),
                &format!("the {what}"),
            );
            return;
        }
        for (i, s) in b.soft.iter().enumerate() {
            let Some(s) = s else { continue };
            let name = names
                .get(i)
                .cloned()
                .unwrap_or_else(|| format!("entry {i}"));
            let item = format!("soft {what} bound on `{name}`");
            for v in [s.l1, s.l2] {
                if !v.is_finite() {
                    self.errors.push(OcpError::NonFinite {
                        item: format!("slack penalty of {item}"),
                        value: v,
                    });
                } else if v < 0.0 {
                    self.errors.push(OcpError::NegativePenalty {
                        item: item.clone(),
                        value: v,
                    });
                }
            }
            if s.l1 == 0.0 && s.l2 == 0.0 {
                self.errors
                    .push(OcpError::ZeroPenalties { item: item.clone() });
            }
            let finite = |v: Option<&f64>| v.is_some_and(|v| v.is_finite());
            if !finite(b.lower.get(i)) && !finite(b.upper.get(i)) {
                self.errors.push(OcpError::SoftUnbounded { item });
            }
        }
    }

    /// A general constraint: its symbols, bounds and slack penalties.
    fn constraint(&mut self, k: &super::Constraint<'g>) {
        let item = format!("constraint `{}`", k.name);
        let (roles, reason) = stage_roles(k.stage);
        self.exprs(&item, &k.expr, roles, reason);
        if k.lower.len() != k.expr.len() || k.upper.len() != k.expr.len() {
            self.errors.push(OcpError::DimensionMismatch {
                item: format!("bounds of {item}"),
                found: format!("{} lower and {} upper values", k.lower.len(), k.upper.len()),
                expected: format!("the constraint has {} entries", k.expr.len()),
            });
        } else {
            for i in 0..k.expr.len() {
                self.bound_pair(&format!("{item} entry {i}"), k.lower[i], k.upper[i]);
            }
        }
        if let Some(s) = k.soft {
            for v in [s.l1, s.l2] {
                if !v.is_finite() {
                    self.errors.push(OcpError::NonFinite {
                        item: format!("slack penalty of {item}"),
                        value: v,
                    });
                } else if v < 0.0 {
                    self.errors.push(OcpError::NegativePenalty {
                        item: item.clone(),
                        value: v,
                    });
                }
            }
        }
    }

    /// Warnings: controls the dynamics do not see.
    fn unused_controls(&self) -> Vec<OcpWarning> {
        let used: HashSet<usize> = super::symbols_of(self.ocp.dynamics.exprs())
            .iter()
            .map(Expr::index)
            .collect();
        self.ocp
            .u()
            .iter()
            .filter(|s| !used.contains(&s.index()))
            .map(|s| OcpWarning::UnusedControl {
                name: s.to_string(),
            })
            .collect()
    }
}

/// Eigenvalues of a symmetric `n x n` matrix given row by row (cyclic Jacobi rotations),
/// ascending. Used for the positive-semidefiniteness check of weights.
pub fn symmetric_eigenvalues(a: &[f64], n: usize) -> Vec<f64> {
    let mut m = a.to_vec();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| m[i * n + j] * m[i * n + j])
            .sum();
        let diag: f64 = (0..n).map(|i| m[i * n + i] * m[i * n + i]).sum();
        if off <= 1e-30 * diag.max(f64::MIN_POSITIVE) || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = m[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                let (app, aqq) = (m[p * n + p], m[q * n + q]);
                let theta = (aqq - app) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let cs = 1.0 / (t * t + 1.0).sqrt();
                let sn = t * cs;
                for k in 0..n {
                    let (akp, akq) = (m[k * n + p], m[k * n + q]);
                    m[k * n + p] = cs * akp - sn * akq;
                    m[k * n + q] = sn * akp + cs * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (m[p * n + k], m[q * n + k]);
                    m[p * n + k] = cs * apk - sn * aqk;
                    m[q * n + k] = sn * apk + cs * aqk;
                }
            }
        }
    }
    let mut eig: Vec<f64> = (0..n).map(|i| m[i * n + i]).collect();
    eig.sort_by(f64::total_cmp);
    eig
}
