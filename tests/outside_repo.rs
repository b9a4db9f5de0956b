//! mpcc and its crates away from this checkout: the `mpcc` binary run from an empty
//! directory, as the tests build it and as `cargo install` installs it from the packaged
//! crates (whose sources are then deleted: models, templates and the runtime's source are
//! embedded), a generated crate with the runtime vendored built offline for the host and for
//! a bare-metal target and again after being moved, a crate with the default versioned
//! dependency built against `mpc-runtime` as `cargo package` packs it (host and bare metal),
//! and a fresh project that has only the packed library crates generates a solver in its
//! `build.rs`, builds and runs it.
//!
//! The builds are offline: the dependencies are in cargo's cache from this workspace's build.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// An empty directory under the system's temporary directory, outside this repository.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mpcc-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("the temporary directory is writable");
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .canonicalize()
        .unwrap();
    assert!(
        !dir.canonicalize().unwrap().starts_with(&repo),
        "{}",
        dir.display()
    );
    dir
}

/// One target directory for the builds below, so nalgebra is compiled once per target.
fn target_dir() -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join("outside_repo")
}

fn text(out: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// `mpcc ARGS` with `dir` as the current directory.
fn mpcc_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mpcc"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("the mpcc binary runs")
}

/// `cargo ARGS` in `dir`, offline, building into [`target_dir`]; panics with its output
/// unless it succeeds.
fn cargo_in(dir: &Path, args: &[&str]) -> String {
    let out = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(args)
        .arg("--offline")
        .arg("--target-dir")
        .arg(target_dir())
        .current_dir(dir)
        .env_remove("RUSTFLAGS")
        .output()
        .expect("cargo runs");
    let shown = text(&out);
    assert!(
        out.status.success(),
        "cargo {args:?} in {}:\n{shown}",
        dir.display()
    );
    shown
}

/// The crates a registry would serve, in dependency order: `mpcc` and every crate it needs.
const PUBLISHED: [&str; 9] = [
    "mpc-dsl",
    "mpc-runtime",
    "mpc-codegen",
    "mpc-models",
    "mpc-mission",
    "mpc-sim",
    "firmware-shim",
    "px4-sim",
    "mpcc",
];

/// The `.crate` files of [`PUBLISHED`] as `cargo package` packs them, packed once for all
/// tests of this file (they run in parallel and read the same files). Not `cargo package`'s
/// own verification: it builds the packed crates as registry crates of version 0.1.0, whose
/// compiled artifacts cargo reuses across changes of their source.
fn packaged() -> &'static Path {
    static PACKAGE_DIR: OnceLock<PathBuf> = OnceLock::new();
    PACKAGE_DIR.get_or_init(|| {
        let mut args = vec!["package"];
        for name in PUBLISHED {
            args.extend(["-p", name]);
        }
        args.extend(["--allow-dirty", "--no-verify"]);
        cargo_in(Path::new(env!("CARGO_MANIFEST_DIR")), &args);
        target_dir().join("package")
    })
}

/// [`PUBLISHED`] unpacked into a fresh `dir`, as a registry would unpack them; each file's
/// time is the time of unpacking (`cargo package` stamps them all with one fixed time, and
/// cargo would take a changed file for unchanged). Returns each crate's directory by name.
fn unpack(dir: &Path) -> impl Fn(&str) -> PathBuf + use<> {
    let version = mpc_codegen::vendor::RUNTIME_VERSION;
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    for name in PUBLISHED {
        let krate = packaged().join(format!("{name}-{version}.crate"));
        let out = Command::new("tar")
            .arg("xzmf")
            .arg(&krate)
            .arg("-C")
            .arg(dir)
            .output()
            .expect("tar runs");
        assert!(out.status.success(), "{}: {}", krate.display(), text(&out));
        assert!(
            dir.join(format!("{name}-{version}/Cargo.toml")).is_file(),
            "{name} not packaged"
        );
    }
    let dir = dir.to_path_buf();
    move |name| dir.join(format!("{name}-{version}"))
}

/// `--config` arguments that replace the registry's crates of [`PUBLISHED`] by the unpacked
/// ones.
fn patches(unpacked: &impl Fn(&str) -> PathBuf) -> Vec<String> {
    PUBLISHED
        .iter()
        .filter(|name| **name != "mpcc")
        .flat_map(|name| {
            let path = unpacked(name);
            [
                "--config".to_string(),
                format!("patch.crates-io.{name}.path={:?}", path.to_str().unwrap()),
            ]
        })
        .collect()
}

const MODEL: &str = include_str!("../models/paper_pointmass.mpc");

/// Every `.rs` file under `dir`, recursively.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `bin` (an `mpcc` executable) run from an empty directory: `check`, `build` and `sim` of
/// the hover, with its log and plots (in the embedded font) written there.
fn works_anywhere(bin: &Path, name: &str) {
    let dir = scratch(name);
    let mpcc = |args: &[&str]| {
        let out = Command::new(bin)
            .args(args)
            .current_dir(&dir)
            .output()
            .expect("the mpcc binary runs");
        let shown = text(&out);
        assert!(out.status.success(), "mpcc {args:?}: {shown}");
        shown
    };
    std::fs::write(dir.join("pointmass.mpc"), MODEL).unwrap();
    let out = mpcc(&["check", "pointmass.mpc"]);
    assert!(out.contains("paper_pointmass"), "{out}");

    let out = mpcc(&["build", "pointmass.mpc", "-o", "solver"]);
    for f in ["Cargo.toml", "src/lib.rs", "include/paper_pointmass.h"] {
        assert!(dir.join("solver").join(f).is_file(), "{f}: {out}");
    }
    let toml = std::fs::read_to_string(dir.join("solver/Cargo.toml")).unwrap();
    assert!(
        toml.contains("mpc-runtime = { version = ") && !toml.contains("path ="),
        "{toml}"
    );
    mpcc(&[
        "build",
        "pointmass.mpc",
        "--vendor-runtime",
        "-o",
        "vendored",
    ]);
    assert!(dir.join("vendored/vendor/mpc-runtime/src/lib.rs").is_file());

    let out = mpcc(&["sim", "--mission", "hover", "--out", "sim-out"]);
    assert!(out.contains("1 of 1 trials succeeded"), "{out}");
    let pngs = std::fs::read_dir(dir.join("sim-out"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "png"))
        })
        .count();
    assert!(pngs > 0, "no plots in sim-out: {out}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn mpcc_works_from_an_empty_directory() {
    works_anywhere(Path::new(env!("CARGO_BIN_EXE_mpcc")), "anywhere");
}

/// `cargo install` of the packaged `mpcc` with only the packaged crates, as a user without
/// this repository installs it (`--debug`: the same code, compiled faster). The packaged
/// sources are deleted before the installed binary runs, so it reads nothing of them.
#[test]
fn cargo_install_from_the_packaged_crates_gives_an_mpcc_that_works_anywhere() {
    // Outside the repository: cargo would take a package under it for a workspace member.
    let sources = scratch("install-sources");
    let unpacked = unpack(&sources);
    let root = scratch("installed");
    let krate = unpacked("mpcc");
    let mut args = vec![
        "install".to_string(),
        "--debug".to_string(),
        "--path".to_string(),
        krate.to_str().unwrap().to_string(),
        "--root".to_string(),
        root.to_str().unwrap().to_string(),
    ];
    args.extend(patches(&unpacked));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let installed = cargo_in(&root, &args);
    assert!(installed.contains("Installed package `mpcc"), "{installed}");
    std::fs::remove_dir_all(&sources).unwrap();
    assert!(!krate.exists());

    works_anywhere(&root.join("bin/mpcc"), "installed-run");
    let _ = std::fs::remove_dir_all(&root);
}

/// The vendored `Cargo.toml` declares the runtime's dependencies as the workspace does (a
/// test of `mpc-codegen`'s `vendor` module, here because it reads the workspace's manifests,
/// which the packed `mpc-codegen` does not carry).
#[test]
fn vendored_dependencies_are_the_runtimes() {
    use mpc_codegen::vendor::{
        RUNTIME_DEPENDENCIES, RUNTIME_FILES, RUNTIME_VERSION, runtime_cargo_toml,
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let workspace = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
    let runtime = std::fs::read_to_string(root.join("runtime/Cargo.toml")).unwrap();
    let section = runtime
        .split("\n[dependencies]\n")
        .nth(1)
        .and_then(|s| s.split("\n[").next())
        .expect("runtime/Cargo.toml has [dependencies]");
    let mut names: Vec<&str> = section
        .lines()
        .filter_map(|l| l.strip_suffix(".workspace = true"))
        .collect();
    names.sort_unstable();
    assert_eq!(names, ["libm", "nalgebra"], "{section}");
    for line in RUNTIME_DEPENDENCIES.lines() {
        assert!(workspace.lines().any(|l| l == line), "{line}");
    }
    assert!(runtime_cargo_toml().contains(&format!("version = \"{RUNTIME_VERSION}\"")));
    assert!(RUNTIME_FILES.iter().any(|(p, _)| *p == "src/lib.rs"));
}

#[test]
fn a_vendored_crate_builds_offline_anywhere_and_for_bare_metal() {
    let first = scratch("vendored");
    std::fs::write(first.join("pointmass.mpc"), MODEL).unwrap();
    let out = mpcc_in(
        &first,
        &[
            "build",
            "pointmass.mpc",
            "--vendor-runtime",
            "--no-c-abi",
            "-o",
            "solver",
        ],
    );
    assert!(out.status.success(), "{}", text(&out));
    let krate = first.join("solver");
    let toml = std::fs::read_to_string(krate.join("Cargo.toml")).unwrap();
    assert!(
        toml.contains("mpc-runtime = { path = \"vendor/mpc-runtime\", default-features = false }"),
        "{toml}"
    );
    let vendored = krate.join("vendor/mpc-runtime");
    for f in ["Cargo.toml", "src/lib.rs", "LICENSE-MIT", "LICENSE-APACHE"] {
        assert!(vendored.join(f).is_file(), "vendor/mpc-runtime/{f} missing");
    }
    // The files written are the runtime's source as it is in this checkout, all of it.
    let runtime = Path::new(env!("CARGO_MANIFEST_DIR")).join("runtime");
    let mut sources = Vec::new();
    rust_files(&runtime.join("src"), &mut sources);
    assert!(sources.len() > 10, "{sources:?}");
    for path in sources {
        let rel = path.strip_prefix(&runtime).unwrap();
        assert_eq!(
            std::fs::read_to_string(vendored.join(rel)).ok(),
            Some(std::fs::read_to_string(&path).unwrap()),
            "vendor/mpc-runtime/{} is not the checkout's",
            rel.display()
        );
    }

    cargo_in(&krate, &["build"]);
    let bare = cargo_in(&krate, &["build", "--target", "thumbv7em-none-eabihf"]);
    assert!(bare.contains("Finished"), "{bare}");

    // Moved elsewhere (the model and the first directory gone), it still builds.
    let second = scratch("vendored-moved");
    let moved = second.join("elsewhere");
    std::fs::rename(&krate, &moved).expect("both under the temporary directory");
    let _ = std::fs::remove_dir_all(&first);
    // Cargo would find the artifacts of the first place fresh (it hashes a path package by
    // its place relative to the workspace): compile both crates again from here.
    cargo_in(
        &moved,
        &["clean", "-p", "paper_pointmass", "-p", "mpc-runtime"],
    );
    let rebuilt = cargo_in(&moved, &["build"]);
    assert!(
        rebuilt.contains("Compiling mpc-runtime") && rebuilt.contains("Compiling paper_pointmass"),
        "{rebuilt}"
    );
    let _ = std::fs::remove_dir_all(&second);
}

#[test]
fn a_versioned_crate_builds_against_the_packaged_runtime() {
    let version = mpc_codegen::vendor::RUNTIME_VERSION;
    let crates = scratch("versioned-crates");
    let unpacked = unpack(&crates);
    let packed = unpacked("mpc-runtime");
    for f in [
        "Cargo.toml",
        "src/lib.rs",
        "build.rs",
        "LICENSE-MIT",
        "README.md",
    ] {
        assert!(packed.join(f).is_file(), "{f} not packaged");
    }

    let dir = scratch("versioned");
    std::fs::write(dir.join("pointmass.mpc"), MODEL).unwrap();
    let out = mpcc_in(&dir, &["build", "pointmass.mpc", "-o", "solver"]);
    assert!(out.status.success(), "{}", text(&out));
    let krate = dir.join("solver");
    let toml = std::fs::read_to_string(krate.join("Cargo.toml")).unwrap();
    let dep = format!("mpc-runtime = {{ version = \"{version}\", default-features = false }}");
    assert!(toml.contains(&dep), "{toml}");
    // The default registry's `mpc-runtime` replaced by the packaged one, as it would be
    // downloaded.
    let patch = format!(
        "patch.crates-io.mpc-runtime.path={:?}",
        packed.to_str().unwrap()
    );
    let built = cargo_in(&krate, &["build", "--config", &patch]);
    assert!(built.contains("Compiling paper_pointmass"), "{built}");
    let bare = cargo_in(
        &krate,
        &[
            "build",
            "--target",
            "thumbv7em-none-eabihf",
            "--config",
            &patch,
        ],
    );
    assert!(bare.contains("Compiling paper_pointmass"), "{bare}");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&crates);
}

/// What a user without this repository has: the library crates as `cargo package` packs
/// them (what a registry would serve). A fresh project generates a solver from its own `.mpc`
/// file in `build.rs` with the packaged generator, builds it against the packaged runtime and
/// runs it; its first control is the one of the same model's solver in `mpc-models` (the
/// code of `generated/paper_pointmass`).
#[test]
fn a_fresh_project_generates_builds_and_runs_a_solver_from_the_packaged_crates() {
    let version = mpc_codegen::vendor::RUNTIME_VERSION;
    let crates = scratch("fresh-crates");
    let unpacked = unpack(&crates);
    let dir = scratch("fresh");
    std::fs::create_dir_all(dir.join("src")).unwrap();
    std::fs::write(dir.join("pointmass.mpc"), MODEL).unwrap();
    let mut toml = format!(
        "[package]\nname = \"fresh\"\nversion = \"0.1.0\"\nedition = \"2024\"\n\n\
         [dependencies]\nmpc-runtime = \"{version}\"\n\n\
         [build-dependencies]\nmpc-codegen = \"{version}\"\n\n[patch.crates-io]\n"
    );
    for name in ["mpc-dsl", "mpc-runtime", "mpc-codegen"] {
        let path = unpacked(name);
        toml += &format!("{name} = {{ path = {:?} }}\n", path.to_str().unwrap());
    }
    std::fs::write(dir.join("Cargo.toml"), toml).unwrap();
    std::fs::write(
        dir.join("build.rs"),
        "fn main() {\n    mpc_codegen::Builder::new(\"pointmass.mpc\")\n        .module(\"solver\")\n        \
         .build()\n        .unwrap_or_else(|e| panic!(\"{e}\"));\n}\n",
    )
    .unwrap();
    std::fs::write(dir.join("src/main.rs"), FRESH_MAIN).unwrap();
    let ran = cargo_in(&dir, &["run", "-q"]);

    let mut s = mpc_models::paper_pointmass::Solver::new();
    s.prepare();
    s.set_x0(&FRESH_X0).unwrap();
    let info = s.feedback();
    let want = format!("{:?} {:?}", info.status, s.u0());
    assert!(
        ran.contains(&want),
        "fresh project: {ran}\nmpc-models' solver: {want}"
    );
    assert!(ran.contains("Ok ["), "{ran}");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&crates);
}

const FRESH_X0: [f64; 9] = [1.0, -0.5, 0.2, 0.0, 0.3, 0.0, 0.0, 0.0, 0.0];

const FRESH_MAIN: &str = "mpc_runtime::include_solver!(\"solver\");\n\n\
fn main() {\n    let mut s = solver::Solver::new();\n    s.prepare();\n    \
s.set_x0(&[1.0, -0.5, 0.2, 0.0, 0.3, 0.0, 0.0, 0.0, 0.0]).unwrap();\n    \
let info = s.feedback();\n    println!(\"{:?} {:?}\", info.status, s.u0());\n}\n";
