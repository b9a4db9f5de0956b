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
//!   bounds and slack penalties (`0, 0` for a hard row).

use mpc_dsl::ocp::{Dynamics, Integrator, ParamKind, Stage, Variable};
use mpc_dsl::{DslError, Expr, Graph, Matrix, Ocp, Program, Vector};

use crate::error::CodegenError;

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
    /// `F`, `A`, `B`.
    pub dynamics: Function,
    /// `F` alone.
    pub dynamics_value: Function,
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
}

fn named(vars: &[Variable<'_>], per_stage: impl Fn(usize) -> bool) -> Vec<Named> {
    let mut off = 0;
    vars.iter()
        .enumerate()
        .map(|(i, v)| {
            let mut doc = v.description.clone().unwrap_or_default();
            if let Some(unit) = &v.unit {
                if !doc.is_empty() {
                    doc.push(' ');
                }
                doc.push_str(&format!("[{unit}]"));
            }
            let n = Named {
                name: v.name.clone(),
                offset: off,
                len: v.len(),
                scalar: v.scalar,
                doc,
                per_stage: per_stage(i),
            };
            off += v.len();
            n
        })
        .collect()
}

/// Stacks `blocks` of square weights into one block-diagonal matrix.
fn block_diag<'g>(g: &'g Graph, blocks: &[&Matrix<'g>]) -> Matrix<'g> {
    let n: usize = blocks.iter().map(|b| b.nrows()).sum();
    let mut data = vec![g.zero(); n * n];
    let mut off = 0;
    for b in blocks {
        for i in 0..b.nrows() {
            for j in 0..b.ncols() {
                data[(off + i) * n + off + j] = b[(i, j)];
            }
        }
        off += b.nrows();
    }
    Matrix::from_row_major(n, n, data).unwrap_or_else(|_| Matrix::zeros(g, n, n))
}

struct Builder<'g> {
    g: &'g Graph,
    x: Vec<Expr<'g>>,
    u: Vec<Expr<'g>>,
    p: Vec<Expr<'g>>,
    pi: Vec<Expr<'g>>,
}

impl<'g> Builder<'g> {
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

    /// `[F | S]` after one step of the integrator: the state and its sensitivity
    /// `S = d/d(x0, u) X`.
    fn rk4_substep(
        &self,
        f: &Vector<'g>,
        fx: &Matrix<'g>,
        fu: &Matrix<'g>,
        x: &Vector<'g>,
        s: &Matrix<'g>,
        dt: f64,
    ) -> Result<(Vector<'g>, Matrix<'g>), CodegenError> {
        let nx = self.x.len();
        // Evaluate f and the stage sensitivity K = f_x(X) S + [0 f_u(X)] at X.
        let at = |xs: &Vector<'g>, ss: &Matrix<'g>| -> Result<_, CodegenError> {
            let k = mpc_dsl::ocp::substitute(f, &self.x, xs)?;
            let fxv = mpc_dsl::ocp::substitute(fx.as_row_major(), &self.x, xs)?;
            let fuv = mpc_dsl::ocp::substitute(fu.as_row_major(), &self.x, xs)?;
            let fx_at = Matrix::from_row_major(nx, nx, fxv.into_vec())?;
            let prod = fx_at.matmul(ss)?;
            let nu = self.u.len();
            let mut data = prod.as_row_major().to_vec();
            for i in 0..nx {
                for j in 0..nu {
                    let e = &mut data[i * (nx + nu) + nx + j];
                    *e += fuv[i * nu + j];
                }
            }
            Ok((k, Matrix::from_row_major(nx, nx + nu, data)?))
        };
        let axpy = |a: &Matrix<'g>, b: &Matrix<'g>, h: f64| a.add(&b.scale(h));
        // The same operations, in the same order, as `mpc_dsl::models::rk4`.
        let (k1, d1) = at(x, s)?;
        let x2 = x.add(&k1.scale(dt / 2.0))?;
        let (k2, d2) = at(&x2, &axpy(s, &d1, dt / 2.0)?)?;
        let x3 = x.add(&k2.scale(dt / 2.0))?;
        let (k3, d3) = at(&x3, &axpy(s, &d2, dt / 2.0)?)?;
        let x4 = x.add(&k3.scale(dt))?;
        let (k4, d4) = at(&x4, &axpy(s, &d3, dt)?)?;
        let incr = k1.add(&k2.scale(2.0))?.add(&k3.scale(2.0))?.add(&k4)?;
        let xn = x.add(&incr.scale(dt / 6.0))?;
        let dincr = d1.add(&d2.scale(2.0))?.add(&d3.scale(2.0))?.add(&d4)?;
        let sn = axpy(s, &dincr, dt / 6.0)?;
        Ok((xn, sn))
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
pub fn lower_with<'g>(ocp: &Ocp<'g>, exact_hessian: bool) -> Result<Lowered, CodegenError> {
    ocp.validate().map_err(CodegenError::Invalid)?;
    let g: &Graph = match ocp.states.first() {
        Some(v) => match v.symbols.first() {
            Some(s) => s.graph(),
            None => return Err(CodegenError::Empty("state")),
        },
        None => return Err(CodegenError::Empty("state")),
    };
    let xm = ocp.x();
    let u = ocp.u();
    let p = ocp.p();
    let (nxm, nu) = (xm.len(), u.len());
    if nu == 0 {
        return Err(CodegenError::Empty("control"));
    }
    let rate = ocp.cost.input_rate.as_ref();
    let u_last: Vec<Expr<'_>> = if rate.is_some() {
        (0..nu)
            .map(|i| g.symbol(&format!("$u_last[{i}]")))
            .collect()
    } else {
        Vec::new()
    };
    let mut x: Vec<Expr<'_>> = xm.to_vec();
    x.extend(u_last.iter().copied());
    let nx = x.len();
    // The dynamics multipliers of the Lagrangian Hessian, made only when it is (`$` keeps
    // them apart from the model's names).
    let pi: Vec<Expr<'_>> = if exact_hessian {
        (0..nx).map(|i| g.symbol(&format!("$pi[{i}]"))).collect()
    } else {
        Vec::new()
    };
    let b = Builder {
        g,
        x: x.clone(),
        u: u.to_vec(),
        p: p.to_vec(),
        pi: pi.clone(),
    };
    let (n, dt) = (ocp.horizon.n, ocp.horizon.dt);

    // ---- dynamics with sensitivities ----------------------------------------------------
    let (fx_next, s, discretization) = {
        let bm = Builder {
            g,
            x: xm.to_vec(),
            u: u.to_vec(),
            p: p.to_vec(),
            pi: Vec::new(),
        };
        let mut wrt = xm.to_vec();
        wrt.extend(u.iter().copied());
        let ident = Matrix::identity(g, nxm);
        let mut s0 = vec![g.zero(); nxm * (nxm + nu)];
        for i in 0..nxm {
            for j in 0..nxm {
                s0[i * (nxm + nu) + j] = ident[(i, j)];
            }
        }
        let s0 = Matrix::from_row_major(nxm, nxm + nu, s0)?;
        match &ocp.dynamics {
            Dynamics::Discrete { x_next } => {
                let jac = g.jacobian(x_next, &wrt)?.to_dense();
                (x_next.clone(), jac, "discrete map".to_string())
            }
            Dynamics::Continuous { xdot, integrator } => {
                let fx = g.jacobian(xdot, &xm)?.to_dense();
                let fu = g.jacobian(xdot, &u)?.to_dense();
                match integrator {
                    Integrator::Euler => {
                        let xn = xm.add(&xdot.scale(dt))?;
                        let mut d = fx.as_row_major().to_vec();
                        let mut full = Vec::with_capacity(nxm * (nxm + nu));
                        for i in 0..nxm {
                            full.extend(d.drain(..nxm));
                            full.extend((0..nu).map(|j| fu[(i, j)]));
                        }
                        let dm = Matrix::from_row_major(nxm, nxm + nu, full)?;
                        (xn, s0.add(&dm.scale(dt))?, "explicit Euler".to_string())
                    }
                    Integrator::Rk4 { steps } => {
                        let steps = (*steps).max(1);
                        let h = dt / steps as f64;
                        let (mut xs, mut ss) = (xm.clone(), s0);
                        for _ in 0..steps {
                            let (a, c) = bm.rk4_substep(xdot, &fx, &fu, &xs, &ss, h)?;
                            xs = a;
                            ss = c;
                        }
                        (
                            xs,
                            ss,
                            format!("RK4, {steps} substep(s) with forward sensitivities"),
                        )
                    }
                }
            }
        }
    };
    let mut dyn_out = Vec::new();
    for (i, &e) in fx_next.iter().enumerate() {
        dyn_out.push((e, Target::Ret(i)));
    }
    for (i, &ul) in u.iter().enumerate() {
        if rate.is_some() {
            dyn_out.push((ul, Target::Ret(nxm + i)));
        }
    }
    for i in 0..nxm {
        for j in 0..nxm {
            dyn_out.push((s[(i, j)], Target::Mat("a", i, j)));
        }
        for j in 0..nu {
            dyn_out.push((s[(i, nxm + j)], Target::Mat("b", i, j)));
        }
    }
    if rate.is_some() {
        for i in 0..nu {
            dyn_out.push((g.one(), Target::Mat("b", nxm + i, i)));
        }
    }
    // `F` alone (the full SQP's merit function): the same expressions, without the
    // sensitivities, which the program then does not compute.
    let value_out: Vec<_> = dyn_out
        .iter()
        .filter(|(_, t)| matches!(t, Target::Ret(_)))
        .cloned()
        .collect();
    let dynamics = b.function("dynamics", &[Arg::X, Arg::U, Arg::P], dyn_out)?;
    let dynamics_value = b.function("dynamics value", &[Arg::X, Arg::U, Arg::P], value_out)?;
    // The dynamics' part of the Lagrangian Hessian, `sum_i pi_i d2F_i/d(x, u)2`, for the full
    // SQP: the symbolic Hessian of the scalar `pi' F` (the input-rate states' `F` is `u`,
    // linear, so only the model states' multipliers enter).
    let dynamics_hessian = if exact_hessian {
        let mut lagrangian = g.zero();
        for (&e, &m) in fx_next.iter().zip(&pi) {
            lagrangian += m * e;
        }
        let mut wrt = x.clone();
        wrt.extend(u.iter().copied());
        let hess = g.hessian(lagrangian, &wrt)?;
        let mut out = Vec::with_capacity(hess.nnz());
        for (i, j, e) in hess.iter() {
            let target = match (i < nx, j < nx) {
                (true, true) => Target::Mat("hxx", i, j),
                (false, true) => Target::Mat("hux", i - nx, j),
                (false, false) => Target::Mat("huu", i - nx, j - nx),
                // The upper right block is `hux` transposed.
                (true, false) => continue,
            };
            out.push((e, target));
        }
        Some(b.function("dynamics Hessian", &[Arg::X, Arg::U, Arg::P, Arg::Pi], out)?)
    } else {
        None
    };

    // ---- residuals and weights ----------------------------------------------------------
    let mut y: Vec<Expr<'_>> = Vec::new();
    let mut w_blocks: Vec<Matrix<'_>> = Vec::new();
    let mut rows = Vec::new();
    let mut push = |y: &mut Vec<Expr<'g>>, r: &[Expr<'g>], what: String| {
        rows.push(RowBlock {
            start: y.len(),
            len: r.len(),
            what,
        });
        y.extend_from_slice(r);
    };
    let c = &ocp.cost;
    if let Some(t) = &c.state {
        push(&mut y, &xm.sub(&t.reference)?, "x - xref (Q)".into());
        w_blocks.push(t.weight.clone());
    }
    if let Some(t) = &c.control {
        push(&mut y, &u.sub(&t.reference)?, "u - uref (R)".into());
        w_blocks.push(t.weight.clone());
    }
    for r in c.residuals.iter().filter(|r| r.stage == Stage::Path) {
        push(&mut y, &r.residual, format!("residual `{}` (W)", r.name));
        w_blocks.push(r.weight.clone());
    }
    if let Some(r) = rate {
        push(
            &mut y,
            &u.sub(&u_last)?,
            "u - u_last: input rate (u_last = u_{-1} at stage 0)".into(),
        );
        w_blocks.push(r.weight.clone());
    }
    let residual_rows = rows;
    let mut yn: Vec<Expr<'_>> = Vec::new();
    let mut wn_blocks: Vec<Matrix<'_>> = Vec::new();
    let mut rows_n = Vec::new();
    if let Some(t) = &c.terminal {
        rows_n.push(RowBlock {
            start: 0,
            len: nxm,
            what: "x_N - xref_N (P)".into(),
        });
        yn.extend(xm.sub(&t.reference)?);
        wn_blocks.push(t.weight.clone());
    }
    for r in c.residuals.iter().filter(|r| r.stage == Stage::Terminal) {
        rows_n.push(RowBlock {
            start: yn.len(),
            len: r.residual.len(),
            what: format!("terminal residual `{}` (W)", r.name),
        });
        yn.extend(r.residual.iter().copied());
        wn_blocks.push(r.weight.clone());
    }
    let (ny, nyn) = (y.len(), yn.len());
    let mut wrt = x.clone();
    wrt.extend(u.iter().copied());
    let mut constant_residual_jacobians = true;
    let residual = {
        let jac = g.jacobian(&y, &wrt)?;
        constant_residual_jacobians &= jac.iter().all(|(_, _, e)| e.as_constant().is_some());
        let mut out: Vec<_> = y
            .iter()
            .enumerate()
            .map(|(i, &e)| (e, Target::Ret(i)))
            .collect();
        for (i, j, e) in jac.iter() {
            let t = if j < nx {
                Target::Mat("jx", i, j)
            } else {
                Target::Mat("ju", i, j - nx)
            };
            out.push((e, t));
        }
        b.function("residual", &[Arg::X, Arg::U, Arg::P], out)?
    };
    let constant_stage_residual_jacobians = constant_residual_jacobians;
    let terminal_residual = {
        let jac = g.jacobian(&yn, &x)?;
        constant_residual_jacobians &= jac.iter().all(|(_, _, e)| e.as_constant().is_some());
        let mut out: Vec<_> = yn
            .iter()
            .enumerate()
            .map(|(i, &e)| (e, Target::Ret(i)))
            .collect();
        out.extend(jac.iter().map(|(i, j, e)| (e, Target::Mat("jx", i, j))));
        b.function("terminal residual", &[Arg::X, Arg::P], out)?
    };
    let w = block_diag(g, &w_blocks.iter().collect::<Vec<_>>());
    let wn = block_diag(g, &wn_blocks.iter().collect::<Vec<_>>());
    let mut wout = Vec::new();
    for i in 0..ny {
        for j in 0..ny {
            wout.push((w[(i, j)], Target::Mat("w", i, j)));
        }
    }
    for i in 0..nyn {
        for j in 0..nyn {
            wout.push((wn[(i, j)], Target::Mat("wn", i, j)));
        }
    }
    let global: Vec<Expr<'_>> = ocp
        .parameters
        .iter()
        .filter(|q| q.kind == ParamKind::Global)
        .flat_map(|q| q.var.symbols.iter().copied())
        .collect();
    // Weights may only use global parameters: compile over those to get a clear error.
    let bw = Builder {
        g,
        x: Vec::new(),
        u: Vec::new(),
        p: global,
        pi: Vec::new(),
    };
    bw.function("weights", &[Arg::P], wout.clone())
        .map_err(|e| match e {
            CodegenError::UnexpectedSymbol { symbol, .. } => CodegenError::UnexpectedSymbol {
                function: "weights",
                symbol,
                allowed: "constants and global parameters".into(),
            },
            other => other,
        })?;
    let weights = b.function("weights", &[Arg::P], wout.clone())?;

    // ---- constraints --------------------------------------------------------------------
    let mut h = Vec::new();
    let mut hn = Vec::new();
    let (mut lg, mut ug, mut l1, mut l2) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut lgn, mut ugn, mut l1n, mut l2n) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut crows, mut crows_n) = (Vec::new(), Vec::new());
    for k in &ocp.constraints {
        let (pen1, pen2) = k.soft.map_or((0.0, 0.0), |s| (s.l1, s.l2));
        let what = match k.soft {
            Some(s) => format!("`{}` (soft, l1 = {:?}, l2 = {:?})", k.name, s.l1, s.l2),
            None => format!("`{}`", k.name),
        };
        let (hv, lo, hi, p1, p2, rws) = match k.stage {
            Stage::Path => (&mut h, &mut lg, &mut ug, &mut l1, &mut l2, &mut crows),
            Stage::Terminal => (
                &mut hn,
                &mut lgn,
                &mut ugn,
                &mut l1n,
                &mut l2n,
                &mut crows_n,
            ),
        };
        rws.push(RowBlock {
            start: hv.len(),
            len: k.expr.len(),
            what,
        });
        hv.extend(k.expr.iter().copied());
        lo.extend_from_slice(&k.lower);
        hi.extend_from_slice(&k.upper);
        p1.extend(std::iter::repeat_n(pen1, k.expr.len()));
        p2.extend(std::iter::repeat_n(pen2, k.expr.len()));
    }
    let (ng, ngn) = (h.len(), hn.len());
    let constraints = if ng > 0 {
        let jac = g.jacobian(&h, &wrt)?;
        let mut out: Vec<_> = h
            .iter()
            .enumerate()
            .map(|(i, &e)| (e, Target::Ret(i)))
            .collect();
        for (i, j, e) in jac.iter() {
            let t = if j < nx {
                Target::Mat("cx", i, j)
            } else {
                Target::Mat("cu", i, j - nx)
            };
            out.push((e, t));
        }
        Some(b.function("constraints", &[Arg::X, Arg::U, Arg::P], out)?)
    } else {
        None
    };
    let terminal_constraints = if ngn > 0 {
        let jac = g.jacobian(&hn, &x)?;
        let mut out: Vec<_> = hn
            .iter()
            .enumerate()
            .map(|(i, &e)| (e, Target::Ret(i)))
            .collect();
        out.extend(jac.iter().map(|(i, j, e)| (e, Target::Mat("cx", i, j))));
        Some(b.function("terminal constraints", &[Arg::X, Arg::P], out)?)
    } else {
        None
    };

    // ---- constant data ------------------------------------------------------------------
    let mut lbx = ocp.state_bounds.lower.clone();
    let mut ubx = ocp.state_bounds.upper.clone();
    lbx.extend(std::iter::repeat_n(f64::NEG_INFINITY, u_last.len()));
    ubx.extend(std::iter::repeat_n(f64::INFINITY, u_last.len()));
    let mut x_guess = ocp.x_guess();
    let u_guess = ocp.u_guess();
    if rate.is_some() {
        x_guess.extend_from_slice(&u_guess);
    }
    let u_prev = match rate {
        Some(r) => {
            let mut idx = Vec::new();
            for e in r.prev.iter() {
                match p.iter().position(|s| s == e) {
                    Some(i) => idx.push(i),
                    None => {
                        return Err(CodegenError::Unsupported(
                            "the input-rate term's `prev` must be parameter entries".into(),
                        ));
                    }
                }
            }
            Some(idx)
        }
        None => None,
    };
    // Whether the weights read the input-rate term's u_{-1}: if not, the automatic u_prev
    // update after each feedback need not re-evaluate them.
    let weights_use_u_prev = match &u_prev {
        Some(idx) => {
            let without: Vec<Expr<'_>> = ocp
                .parameters
                .iter()
                .filter(|q| q.kind == ParamKind::Global)
                .flat_map(|q| q.var.symbols.iter().copied())
                .filter(|s| !idx.iter().any(|&i| p.get(i) == Some(s)))
                .collect();
            let bu = Builder {
                g,
                x: Vec::new(),
                u: Vec::new(),
                p: without,
                pi: Vec::new(),
            };
            bu.function("weights", &[Arg::P], wout).is_err()
        }
        None => false,
    };
    Ok(Lowered {
        name: ocp.name.clone(),
        weights_use_u_prev,
        nx_model: nxm,
        nx,
        nu,
        np: p.len(),
        ny,
        nyn,
        ng,
        ngn,
        n,
        dt,
        discretization,
        dynamics,
        dynamics_value,
        dynamics_hessian,
        residual,
        terminal_residual,
        constant_residual_jacobians,
        constant_stage_residual_jacobians,
        constraints,
        terminal_constraints,
        weights,
        residual_rows,
        terminal_residual_rows: rows_n,
        constraint_rows: crows,
        terminal_constraint_rows: crows_n,
        lbx,
        ubx,
        lbu: ocp.control_bounds.lower.clone(),
        ubu: ocp.control_bounds.upper.clone(),
        lg,
        ug,
        lgn,
        ugn,
        l1,
        l2,
        l1n,
        l2n,
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
    })
}
