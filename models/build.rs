//! Generates the paper's solvers (those `mpcc sim`, `mpcc fly` and `mpcc bench` fly) from the
//! `.mpc` files beside this script into `OUT_DIR`, as `mpc_codegen::Builder` does in any
//! user's `build.rs`. `src/lib.rs` includes each module; the checked-in crates of
//! `generated/` are the same code with a `Cargo.toml`, a C ABI and a header
//! (`generated/README.md`).

use mpc_codegen::{Builder, QpMethod, QpOptions, Scalar};

/// A solver to generate: module name, model file (without `.mpc`), variant, f32, exact
/// Hessian, QP method.
type Spec = (
    &'static str,
    &'static str,
    Option<&'static str>,
    bool,
    bool,
    Option<QpMethod>,
);

/// The options of each `generated/` crate of the same name (`generated/README.md`).
const SOLVERS: [Spec; 10] = [
    (
        "paper_pointmass",
        "paper_pointmass",
        None,
        false,
        false,
        None,
    ),
    (
        "quadrotor_probe",
        "quadrotor_probe",
        None,
        false,
        false,
        None,
    ),
    (
        "quadrotor_rates",
        "quadrotor_rates",
        None,
        false,
        false,
        None,
    ),
    (
        "quadrotor_rates_a",
        "quadrotor_rates",
        Some("A"),
        false,
        false,
        None,
    ),
    (
        "quadrotor_rates_a_exact",
        "quadrotor_rates",
        Some("A"),
        false,
        true,
        Some(QpMethod::Riccati),
    ),
    (
        "quadrotor_rates_b_exact",
        "quadrotor_rates",
        None,
        false,
        true,
        Some(QpMethod::Riccati),
    ),
    (
        "quadrotor_rates_f32",
        "quadrotor_rates",
        Some("A"),
        true,
        false,
        Some(QpMethod::Condensed),
    ),
    (
        "quadrotor_rates_b_f32",
        "quadrotor_rates",
        None,
        true,
        false,
        None,
    ),
    (
        "quadrotor_rates_n40",
        "quadrotor_rates",
        Some("N40"),
        false,
        false,
        None,
    ),
    (
        "quadrotor_rates_n40_f32",
        "quadrotor_rates",
        Some("N40"),
        true,
        false,
        None,
    ),
];

fn main() {
    for (module, model, variant, f32, exact, method) in SOLVERS {
        let mut b = Builder::new(format!("{model}.mpc"))
            .module(module)
            .exact_hessian(exact)
            .qp(QpOptions {
                method,
                ..QpOptions::default()
            });
        if let Some(v) = variant {
            b = b.variant(v);
        }
        if f32 {
            b = b.scalar(Scalar::F32);
        }
        if let Err(e) = b.build() {
            panic!("{model}.mpc, module {module}: {e}");
        }
    }
}
