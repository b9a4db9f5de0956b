//! The quadrotor rate model (QR-bench): symbolic model, RK4 discretization, Jacobians and SSA,
//! each checked against an independent hand-written f64 implementation.

use mpc_dsl::models::{GRAVITY, quadrotor_rates, quadrotor_rates_rhs, rk4};
use mpc_dsl::{Expr, Graph, Program};
use nalgebra::Quaternion;
use proptest::prelude::*;

/// QR-bench's ODE written out by hand from its definition (`docs/bench.md`).
fn rhs_f64(x: &[f64; 10], u: &[f64; 4]) -> [f64; 10] {
    let (qw, qx, qy, qz) = (x[3], x[4], x[5], x[6]);
    let c = u[0];
    let qdot = Quaternion::new(qw, qx, qy, qz) * Quaternion::new(0.0, u[1], u[2], u[3]) * 0.5;
    [
        x[7],
        x[8],
        x[9],
        qdot.w,
        qdot.i,
        qdot.j,
        qdot.k,
        2.0 * (qw * qy + qx * qz) * c,
        2.0 * (qy * qz - qw * qx) * c,
        (1.0 - 2.0 * (qx * qx + qy * qy)) * c - GRAVITY,
    ]
}

fn rk4_f64(x: &[f64; 10], u: &[f64; 4], h: f64) -> [f64; 10] {
    let add = |a: &[f64; 10], k: &[f64; 10], s: f64| core::array::from_fn(|i| a[i] + s * k[i]);
    let k1 = rhs_f64(x, u);
    let k2 = rhs_f64(&add(x, &k1, h / 2.0), u);
    let k3 = rhs_f64(&add(x, &k2, h / 2.0), u);
    let k4 = rhs_f64(&add(x, &k3, h), u);
    core::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

const DT: f64 = 0.04;

fn state() -> impl Strategy<Value = ([f64; 10], [f64; 4])> {
    (
        prop::array::uniform10(-2.0f64..2.0),
        prop::array::uniform4(-1.0f64..1.0),
        (0.0f64..20.0, prop::array::uniform3(-6.0f64..6.0)),
    )
        .prop_map(|(mut x, q, (c, w))| {
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-3);
            for k in 0..4 {
                x[3 + k] = q[k] / n;
            }
            (x, [c, w[0], w[1], w[2]])
        })
}

struct Discrete<'g> {
    wrt: Vec<Expr<'g>>,
    xnext: Vec<Expr<'g>>,
}

fn discretize(g: &Graph) -> Discrete<'_> {
    let m = quadrotor_rates(g).unwrap();
    let xnext = rk4(&m.x, DT, 1, |x| quadrotor_rates_rhs(x, &m.u)).unwrap();
    let mut wrt = m.x.into_vec();
    wrt.extend(m.u.iter().copied());
    Discrete {
        wrt,
        xnext: xnext.into_vec(),
    }
}

fn inputs(x: &[f64; 10], u: &[f64; 4]) -> Vec<f64> {
    x.iter().chain(u).copied().collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn model_and_rk4_match_hand_written((x, u) in state()) {
        let g = Graph::new();
        let m = quadrotor_rates(&g).unwrap();
        let b: Vec<(Expr<'_>, f64)> = m.x.iter().chain(m.u.iter()).copied().zip(inputs(&x, &u)).collect();
        let xdot = g.eval(&m.xdot, &b).unwrap();
        for (k, (a, w)) in xdot.iter().zip(rhs_f64(&x, &u)).enumerate() {
            prop_assert!((a - w).abs() <= 1e-12 * w.abs().max(1.0), "xdot[{k}] {a} vs {w}");
        }
        let d = discretize(&g);
        let xn = g.eval(&d.xnext, &b).unwrap();
        for (k, (a, w)) in xn.iter().zip(rk4_f64(&x, &u, DT)).enumerate() {
            prop_assert!((a - w).abs() <= 1e-12 * w.abs().max(1.0), "x+[{k}] {a} vs {w}");
        }
    }

    /// [A B] of the RK4 step against central differences of the hand-written RK4.
    #[test]
    fn rk4_jacobian_matches_finite_differences((x, u) in state()) {
        let g = Graph::new();
        let d = discretize(&g);
        let jac = g.jacobian(&d.xnext, &d.wrt).unwrap();
        let prog = g.compile(jac.to_dense().as_row_major(), &d.wrt).unwrap();
        let ad = prog.eval(&inputs(&x, &u)).unwrap();
        let h = 1e-6;
        for j in 0..14 {
            let (mut xp, mut up, mut xm, mut um) = (x, u, x, u);
            if j < 10 { xp[j] += h; xm[j] -= h; } else { up[j - 10] += h; um[j - 10] -= h; }
            let (fp, fm) = (rk4_f64(&xp, &up, DT), rk4_f64(&xm, &um, DT));
            for i in 0..10 {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                let a = ad[i * 14 + j];
                prop_assert!((a - fd).abs() <= 1e-6 * fd.abs().max(1.0), "d x+[{i}] / d in[{j}]: {a} vs {fd}");
            }
        }
    }

    /// The SSA program of the discrete model and its Jacobian computes bit for bit what the
    /// interpreter computes.
    #[test]
    fn ssa_equals_interpreter((x, u) in state()) {
        let g = Graph::new();
        let d = discretize(&g);
        let jac = g.jacobian(&d.xnext, &d.wrt).unwrap();
        let mut outs = d.xnext.clone();
        outs.extend_from_slice(jac.values());
        let prog = g.compile(&outs, &d.wrt).unwrap();
        let vals = inputs(&x, &u);
        let b: Vec<(Expr<'_>, f64)> = d.wrt.iter().copied().zip(vals.iter().copied()).collect();
        let want = g.eval(&outs, &b).unwrap();
        let got = prog.eval(&vals).unwrap();
        for (k, (a, w)) in got.iter().zip(&want).enumerate() {
            prop_assert_eq!(a.to_bits(), w.to_bits(), "output {}: {} vs {}", k, a, w);
        }
    }
}

fn lowered(g: &Graph) -> Program {
    let d = discretize(g);
    let jac = g.jacobian(&d.xnext, &d.wrt).unwrap();
    let mut outs = d.xnext.clone();
    outs.extend_from_slice(jac.values());
    g.compile(&outs, &d.wrt).unwrap()
}

/// The same model gives the same program text whatever else the graph holds and in whatever
/// order the graph's nodes were created.
#[test]
fn lowering_is_deterministic() {
    let reference = lowered(&Graph::new()).to_string();
    let g = Graph::new();
    // Unrelated nodes first, and the controls declared before the states.
    let junk = g.symbol("junk");
    let _ = (junk * 3.0).sin() + g.symbol("wz") * g.symbol("c");
    assert_eq!(lowered(&g).to_string(), reference);
    assert_eq!(
        lowered(&g).to_string(),
        reference,
        "lowering twice in one graph"
    );
}

/// The Jacobian has the structure the model implies: position rows do not depend on the
/// controls' body rates directly except through the quaternion, etc. Spot-check entries that
/// are exactly known: d p+ / d p = I and d q+ / d c = 0.
#[test]
fn rk4_jacobian_structure() {
    let g = Graph::new();
    let d = discretize(&g);
    let jac = g.jacobian(&d.xnext, &d.wrt).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            let e = jac.get(i, j);
            if i == j {
                assert_eq!(e.and_then(|e| e.as_constant()), Some(1.0));
            } else {
                assert_eq!(e, None, "d p+[{i}] / d p[{j}] is structurally zero");
            }
        }
    }
    for i in 3..7 {
        assert_eq!(jac.get(i, 10), None, "attitude does not depend on thrust");
        for j in 0..3 {
            assert_eq!(jac.get(i, j), None, "attitude does not depend on position");
        }
    }
    // Velocity depends on thrust, attitude does on body rates.
    assert!(jac.get(7, 10).is_some() && jac.get(3, 11).is_some());
}
