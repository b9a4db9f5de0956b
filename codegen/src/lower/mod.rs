//! Lowering an [`Ocp`] to the straight-line functions a generated solver evaluates.
//!
//! The result ([`Lowered`]) is independent of the output language: every model function is a
//! [`Program`] (SSA, every distinct subexpression once) with a map saying where each output
//! goes. What the runtime's `Model` trait needs is built here:
//!
//! - **Dynamics**: `F(x, u, p)` over one shooting interval with `A = dF/dx`, `B = dF/du`. For
//!   continuous dynamics the integrator is applied together with its forward sensitivities
//!   (RK4: `K_i = f_x(X_i) S_i + [0 f_u(X_i)]` per stage, `S` updated like `X`), never by
//!   differentiating an expanded multi-step expression. The state part is built with exactly
//!   the operations of [`Ocp::discrete_map`], so `F` is the same expression as the reference.
//!   Structure comes for free from the graph's construction-time rules: the initial
//!   sensitivity `[I 0]` is made of constants, so products with its zeros and ones vanish,
//!   and every Jacobian entry that is a constant is emitted as one.
//! - **Input-rate cost** `1/2 |u_k - u_{k-1}|^2`: handled by augmenting the state with the
//!   last applied control, `x_aug = (x, u_last)`, `u_last+ = u`. The residual gains
//!   `u - u_last`; at stage 0, `u_last` is the input-rate parameter (`u_{-1}`), which the
//!   generated solver writes into the augmented initial state. The QP keeps its stage-wise
//!   structure (no coupling term between stages), as acados does.
//! - **Cost**: one stage residual `y = (x - xref, u - uref, r(x, u, p), u - u_last)` with the
//!   block-diagonal weight `W = diag(Q, R, W_r, W_rate)` (Gauss-Newton Hessian `J'WJ`), the
//!   terminal residual `y_N = (x_N - xref_N, r_N(x, p))` with `diag(P, W_rN)`. References are
//!   expressions of parameters inside the residual, so the runtime's own reference is zero.
//!   Weights may depend on global parameters; they are a separate function of `p`.
//! - **Constraints**: path and terminal general constraints stacked, with their Jacobians,
//!   bounds and slack penalties (`0, 0` for a hard row), then the soft box bounds' rows
//!   (`soft_bounds.rs`: `h = u_j`, `h = x_j` and `h_N = x_j`).
//!
//! The steps are in [`lower_with`], in order: the symbols, the dynamics (`dynamics.rs`), the
//! cost (`cost.rs`), the constraints (`constraints.rs`), the constant data (`data.rs`).

mod constraints;
mod cost;
mod data;
mod dynamics;
mod general_cost;
mod soft_bounds;

pub use soft_bounds::SoftBounds;

use mpc_dsl::ocp::{ParamKind, Stage, Variable};
use mpc_dsl::{DslError, Expr, Graph, Ocp, Program, Vector};

use crate::error::CodegenError;
use constraints::StackedConstraints;
use cost::{lower_cost, weights_read_u_prev};
use data::{guesses, named, state_bounds, u_prev_entries};
use dynamics::{discretize, dynamics_functions, dynamics_hessian, irk_functions, irk_of};
pub use general_cost::GeneralCostFunctions;
use general_cost::{constraints_hessian, general_cost};

/// Which argument of a model function an input is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arg {
    /// The (augmented) state `x`.
    X,
    /// The control `u`.
    U,
    /// The parameters `p`.
    P,
    /// The dynamics multipliers `pi` (one per state), of the Lagrangian Hessian.
    Pi,
    /// The general constraints' multipliers `mu` (one per row), of the Lagrangian Hessian.
    Mu,
}

/// Where an output of a [`Function`] is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Entry `i` of the returned vector.
    Ret(usize),
    /// Entry `(i, j)` of the named output matrix.
    Mat(&'static str, usize, usize),
}

/// One model function: a program, its inputs and where each output goes.
#[derive(Clone, Debug)]
pub struct Function {
    /// The straight-line program.
    pub program: Program,
    /// What each program input is: argument and index.
    pub inputs: Vec<(Arg, usize)>,
    /// Where each program output goes.
    pub outputs: Vec<Target>,
}

/// An implicit (collocation) step's settings, as in the model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IrkStep {
    /// Collocation stages (1 to 3).
    pub stages: usize,
    /// Substeps per interval.
    pub steps: usize,
    /// Newton iterations per substep.
    pub newton: usize,
    /// Radau IIA collocation (Gauss-Legendre otherwise).
    pub radau: bool,
}

/// A named block of rows (of the residual or of the constraints), for documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct RowBlock {
    /// First row.
    pub start: usize,
    /// Number of rows.
    pub len: usize,
    /// What the rows are (`x - xref (Q)`, `swing_gimbal`, ...).
    pub what: String,
}

/// A named state, control or parameter entry range.
#[derive(Clone, Debug, PartialEq)]
pub struct Named {
    /// Name as in the model.
    pub name: String,
    /// First entry.
    pub offset: usize,
    /// Number of entries.
    pub len: usize,
    /// Declared as a scalar.
    pub scalar: bool,
    /// Unit and description, for documentation.
    pub doc: String,
    /// For parameters: one value per stage (`true`) or global.
    pub per_stage: bool,
}

/// An [`Ocp`] lowered to functions and constant data.
#[derive(Clone, Debug)]
pub struct Lowered {
    /// Model name.
    pub name: String,
    /// The model's choice of the real-time iteration's shift (`solver { shift = ...; }`).
    pub shift: Option<bool>,
    /// States of the model (without the input-rate augmentation).
    pub nx_model: usize,
    /// States of the solver (`nx_model + nu` with an input-rate cost).
    pub nx: usize,
    /// Controls.
    pub nu: usize,
    /// Parameters.
    pub np: usize,
    /// Stage residual rows.
    pub ny: usize,
    /// Terminal residual rows.
    pub nyn: usize,
    /// Stage general constraint rows.
    pub ng: usize,
    /// Terminal general constraint rows.
    pub ngn: usize,
    /// Horizon.
    pub n: usize,
    /// Interval length in seconds.
    pub dt: f64,
    /// How the dynamics are discretized, in words.
    pub discretization: String,
    /// `F`, `A`, `B`; with [`irk`](Self::irk), the ODE's right-hand side instead:
    /// `f(x, u, p)` over the model's states with `fx = df/dx`, `fu = df/du`, which the
    /// emitted implicit step evaluates at its stage points.
    pub dynamics: Function,
    /// `F` alone; with [`irk`](Self::irk), `f(x, u, p)` alone.
    pub dynamics_value: Function,
    /// The implicit integrator's settings, when the model integrates with `irk`: the step is
    /// then emitted as a call of `mpc_runtime::implicit` around [`dynamics`](Self::dynamics).
    pub irk: Option<IrkStep>,
    /// The Hessian of `pi' F(x, u, p)` over `(x, u)`, as `hxx`, `hux`, `huu` (with
    /// [`lower_with`]'s `exact_hessian`).
    pub dynamics_hessian: Option<Function>,
    /// `y`, `J_x`, `J_u`.
    pub residual: Function,
    /// `y_N`, `J_x`.
    pub terminal_residual: Function,
    /// Every entry of `J_x`, `J_u` and the terminal `J_x` is a constant (the residuals are
    /// linear in the states and controls, whatever the parameters).
    pub constant_residual_jacobians: bool,
    /// Every entry of the stage residual's `J_x` and `J_u` is a constant (the terminal
    /// residual may be nonlinear): one `J'WJ` serves every stage.
    pub constant_stage_residual_jacobians: bool,
    /// The general cost terms' sums with their gradients and Hessians (a model with
    /// general terms only).
    pub general_cost: Option<GeneralCostFunctions>,
    /// The Hessian of `mu' h(x, u, p)` over `(x, u)` (with `exact_hessian` and `ng > 0`).
    pub constraints_hessian: Option<Function>,
    /// The Hessian of `mu' h_N(x, p)` over `x` (with `exact_hessian` and `ngn > 0`).
    pub terminal_constraints_hessian: Option<Function>,
    /// `h`, `C_x`, `C_u` (when `ng > 0`).
    pub constraints: Option<Function>,
    /// `h_N`, `C_x` (when `ngn > 0`).
    pub terminal_constraints: Option<Function>,
    /// `W` and `W_N` from the parameters.
    pub weights: Function,
    /// Rows of `y`.
    pub residual_rows: Vec<RowBlock>,
    /// Rows of `y_N`.
    pub terminal_residual_rows: Vec<RowBlock>,
    /// Rows of `h`.
    pub constraint_rows: Vec<RowBlock>,
    /// Rows of `h_N`.
    pub terminal_constraint_rows: Vec<RowBlock>,
    /// State bounds (length `nx`, infinite = absent).
    pub lbx: Vec<f64>,
    /// State upper bounds.
    pub ubx: Vec<f64>,
    /// Control lower bounds.
    pub lbu: Vec<f64>,
    /// Control upper bounds.
    pub ubu: Vec<f64>,
    /// Stage constraint bounds.
    pub lg: Vec<f64>,
    /// Stage constraint upper bounds.
    pub ug: Vec<f64>,
    /// Terminal constraint bounds.
    pub lgn: Vec<f64>,
    /// Terminal constraint upper bounds.
    pub ugn: Vec<f64>,
    /// L1 slack penalties of the stage constraints (0 = hard).
    pub l1: Vec<f64>,
    /// L2 slack penalties of the stage constraints.
    pub l2: Vec<f64>,
    /// L1 slack penalties of the terminal constraints.
    pub l1n: Vec<f64>,
    /// L2 slack penalties of the terminal constraints.
    pub l2n: Vec<f64>,
    /// Initial guess of the (augmented) state.
    pub x_guess: Vec<f64>,
    /// Initial guess of the control.
    pub u_guess: Vec<f64>,
    /// Default parameter values.
    pub p_default: Vec<f64>,
    /// Named state ranges (model states only).
    pub states: Vec<Named>,
    /// Named control ranges.
    pub controls: Vec<Named>,
    /// Named parameter ranges.
    pub params: Vec<Named>,
    /// With an input-rate cost: the parameter entries holding `u_{-1}` (one per control).
    pub u_prev: Option<Vec<usize>>,
    /// Whether the weights depend on the `u_prev` parameters (then the automatic update after
    /// each feedback re-evaluates them).
    pub weights_use_u_prev: bool,
    /// The soft state and control bounds, lowered to the last general rows (`ng`, `ngn`,
    /// the bounds and penalties above count them; the box bounds above do not).
    pub soft_bounds: SoftBounds,
}

/// Compiles expressions over the symbols of some arguments into [`Function`]s.
struct Builder<'g> {
    g: &'g Graph,
    x: Vec<Expr<'g>>,
    u: Vec<Expr<'g>>,
    p: Vec<Expr<'g>>,
    pi: Vec<Expr<'g>>,
    mu: Vec<Expr<'g>>,
}

impl<'g> Builder<'g> {
    /// A builder over the parameters `p` only (no states, controls or multipliers).
    fn over_params(g: &'g Graph, p: Vec<Expr<'g>>) -> Builder<'g> {
        Builder {
            g,
            x: Vec::new(),
            u: Vec::new(),
            p,
            pi: Vec::new(),
            mu: Vec::new(),
        }
    }

    /// Compiles `outputs` over `(x, u, p)` (or the subset `args`), mapping each output to
    /// its target. `what` names the function in errors.
    fn function(
        &self,
        what: &'static str,
        args: &[Arg],
        outputs: Vec<(Expr<'g>, Target)>,
    ) -> Result<Function, CodegenError> {
        let mut inputs = Vec::new();
        let mut syms = Vec::new();
        for &a in args {
            let v = match a {
                Arg::X => &self.x,
                Arg::U => &self.u,
                Arg::P => &self.p,
                Arg::Pi => &self.pi,
                Arg::Mu => &self.mu,
            };
            for (i, &s) in v.iter().enumerate() {
                inputs.push((a, i));
                syms.push(s);
            }
        }
        let (exprs, targets): (Vec<_>, Vec<_>) = outputs.into_iter().unzip();
        let program = self.g.compile(&exprs, &syms).map_err(|e| match e {
            DslError::UnboundSymbol { name } => CodegenError::UnexpectedSymbol {
                function: what,
                symbol: name,
                allowed: args
                    .iter()
                    .map(|a| match a {
                        Arg::X => "states",
                        Arg::U => "controls",
                        Arg::P => "parameters",
                        Arg::Pi => "dynamics multipliers",
                        Arg::Mu => "constraint multipliers",
                    })
                    .collect::<Vec<_>>()
                    .join(", "),
            },
            other => CodegenError::Dsl(other),
        })?;
        Ok(Function {
            program,
            inputs,
            outputs: targets,
        })
    }

    /// A function of `(x, u, p)` (or `(x, p)` without `u_mat`) returning `exprs` and
    /// writing their Jacobian over the states into matrix `x_mat` and over the controls into
    /// `u_mat`; and whether every entry of that Jacobian is a constant.
    fn with_jacobian(
        &self,
        what: &'static str,
        exprs: &[Expr<'g>],
        x_mat: &'static str,
        u_mat: Option<&'static str>,
    ) -> Result<(Function, bool), CodegenError> {
        let nx = self.x.len();
        let mut wrt = self.x.clone();
        let args: &[Arg] = match u_mat {
            Some(_) => {
                wrt.extend(self.u.iter().copied());
                &[Arg::X, Arg::U, Arg::P]
            }
            None => &[Arg::X, Arg::P],
        };
        let jac = self.g.jacobian(exprs, &wrt)?;
        let constant = jac.iter().all(|(_, _, e)| e.as_constant().is_some());
        let mut out: Vec<_> = (exprs.iter().enumerate())
            .map(|(i, &e)| (e, Target::Ret(i)))
            .collect();
        for (i, j, e) in jac.iter() {
            let t = match u_mat {
                Some(m) if j >= nx => Target::Mat(m, i, j - nx),
                _ => Target::Mat(x_mat, i, j),
            };
            out.push((e, t));
        }
        Ok((self.function(what, args, out)?, constant))
    }
}

/// Lowers a validated problem.
///
/// # Errors
/// [`CodegenError::Invalid`] if the problem does not validate; [`CodegenError::UnexpectedSymbol`]
/// when a terminal function uses a control or a weight uses a per-stage parameter;
/// [`CodegenError::Dsl`] for errors of the symbolic layer.
pub fn lower<'g>(ocp: &Ocp<'g>) -> Result<Lowered, CodegenError> {
    lower_with(ocp, false)
}

/// [`lower`], and with `exact_hessian` the dynamics' part of the Lagrangian Hessian
/// ([`Lowered::dynamics_hessian`]).
///
/// # Errors
/// As [`lower`].
// Over 80 lines: half of it is the `Lowered` literal, and the steps before it must stay in
// one place, in their order (below).
pub fn lower_with<'g>(ocp: &Ocp<'g>, exact_hessian: bool) -> Result<Lowered, CodegenError> {
    // The steps in the order they add to the graph and may fail: changing it may change the
    // generated code (the graph's numbering) and which error is reported first.
    ocp.validate().map_err(CodegenError::Invalid)?;
    let v = Symbols::new(ocp, exact_hessian)?;
    let b = v.builder();
    let irk = irk_of(ocp);
    let (dynamics, dynamics_value, dynamics_hessian, discretization) = match irk {
        Some(_) if exact_hessian => return Err(CodegenError::ExactHessianWithIrk),
        Some(step) => irk_functions(ocp, &v, step)?,
        None => {
            let map = discretize(ocp, &v)?;
            let (dynamics, dynamics_value) = dynamics_functions(ocp, &v, &b, &map)?;
            let hessian = if exact_hessian {
                Some(dynamics_hessian(&v, &b, &map.x_next)?)
            } else {
                None
            };
            (dynamics, dynamics_value, hessian, map.how)
        }
    };
    let cost = lower_cost(ocp, &v, &b)?;
    let mut path = StackedConstraints::of(ocp, Stage::Path);
    let mut terminal = StackedConstraints::of(ocp, Stage::Terminal);
    let soft_bounds = soft_bounds::append_soft_bounds(ocp, &mut path, &mut terminal);
    let constraints = (!path.h.is_empty())
        .then(|| b.with_jacobian("constraints", &path.h, "cx", Some("cu")))
        .transpose()?;
    let terminal_constraints = (!terminal.h.is_empty())
        .then(|| b.with_jacobian("terminal constraints", &terminal.h, "cx", None))
        .transpose()?;
    let (mut lbx, mut ubx) = state_bounds(ocp, &v);
    soft_bounds::hard_only(&ocp.state_bounds, &mut lbx, &mut ubx);
    let (mut lbu, mut ubu) = (
        ocp.control_bounds.lower.clone(),
        ocp.control_bounds.upper.clone(),
    );
    soft_bounds::hard_only(&ocp.control_bounds, &mut lbu, &mut ubu);
    let (x_guess, u_guess) = guesses(ocp);
    let u_prev = u_prev_entries(ocp, &v)?;
    let weights_use_u_prev = (u_prev.as_deref())
        .is_some_and(|idx| weights_read_u_prev(ocp, &v, idx, cost.weight_outputs));
    // Last: the general cost and the constraints' curvature add to the graph only for the
    // models that have them, so the functions above are those of a model without them.
    let general_cost = general_cost(ocp, &v, &b)?;
    let (constraints_hessian, terminal_constraints_hessian) = if exact_hessian {
        (
            constraints_hessian(&v, &path.h, Stage::Path)?,
            constraints_hessian(&v, &terminal.h, Stage::Terminal)?,
        )
    } else {
        (None, None)
    };
    Ok(Lowered {
        name: ocp.name.clone(),
        shift: ocp.solver.shift,
        weights_use_u_prev,
        nx_model: v.xm.len(),
        nx: v.x.len(),
        nu: v.u.len(),
        np: v.p.len(),
        ny: cost.stage.y.len(),
        nyn: cost.terminal.y.len(),
        ng: path.h.len(),
        ngn: terminal.h.len(),
        n: ocp.horizon.n,
        dt: ocp.horizon.dt,
        discretization,
        dynamics,
        dynamics_value,
        irk,
        dynamics_hessian,
        residual: cost.residual,
        terminal_residual: cost.terminal_residual,
        constant_residual_jacobians: cost.constant_jacobians,
        constant_stage_residual_jacobians: cost.constant_stage_jacobians,
        general_cost,
        constraints_hessian,
        terminal_constraints_hessian,
        constraints: constraints.map(|(f, _)| f),
        terminal_constraints: terminal_constraints.map(|(f, _)| f),
        weights: cost.weights,
        residual_rows: cost.stage.rows,
        terminal_residual_rows: cost.terminal.rows,
        constraint_rows: path.rows,
        terminal_constraint_rows: terminal.rows,
        lbx,
        ubx,
        lbu,
        ubu,
        lg: path.lower,
        ug: path.upper,
        lgn: terminal.lower,
        ugn: terminal.upper,
        l1: path.l1,
        l2: path.l2,
        l1n: terminal.l1,
        l2n: terminal.l2,
        x_guess,
        u_guess,
        p_default: ocp.p_default(),
        states: named(&ocp.states, |_| false),
        controls: named(&ocp.controls, |_| false),
        params: {
            let vars: Vec<Variable<'_>> = ocp.parameters.iter().map(|q| q.var.clone()).collect();
            named(&vars, |i| ocp.parameters[i].kind == ParamKind::Stage)
        },
        u_prev,
        soft_bounds,
    })
}

/// The problem's symbols as the lowered functions see them.
struct Symbols<'g> {
    g: &'g Graph,
    /// The model's states.
    xm: Vector<'g>,
    /// The controls.
    u: Vector<'g>,
    /// The parameters.
    p: Vector<'g>,
    /// With an input-rate cost, the last applied control (`$u_last[i]`, one per control);
    /// empty otherwise.
    u_last: Vec<Expr<'g>>,
    /// The solver's states: the model's, then `u_last`.
    x: Vec<Expr<'g>>,
    /// With the exact Hessian, the dynamics' multipliers (`$pi[i]`, one per solver state);
    /// empty otherwise.
    pi: Vec<Expr<'g>>,
}

impl<'g> Symbols<'g> {
    /// The symbols of `ocp`, and the new ones the lowering adds (`$` keeps them apart from
    /// the model's names).
    ///
    /// # Errors
    /// [`CodegenError::Empty`] for a model without states or controls.
    fn new(ocp: &Ocp<'g>, exact_hessian: bool) -> Result<Symbols<'g>, CodegenError> {
        let g: &'g Graph = match ocp.states.first().and_then(|v| v.symbols.first()) {
            Some(s) => s.graph(),
            None => return Err(CodegenError::Empty("state")),
        };
        let (xm, u, p) = (ocp.x(), ocp.u(), ocp.p());
        if u.is_empty() {
            return Err(CodegenError::Empty("control"));
        }
        let u_last: Vec<Expr<'g>> = if ocp.cost.input_rate.is_some() {
            (0..u.len())
                .map(|i| g.symbol(&format!("$u_last[{i}]")))
                .collect()
        } else {
            Vec::new()
        };
        let mut x: Vec<Expr<'g>> = xm.to_vec();
        x.extend(u_last.iter().copied());
        // The dynamics multipliers of the Lagrangian Hessian, made only when it is.
        let pi: Vec<Expr<'g>> = if exact_hessian {
            (0..x.len())
                .map(|i| g.symbol(&format!("$pi[{i}]")))
                .collect()
        } else {
            Vec::new()
        };
        Ok(Symbols {
            g,
            xm,
            u,
            p,
            u_last,
            x,
            pi,
        })
    }

    /// A builder over the solver's states, the controls, the parameters and the
    /// multipliers.
    fn builder(&self) -> Builder<'g> {
        Builder {
            g: self.g,
            x: self.x.clone(),
            u: self.u.to_vec(),
            p: self.p.to_vec(),
            pi: self.pi.clone(),
            mu: Vec::new(),
        }
    }

    /// A builder over the model's states (for the integrator).
    fn model_builder(&self) -> Builder<'g> {
        Builder {
            g: self.g,
            x: self.xm.to_vec(),
            u: self.u.to_vec(),
            p: self.p.to_vec(),
            pi: Vec::new(),
            mu: Vec::new(),
        }
    }
}
