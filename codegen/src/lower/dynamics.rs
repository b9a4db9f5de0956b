//! Lowering the dynamics: discretized with their sensitivities, the functions `dynamics`
//! and `dynamics value`, and the dynamics' Lagrangian Hessian.

use mpc_dsl::ocp::{Collocation, Dynamics, Integrator};
use mpc_dsl::{DslError, Graph, Matrix, Ocp, Vector};

use super::{Arg, Builder, Function, IrkStep, Symbols, Target};
use crate::error::CodegenError;

/// The model's dynamics over one interval: `F` and its sensitivity.
pub(super) struct Discretized<'g> {
    /// `F(x, u, p)` of the model states.
    pub(super) x_next: Vector<'g>,
    /// `[dF/dx dF/du]`, `nx_model` by `nx_model + nu`.
    pub(super) s: Matrix<'g>,
    /// The discretization, in words.
    pub(super) how: String,
}

/// Discretizes the dynamics with their sensitivities: a discrete map is differentiated;
/// an ODE is integrated together with its forward sensitivities ([`euler`], [`rk4`]).
pub(super) fn discretize<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
) -> Result<Discretized<'g>, CodegenError> {
    let (g, xm, u) = (v.g, &v.xm, &v.u);
    let mut wrt = xm.to_vec();
    wrt.extend(u.iter().copied());
    let s0 = initial_sensitivity(g, xm.len(), u.len())?;
    match &ocp.dynamics {
        Dynamics::Discrete { x_next } => Ok(Discretized {
            s: g.jacobian(x_next, &wrt)?.to_dense(),
            x_next: x_next.clone(),
            how: "discrete map".to_string(),
        }),
        Dynamics::Continuous { xdot, integrator } => {
            let fx = g.jacobian(xdot, xm)?.to_dense();
            let fu = g.jacobian(xdot, u)?.to_dense();
            match integrator {
                Integrator::Euler => euler(v, xdot, &fx, &fu, s0, ocp.horizon.dt),
                Integrator::Rk4 { steps } => rk4(v, xdot, &fx, &fu, s0, (*steps, ocp.horizon.dt)),
                // Lowered by `irk_functions`: the step is emitted, not an expression.
                Integrator::Irk { .. } => Err(CodegenError::Dsl(DslError::NoClosedForm {
                    what: "the discrete map of an irk (implicit) integrator",
                })),
            }
        }
    }
}

/// The settings of the model's implicit integrator, if it has one.
pub(super) fn irk_of(ocp: &Ocp<'_>) -> Option<IrkStep> {
    match ocp.dynamics {
        Dynamics::Continuous {
            integrator:
                Integrator::Irk {
                    stages,
                    steps,
                    newton,
                    collocation,
                },
            ..
        } => Some(IrkStep {
            stages,
            steps,
            newton,
            radau: collocation == Collocation::RadauIia,
        }),
        _ => None,
    }
}

/// The functions of an implicit step: the right-hand side `f(x, u, p)` over the model's
/// states with `fx = df/dx` and `fu = df/du` (what the emitted Newton iteration and
/// sensitivity solve evaluate at the stage points), `f` alone, no Hessian, and the
/// discretization in words. The step itself is emitted around them (`emit/implicit.rs`).
#[allow(clippy::type_complexity)]
pub(super) fn irk_functions<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
    step: IrkStep,
) -> Result<(Function, Function, Option<Function>, String), CodegenError> {
    let xdot = ocp.dynamics.exprs();
    let b = v.model_builder();
    let (rhs, _) = b.with_jacobian("dynamics right-hand side", xdot, "fx", Some("fu"))?;
    let value_out = (xdot.iter().enumerate())
        .map(|(i, &e)| (e, Target::Ret(i)))
        .collect();
    let args = [Arg::X, Arg::U, Arg::P];
    let value = b.function("dynamics right-hand side", &args, value_out)?;
    let how = format!(
        "{} IRK, {} stage(s), {} substep(s), {} Newton iteration(s) each, sensitivities by \
         the implicit function theorem",
        if step.radau {
            "Radau IIA"
        } else {
            "Gauss-Legendre"
        },
        step.stages,
        step.steps,
        step.newton
    );
    Ok((rhs, value, None, how))
}

/// The sensitivity `[I 0]` of the initial state over `(x0, u)`.
pub(super) fn initial_sensitivity<'g>(
    g: &'g Graph,
    nxm: usize,
    nu: usize,
) -> Result<Matrix<'g>, CodegenError> {
    let ident = Matrix::identity(g, nxm);
    let mut s0 = vec![g.zero(); nxm * (nxm + nu)];
    for i in 0..nxm {
        for j in 0..nxm {
            s0[i * (nxm + nu) + j] = ident[(i, j)];
        }
    }
    Ok(Matrix::from_row_major(nxm, nxm + nu, s0)?)
}

/// One explicit Euler step of `xdot` over `dt`, with its sensitivity `s0 + dt [f_x f_u]`.
pub(super) fn euler<'g>(
    v: &Symbols<'g>,
    xdot: &Vector<'g>,
    fx: &Matrix<'g>,
    fu: &Matrix<'g>,
    s0: Matrix<'g>,
    dt: f64,
) -> Result<Discretized<'g>, CodegenError> {
    let (nxm, nu) = (v.xm.len(), v.u.len());
    let xn = v.xm.add(&xdot.scale(dt))?;
    let mut d = fx.as_row_major().to_vec();
    let mut full = Vec::with_capacity(nxm * (nxm + nu));
    for i in 0..nxm {
        full.extend(d.drain(..nxm));
        full.extend((0..nu).map(|j| fu[(i, j)]));
    }
    let dm = Matrix::from_row_major(nxm, nxm + nu, full)?;
    Ok(Discretized {
        x_next: xn,
        s: s0.add(&dm.scale(dt))?,
        how: "explicit Euler".to_string(),
    })
}

/// `steps` RK4 substeps of `xdot` over `dt`, each with its forward sensitivities
/// ([`Builder::rk4_substep`]).
pub(super) fn rk4<'g>(
    v: &Symbols<'g>,
    xdot: &Vector<'g>,
    fx: &Matrix<'g>,
    fu: &Matrix<'g>,
    s0: Matrix<'g>,
    (steps, dt): (usize, f64),
) -> Result<Discretized<'g>, CodegenError> {
    let bm = v.model_builder();
    let steps = steps.max(1);
    let h = dt / steps as f64;
    let (mut xs, mut ss) = (v.xm.clone(), s0);
    for _ in 0..steps {
        let (a, c) = bm.rk4_substep(xdot, fx, fu, &xs, &ss, h)?;
        xs = a;
        ss = c;
    }
    Ok(Discretized {
        x_next: xs,
        s: ss,
        how: format!("RK4, {steps} substep(s) with forward sensitivities"),
    })
}

/// `dynamics` (`F`, `a = dF/dx`, `b = dF/du` of the solver's states: with an input-rate
/// cost, `u_last+ = u`) and `dynamics value` (`F` alone, the full SQP's merit function: the
/// same expressions, without the sensitivities, which the program then does not compute).
pub(super) fn dynamics_functions<'g>(
    ocp: &Ocp<'g>,
    v: &Symbols<'g>,
    b: &Builder<'g>,
    map: &Discretized<'g>,
) -> Result<(Function, Function), CodegenError> {
    let (nxm, nu) = (v.xm.len(), v.u.len());
    let rate = ocp.cost.input_rate.is_some();
    let mut out = Vec::new();
    for (i, &e) in map.x_next.iter().enumerate() {
        out.push((e, Target::Ret(i)));
    }
    for (i, &ul) in v.u.iter().enumerate() {
        if rate {
            out.push((ul, Target::Ret(nxm + i)));
        }
    }
    for i in 0..nxm {
        for j in 0..nxm {
            out.push((map.s[(i, j)], Target::Mat("a", i, j)));
        }
        for j in 0..nu {
            out.push((map.s[(i, nxm + j)], Target::Mat("b", i, j)));
        }
    }
    if rate {
        for i in 0..nu {
            out.push((v.g.one(), Target::Mat("b", nxm + i, i)));
        }
    }
    let value_out: Vec<_> = (out.iter())
        .filter(|(_, t)| matches!(t, Target::Ret(_)))
        .cloned()
        .collect();
    let args = [Arg::X, Arg::U, Arg::P];
    let dynamics = b.function("dynamics", &args, out)?;
    let dynamics_value = b.function("dynamics value", &args, value_out)?;
    Ok((dynamics, dynamics_value))
}

/// The dynamics' part of the Lagrangian Hessian, `sum_i pi_i d2F_i/d(x, u)2`, for the full
/// SQP: the symbolic Hessian of the scalar `pi' F` (the input-rate states' `F` is `u`,
/// linear, so only the model states' multipliers enter), as `hxx`, `hux` and `huu`.
pub(super) fn dynamics_hessian<'g>(
    v: &Symbols<'g>,
    b: &Builder<'g>,
    x_next: &Vector<'g>,
) -> Result<Function, CodegenError> {
    let mut lagrangian = v.g.zero();
    for (&e, &m) in x_next.iter().zip(&v.pi) {
        lagrangian += m * e;
    }
    let mut wrt = v.x.clone();
    wrt.extend(v.u.iter().copied());
    let out = super::general_cost::hessian_targets(v, lagrangian, &wrt)?;
    b.function("dynamics Hessian", &[Arg::X, Arg::U, Arg::P, Arg::Pi], out)
}

impl<'g> Builder<'g> {
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
