//! Prints what the solver's memory is made of, for the QR-bench dimensions of the
//! microcontroller build (f32, NX = 10, NU = 4, N = 10, 14 parameters, 14 stage and 10
//! terminal residuals, no general constraints):
//!
//! `cargo run -p mpc-runtime --example workspace_sizes`
//!
//! The sizes are those of the host (`usize` fields are 8 bytes here, 4 on a Cortex-M).

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
    let qp = size_of::<OcpQp<T, NX, NU, 0, 0, N>>();
    let riccati_only = size_of::<QpSolver<T, NX, NU, 0, 0, N, 0>>();
    let with_condensing = size_of::<QpSolver<T, NX, NU, 0, 0, N, N>>();
    // The model is a unit struct in generated code; `()` has its size.
    let rti = size_of::<Rti<T, (), NX, NU, NP, NY, NYN, 0, 0, N, N>>();
    println!("f32, NX = {NX}, NU = {NU}, N = {N} (bytes)");
    println!("OCP-QP data (stages and terminal)    {qp:>7}");
    println!("QP solver without condensing storage {riccati_only:>7}");
    println!(
        "condensing storage                   {:>7}",
        with_condensing - riccati_only
    );
    println!(
        "RTI trajectories, references, weights {:>6}",
        rti - qp - with_condensing
    );
    println!("RTI solver in total (NC = N)         {rti:>7}");
}
