//! Prints what the solver's memory is made of, for the QR-bench dimensions of the
//! microcontroller build (f32, NX = 10, NU = 4, N = 10, 14 parameters, 14 stage and 10
//! terminal residuals, no general constraints):
//!
//! `cargo run -p mpc-runtime --example workspace_sizes`
//!
//! The sizes are those of the host (`usize` fields are 8 bytes here, 4 on a Cortex-M). The
//! generated solver of the firmware (`generated/quadrotor_rates_f32`) condenses (`NC = N`)
//! and has no state-bound rows (`NBX = 0`), no Riccati storage (`NR = 0`) and one stage
//! Hessian in its QP (`NH = 1`).

use core::mem::size_of;

use mpc_runtime::{OcpQp, QpSolver, Rti};

type T = f32;
const NX: usize = 10;
const NU: usize = 4;
const NP: usize = 14;
const NY: usize = 14;
const NYN: usize = 10;
const N: usize = 10;

fn main() {
    let qp_per_stage = size_of::<OcpQp<T, NX, NU, 0, 0, N>>();
    let qp = size_of::<OcpQp<T, NX, NU, 0, 0, N, 1>>();
    let full = size_of::<QpSolver<T, NX, NU, 0, 0, N, 0>>();
    let no_state_rows = size_of::<QpSolver<T, NX, NU, 0, 0, N, 0, 0>>();
    let firmware = size_of::<QpSolver<T, NX, NU, 0, 0, N, N, 0, 0>>();
    let condensing = size_of::<QpSolver<T, NX, NU, 0, 0, N, N>>() - full;
    // The model is a unit struct in generated code; `()` has its size.
    let rti = size_of::<Rti<T, (), NX, NU, NP, NY, NYN, 0, 0, N, N, 0, 0, 1>>();
    println!("f32, NX = {NX}, NU = {NU}, N = {N} (bytes)");
    println!("OCP-QP data, a Hessian per stage (NH = N) {qp_per_stage:>6}");
    println!("OCP-QP data, one stage Hessian (NH = 1)  {qp:>7}");
    println!("QP solver, NC = 0, NBX = NX, NR = N      {full:>7}");
    println!(
        "  of which state-bound rows             {:>7}",
        full - no_state_rows
    );
    println!(
        "  of which Riccati storage              {:>7}",
        no_state_rows - (firmware - condensing)
    );
    println!("condensing storage (NC = N)              {condensing:>7}");
    println!("QP solver, NC = N, NBX = 0, NR = 0       {firmware:>7}");
    println!(
        "RTI trajectories, references, weights    {:>7}",
        rti - qp - firmware
    );
    println!("RTI solver in total (NC = N, NBX = 0, NR = 0, NH = 1) {rti:>7}");
}
