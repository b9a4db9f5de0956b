//! Tells the crates that depend on this one directly (`mpc-codegen`) where its sources are
//! and its version, so that they can embed a copy of them (`mpcc build --vendor-runtime`).

fn main() {
    let root = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let version = std::env::var("CARGO_PKG_VERSION").expect("cargo sets CARGO_PKG_VERSION");
    // `DEP_MPC_RUNTIME_ROOT` and `DEP_MPC_RUNTIME_VERSION` in the dependents' build scripts.
    println!("cargo::metadata=root={root}");
    println!("cargo::metadata=version={version}");
    println!("cargo::rerun-if-changed=build.rs");
}
