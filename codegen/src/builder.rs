//! [`Builder`]: code generation from a `build.rs`, as prost-build and tonic-build do.

use std::path::{Path, PathBuf};

use mpc_dsl::Ocp;

use crate::error::CodegenError;
use crate::options::{Options, QpOptions, Scalar};

/// Generates a solver module into `OUT_DIR` from a `build.rs`.
///
/// In `build.rs`:
///
/// ```no_run
/// mpc_codegen::Builder::new("models/quadrotor_rates.mpc")
///     .module("quadrotor")
///     .scalar(mpc_codegen::Scalar::F32)
///     .build()
///     .unwrap_or_else(|e| panic!("{e}"));
/// ```
///
/// and in the crate: `mpc_runtime::include_solver!("quadrotor");`, then
/// `quadrotor::Solver::new()`.
///
/// The module is `pub mod <module>` in `$OUT_DIR/<module>.rs`; it needs `mpc-runtime` and
/// `libm` as dependencies of the crate that includes it: the module names `mpc_runtime::...`
/// and resolves it through that crate's own `[dependencies]`, by version
/// (`mpc-runtime = { version = "0.1", default-features = false }`, the version of this
/// `mpc-codegen`) or by path (a checkout, or a copy such as `mpcc build --vendor-runtime`
/// writes). [`Options::runtime`] plays no part here: no `Cargo.toml` is written. Cargo is
/// told to rerun the build script when the model file changes.
#[derive(Clone, Debug)]
pub struct Builder {
    file: Option<PathBuf>,
    variant: Option<String>,
    module: Option<String>,
    out_dir: Option<PathBuf>,
    opts: Options,
}

impl Builder {
    /// A builder for the `.mpc` file `path` (relative to the package, as build scripts run
    /// there). Defaults: f64, the model's name as module name, no C ABI.
    pub fn new(path: impl AsRef<Path>) -> Builder {
        Builder {
            file: Some(path.as_ref().to_path_buf()),
            ..Builder::from_ocp()
        }
    }

    /// A builder for a problem made with the Rust builder API (pass it to
    /// [`build_ocp`](Self::build_ocp)).
    pub fn from_ocp() -> Builder {
        Builder {
            file: None,
            variant: None,
            module: None,
            out_dir: None,
            opts: Options {
                c_abi: false,
                ..Options::default()
            },
        }
    }

    /// Applies the file's `variant NAME { ... }` block.
    pub fn variant(mut self, name: &str) -> Builder {
        self.variant = Some(name.to_string());
        self
    }

    /// The module name (default: the model's name).
    pub fn module(mut self, name: &str) -> Builder {
        self.module = Some(name.to_string());
        self
    }

    /// Scalar type.
    pub fn scalar(mut self, s: Scalar) -> Builder {
        self.opts.scalar = s;
        self
    }

    /// QP settings baked into the solver.
    pub fn qp(mut self, qp: QpOptions) -> Builder {
        self.opts.qp = qp;
        self
    }

    /// Shift the trajectory before each preparation.
    pub fn shift(mut self, on: bool) -> Builder {
        self.opts.shift = Some(on);
        self
    }

    /// Also emit the C ABI functions (`#[no_mangle] extern "C"`) into the module.
    pub fn c_abi(mut self, on: bool) -> Builder {
        self.opts.c_abi = on;
        self
    }

    /// Emit the dynamics' Lagrangian Hessian for exact-Hessian full SQP steps (see
    /// [`Options::exact_hessian`]).
    pub fn exact_hessian(mut self, on: bool) -> Builder {
        self.opts.exact_hessian = on;
        self
    }

    /// Write into `dir` instead of `$OUT_DIR`.
    pub fn out_dir(mut self, dir: impl AsRef<Path>) -> Builder {
        self.out_dir = Some(dir.as_ref().to_path_buf());
        self
    }

    fn target(&self, module: &str) -> Result<PathBuf, CodegenError> {
        let dir = match &self.out_dir {
            Some(d) => d.clone(),
            None => std::env::var_os("OUT_DIR")
                .map(PathBuf::from)
                .ok_or_else(|| {
                    CodegenError::Option(
                        "OUT_DIR is not set: call the Builder from build.rs, or set out_dir()"
                            .into(),
                    )
                })?,
        };
        Ok(dir.join(format!("{module}.rs")))
    }

    fn write(&self, module: &str, text: &str) -> Result<PathBuf, CodegenError> {
        let path = self.target(module)?;
        if std::fs::read_to_string(&path).is_ok_and(|old| old == text) {
            return Ok(path);
        }
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|source| CodegenError::Io {
                path: parent.display().to_string(),
                source,
            })?;
        }
        let tmp = path.with_extension("mpcc-tmp");
        let err = |p: &Path| {
            let p = p.display().to_string();
            move |source| CodegenError::Io { path: p, source }
        };
        std::fs::write(&tmp, text).map_err(err(&tmp))?;
        std::fs::rename(&tmp, &path).map_err(err(&path))?;
        Ok(path)
    }

    /// Generates from the `.mpc` file; returns the written path.
    ///
    /// # Errors
    /// [`CodegenError::Option`] if the builder was made with [`from_ocp`](Self::from_ocp),
    /// the file's parse errors (rendered), and those of [`generate_module`](crate::generate_module).
    pub fn build(&self) -> Result<PathBuf, CodegenError> {
        let Some(file) = &self.file else {
            return Err(CodegenError::Option(
                "this Builder has no model file: use build_ocp(&ocp)".into(),
            ));
        };
        println!("cargo:rerun-if-changed={}", file.display());
        crate::with_model_file(file, self.variant.as_deref(), |ocp| self.build_ocp(ocp))
    }

    /// Generates from a problem; returns the written path.
    ///
    /// # Errors
    /// Those of [`generate_module`](crate::generate_module), and [`CodegenError::Io`].
    pub fn build_ocp(&self, ocp: &Ocp<'_>) -> Result<PathBuf, CodegenError> {
        let module = self.module.clone().unwrap_or_else(|| ocp.name.clone());
        let mut opts = self.opts.clone();
        opts.crate_name = Some(module.clone());
        let text = crate::generate_module(ocp, &module, &opts)?;
        self.write(&module, &text)
    }
}
