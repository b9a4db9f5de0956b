//! Test support: random OCP-QPs and an independent reference solution by clarabel on the QP
//! written out in full sparse form.

#![allow(dead_code)]

pub mod double_integrator;
pub mod pendulum;
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
        let (s, h) = (&mut qp.stages[k], &mut qp.hessians[k]);
        // A convex stage Hessian [Q S'; S R] = M'M + diag(eps), split into blocks; 30 % of the
        // stages have no state cost at all (singular Hessians happen, e.g. no cost on a state).
        if rng.chance(0.3) {
            h.q = SMatrix::zeros();
            h.s = SMatrix::zeros();
            h.r = psd(&mut rng, 0.1);
        } else {
            let m: SMatrix<f64, NU, NU> = rng.mat(1.0);
            let mx: SMatrix<f64, NX, NX> = rng.mat(1.0);
            let coupling: SMatrix<f64, NX, NU> = rng.mat(0.3);
            // rows [mx coupling; 0 m]: H = [mx'mx, mx'coupling; coupling'mx, coupling'coupling + m'm]
            h.q = mx.transpose() * mx + SMatrix::<f64, NX, NX>::identity() * 1e-2;
            h.s = coupling.transpose() * mx;
            h.r = coupling.transpose() * coupling
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

/// [`random_qp`] with soft general constraints: each general row (stage and terminal) is soft
/// with probability 0.6, with an L1 penalty only, an L2 penalty only, or both (each in
/// [0.1, 3]); a soft row's bounds are moved off the witness trajectory and narrowed (to a band
/// of width at most 0.4 around a point up to 1 away), so its slacks are often active, and
/// with soft rows the QP stays feasible whatever the bounds.
pub fn random_soft_qp<
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
>(
    seed: u64,
) -> OcpQp<f64, NX, NU, NG, NGN, N> {
    let mut qp = random_qp::<NX, NU, NG, NGN, N>(seed);
    let mut rng = Rng::new(seed ^ 0x9E37_79B9_7F4A_7C15);
    let mut soften = |lg: &mut f64, ug: &mut f64, l1: &mut f64, l2: &mut f64| {
        if !rng.chance(0.6) {
            return;
        }
        let kind = rng.next();
        *l1 = if kind < 2.0 / 3.0 {
            rng.uniform(0.1, 3.0)
        } else {
            0.0
        };
        *l2 = if kind >= 1.0 / 3.0 {
            rng.uniform(0.1, 3.0)
        } else {
            0.0
        };
        let c = 0.5 * (*lg + *ug) + rng.uniform(-1.0, 1.0);
        let hw = rng.uniform(0.0, 0.2);
        *lg = c - hw;
        *ug = c + hw;
    };
    for s in qp.stages.iter_mut() {
        for i in 0..NG {
            soften(
                &mut s.lg[i],
                &mut s.ug[i],
                &mut s.soft_l1[i],
                &mut s.soft_l2[i],
            );
        }
    }
    let t = &mut qp.terminal;
    for i in 0..NGN {
        soften(
            &mut t.lg[i],
            &mut t.ug[i],
            &mut t.soft_l1[i],
            &mut t.soft_l2[i],
        );
    }
    qp
}

/// The QP in clarabel's form over `z = (u_0, x_1, u_1, ..., x_{N-1}, u_{N-1}, x_N, s)`, where
/// `s` are the slacks of the soft general-constraint sides (lower before upper, stage by
/// stage, then the terminal rows), written out as variables of their own with cost
/// `l1 s + 1/2 l2 s^2`, `s >= 0` (where `l1 > 0`, see below), relaxing their side.
pub struct Dense {
    pub p: Vec<Vec<f64>>,
    pub q: Vec<f64>,
    pub a: Vec<Vec<f64>>,
    pub b: Vec<f64>,
    pub n_eq: usize,
    pub n_ineq: usize,
    /// Index in `z` of the (lower, upper) slack of each general row, per stage and then the
    /// terminal stage (index N); `None` for hard rows and absent sides.
    pub slack_index: Vec<Vec<(Option<usize>, Option<usize>)>>,
}

pub fn dense<
    const NX: usize,
    const NU: usize,
    const NG: usize,
    const NGN: usize,
    const N: usize,
    const NH: usize,
>(
    qp: &OcpQp<f64, NX, NU, NG, NGN, N, NH>,
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
    let nprimal = NU + (N - 1) * (NX + NU) + NX;
    let big = 1e19;
    // Slack variables after the primal ones.
    let mut nz = nprimal;
    let mut slack_index = Vec::new();
    let mut slack_cost = Vec::new();
    let rows = qp
        .stages
        .iter()
        .map(|s| {
            (
                s.lg.as_slice(),
                s.ug.as_slice(),
                s.soft_l1.as_slice(),
                s.soft_l2.as_slice(),
            )
        })
        .chain(std::iter::once((
            qp.terminal.lg.as_slice(),
            qp.terminal.ug.as_slice(),
            qp.terminal.soft_l1.as_slice(),
            qp.terminal.soft_l2.as_slice(),
        )));
    for (lg, ug, l1, l2) in rows {
        let mut idx = Vec::new();
        for i in 0..lg.len() {
            let soft = l1[i] > 0.0 || l2[i] > 0.0;
            let mut side = |present: bool| {
                if soft && present {
                    slack_cost.push((l1[i], l2[i]));
                    nz += 1;
                    Some(nz - 1)
                } else {
                    None
                }
            };
            let lo = side(lg[i] > -big);
            let hi = side(ug[i] < big);
            idx.push((lo, hi));
        }
        slack_index.push(idx);
    }
    let mut p = vec![vec![0.0; nz]; nz];
    let mut q = vec![0.0; nz];
    let mut eq: Vec<(Vec<f64>, f64)> = Vec::new();
    let mut ineq: Vec<(Vec<f64>, f64)> = Vec::new();
    for (j, (l1, l2)) in slack_cost.iter().enumerate() {
        let z = nprimal + j;
        q[z] += l1;
        p[z][z] += l2;
        // `s >= 0`. Without a linear penalty it is redundant (a negative slack tightens its
        // row and costs more) and left out: kept, it is weakly active (slack and multiplier
        // both zero) wherever the side is satisfied, and an interior-point solver, clarabel
        // included, pins such a slack only to about sqrt(mu).
        if *l1 > 0.0 {
            let mut row = vec![0.0; nz];
            row[z] = -1.0;
            ineq.push((row, 0.0));
        }
    }
    // A general row with optional slacks: lo - s_l <= row z + offset <= hi + s_u.
    let general = |row: Vec<f64>,
                   offset: f64,
                   lo: f64,
                   hi: f64,
                   slacks: (Option<usize>, Option<usize>),
                   ineq: &mut Vec<(Vec<f64>, f64)>| {
        if hi < big {
            let mut r = row.clone();
            if let Some(j) = slacks.1 {
                r[j] = -1.0;
            }
            ineq.push((r, hi - offset));
        }
        if lo > -big {
            let mut r: Vec<f64> = row.iter().map(|v| -v).collect();
            if let Some(j) = slacks.0 {
                r[j] = -1.0;
            }
            ineq.push((r, offset - lo));
        }
    };
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
        let h = qp.hessian(k).expect("a Hessian for every stage");
        for i in 0..NU {
            for j in 0..NU {
                p[uo(k) + i][uo(k) + j] += h.r[(i, j)];
            }
            q[uo(k) + i] += s.gu[i];
        }
        if k == 0 {
            let sx = h.s * qp.x0;
            for i in 0..NU {
                q[uo(0) + i] += sx[i];
            }
        } else {
            for i in 0..NX {
                for j in 0..NX {
                    p[xo(k) + i][xo(k) + j] += h.q[(i, j)];
                }
                q[xo(k) + i] += s.gx[i];
            }
            for i in 0..NU {
                for j in 0..NX {
                    p[uo(k) + i][xo(k) + j] += h.s[(i, j)];
                    p[xo(k) + j][uo(k) + i] += h.s[(i, j)];
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
        for (g, &slacks) in slack_index[k].iter().enumerate() {
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
            general(row, offset, s.lg[g], s.ug[g], slacks, &mut ineq);
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
    for (g, &slacks) in slack_index[N].iter().enumerate() {
        let mut row = vec![0.0; nz];
        for j in 0..NX {
            row[xo(N) + j] = t.c[(g, j)];
        }
        general(row, 0.0, t.lg[g], t.ug[g], slacks, &mut ineq);
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
        slack_index,
    }
}

/// Clarabel's solution: controls, states, and the smallest `max(slack, multiplier)` over the
/// inequality rows (near zero where the solution is degenerate: a bound that is active with a
/// vanishing multiplier).
pub struct Reference<const NX: usize, const NU: usize> {
    pub u: Vec<SVector<f64, NU>>,
    pub x: Vec<SVector<f64, NX>>,
    /// Lower and upper slacks of the general rows per stage, then the terminal stage (index
    /// N); zero for hard rows.
    pub sl: Vec<Vec<f64>>,
    pub su: Vec<Vec<f64>>,
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
    const NH: usize,
>(
    qp: &OcpQp<f64, NX, NU, NG, NGN, N, NH>,
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
    let slack = |j: Option<usize>| j.map_or(0.0, |j| z[j]);
    let sl = d
        .slack_index
        .iter()
        .map(|v| v.iter().map(|&(l, _)| slack(l)).collect())
        .collect();
    let su = d
        .slack_index
        .iter()
        .map(|v| v.iter().map(|&(_, h)| slack(h)).collect())
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
        sl,
        su,
        strict_complementarity,
    })
}
