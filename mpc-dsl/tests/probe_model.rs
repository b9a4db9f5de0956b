//! `models/quadrotor_probe.mpc` against independent references: a 5x5 mass-matrix solve of
//! the Lagrange equations (nalgebra), the Euler-Lagrange residual of the Lagrangian built
//! with the symbolic AD, energy conservation in free swing, the hanging equilibrium, and
//! mp = 0 reducing to QR-bench.
//!
//! The model's actuator lags (states `wb`, `ct` behind the setpoints `w`, `c`) are checked
//! apart: the other 14 derivatives, evaluated with the lag states equal to a control vector
//! `u = (c, w)`, are those of the lag-free model with `u` as its input, and the lag
//! derivatives are first order with the parameters `tau_w`, `tau_c`.

use mpc_dsl::lang::{ParseOptions, parse};
use mpc_dsl::ocp::Ocp;
use mpc_dsl::{Expr, Graph, Program};
use nalgebra::{Matrix3x2, SMatrix, SVector, Vector3};

const SRC: &str = include_str!("../../models/quadrotor_probe.mpc");
const G: f64 = 9.81;
const L: f64 = 0.5;

mod common;
use common::Rng;

fn model(g: &Graph) -> Ocp<'_> {
    match parse(g, SRC, &ParseOptions::default()) {
        Ok(p) => {
            assert!(p.warnings.is_empty());
            p.ocp
        }
        Err(e) => panic!("{}", e.render("quadrotor_probe.mpc", SRC)),
    }
}

/// Number of states of the lag-free model (p, q, v, ang, dang); the lag states wb (14..17)
/// and ct (17) follow.
const NX0: usize = 14;
/// Defaults of the lag time constants in the model file.
const TAU_W: f64 = 0.04;
const TAU_C: f64 = 0.03;

/// f(x, u, [mq, mp, tau_w, tau_c]) as a program over (x, u, mq, mp, tau_w, tau_c).
fn program(g: &Graph, ocp: &Ocp<'_>) -> Program {
    let mut inputs: Vec<Expr<'_>> = ocp.x().to_vec();
    inputs.extend(ocp.u().iter().copied());
    for name in ["mq", "mp", "tau_w", "tau_c"] {
        inputs.push(ocp.variable(name).unwrap().symbols[0]);
    }
    g.compile(ocp.dynamics_exprs(), &inputs).unwrap()
}

/// All 18 derivatives of the model at the full state `x` (lag states included).
#[allow(clippy::too_many_arguments)]
fn f_full(
    prog: &Program,
    x: &[f64],
    u: &[f64],
    mq: f64,
    mp: f64,
    tau_w: f64,
    tau_c: f64,
) -> Vec<f64> {
    assert_eq!((x.len(), u.len()), (NX0 + 4, 4));
    let mut input = x.to_vec();
    input.extend_from_slice(u);
    input.extend_from_slice(&[mq, mp, tau_w, tau_c]);
    prog.eval(&input).unwrap()
}

/// The lag-free model seen through the lags: the 14 derivatives of (p, q, v, ang, dang) at
/// the state `x` (14 entries) extended with delivered rates wb = u[1..4] and thrust ct = u[0].
/// They must not depend on the setpoints or the time constants (only on what is delivered):
/// evaluated again with other setpoints and other tau, they are bit for bit the same; and
/// with the setpoints equal to the delivered values the lag states are at rest.
fn f(prog: &Program, x: &[f64], u: &[f64], mq: f64, mp: f64) -> Vec<f64> {
    assert_eq!((x.len(), u.len()), (NX0, 4));
    let mut xl = x.to_vec();
    xl.extend_from_slice(&u[1..4]);
    xl.push(u[0]);
    let d = f_full(prog, &xl, u, mq, mp, TAU_W, TAU_C);
    assert!(
        d[NX0..].iter().all(|v| *v == 0.0),
        "setpoints = delivered values: the lags rest, {:?}",
        &d[NX0..]
    );
    let other_setpoints = [u[0] + 1.7, u[1] - 0.9, u[2] + 0.4, u[3] - 1.3];
    let d2 = f_full(prog, &xl, &other_setpoints, mq, mp, 0.11, 0.07);
    assert_eq!(
        &d[..NX0],
        &d2[..NX0],
        "the vehicle and swing derivatives depend on the setpoints or tau"
    );
    d[..NX0].to_vec()
}

/// Link direction and its derivatives, hand-written.
fn link(a: f64, b: f64) -> (Vector3<f64>, Matrix3x2<f64>, [Vector3<f64>; 3]) {
    let (sa, ca, sb, cb) = (a.sin(), a.cos(), b.sin(), b.cos());
    let n = Vector3::new(sa * cb, sb, -ca * cb);
    let na = Vector3::new(ca * cb, 0.0, sa * cb);
    let nb = Vector3::new(-sa * sb, cb, ca * sb);
    let naa = Vector3::new(-sa * cb, 0.0, ca * cb);
    let nab = Vector3::new(-ca * sb, 0.0, -sa * sb);
    let nbb = Vector3::new(-sa * cb, -sb, ca * cb);
    (n, Matrix3x2::from_columns(&[na, nb]), [naa, nab, nbb])
}

/// Thrust direction R(q) e3 for a (not necessarily unit) quaternion, QR-bench formula.
fn body_z(q: &[f64]) -> Vector3<f64> {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    Vector3::new(
        2.0 * (w * y + x * z),
        2.0 * (y * z - w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

/// Reference: (P'', theta'') from the Lagrange equations written as a 5x5 linear system
/// [M I, mp l J; mp l J', mp l^2 J'J] [P''; theta''] = [F - M g e3 - mp l h; -mp l J'(l h + g e3)].
fn lagrange_reference(x: &[f64], u: &[f64], mq: f64, mp: f64) -> (Vector3<f64>, [f64; 2]) {
    let m = mq + mp;
    let (_, j, [naa, nab, nbb]) = link(x[10], x[11]);
    let (da, db) = (x[12], x[13]);
    let h = naa * da * da + nab * (2.0 * da * db) + nbb * db * db;
    let e3 = Vector3::z();
    let force = body_z(&x[3..7]) * (m * u[0]);
    let mut a = SMatrix::<f64, 5, 5>::zeros();
    let mut rhs = SVector::<f64, 5>::zeros();
    for i in 0..3 {
        a[(i, i)] = m;
        for k in 0..2 {
            a[(i, 3 + k)] = mp * L * j[(i, k)];
            a[(3 + k, i)] = mp * L * j[(i, k)];
        }
    }
    let jtj = j.transpose() * j;
    for r in 0..2 {
        for c in 0..2 {
            a[(3 + r, 3 + c)] = mp * L * L * jtj[(r, c)];
        }
    }
    let top = force - e3 * (m * G) - h * (mp * L);
    let bottom = -(j.transpose() * (h * L + e3 * G)) * (mp * L);
    rhs.fixed_rows_mut::<3>(0).copy_from(&top);
    rhs.fixed_rows_mut::<2>(3).copy_from(&bottom);
    let sol = a
        .lu()
        .solve(&rhs)
        .expect("mass matrix is regular for mp > 0, |beta| < pi/2");
    (Vector3::new(sol[0], sol[1], sol[2]), [sol[3], sol[4]])
}

fn random_state(rng: &mut Rng) -> Vec<f64> {
    let mut x: Vec<f64> = (0..14).map(|_| rng.uniform(-1.0, 1.0)).collect();
    x[11] = rng.uniform(-1.2, 1.2); // keep away from the beta = pi/2 gimbal
    x[12] = rng.uniform(-3.0, 3.0);
    x[13] = rng.uniform(-3.0, 3.0);
    x
}

#[test]
fn probe_model_matches_the_mass_matrix_solve() {
    let g = Graph::new();
    let ocp = model(&g);
    // Parameters: mq, mp, tau_w, tau_c (1 each), q_w[18], p_w[18], r_w[4], vthrow[3],
    // w_throw, z_floor (1 each); stage: xref[18], uref[4].
    assert_eq!(
        (ocp.nx(), ocp.nu(), ocp.np()),
        (18, 4, 4 + 18 + 18 + 4 + 3 + 2 + 18 + 4)
    );
    let prog = program(&g, &ocp);
    let mut rng = Rng(0xdead_beef);
    for _ in 0..200 {
        let x = random_state(&mut rng);
        let u = [rng.uniform(0.0, 20.0), 0.3, -0.2, 0.1];
        let (mq, mp) = (rng.uniform(0.5, 3.0), rng.uniform(0.05, 1.0));
        let got = f(&prog, &x, &u, mq, mp);
        let (acc, th) = lagrange_reference(&x, &u, mq, mp);
        let want = [acc.x, acc.y, acc.z, x[12], x[13], th[0], th[1]];
        let got_sel = [got[7], got[8], got[9], got[10], got[11], got[12], got[13]];
        for (a, b) in got_sel.iter().zip(&want) {
            assert!(
                (a - b).abs() <= 1e-9 * (1.0 + b.abs()),
                "{got_sel:?} vs {want:?}"
            );
        }
        assert_eq!(&got[0..3], &x[7..10]);
    }
}

/// The Euler-Lagrange equations of L(P, theta, P', theta'), built and differentiated
/// symbolically here (not from the model file), hold for the model's accelerations:
/// d/dt dL/dq' - dL/dq = Q with d/dt dL/dq' = (d2L/dq'dq) q' + (d2L/dq'2) q''.
#[test]
fn probe_model_satisfies_euler_lagrange() {
    let gm = Graph::new();
    let ocp = model(&gm);
    let prog = program(&gm, &ocp);

    let g = Graph::new();
    let q = g.symbols("q", 5); // x, y, z, alpha, beta
    let qd = g.symbols("qd", 5);
    let (mq, mp) = (g.symbol("mq"), g.symbol("mp"));
    let (a, b) = (q[3], q[4]);
    let n = [a.sin() * b.cos(), b.sin(), -(a.cos() * b.cos())];
    // n' by the chain rule, symbolically.
    let ndot: Vec<Expr<'_>> = n
        .iter()
        .map(|&ni| {
            let gr = g.gradient(ni, &[a, b]).unwrap();
            gr[0] * qd[3] + gr[1] * qd[4]
        })
        .collect();
    let vp: Vec<Expr<'_>> = (0..3).map(|i| qd[i] + L * ndot[i]).collect();
    let kin = 0.5 * mq * (qd[0].square() + qd[1].square() + qd[2].square())
        + 0.5 * mp * (vp[0].square() + vp[1].square() + vp[2].square());
    let pot = mq * G * q[2] + mp * G * (q[2] + L * n[2]);
    let lag = kin - pot;
    let mut vars: Vec<Expr<'_>> = q.to_vec();
    vars.extend(qd.iter().copied());
    let dl_dq = g.gradient(lag, &q).unwrap();
    let dl_dqd = g.gradient(lag, &qd).unwrap();
    let h_qd_q = g.jacobian(&dl_dqd, &q).unwrap().to_dense();
    let h_qd_qd = g.jacobian(&dl_dqd, &qd).unwrap().to_dense();

    let mut rng = Rng(99);
    for _ in 0..50 {
        let x = random_state(&mut rng);
        let u = [rng.uniform(0.0, 20.0), 0.0, 0.0, 0.0];
        let (m_q, m_p) = (rng.uniform(0.5, 3.0), rng.uniform(0.05, 1.0));
        let xd = f(&prog, &x, &u, m_q, m_p);
        let qv = [x[0], x[1], x[2], x[10], x[11]];
        let qdv = [x[7], x[8], x[9], x[12], x[13]];
        let qdd = [xd[7], xd[8], xd[9], xd[12], xd[13]];
        let mut bind: Vec<(Expr<'_>, f64)> = vars
            .iter()
            .copied()
            .zip(qv.iter().chain(&qdv).copied())
            .collect();
        bind.push((mq, m_q));
        bind.push((mp, m_p));
        let ev = |e: &[Expr<'_>]| g.eval(e, &bind).unwrap();
        let dq = ev(&dl_dq);
        let hq = ev(h_qd_q.as_row_major());
        let hqd = ev(h_qd_qd.as_row_major());
        let force = body_z(&x[3..7]) * ((m_q + m_p) * u[0]);
        let gen_force = [force.x, force.y, force.z, 0.0, 0.0];
        for i in 0..5 {
            let ddt: f64 = (0..5)
                .map(|j| hq[i * 5 + j] * qdv[j] + hqd[i * 5 + j] * qdd[j])
                .sum();
            let res = ddt - dq[i] - gen_force[i];
            assert!(
                res.abs() < 1e-8 * (1.0 + gen_force[i].abs() + dq[i].abs()),
                "row {i}: {res}"
            );
        }
    }
}

fn energy(x: &[f64], mq: f64, mp: f64) -> f64 {
    let (n, j, _) = link(x[10], x[11]);
    let v = Vector3::new(x[7], x[8], x[9]);
    let vp = v + j * nalgebra::Vector2::new(x[12], x[13]) * L;
    0.5 * mq * v.norm_squared()
        + 0.5 * mp * vp.norm_squared()
        + mq * G * x[2]
        + mp * G * (x[2] + L * n.z)
}

/// RK4 on the model with the work done by the thrust integrated alongside (W' = F.v).
fn simulate(
    prog: &Program,
    x0: &[f64],
    u: &[f64],
    mq: f64,
    mp: f64,
    h: f64,
    steps: usize,
) -> Vec<(Vec<f64>, f64)> {
    let rhs = |x: &[f64]| -> Vec<f64> {
        let mut d = f(prog, &x[..14], u, mq, mp);
        let force = body_z(&x[3..7]) * ((mq + mp) * u[0]);
        d.push(force.dot(&Vector3::new(x[7], x[8], x[9])));
        d
    };
    let mut x: Vec<f64> = x0.to_vec();
    x.push(0.0);
    let mut out = vec![(x[..14].to_vec(), 0.0)];
    let axpy = |x: &[f64], k: &[f64], s: f64| -> Vec<f64> {
        x.iter().zip(k).map(|(a, b)| a + s * b).collect()
    };
    for _ in 0..steps {
        let k1 = rhs(&x);
        let k2 = rhs(&axpy(&x, &k1, h / 2.0));
        let k3 = rhs(&axpy(&x, &k2, h / 2.0));
        let k4 = rhs(&axpy(&x, &k3, h));
        for i in 0..x.len() {
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        out.push((x[..14].to_vec(), x[14]));
    }
    out
}

#[test]
fn free_swing_conserves_energy() {
    let g = Graph::new();
    let ocp = model(&g);
    let prog = program(&g, &ocp);
    let (mq, mp) = (1.5, 0.2);
    // Hover thrust, level attitude, zero body rates; the probe swings from 0.6 / -0.4 rad.
    let mut x0 = vec![0.0; 14];
    x0[3] = 1.0;
    x0[2] = 2.0;
    x0[10] = 0.6;
    x0[11] = -0.4;
    x0[12] = 0.5;
    for (u, label) in [
        ([G, 0.0, 0.0, 0.0], "hover thrust"),
        ([0.0; 4], "no thrust"),
    ] {
        let traj = simulate(&prog, &x0, &u, mq, mp, 1e-3, 2000);
        let e0 = energy(&x0, mq, mp);
        let mut max_swing: f64 = 0.0;
        for (x, work) in &traj {
            let drift = energy(x, mq, mp) - work - e0;
            assert!(
                drift.abs() < 1e-9 * e0.abs().max(1.0),
                "{label}: energy drift {drift}"
            );
            max_swing = max_swing.max(x[10].abs());
        }
        assert!(max_swing > 0.5, "{label}: the probe actually swings");
    }
}

#[test]
fn equilibrium_hangs_straight_down() {
    let g = Graph::new();
    let ocp = model(&g);
    let prog = program(&g, &ocp);
    let mut x = vec![0.0; 14];
    x[3] = 1.0;
    x[0] = 4.0;
    x[2] = 2.0;
    for &(mq, mp) in &[(1.5, 0.2), (1.0, 0.0), (2.0, 1.0)] {
        let xd = f(&prog, &x, &[G, 0.0, 0.0, 0.0], mq, mp);
        assert!(xd.iter().all(|v| v.abs() < 1e-12), "{xd:?}");
    }
    // Displaced, the probe is pulled back (restoring accelerations).
    for (k, s) in [(10, 0.2), (10, -0.2), (11, 0.2), (11, -0.2)] {
        let mut y = x.clone();
        y[k] = s;
        let yd = f(&prog, &y, &[G, 0.0, 0.0, 0.0], 1.5, 0.2);
        assert!(yd[k + 2] * s < 0.0, "angle {k} = {s}: {}", yd[k + 2]);
    }
    // The potential at fixed vehicle height is smallest straight down.
    let pot = |a: f64, b: f64| {
        energy(
            &[
                0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, a, b, 0.0, 0.0,
            ],
            1.5,
            0.2,
        )
    };
    for a in [-0.5, -0.1, 0.1, 0.5] {
        assert!(pot(a, 0.0) > pot(0.0, 0.0) && pot(0.0, a) > pot(0.0, 0.0));
    }
}

#[test]
fn without_the_probe_it_is_qr_bench() {
    let g = Graph::new();
    let ocp = model(&g);
    let prog = program(&g, &ocp);
    let mut rng = Rng(4242);
    for _ in 0..100 {
        let x = random_state(&mut rng);
        let u = [
            rng.uniform(0.0, 20.0),
            rng.uniform(-5.0, 5.0),
            rng.uniform(-5.0, 5.0),
            rng.uniform(-5.0, 5.0),
        ];
        let xd = f(&prog, &x, &u, rng.uniform(0.5, 3.0), 0.0);
        let acc = body_z(&x[3..7]) * u[0] - Vector3::z() * G;
        for i in 0..3 {
            assert!((xd[7 + i] - acc[i]).abs() < 1e-12 * (1.0 + acc[i].abs()));
        }
    }
}

/// `0.5 q ⊗ (0, w)`, the Hamilton product written out.
fn quat_kinematics(q: &[f64], w: &[f64]) -> [f64; 4] {
    let (a, b, c, d) = (q[0], q[1], q[2], q[3]);
    [
        0.5 * (-b * w[0] - c * w[1] - d * w[2]),
        0.5 * (a * w[0] + c * w[2] - d * w[1]),
        0.5 * (a * w[1] - b * w[2] + d * w[0]),
        0.5 * (a * w[2] + b * w[1] - c * w[0]),
    ]
}

/// The lag states: der(wb) = (w - wb)/tau_w and der(ct) = (c - ct)/tau_c at random points
/// (random tau, setpoints and delivered values apart); the attitude turns with the delivered
/// rates wb and the vehicle accelerates with the delivered thrust ct, not the setpoints; with
/// mp = 0 the swing is frozen (der(dang) = 0) and with mp = 0.2 der(dang) is the mass-matrix
/// solve's (the `live` factor is 1 - 5e-12 there).
#[test]
fn lags_are_first_order_and_the_swing_freezes_without_probe() {
    let g = Graph::new();
    let ocp = model(&g);
    let prog = program(&g, &ocp);
    let mut rng = Rng(0x1a95);
    for _ in 0..200 {
        let mut x = random_state(&mut rng);
        let wb = [
            rng.uniform(-4.0, 4.0),
            rng.uniform(-4.0, 4.0),
            rng.uniform(-2.0, 2.0),
        ];
        let ct = rng.uniform(0.0, 25.0);
        x.extend_from_slice(&wb);
        x.push(ct);
        let u = [
            rng.uniform(0.0, 30.0),
            rng.uniform(-6.0, 6.0),
            rng.uniform(-6.0, 6.0),
            rng.uniform(-3.0, 3.0),
        ];
        let (tau_w, tau_c) = (rng.uniform(0.01, 0.3), rng.uniform(0.01, 0.3));
        let mq = rng.uniform(0.5, 3.0);
        let delivered = [ct, wb[0], wb[1], wb[2]];
        for mp in [0.2, 0.0] {
            let d = f_full(&prog, &x, &u, mq, mp, tau_w, tau_c);
            for i in 0..3 {
                let want = (u[1 + i] - wb[i]) / tau_w;
                assert!(
                    (d[NX0 + i] - want).abs() <= 1e-14 * want.abs().max(1.0),
                    "der(wb[{i}]) = {} vs {want}",
                    d[NX0 + i]
                );
            }
            let want = (u[0] - ct) / tau_c;
            assert!(
                (d[NX0 + 3] - want).abs() <= 1e-14 * want.abs().max(1.0),
                "der(ct) = {} vs {want}",
                d[NX0 + 3]
            );
            let qd = quat_kinematics(&x[3..7], &wb);
            for i in 0..4 {
                assert!(
                    (d[3 + i] - qd[i]).abs() <= 1e-14 * (1.0 + qd[i].abs()),
                    "der(q) with wb: {:?} vs {qd:?}",
                    &d[3..7]
                );
            }
            assert_eq!(&d[0..3], &x[7..10], "der(p) = v");
            assert_eq!(&d[10..12], &x[12..14], "der(ang) = dang");
            if mp == 0.0 {
                assert_eq!(&d[12..14], &[0.0, 0.0], "frozen swing without the probe");
                let acc = body_z(&x[3..7]) * ct - Vector3::z() * G;
                for i in 0..3 {
                    assert!((d[7 + i] - acc[i]).abs() < 1e-12 * (1.0 + acc[i].abs()));
                }
            } else {
                let (acc, th) = lagrange_reference(&x, &delivered, mq, mp);
                let want = [acc.x, acc.y, acc.z, th[0], th[1]];
                let got = [d[7], d[8], d[9], d[12], d[13]];
                for (a, b) in got.iter().zip(&want) {
                    assert!(
                        (a - b).abs() <= 1e-9 * (1.0 + b.abs()),
                        "{got:?} vs {want:?}"
                    );
                }
            }
        }
    }
}

/// The probe model through the Rust builder, operation for operation as in the file.
fn probe_builder(g: &Graph) -> Ocp<'_> {
    use mpc_dsl::linalg::{Matrix, dot, quat_mul, quat_rotate};
    use mpc_dsl::ocp::{Decl, Integrator, Slack, Stage};
    let mut b = Ocp::builder(g, "quadrotor_probe");
    let p = b.state(
        Decl::vector("p", 3)
            .unit("m")
            .describe("vehicle position, world frame, z up"),
    );
    let q = b.state(
        Decl::vector("q", 4)
            .describe("attitude quaternion body->world (w, x, y, z)")
            .start(&[1.0, 0.0, 0.0, 0.0]),
    );
    let v = b.state(
        Decl::vector("v", 3)
            .unit("m/s")
            .describe("vehicle velocity, world frame"),
    );
    let ang = b.state(
        Decl::vector("ang", 2)
            .unit("rad")
            .describe("swing angles (alpha in-plane, beta out-of-plane)"),
    );
    let dang = b.state(
        Decl::vector("dang", 2)
            .unit("rad/s")
            .describe("swing rates"),
    );
    let wb = b.state(
        Decl::vector("wb", 3)
            .unit("rad/s")
            .describe("body rates as the rate loop delivers them (first-order lag behind w)"),
    );
    let ct = b.state(
        Decl::scalar("ct")
            .unit("m/s^2")
            .describe("collective thrust as the rotors deliver it (first-order lag behind c)")
            .start(&[9.81]),
    )[0];
    let c = b.control(
        Decl::scalar("c")
            .unit("m/s^2")
            .describe("collective thrust setpoint, normalized by the total mass mq + mp"),
    );
    let w = b.control(
        Decl::vector("w", 3)
            .unit("rad/s")
            .describe("body-rate setpoint (x, y, z) for the rate loop"),
    );
    let mq = b.global_param(
        Decl::scalar("mq")
            .unit("kg")
            .describe("vehicle mass (ours: 1.5 kg)")
            .start(&[1.5]),
    )[0];
    let mp = b.global_param(
        Decl::scalar("mp")
            .unit("kg")
            .describe("probe mass (0 after release)")
            .start(&[0.2]),
    )[0];
    let tau_w = b.global_param(
        Decl::scalar("tau_w")
            .unit("s")
            .describe("time constant of the rate loop's response")
            .start(&[0.04]),
    )[0];
    let tau_c = b.global_param(
        Decl::scalar("tau_c")
            .unit("s")
            .describe("time constant of the rotors' thrust response")
            .start(&[0.03]),
    )[0];
    let q_w = b.global_param(Decl::vector("q_w", 18).describe("diagonal of Q").start(&[
        100.0, 100.0, 100.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.1, 0.1, 0.0, 0.0,
        0.0, 0.0,
    ]));
    let p_w = b.global_param(Decl::vector("p_w", 18).describe("diagonal of P").start(&[
        500.0, 500.0, 500.0, 50.0, 50.0, 50.0, 50.0, 5.0, 5.0, 5.0, 5.0, 5.0, 0.5, 0.5, 0.0, 0.0,
        0.0, 0.0,
    ]));
    let r_w = b.global_param(
        Decl::vector("r_w", 4)
            .describe("diagonal of R")
            .start(&[0.5, 1.0, 1.0, 1.0]),
    );
    let vthrow = b.global_param(
        Decl::vector("vthrow", 3)
            .unit("m/s")
            .describe("probe velocity wanted at the end of the horizon (throw planning)")
            .start(&[0.0, 0.0, 0.0]),
    );
    let w_throw = b.global_param(
        Decl::scalar("w_throw")
            .describe("weight of the terminal probe-velocity residual (0: tracking)")
            .start(&[0.0]),
    )[0];
    let z_floor = b.global_param(
        Decl::scalar("z_floor")
            .unit("m")
            .describe("soft floor on the vehicle's height (lower it to land)")
            .start(&[1.0]),
    )[0];
    let xref = b.stage_param(
        Decl::vector("xref", 18)
            .describe("state reference")
            .start(&[
                4.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 9.81,
            ]),
    );
    let uref = b.stage_param(
        Decl::vector("uref", 4)
            .describe("control reference")
            .start(&[9.81, 0.0, 0.0, 0.0]),
    );
    let z = g.zero();
    let m = mq + mp;
    let (sa, ca, sb, cb) = (ang[0].sin(), ang[0].cos(), ang[1].sin(), ang[1].cos());
    let n = [sa * cb, sb, -ca * cb];
    let na = [ca * cb, z, sa * cb];
    let nb = [-sa * sb, cb, ca * sb];
    let ndot2 = cb.powi(2) * dang[0].powi(2) + dang[1].powi(2);
    let thrust: Vec<Expr<'_>> = quat_rotate(&q, &[z, z, ct])
        .unwrap()
        .iter()
        .map(|&e| m * e)
        .collect();
    let k = mp * (G * n[2] - L * ndot2);
    let bv: Vec<Expr<'_>> = (0..3)
        .map(|i| {
            let grav = if i == 2 { G * mq } else { z };
            thrust[i] - grav - k * n[i]
        })
        .collect();
    let s = mp / m * dot(&n, &bv).unwrap();
    let acc: Vec<Expr<'_>> = (0..3).map(|i| (bv[i] - s * n[i]) / mq).collect();
    let gacc = [acc[0], acc[1], acc[2] + G];
    let live = mp / (mp + 1e-12);
    let dd = [
        live * (-dot(&na, &gacc).unwrap() / (L * cb.powi(2)) + 2.0 * sb / cb * dang[0] * dang[1]),
        live * (-dot(&nb, &gacc).unwrap() / L - sb * cb * dang[0].powi(2)),
    ];
    let qd = quat_mul(&q, &[z, wb[0], wb[1], wb[2]]).unwrap().scale(0.5);
    let dwb: Vec<Expr<'_>> = (0..3).map(|i| (w[i] - wb[i]) / tau_w).collect();
    let dct = (c[0] - ct) / tau_c;
    let xdot: Vec<Expr<'_>> = v
        .iter()
        .chain(qd.iter())
        .chain(&acc)
        .chain(dang.iter())
        .chain(&dd)
        .chain(&dwb)
        .chain(&[dct])
        .copied()
        .collect();
    b.ode(&xdot, Integrator::Rk4 { steps: 2 });
    b.horizon(20, 0.05);
    let vprobe: Vec<Expr<'_>> = (0..3)
        .map(|i| v[i] + L * (na[i] * dang[0] + nb[i] * dang[1]))
        .collect();
    let throw: Vec<Expr<'_>> = (0..3).map(|i| vprobe[i] - vthrow[i]).collect();
    b.state_cost(Matrix::diag(g, &q_w), &xref);
    b.control_cost(Matrix::diag(g, &r_w), &uref);
    b.terminal_cost(Matrix::diag(g, &p_w), &xref);
    b.residual(
        "throw",
        Stage::Terminal,
        &throw,
        Matrix::identity(g, 3).scale(w_throw),
    );
    b.bound(&c, 0.0, 30.0);
    b.bound(&w[0..2], -20.0, 20.0);
    b.bound(&w[2..3], -6.0, 6.0);
    b.soft_constraint(
        "swing_gimbal",
        Stage::Path,
        &ang[1..2],
        &[-1.4],
        &[1.4],
        Slack {
            l1: 100.0,
            l2: 100.0,
        },
    );
    b.soft_constraint(
        "floor",
        Stage::Path,
        &[p[2] - z_floor],
        &[0.0],
        &[f64::INFINITY],
        Slack {
            l1: 100.0,
            l2: 1000.0,
        },
    );
    b.build().unwrap()
}

#[test]
fn probe_file_equals_builder() {
    let g = Graph::new();
    let parsed = model(&g);
    let built = probe_builder(&g);
    assert_eq!(parsed.dynamics, built.dynamics);
    assert_eq!(parsed, built);
}
