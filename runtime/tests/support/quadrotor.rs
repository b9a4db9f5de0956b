//! The quadrotor rate model of QR-bench (`docs/bench.md`) written by hand: the ODE,
//! its Jacobians, and one RK4 step with exact forward sensitivities.

use mpc_runtime::{Model, Real, Rti};
use nalgebra::{SMatrix, SVector};

pub const NX: usize = 10;
pub const NU: usize = 4;
pub const NY: usize = 14;
pub const G: f64 = 9.81;

/// One RK4 step of length `dt` per shooting interval; residual y = (x, u), terminal y = x.
/// `CONST_J`: whether it declares its (constant) residual Jacobians constant
/// (`Model::CONSTANT_RESIDUAL_JACOBIANS`); the default keeps the solver's general path.
/// `CURVED_N`: the terminal residual is `x_i + x_i^2 / 50` instead (nonlinear, so only the
/// stage Jacobians are constant: `Model::CONSTANT_STAGE_RESIDUAL_JACOBIANS` is `CONST_J`).
#[derive(Clone, Copy, Debug)]
pub struct Quadrotor<T, const CONST_J: bool = false, const CURVED_N: bool = false> {
    pub dt: T,
}

/// `xdot = f(x, u)` with `fx = df/dx`, `fu = df/du`.
pub fn ode<T: Real>(
    x: &SVector<T, NX>,
    u: &SVector<T, NU>,
    fx: &mut SMatrix<T, NX, NX>,
    fu: &mut SMatrix<T, NX, NU>,
) -> SVector<T, NX> {
    let h = T::lit(0.5);
    let two = T::lit(2.0);
    let (qw, qx, qy, qz) = (x[3], x[4], x[5], x[6]);
    let (c, wx, wy, wz) = (u[0], u[1], u[2], u[3]);
    let mut f = SVector::<T, NX>::zeros();
    f[0] = x[7];
    f[1] = x[8];
    f[2] = x[9];
    f[3] = h * (-qx * wx - qy * wy - qz * wz);
    f[4] = h * (qw * wx + qy * wz - qz * wy);
    f[5] = h * (qw * wy - qx * wz + qz * wx);
    f[6] = h * (qw * wz + qx * wy - qy * wx);
    f[7] = two * (qw * qy + qx * qz) * c;
    f[8] = two * (qy * qz - qw * qx) * c;
    f[9] = (T::ONE - two * (qx * qx + qy * qy)) * c - T::lit(G);
    fx.fill(T::ZERO);
    fu.fill(T::ZERO);
    for i in 0..3 {
        fx[(i, 7 + i)] = T::ONE;
    }
    let omega = [
        [T::ZERO, -wx, -wy, -wz],
        [wx, T::ZERO, wz, -wy],
        [wy, -wz, T::ZERO, wx],
        [wz, wy, -wx, T::ZERO],
    ];
    let xi = [[-qx, -qy, -qz], [qw, -qz, qy], [qz, qw, -qx], [-qy, qx, qw]];
    for i in 0..4 {
        for j in 0..4 {
            fx[(3 + i, 3 + j)] = h * omega[i][j];
        }
        for j in 0..3 {
            fu[(3 + i, 1 + j)] = h * xi[i][j];
        }
    }
    let dv = [
        [qy, qz, qw, qx],
        [-qx, -qw, qz, qy],
        [T::ZERO, -two * qx, -two * qy, T::ZERO],
    ];
    for i in 0..3 {
        for j in 0..4 {
            fx[(7 + i, 3 + j)] = two * c * dv[i][j];
        }
    }
    fu[(7, 0)] = two * (qw * qy + qx * qz);
    fu[(8, 0)] = two * (qy * qz - qw * qx);
    fu[(9, 0)] = T::ONE - two * (qx * qx + qy * qy);
    f
}

/// One classical RK4 step with its sensitivities `A = dx+/dx`, `B = dx+/du`.
pub fn rk4<T: Real>(
    x: &SVector<T, NX>,
    u: &SVector<T, NU>,
    dt: T,
    a: &mut SMatrix<T, NX, NX>,
    b: &mut SMatrix<T, NX, NU>,
) -> SVector<T, NX> {
    let mut fx = SMatrix::<T, NX, NX>::zeros();
    let mut fu = SMatrix::<T, NX, NU>::zeros();
    let half = dt * T::lit(0.5);
    let id = SMatrix::<T, NX, NX>::identity();
    let k1 = ode(x, u, &mut fx, &mut fu);
    let (k1x, k1u) = (fx, fu);
    let k2 = ode(&(x + k1 * half), u, &mut fx, &mut fu);
    let (k2x, k2u) = (fx * (id + k1x * half), fx * k1u * half + fu);
    let k3 = ode(&(x + k2 * half), u, &mut fx, &mut fu);
    let (k3x, k3u) = (fx * (id + k2x * half), fx * k2u * half + fu);
    let k4 = ode(&(x + k3 * dt), u, &mut fx, &mut fu);
    let (k4x, k4u) = (fx * (id + k3x * dt), fx * k3u * dt + fu);
    let sixth = dt / T::lit(6.0);
    let two = T::lit(2.0);
    *a = id + (k1x + k2x * two + k3x * two + k4x) * sixth;
    *b = (k1u + k2u * two + k3u * two + k4u) * sixth;
    x + (k1 + k2 * two + k3 * two + k4) * sixth
}

/// The plant of the closed loop: the same ODE, RK4 with `substeps` steps over `dt`.
pub fn plant(
    x: &SVector<f64, NX>,
    u: &SVector<f64, NU>,
    dt: f64,
    substeps: usize,
) -> SVector<f64, NX> {
    let mut a = SMatrix::zeros();
    let mut b = SMatrix::zeros();
    let mut x = *x;
    for _ in 0..substeps {
        x = rk4(&x, u, dt / substeps as f64, &mut a, &mut b);
    }
    x
}

impl<T: Real, const CONST_J: bool, const CURVED_N: bool> Model<T, NX, NU, 0, NY, NX, 0, 0>
    for Quadrotor<T, CONST_J, CURVED_N>
{
    const CONSTANT_RESIDUAL_JACOBIANS: bool = CONST_J && !CURVED_N;
    const CONSTANT_STAGE_RESIDUAL_JACOBIANS: bool = CONST_J;

    fn dynamics(
        &self,
        x: &SVector<T, NX>,
        u: &SVector<T, NU>,
        _p: &SVector<T, 0>,
        a: &mut SMatrix<T, NX, NX>,
        b: &mut SMatrix<T, NX, NU>,
    ) -> SVector<T, NX> {
        rk4(x, u, self.dt, a, b)
    }

    fn residual(
        &self,
        x: &SVector<T, NX>,
        u: &SVector<T, NU>,
        _p: &SVector<T, 0>,
        jx: &mut SMatrix<T, NY, NX>,
        ju: &mut SMatrix<T, NY, NU>,
    ) -> SVector<T, NY> {
        jx.fill(T::ZERO);
        ju.fill(T::ZERO);
        for i in 0..NX {
            jx[(i, i)] = T::ONE;
        }
        for i in 0..NU {
            ju[(NX + i, i)] = T::ONE;
        }
        SVector::from_fn(|i, _| if i < NX { x[i] } else { u[i - NX] })
    }

    fn terminal_residual(
        &self,
        x: &SVector<T, NX>,
        _p: &SVector<T, 0>,
        jx: &mut SMatrix<T, NX, NX>,
    ) -> SVector<T, NX> {
        *jx = SMatrix::identity();
        if CURVED_N {
            let c = T::lit(0.02);
            for i in 0..NX {
                jx[(i, i)] = T::ONE + c * T::lit(2.0) * x[i];
            }
            return x + x.component_mul(x) * c;
        }
        *x
    }
}

/// QR-bench cost and bounds.
pub fn q_diag() -> [f64; NX] {
    [100.0, 100.0, 100.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0, 1.0]
}
pub const R_DIAG: [f64; NU] = [0.5, 1.0, 1.0, 1.0];
pub const X_REF: [f64; NX] = [4.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
pub const U_REF: [f64; NU] = [G, 0.0, 0.0, 0.0];
pub const X0: [f64; NX] = [0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
pub const U_LO: [f64; NU] = [0.0, -20.0, -20.0, -6.0];
pub const U_HI: [f64; NU] = [20.0, 20.0, 20.0, 6.0];

/// The RTI solver of QR-bench with horizon `N`, in precision `T`; `NC = N` gives it storage
/// for condensing (`NC = 0`: the Riccati recursion only).
pub type QrSolver<
    T,
    const N: usize,
    const NC: usize = 0,
    const CONST_J: bool = false,
    const NH: usize = N,
> = Rti<T, Quadrotor<T, CONST_J>, NX, NU, 0, NY, NX, 0, 0, N, NC, NX, N, NH>;

/// A QR-bench solver in `f64` (Riccati recursion); see [`qrbench_in`].
pub fn qrbench<const N: usize>(dt: f64) -> Box<QrSolver<f64, N>> {
    qrbench_in::<f64, N, 0>(dt)
}

/// The QP that the QR-bench closed loop (the f64 solver of [`qrbench`] from `X0`, flying
/// [`plant`]) prepares at step `k`, with `x0` the measured state's offset from the first
/// stage, as the feedback would solve it.
pub fn closed_loop_qp<const N: usize>(
    dt: f64,
    k: usize,
) -> mpc_runtime::OcpQp<f64, NX, NU, 0, 0, N> {
    let mut s = qrbench::<N>(dt);
    let mut x = SVector::from(X0);
    for _ in 0..k {
        s.prepare();
        let (u, _) = s.feedback(&x);
        x = plant(&x, &u, dt, 10);
    }
    s.prepare();
    let mut qp = *s.qp();
    qp.x0 = x - s.state(0).copied().unwrap_or(x);
    qp
}

/// A QR-bench solver: weights `W = diag(Q, R)`, `W_N = 5 Q`, the hover reference at (4, 0, 2)
/// on every stage, the control bounds, and the first guess `x_k = x0`, `u_k = 0`.
pub fn qrbench_in<T: Real, const N: usize, const NC: usize>(dt: f64) -> Box<QrSolver<T, N, NC>> {
    let mut s = Box::new(QrSolver::<T, N, NC>::new(Quadrotor { dt: T::lit(dt) }));
    configure(&mut s);
    s
}

/// [`qrbench_in`] from [`Rti::unconfigured`](mpc_runtime::Rti::unconfigured) (every field
/// zero): the default settings, then the same configuration.
pub fn qrbench_unconfigured<T: Real, const N: usize, const NC: usize>(
    dt: f64,
) -> Box<QrSolver<T, N, NC>> {
    let mut s = Box::new(QrSolver::<T, N, NC>::unconfigured(Quadrotor {
        dt: T::lit(dt),
    }));
    s.settings = mpc_runtime::RtiSettings::DEFAULT;
    configure(&mut s);
    s
}

/// [`qrbench_in`] in f64 with the model declaring its residual Jacobians constant.
pub fn qrbench_constant_jacobians<const N: usize>(dt: f64) -> Box<QrSolver<f64, N, 0, true>> {
    let mut s = Box::new(QrSolver::<f64, N, 0, true>::new(Quadrotor { dt }));
    configure(&mut s);
    s
}

/// [`qrbench_constant_jacobians`] with one Hessian for all stages in its QP (`NH = 1`).
pub fn qrbench_one_hessian<const N: usize>(dt: f64) -> Box<QrSolver<f64, N, 0, true, 1>> {
    let mut s = Box::new(QrSolver::<f64, N, 0, true, 1>::new(Quadrotor { dt }));
    configure(&mut s);
    s
}

/// [`qrbench_in`] in f64 with the curved terminal residual (`CURVED_N`), declaring its
/// stage residual Jacobians constant (`CONST_J`) and one stage Hessian (`NH = 1`), or not
/// (the solver's general path, `NH = N`).
pub fn qrbench_curved_terminal<const N: usize, const CONST_J: bool, const NH: usize>(
    dt: f64,
) -> Box<Rti<f64, Quadrotor<f64, CONST_J, true>, NX, NU, 0, NY, NX, 0, 0, N, 0, NX, N, NH>> {
    let mut s = Box::new(Rti::new(Quadrotor { dt }));
    configure(&mut s);
    s
}

fn configure<
    T: Real,
    M: Model<T, NX, NU, 0, NY, NX, 0, 0>,
    const N: usize,
    const NC: usize,
    const NH: usize,
>(
    s: &mut Rti<T, M, NX, NU, 0, NY, NX, 0, 0, N, NC, NX, N, NH>,
) {
    let c = |v: f64| T::lit(v);
    let mut w = SMatrix::<T, NY, NY>::zeros();
    let mut wn = SMatrix::<T, NX, NX>::zeros();
    for (i, q) in q_diag().iter().enumerate() {
        w[(i, i)] = c(*q);
        wn[(i, i)] = c(5.0 * q);
    }
    for (i, r) in R_DIAG.iter().enumerate() {
        w[(NX + i, NX + i)] = c(*r);
    }
    s.set_weights(&w, &wn).expect("finite weights");
    let yref = SVector::<T, NY>::from_fn(|i, _| c(if i < NX { X_REF[i] } else { U_REF[i - NX] }));
    for k in 0..N {
        s.set_reference(k, &yref).expect("finite reference");
    }
    s.set_terminal_reference(&SVector::from_fn(|i, _| c(X_REF[i])))
        .expect("finite reference");
    let inf = SVector::<T, NX>::repeat(T::INF);
    s.set_bounds(
        &-inf,
        &inf,
        &SVector::from_fn(|i, _| c(U_LO[i])),
        &SVector::from_fn(|i, _| c(U_HI[i])),
    )
    .expect("bounds");
    s.set_guess(&SVector::from_fn(|i, _| c(X0[i])), &SVector::zeros())
        .expect("guess");
}
