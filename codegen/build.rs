//! Embeds the source of the `mpc-runtime` this crate depends on (`vendor::RUNTIME_FILES`), so
//! that `mpcc build --vendor-runtime` can write a copy of it beside a generated crate from an
//! installed binary, with no checkout. The runtime's build script says where it is.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn collect(dir: &Path, root: &Path, out: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            collect(&path, root, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(
                path.strip_prefix(root)
                    .expect("under the root")
                    .to_path_buf(),
            );
        }
    }
}

fn main() {
    let root = PathBuf::from(
        std::env::var("DEP_MPC_RUNTIME_ROOT")
            .expect("mpc-runtime's build script sets DEP_MPC_RUNTIME_ROOT"),
    );
    let version = std::env::var("DEP_MPC_RUNTIME_VERSION")
        .expect("mpc-runtime's build script sets DEP_MPC_RUNTIME_VERSION");
    let mut files = Vec::new();
    collect(&root.join("src"), &root, &mut files);
    for license in ["LICENSE-MIT", "LICENSE-APACHE"] {
        if root.join(license).is_file() {
            files.push(PathBuf::from(license));
        }
    }
    files.sort();
    let mut code = format!(
        "/// The version of the embedded runtime.\npub const RUNTIME_VERSION: &str = {version:?};\n\
         /// The embedded runtime's files: `(path relative to its crate, contents)`.\n\
         pub const RUNTIME_FILES: &[(&str, &str)] = &[\n"
    );
    for rel in &files {
        let abs = root.join(rel);
        let rel = rel.to_str().expect("a UTF-8 path").replace('\\', "/");
        let abs = abs.to_str().expect("a UTF-8 path");
        writeln!(code, "    ({rel:?}, include_str!({abs:?})),").expect("a String");
    }
    code.push_str("];\n");
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    std::fs::write(out.join("runtime_files.rs"), code).expect("OUT_DIR is writable");
    // `include_str!` makes cargo track each file; new files show up in the directory.
    println!("cargo::rerun-if-changed={}", root.join("src").display());
    println!("cargo::rerun-if-changed=build.rs");
}
