//! The Rust front end: a builder that reads like the math.
//!
//! ```
//! use mpc_dsl::{Graph, Matrix, Vector};
//! use mpc_dsl::ocp::{Decl, Integrator, Ocp};
//!
//! let g = Graph::new();
//! let mut b = Ocp::builder(&g, "double_integrator");
//! let pos = b.state(Decl::scalar("pos").unit("m"));
//! let vel = b.state(Decl::scalar("vel").unit("m/s"));
//! let acc = b.control(Decl::scalar("acc"));
//! let xref = b.stage_param(Decl::vector("xref", 2));
//! b.ode(&[vel[0], acc[0]], Integrator::Rk4 { steps: 1 });
//! b.horizon(20, 0.05);
//! b.state_cost(Matrix::diag(&g, &Vector::constants(&g, &[10.0, 1.0])), &xref);
//! b.control_cost(Matrix::identity(&g, 1), &Vector::zeros(&g, 1));
//! b.bound(&acc, -5.0, 5.0);
//! let ocp = b.build().unwrap();
//! assert_eq!((ocp.nx(), ocp.nu(), ocp.np()), (2, 1, 2));
//! ```

use crate::graph::{Expr, Graph};
use crate::linalg::{Matrix, Vector};

use super::{
    Bounds, Constraint, Cost, Dynamics, GeneralCost, Horizon, InputRate, Integrator, Ocp, OcpError,
    ParamKind, Parameter, Residual, Slack, SolverChoices, Stage, Tracking, ValidationErrors,
    Variable,
};

/// A declaration of a state, control or parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct Decl {
    name: String,
    len: usize,
    scalar: bool,
    unit: Option<String>,
    description: Option<String>,
    start: Option<Vec<f64>>,
}

impl Decl {
    /// A scalar, whose symbol is called `name`.
    pub fn scalar(name: &str) -> Decl {
        Decl {
            name: name.to_owned(),
            len: 1,
            scalar: true,
            unit: None,
            description: None,
            start: None,
        }
    }

    /// A vector of `len` entries, whose symbols are called `name[0]`, ..., `name[len-1]`.
    pub fn vector(name: &str, len: usize) -> Decl {
        Decl {
            len,
            scalar: false,
            ..Decl::scalar(name)
        }
    }

    /// Sets the physical unit.
    pub fn unit(mut self, unit: &str) -> Decl {
        self.unit = Some(unit.to_owned());
        self
    }

    /// Sets the description.
    pub fn describe(mut self, text: &str) -> Decl {
        self.description = Some(text.to_owned());
        self
    }

    /// Sets the initial guess (states, controls) or default value (parameters). One value is
    /// broadcast to every entry.
    pub fn start(mut self, values: &[f64]) -> Decl {
        self.start = Some(if values.len() == 1 {
            vec![values[0]; self.len]
        } else {
            values.to_vec()
        });
        self
    }

    fn into_variable<'g>(self, g: &'g Graph) -> Variable<'g> {
        let symbols = if self.scalar {
            Vector::new(vec![g.symbol(&self.name)])
        } else {
            g.symbols(&self.name, self.len)
        };
        Variable {
            name: self.name,
            symbols,
            scalar: self.scalar,
            unit: self.unit,
            description: self.description,
            start: self.start,
        }
    }
}

/// One call of [`OcpBuilder::bound_each`] or [`OcpBuilder::soft_bound_each`].
#[derive(Debug)]
struct BoundRequest<'g> {
    symbols: Vec<Expr<'g>>,
    lower: Vec<f64>,
    upper: Vec<f64>,
    /// The slack penalties of each entry, for a soft bound.
    soft: Option<Vec<Slack>>,
}

/// Builds an [`Ocp`]. Methods record what they are given; [`build`](Self::build) validates
/// everything at once and reports every error.
#[derive(Debug)]
pub struct OcpBuilder<'g> {
    graph: &'g Graph,
    ocp: Ocp<'g>,
    has_dynamics: bool,
    has_horizon: bool,
    bound_requests: Vec<BoundRequest<'g>>,
    errors: Vec<OcpError>,
}

impl<'g> OcpBuilder<'g> {
    /// An empty problem called `name` in `graph`.
    pub fn new(graph: &'g Graph, name: &str) -> OcpBuilder<'g> {
        OcpBuilder {
            graph,
            ocp: Ocp {
                name: name.to_owned(),
                states: Vec::new(),
                controls: Vec::new(),
                parameters: Vec::new(),
                dynamics: Dynamics::Discrete {
                    x_next: Vector::default(),
                },
                horizon: Horizon { n: 0, dt: 0.0 },
                cost: Cost::default(),
                state_bounds: Bounds::unbounded(0),
                control_bounds: Bounds::unbounded(0),
                constraints: Vec::new(),
                solver: SolverChoices::default(),
            },
            has_dynamics: false,
            has_horizon: false,
            bound_requests: Vec::new(),
            errors: Vec::new(),
        }
    }

    /// The graph the problem is built in.
    pub fn graph(&self) -> &'g Graph {
        self.graph
    }

    /// Declares a state; returns its symbols.
    pub fn state(&mut self, decl: Decl) -> Vector<'g> {
        let v = decl.into_variable(self.graph);
        let s = v.symbols.clone();
        self.ocp.states.push(v);
        s
    }

    /// Declares a control; returns its symbols.
    pub fn control(&mut self, decl: Decl) -> Vector<'g> {
        let v = decl.into_variable(self.graph);
        let s = v.symbols.clone();
        self.ocp.controls.push(v);
        s
    }

    /// Declares a runtime parameter; returns its symbols.
    pub fn param(&mut self, decl: Decl, kind: ParamKind) -> Vector<'g> {
        let var = decl.into_variable(self.graph);
        let s = var.symbols.clone();
        self.ocp.parameters.push(Parameter { var, kind });
        s
    }

    /// Declares a parameter with one value per stage (a reference).
    pub fn stage_param(&mut self, decl: Decl) -> Vector<'g> {
        self.param(decl, ParamKind::Stage)
    }

    /// Declares a parameter with one value for the whole horizon.
    pub fn global_param(&mut self, decl: Decl) -> Vector<'g> {
        self.param(decl, ParamKind::Global)
    }

    /// Continuous dynamics `xdot = f(x, u, p)`, one expression per state entry, discretized
    /// by `integrator`: [`Integrator::Rk4`], or for stiff dynamics the implicit
    /// [`Integrator::Irk`] (e.g. [`Integrator::gauss_legendre`]`(2)`). Its settings are checked
    /// by [`build`](Self::build): [`OcpError::IrkStages`] for stages outside 1..=3,
    /// [`OcpError::IrkZero`] for zero substeps or Newton iterations (from a `.mpc` file,
    /// located at the integrator).
    pub fn ode(&mut self, xdot: &[Expr<'g>], integrator: Integrator) -> &mut Self {
        self.set_dynamics(Dynamics::Continuous {
            xdot: xdot.iter().copied().collect(),
            integrator,
        })
    }

    /// Discrete dynamics `x_{k+1} = F(x_k, u_k, p)`.
    pub fn discrete(&mut self, x_next: &[Expr<'g>]) -> &mut Self {
        self.set_dynamics(Dynamics::Discrete {
            x_next: x_next.iter().copied().collect(),
        })
    }

    fn set_dynamics(&mut self, d: Dynamics<'g>) -> &mut Self {
        if self.has_dynamics {
            self.errors.push(OcpError::Duplicate {
                what: "dynamics".into(),
            });
        }
        self.has_dynamics = true;
        self.ocp.dynamics = d;
        self
    }

    /// Horizon `N` intervals of `dt` seconds.
    pub fn horizon(&mut self, n: usize, dt: f64) -> &mut Self {
        self.has_horizon = true;
        self.ocp.horizon = Horizon { n, dt };
        self
    }

    /// The generated solver's default shift of the trajectory between real-time iterations
    /// (`RtiSettings::shift`; without this call, the runtime's default).
    pub fn shift(&mut self, on: bool) -> &mut Self {
        self.ocp.solver.shift = Some(on);
        self
    }

    /// State tracking `1/2 |x_k - xref_k|^2_Q` on `k < N`.
    pub fn state_cost(&mut self, q: Matrix<'g>, xref: &[Expr<'g>]) -> &mut Self {
        self.ocp.cost.state = Some(tracking(q, xref));
        self
    }

    /// Control tracking `1/2 |u_k - uref_k|^2_R` on `k < N`.
    pub fn control_cost(&mut self, r: Matrix<'g>, uref: &[Expr<'g>]) -> &mut Self {
        self.ocp.cost.control = Some(tracking(r, uref));
        self
    }

    /// Terminal tracking `1/2 |x_N - xref_N|^2_P`.
    pub fn terminal_cost(&mut self, p: Matrix<'g>, xref: &[Expr<'g>]) -> &mut Self {
        self.ocp.cost.terminal = Some(tracking(p, xref));
        self
    }

    /// Nonlinear least squares `1/2 |r(x, u, p)|^2_W` on `k < N` (path) or at `N`.
    pub fn residual(
        &mut self,
        name: &str,
        stage: Stage,
        r: &[Expr<'g>],
        w: Matrix<'g>,
    ) -> &mut Self {
        self.ocp.cost.residuals.push(Residual {
            name: name.to_owned(),
            stage,
            residual: r.iter().copied().collect(),
            weight: w,
        });
        self
    }

    /// Input-rate cost `1/2 |u_k - u_{k-1}|^2_W`, with `u_{-1} = prev` (parameter symbols).
    pub fn input_rate(&mut self, w: Matrix<'g>, prev: &[Expr<'g>]) -> &mut Self {
        self.ocp.cost.input_rate = Some(InputRate {
            weight: w,
            prev: prev.iter().copied().collect(),
        });
        self
    }

    /// A general cost term `l(x, u, p)` added to the objective on every stage `k < N`
    /// ([`Stage::Path`]), or `l_N(x, p)` at `N` ([`Stage::Terminal`]), as it is (no factor
    /// 1/2). Terms at the same stage are summed, with the least-squares terms.
    pub fn general_cost(&mut self, name: &str, stage: Stage, l: Expr<'g>) -> &mut Self {
        self.ocp.cost.general.push(GeneralCost {
            name: name.to_owned(),
            stage,
            expr: l,
        });
        self
    }

    /// Box bound `lower <= s <= upper` on every state or control symbol in `symbols`
    /// (infinite values allowed).
    pub fn bound(&mut self, symbols: &[Expr<'g>], lower: f64, upper: f64) -> &mut Self {
        let n = symbols.len();
        self.bound_each(symbols, &vec![lower; n], &vec![upper; n])
    }

    /// Box bounds with one lower and one upper value per symbol.
    pub fn bound_each(&mut self, symbols: &[Expr<'g>], lower: &[f64], upper: &[f64]) -> &mut Self {
        self.bound_requests.push(BoundRequest {
            symbols: symbols.to_vec(),
            lower: lower.to_vec(),
            upper: upper.to_vec(),
            soft: None,
        });
        self
    }

    /// Soft box bound `lower <= s <= upper` on every state or control symbol in `symbols`,
    /// its violation penalized with `slack` (like a soft general constraint's; a state
    /// bound on stages `1..=N`, a control bound on `k < N`).
    pub fn soft_bound(
        &mut self,
        symbols: &[Expr<'g>],
        lower: f64,
        upper: f64,
        slack: Slack,
    ) -> &mut Self {
        let n = symbols.len();
        self.soft_bound_each(symbols, &vec![lower; n], &vec![upper; n], &vec![slack; n])
    }

    /// Soft box bounds with one lower and upper value and one pair of penalties per symbol.
    pub fn soft_bound_each(
        &mut self,
        symbols: &[Expr<'g>],
        lower: &[f64],
        upper: &[f64],
        slacks: &[Slack],
    ) -> &mut Self {
        self.bound_requests.push(BoundRequest {
            symbols: symbols.to_vec(),
            lower: lower.to_vec(),
            upper: upper.to_vec(),
            soft: Some(slacks.to_vec()),
        });
        self
    }

    /// General constraint `lower <= h <= upper` (hard; see [`soft_constraint`]).
    ///
    /// [`soft_constraint`]: Self::soft_constraint
    pub fn constraint(
        &mut self,
        name: &str,
        stage: Stage,
        h: &[Expr<'g>],
        lower: &[f64],
        upper: &[f64],
    ) -> &mut Self {
        self.push_constraint(name, stage, h, lower, upper, None)
    }

    /// Soft general constraint with slack penalties.
    pub fn soft_constraint(
        &mut self,
        name: &str,
        stage: Stage,
        h: &[Expr<'g>],
        lower: &[f64],
        upper: &[f64],
        slack: Slack,
    ) -> &mut Self {
        self.push_constraint(name, stage, h, lower, upper, Some(slack))
    }

    fn push_constraint(
        &mut self,
        name: &str,
        stage: Stage,
        h: &[Expr<'g>],
        lower: &[f64],
        upper: &[f64],
        soft: Option<Slack>,
    ) -> &mut Self {
        let bcast = |v: &[f64]| {
            if v.len() == 1 {
                vec![v[0]; h.len()]
            } else {
                v.to_vec()
            }
        };
        self.ocp.constraints.push(Constraint {
            name: name.to_owned(),
            stage,
            expr: h.iter().copied().collect(),
            lower: bcast(lower),
            upper: bcast(upper),
            soft,
        });
        self
    }

    /// Finishes and validates. Returns the problem and the warnings.
    ///
    /// # Errors
    /// Every problem found, as [`ValidationErrors`].
    pub fn build_with_warnings(mut self) -> Result<(Ocp<'g>, Vec<OcpWarning>), ValidationErrors> {
        if !self.has_dynamics {
            self.errors.push(OcpError::Missing {
                what: "dynamics".into(),
            });
        }
        if !self.has_horizon {
            self.errors.push(OcpError::Missing {
                what: "horizon".into(),
            });
        }
        let (nx, nu) = (self.ocp.nx(), self.ocp.nu());
        self.ocp.state_bounds = Bounds::unbounded(nx);
        self.ocp.control_bounds = Bounds::unbounded(nu);
        let x = self.ocp.x();
        let u = self.ocp.u();
        for r in std::mem::take(&mut self.bound_requests) {
            self.apply_bounds(r, &x, &u);
        }
        let result = self.ocp.validate();
        match result {
            Ok(w) if self.errors.is_empty() => Ok((self.ocp, w)),
            Err(e)
                if e.errors
                    .iter()
                    .all(|err| err.culprit() == Some("the dynamics"))
                    && !self.has_dynamics =>
            {
                Err(ValidationErrors {
                    errors: self.errors,
                    warnings: e.warnings,
                })
            }
            Ok(w) => Err(ValidationErrors {
                errors: self.errors,
                warnings: w,
            }),
            Err(mut e) => {
                if !self.has_dynamics {
                    // Already reported as missing; its empty placeholder has no length.
                    e.errors.retain(|err| err.culprit() != Some("the dynamics"));
                }
                self.errors.append(&mut e.errors);
                e.errors = self.errors;
                Err(e)
            }
        }
    }

    /// Writes one bound request into the problem's state or control bounds.
    fn apply_bounds(&mut self, r: BoundRequest<'g>, x: &[Expr<'g>], u: &[Expr<'g>]) {
        let n = r.symbols.len();
        let soft_len = r.soft.as_ref().map_or(n, Vec::len);
        if r.lower.len() != n || r.upper.len() != n || soft_len != n {
            self.errors.push(OcpError::DimensionMismatch {
                item: "box bound".into(),
                found: format!(
                    "{} lower and {} upper values ({} slack penalties)",
                    r.lower.len(),
                    r.upper.len(),
                    soft_len
                ),
                expected: format!("{n} (one per bounded entry)"),
            });
            return;
        }
        for (i, s) in r.symbols.iter().enumerate() {
            let (bounds, idx) = if let Some(j) = x.iter().position(|e| e == s) {
                (&mut self.ocp.state_bounds, j)
            } else if let Some(j) = u.iter().position(|e| e == s) {
                (&mut self.ocp.control_bounds, j)
            } else {
                self.errors.push(OcpError::NotAVariable {
                    item: "box bound".into(),
                    name: s.to_string(),
                });
                continue;
            };
            bounds.lower[idx] = r.lower[i];
            bounds.upper[idx] = r.upper[i];
            bounds.soft[idx] = r.soft.as_ref().map(|v| v[i]);
        }
    }

    /// Finishes and validates, dropping the warnings.
    ///
    /// # Errors
    /// Every problem found, as [`ValidationErrors`].
    pub fn build(self) -> Result<Ocp<'g>, ValidationErrors> {
        self.build_with_warnings().map(|(o, _)| o)
    }
}

use super::OcpWarning;

fn tracking<'g>(w: Matrix<'g>, reference: &[Expr<'g>]) -> Tracking<'g> {
    Tracking {
        weight: w,
        reference: reference.iter().copied().collect(),
    }
}
