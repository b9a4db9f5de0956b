//! General cost terms through the lowering and the runtime:
//!
//! - the lowered `stage_cost` / `terminal_cost` functions (the programs the generated code is
//!   emitted from) against CasADi's value, gradient and Hessian at random points, to 1e-9
//!   (`benches/peers/general_cost/derivatives.csv`, by `benches/peers/general_cost_casadi.py`);
//! - `Rti::solve_sqp` on `tests/data/pendulum_cost.mpc` (least squares, an energy term, a
//!   log barrier, a nonlinear output, a terminal term) against IPOPT's solution of the same
//!   problem written independently in CasADi, to 1e-6 over the whole trajectory, with
//!   Gauss-Newton (projected) and exact-Hessian steps; the exact Hessian in fewer iterations;
//! - a quadratic general cost against the same cost written as least squares (the same
//!   RTI steps and solutions), and a nonconvex cost whose projection keeps every QP convex.
//!
//! The runtime runs the lowered programs through a `Model` that evaluates them on the host
//! (`Interp`), so these tests need no generated crate; `tests/general_cost.rs` (at the
//! repository root) builds one end to end.

use std::path::PathBuf;

use mpc_codegen::lower::{Arg, Function, Target};
use mpc_codegen::{Lowered, lower_with};
use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};
use mpc_runtime::nalgebra::{DMatrix, SMatrix, SVector};
use mpc_runtime::{Model, Rti, RtiSettings, RtiStatus};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn lowered(src: &str, exact: bool) -> Lowered {
    let g = Graph::new();
    let parsed = match parse(&g, src, &ParseOptions::default()) {
        Ok(p) => p,
        Err(d) => panic!("{}", d.render("model.mpc", src)),
    };
    lower_with(&parsed.ocp, exact).unwrap()
}

/// Runs `f` at `(x, u, p)` with multipliers `m` (`pi` or `mu`) and hands each output to `put`.
fn run(f: &Function, x: &[f64], u: &[f64], p: &[f64], m: &[f64], mut put: impl FnMut(Target, f64)) {
    let inputs: Vec<f64> = (f.inputs.iter())
        .map(|&(a, i)| match a {
            Arg::X => x[i],
            Arg::U => u[i],
            Arg::P => p[i],
            Arg::Pi | Arg::Mu => m[i],
        })
        .collect();
    let out = f.program.eval(&inputs).unwrap();
    for (&v, &t) in out.iter().zip(&f.outputs) {
        put(t, v);
    }
}

/// Writes output `t = v` into the returned vector or the named matrix.
fn put<const R: usize>(
    ret: &mut SVector<f64, R>,
    mats: &mut [(&str, &mut [f64], usize)],
    t: Target,
    v: f64,
) {
    match t {
        Target::Ret(i) => ret[i] = v,
        Target::Mat(name, i, j) => {
            let (_, m, rows) = mats.iter_mut().find(|(n, _, _)| *n == name).unwrap();
            m[i + j * *rows] = v;
        }
    }
}

/// A model that evaluates the lowered programs (column-major matrices, as nalgebra's).
struct Interp<const EXACT: bool, const GENERAL: bool> {
    l: Lowered,
}

macro_rules! call {
    ($f:expr, $x:expr, $u:expr, $p:expr, $m:expr, $ret:expr, [$($name:literal => $mat:expr),*]) => {{
        $( $mat.fill(0.0); )*
        let mut mats: Vec<(&str, &mut [f64], usize)> = vec![$( { let rows = $mat.nrows(); ($name, $mat.as_mut_slice(), rows) } ),*];
        run($f, $x, $u, $p, $m, |t, v| put($ret, &mut mats, t, v));
    }};
}

impl<
    const NX: usize,
    const NU: usize,
    const NP: usize,
    const NY: usize,
    const NYN: usize,
    const NG: usize,
    const NGN: usize,
    const EXACT: bool,
    const GENERAL: bool,
> Model<f64, NX, NU, NP, NY, NYN, NG, NGN> for Interp<EXACT, GENERAL>
{
    const EXACT_HESSIAN: bool = EXACT;
    const GENERAL_COST: bool = GENERAL;

    fn dynamics(
        &self,
        x: &SVector<f64, NX>,
        u: &SVector<f64, NU>,
        p: &SVector<f64, NP>,
        a: &mut SMatrix<f64, NX, NX>,
        b: &mut SMatrix<f64, NX, NU>,
    ) -> SVector<f64, NX> {
        let mut r = SVector::zeros();
        call!(&self.l.dynamics, x.as_slice(), u.as_slice(), p.as_slice(), &[], &mut r, ["a" => a, "b" => b]);
        r
    }

    fn dynamics_hessian(
        &self,
        x: &SVector<f64, NX>,
        u: &SVector<f64, NU>,
        p: &SVector<f64, NP>,
        pi: &SVector<f64, NX>,
        hxx: &mut SMatrix<f64, NX, NX>,
        hux: &mut SMatrix<f64, NU, NX>,
        huu: &mut SMatrix<f64, NU, NU>,
    ) {
        let f = self.l.dynamics_hessian.as_ref().unwrap();
        let mut r = SVector::<f64, 0>::zeros();
        call!(f, x.as_slice(), u.as_slice(), p.as_slice(), pi.as_slice(), &mut r, ["hxx" => hxx, "hux" => hux, "huu" => huu]);
    }

    fn residual(
        &self,
        x: &SVector<f64, NX>,
        u: &SVector<f64, NU>,
        p: &SVector<f64, NP>,
        jx: &mut SMatrix<f64, NY, NX>,
        ju: &mut SMatrix<f64, NY, NU>,
    ) -> SVector<f64, NY> {
        let mut r = SVector::zeros();
        call!(&self.l.residual, x.as_slice(), u.as_slice(), p.as_slice(), &[], &mut r, ["jx" => jx, "ju" => ju]);
        r
    }

    fn terminal_residual(
        &self,
        x: &SVector<f64, NX>,
        p: &SVector<f64, NP>,
        jx: &mut SMatrix<f64, NYN, NX>,
    ) -> SVector<f64, NYN> {
        let mut r = SVector::zeros();
        call!(&self.l.terminal_residual, x.as_slice(), &[], p.as_slice(), &[], &mut r, ["jx" => jx]);
        r
    }

    fn constraints(
        &self,
        x: &SVector<f64, NX>,
        u: &SVector<f64, NU>,
        p: &SVector<f64, NP>,
        cx: &mut SMatrix<f64, NG, NX>,
        cu: &mut SMatrix<f64, NG, NU>,
    ) -> SVector<f64, NG> {
        let mut r = SVector::zeros();
        let Some(f) = self.l.constraints.as_ref() else {
            cx.fill(0.0);
            cu.fill(0.0);
            return r;
        };
        call!(f, x.as_slice(), u.as_slice(), p.as_slice(), &[], &mut r, ["cx" => cx, "cu" => cu]);
        r
    }

    fn constraints_hessian(
        &self,
        x: &SVector<f64, NX>,
        u: &SVector<f64, NU>,
        p: &SVector<f64, NP>,
        mu: &SVector<f64, NG>,
        hxx: &mut SMatrix<f64, NX, NX>,
        hux: &mut SMatrix<f64, NU, NX>,
        huu: &mut SMatrix<f64, NU, NU>,
    ) {
        let f = self.l.constraints_hessian.as_ref().unwrap();
        let mut r = SVector::<f64, 0>::zeros();
        call!(f, x.as_slice(), u.as_slice(), p.as_slice(), mu.as_slice(), &mut r, ["hxx" => hxx, "hux" => hux, "huu" => huu]);
    }

    fn stage_cost(
        &self,
        x: &SVector<f64, NX>,
        u: &SVector<f64, NU>,
        p: &SVector<f64, NP>,
        gx: &mut SVector<f64, NX>,
        gu: &mut SVector<f64, NU>,
        hxx: &mut SMatrix<f64, NX, NX>,
        hux: &mut SMatrix<f64, NU, NX>,
        huu: &mut SMatrix<f64, NU, NU>,
    ) -> f64 {
        let f = &self.l.general_cost.as_ref().unwrap().stage;
        let mut r = SVector::<f64, 1>::zeros();
        call!(f, x.as_slice(), u.as_slice(), p.as_slice(), &[], &mut r,
            ["gx" => gx, "gu" => gu, "hxx" => hxx, "hux" => hux, "huu" => huu]);
        r[0]
    }

    fn stage_cost_value(
        &self,
        x: &SVector<f64, NX>,
        u: &SVector<f64, NU>,
        p: &SVector<f64, NP>,
    ) -> f64 {
        let f = &self.l.general_cost.as_ref().unwrap().stage_value;
        let mut r = SVector::<f64, 1>::zeros();
        let mut none = SVector::<f64, 0>::zeros();
        call!(f, x.as_slice(), u.as_slice(), p.as_slice(), &[], &mut r, ["none" => none]);
        r[0]
    }

    fn terminal_cost(
        &self,
        x: &SVector<f64, NX>,
        p: &SVector<f64, NP>,
        gx: &mut SVector<f64, NX>,
        hxx: &mut SMatrix<f64, NX, NX>,
    ) -> f64 {
        let f = &self.l.general_cost.as_ref().unwrap().terminal;
        let mut r = SVector::<f64, 1>::zeros();
        call!(f, x.as_slice(), &[], p.as_slice(), &[], &mut r, ["gx" => gx, "hxx" => hxx]);
        r[0]
    }

    fn terminal_cost_value(&self, x: &SVector<f64, NX>, p: &SVector<f64, NP>) -> f64 {
        let f = &self.l.general_cost.as_ref().unwrap().terminal_value;
        let mut r = SVector::<f64, 1>::zeros();
        let mut none = SVector::<f64, 0>::zeros();
        call!(f, x.as_slice(), &[], p.as_slice(), &[], &mut r, ["none" => none]);
        r[0]
    }
}

// ------------------------------------------------------------------ derivatives vs CasADi

/// The costs of `general_cost_casadi.py`'s `cost_cases`, written in `.mpc`.
const CASES: [(&str, &str); 4] = [
    (
        "barrier",
        "stage barrier = -log(1 - x[0]^2 - 0.5 * u[0]^2 - 0.2 * x[1] * u[1]);",
    ),
    (
        "output",
        "stage output = (sin(x[0]) * x[1] + exp(0.3 * x[2]) * u[1] - a)^2;",
    ),
    (
        "energy",
        "stage energy = a * (u[0]^2 + u[1]^2) * (1 + x[1]^2) + u[0] * x[2];",
    ),
    (
        "terminal",
        "terminal tcost = x[0]^4 + cos(x[1]) * x[2]^2 + a * x[2];",
    ),
];

fn case_model(term: &str) -> String {
    format!(
        "model c; state x[3]; control u[2]; param a global;
         dynamics discrete {{ next(x) = [x[1], x[2], u[0] + u[1]]; }}
         horizon N = 3, dt = 0.1;
         cost {{ {term} }}"
    )
}

/// Value, gradient over `(x, u)` and Hessian (row-major 5x5) of the lowered function of
/// `l` at a point.
fn lowered_derivatives(l: &Lowered, terminal: bool, x: &[f64], u: &[f64], a: f64) -> Vec<f64> {
    let c = l.general_cost.as_ref().unwrap();
    let mut v = vec![0.0; 1 + 5 + 25];
    let f = if terminal { &c.terminal } else { &c.stage };
    run(f, x, u, &[a], &[], |t, val| match t {
        Target::Ret(0) => v[0] = val,
        Target::Mat("gx", i, 0) => v[1 + i] = val,
        Target::Mat("gu", i, 0) => v[4 + i] = val,
        Target::Mat("hxx", i, j) => v[6 + i * 5 + j] = val,
        Target::Mat("hux", i, j) => {
            v[6 + (3 + i) * 5 + j] = val;
            v[6 + j * 5 + 3 + i] = val;
        }
        Target::Mat("huu", i, j) => v[6 + (3 + i) * 5 + 3 + j] = val,
        other => panic!("unexpected output {other:?}"),
    });
    // The value-only functions agree with the full ones.
    let fv = if terminal {
        &c.terminal_value
    } else {
        &c.stage_value
    };
    run(fv, x, u, &[a], &[], |_, val| assert_eq!(val, v[0]));
    v
}

#[test]
fn derivatives_match_casadi() {
    let path = root().join("benches/peers/general_cost/derivatives.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.len(), 2 + 7 + 5 + 25);
    let models: Vec<(&str, Lowered)> = CASES
        .iter()
        .map(|(name, term)| (*name, lowered(&case_model(term), false)))
        .collect();
    let mut checked = 0;
    let mut worst: f64 = 0.0;
    for line in lines {
        let cols: Vec<&str> = line.split(',').collect();
        let (name, l) = models.iter().find(|(n, _)| *n == cols[0]).unwrap();
        let v: Vec<f64> = cols[2..].iter().map(|s| s.parse().unwrap()).collect();
        let (x, u, a) = (&v[0..3], &v[3..5], v[5]);
        let want = &v[6..];
        let got = lowered_derivatives(l, *name == "terminal", x, u, a);
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            let err = (g - w).abs() / w.abs().max(1.0);
            worst = worst.max(err);
            assert!(
                err <= 1e-9,
                "{name} at {x:?} {u:?} {a}: output {i}: {g} vs CasADi {w}"
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 24);
    println!("general cost derivatives: {checked} points, largest deviation {worst:.1e}");
}

// ------------------------------------------------------------------ the pendulum vs IPOPT

const PENDULUM: &str = include_str!("../../tests/data/pendulum_cost.mpc");

type Pendulum<const EXACT: bool> = Rti<f64, Interp<EXACT, true>, 2, 1, 2, 3, 0, 0, 0, 30>;

/// The pendulum's solver with the model's defaults (weights, parameters, guess).
fn pendulum<const EXACT: bool>() -> Box<Pendulum<EXACT>> {
    let l = lowered(PENDULUM, EXACT);
    assert_eq!((l.nx, l.nu, l.np, l.ny, l.nyn, l.n), (2, 1, 2, 3, 0, 30));
    configure(Box::new(Rti::new(Interp { l })))
}

/// Weights, parameters and guess from the lowered model's defaults.
fn configure<
    const NX: usize,
    const NU: usize,
    const NP: usize,
    const NY: usize,
    const NYN: usize,
    const N: usize,
    const E: bool,
    const G: bool,
>(
    mut rti: Box<Rti<f64, Interp<E, G>, NX, NU, NP, NY, NYN, 0, 0, N>>,
) -> Box<Rti<f64, Interp<E, G>, NX, NU, NP, NY, NYN, 0, 0, N>> {
    let l = &rti.model.l;
    let p = SVector::<f64, NP>::from_column_slice(&l.p_default);
    let (mut w, mut wn) = (
        SMatrix::<f64, NY, NY>::zeros(),
        SMatrix::<f64, NYN, NYN>::zeros(),
    );
    let mut r = SVector::<f64, 0>::zeros();
    call!(&l.weights, &[], &[], p.as_slice(), &[], &mut r, ["w" => w, "wn" => wn]);
    let x = SVector::<f64, NX>::from_column_slice(&l.x_guess);
    let u = SVector::<f64, NU>::from_column_slice(&l.u_guess);
    rti.set_weights(&w, &wn).unwrap();
    rti.set_param_all(&p).unwrap();
    rti.set_guess(&x, &u).unwrap();
    rti
}

fn sqp_settings(s: &mut RtiSettings<f64>) {
    s.sqp_max_iter = 200;
    s.sqp_tol = 1e-11;
    s.sqp_kkt_tol = 1e-10;
}

/// IPOPT's trajectory: rows `(x_k, u_k)`, the last `x_N`.
fn ipopt() -> Vec<Vec<f64>> {
    let path = root().join("benches/peers/general_cost/pendulum_cost_ipopt.csv");
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    assert_eq!(lines.next(), Some("k,th,om,tau"));
    lines
        .map(|l| l.split(',').skip(1).map(|s| s.parse().unwrap()).collect())
        .collect()
}

/// The largest deviation from IPOPT over every state and control.
fn deviation<const E: bool>(rti: &Pendulum<E>) -> f64 {
    let want = ipopt();
    assert_eq!(want.len(), 31);
    let mut worst: f64 = 0.0;
    for (k, row) in want.iter().enumerate() {
        let x = rti.state(k).unwrap();
        worst = worst.max((x[0] - row[0]).abs()).max((x[1] - row[1]).abs());
        if k < 30 {
            worst = worst.max((rti.control(k).unwrap()[0] - row[2]).abs());
        }
    }
    worst
}

/// IPOPT's optimal cost (the first line of its file).
fn ipopt_cost() -> f64 {
    let path = root().join("benches/peers/general_cost/pendulum_cost_ipopt.csv");
    let text = std::fs::read_to_string(path).unwrap();
    let first = text.lines().next().unwrap();
    first
        .rsplit("cost ")
        .next()
        .unwrap()
        .trim()
        .parse()
        .unwrap()
}

#[test]
fn solve_sqp_matches_ipopt_with_either_hessian() {
    let x0 = SVector::<f64, 2>::new(1.0, 0.0);
    let mut gn = pendulum::<false>();
    sqp_settings(&mut gn.settings);
    let info_gn = gn.solve_sqp(&x0);
    let mut exact = pendulum::<true>();
    sqp_settings(&mut exact.settings);
    let info_exact = exact.solve_sqp(&x0);
    let (dev_gn, dev_exact) = (deviation(&gn), deviation(&exact));
    println!(
        "pendulum_cost: Gauss-Newton {} iterations, deviation from IPOPT {dev_gn:.1e}; \
         exact Hessian {} iterations, {dev_exact:.1e}",
        info_gn.sqp_iterations, info_exact.sqp_iterations
    );
    assert_eq!(info_gn.status, RtiStatus::Ok, "{info_gn:?}");
    assert_eq!(info_exact.status, RtiStatus::Ok, "{info_exact:?}");
    assert!(dev_gn <= 1e-6, "{dev_gn}");
    assert!(dev_exact <= 1e-6, "{dev_exact}");
    // The cost read-out includes the general terms: IPOPT's objective.
    let (c, want) = (exact.cost(), ipopt_cost());
    assert!((c - want).abs() <= 1e-8 * want, "{c} vs IPOPT {want}");
    // Newton's steps on the curved cost converge in fewer iterations.
    assert!(
        info_exact.sqp_iterations < info_gn.sqp_iterations,
        "exact {} vs Gauss-Newton {}",
        info_exact.sqp_iterations,
        info_gn.sqp_iterations
    );
}

// ------------------------------------------------------------------ closed-form cases

const QUADRATIC: &str = "model q;
state th; state om; control tau;
dynamics ode rk4(2) { der(th) = om; der(om) = -9.81 * sin(th) - 0.2 * om + tau; }
horizon N = 20, dt = 0.05;
cost { Q = diag(0.5, 0.05); R = diag(0.01); TERM }
";

/// `stage q = 1/2 (2 th^2 + 0.5 tau^2 + 0.4 th tau...)` as a general term and as a
/// least-squares residual `[th, tau]` with the weight `[[2, 0.2], [0.2, 0.5]]`: the same
/// objective, so the same QPs, RTI steps and converged solution.
#[test]
fn a_quadratic_general_cost_equals_its_least_squares() {
    let general = QUADRATIC.replace(
        "TERM",
        "stage q = 0.5 * (2 * th^2 + 0.4 * th * tau + 0.5 * tau^2);",
    );
    let lsq = QUADRATIC.replace(
        "TERM",
        "residual q = [th, tau] weight mat([2, 0.2], [0.2, 0.5]);",
    );
    let lg = lowered(&general, false);
    let ll = lowered(&lsq, false);
    assert_eq!((lg.ny, ll.ny), (3, 5));
    let mut a: Box<Rti<f64, Interp<false, true>, 2, 1, 0, 3, 0, 0, 0, 20>> =
        configure(Box::new(Rti::new(Interp { l: lg })));
    let mut b: Box<Rti<f64, Interp<false, false>, 2, 1, 0, 5, 0, 0, 0, 20>> =
        configure(Box::new(Rti::new(Interp { l: ll })));
    let mut x = SVector::<f64, 2>::new(0.8, -0.5);
    for step in 0..15 {
        a.prepare();
        b.prepare();
        let (ua, ia) = a.feedback(&x);
        let (ub, ib) = b.feedback(&x);
        assert_eq!((ia.status, ib.status), (RtiStatus::Ok, RtiStatus::Ok));
        assert!((ua - ub).amax() <= 1e-12, "step {step}: {ua} vs {ub}");
        assert!((a.cost() - b.cost()).abs() <= 1e-12 * b.cost().max(1.0));
        // The plant: the model's own discrete map.
        let (mut am, mut bm) = (SMatrix::zeros(), SMatrix::zeros());
        x = Model::<f64, 2, 1, 0, 5, 0, 0, 0>::dynamics(
            &b.model,
            &x,
            &ub,
            &SVector::zeros(),
            &mut am,
            &mut bm,
        );
    }
    let x0 = SVector::<f64, 2>::new(0.8, -0.5);
    sqp_settings(&mut a.settings);
    sqp_settings(&mut b.settings);
    assert_eq!(a.solve_sqp(&x0).status, RtiStatus::Ok);
    assert_eq!(b.solve_sqp(&x0).status, RtiStatus::Ok);
    for k in 0..20 {
        let d = (a.control(k).unwrap() - b.control(k).unwrap()).amax();
        assert!(d <= 1e-10, "u_{k}: {d}");
    }
}

/// A double well `4 (th^2 - 1/4)^2`, whose curvature `48 th^2 - 4` is negative near
/// `th = 0`, more than the least squares' `0.5` makes up: every QP of a closed loop stays
/// convex (its stage Hessians positive semidefinite) by the projection, and the loop runs.
#[test]
fn a_nonconvex_cost_is_projected_and_the_rti_runs() {
    let src = QUADRATIC.replace("TERM", "stage well = 4 * (th^2 - 0.25)^2;");
    let l = lowered(&src, false);
    let mut rti: Box<Rti<f64, Interp<false, true>, 2, 1, 0, 3, 0, 0, 0, 20>> =
        configure(Box::new(Rti::new(Interp { l })));
    let mut x = SVector::<f64, 2>::new(0.05, 0.0);
    let mut projected = 0;
    for step in 0..40 {
        rti.prepare();
        for k in 0..20 {
            let h = stage_hessian(&rti, k);
            let eig = h.symmetric_eigenvalues();
            assert!(eig.min() >= -1e-12, "step {step} stage {k}: {eig}");
            // The exact stage Hessian (least squares + the well) where the QP's is projected.
            let th = rti.state(k).unwrap()[0];
            if 48.0 * th * th - 4.0 + 0.5 < 0.0 {
                projected += 1;
            }
        }
        let (u, info) = rti.feedback(&x);
        assert_eq!(info.status, RtiStatus::Ok, "step {step}: {info:?}");
        assert!(u.iter().all(|v| v.is_finite()));
        let (mut am, mut bm) = (SMatrix::zeros(), SMatrix::zeros());
        x = Model::<f64, 2, 1, 0, 3, 0, 0, 0>::dynamics(
            &rti.model,
            &x,
            &u,
            &SVector::zeros(),
            &mut am,
            &mut bm,
        );
    }
    assert!(projected > 0, "the well's curvature was never negative");
    // The loop settles in a well, at th^2 = 1/4 less what the least squares pull.
    let th = x[0].abs();
    assert!(th > 0.3 && th < 0.5, "{x}");
}

/// The QP's stage Hessian `[Q S'; S R]` of stage `k`, as a dense matrix.
fn stage_hessian<const NY: usize, const N: usize>(
    rti: &Rti<f64, Interp<false, true>, 2, 1, 0, NY, 0, 0, 0, N>,
    k: usize,
) -> DMatrix<f64> {
    let s = &rti.qp().hessians[k];
    DMatrix::from_fn(3, 3, |i, j| match (i < 2, j < 2) {
        (true, true) => s.q[(i, j)],
        (false, true) => s.s[(i - 2, j)],
        (true, false) => s.s[(j - 2, i)],
        (false, false) => s.r[(i - 2, j - 2)],
    })
}

// ------------------------------------------------------------------ constraints' curvature

/// The pendulum with its speed limited by a nonlinear row, `om^2 <= 1`, which the
/// unconstrained solution exceeds (1.89 rad/s mid-horizon).
fn limited() -> String {
    PENDULUM.replace(
        "horizon N",
        "constraints { speed: -inf <= om^2 <= 1 soft l1 = 100; }\nhorizon N",
    )
}

/// The lowered Hessian of `mu' h` against central differences of the lowered Jacobian of
/// `h`, at random points and multipliers.
#[test]
fn the_constraints_hessian_matches_differences_of_their_jacobian() {
    let l = lowered(&limited(), true);
    let (jac, hess) = (
        l.constraints.as_ref().unwrap(),
        l.constraints_hessian.as_ref().unwrap(),
    );
    // Row `[dh/dx, dh/du]` of the one constraint at `z = (th, om, tau)`.
    let grad = |z: &[f64]| {
        let mut g = [0.0; 3];
        run(jac, &z[0..2], &z[2..3], &[2.0, 0.5], &[], |t, v| match t {
            Target::Mat("cx", 0, j) => g[j] = v,
            Target::Mat("cu", 0, 0) => g[2] = v,
            _ => {}
        });
        g
    };
    let mut seed = 7u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for _ in 0..5 {
        let z = [2.0 * rnd(), 2.0 * rnd(), 2.0 * rnd()];
        let mu = 3.0 * rnd();
        let mut h = [[0.0; 3]; 3];
        run(
            hess,
            &z[0..2],
            &z[2..3],
            &[2.0, 0.5],
            &[mu],
            |t, v| match t {
                Target::Mat("hxx", i, j) => h[i][j] = v,
                Target::Mat("hux", 0, j) => {
                    h[2][j] = v;
                    h[j][2] = v;
                }
                Target::Mat("huu", 0, 0) => h[2][2] = v,
                other => panic!("{other:?}"),
            },
        );
        let e = 1e-6;
        for j in 0..3 {
            let (mut zp, mut zm) = (z, z);
            zp[j] += e;
            zm[j] -= e;
            let (gp, gm) = (grad(&zp), grad(&zm));
            for i in 0..3 {
                let fd = mu * (gp[i] - gm[i]) / (2.0 * e);
                assert!(
                    (h[i][j] - fd).abs() <= 1e-7,
                    "({i},{j}) at {z:?}: {} vs {fd}",
                    h[i][j]
                );
            }
        }
    }
}

/// With the speed limit active (a soft row with an exact L1 penalty, which the merit
/// function weighs), exact-Hessian steps (the dynamics', the cost's and the constraint's
/// curvature) converge to Gauss-Newton's solution, in no more iterations. (A hard nonlinear
/// row is not in the merit function: neither Hessian's SQP converges on it in 200
/// iterations, the runtime's limitation, not this feature's.)
#[test]
fn exact_steps_with_an_active_nonlinear_constraint() {
    type Limited<const E: bool> = Rti<f64, Interp<E, true>, 2, 1, 2, 3, 0, 1, 0, 30>;
    fn solve<const E: bool>() -> (Box<Limited<E>>, u32) {
        let l = lowered(&limited(), E);
        let mut rti: Box<Limited<E>> = Box::new(Rti::new(Interp { l }));
        let l = &rti.model.l;
        let p = SVector::<f64, 2>::from_column_slice(&l.p_default);
        let (mut w, mut wn) = (SMatrix::<f64, 3, 3>::zeros(), SMatrix::<f64, 0, 0>::zeros());
        let mut r = SVector::<f64, 0>::zeros();
        call!(&l.weights, &[], &[], p.as_slice(), &[], &mut r, ["w" => w, "wn" => wn]);
        let (lg, ug) = (SVector::from([l.lg[0]]), SVector::from([l.ug[0]]));
        let (l1, l2) = (SVector::from([l.l1[0]]), SVector::from([l.l2[0]]));
        rti.set_weights(&w, &wn).unwrap();
        rti.set_param_all(&p).unwrap();
        rti.set_constraint_bounds(&lg, &ug, &SVector::zeros(), &SVector::zeros())
            .unwrap();
        rti.set_soft_penalties(&l1, &l2, &SVector::zeros(), &SVector::zeros())
            .unwrap();
        sqp_settings(&mut rti.settings);
        // The QPs with an active row are solved by the interior point to its tolerances
        // (1e-8): the step test at that level.
        rti.settings.sqp_tol = 1e-6;
        let info = rti.solve_sqp(&SVector::<f64, 2>::new(1.0, 0.0));
        assert_eq!(info.status, RtiStatus::Ok, "exact {E}: {info:?}");
        (rti, info.sqp_iterations)
    }
    let (exact, it_exact) = solve::<true>();
    let (gn, it_gn) = solve::<false>();
    let mut worst: f64 = 0.0;
    let mut top: f64 = 0.0; // the largest row multiplier
    for k in 0..=30 {
        let (a, b) = (gn.state(k).unwrap(), exact.state(k).unwrap());
        worst = worst.max((a - b).amax());
        if k < 30 {
            top = top.max(exact.constraint_multipliers(k).unwrap()[0].abs());
            worst = worst.max((gn.control(k).unwrap() - exact.control(k).unwrap()).amax());
        }
    }
    println!(
        "speed limit: Gauss-Newton {it_gn}, exact {it_exact} iterations, difference {worst:.1e}"
    );
    // The row binds (its multiplier is not zero), so its curvature is in the exact steps.
    assert!(
        top > 0.1,
        "the limit does not bind: multipliers up to {top}"
    );
    assert!(worst <= 1e-7, "{worst}");
    assert!(
        it_exact <= it_gn,
        "exact {it_exact} vs Gauss-Newton {it_gn}"
    );
}
