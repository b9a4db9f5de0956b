//! The runtime's source, embedded at build time, for crates that carry their own copy of it
//! ([`RuntimeDep::Vendored`](crate::RuntimeDep::Vendored)).

use std::path::PathBuf;

include!(concat!(env!("OUT_DIR"), "/runtime_files.rs"));

/// Where a vendored runtime goes, relative to the generated crate.
pub const VENDOR_DIR: &str = "vendor/mpc-runtime";

/// The vendored runtime's `Cargo.toml`: the runtime's package without workspace inheritance,
/// with the same versioned dependencies as `runtime/Cargo.toml` (a test compares them).
pub fn runtime_cargo_toml() -> String {
    format!(
        "# mpc-runtime {RUNTIME_VERSION}, vendored by mpcc {}. Do not edit: regenerate with \
         `mpcc build --vendor-runtime`.\n\
         [package]\nname = \"mpc-runtime\"\nversion = \"{RUNTIME_VERSION}\"\nedition = \"2024\"\n\
         rust-version = \"1.95\"\nlicense = \"MIT OR Apache-2.0\"\n\
         description = \"no_std RTI-SQP solver: the runtime of mpcc-generated solvers (vendored \
         copy)\"\npublish = false\n\n\
         [dependencies]\n{}",
        crate::VERSION,
        RUNTIME_DEPENDENCIES
    )
}

/// The runtime's dependencies as the vendored `Cargo.toml` declares them.
pub const RUNTIME_DEPENDENCIES: &str = "libm = \"0.2\"\n\
    nalgebra = { version = \"0.35\", default-features = false, features = [\"libm\"] }\n";

/// The vendored runtime's files, relative to the generated crate.
pub fn files() -> Vec<(PathBuf, String)> {
    let dir = PathBuf::from(VENDOR_DIR);
    let mut files = vec![(dir.join("Cargo.toml"), runtime_cargo_toml())];
    files.extend(
        RUNTIME_FILES
            .iter()
            .map(|(rel, text)| (dir.join(rel), (*text).to_string())),
    );
    files
}
