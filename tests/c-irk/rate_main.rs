//! The irk test's Rust program (tests/irk_c.rs): the stiff model with an input-rate cost
//! (its state augmented with the last control, `u_last+ = u`) and Radau IIA collocation
//! (`irk(stages = 3, steps = 2, collocation = radau_iia)`), generated into a temporary
//! directory. Prints the largest relative difference between the step's `[A B]` and central
//! differences of `dynamics_value`, then runs `solve_sqp` from rest and a 60-step closed loop
//! on the generated step itself, and prints "fd STATUS ITERATIONS s v F".

use mpc_runtime::nalgebra::{SMatrix, SVector};
use stiff_rate::{NU, NX, NX_MODEL, P_DEFAULT, RtiStatus, Solver, functions};

fn main() {
    assert_eq!(functions::IRK.tableau, &mpc_runtime::implicit::RADAU_IIA[2]);
    let p = SVector::from(P_DEFAULT);
    let x0 = [0.7, -0.4, 5.0, 3.0];
    let u0 = [12.0];
    let (mut a, mut b) = (SMatrix::<f64, NX, NX>::zeros(), SMatrix::<f64, NX, NU>::zeros());
    let f0 = functions::dynamics(&SVector::from(x0), &SVector::from(u0), &p, &mut a, &mut b);
    assert_eq!(f0, functions::dynamics_value(&SVector::from(x0), &SVector::from(u0), &p));
    assert_eq!(f0[NX_MODEL], u0[0]);
    let mut worst = 0.0_f64;
    for j in 0..NX + NU {
        let scale = 1.0 + if j < NX { x0[j] } else { u0[0] }.abs();
        let h = 1e-6 * scale;
        let (mut xp, mut xm, mut up, mut um) = (x0, x0, u0, u0);
        if j < NX {
            xp[j] += h;
            xm[j] -= h;
        } else {
            up[0] += h;
            um[0] -= h;
        }
        let fp = functions::dynamics_value(&SVector::from(xp), &SVector::from(up), &p);
        let fm = functions::dynamics_value(&SVector::from(xm), &SVector::from(um), &p);
        for i in 0..NX {
            let fd = (fp[i] - fm[i]) / (2.0 * h);
            let exact = if j < NX { a[(i, j)] } else { b[(i, j - NX)] };
            worst = worst.max((fd - exact).abs() / (1.0 + exact.abs()));
        }
    }
    let mut s = Solver::new();
    s.set_x0(&[0.0; NX_MODEL]).unwrap();
    let info = s.solve_sqp();
    let status = if info.status == RtiStatus::Ok { "Ok" } else { "failed" };
    let iterations = info.sqp_iterations;
    let mut s = Solver::new();
    let mut x = [0.0; NX_MODEL];
    for _ in 0..60 {
        s.set_x0(&x).unwrap();
        s.prepare();
        assert_eq!(s.feedback().status, RtiStatus::Ok);
        let xa = SVector::from([x[0], x[1], x[2], 0.0]);
        let next = functions::dynamics_value(&xa, &SVector::from(s.u0()), &p);
        x = [next[0], next[1], next[2]];
    }
    println!("{worst:e} {status} {iterations} {} {} {}", x[0], x[1], x[2]);
}
