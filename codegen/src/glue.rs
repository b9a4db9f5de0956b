//! Build glue for C and C++ projects, written next to a `--staticlib` crate with a C ABI: a
//! Makefile fragment `<name>.mk` (host and bare metal) and a pkg-config file `<name>.pc`
//! (host). Why these and not a CMake package: `docs/codegen.md`, "Build glue for C".

use std::path::PathBuf;

use crate::Options;

/// The system libraries a hosted (`std`) staticlib needs on Linux, as the C ABI test links
/// them (`cc` adds `-lc` and `-lgcc_s` itself); bare metal needs none.
pub const HOST_LIBS: &str = "-lpthread -ldl -lm";

/// The cargo arguments of a bare-metal build: no `std`, the crate's own panic handler.
pub const BARE_METAL_FEATURES: &str = "--no-default-features --features panic-handler";

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
    ]
}

/// The Makefile fragment: `<NAME>_CFLAGS`, `<NAME>_LIBS`, `<NAME>_LIB` and a rule that runs
/// cargo for a missing archive. `<NAME>_TARGET` (set before the `include`) selects a
/// cross build (bare metal: no system libraries).
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
# the library is then built without `std`, with the crate's panic handler, and links no
# system libraries. Override {v}_TARGET_DIR to share a cargo target directory.

{v}_DIR := $(patsubst %/,%,$(dir $(lastword $(MAKEFILE_LIST))))
# The rule below must not become the including Makefile's default goal.
{v}_DEFAULT_GOAL := $(.DEFAULT_GOAL)
{v}_TARGET ?=
{v}_PROFILE ?= release
{v}_TARGET_DIR ?= $({v}_DIR)/target
CARGO ?= cargo

ifeq ($(strip $({v}_TARGET)),)
{v}_LIBDIR := $({v}_TARGET_DIR)/$({v}_PROFILE)
{v}_CARGO_FLAGS ?=
{v}_SYSLIBS ?= {HOST_LIBS}
else
{v}_LIBDIR := $({v}_TARGET_DIR)/$({v}_TARGET)/$({v}_PROFILE)
{v}_CARGO_FLAGS ?= --target $({v}_TARGET) {BARE_METAL_FEATURES}
{v}_SYSLIBS ?=
endif

{v}_LIB := $({v}_LIBDIR)/lib{name}.a
{v}_CFLAGS := -I$({v}_DIR)/include
{v}_LIBS := $({v}_LIB) $({v}_SYSLIBS)
# cargo's profile `dev` builds into `debug/`.
{v}_CARGO_PROFILE := $(if $(filter debug,$({v}_PROFILE)),dev,$({v}_PROFILE))

.PHONY: {name}-staticlib
$({v}_LIB) {name}-staticlib:
\t$(CARGO) build --profile $({v}_CARGO_PROFILE) --manifest-path $({v}_DIR)/Cargo.toml \\
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
         bare metal (e.g. Cortex-M4F; no system libraries):\n  \
         cargo build --release --manifest-path {dir}/Cargo.toml --target thumbv7em-none-eabihf \
         {BARE_METAL_FEATURES}\n  \
         arm-none-eabi-gcc ... main.c -I{dir}/include \
         {dir}/target/thumbv7em-none-eabihf/release/lib{name}.a\n"
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
        assert_eq!(names, ["m.mk", "m.pc"]);
        o.c_abi = false;
        assert!(files("m", "s", &o).is_empty());
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
