//! Tests of the tethered probe against independent references: energy and period of the
//! fixed-pivot pendulum, momentum and energy balances of the coupled plant, a 5x5 solve of
//! the Lagrange equations, release bookkeeping, closed-form ballistic landings, the massless
//! probe against the plain plant, and ground strikes.

use mpc_sim::plant::{Contact, CrashReason, Disturbance, Plant, QuadParams, QuadState};
use mpc_sim::probe::{
    ProbeParams, ProbePhase, link_acceleration, link_direction, link_jacobian, swing_acceleration,
    swing_angles, swing_rates,
};
use nalgebra::{Matrix3, Matrix3x2, SMatrix, SVector, UnitQuaternion, Vector3};

const DT: f64 = 0.001;

/// A deterministic generator: `uniform(lo, hi)` draws in `[lo, hi)`.
struct Rng(rand::rngs::StdRng);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(rand::SeedableRng::seed_from_u64(seed))
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        rand::Rng::random_range(&mut self.0, lo..hi)
    }
}

fn no_drag() -> QuadParams {
    QuadParams {
        drag: Vector3::zeros(),
        omega_min: 0.0,
        ..QuadParams::default()
    }
}

/// The link direction, its Jacobian and second derivatives (n_aa, n_ab, n_bb), written out
/// here independently of the crate.
fn link(ang: [f64; 2]) -> (Vector3<f64>, Matrix3x2<f64>, [Vector3<f64>; 3]) {
    let [a, b] = ang;
    let (sa, ca, sb, cb) = (a.sin(), a.cos(), b.sin(), b.cos());
    let n = Vector3::new(sa * cb, sb, -ca * cb);
    let na = Vector3::new(ca * cb, 0.0, sa * cb);
    let nb = Vector3::new(-sa * sb, cb, ca * sb);
    let naa = Vector3::new(-sa * cb, 0.0, ca * cb);
    let nab = Vector3::new(-ca * sb, 0.0, -sa * sb);
    let nbb = Vector3::new(-sa * cb, -sb, ca * cb);
    (n, Matrix3x2::from_columns(&[na, nb]), [naa, nab, nbb])
}

/// Reference accelerations (P'', theta'', lambda) from the Lagrange equations of
/// L = 1/2 mq |P'|^2 + 1/2 mp |P + l n|'^2 - mq g z - mp g (z + l n_z), with the generalized
/// force F on P, solved as one 5x5 linear system by LU:
///
/// [ M I        mp l J      ] [P''    ]   [ F - M g e3 - mp l h        ]
/// [ mp l J^T   mp l^2 J^T J] [theta'']= [ -mp l J^T (l h + g e3)     ]
///
/// with h = n_aa a'^2 + 2 n_ab a' b' + n_bb b'^2 (so n'' = J theta'' + h). The tension
/// follows from the vehicle's Newton equation mq P'' = F - mq g e3 + lambda n.
fn lagrange(
    f: &Vector3<f64>,
    mq: f64,
    pp: &ProbeParams,
    g: f64,
    ang: [f64; 2],
    dang: [f64; 2],
) -> (Vector3<f64>, [f64; 2], f64) {
    let (mp, l) = (pp.mass, pp.length);
    let m = mq + mp;
    let (n, j, [naa, nab, nbb]) = link(ang);
    let [da, db] = dang;
    let h = naa * (da * da) + nab * (2.0 * da * db) + nbb * (db * db);
    let e3 = Vector3::z();
    let mut a = SMatrix::<f64, 5, 5>::zeros();
    a.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Matrix3::identity() * m));
    a.fixed_view_mut::<3, 2>(0, 3).copy_from(&(j * (mp * l)));
    a.fixed_view_mut::<2, 3>(3, 0)
        .copy_from(&(j.transpose() * (mp * l)));
    a.fixed_view_mut::<2, 2>(3, 3)
        .copy_from(&(j.transpose() * j * (mp * l * l)));
    let mut rhs = SVector::<f64, 5>::zeros();
    rhs.fixed_rows_mut::<3>(0)
        .copy_from(&(f - e3 * (m * g) - h * (mp * l)));
    rhs.fixed_rows_mut::<2>(3)
        .copy_from(&(-(j.transpose() * (h * l + e3 * g)) * (mp * l)));
    let x = a.lu().solve(&rhs).expect("regular mass matrix");
    let pdd = Vector3::new(x[0], x[1], x[2]);
    let lambda = n.dot(&(pdd * mq - f + e3 * (mq * g)));
    (pdd, [x[3], x[4]], lambda)
}

/// The vehicle's non-gravitational world force, written out here: thrust along body z,
/// linear body-axis drag on the air-relative velocity, disturbance force.
fn force(p: &QuadParams, s: &QuadState, d: &Disturbance) -> Vector3<f64> {
    let thrust: f64 = s.omega.iter().map(|o| p.k_thrust * o * o).sum();
    let r = s.q.to_rotation_matrix().into_inner();
    let drag = r * Matrix3::from_diagonal(&p.drag) * r.transpose() * (s.v - d.wind);
    r * Vector3::new(0.0, 0.0, thrust) - drag + d.force
}

/// Probe velocity from the vehicle state and the swing state, written out here.
fn probe_velocity(s: &QuadState, l: f64, ang: [f64; 2], dang: [f64; 2]) -> Vector3<f64> {
    let (_, j, _) = link(ang);
    s.v + j * nalgebra::Vector2::new(dang[0], dang[1]) * l
}

fn momentum(plant: &Plant) -> Vector3<f64> {
    let s = plant.state();
    let mut m = s.v * plant.params.mass;
    if let Some(p) = plant.probe() {
        m += p.velocity(s) * p.params().mass;
    }
    m
}

fn energy(plant: &Plant) -> f64 {
    let s = plant.state();
    let (mq, g) = (plant.params.mass, plant.params.g);
    let mut e = 0.5 * mq * s.v.norm_squared() + mq * g * s.p.z;
    if let Some(p) = plant.probe() {
        let mp = p.params().mass;
        e += 0.5 * mp * p.velocity(s).norm_squared() + mp * g * p.position(s).z;
    }
    e
}

/// Rotor speed giving the collective thrust `t` (four equal rotors).
fn rotor_speed(p: &QuadParams, t: f64) -> f64 {
    (t / (4.0 * p.k_thrust)).sqrt()
}

#[test]
fn link_geometry_matches_its_definition() {
    let mut rng = Rng::new(7);
    for _ in 0..100 {
        let ang = [rng.uniform(-3.0, 3.0), rng.uniform(-1.4, 1.4)];
        let (n, j, _) = link(ang);
        assert!((link_direction(ang) - n).norm() < 1e-15);
        assert!((link_direction(ang).norm() - 1.0).abs() < 1e-15);
        let (na, nb) = link_jacobian(ang);
        // Central differences of the crate's own direction.
        let e = 1e-6;
        let fd = |i: usize| {
            let mut p = ang;
            let mut m = ang;
            p[i] += e;
            m[i] -= e;
            (link_direction(p) - link_direction(m)) / (2.0 * e)
        };
        assert!((na - fd(0)).norm() < 1e-9 && (nb - fd(1)).norm() < 1e-9);
        assert!((na - j.column(0)).norm() < 1e-15 && (nb - j.column(1)).norm() < 1e-15);
    }
    assert!((link_direction([0.0, 0.0]) + Vector3::z()).norm() < 1e-15);
}

/// RK4 of the fixed-pivot pendulum through `swing_acceleration`.
fn pendulum_step(x: [f64; 4], dt: f64, g: f64, l: f64) -> [f64; 4] {
    let f = |x: [f64; 4]| {
        let [dda, ddb] = swing_acceleration([x[0], x[1]], [x[2], x[3]], &Vector3::zeros(), g, l);
        [x[2], x[3], dda, ddb]
    };
    let add = |x: [f64; 4], k: [f64; 4], h: f64| std::array::from_fn(|i| x[i] + h * k[i]);
    let k1 = f(x);
    let k2 = f(add(x, k1, 0.5 * dt));
    let k3 = f(add(x, k2, 0.5 * dt));
    let k4 = f(add(x, k3, dt));
    std::array::from_fn(|i| x[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

#[test]
fn fixed_pivot_pendulum_conserves_energy_and_has_the_small_angle_period() {
    let (g, mp, l) = (9.81, 0.2, 0.5);
    let e = |x: [f64; 4]| {
        let cb = x[1].cos();
        0.5 * mp * l * l * (cb * cb * x[2] * x[2] + x[3] * x[3])
            + mp * g * l * link_direction([x[0], x[1]]).z
    };
    let mut x = [1.0, 0.3, 0.5, -0.2];
    let e0 = e(x);
    let mut worst: f64 = 0.0;
    let mut max_db: f64 = 0.0;
    for _ in 0..50_000 {
        x = pendulum_step(x, 1e-4, g, l);
        worst = worst.max((e(x) - e0).abs() / e0.abs());
        max_db = max_db.max((x[1] - 0.3).abs());
    }
    println!("pendulum energy: worst relative drift {worst:.3e} over 5 s");
    assert!(worst < 1e-8, "{worst}");
    // A genuinely spherical motion (beta moves).
    assert!(max_db > 0.1, "{max_db}");

    // Small planar swing: period 2 pi sqrt(l/g) (amplitude correction a0^2/16 = 6e-6).
    let mut x = [0.01, 0.0, 0.0, 0.0];
    let dt = 1e-4;
    let mut crossings = Vec::new();
    for k in 0..100_000 {
        let next = pendulum_step(x, dt, g, l);
        if x[0] < 0.0 && next[0] >= 0.0 {
            crossings.push((k as f64 + x[0] / (x[0] - next[0])) * dt);
        }
        assert!(next[1] == 0.0 && next[3] == 0.0);
        x = next;
    }
    let periods = (crossings.len() - 1) as f64;
    let period = (crossings[crossings.len() - 1] - crossings[0]) / periods;
    let want = 2.0 * std::f64::consts::PI * (l / g).sqrt();
    println!("pendulum period {period:.9} s vs {want:.9} s ({periods} periods)");
    assert!((period - want).abs() < 1e-3 * want, "{period} vs {want}");
    // Finer: with the first amplitude correction, T = T0 (1 + a0^2 / 16).
    let corrected = want * (1.0 + 0.01_f64.powi(2) / 16.0);
    println!(
        "  with the amplitude correction: {:.3e} relative",
        (period / corrected - 1.0).abs()
    );
    assert!((period / corrected - 1.0).abs() < 1e-6);
}

#[test]
fn coupled_momentum_follows_the_external_force_and_free_fall_conserves_energy() {
    let p = no_drag();
    let pp = ProbeParams::default();
    let m = p.mass + pp.mass;
    let q = UnitQuaternion::from_euler_angles(0.2, -0.15, 0.7);
    for thrust in [0.0, 1.3 * m * p.g] {
        let w = rotor_speed(&p, thrust);
        let start = QuadState {
            q,
            omega: [w; 4],
            v: Vector3::new(1.0, -0.5, 0.3),
            ..QuadState::at_rest(Vector3::new(0.0, 0.0, 100.0))
        };
        let mut plant = Plant::new(p.clone(), start.clone());
        plant.attach_probe(pp, [0.6, -0.3], [1.5, -1.0]);
        assert!((plant.total_mass() - m).abs() < 1e-15);
        let f = force(&p, &start, &Disturbance::default());
        let ext = f - Vector3::z() * (m * p.g);
        let (pi0, e0) = (momentum(&plant), energy(&plant));
        let mut worst_rate: f64 = 0.0;
        let mut worst_e: f64 = 0.0;
        let mut worst_e_swing: f64 = 0.0;
        let mut worst_work: f64 = 0.0;
        for k in 1..=2000 {
            assert_eq!(
                plant.step(&[w; 4], &Disturbance::default(), DT),
                Contact::Airborne
            );
            let t = k as f64 * DT;
            // Attitude fixed: the thrust force is constant.
            assert_eq!(plant.state().q, q);
            let err = (momentum(&plant) - pi0 - ext * t).norm();
            worst_rate = worst_rate.max(err / t);
            // Work-energy: the constant force F acting at the vehicle does F.(P - P0)
            // (0 in free fall, where the total energy is conserved).
            let work = f.dot(&(plant.state().p - start.p));
            worst_work = worst_work.max((energy(&plant) - e0 - work).abs() / e0.abs());
            if thrust == 0.0 {
                let de = (energy(&plant) - e0).abs();
                worst_e = worst_e.max(de / e0.abs());
                // Relative to the swing energy alone (about 0.07 J), a far stricter scale.
                let s = plant.state();
                let pr = plant.probe().unwrap();
                let rel = pr.velocity(s) - s.v;
                worst_e_swing = worst_e_swing.max(de / (0.5 * pp.mass * rel.norm_squared()));
            }
        }
        println!(
            "thrust {thrust:.2} N: momentum error {worst_rate:.3e} (N s)/s; \
             energy - work {worst_work:.3e} of E0"
        );
        if thrust == 0.0 {
            println!(
                "free fall: energy drift {worst_e:.3e} of E0, {worst_e_swing:.3e} of the swing \
                 energy"
            );
        }
        assert!(worst_rate < 1e-9, "{worst_rate}");
        assert!(worst_e < 1e-8, "{worst_e}");
        assert!(worst_e_swing < 1e-8, "{worst_e_swing}");
        assert!(worst_work < 1e-8, "{worst_work}");
        // The probe did swing relative to the vehicle.
        let pr = plant.probe().unwrap();
        assert!((pr.ang()[0] - 0.6).abs() > 0.5);
    }
}

#[test]
fn plant_accelerations_match_a_lagrange_mass_matrix_solve() {
    let mut rng = Rng::new(0x5eed);
    let mut worst: f64 = 0.0;
    let mut worst_tension: f64 = 0.0;
    let mut worst_acc: f64 = 0.0;
    let mut worst_step: f64 = 0.0;
    for _ in 0..300 {
        let p = QuadParams {
            mass: rng.uniform(0.5, 2.0),
            ..QuadParams::default()
        };
        let pp = ProbeParams {
            mass: rng.uniform(0.01, 0.6),
            length: rng.uniform(0.2, 1.2),
            drag: 0.0,
        };
        let s = QuadState {
            p: Vector3::new(0.0, 0.0, 50.0),
            v: Vector3::new(
                rng.uniform(-5.0, 5.0),
                rng.uniform(-5.0, 5.0),
                rng.uniform(-3.0, 3.0),
            ),
            q: UnitQuaternion::from_euler_angles(
                rng.uniform(-0.8, 0.8),
                rng.uniform(-0.8, 0.8),
                rng.uniform(-3.0, 3.0),
            ),
            w: Vector3::new(
                rng.uniform(-3.0, 3.0),
                rng.uniform(-3.0, 3.0),
                rng.uniform(-1.0, 1.0),
            ),
            omega: std::array::from_fn(|_| rng.uniform(300.0, 2600.0)),
        };
        let d = Disturbance {
            wind: Vector3::new(
                rng.uniform(-4.0, 4.0),
                rng.uniform(-4.0, 4.0),
                rng.uniform(-1.0, 1.0),
            ),
            force: Vector3::new(
                rng.uniform(-2.0, 2.0),
                rng.uniform(-2.0, 2.0),
                rng.uniform(-2.0, 2.0),
            ),
            torque: Vector3::zeros(),
        };
        let ang = [rng.uniform(-1.3, 1.3), rng.uniform(-1.2, 1.2)];
        let dang = [rng.uniform(-4.0, 4.0), rng.uniform(-4.0, 4.0)];
        let mut plant = Plant::new(p.clone(), s.clone());
        plant.attach_probe(pp, ang, dang);

        let (acc, swing) = plant.accelerations(&d);
        let swing = swing.unwrap();
        let (pdd, tdd, _) = lagrange(&force(&p, &s, &d), p.mass, &pp, p.g, ang, dang);
        let scale = 1.0 + pdd.norm() + tdd[0].abs() + tdd[1].abs();
        let err = (acc - pdd).norm() + (swing[0] - tdd[0]).abs() + (swing[1] - tdd[1]).abs();
        worst = worst.max(err / scale);
        assert!(
            err < 1e-9 * scale,
            "{err}: {acc} vs {pdd}, {swing:?} vs {tdd:?}"
        );

        // Tension and accelerometer with the plant's last disturbance (none yet).
        let f0 = force(&p, &s, &Disturbance::default());
        let (_, _, lambda) = lagrange(&f0, p.mass, &pp, p.g, ang, dang);
        let tension = plant.link_tension().unwrap();
        worst_tension = worst_tension.max((tension - lambda).abs() / (1.0 + lambda.abs()));
        assert!((tension - lambda).abs() < 1e-9 * (1.0 + lambda.abs()));
        let (n, _, _) = link(ang);
        let want = s.q.inverse_transform_vector(&(f0 + n * lambda)) / p.mass;
        let got = plant.specific_acceleration();
        worst_acc = worst_acc.max((got - want).norm() / (1.0 + want.norm()));
        assert!(
            (got - want).norm() < 1e-9 * (1.0 + want.norm()),
            "{got} vs {want}"
        );

        // The step integrates these accelerations (first order in a tiny step; rotors held).
        let h = 1e-7;
        plant.step(&s.omega, &d, h);
        let st = plant.state();
        let pr = plant.probe().unwrap();
        let fd_err = ((st.v - s.v) / h - pdd).norm()
            + ((pr.dang()[0] - dang[0]) / h - tdd[0]).abs()
            + ((pr.dang()[1] - dang[1]) / h - tdd[1]).abs();
        worst_step = worst_step.max(fd_err / scale);
        assert!(fd_err < 1e-4 * scale, "{fd_err}");
    }
    println!(
        "Lagrange 5x5: worst relative error {worst:.3e}; tension {worst_tension:.3e}; \
         accelerometer {worst_acc:.3e}; one 1e-7 s step {worst_step:.3e}"
    );
}

#[test]
fn release_keeps_momentum_and_removes_the_link_force_from_the_accelerometer() {
    let p = QuadParams::default();
    let pp = ProbeParams::default();
    let q = UnitQuaternion::from_euler_angles(0.15, -0.1, 0.3);
    let w = rotor_speed(&p, 1.1 * (p.mass + pp.mass) * p.g);
    let s = QuadState {
        q,
        omega: [w; 4],
        v: Vector3::new(2.0, 1.0, 0.5),
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 30.0))
    };
    let mut plant = Plant::new(p.clone(), s);
    plant.attach_probe(pp, [0.3, 0.1], [0.8, -0.6]);
    for _ in 0..300 {
        plant.step(&[w; 4], &Disturbance::default(), DT);
    }
    let before = plant.state().clone();
    let pr = plant.probe().unwrap().clone();
    let (ang, dang) = (pr.ang(), pr.dang());
    let vp = probe_velocity(&before, pp.length, ang, dang);
    let pi_before = before.v * p.mass + vp * pp.mass;
    let acc_before = plant.specific_acceleration();
    let f = force(&p, &before, &Disturbance::default());
    let (_, _, lambda) = lagrange(&f, p.mass, &pp, p.g, ang, dang);
    let (n, _, _) = link(ang);
    assert!(lambda > 0.0, "taut link: {lambda}");

    let r = plant.release_probe().unwrap();
    assert!(plant.release_probe().is_none(), "already released");
    let after = plant.state().clone();
    assert_eq!(
        after, before,
        "the vehicle's state is unchanged at the release"
    );
    let pr = plant.probe().unwrap();
    assert_eq!(pr.phase(), ProbePhase::Free);
    assert_eq!(pr.release(), Some(r));
    assert_eq!(r.time, plant.time());
    assert_eq!(r.vehicle_velocity, before.v);
    assert!((r.position - (before.p + n * pp.length)).norm() < 1e-12);
    assert!((r.velocity - vp).norm() < 1e-12, "{} vs {vp}", r.velocity);
    let pi_after = momentum(&plant);
    let dpi = (pi_after - pi_before).norm();
    assert!(dpi < 1e-12, "{dpi}");
    assert!((plant.total_mass() - p.mass).abs() < 1e-15);

    let jump = plant.specific_acceleration() - acc_before;
    let want = -q.inverse_transform_vector(&(n * lambda)) / p.mass;
    let jerr = (jump - want).norm();
    println!("release: momentum change {dpi:.3e} N s, accelerometer jump error {jerr:.3e} m/s^2");
    assert!(jerr < 1e-9, "{jump} vs {want}");

    // Sign and size on a hanging probe in hover: the accelerometer reads g with the probe
    // and M g / mq after the release (the jump is +mp g / mq along body z).
    let hover = QuadState {
        omega: [rotor_speed(&p, (p.mass + pp.mass) * p.g); 4],
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 10.0))
    };
    let mut plant = Plant::new(p.clone(), hover.clone());
    plant.attach_probe(pp, [0.0, 0.0], [0.0, 0.0]);
    plant.step(&hover.omega, &Disturbance::default(), DT);
    assert!((plant.state().v).norm() < 1e-12, "balanced hover");
    assert!((plant.link_tension().unwrap() - pp.mass * p.g).abs() < 1e-12);
    let a0 = plant.specific_acceleration();
    assert!((a0 - Vector3::new(0.0, 0.0, p.g)).norm() < 1e-12, "{a0}");
    plant.release_probe();
    let a1 = plant.specific_acceleration();
    let want = Vector3::new(0.0, 0.0, (p.mass + pp.mass) * p.g / p.mass);
    assert!((a1 - want).norm() < 1e-12, "{a1}");
    assert!(plant.link_tension().is_none());

    // After the release the vehicle moves exactly as a plant that never had a probe.
    let mut twin = Plant::new(p.clone(), plant.state().clone());
    for k in 0..500 {
        let cmd = [w * (1.0 + 0.01 * (k % 7) as f64), w, w, w * 0.99];
        let d = Disturbance {
            wind: Vector3::new(1.0, 0.0, 0.0),
            ..Disturbance::default()
        };
        assert_eq!(plant.step(&cmd, &d, DT), twin.step(&cmd, &d, DT));
        assert_eq!(plant.state(), twin.state());
    }
}

/// Attaches a probe to a vehicle moving at `v` from `p0` and releases it at once, then steps
/// the (hovering) vehicle with `dt` until the probe lands. Returns the plant.
fn drop_probe(pp: ProbeParams, dt: f64, wind: Vector3<f64>) -> Plant {
    let p = QuadParams::default();
    let w = p.hover_rotor_speed();
    let s = QuadState {
        v: Vector3::new(5.0, -1.0, 2.0),
        ..QuadState::hovering(Vector3::new(1.0, 2.0, 20.0), &p)
    };
    let mut plant = Plant::new(p, s);
    plant.attach_probe(pp, [0.4, 0.2], [1.0, -0.5]);
    plant.release_probe().unwrap();
    let d = Disturbance {
        wind,
        ..Disturbance::default()
    };
    for _ in 0..(10.0 / dt) as usize {
        assert!(!plant.step(&[w; 4], &d, dt).is_crash());
        if plant.probe().unwrap().phase() == ProbePhase::Landed {
            break;
        }
    }
    plant
}

/// Independent reference for the drag case: fine RK4 (1e-5 s) of
/// x'' = -g e3 - k |x'| x' (still air), then linear interpolation of the crossing step.
fn drag_reference(p0: Vector3<f64>, v0: Vector3<f64>, k: f64, g: f64) -> (f64, Vector3<f64>) {
    let h = 1e-5;
    let acc = |v: Vector3<f64>| -Vector3::z() * g - v * (k * v.norm());
    let (mut p, mut v, mut t) = (p0, v0, 0.0);
    loop {
        let (k1p, k1v) = (v, acc(v));
        let (k2p, k2v) = (v + k1v * (h / 2.0), acc(v + k1v * (h / 2.0)));
        let (k3p, k3v) = (v + k2v * (h / 2.0), acc(v + k2v * (h / 2.0)));
        let (k4p, k4v) = (v + k3v * h, acc(v + k3v * h));
        let pn = p + (k1p + k2p * 2.0 + k3p * 2.0 + k4p) * (h / 6.0);
        let vn = v + (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (h / 6.0);
        if pn.z <= 0.0 {
            let s = p.z / (p.z - pn.z);
            return (t + s * h, p + (pn - p) * s);
        }
        (p, v, t) = (pn, vn, t + h);
    }
}

#[test]
fn ballistic_landing_matches_the_closed_form_and_drag_converges() {
    let g = QuadParams::default().g;
    // Without drag: the exact crossing for every step size.
    for dt in [4e-3, 1e-3, 2.5e-4] {
        let mut plant = drop_probe(ProbeParams::default(), dt, Vector3::zeros());
        let pr = plant.probe().unwrap().clone();
        let r = pr.release().unwrap();
        let l = pr.landing().unwrap();
        let (z0, vz) = (r.position.z, r.velocity.z);
        let t_star = (vz + (vz * vz + 2.0 * g * z0).sqrt()) / g;
        let want = Vector3::new(
            r.position.x + r.velocity.x * t_star,
            r.position.y + r.velocity.y * t_star,
            0.0,
        );
        let err = (l.position - want).norm();
        let terr = (l.time - (r.time + t_star)).abs();
        println!("no drag, dt {dt}: landing error {err:.3e} m, time error {terr:.3e} s");
        assert!(err < 1e-9, "{} vs {want}", l.position);
        assert!(terr < 1e-9);
        assert_eq!(l.position.z, 0.0);
        // After the landing the probe stays put.
        let s = plant.state().clone();
        assert_eq!(pr.position(&s), l.position);
        for _ in 0..200 {
            plant.step(
                &[QuadParams::default().hover_rotor_speed(); 4],
                &Disturbance::default(),
                dt,
            );
        }
        let pr2 = plant.probe().unwrap();
        assert_eq!(pr2.phase(), ProbePhase::Landed);
        assert_eq!(pr2.position(plant.state()), l.position);
        assert_eq!(pr2.velocity(plant.state()), Vector3::zeros());
        assert_eq!(pr2.landing(), Some(l));
    }

    // With quadratic drag: shorter range, converging to a fine independent reference.
    let pp = ProbeParams {
        drag: 0.005,
        ..ProbeParams::default()
    };
    let free = drop_probe(ProbeParams::default(), 1e-3, Vector3::zeros());
    let free_land = free.probe().unwrap().landing().unwrap();
    let r = free.probe().unwrap().release().unwrap();
    let (t_ref, p_ref) = drag_reference(r.position, r.velocity, pp.drag / pp.mass, g);
    let range = |x: Vector3<f64>| (x - r.position).xy().norm();
    assert!(
        range(p_ref) < range(free_land.position) - 1.0,
        "drag shortens the range: {} vs {}",
        range(p_ref),
        range(free_land.position)
    );
    let mut errs = Vec::new();
    for dt in [4e-3, 2e-3, 1e-3, 5e-4] {
        let plant = drop_probe(pp, dt, Vector3::zeros());
        let l = plant.probe().unwrap().landing().unwrap();
        assert_eq!(l.position.z, 0.0);
        let err = (l.position - p_ref).norm();
        let terr = (l.time - (r.time + t_ref)).abs();
        println!("drag, dt {dt}: landing error {err:.3e} m, time error {terr:.3e} s");
        assert!(terr < 1e-2 * dt);
        errs.push(err);
    }
    for pair in errs.windows(2) {
        assert!(pair[1] < 0.5 * pair[0], "{errs:?}");
    }
    assert!(errs[2] < 1e-5, "{errs:?}");

    // The drag acts on the air-relative velocity: a tail wind lengthens the range.
    let windy = drop_probe(pp, 1e-3, Vector3::new(5.0, -1.0, 0.0));
    let l = windy.probe().unwrap().landing().unwrap();
    assert!(range(l.position) > range(p_ref) + 0.5);
}

#[test]
fn massless_probe_leaves_the_vehicle_bit_identical() {
    let p = QuadParams::default();
    let above = 1.15 * p.hover_rotor_speed();
    let mut a = Plant::new(p.clone(), QuadState::at_rest(Vector3::new(1.0, -1.0, 0.0)));
    let mut b = a.clone();
    let massless = ProbeParams {
        mass: 0.0,
        ..ProbeParams::default()
    };
    b.attach_probe(massless, [0.5, 0.2], [1.0, -1.0]);
    assert_eq!(b.total_mass(), p.mass);
    let mut max_swing: f64 = 0.0;
    for k in 0..4000 {
        let t = k as f64 * DT;
        let cmd = if k < 200 {
            [0.9 * p.hover_rotor_speed(); 4]
        } else {
            let u = 0.002 * (7.0 * t).sin();
            [
                above * (1.0 + u),
                above * (1.0 - u),
                above * (1.0 + 0.5 * u),
                above,
            ]
        };
        let d = Disturbance {
            wind: Vector3::new(2.0 * t.sin(), 1.0, 0.0),
            force: Vector3::new(0.3, -0.2 * t.cos(), 0.1),
            torque: Vector3::new(0.0, 0.001 * t.sin(), 0.0),
        };
        let ca = a.step(&cmd, &d, DT);
        let cb = b.step(&cmd, &d, DT);
        assert_eq!(ca, cb, "step {k}");
        assert_eq!(a.state(), b.state(), "step {k}");
        assert_eq!(a.specific_acceleration(), b.specific_acceleration());
        let pr = b.probe().unwrap();
        assert!(pr.is_finite() && pr.is_attached());
        max_swing = max_swing.max((pr.ang()[0] - 0.5).abs());
    }
    assert!(
        a.state().p.z > 1.0,
        "lifted off and flew: {:?} {:?}",
        a.state(),
        a.contact()
    );
    assert!(
        max_swing > 0.1,
        "the massless probe still swings: {max_swing}"
    );
    assert_eq!(b.link_tension(), Some(0.0));
}

#[test]
fn probe_below_ground_while_attached_is_recorded() {
    let p = no_drag();
    let pp = ProbeParams::default();
    // Free fall from 2 m with a hanging probe: it stays hanging and passes z = 0 at
    // t = sqrt(2 * 1.5 / g), before the vehicle hits the ground.
    let mut plant = Plant::new(p.clone(), QuadState::at_rest(Vector3::new(0.0, 0.0, 2.0)));
    plant.attach_probe(pp, [0.0, 0.0], [0.0, 0.0]);
    assert_eq!(plant.probe().unwrap().start(), Vector3::new(0.0, 0.0, 1.5));
    let t_star = (2.0 * 1.5 / p.g).sqrt();
    let mut crossed_airborne = false;
    for _ in 0..1000 {
        let c = plant.step(&[0.0; 4], &Disturbance::default(), DT);
        let pr = plant.probe().unwrap();
        if pr.struck_ground_attached().is_some() && c == Contact::Airborne {
            crossed_airborne = true;
            assert!(pr.position(plant.state()).z < 0.0);
            assert!(pr.is_attached(), "the dynamics continue");
        }
        if c.is_crash() {
            break;
        }
    }
    assert!(crossed_airborne);
    let t = plant.probe().unwrap().struck_ground_attached().unwrap();
    println!("probe ground strike recorded at {t:.6} s, crossing at {t_star:.6} s");
    assert!(t >= t_star && t < t_star + DT + 1e-12, "{t} vs {t_star}");

    // Hovering high: never recorded.
    let hover = QuadState {
        omega: [rotor_speed(&p, (p.mass + pp.mass) * p.g); 4],
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 5.0))
    };
    let mut plant = Plant::new(p.clone(), hover.clone());
    plant.attach_probe(pp, [0.5, 0.0], [0.0, 0.0]);
    for _ in 0..1000 {
        plant.step(&hover.omega, &Disturbance::default(), DT);
    }
    assert!(plant.probe().unwrap().struck_ground_attached().is_none());
}

#[test]
fn grounded_vehicle_holds_the_probe_and_lifts_off_with_the_total_weight() {
    let p = QuadParams::default();
    let pp = ProbeParams::default();
    let mut plant = Plant::new(p.clone(), QuadState::at_rest(Vector3::zeros()));
    // A steep link angle (n_z^2 = 0.13): with a probe hanging nearly straight down the
    // coupled dynamics alone would keep the vehicle down between the two weights, so only
    // this case tests the lift-off rule.
    plant.attach_probe(pp, [1.2, 0.1], [3.0, 1.0]);
    // Attached below the ground plane: recorded at once.
    assert_eq!(plant.probe().unwrap().struck_ground_attached(), Some(0.0));
    assert_eq!(plant.probe().unwrap().dang(), [0.0, 0.0], "held");
    // Thrust above the vehicle's weight but below the total weight: stays down.
    let between = rotor_speed(&p, 0.5 * (2.0 * p.mass + pp.mass) * p.g);
    for _ in 0..500 {
        assert_eq!(
            plant.step(&[between; 4], &Disturbance::default(), DT),
            Contact::OnGround
        );
    }
    let pr = plant.probe().unwrap();
    assert_eq!((pr.ang(), pr.dang()), ([1.2, 0.1], [0.0, 0.0]));
    // Above the total weight: lifts off and the probe swings.
    let above = rotor_speed(&p, 1.2 * (p.mass + pp.mass) * p.g);
    for _ in 0..1000 {
        plant.step(&[above; 4], &Disturbance::default(), DT);
    }
    assert_eq!(plant.contact(), Contact::Airborne);
    assert!(plant.state().p.z > 0.1);
    assert!(plant.probe().unwrap().dang()[0].abs() > 1e-3);
}

#[test]
fn non_finite_probe_crashes_without_nan_state() {
    let p = QuadParams::default();
    let start = QuadState::hovering(Vector3::new(0.0, 0.0, 10.0), &p);
    let w = p.hover_rotor_speed();
    // Non-finite or invalid attachment.
    for (pp, ang) in [
        (ProbeParams::default(), [f64::NAN, 0.0]),
        (
            ProbeParams {
                length: 0.0,
                ..ProbeParams::default()
            },
            [0.0, 0.0],
        ),
    ] {
        let mut plant = Plant::new(p.clone(), start.clone());
        plant.attach_probe(pp, ang, [0.0, 0.0]);
        assert!(matches!(
            plant.crashed(),
            Some(Contact::Crash {
                reason: CrashReason::NonFinite,
                ..
            })
        ));
        assert!(plant.probe().is_none() && plant.state().is_finite());
    }
    // Rates so large that |n'|^2 overflows.
    let mut plant = Plant::new(p.clone(), start);
    plant.attach_probe(ProbeParams::default(), [0.1, 0.1], [1e200, 1e200]);
    let c = plant.step(&[w; 4], &Disturbance::default(), DT);
    assert!(
        matches!(
            c,
            Contact::Crash {
                reason: CrashReason::NonFinite,
                ..
            }
        ),
        "{c:?}"
    );
    assert!(plant.state().is_finite() && plant.probe().unwrap().is_finite());
    assert_eq!(plant.step(&[w; 4], &Disturbance::default(), DT), c);
}

/// The plant keeps the link direction, not the two swing angles, so a probe swinging through
/// `|beta| = pi/2` (the angles' singularity) flies exactly as the same motion turned by 90 deg
/// about the vertical, where the swing is `alpha` and the angles are regular: the plant's
/// physics is invariant under turns about the vertical, so the two runs must agree. In the
/// angles the turned run's equation divides by `cos^2 beta`, which is 0 there.
#[test]
fn a_swing_through_beta_pi_over_2_flies_as_the_same_swing_turned_about_the_vertical() {
    let p = no_drag();
    let pp = ProbeParams::default();
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
    let w = rotor_speed(&p, (p.mass + pp.mass) * p.g);
    let start = |q: UnitQuaternion<f64>| QuadState {
        q,
        omega: [w; 4],
        ..QuadState::at_rest(Vector3::new(0.0, 0.0, 50.0))
    };
    // In-plane (x-z): alpha from 1.2 rad at 6 rad/s goes over the pivot; beta stays 0.
    let mut a = Plant::new(p.clone(), start(UnitQuaternion::identity()));
    a.attach_probe(pp, [1.2, 0.0], [6.0, 0.0]);
    // The same turned by 90 deg: the swing is beta, through pi/2.
    let mut b = Plant::new(p.clone(), start(turn));
    b.attach_probe(pp, [0.0, 1.2], [0.0, 6.0]);
    let (mut worst, mut max_beta, mut worst_unit) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut highest = f64::NEG_INFINITY;
    for _ in 0..1500 {
        a.step(&[w; 4], &Disturbance::default(), DT);
        b.step(&[w; 4], &Disturbance::default(), DT);
        let (sa, sb) = (a.state().clone(), b.state().clone());
        let (pa, pb) = (a.probe().unwrap(), b.probe().unwrap());
        worst = worst
            .max((turn * sa.p - sb.p).norm())
            .max((turn * pa.position(&sa) - pb.position(&sb)).norm())
            .max((turn * pa.velocity(&sa) - pb.velocity(&sb)).norm());
        max_beta = max_beta.max(pb.link_direction().y.asin().abs());
        highest = highest.max(pb.link_direction().z);
        worst_unit = worst_unit.max((pb.link_direction().norm() - 1.0).abs());
        assert!(pb.link_direction().dot(&pb.link_rate()).abs() < 1e-12);
    }
    println!("turned swing: largest difference {worst:.2e}, largest |beta| {max_beta:.4} rad");
    assert!(a.crashed().is_none() && b.crashed().is_none());
    // Over the pole: |beta| reaches pi/2 and the probe rises above the pivot.
    assert!(max_beta > 1.57 && highest > 0.3, "{max_beta} {highest}");
    assert!(worst < 1e-9, "{worst:e}");
    assert!(worst_unit < 1e-14, "{worst_unit:e}");
}

/// The plant's link equation against the swing equation in angles, at random regular states:
/// `n''` from the angles' accelerations and the link's second derivatives (written out in
/// this file) equals `link_acceleration`; the angles and rates are recovered from `n`, `n'`.
#[test]
fn the_link_equation_is_the_swing_equation_in_other_coordinates() {
    let mut rng = Rng::new(31);
    let (g, l) = (9.81, 0.5);
    for _ in 0..200 {
        let ang = [rng.uniform(-3.0, 3.0), rng.uniform(-1.4, 1.4)];
        let dang = [rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0)];
        let acc = Vector3::new(
            rng.uniform(-20.0, 20.0),
            rng.uniform(-20.0, 20.0),
            rng.uniform(-20.0, 20.0),
        );
        let (n, j, [naa, nab, nbb]) = link(ang);
        let nd = j * nalgebra::Vector2::new(dang[0], dang[1]);
        let [dda, ddb] = swing_acceleration(ang, dang, &acc, g, l);
        let ndd_angles = j * nalgebra::Vector2::new(dda, ddb)
            + naa * (dang[0] * dang[0])
            + nab * (2.0 * dang[0] * dang[1])
            + nbb * (dang[1] * dang[1]);
        let ndd = link_acceleration(&n, &nd, &acc, g, l);
        assert!(
            (ndd - ndd_angles).norm() < 1e-9 * (1.0 + ndd.norm()),
            "{ndd} {ndd_angles}"
        );
        let back = swing_angles(&n);
        let rates = swing_rates(back, &nd);
        assert!((back[0] - ang[0]).abs() < 1e-12 && (back[1] - ang[1]).abs() < 1e-12);
        assert!((rates[0] - dang[0]).abs() < 1e-9 && (rates[1] - dang[1]).abs() < 1e-9);
    }
}
