//! Test support: random OCP-QPs and an independent reference solution by clarabel on the QP
//! written out in full sparse form.

#![allow(dead_code)]

pub mod quadrotor;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use mpc_runtime::OcpQp;
use nalgebra::{SMatrix, SVector};

/// xorshift64*: deterministic test data from a seed.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed | 1)
    }
    pub fn next(&mut self) -> f64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        ((x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64) / ((1u64 << 53) as f64)
    }
    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
    pub fn mat<const R: usize, const C: usize>(&mut self, s: f64) -> SMatrix<f64, R, C> {
        SMatrix::from_fn(|_, _| self.uniform(-s, s))
    }
    pub fn vec<const R: usize>(&mut self, s: f64) -> SVector<f64, R> {
        SVector::from_fn(|_, _| self.uniform(-s, s))
    }
    pub fn chance(&mut self, p: f64) -> bool {
        self.next() < p
    }
}

fn psd<const R: usize>(rng: &mut Rng, eps: f64) -> SMatrix<f64, R, R> {
    let m: SMatrix<f64, R, R> = rng.mat(1.0);
    m.transpose() * m + SMatrix::<f64, R, R>::identity() * eps
}

/// A random feasible OCP-QP: a random trajectory is generated first and every bound is placed
/// around it, so it is feasible; strong random gradients push the optimum onto bounds.
pub fn random_qp<
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
>(
    seed: u64,
) -> OcpQp<f64, NX, NU, NG, NGN, N> {
    random_qp_with_witness(seed).0
}

/// [`random_qp`] and the feasible control sequence its bounds were placed around.
pub fn random_qp_with_witness<
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
>(
    seed: u64,
) -> (OcpQp<f64, NX, NU, NG, NGN, N>, Vec<SVector<f64, NU>>) {
    let mut witness = Vec::new();
    let mut rng = Rng::new(seed);
    let mut qp = OcpQp::<f64, NX, NU, NG, NGN, N>::NEW;
    qp.x0 = rng.vec(1.0);
    let mut x = qp.x0;
    for k in 0..N {
        let s = &mut qp.stages[k];
        // A convex stage Hessian [Q S'; S R] = M'M + diag(eps), split into blocks; 30 % of the
        // stages have no state cost at all (singular Hessians happen, e.g. no cost on a state).
        if rng.chance(0.3) {
            s.q = SMatrix::zeros();
            s.s = SMatrix::zeros();
            s.r = psd(&mut rng, 0.1);
        } else {
            let m: SMatrix<f64, NU, NU> = rng.mat(1.0);
            let mx: SMatrix<f64, NX, NX> = rng.mat(1.0);
            let coupling: SMatrix<f64, NX, NU> = rng.mat(0.3);
            // rows [mx coupling; 0 m]: H = [mx'mx, mx'coupling; coupling'mx, coupling'coupling + m'm]
            s.q = mx.transpose() * mx + SMatrix::<f64, NX, NX>::identity() * 1e-2;
            s.s = coupling.transpose() * mx;
            s.r = coupling.transpose() * coupling
                + m.transpose() * m
                + SMatrix::<f64, NU, NU>::identity() * 0.1;
        }
        s.gx = rng.vec(3.0);
        s.gu = rng.vec(3.0);
        // Dynamics like a discretized system: near identity, scaled to infinity norm <= 1.1 so
        // that 30 stages do not blow states up by orders of magnitude.
        let a: SMatrix<f64, NX, NX> = SMatrix::identity() + rng.mat::<NX, NX>(0.3);
        let norm = (0..NX).map(|i| a.row(i).abs().sum()).fold(0.0, f64::max);
        s.a = a * (1.1 / norm.max(1.1));
        s.b = rng.mat(1.0);
        s.f = rng.vec(0.2);
        let u: SVector<f64, NU> = rng.vec(1.0);
        witness.push(u);
        for i in 0..NU {
            if rng.chance(0.8) {
                s.lbu[i] = u[i] - rng.uniform(0.0, 0.5);
            }
            if rng.chance(0.8) {
                s.ubu[i] = u[i] + rng.uniform(0.0, 0.5);
            }
        }
        if k > 0 {
            for i in 0..NX {
                if rng.chance(0.3) {
                    s.lbx[i] = x[i] - rng.uniform(0.0, 1.0);
                }
                if rng.chance(0.3) {
                    s.ubx[i] = x[i] + rng.uniform(0.0, 1.0);
                }
            }
        }
        s.c = rng.mat(1.0);
        s.d = rng.mat(1.0);
        let g = s.c * x + s.d * u;
        for i in 0..NG {
            s.lg[i] = g[i] - rng.uniform(0.0, 0.5);
            s.ug[i] = g[i] + rng.uniform(0.0, 0.5);
        }
        x = s.a * x + s.b * u + s.f;
    }
    let t = &mut qp.terminal;
    t.q = psd(&mut rng, 1e-2);
    t.gx = rng.vec(3.0);
    for i in 0..NX {
        if rng.chance(0.3) {
            t.lbx[i] = x[i] - rng.uniform(0.0, 1.0);
            t.ubx[i] = x[i] + rng.uniform(0.0, 1.0);
        }
    }
    t.c = rng.mat(1.0);
    let g = t.c * x;
    for i in 0..NGN {
        t.lg[i] = g[i] - rng.uniform(0.0, 0.5);
        t.ug[i] = g[i] + rng.uniform(0.0, 0.5);
    }
    (qp, witness)
}

/// The QP in clarabel's form over `z = (u_0, x_1, u_1, ..., x_{N-1}, u_{N-1}, x_N)`.
pub struct Dense {
    pub p: Vec<Vec<f64>>,
    pub q: Vec<f64>,
    pub a: Vec<Vec<f64>>,
    pub b: Vec<f64>,
    pub n_eq: usize,
    pub n_ineq: usize,
}

pub fn dense<
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
>(
    qp: &OcpQp<f64, NX, NU, NG, NGN, N>,
) -> Dense {
    // Offsets: u_k at uo(k), x_k (k >= 1) at xo(k).
    let uo = |k: usize| {
        if k == 0 {
            0
        } else {
            NU + (k - 1) * (NX + NU) + NX
        }
    };
    let xo = |k: usize| NU + (k - 1) * (NX + NU);
    let nz = NU + (N - 1) * (NX + NU) + NX;
    let mut p = vec![vec![0.0; nz]; nz];
    let mut q = vec![0.0; nz];
    let mut eq: Vec<(Vec<f64>, f64)> = Vec::new();
    let mut ineq: Vec<(Vec<f64>, f64)> = Vec::new();
    let big = 1e19;
    let two_sided =
        |row: Vec<f64>, offset: f64, lo: f64, hi: f64, ineq: &mut Vec<(Vec<f64>, f64)>| {
            // lo <= row z + offset <= hi
            if hi < big {
                ineq.push((row.clone(), hi - offset));
            }
            if lo > -big {
                ineq.push((row.iter().map(|v| -v).collect(), offset - lo));
            }
        };
    for k in 0..N {
        let s = &qp.stages[k];
        for i in 0..NU {
            for j in 0..NU {
                p[uo(k) + i][uo(k) + j] += s.r[(i, j)];
            }
            q[uo(k) + i] += s.gu[i];
        }
        if k == 0 {
            let sx = s.s * qp.x0;
            for i in 0..NU {
                q[uo(0) + i] += sx[i];
            }
        } else {
            for i in 0..NX {
                for j in 0..NX {
                    p[xo(k) + i][xo(k) + j] += s.q[(i, j)];
                }
                q[xo(k) + i] += s.gx[i];
            }
            for i in 0..NU {
                for j in 0..NX {
                    p[uo(k) + i][xo(k) + j] += s.s[(i, j)];
                    p[xo(k) + j][uo(k) + i] += s.s[(i, j)];
                }
            }
        }
        // Dynamics: x_{k+1} - A x_k - B u_k = f (+ A x0 at k = 0).
        let next = if k + 1 == N { xo(N) } else { xo(k + 1) };
        for i in 0..NX {
            let mut row = vec![0.0; nz];
            row[next + i] = 1.0;
            for j in 0..NU {
                row[uo(k) + j] = -s.b[(i, j)];
            }
            let mut rhs = s.f[i];
            if k == 0 {
                rhs += (s.a * qp.x0)[i];
            } else {
                for j in 0..NX {
                    row[xo(k) + j] = -s.a[(i, j)];
                }
            }
            eq.push((row, rhs));
        }
        // Bounds.
        for i in 0..NU {
            let mut row = vec![0.0; nz];
            row[uo(k) + i] = 1.0;
            two_sided(row, 0.0, s.lbu[i], s.ubu[i], &mut ineq);
        }
        if k > 0 {
            for i in 0..NX {
                let mut row = vec![0.0; nz];
                row[xo(k) + i] = 1.0;
                two_sided(row, 0.0, s.lbx[i], s.ubx[i], &mut ineq);
            }
        }
        for g in 0..NG {
            let mut row = vec![0.0; nz];
            let mut offset = 0.0;
            for j in 0..NU {
                row[uo(k) + j] = s.d[(g, j)];
            }
            if k == 0 {
                offset = (s.c * qp.x0)[g];
            } else {
                for j in 0..NX {
                    row[xo(k) + j] = s.c[(g, j)];
                }
            }
            two_sided(row, offset, s.lg[g], s.ug[g], &mut ineq);
        }
    }
    let t = &qp.terminal;
    for i in 0..NX {
        for j in 0..NX {
            p[xo(N) + i][xo(N) + j] += t.q[(i, j)];
        }
        q[xo(N) + i] += t.gx[i];
        let mut row = vec![0.0; nz];
        row[xo(N) + i] = 1.0;
        two_sided(row, 0.0, t.lbx[i], t.ubx[i], &mut ineq);
    }
    for g in 0..NGN {
        let mut row = vec![0.0; nz];
        for j in 0..NX {
            row[xo(N) + j] = t.c[(g, j)];
        }
        two_sided(row, 0.0, t.lg[g], t.ug[g], &mut ineq);
    }
    let n_eq = eq.len();
    let n_ineq = ineq.len();
    let (a, b): (Vec<_>, Vec<_>) = eq.into_iter().chain(ineq).unzip();
    Dense {
        p,
        q,
        a,
        b,
        n_eq,
        n_ineq,
    }
}

/// Clarabel's solution: controls, states, and the smallest `max(slack, multiplier)` over the
/// inequality rows (near zero where the solution is degenerate: a bound that is active with a
/// vanishing multiplier).
pub struct Reference<const NX: usize, const NU: usize> {
    pub u: Vec<SVector<f64, NU>>,
    pub x: Vec<SVector<f64, NX>>,
    pub strict_complementarity: f64,
}

/// Solves with clarabel to tight tolerances, or `None` where clarabel itself does not reach
/// `Solved` (those cases have no reference).
pub fn clarabel_solve<
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
>(
    qp: &OcpQp<f64, NX, NU, NG, NGN, N>,
) -> Option<Reference<NX, NU>> {
    let d = dense(qp);
    let p = CscMatrix::from(&d.p).to_triu();
    let a = CscMatrix::from(&d.a);
    let cones = [
        SupportedConeT::ZeroConeT(d.n_eq),
        SupportedConeT::NonnegativeConeT(d.n_ineq),
    ];
    let settings = DefaultSettingsBuilder::default()
        .verbose(std::env::var("CLARABEL_VERBOSE").is_ok())
        .tol_gap_abs(1e-12)
        .tol_gap_rel(1e-12)
        .tol_feas(1e-12)
        .max_iter(200)
        .build()
        .unwrap();
    let mut solver = DefaultSolver::new(&p, &d.q, &a, &d.b, &cones, settings).unwrap();
    solver.solve();
    if solver.solution.status != SolverStatus::Solved {
        return None;
    }
    let z = &solver.solution.x;
    let uo = |k: usize| {
        if k == 0 {
            0
        } else {
            NU + (k - 1) * (NX + NU) + NX
        }
    };
    let xo = |k: usize| NU + (k - 1) * (NX + NU);
    let us = (0..N)
        .map(|k| SVector::from_fn(|i, _| z[uo(k) + i]))
        .collect();
    let xs = (0..=N)
        .map(|k| {
            if k == 0 {
                qp.x0
            } else {
                SVector::from_fn(|i, _| z[xo(k) + i])
            }
        })
        .collect();
    let sol = &solver.solution;
    let strict_complementarity = sol.s[d.n_eq..]
        .iter()
        .zip(&sol.z[d.n_eq..])
        .map(|(s, z)| s.max(*z))
        .fold(f64::INFINITY, f64::min);
    Some(Reference {
        u: us,
        x: xs,
        strict_complementarity,
    })
}
