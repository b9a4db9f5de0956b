//! Build glue for C and C++ projects, written next to a `--staticlib` crate with a C ABI: a
//! Makefile fragment `<name>.mk` (host and bare metal), a pkg-config file `<name>.pc`
//! (host) and the bare-metal library crate `bare-metal/` (the firmware profile). Why these
//! and not a CMake package, and why a crate of its own: `docs/codegen.md`, "Build glue for
//! C".

use std::path::PathBuf;

use crate::Options;

/// The system libraries a hosted (`std`) staticlib needs on Linux, as the C ABI test links
/// them (`cc` adds `-lc` and `-lgcc_s` itself); bare metal needs none.
pub const HOST_LIBS: &str = "-lpthread -ldl -lm";

/// The directory (in the generated crate) of the bare-metal library crate.
pub const BARE_METAL_DIR: &str = "bare-metal";

/// The glue files of crate `name` (paths relative to the crate), none unless the crate is a
/// staticlib with the C ABI.
pub(crate) fn files(name: &str, stamp: &str, opts: &Options) -> Vec<(PathBuf, String)> {
    if !(opts.staticlib && opts.c_abi) {
        return Vec::new();
    }
    vec![
        (PathBuf::from(format!("{name}.mk")), makefile(name, stamp)),
        (
            PathBuf::from(format!("{name}.pc")),
            pkg_config(name, stamp, opts.scalar.c()),
        ),
        (
            PathBuf::from(format!("{BARE_METAL_DIR}/Cargo.toml")),
            bare_metal_cargo_toml(name, stamp),
        ),
        (
            PathBuf::from(format!("{BARE_METAL_DIR}/src/lib.rs")),
            bare_metal_lib(name, stamp),
        ),
    ]
}

/// The manifest of the bare-metal library crate: a staticlib that re-exports crate `name`
/// (no `std`, its panic handler) and carries the firmware profile. The crate is the LTO
/// root, so the whole library is optimized for size ("s") after LTO, while the solver crate
/// (where the runtime's generic code is instantiated) and the runtime are optimized at 2
/// before it: the Rust firmware's split. Built as the generated crate itself, the solver
/// crate would be the root and its opt-level would apply to everything.
fn bare_metal_cargo_toml(name: &str, stamp: &str) -> String {
    format!(
        "# {stamp}
# The static library lib{name}_bare_metal.a for bare-metal C firmware:
# the C ABI of `{name}` without `std`, with its panic handler, built with the
# profile below. Build it with
#   cargo build --release --manifest-path <this directory>/Cargo.toml --target <target>
[package]
name = \"{name}_bare_metal\"
version = \"0.1.0\"
edition = \"2024\"
rust-version = \"1.95\"
license = \"MIT OR Apache-2.0\"
description = \"The static library of mpcc-generated `{name}` for bare metal\"
publish = false

# Standalone (own workspace), so that the profile below is the one cargo uses.
[workspace]

[lib]
crate-type = [\"staticlib\"]

[dependencies]
{name} = {{ path = \"..\", default-features = false, features = [\"panic-handler\"] }}

# This crate is the LTO root: \"s\" applies to the whole library after (fat) LTO; the
# solver crate, where the runtime's generic code is compiled, and the runtime are
# optimized at 2 before it (the bare-metal C firmware test measures the trade-off).
[profile.release]
opt-level = \"s\"
lto = true
codegen-units = 1
panic = \"abort\"
debug = false

[profile.release.package.{name}]
opt-level = 2

[profile.release.package.mpc-runtime]
opt-level = 2
"
    )
}

/// The bare-metal library crate's source: the solver crate re-exported, which links its C
/// functions and panic handler into the archive.
fn bare_metal_lib(name: &str, stamp: &str) -> String {
    format!(
        "//! {stamp}
//!
//! The C ABI of `{name}` as a static library for bare-metal firmware (see `Cargo.toml`).
#![no_std]

pub use {name}::*;
"
    )
}

/// The Makefile fragment: `<NAME>_CFLAGS`, `<NAME>_LIBS`, `<NAME>_LIB` and a rule that runs
/// cargo for a missing archive. `<NAME>_TARGET` (set before the `include`) selects a
/// cross build: the bare-metal library crate, no system libraries.
fn makefile(name: &str, stamp: &str) -> String {
    let v = name.to_uppercase();
    format!(
        "# {stamp}
#
# Build glue for C/C++ projects (GNU make). In your Makefile:
#
#   include path/to/{name}.mk
#   app: main.c $({v}_LIB)
#   \t$(CC) $(CFLAGS) $({v}_CFLAGS) -o $@ main.c $({v}_LIBS)
#
# The static library is built by cargo; the rule below runs it when the archive is missing
# (`make {name}-staticlib` always asks cargo, which rebuilds only what changed). For bare
# metal set {v}_TARGET to the Rust target (e.g. thumbv7em-none-eabihf) before the include:
# the library is then lib{name}_bare_metal.a of the crate in {BARE_METAL_DIR}/ (without `std`,
# with the crate's panic handler, the firmware profile of its Cargo.toml) and links no
# system libraries. Override {v}_TARGET_DIR to share a cargo target directory.

{v}_DIR := $(patsubst %/,%,$(dir $(lastword $(MAKEFILE_LIST))))
# The rule below must not become the including Makefile's default goal.
{v}_DEFAULT_GOAL := $(.DEFAULT_GOAL)
{v}_TARGET ?=
{v}_PROFILE ?= release
{v}_TARGET_DIR ?= $({v}_DIR)/target
CARGO ?= cargo

ifeq ($(strip $({v}_TARGET)),)
{v}_MANIFEST := $({v}_DIR)/Cargo.toml
{v}_LIBDIR := $({v}_TARGET_DIR)/$({v}_PROFILE)
{v}_LIBNAME := {name}
{v}_CARGO_FLAGS ?=
{v}_SYSLIBS ?= {HOST_LIBS}
else
{v}_MANIFEST := $({v}_DIR)/{BARE_METAL_DIR}/Cargo.toml
{v}_LIBDIR := $({v}_TARGET_DIR)/$({v}_TARGET)/$({v}_PROFILE)
{v}_LIBNAME := {name}_bare_metal
{v}_CARGO_FLAGS ?= --target $({v}_TARGET)
{v}_SYSLIBS ?=
endif

{v}_LIB := $({v}_LIBDIR)/lib$({v}_LIBNAME).a
{v}_CFLAGS := -I$({v}_DIR)/include
{v}_LIBS := $({v}_LIB) $({v}_SYSLIBS)
# cargo's profile `dev` builds into `debug/`.
{v}_CARGO_PROFILE := $(if $(filter debug,$({v}_PROFILE)),dev,$({v}_PROFILE))

.PHONY: {name}-staticlib
$({v}_LIB) {name}-staticlib:
\t$(CARGO) build --profile $({v}_CARGO_PROFILE) --manifest-path $({v}_MANIFEST) \\
\t\t--target-dir $({v}_TARGET_DIR) $({v}_CARGO_FLAGS)

.DEFAULT_GOAL := $({v}_DEFAULT_GOAL)
"
    )
}

/// The pkg-config file of the host build (release profile, the crate's own `target/`),
/// located by `${pcfiledir}`, so the crate directory can move.
fn pkg_config(name: &str, stamp: &str, real: &str) -> String {
    format!(
        "# {stamp}
# Host build: cargo build --release --manifest-path <this directory>/Cargo.toml
# Use: PKG_CONFIG_PATH=<this directory> pkg-config --cflags --libs {name}
prefix=${{pcfiledir}}
includedir=${{prefix}}/include
libdir=${{prefix}}/target/release

Name: {name}
Description: mpcc-generated NMPC solver {name} ({real}), C ABI, static library
Version: 0.1.0
Cflags: -I${{includedir}}
Libs: ${{libdir}}/lib{name}.a {HOST_LIBS}
"
    )
}

/// What `mpcc build --staticlib` prints after writing crate `name` into `dir` (as the user
/// spelled it): the cargo command and the compile and link line, host and bare metal.
pub fn usage(dir: &str, name: &str) -> String {
    let v = name.to_uppercase();
    format!(
        "build the static library (host):\n  \
         cargo build --release --manifest-path {dir}/Cargo.toml\n\
         compile and link a C program with it:\n  \
         cc main.c -I{dir}/include {dir}/target/release/lib{name}.a {HOST_LIBS}\n  \
         (or GNU make: include {dir}/{name}.mk, then $({v}_CFLAGS) ... $({v}_LIBS); \
         or pkg-config: PKG_CONFIG_PATH={dir} pkg-config --cflags --libs {name})\n\
         bare metal (e.g. Cortex-M4F; no system libraries; the firmware profile):\n  \
         cargo build --release --manifest-path {dir}/{BARE_METAL_DIR}/Cargo.toml \
         --target thumbv7em-none-eabihf\n  \
         arm-none-eabi-gcc ... main.c -I{dir}/include \
         {dir}/{BARE_METAL_DIR}/target/thumbv7em-none-eabihf/release/lib{name}_bare_metal.a\n"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glue_only_for_a_staticlib_with_the_c_abi() {
        let mut o = Options::new();
        assert!(files("m", "s", &o).is_empty());
        o.staticlib = true;
        let f = files("m", "s", &o);
        let names: Vec<_> = f.iter().map(|(p, _)| p.display().to_string()).collect();
        assert_eq!(
            names,
            [
                "m.mk",
                "m.pc",
                "bare-metal/Cargo.toml",
                "bare-metal/src/lib.rs"
            ]
        );
        o.c_abi = false;
        assert!(files("m", "s", &o).is_empty());
    }

    #[test]
    fn the_fragment_builds_the_bare_metal_crate_it_names() {
        let mk = makefile("m", "s");
        let manifest = bare_metal_cargo_toml("m", "s");
        // The archive cargo writes is lib<package name>.a: the name the fragment links.
        assert!(
            manifest.contains("\n[package]\nname = \"m_bare_metal\"\n"),
            "{manifest}"
        );
        assert!(mk.contains("M_LIBNAME := m_bare_metal\n"), "{mk}");
        assert!(
            mk.contains("M_MANIFEST := $(M_DIR)/bare-metal/Cargo.toml\n"),
            "{mk}"
        );
        // A staticlib of its own workspace, so that its profile is the one cargo uses.
        assert!(manifest.contains("\n[workspace]\n"), "{manifest}");
        assert!(
            manifest.contains("crate-type = [\"staticlib\"]"),
            "{manifest}"
        );
        assert!(bare_metal_lib("m", "s").contains("pub use m::*;"));
    }

    #[test]
    fn makefile_recipe_lines_start_with_a_tab() {
        let mk = makefile("m", "s");
        let recipe: Vec<_> = mk
            .lines()
            .skip_while(|l| !l.starts_with("$(M_LIB) m-staticlib:"))
            .skip(1)
            .take_while(|l| !l.is_empty())
            .collect();
        assert_eq!(recipe.len(), 2, "{mk}");
        assert!(recipe.iter().all(|l| l.starts_with('\t')), "{mk}");
        // The fragment gives the default goal back to the including Makefile.
        assert!(
            mk.trim_end()
                .ends_with(".DEFAULT_GOAL := $(M_DEFAULT_GOAL)"),
            "{mk}"
        );
    }
}
