//! Generates the QR-bench solver (variant A: N = 10, dt = 0.04) in f32 into `OUT_DIR`.

fn main() {
    mpc_codegen::Builder::new("../../models/quadrotor_rates.mpc")
        .variant("A")
        .module("quadrotor")
        .scalar(mpc_codegen::Scalar::F32)
        .build()
        .unwrap_or_else(|e| panic!("{e}"));
}
