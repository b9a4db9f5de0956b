//! The build glue of `mpcc build --staticlib` for C projects: generates a double integrator
//! (`tests/c-glue/glue_di.mpc`) into a temporary directory, builds its static library through
//! the generated Makefile fragment's rule, and builds and runs the same C program
//! (`tests/c-glue/main.c`, `-Wall -Wextra -Werror`) three ways: with the fragment
//! (`tests/c-glue/Makefile`), with the compile and link line `mpcc build` printed, and with
//! the generated pkg-config file. Each must fly the loop to rest at the origin and print the
//! same final state. Needs make, cc and pkg-config (the test fails without them).
#![cfg(unix)]

use std::path::Path;
use std::process::Command;

mod common;

use common::{TempDir, run};

/// The generated crate's name (the model's).
const NAME: &str = "glue_di";

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Runs a built C program and checks its closed loop: every step OK, at rest at the origin.
/// Returns its output line.
fn fly(exe: &Path, what: &str) -> String {
    let out = run(&mut Command::new(exe), what);
    let line = String::from_utf8_lossy(&out.stdout).trim().to_string();
    let v: Vec<f64> = line
        .split_whitespace()
        .map(|w| w.parse().unwrap_or_else(|_| panic!("{what}: {line:?}")))
        .collect();
    assert_eq!(v.len(), 3, "{what}: {line:?}");
    assert_eq!(v[2], 50.0, "{what}: not every step was OK: {line:?}");
    assert!(
        v[0].abs() < 1e-4 && v[1].abs() < 1e-4,
        "{what}: not at rest at the origin: {line:?}"
    );
    line
}

#[test]
fn a_c_program_builds_with_the_generated_glue() {
    // Outside the repository: a crate under it would be taken for a workspace member.
    let tmp = TempDir(std::env::temp_dir().join(format!("mpcc-c-glue-{}", std::process::id())));
    let crate_dir = tmp.0.join(NAME);
    let out_dir = crate_dir.to_str().expect("UTF-8 temporary directory");
    // This checkout's runtime (the default, a version, is not in the offline cache).
    let runtime = format!("{}/runtime", env!("CARGO_MANIFEST_DIR"));
    let (code, stdout, stderr) = common::mpcc(&[
        "build",
        "tests/c-glue/glue_di.mpc",
        "-o",
        out_dir,
        "--staticlib",
        "--runtime-path",
        &runtime,
    ]);
    assert_eq!(code, Some(0), "mpcc build failed:\n{stdout}\n{stderr}");
    for file in [format!("{NAME}.mk"), format!("{NAME}.pc")] {
        assert!(crate_dir.join(&file).is_file(), "{file} not written");
        assert!(stdout.contains(&file), "{file} not reported:\n{stdout}");
    }
    let printed = format!(
        "cc main.c -I{out_dir}/include {out_dir}/target/release/lib{NAME}.a -lpthread -ldl -lm"
    );
    let link_line = stdout
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("cc main.c"))
        .unwrap_or_else(|| panic!("no compile and link line printed:\n{stdout}"));
    assert_eq!(link_line, printed);

    // The crate's target/ is a link to a directory kept between runs: the runtime's build
    // is reused, and the printed line and the pkg-config file work as written.
    let shared = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generated-staticlibs");
    std::fs::create_dir_all(&shared).expect("create the shared target directory");
    std::os::unix::fs::symlink(&shared, crate_dir.join("target")).expect("link target/");

    // With the fragment: its (phony) rule asks cargo, then the Makefile's own default goal.
    let c_dir = repo().join("tests/c-glue");
    let make = |goal: Option<&str>| {
        let mut cmd = Command::new("make");
        cmd.current_dir(&c_dir)
            .arg(format!("CRATE={out_dir}"))
            .arg(format!("OUT={}", tmp.0.display()))
            .env("CARGO_NET_OFFLINE", "true");
        cmd.args(goal);
        run(&mut cmd, &format!("make {}", goal.unwrap_or("")))
    };
    make(Some(&format!("{NAME}-staticlib")));
    make(None);
    let with_make = fly(&tmp.0.join("glue_di_loop"), "the program built by make");

    // With the line mpcc printed (the warnings flags added).
    let main_c = c_dir.join("main.c");
    let exe = tmp.0.join("printed");
    common::build_with_printed_line(link_line, &main_c, &exe);
    assert_eq!(
        fly(&exe, "the program built by the printed line"),
        with_make
    );

    // With pkg-config, which finds the crate from the file's own directory.
    let pc = run(
        Command::new("pkg-config")
            .args(["--cflags", "--libs", NAME])
            .env("PKG_CONFIG_PATH", &crate_dir),
        "pkg-config",
    );
    let flags = String::from_utf8_lossy(&pc.stdout).into_owned();
    assert!(
        flags.contains(&format!("-I{out_dir}/include")),
        "pkg-config: {flags}"
    );
    let exe = tmp.0.join("pkg_config");
    run(
        Command::new("cc")
            .args([
                "-std=c11",
                "-Wall",
                "-Wextra",
                "-Werror",
                "-pedantic",
                "-O2",
            ])
            .arg(&main_c)
            .args(flags.split_whitespace())
            .arg("-o")
            .arg(&exe),
        "cc with pkg-config's flags",
    );
    assert_eq!(fly(&exe, "the program built with pkg-config"), with_make);
}
