//! Generates the paper's solvers (those `mpcc sim`, `mpcc fly` and `mpcc bench` fly) from the
//! `.mpc` files beside this script into `OUT_DIR`, as `mpc_codegen::Builder` does in any
//! user's `build.rs`. `src/lib.rs` includes each module; the checked-in crates of
//! `generated/` are the same code with a `Cargo.toml`, a C ABI and a header
//! (`generated/README.md`).

use mpc_codegen::{Builder, QpMethod, QpOptions, Scalar};

/// Module, model file (without `.mpc`), and the options of the `generated/` crate of the same
/// name as its `mpcc build` command in `generated/README.md` gives them.
const SOLVERS: [(&str, &str, &str); 10] = [
    ("paper_pointmass", "paper_pointmass", ""),
    ("quadrotor_probe", "quadrotor_probe", ""),
    ("quadrotor_rates", "quadrotor_rates", ""),
    ("quadrotor_rates_a", "quadrotor_rates", "--variant A"),
    (
        "quadrotor_rates_a_exact",
        "quadrotor_rates",
        "--variant A --exact-hessian --qp-method riccati",
    ),
    (
        "quadrotor_rates_b_exact",
        "quadrotor_rates",
        "--exact-hessian --qp-method riccati",
    ),
    (
        "quadrotor_rates_f32",
        "quadrotor_rates",
        "--variant A --f32 --qp-method condensed",
    ),
    ("quadrotor_rates_b_f32", "quadrotor_rates", "--f32"),
    ("quadrotor_rates_n40", "quadrotor_rates", "--variant N40"),
    (
        "quadrotor_rates_n40_f32",
        "quadrotor_rates",
        "--variant N40 --f32",
    ),
];

/// The builder for `model.mpc` with `mpcc build`'s flags `flags`.
fn builder(module: &str, model: &str, flags: &str) -> Builder {
    let mut b = Builder::new(format!("{model}.mpc")).module(module);
    let mut flags = flags.split_whitespace();
    while let Some(flag) = flags.next() {
        let mut value = || {
            flags
                .next()
                .unwrap_or_else(|| panic!("{flag} needs a value"))
        };
        b = match flag {
            "--variant" => b.variant(value()),
            "--f32" => b.scalar(Scalar::F32),
            "--exact-hessian" => b.exact_hessian(true),
            "--qp-method" => {
                let method = match value() {
                    "riccati" => QpMethod::Riccati,
                    "condensed" => QpMethod::Condensed,
                    other => panic!("--qp-method {other}: riccati or condensed"),
                };
                b.qp(QpOptions {
                    method: Some(method),
                    ..QpOptions::default()
                })
            }
            other => panic!("{module}: {other} is not a flag this script knows"),
        };
    }
    b
}

fn main() {
    for (module, model, flags) in SOLVERS {
        if let Err(e) = builder(module, model, flags).build() {
            panic!("{model}.mpc, module {module}: {e}");
        }
    }
}
