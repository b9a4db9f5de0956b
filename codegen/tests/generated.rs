//! The checked-in generated crates (`generated/`) against independent references: the
//! mpc-dsl interpreter on the model's own expressions, central finite differences of the
//! generated functions, and acados' closed loop of QR-bench.

#[path = "../../runtime/tests/support/quadrotor.rs"]
#[allow(dead_code)]
mod quadrotor;

use std::path::{Path, PathBuf};

use mpc_codegen::{
    GeneratedCrate, Options, QpMethod, QpOptions, RuntimeDep, Scalar, with_model_file,
};
use mpc_dsl::{Expr, Graph, Ocp};
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The checked-in crates: (model file, variant, options, directory). `generated/README.md`
/// lists the same `mpcc build` commands.
fn checked_in() -> Vec<(&'static str, Option<&'static str>, Options, &'static str)> {
    let base = Options {
        runtime: RuntimeDep::Path("../../runtime".into()),
        ..Options::new()
    };
    vec![
        (
            "models/quadrotor_rates.mpc",
            None,
            base.clone(),
            "generated/quadrotor_rates",
        ),
        (
            "models/quadrotor_rates.mpc",
            Some("A"),
            Options {
                crate_name: Some("quadrotor_rates_a".into()),
                ..base.clone()
            },
            "generated/quadrotor_rates_a",
        ),
        (
            "models/quadrotor_rates.mpc",
            Some("A"),
            Options {
                crate_name: Some("quadrotor_rates_a_exact".into()),
                exact_hessian: true,
                qp: QpOptions {
                    method: Some(QpMethod::Riccati),
                    ..QpOptions::default()
                },
                ..base.clone()
            },
            "generated/quadrotor_rates_a_exact",
        ),
        (
            "models/quadrotor_rates.mpc",
            None,
            Options {
                crate_name: Some("quadrotor_rates_b_exact".into()),
                exact_hessian: true,
                qp: QpOptions {
                    method: Some(QpMethod::Riccati),
                    ..QpOptions::default()
                },
                ..base.clone()
            },
            "generated/quadrotor_rates_b_exact",
        ),
        (
            "models/quadrotor_rates.mpc",
            Some("A"),
            Options {
                scalar: Scalar::F32,
                crate_name: Some("quadrotor_rates_f32".into()),
                qp: QpOptions {
                    method: Some(QpMethod::Condensed),
                    ..QpOptions::default()
                },
                ..base.clone()
            },
            "generated/quadrotor_rates_f32",
        ),
        (
            "models/quadrotor_rates.mpc",
            None,
            Options {
                scalar: Scalar::F32,
                crate_name: Some("quadrotor_rates_b_f32".into()),
                ..base.clone()
            },
            "generated/quadrotor_rates_b_f32",
        ),
        (
            "models/quadrotor_rates.mpc",
            Some("N40"),
            Options {
                crate_name: Some("quadrotor_rates_n40".into()),
                ..base.clone()
            },
            "generated/quadrotor_rates_n40",
        ),
        (
            "models/quadrotor_rates.mpc",
            Some("N40"),
            Options {
                scalar: Scalar::F32,
                crate_name: Some("quadrotor_rates_n40_f32".into()),
                ..base.clone()
            },
            "generated/quadrotor_rates_n40_f32",
        ),
        (
            "models/paper_pointmass.mpc",
            None,
            base.clone(),
            "generated/paper_pointmass",
        ),
        (
            "models/quadrotor_probe.mpc",
            None,
            base,
            "generated/quadrotor_probe",
        ),
    ]
}

fn regenerate(file: &str, variant: Option<&str>, opts: &Options) -> GeneratedCrate {
    mpc_codegen::generate_file(root().join(file), variant, opts)
        .unwrap_or_else(|e| panic!("{file}: {e}"))
}

#[test]
fn checked_in_crates_are_current_and_generation_is_deterministic() {
    for (file, variant, opts, dir) in checked_in() {
        let a = regenerate(file, variant, &opts);
        let b = regenerate(file, variant, &opts);
        assert_eq!(a, b, "{file}: two generations differ");
        let stale = a.check(&root().join(dir));
        assert!(
            stale.is_empty(),
            "{dir}: {stale:?} differ from the generator's output; regenerate with \
             `cargo run -- build {file} --runtime-path ../../runtime -o {dir}{}` (see generated/README.md)",
            variant
                .map(|v| format!(" --variant {v}"))
                .unwrap_or_default()
        );
    }
}

/// `src/lib.rs` of a generated crate.
fn lib_rs(g: &GeneratedCrate) -> &str {
    g.files
        .iter()
        .find(|(p, _)| p.ends_with("src/lib.rs"))
        .map(|(_, c)| c.as_str())
        .expect("a src/lib.rs")
}

/// Condensing storage (`NC`) and the method setting follow `QpOptions::method` (`NBX`, `NR`
/// and `NH` the model too): `Auto` gives no model the storage (QR-bench A, B, the point
/// mass), as `Riccati` does; `Condensed` gives it (QR-bench A: then without Riccati storage).
/// The state-bound rows (`NBX`) are the states
/// with a bound in the model file (the point mass bounds its 3 accelerations), and a solver
/// that condenses and has nothing but control bounds has no Riccati storage (`NR = 0`); the
/// probe model's general constraints (its soft floor) keep it (`NR = N`) even condensed. The
/// QP has one stage Hessian (`NH = 1`) where every stage residual is linear in the model file
/// (`x - xref`, `u - uref`: QR-bench, the point mass, and the probe, whose terminal residual,
/// the probe's velocity, is not linear but has no stage Hessian).
#[test]
fn condensing_storage_follows_the_method_and_the_model() {
    let rates = "models/quadrotor_rates.mpc";
    let (condensed, riccati) = (Some(QpMethod::Condensed), Some(QpMethod::Riccati));
    let cases = [
        (rates, Some("A"), None, ["0", "0", "10", "1"], None),
        (
            rates,
            Some("A"),
            condensed,
            ["10", "0", "0", "1"],
            Some("Condensed"),
        ),
        (rates, None, None, ["0", "0", "20", "1"], None),
        (
            "models/paper_pointmass.mpc",
            None,
            None,
            ["0", "3", "10", "1"],
            None,
        ),
        (
            rates,
            None,
            condensed,
            ["20", "0", "0", "1"],
            Some("Condensed"),
        ),
        (
            rates,
            Some("A"),
            riccati,
            ["0", "0", "10", "1"],
            Some("Riccati"),
        ),
        (
            "models/quadrotor_probe.mpc",
            None,
            condensed,
            ["20", "0", "20", "1"],
            Some("Condensed"),
        ),
    ];
    for (file, variant, method, [nc, nbx, nr, nh], set) in cases {
        let opts = Options {
            qp: QpOptions {
                method,
                ..QpOptions::default()
            },
            ..Options::new()
        };
        let g = regenerate(file, variant, &opts);
        let lib = lib_rs(&g);
        let what = format!("{file} {variant:?} {method:?}");
        for (name, value) in [("NC", nc), ("NBX", nbx), ("NR", nr), ("NH", nh)] {
            assert!(
                lib.contains(&format!("pub const {name}: usize = {value};")),
                "{what}: {name} = {value}"
            );
        }
        let flat: String = lib.split_whitespace().collect();
        assert!(
            flat.contains("Rti<Real,Model,NX,NU,NP,NY,NYN,NG,NGN,N,NC,NBX,NR,NH,>"),
            "{what}"
        );
        let line = |m: &str| format!("s.qp.method = mpc_runtime::QpMethod::{m};");
        for m in ["Condensed", "Riccati"] {
            assert_eq!(lib.contains(&line(m)), set == Some(m), "{what}: {m}");
        }
    }
}

/// The checked-in QR-bench A solver in f32 (generated with `--qp-method condensed`)
/// condenses its QPs and reaches the hover; A in f64 and B (the generator's default) solve
/// them by the Riccati recursion.
#[test]
fn checked_in_solvers_solve_by_the_method_they_were_generated_with() {
    let x0 = quadrotor::X0;
    let mut a = Box::new(quadrotor_rates_f32::Solver::new());
    let mut x = SVector::from(x0);
    for _ in 0..100 {
        a.prepare();
        assert!(a.rti().condensed());
        a.set_x0(&x.cast::<f32>().into()).unwrap();
        assert_eq!(a.feedback().status, quadrotor_rates_f32::RtiStatus::Ok);
        let u = SVector::from(a.u0()).cast::<f64>();
        x = quadrotor::plant(&x, &u, 0.04, 10);
    }
    let err = ((x[0] - 4.0).powi(2) + x[1].powi(2) + (x[2] - 2.0).powi(2)).sqrt();
    assert!(err < 0.01, "A (f32, condensed): final position error {err}");
    let mut b = Box::new(quadrotor_rates::Solver::new());
    b.prepare();
    assert!(!b.rti().condensed());
    let mut a64 = Box::new(quadrotor_rates_a::Solver::new());
    a64.prepare();
    assert!(!a64.rti().condensed());
}

/// xorshift64*.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        ((x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64) / ((1u64 << 53) as f64)
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

fn rel_close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()).max(1.0)
}

/// Interpreter values of `exprs` with `x`, `u`, `p` bound.
fn interp<'g>(
    g: &'g Graph,
    exprs: &[Expr<'g>],
    ocp: &Ocp<'g>,
    x: &[f64],
    u: &[f64],
    p: &[f64],
) -> Vec<f64> {
    let mut b: Vec<(Expr<'g>, f64)> = Vec::new();
    b.extend(ocp.x().iter().copied().zip(x.iter().copied()));
    b.extend(ocp.u().iter().copied().zip(u.iter().copied()));
    b.extend(ocp.p().iter().copied().zip(p.iter().copied()));
    g.eval(exprs, &b).unwrap()
}

/// Central differences of `f` at `z` (step scaled per entry), as a dense matrix.
fn fd_jacobian(f: impl Fn(&DVector<f64>) -> DVector<f64>, z: &DVector<f64>) -> DMatrix<f64> {
    let m = f(z).len();
    let mut j = DMatrix::zeros(m, z.len());
    for c in 0..z.len() {
        let h = 1e-6 * z[c].abs().max(1.0);
        let (mut zp, mut zm) = (z.clone(), z.clone());
        zp[c] += h;
        zm[c] -= h;
        let d = (f(&zp) - f(&zm)) / (2.0 * h);
        j.set_column(c, &d);
    }
    j
}

fn assert_mat_close(what: &str, a: &DMatrix<f64>, b: &DMatrix<f64>, tol: f64) {
    assert_eq!(a.shape(), b.shape(), "{what}: shapes");
    for i in 0..a.nrows() {
        for j in 0..a.ncols() {
            assert!(
                rel_close(a[(i, j)], b[(i, j)], tol),
                "{what} ({i}, {j}): {} vs {}",
                a[(i, j)],
                b[(i, j)]
            );
        }
    }
}

/// A random state near the flight envelope: unit-ish quaternion, moderate velocities.
fn random_point(rng: &mut Rng, nx: usize, nu: usize, np: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let x = (0..nx).map(|_| rng.range(-1.0, 1.0)).collect();
    let u = (0..nu).map(|_| rng.range(-2.0, 12.0)).collect();
    let p = (0..np).map(|_| rng.range(0.1, 2.0)).collect();
    (x, u, p)
}

/// `generated/quadrotor_rates`: F equals the interpreter on `Ocp::discrete_map` (1e-12
/// relative), A and B equal the interpreter on reverse-mode AD of that map (1e-10) and the
/// finite differences of the generated F (1e-6); the residual and weights equal the model's
/// cost written out by hand from the `.mpc` file.
#[test]
fn quadrotor_rates_functions_match_interpreter_and_finite_differences() {
    use quadrotor_rates as m;
    with_model_file(&root().join("models/quadrotor_rates.mpc"), None, |ocp| {
        let g = ocp.x()[0].graph();
        let fd_map = ocp.discrete_map()?;
        let mut wrt = ocp.x().to_vec();
        wrt.extend(ocp.u().iter().copied());
        let jac = g.jacobian(&fd_map, &wrt)?.to_dense();
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        for _ in 0..50 {
            let (x, u, p) = random_point(&mut rng, m::NX, m::NU, m::NP);
            let (xs, us, ps) = (
                SVector::<f64, { m::NX }>::from_column_slice(&x),
                SVector::<f64, { m::NU }>::from_column_slice(&u),
                SVector::<f64, { m::NP }>::from_column_slice(&p),
            );
            let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
            let f = m::functions::dynamics(&xs, &us, &ps, &mut a, &mut b);
            // The value alone is the same program without the sensitivities: the same bits.
            assert_eq!(m::functions::dynamics_value(&xs, &us, &ps), f);
            let want = interp(g, &fd_map, ocp, &x, &u, &p);
            for i in 0..m::NX {
                assert!(
                    rel_close(f[i], want[i], 1e-12),
                    "F[{i}]: {} vs {}",
                    f[i],
                    want[i]
                );
            }
            let jv = interp(g, jac.as_row_major(), ocp, &x, &u, &p);
            let nz = m::NX + m::NU;
            for i in 0..m::NX {
                for j in 0..nz {
                    let got = if j < m::NX {
                        a[(i, j)]
                    } else {
                        b[(i, j - m::NX)]
                    };
                    assert!(rel_close(got, jv[i * nz + j], 1e-10), "[A B]({i},{j})");
                }
            }
            let z = DVector::from_iterator(nz, x.iter().chain(&u).copied());
            let fnum = fd_jacobian(
                |z| {
                    let xs = SVector::<f64, { m::NX }>::from_fn(|i, _| z[i]);
                    let us = SVector::<f64, { m::NU }>::from_fn(|i, _| z[m::NX + i]);
                    let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
                    let f = m::functions::dynamics(&xs, &us, &ps, &mut a, &mut b);
                    DVector::from_column_slice(f.as_slice())
                },
                &z,
            );
            let mut ab = DMatrix::zeros(m::NX, nz);
            ab.view_mut((0, 0), (m::NX, m::NX)).copy_from(&a);
            ab.view_mut((0, m::NX), (m::NX, m::NU)).copy_from(&b);
            assert_mat_close("[A B] vs finite differences", &ab, &fnum, 1e-6);

            // Residual (x - xref, u - uref): xref = p[0..10], uref = p[10..14].
            let (mut jx, mut ju) = (SMatrix::zeros(), SMatrix::zeros());
            let y = m::functions::residual(&xs, &us, &ps, &mut jx, &mut ju);
            for i in 0..m::NX {
                assert_eq!(y[i], x[i] - p[i]);
                assert_eq!(jx[(i, i)], 1.0);
            }
            for i in 0..m::NU {
                assert_eq!(y[m::NX + i], u[i] - p[m::NX + i]);
                assert_eq!(ju[(m::NX + i, i)], 1.0);
            }
            assert_eq!(jx.iter().filter(|&&v| v != 0.0).count(), m::NX);
            assert_eq!(ju.iter().filter(|&&v| v != 0.0).count(), m::NU);
        }
        // W = diag(Q, R), W_N = 5 Q from the file.
        let q = [100.0, 100.0, 100.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0, 1.0];
        let r = [0.5, 1.0, 1.0, 1.0];
        let (mut w, mut wn) = (SMatrix::zeros(), SMatrix::zeros());
        m::functions::weights(&SVector::zeros(), &mut w, &mut wn);
        let wd: Vec<f64> = q.iter().chain(&r).copied().collect();
        assert_eq!(
            w,
            SMatrix::<f64, 14, 14>::from_diagonal(&SVector::from_column_slice(&wd))
        );
        assert_eq!(
            wn,
            SMatrix::<f64, 10, 10>::from_diagonal(&SVector::from_column_slice(&q)) * 5.0
        );
        assert_eq!(m::LBU, [0.0, -20.0, -20.0, -6.0]);
        assert_eq!(m::UBU, [20.0, 20.0, 20.0, 6.0]);
        assert!(m::LBX.iter().all(|v| *v == f64::NEG_INFINITY));
        Ok(())
    })
    .unwrap();
}

/// `generated/quadrotor_rates_a_exact`: the dynamics' Lagrangian Hessian (the Hessian of
/// `pi' F`) equals the central differences of the generated Jacobians contracted with `pi`,
/// `d/d(x, u) [A'pi; B'pi]` (1e-6 relative), and is symmetric; the solver keeps a Hessian per
/// stage.
#[test]
fn quadrotor_rates_exact_hessian_matches_finite_differences_of_the_jacobians() {
    use mpc_runtime::Model;
    use quadrotor_rates_a_exact as m;
    const NZ: usize = m::NX + m::NU;
    assert_eq!(m::NH, m::N);
    const {
        assert!(
            <m::Model as Model<
                f64,
                { m::NX },
                { m::NU },
                { m::NP },
                { m::NY },
                { m::NYN },
                { m::NG },
                { m::NGN },
            >>::EXACT_HESSIAN
        )
    };
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    for _ in 0..20 {
        let (x, u, p) = random_point(&mut rng, m::NX, m::NU, m::NP);
        let pi: Vec<f64> = (0..m::NX).map(|_| rng.range(-50.0, 50.0)).collect();
        let ps = SVector::<f64, { m::NP }>::from_column_slice(&p);
        let piv = SVector::<f64, { m::NX }>::from_column_slice(&pi);
        let (xs, us) = (
            SVector::<f64, { m::NX }>::from_column_slice(&x),
            SVector::<f64, { m::NU }>::from_column_slice(&u),
        );
        let (mut hxx, mut hux, mut huu) = (SMatrix::zeros(), SMatrix::zeros(), SMatrix::zeros());
        m::functions::dynamics_hessian(&xs, &us, &ps, &piv, &mut hxx, &mut hux, &mut huu);
        let mut h = DMatrix::zeros(NZ, NZ);
        h.view_mut((0, 0), (m::NX, m::NX)).copy_from(&hxx);
        h.view_mut((m::NX, 0), (m::NU, m::NX)).copy_from(&hux);
        h.view_mut((0, m::NX), (m::NX, m::NU))
            .copy_from(&hux.transpose());
        h.view_mut((m::NX, m::NX), (m::NU, m::NU)).copy_from(&huu);
        let z = DVector::from_iterator(NZ, x.iter().chain(&u).copied());
        let fd = fd_jacobian(
            |z| {
                let xs = SVector::<f64, { m::NX }>::from_fn(|i, _| z[i]);
                let us = SVector::<f64, { m::NU }>::from_fn(|i, _| z[m::NX + i]);
                let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
                let _ = m::functions::dynamics(&xs, &us, &ps, &mut a, &mut b);
                let (ga, gb) = (a.transpose() * piv, b.transpose() * piv);
                DVector::from_iterator(NZ, ga.iter().chain(gb.iter()).copied())
            },
            &z,
        );
        assert_mat_close("Hessian of pi'F vs finite differences", &h, &fd, 1e-6);
        assert!(hxx.iter().any(|&v| v != 0.0) && hux.iter().any(|&v| v != 0.0));
        assert_eq!(hxx, hxx.transpose());
    }
}

/// `generated/paper_pointmass` (input-rate cost: state augmented with the last control):
/// F and the residual equal the interpreter on the model's expressions, the augmentation is
/// `u_last+ = u` and `y` ends with `u - u_last`; Jacobians equal finite differences.
#[test]
fn paper_pointmass_functions_match_interpreter() {
    use paper_pointmass as m;
    assert_eq!(m::NX, m::NX_MODEL + m::NU);
    with_model_file(&root().join("models/paper_pointmass.mpc"), None, |ocp| {
        let g = ocp.x()[0].graph();
        let fd_map = ocp.discrete_map()?;
        let xref = &ocp.cost.state.as_ref().unwrap().reference;
        let mut rng = Rng(77);
        for _ in 0..30 {
            let (x, u, p) = random_point(&mut rng, m::NX, m::NU, m::NP);
            let xm = &x[..m::NX_MODEL];
            let (xs, us, ps) = (
                SVector::<f64, { m::NX }>::from_column_slice(&x),
                SVector::<f64, { m::NU }>::from_column_slice(&u),
                SVector::<f64, { m::NP }>::from_column_slice(&p),
            );
            let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
            let f = m::functions::dynamics(&xs, &us, &ps, &mut a, &mut b);
            // The value alone is the same program without the sensitivities: the same bits.
            assert_eq!(m::functions::dynamics_value(&xs, &us, &ps), f);
            let want = interp(g, &fd_map, ocp, xm, &u, &p);
            for i in 0..m::NX_MODEL {
                assert!(rel_close(f[i], want[i], 1e-12), "F[{i}]");
            }
            for i in 0..m::NU {
                assert_eq!(f[m::NX_MODEL + i], u[i], "u_last+ = u");
            }
            let r = interp(g, xref, ocp, xm, &u, &p);
            let (mut jx, mut ju) = (SMatrix::zeros(), SMatrix::zeros());
            let y = m::functions::residual(&xs, &us, &ps, &mut jx, &mut ju);
            for i in 0..m::NX_MODEL {
                assert_eq!(y[i], xm[i] - r[i]);
            }
            for i in 0..m::NU {
                assert_eq!(y[m::NX_MODEL + i], u[i] - x[m::NX_MODEL + i]);
            }
            let nz = m::NX + m::NU;
            let z = DVector::from_iterator(nz, x.iter().chain(&u).copied());
            let split = |z: &DVector<f64>| {
                (
                    SVector::<f64, { m::NX }>::from_fn(|i, _| z[i]),
                    SVector::<f64, { m::NU }>::from_fn(|i, _| z[m::NX + i]),
                )
            };
            let fnum = fd_jacobian(
                |z| {
                    let (xs, us) = split(z);
                    let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
                    DVector::from_column_slice(
                        m::functions::dynamics(&xs, &us, &ps, &mut a, &mut b).as_slice(),
                    )
                },
                &z,
            );
            let mut ab = DMatrix::zeros(m::NX, nz);
            ab.view_mut((0, 0), (m::NX, m::NX)).copy_from(&a);
            ab.view_mut((0, m::NX), (m::NX, m::NU)).copy_from(&b);
            assert_mat_close("[A B]", &ab, &fnum, 1e-6);
            let ynum = fd_jacobian(
                |z| {
                    let (xs, us) = split(z);
                    let (mut jx, mut ju) = (SMatrix::zeros(), SMatrix::zeros());
                    DVector::from_column_slice(
                        m::functions::residual(&xs, &us, &ps, &mut jx, &mut ju).as_slice(),
                    )
                },
                &z,
            );
            let mut jj = DMatrix::zeros(m::NY, nz);
            jj.view_mut((0, 0), (m::NY, m::NX)).copy_from(&jx);
            jj.view_mut((0, m::NX), (m::NY, m::NU)).copy_from(&ju);
            assert_mat_close("[Jx Ju]", &jj, &ynum, 1e-6);
        }
        Ok(())
    })
    .unwrap();
}

/// `generated/quadrotor_rates_f32` (variant A, f32) follows the f64 interpreter to f32
/// accuracy.
#[test]
fn quadrotor_rates_f32_matches_interpreter_in_single_precision() {
    use quadrotor_rates_f32 as m;
    assert_eq!((m::N, m::DT), (10, 0.04));
    with_model_file(
        &root().join("models/quadrotor_rates.mpc"),
        Some("A"),
        |ocp| {
            let g = ocp.x()[0].graph();
            let fd_map = ocp.discrete_map()?;
            let mut rng = Rng(5);
            for _ in 0..30 {
                let (x, u, p) = random_point(&mut rng, m::NX, m::NU, m::NP);
                let c = |v: &[f64]| v.iter().map(|&e| e as f32).collect::<Vec<f32>>();
                let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
                let f = m::functions::dynamics(
                    &SVector::from_column_slice(&c(&x)),
                    &SVector::from_column_slice(&c(&u)),
                    &SVector::from_column_slice(&c(&p)),
                    &mut a,
                    &mut b,
                );
                let want = interp(g, &fd_map, ocp, &x, &u, &p);
                for i in 0..m::NX {
                    assert!(rel_close(f64::from(f[i]), want[i], 1e-5), "F[{i}]");
                }
            }
            Ok(())
        },
    )
    .unwrap();
}

/// Rows of an acados anchor CSV: state and control (absent in the last row).
fn anchor(name: &str) -> Vec<(SVector<f64, 10>, Option<SVector<f64, 4>>)> {
    let path = root().join("runtime/tests/data").join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').filter_map(|s| s.parse().ok()).collect();
            let x = SVector::from_fn(|i, _| v[1 + i]);
            let u = (v.len() >= 15).then(|| SVector::from_fn(|i, _| v[11 + i]));
            (x, u)
        })
        .collect()
}

/// The whole pipeline, `.mpc` → generated crate → runtime, flies QR-bench config B exactly
/// as acados does (same algorithm, first guess x_k = x0, u_k = 0, no shift): every state
/// within 1e-4 of acados' closed loop at every step.
#[test]
fn generated_quadrotor_rates_matches_acados_closed_loop() {
    use quadrotor_rates as m;
    let rows = anchor("acados_qrbench_B.csv");
    let mut s = Box::new(m::Solver::new());
    // acados' runs keep the last solution in place between steps: no shift.
    s.settings_mut().shift = false;
    let x0 = quadrotor::X0;
    s.set_guess(&x0, &[0.0; 4]).unwrap();
    let mut x = SVector::from(x0);
    for (k, (ax, au)) in rows.iter().enumerate() {
        let dx = (x - ax).amax();
        assert!(dx <= 1e-4, "step {k}: state differs from acados by {dx:e}");
        let Some(au) = au else { break };
        s.prepare();
        s.set_x0(&x.into()).unwrap();
        let info = s.feedback();
        assert_eq!(info.status, m::RtiStatus::Ok, "step {k}: {info:?}");
        let u = SVector::from(s.u0());
        assert!(
            (u - au).amax() <= 2e-3,
            "step {k}: control {u} vs acados {au}"
        );
        x = quadrotor::plant(&x, &u, m::DT, 10);
    }
}

/// Named setters: a reference set by name moves the solution as the same entries set in
/// the raw parameter vector do; non-finite values and bad stages are refused and change
/// nothing.
#[test]
fn named_setters_and_refusals() {
    use quadrotor_rates as m;
    let mut a = Box::new(m::Solver::new());
    let mut b = Box::new(m::Solver::new());
    let xref = [1.0, 2.0, 3.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    a.set_xref_all(&xref).unwrap();
    let mut p = b.param(0).unwrap();
    p[m::PARAM_XREF].copy_from_slice(&xref);
    b.set_param_all(&p).unwrap();
    for s in [&mut a, &mut b] {
        s.set_x0(&quadrotor::X0).unwrap();
        s.prepare();
        assert_eq!(s.feedback().status, m::RtiStatus::Ok);
    }
    assert_eq!(a.u0(), b.u0());
    assert_eq!(a.u0_c(), a.u0()[0]);
    assert_eq!(a.u0_w(), [a.u0()[1], a.u0()[2], a.u0()[3]]);
    let before = a.param(3).unwrap();
    assert_eq!(a.set_xref(3, &[f64::NAN; 10]), Err(m::SetError::NonFinite));
    assert_eq!(
        a.set_xref(m::N + 1, &xref),
        Err(m::SetError::StageOutOfRange)
    );
    assert_eq!(a.set_x0(&[f64::INFINITY; 10]), Err(m::SetError::NonFinite));
    assert_eq!(a.param(3).unwrap(), before);
    assert!(m::Solver::unconfigured().configure().is_ok());
}

/// The input-rate cost through the augmented state: with a large rate weight relative to the
/// tracking weight, the first control stays near the u_prev it is told, and after a
/// feedback u_prev becomes the control just returned.
#[test]
fn paper_pointmass_input_rate_uses_u_prev() {
    use paper_pointmass as m;
    let mut s = Box::new(m::Solver::new());
    let mut xref = [0.0; 9];
    xref[0] = 1.0;
    s.set_xref_all(&xref).unwrap();
    s.set_x0(&[0.0; 9]).unwrap();
    let run = |s: &mut m::Solver, prev: [f64; 3]| {
        s.set_u_prev(&prev).unwrap();
        s.prepare();
        let info = s.feedback();
        assert_eq!(info.status, m::RtiStatus::Ok);
        s.u0()
    };
    let u_a = run(&mut s.clone(), [0.0; 3]);
    let u_b = run(&mut s.clone(), [10.0, 0.0, 0.0]);
    // The rate term pulls u0 toward u_prev: a larger u_prev gives a larger first jerk.
    assert!(u_b[0] > u_a[0] + 1e-3, "{u_a:?} vs {u_b:?}");
    let mut t = s.clone();
    let u = run(&mut t, [0.0; 3]);
    let p = t.param(0).unwrap();
    assert_eq!(&p[m::PARAM_U_PREV], &u[..]);
}

/// Setting a global parameter (and the automatic `u_prev` update after a feedback) changes
/// only that parameter's entries: per-stage references set before survive in every stage,
/// and the global value reaches every stage (regression: the setters used to copy stage 0's
/// whole vector to all stages).
#[test]
fn global_setters_keep_per_stage_parameters() {
    use paper_pointmass as m;
    let mut s = Box::new(m::Solver::new());
    let stage_ref = |k: usize| {
        let mut x = [0.0; 9];
        x[0] = 0.1 * k as f64;
        x[2] = 1.0 + 0.01 * k as f64;
        x
    };
    for k in 0..=m::N {
        s.set_xref(k, &stage_ref(k)).unwrap();
    }
    let qw = [7.0; 9];
    s.set_q_w(&qw).unwrap();
    s.set_u_prev(&[0.5, -0.5, 0.25]).unwrap();
    for k in 0..=m::N {
        let p = s.param(k).unwrap();
        assert_eq!(&p[m::PARAM_XREF], &stage_ref(k)[..], "xref at stage {k}");
        assert_eq!(&p[m::PARAM_Q_W], &qw[..], "q_w at stage {k}");
        assert_eq!(
            &p[m::PARAM_U_PREV],
            &[0.5, -0.5, 0.25][..],
            "u_prev at stage {k}"
        );
    }
    s.set_x0(&[0.0; 9]).unwrap();
    s.prepare();
    assert_eq!(s.feedback().status, m::RtiStatus::Ok);
    let u = s.u0();
    for k in 0..=m::N {
        let p = s.param(k).unwrap();
        assert_eq!(
            &p[m::PARAM_XREF],
            &stage_ref(k)[..],
            "xref at stage {k} after feedback"
        );
        assert_eq!(
            &p[m::PARAM_U_PREV],
            &u[..],
            "u_prev at stage {k} after feedback"
        );
    }
}

/// `generated/quadrotor_probe` (18 states with the actuator lags, mass, lag and weight
/// parameters, two soft constraints): F equals the interpreter on the model's discrete map,
/// [A B] equals finite differences, the soft rows are `beta` and `z - z_floor` with their
/// bounds, penalties and Jacobians; a closed loop on the model's own discretization, from a
/// consistent hover (delivered rates 0, delivered thrust g), reaches the default reference.
#[test]
fn quadrotor_probe_functions_constraint_and_closed_loop() {
    use quadrotor_probe as m;
    assert_eq!((m::NX, m::NU, m::NG, m::NGN), (18, 4, 2, 0));
    assert_eq!(
        (m::LG, m::UG, m::L1, m::L2),
        (
            [-1.4, 0.0],
            [1.4, f64::INFINITY],
            [100.0, 100.0],
            [100.0, 1000.0]
        )
    );
    let (mq, mp, tau_w, tau_c, z_floor) = (
        m::PARAM_MQ.start,
        m::PARAM_MP.start,
        m::PARAM_TAU_W.start,
        m::PARAM_TAU_C.start,
        m::PARAM_Z_FLOOR.start,
    );
    with_model_file(&root().join("models/quadrotor_probe.mpc"), None, |ocp| {
        let g = ocp.x()[0].graph();
        let fd_map = ocp.discrete_map()?;
        let mut rng = Rng(11);
        for _ in 0..20 {
            let (mut x, u, mut p) = random_point(&mut rng, m::NX, m::NU, m::NP);
            x[3] += 1.0; // keep the quaternion away from zero
            x[m::STATE_CT.start] += 9.81; // delivered thrust near hover
            p[mq] = 1.5; // masses
            p[mp] = 0.2;
            p[tau_w] = rng.range(0.02, 0.1); // lags around the defaults (40 ms, 30 ms)
            p[tau_c] = rng.range(0.02, 0.1);
            let (xs, us, ps) = (
                SVector::<f64, { m::NX }>::from_column_slice(&x),
                SVector::<f64, { m::NU }>::from_column_slice(&u),
                SVector::<f64, { m::NP }>::from_column_slice(&p),
            );
            let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
            let f = m::functions::dynamics(&xs, &us, &ps, &mut a, &mut b);
            // The value alone is the same program without the sensitivities: the same bits.
            assert_eq!(m::functions::dynamics_value(&xs, &us, &ps), f);
            let want = interp(g, &fd_map, ocp, &x, &u, &p);
            for i in 0..m::NX {
                assert!(
                    rel_close(f[i], want[i], 1e-12),
                    "F[{i}]: {} vs {}",
                    f[i],
                    want[i]
                );
            }
            let nz = m::NX + m::NU;
            let z = DVector::from_iterator(nz, x.iter().chain(&u).copied());
            let fnum = fd_jacobian(
                |z| {
                    let xs = SVector::<f64, { m::NX }>::from_fn(|i, _| z[i]);
                    let us = SVector::<f64, { m::NU }>::from_fn(|i, _| z[m::NX + i]);
                    let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
                    DVector::from_column_slice(
                        m::functions::dynamics(&xs, &us, &ps, &mut a, &mut b).as_slice(),
                    )
                },
                &z,
            );
            let mut ab = DMatrix::zeros(m::NX, nz);
            ab.view_mut((0, 0), (m::NX, m::NX)).copy_from(&a);
            ab.view_mut((0, m::NX), (m::NX, m::NU)).copy_from(&b);
            assert_mat_close("[A B]", &ab, &fnum, 1e-5);
            let (mut cx, mut cu) = (SMatrix::zeros(), SMatrix::zeros());
            let h = m::functions::constraints(&xs, &us, &ps, &mut cx, &mut cu);
            assert_eq!(h[0], x[11], "the first soft row is beta = ang[1]");
            assert_eq!(
                h[1],
                x[2] - p[z_floor],
                "the second soft row is z - z_floor"
            );
            let mut e = SMatrix::<f64, 2, { m::NX }>::zeros();
            e[(0, 11)] = 1.0;
            e[(1, 2)] = 1.0;
            assert_eq!(cx, e);
            assert!(cu.iter().all(|v| *v == 0.0));
        }
        Ok(())
    })
    .unwrap();
    let target = &m::P_DEFAULT[m::PARAM_XREF][0..3];
    assert_eq!(
        target,
        &[4.0, 0.0, 2.0],
        "the model's default reference position"
    );
    let mut s = Box::new(m::Solver::new());
    // Hovering at rest 4 m away: level, delivered rates 0, delivered thrust g (the lag
    // states consistent with the hover control).
    let mut x = [0.0; m::NX_MODEL];
    x[2] = 2.0;
    x[3] = 1.0;
    x[m::STATE_CT.start] = 9.81;
    s.set_guess(&x, &[9.81, 0.0, 0.0, 0.0]).unwrap();
    // The 0.2 kg probe swings widely on the 4 m dash and its swing is lightly damped (weights
    // 1 and 0.1 on angle and rate): 10 s (200 steps) to settle, and the vehicle stays within
    // 5 cm over the last 2.5 s.
    const STEPS: usize = 200;
    const SETTLED: usize = 150;
    let dist = |x: &[f64; m::NX_MODEL]| {
        ((x[0] - target[0]).powi(2) + (x[1] - target[1]).powi(2) + (x[2] - target[2]).powi(2))
            .sqrt()
    };
    let mut worst_settled: f64 = 0.0;
    for k in 0..STEPS {
        s.prepare();
        s.set_x0(&x).unwrap();
        let info = s.feedback();
        assert_eq!(info.status, m::RtiStatus::Ok, "step {k}: {info:?}");
        let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
        let p = SVector::from(s.param(0).unwrap());
        let xn = m::functions::dynamics(
            &SVector::from(x),
            &SVector::from(s.u0()),
            &p,
            &mut a,
            &mut b,
        );
        x = xn.into();
        if k >= SETTLED {
            worst_settled = worst_settled.max(dist(&x));
        }
    }
    let err = dist(&x);
    assert!(err < 0.05, "final position error {err} m, state {x:?}");
    assert!(
        worst_settled < 0.05,
        "position error up to {worst_settled} m after step {SETTLED}"
    );
}

/// QR-bench B at hover with the reference `dz` above: converged by the full SQP from the
/// hover guess.
fn qrbench_climb(s: &mut quadrotor_rates::Solver, dz: f64) -> quadrotor_rates::RtiInfo<f64> {
    let x0 = [0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut xref = x0;
    xref[2] += dz;
    s.set_xref_all(&xref).unwrap();
    s.set_guess(&x0, &[9.81, 0.0, 0.0, 0.0]).unwrap();
    s.set_x0(&x0).unwrap();
    s.solve_sqp()
}

/// Run-time control bounds on QR-bench B: a hover reference 5 m above makes the converged
/// plan want more than 12 m/s^2 of thrust at once; with `c <= 12` set at run time, the first
/// control's thrust is 12 and no stage's exceeds it. The getters return what was set.
#[test]
fn control_bounds_set_at_run_time_bound_the_plan() {
    use quadrotor_rates as m;
    let c = m::CONTROL_C.start;
    let mut free = Box::new(m::Solver::new());
    assert_eq!(free.control_bounds(), (m::LBU, m::UBU));
    let info = qrbench_climb(&mut free, 5.0);
    assert_eq!(info.status, m::RtiStatus::Ok, "{info:?}");
    assert!(free.u0()[c] > 12.0, "unbounded u0: {:?}", free.u0());

    let mut bounded = Box::new(m::Solver::new());
    let mut ub = m::UBU;
    ub[c] = 12.0;
    bounded.set_control_bounds(&m::LBU, &ub).unwrap();
    assert_eq!(bounded.control_bounds(), (m::LBU, ub));
    let info = qrbench_climb(&mut bounded, 5.0);
    assert_eq!(info.status, m::RtiStatus::Ok, "{info:?}");
    let u0 = bounded.u0();
    assert!((u0[c] - 12.0).abs() <= 1e-6, "bounded u0: {u0:?}");
    for k in 0..m::N {
        let u = bounded.control(k).unwrap();
        assert!(u[c] <= 12.0 + 1e-6, "stage {k}: {u:?}");
    }
    // Unbounded again (infinite bounds): the plan is the free one.
    let lb = [-m::Real::INFINITY; m::NU];
    bounded
        .set_control_bounds(&lb, &[m::Real::INFINITY; m::NU])
        .unwrap();
    qrbench_climb(&mut bounded, 5.0);
    assert!(
        bounded.u0()[c] > 12.0,
        "unbounded again: {:?}",
        bounded.u0()
    );
}

/// The bound setters refuse NaN, a lower bound `+inf` (an upper bound `-inf`), crossed
/// bounds and, on QR-bench (no state-bound rows: `NBX = 0`), any state bound, each with its
/// error and without changing the bounds in use.
#[test]
fn bound_setters_refuse_bad_bounds_and_change_nothing() {
    use m::SetError::{CrossedBounds, NonFinite, TooManyStateBounds};
    use quadrotor_rates as m;
    let mut s = Box::new(m::Solver::new());
    let mut ub = m::UBU;
    ub[0] = 12.0;
    s.set_control_bounds(&m::LBU, &ub).unwrap();
    let (u_before, x_before) = (s.control_bounds(), s.state_bounds());
    assert_eq!(
        x_before,
        ([-f64::INFINITY; m::NX_MODEL], [f64::INFINITY; m::NX_MODEL])
    );
    let with = |v: [f64; m::NU], i: usize, e: f64| {
        let mut v = v;
        v[i] = e;
        v
    };
    let refusals = [
        (with(m::LBU, 1, f64::NAN), ub, NonFinite),
        (m::LBU, with(ub, 3, f64::NAN), NonFinite),
        (
            with(m::LBU, 0, f64::INFINITY),
            with(ub, 0, f64::INFINITY),
            NonFinite,
        ),
        (
            with(m::LBU, 0, -f64::INFINITY),
            with(ub, 0, -f64::INFINITY),
            NonFinite,
        ),
        (with(m::LBU, 0, 13.0), ub, CrossedBounds),
    ];
    for (lb, ub, err) in refusals {
        assert_eq!(s.set_control_bounds(&lb, &ub), Err(err), "{lb:?} {ub:?}");
        assert_eq!((s.control_bounds(), s.state_bounds()), (u_before, x_before));
    }
    assert_eq!(m::NBX, 0);
    let (lbx, mut ubx) = x_before;
    ubx[m::STATE_P.start + 2] = 4.0;
    assert_eq!(s.set_state_bounds(&lbx, &ubx), Err(TooManyStateBounds));
    let mut nan = lbx;
    nan[0] = f64::NAN;
    assert_eq!(s.set_state_bounds(&nan, &x_before.1), Err(NonFinite));
    assert_eq!((s.control_bounds(), s.state_bounds()), (u_before, x_before));
    // No general constraints: their setters take (and their getters give) empty arrays.
    assert_eq!((m::NG, m::NGN), (0, 0));
    assert_eq!(s.set_constraint_bounds(&[], &[]), Ok(()));
    assert_eq!(s.set_terminal_constraint_bounds(&[], &[]), Ok(()));
    assert_eq!(s.constraint_bounds(), ([], []));
}

/// A state bound set at run time on the point mass (3 state-bound rows, its accelerations):
/// the z acceleration's row given to the height, `z <= 0.2` holds along the converged plan
/// from a climb at 1 m/s toward a reference 1 m up, which the unbounded plan passes. The
/// input-rate states appended to the model's keep their (absent) bounds; a fourth bounded
/// state is refused.
#[test]
fn state_bounds_set_at_run_time_bound_the_plan() {
    use paper_pointmass as m;
    const Z: usize = 2;
    let plan_top = |s: &mut m::Solver| {
        let mut xref = [0.0; m::NX_MODEL];
        xref[Z] = 1.0;
        s.set_xref_all(&xref).unwrap();
        let mut x0 = [0.0; m::NX_MODEL];
        x0[m::STATE_VEL.start + 2] = 1.0;
        s.set_x0(&x0).unwrap();
        let info = s.solve_sqp();
        assert_eq!(info.status, m::RtiStatus::Ok, "{info:?}");
        (1..=m::N)
            .map(|k| s.state(k).unwrap()[Z])
            .fold(f64::MIN, f64::max)
    };
    let mut free = Box::new(m::Solver::new());
    let (lbx, ubx) = free.state_bounds();
    let free_top = plan_top(&mut free);
    assert!(free_top > 0.25, "unbounded plan's highest z: {free_top}");

    let mut s = Box::new(m::Solver::new());
    let (mut lb, mut ub) = (lbx, ubx);
    let az = m::STATE_ACC.start + 2;
    (lb[az], ub[az]) = (-f64::INFINITY, f64::INFINITY);
    ub[Z] = 0.2;
    s.set_state_bounds(&lb, &ub).unwrap();
    assert_eq!(s.state_bounds(), (lb, ub));
    let (all_lbx, all_ubx, _, _) = s.rti().bounds();
    for i in m::NX_MODEL..m::NX {
        assert_eq!(
            (all_lbx[i], all_ubx[i]),
            (m::LBX[i], m::UBX[i]),
            "state {i}"
        );
    }
    let top = plan_top(&mut s);
    assert!(top <= 0.2 + 1e-6, "bounded plan's highest z: {top}");
    assert!(top > 0.2 - 1e-3, "the bound is active: {top}");

    let mut four = lbx;
    four[Z] = -1.0;
    assert_eq!(
        s.set_state_bounds(&four, &ubx),
        Err(m::SetError::TooManyStateBounds)
    );
    assert_eq!(s.state_bounds(), (lb, ub));
}

/// The probe's two soft constraint rows: their bounds read back as the model file's, a new
/// pair is taken and read back, NaN and crossed pairs are refused and change nothing; the
/// probe has no terminal rows.
#[test]
fn constraint_bounds_set_at_run_time_are_kept() {
    use quadrotor_probe as m;
    let mut s = Box::new(m::Solver::new());
    assert_eq!(s.constraint_bounds(), (m::LG, m::UG));
    let (lg, ug) = ([-0.5, -0.25], [0.5, f64::INFINITY]);
    s.set_constraint_bounds(&lg, &ug).unwrap();
    assert_eq!(s.constraint_bounds(), (lg, ug));
    assert_eq!(
        s.set_constraint_bounds(&[f64::NAN, 0.0], &ug),
        Err(m::SetError::NonFinite)
    );
    assert_eq!(
        s.set_constraint_bounds(&[0.6, 0.0], &ug),
        Err(m::SetError::CrossedBounds)
    );
    assert_eq!(s.constraint_bounds(), (lg, ug));
    assert_eq!(s.terminal_constraint_bounds(), ([], []));
    assert_eq!(s.set_terminal_constraint_bounds(&[], &[]), Ok(()));
}

/// The f32 solver that condenses (QR-bench A) takes run-time control bounds too: one
/// real-time iteration toward a reference 5 m above asks for more than 12 m/s^2 of thrust,
/// and exactly 12 (to f32 accuracy) once `c <= 12` is set.
#[test]
fn control_bounds_set_at_run_time_bound_the_condensed_f32_solver() {
    use quadrotor_rates_f32 as m;
    let climb = |s: &mut m::Solver| {
        let x0 = [0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut xref = x0;
        xref[2] += 5.0;
        s.set_xref_all(&xref).unwrap();
        s.set_guess(&x0, &[9.81, 0.0, 0.0, 0.0]).unwrap();
        s.prepare();
        assert!(s.rti().condensed());
        s.set_x0(&x0).unwrap();
        assert_eq!(s.feedback().status, m::RtiStatus::Ok);
        s.u0()[m::CONTROL_C.start]
    };
    let free = climb(&mut m::Solver::new());
    assert!(free > 12.5, "unbounded thrust {free}");
    let mut s = Box::new(m::Solver::new());
    let mut ub = m::UBU;
    ub[m::CONTROL_C.start] = 12.0;
    s.set_control_bounds(&m::LBU, &ub).unwrap();
    assert_eq!(s.control_bounds(), (m::LBU, ub));
    let c = climb(&mut s);
    assert!((c - 12.0).abs() <= 1e-4, "bounded thrust {c}");
}

/// A parameter that feeds a weight (`q_w`, the diagonal of Q in `paper_pointmass`) is
/// refused at set time if it makes the weight negative, by every setter that reaches it,
/// and nothing changes; a positive one is accepted and reaches the solver's weights.
#[test]
fn parameters_that_make_a_weight_negative_are_refused() {
    use paper_pointmass as m;
    let mut s = Box::new(m::Solver::new());
    let before: Vec<_> = (0..=m::N).map(|k| s.param(k).unwrap()).collect();
    let w_before = *s.rti().weights().0;
    let mut q = [1.0; 9];
    q[4] = -0.5;
    assert_eq!(s.set_q_w(&q), Err(m::SetError::NegativeWeight));
    let mut p = before[0];
    p[m::PARAM_Q_W.start + 4] = -0.5;
    assert_eq!(s.set_param(0, &p), Err(m::SetError::NegativeWeight));
    assert_eq!(s.set_param_all(&p), Err(m::SetError::NegativeWeight));
    let after: Vec<_> = (0..=m::N).map(|k| s.param(k).unwrap()).collect();
    assert_eq!(after, before);
    assert_eq!(*s.rti().weights().0, w_before);
    q[4] = 0.5;
    assert_eq!(s.set_q_w(&q), Ok(()));
    assert_eq!(s.rti().weights().0[(4, 4)], 0.5);
}

/// The generated `set_settings` validates; `set_trajectory_guess` and `trajectory` round-trip
/// (the appended input-rate states of stage `k >= 1` take `u[k - 1]`); the soft-penalty and
/// read-out methods exist on a model without general rows.
#[test]
fn generated_run_time_api_round_trips() {
    use paper_pointmass as m;
    let mut s = Box::new(m::Solver::new());
    let mut bad = *s.settings();
    bad.qp.tol_stat = -1.0;
    assert_eq!(s.set_settings(&bad), Err(m::SetError::InvalidSetting));
    let mut good = *s.settings();
    good.shift = !good.shift;
    assert_eq!(s.set_settings(&good), Ok(()));
    assert_eq!(*s.settings(), good);
    let x: [[f64; m::NX_MODEL]; m::N + 1] =
        core::array::from_fn(|k| core::array::from_fn(|i| (k * 10 + i) as f64 * 0.01));
    let u: [[f64; m::NU]; m::N] = core::array::from_fn(|k| [k as f64, 0.5, -0.5]);
    s.set_trajectory_guess(&x, &u).unwrap();
    let (mut xb, mut ub) = ([[0.0; m::NX_MODEL]; m::N + 1], [[0.0; m::NU]; m::N]);
    s.trajectory(&mut xb, &mut ub);
    assert_eq!((xb, ub), (x, u));
    assert_eq!(s.rti().state(3).unwrap()[m::NX_MODEL], u[2][0]);
    let mut xn = x;
    xn[2][1] = f64::NAN;
    assert_eq!(s.set_trajectory_guess(&xn, &u), Err(m::SetError::NonFinite));
    s.trajectory(&mut xb, &mut ub);
    assert_eq!(xb, x);
    assert_eq!(s.set_soft_penalties(&[], &[]), Ok(()));
    assert_eq!(s.soft_penalties(), ([], []));
    s.set_x0(&[0.1; m::NX_MODEL]).unwrap();
    assert_eq!(s.solve_sqp().status, m::RtiStatus::Ok);
    assert!(s.kkt_residual().unwrap() <= 1e-5);
    assert!(s.cost() > 0.0);
}
