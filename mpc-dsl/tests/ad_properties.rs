//! Automatic differentiation checked against central finite differences of the interpreter,
//! on random expression DAGs with shared subexpressions.
//!
//! Finite differences use Ridders' method: central differences at a shrinking sequence of
//! steps, extrapolated to step zero (Richardson), keeping the estimate whose error estimate is
//! smallest. Plain central differences at a single step are only good to about 1e-7 on deep
//! compositions, too loose to judge a relative tolerance of 1e-6.

use mpc_dsl::{Expr, Graph};
use nalgebra::SVector;
use num_dual::DualNum;
use proptest::prelude::*;

const N_INPUTS: usize = 3;
const N_OUTPUTS: usize = 3;

/// One construction step of a random DAG. `a` indexes the most recent nodes (so depth grows),
/// `b` any node (so subexpressions are shared).
#[derive(Clone, Debug)]
struct Step {
    op: u8,
    a: usize,
    b: usize,
}

const N_OPS: u8 = 24;

fn steps() -> impl Strategy<Value = Vec<Step>> {
    prop::collection::vec(
        (0..N_OPS, 0usize..3, any::<usize>()).prop_map(|(op, a, b)| Step { op, a, b }),
        14..36,
    )
}

/// A random DAG, its outputs, its depth and the expressions whose sign switches a kink
/// (abs, min, max, sign): the function is smooth where none of them is near zero.
struct Dag<'g> {
    inputs: Vec<Expr<'g>>,
    outputs: Vec<Expr<'g>>,
    depth: usize,
    switches: Vec<Expr<'g>>,
}

fn build<'g>(g: &'g Graph, recipe: &[Step]) -> Dag<'g> {
    let inputs: Vec<Expr<'g>> = (0..N_INPUTS).map(|i| g.symbol(&format!("x{i}"))).collect();
    let mut pool: Vec<(Expr<'g>, usize)> = inputs.iter().map(|&x| (x, 0)).collect();
    let mut switches = Vec::new();
    for s in recipe {
        let n = pool.len();
        let (a, da) = pool[n - 1 - s.a.min(n - 1)];
        let (b, db) = pool[s.b % n];
        // Every operation is smooth on the whole real line except the four kinked ones, whose
        // switching expression is recorded.
        let e = match s.op {
            0 => a + b,
            1 => a - b,
            2 => a * b,
            3 => a / (1.0 + b.square()),
            4 => a.sin(),
            5 => a.cos() * b,
            6 => a.tanh(),
            7 => a.atan(),
            8 => a.tanh().exp(),
            9 => (1.0 + a.square()).ln(),
            10 => (0.5 + a.square()).sqrt(),
            11 => a.tanh().powi(3),
            12 => (1.0 + a.square()).powi(-2),
            13 => (1.0 + a.square()).pow(b.tanh()),
            14 => a.atan2(1.0 + b.square()),
            15 => (0.9 * a.tanh()).asin(),
            16 => (0.9 * a.tanh()).acos(),
            17 => (0.5 * a.tanh()).tan(),
            18 => {
                switches.push(a);
                a.abs()
            }
            19 => {
                switches.push(a - b);
                a.min(b)
            }
            20 => {
                switches.push(a - b);
                a.max(b)
            }
            21 => {
                switches.push(a);
                a.sign() * b
            }
            22 => -a * 0.5 + b,
            _ => a.smooth_sign(0.3) + b.smooth_step(0.5),
        };
        pool.push((e, da.max(db) + 1));
    }
    let n = pool.len();
    let outputs = pool[n - N_OUTPUTS..].iter().map(|&(e, _)| e).collect();
    let depth = pool.iter().map(|&(_, d)| d).max().unwrap_or(0);
    Dag {
        inputs,
        outputs,
        depth,
        switches,
    }
}

fn point() -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-1.5f64..1.5, N_INPUTS)
}

fn eval<'g>(g: &'g Graph, dag: &Dag<'g>, exprs: &[Expr<'g>], x: &[f64]) -> Vec<f64> {
    let b: Vec<(Expr<'g>, f64)> = dag.inputs.iter().copied().zip(x.iter().copied()).collect();
    g.eval(exprs, &b).expect("all inputs bound")
}

/// Largest step the finite differences take.
const H0: f64 = 0.02;

/// Whether the DAG is smooth on the box the finite differences sample (no kink switches sign
/// between `x` and any point `x + H0 (si ei + sj ej)`, and none is near zero at `x`), and its
/// values are of moderate size.
fn smooth_at<'g>(g: &'g Graph, dag: &Dag<'g>, x: &[f64]) -> bool {
    let s0 = eval(g, dag, &dag.switches, x);
    let out = eval(g, dag, &dag.outputs, x);
    if !(s0.iter().all(|s| s.abs() > 1e-3) && out.iter().all(|v| v.is_finite() && v.abs() < 1e4)) {
        return false;
    }
    for i in 0..N_INPUTS {
        for j in 0..N_INPUTS {
            for (si, sj) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                let mut p = x.to_vec();
                p[i] += si * H0;
                p[j] += sj * H0;
                let s = eval(g, dag, &dag.switches, &p);
                if s.iter().zip(&s0).any(|(a, b)| a.signum() != b.signum()) {
                    return false;
                }
            }
        }
    }
    true
}

/// Ridders' extrapolation of a central-difference formula `d(h)` whose error is a series in
/// `h^2`, starting from step `h`: the estimate and its error estimate.
fn ridders(d: impl Fn(f64) -> f64, h: f64) -> (f64, f64) {
    const SHRINK: f64 = 1.4;
    const N: usize = 10;
    let mut tab = [[0.0f64; N]; N];
    let mut h = h;
    tab[0][0] = d(h);
    let mut best = tab[0][0];
    let mut err = f64::INFINITY;
    for i in 1..N {
        h /= SHRINK;
        tab[0][i] = d(h);
        let mut fac = SHRINK * SHRINK;
        for j in 1..=i {
            tab[j][i] = (tab[j - 1][i] * fac - tab[j - 1][i - 1]) / (fac - 1.0);
            fac *= SHRINK * SHRINK;
            let e = (tab[j][i] - tab[j - 1][i])
                .abs()
                .max((tab[j][i] - tab[j - 1][i - 1]).abs());
            if e <= err {
                err = e;
                best = tab[j][i];
            }
        }
        if (tab[i][i] - tab[i - 1][i - 1]).abs() >= 2.0 * err {
            break;
        }
    }
    (best, err)
}

/// Relative agreement to 1e-6 (absolute below 1).
fn close((fd, _): (f64, f64), ad: f64) -> bool {
    (ad - fd).abs() <= 1e-6 * fd.abs().max(1.0)
}

/// Whether the finite difference resolves the derivative to well below the tolerance by its
/// own error estimate; where it does not (the function varies too fast at the scale of the
/// steps), the point is not one where differences can judge a derivative.
fn resolved((fd, fd_err): (f64, f64)) -> bool {
    fd.is_finite() && fd_err <= 1e-8 * fd.abs().max(1.0)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, max_global_rejects: 4096, ..ProptestConfig::default() })]

    #[test]
    fn jacobian_matches_central_differences(recipe in steps(), x in point()) {
        let g = Graph::new();
        let dag = build(&g, &recipe);
        prop_assume!(dag.depth >= 6);
        prop_assume!(smooth_at(&g, &dag, &x));
        let jac = g.jacobian(&dag.outputs, &dag.inputs).unwrap();
        let dense = jac.to_dense();
        let ad = eval(&g, &dag, dense.as_row_major(), &x);
        for j in 0..N_INPUTS {
            let diff = |h: f64| {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[j] += h;
                xm[j] -= h;
                let (fp, fm) = (eval(&g, &dag, &dag.outputs, &xp), eval(&g, &dag, &dag.outputs, &xm));
                fp.iter().zip(&fm).map(|(a, b)| (a - b) / (2.0 * h)).collect::<Vec<_>>()
            };
            for i in 0..N_OUTPUTS {
                let fd = ridders(|h| diff(h)[i], H0);
                let a = ad[i * N_INPUTS + j];
                prop_assume!(resolved(fd));
                prop_assert!(close(fd, a), "d out{i} / d x{j}: AD {a} vs FD {fd:?}; f = {}", dag.outputs[i]);
                // Structural zeros are true zeros.
                if !jac.sparsity().contains(i, j) {
                    prop_assert_eq!(a, 0.0);
                }
            }
        }
    }

    #[test]
    fn hessian_matches_central_differences(recipe in steps(), x in point()) {
        let g = Graph::new();
        let dag = build(&g, &recipe);
        prop_assume!(dag.depth >= 6);
        prop_assume!(smooth_at(&g, &dag, &x));
        let f = dag.outputs[N_OUTPUTS - 1];
        let hess = g.hessian(f, &dag.inputs).unwrap();
        let ad = eval(&g, &dag, hess.to_dense().as_row_major(), &x);
        let f_at = |p: &[f64]| eval(&g, &dag, &[f], p)[0];
        for i in 0..N_INPUTS {
            for j in 0..N_INPUTS {
                let second = |h: f64| {
                    let shifted = |si: f64, sj: f64| {
                        let mut p = x.clone();
                        p[i] += si * h;
                        p[j] += sj * h;
                        f_at(&p)
                    };
                    (shifted(1.0, 1.0) - shifted(1.0, -1.0) - shifted(-1.0, 1.0) + shifted(-1.0, -1.0))
                        / (4.0 * h * h)
                };
                let fd = ridders(second, H0 / 2.0);
                let a = ad[i * N_INPUTS + j];
                prop_assume!(resolved(fd));
                prop_assert!(close(fd, a), "H[{i}][{j}]: AD {a} vs FD {fd:?}; f = {f}");
                prop_assert_eq!(hess.get(i, j), hess.get(j, i), "Hessian is symmetric by construction");
            }
        }
    }

    /// jvp, vjp and hvp give the same numbers as products with the full Jacobian / Hessian.
    #[test]
    fn directional_products_agree_with_full_matrices(recipe in steps(), x in point(),
                                                      v in prop::collection::vec(-1.0f64..1.0, N_INPUTS),
                                                      w in prop::collection::vec(-1.0f64..1.0, N_OUTPUTS)) {
        let g = Graph::new();
        let dag = build(&g, &recipe);
        let vs: Vec<Expr<'_>> = v.iter().map(|&c| g.constant(c).unwrap()).collect();
        let ws: Vec<Expr<'_>> = w.iter().map(|&c| g.constant(c).unwrap()).collect();
        let jac = eval(&g, &dag, g.jacobian(&dag.outputs, &dag.inputs).unwrap().to_dense().as_row_major(), &x);
        let jv = eval(&g, &dag, &g.jvp(&dag.outputs, &dag.inputs, &vs).unwrap(), &x);
        let jtw = eval(&g, &dag, &g.vjp(&dag.outputs, &dag.inputs, &ws).unwrap(), &x);
        prop_assume!(jac.iter().chain(&jv).chain(&jtw).all(|v| v.is_finite() && v.abs() < 1e8));
        for i in 0..N_OUTPUTS {
            let want: f64 = (0..N_INPUTS).map(|j| jac[i * N_INPUTS + j] * v[j]).sum();
            prop_assert!((jv[i] - want).abs() <= 1e-9 * want.abs().max(1.0), "Jv[{i}] {} vs {want}", jv[i]);
        }
        for j in 0..N_INPUTS {
            let want: f64 = (0..N_OUTPUTS).map(|i| jac[i * N_INPUTS + j] * w[i]).sum();
            prop_assert!((jtw[j] - want).abs() <= 1e-9 * want.abs().max(1.0), "J'w[{j}] {} vs {want}", jtw[j]);
        }
        let f = dag.outputs[0];
        let h = eval(&g, &dag, g.hessian(f, &dag.inputs).unwrap().to_dense().as_row_major(), &x);
        let hv = eval(&g, &dag, &g.hvp(f, &dag.inputs, &vs).unwrap(), &x);
        prop_assume!(h.iter().chain(&hv).all(|v| v.is_finite() && v.abs() < 1e8));
        for i in 0..N_INPUTS {
            let want: f64 = (0..N_INPUTS).map(|j| h[i * N_INPUTS + j] * v[j]).sum();
            prop_assert!((hv[i] - want).abs() <= 1e-9 * want.abs().max(1.0), "Hv[{i}] {} vs {want}", hv[i]);
        }
    }

    /// The compiled SSA program computes exactly (bit for bit) what the interpreter computes,
    /// and contains no two identical instructions.
    #[test]
    fn program_equals_interpreter(recipe in steps(), x in point()) {
        let g = Graph::new();
        let dag = build(&g, &recipe);
        let jac = g.jacobian(&dag.outputs, &dag.inputs).unwrap();
        let mut outs = dag.outputs.clone();
        outs.extend_from_slice(jac.values());
        let prog = g.compile(&outs, &dag.inputs).unwrap();
        let want = eval(&g, &dag, &outs, &x);
        let got = prog.eval(&x).unwrap();
        for (k, (a, b)) in got.iter().zip(&want).enumerate() {
            prop_assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "output {k}: {a} vs {b}");
        }
        let mut seen = std::collections::HashSet::new();
        for ins in prog.instrs() {
            prop_assert!(seen.insert(format!("{ins:?}")), "instruction computed twice: {ins:?}");
        }
    }
}

/// Reverse mode on a graph whose expanded tree has 2^k leaves: the derivative graph must grow
/// linearly with the DAG, not with the tree.
#[test]
fn reverse_mode_is_linear_in_graph_size() {
    let g = Graph::new();
    let (x, y) = (g.symbol("x"), g.symbol("y"));
    let mut e = x;
    let depth = 2000;
    for k in 0..depth {
        // e uses the previous e three times: the tree has 3^k copies of x.
        e = (e * e).sin() + e * (0.5 + 0.25 * f64::from(k % 7)) + y * e;
    }
    let before = g.len();
    let grad = g.gradient(e, &[x, y]).unwrap();
    let added = g.len() - before;
    assert!(
        added <= 12 * before,
        "gradient added {added} nodes to a {before}-node graph"
    );
    // And the derivative is right: compare with finite differences on a shallow copy.
    let g2 = Graph::new();
    let x2 = g2.symbol("x");
    let mut e2 = x2;
    for _ in 0..30 {
        e2 = (e2 * e2).sin() * 0.9 + e2 * 0.3;
    }
    let d = g2.gradient(e2, &[x2]).unwrap()[0];
    let at = |v: f64| g2.eval(&[e2], &[(x2, v)]).unwrap()[0];
    let ad = g2.eval(&[d], &[(x2, 0.4)]).unwrap()[0];
    let fd = ridders(|h| (at(0.4 + h) - at(0.4 - h)) / (2.0 * h), H0);
    assert!(resolved(fd), "{fd:?}");
    assert!(close(fd, ad), "AD {ad} vs FD {fd:?}");
    assert_eq!(grad.len(), 2);
}

/// Forward (tall Jacobian) and reverse (wide Jacobian) paths give the same entries.
#[test]
fn forward_and_reverse_jacobians_agree() {
    let g = Graph::new();
    let x: Vec<Expr<'_>> = (0..2).map(|i| g.symbol(&format!("x{i}"))).collect();
    let outs = vec![
        x[0] * x[1],
        x[0].sin(),
        x[1].exp() + x[0],
        (x[0] * x[1]).cos(),
    ];
    // 4 outputs > 2 inputs: forward mode.
    let tall = g.jacobian(&outs, &x).unwrap();
    // Same rows one at a time: 1 output <= 2 inputs: reverse mode.
    for (i, &o) in outs.iter().enumerate() {
        let row = g.jacobian(&[o], &x).unwrap();
        for j in 0..2 {
            let a = tall
                .get(i, j)
                .map(|e| g.eval(&[e], &[(x[0], 0.3), (x[1], -0.7)]).unwrap()[0]);
            let b = row
                .get(0, j)
                .map(|e| g.eval(&[e], &[(x[0], 0.3), (x[1], -0.7)]).unwrap()[0]);
            assert_eq!(a, b, "entry ({i}, {j})");
        }
    }
    // Sparsity: row 1 depends on x0 only, the others on both.
    let pattern: Vec<(usize, usize)> = tall.sparsity().iter().collect();
    assert_eq!(
        pattern,
        vec![(0, 0), (0, 1), (1, 0), (2, 0), (2, 1), (3, 0), (3, 1)]
    );
}

#[test]
fn sparsity_excludes_independent_and_cancelled_entries() {
    let g = Graph::new();
    let (x, y, z) = (g.symbol("x"), g.symbol("y"), g.symbol("z"));
    let p = g.symbol("p"); // a parameter, not differentiated
    let jac = g
        .jacobian(&[x * y * p, z, (x + y) - y, p.sin()], &[x, y, z])
        .unwrap();
    let pattern: Vec<(usize, usize)> = jac.sparsity().iter().collect();
    // (x + y) - y is not simplified to x, but its y-derivative 1 - 1 folds to 0.
    assert_eq!(pattern, vec![(0, 0), (0, 1), (1, 2), (2, 0)]);
    assert_eq!(jac.get(1, 2), Some(g.one()));
    assert_eq!(
        jac.get(0, 1),
        Some(x * p),
        "d(x y p)/dy by forward mode (4 outputs > 3 variables): tangent x, times p"
    );
    assert_eq!(jac.nnz(), 4);
    assert_eq!(jac.sparsity().row_ptr(), &[0, 2, 3, 4, 4]);
}

#[test]
fn nonsmooth_derivative_conventions() {
    let g = Graph::new();
    let (x, y) = (g.symbol("x"), g.symbol("y"));
    let at = |e: Expr<'_>, a: f64, b: f64| g.eval(&[e], &[(x, a), (y, b)]).unwrap()[0];
    let d = |e| g.gradient(e, &[x, y]).unwrap();
    // |x|' = sign(x), 0 at 0.
    assert_eq!(at(d(x.abs())[0], -2.0, 0.0), -1.0);
    assert_eq!(at(d(x.abs())[0], 0.0, 0.0), 0.0);
    // min/max follow the selected operand; ties go to the first.
    let dmin = d(x.min(y));
    assert_eq!((at(dmin[0], 1.0, 2.0), at(dmin[1], 1.0, 2.0)), (1.0, 0.0));
    assert_eq!((at(dmin[0], 3.0, 2.0), at(dmin[1], 3.0, 2.0)), (0.0, 1.0));
    assert_eq!((at(dmin[0], 2.0, 2.0), at(dmin[1], 2.0, 2.0)), (1.0, 0.0));
    let dmax = d(x.max(y));
    assert_eq!((at(dmax[0], 1.0, 2.0), at(dmax[1], 1.0, 2.0)), (0.0, 1.0));
    // sign and step have zero derivative.
    assert!(d(x.sign())[0].is_zero());
    assert!(d(x.step())[0].is_zero());
    // atan2 in all four quadrants against the closed form.
    let da = d(y.atan2(x));
    for &(a, b) in &[(1.0, 2.0), (-1.0, 2.0), (-1.0, -2.0), (1.0, -2.0)] {
        let r2 = a * a + b * b;
        assert!((at(da[0], a, b) - (-b / r2)).abs() < 1e-15);
        assert!((at(da[1], a, b) - (a / r2)).abs() < 1e-15);
    }
}

#[test]
fn differentiation_variables_must_be_distinct_symbols() {
    let g = Graph::new();
    let (x, y) = (g.symbol("x"), g.symbol("y"));
    assert!(matches!(
        g.gradient(x * y, &[x, x * y]),
        Err(mpc_dsl::DslError::NotASymbol { .. })
    ));
    assert!(matches!(
        g.jacobian(&[x * y], &[x, x]),
        Err(mpc_dsl::DslError::DuplicateInput { .. })
    ));
    assert!(matches!(
        g.jvp(&[x], &[x, y], &[g.one()]),
        Err(mpc_dsl::DslError::LengthMismatch { .. })
    ));
}

/// The same random DAG evaluated with num-dual's dual numbers: an independent forward-mode AD
/// implementation, exact up to rounding, so the comparison can be tight.
fn run_dual<T: DualNum<Primitive = f64> + Copy>(recipe: &[Step], x: &[T]) -> Vec<T> {
    let mut pool: Vec<T> = x.to_vec();
    let sq1 = |v: T| v.powi(2) + 1.0;
    for s in recipe {
        let n = pool.len();
        let a = pool[n - 1 - s.a.min(n - 1)];
        let b = pool[s.b % n];
        let e = match s.op {
            0 => a + b,
            1 => a - b,
            2 => a * b,
            3 => a / sq1(b),
            4 => a.sin(),
            5 => a.cos() * b,
            6 => a.tanh(),
            7 => a.atan(),
            8 => a.tanh().exp(),
            9 => sq1(a).ln(),
            10 => (a.powi(2) + 0.5).sqrt(),
            11 => a.tanh().powi(3),
            12 => sq1(a).powi(-2),
            13 => sq1(a).powd(b.tanh()),
            14 => a.atan2(sq1(b)),
            15 => (a.tanh() * 0.9).asin(),
            16 => (a.tanh() * 0.9).acos(),
            17 => (a.tanh() * 0.5).tan(),
            18 => a.abs(),
            19 => {
                if a.re() <= b.re() {
                    a
                } else {
                    b
                }
            }
            20 => {
                if a.re() >= b.re() {
                    a
                } else {
                    b
                }
            }
            21 => b * a.re().signum() * f64::from(u8::from(a.re() != 0.0)),
            22 => a * -0.5 + b,
            _ => a / (a.powi(2) + 0.09).sqrt() + ((b / 0.5).tanh() + 1.0) * 0.5,
        };
        pool.push(e);
    }
    pool[pool.len() - N_OUTPUTS..].to_vec()
}

fn rel_close(ours: f64, oracle: f64) -> bool {
    (ours - oracle).abs() <= 1e-9 * oracle.abs().max(1.0)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, max_global_rejects: 4096, ..ProptestConfig::default() })]

    /// Jacobians and Hessians agree with num-dual to 1e-9 relative (differences are rounding:
    /// the two evaluate the chain rule in different orders).
    #[test]
    fn jacobian_and_hessian_match_num_dual(recipe in steps(), x in point()) {
        let g = Graph::new();
        let dag = build(&g, &recipe);
        prop_assume!(dag.depth >= 6);
        let s0 = eval(&g, &dag, &dag.switches, &x);
        prop_assume!(s0.iter().all(|s| s.abs() > 1e-9)); // not exactly on a kink
        let ours_j = eval(&g, &dag, g.jacobian(&dag.outputs, &dag.inputs).unwrap().to_dense().as_row_major(), &x);
        let xv = SVector::<f64, N_INPUTS>::from_column_slice(&x);
        let (_, oracle_j) = num_dual::jacobian(
            |v| SVector::<_, N_OUTPUTS>::from_column_slice(&run_dual(&recipe, v.as_slice())),
            &xv,
        );
        prop_assume!(oracle_j.iter().all(|v| v.is_finite() && v.abs() < 1e12));
        for i in 0..N_OUTPUTS {
            for j in 0..N_INPUTS {
                let (a, b) = (ours_j[i * N_INPUTS + j], oracle_j[(i, j)]);
                prop_assert!(rel_close(a, b), "J[{i}][{j}] ours {a} num-dual {b}");
            }
        }
        let f = dag.outputs[N_OUTPUTS - 1];
        let ours_h = eval(&g, &dag, g.hessian(f, &dag.inputs).unwrap().to_dense().as_row_major(), &x);
        let (_, _, oracle_h) = num_dual::hessian(|v| run_dual(&recipe, v.as_slice())[N_OUTPUTS - 1], &xv);
        prop_assume!(oracle_h.iter().all(|v| v.is_finite() && v.abs() < 1e12));
        for i in 0..N_INPUTS {
            for j in 0..N_INPUTS {
                let (a, b) = (ours_h[i * N_INPUTS + j], oracle_h[(i, j)]);
                prop_assert!(rel_close(a, b), "H[{i}][{j}] ours {a} num-dual {b}");
            }
        }
    }
}
