//! `docs/tutorial.md`, followed word for word: every block marked `<!-- file: PATH -->` is
//! written to PATH and every `sh` block marked `<!-- run -->` is run line by line, in order,
//! in a fresh folder outside the repository that holds a link `mpcc` to this checkout (the
//! tutorial's clone). `mpcc` on the PATH is the one this test suite built; cargo runs offline
//! (the workspace's build fetched every crate the tutorial's projects use). The tutorial's
//! own checks (the Rust program's assertion, the C program's exit status) decide the outcome.

use std::path::{Path, PathBuf};
use std::process::Command;

/// One step of the tutorial.
#[derive(Debug)]
enum Step {
    /// Write this file (a path relative to the work folder) with these contents.
    File(String, String),
    /// Run this shell line in the work folder.
    Run(String),
}

/// The marked blocks of `doc`, in order.
fn steps(doc: &str) -> Vec<Step> {
    let mut out = Vec::new();
    let mut lines = doc.lines();
    while let Some(line) = lines.next() {
        let marker = line.trim();
        let file = marker
            .strip_prefix("<!-- file: ")
            .and_then(|m| m.strip_suffix(" -->"));
        if file.is_none() && marker != "<!-- run -->" {
            continue;
        }
        let fence = lines.next().unwrap_or_default();
        assert!(
            fence.starts_with("```"),
            "a marker not before a block: {line}"
        );
        let body: Vec<&str> = lines
            .by_ref()
            .take_while(|l| !l.starts_with("```"))
            .collect();
        match file {
            Some(path) => out.push(Step::File(path.to_string(), body.join("\n") + "\n")),
            None => out.extend(
                (body.iter())
                    .filter(|l| !l.trim().is_empty())
                    .map(|l| Step::Run(l.to_string())),
            ),
        }
    }
    out
}

fn run(dir: &Path, line: &str) -> String {
    let mpcc = PathBuf::from(env!("CARGO_BIN_EXE_mpcc"));
    let path = format!(
        "{}:{}",
        mpcc.parent().unwrap().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new("sh")
        .args(["-c", line])
        .current_dir(dir)
        .env("PATH", path)
        .env("CARGO_NET_OFFLINE", "true")
        // The tutorial's projects build in their own folders, as a reader's would.
        .env_remove("CARGO_TARGET_DIR")
        .output()
        .expect("sh runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "`{line}` failed ({}):\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

#[test]
fn the_tutorial_works_as_written() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(root.join("docs/tutorial.md")).unwrap();
    let steps = steps(&doc);
    let runs = steps.iter().filter(|s| matches!(s, Step::Run(_))).count();
    assert!(runs >= 6 && steps.len() >= runs + 5, "{steps:?}");

    let dir = std::env::temp_dir().join(format!("mpcc-tutorial-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::os::unix::fs::symlink(&root, dir.join("mpcc")).unwrap();
    let mut printed = String::new();
    for step in &steps {
        match step {
            Step::File(path, text) => {
                let path = dir.join(path);
                std::fs::create_dir_all(path.parent().unwrap()).unwrap();
                std::fs::write(path, text).unwrap();
            }
            Step::Run(line) => printed += &run(&dir, line),
        }
    }
    println!("{printed}");
    // Both closed loops say where the pendulum ended (and checked it themselves).
    assert_eq!(
        printed.matches("after 10 s: theta = 3.1416 rad").count(),
        2,
        "{printed}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
