//! Generation options.

/// The scalar type of the generated solver.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Scalar {
    /// `f64` (default).
    #[default]
    F64,
    /// `f32` (microcontrollers with a single-precision FPU).
    F32,
}

impl Scalar {
    /// `f64` or `f32`.
    pub fn rust(self) -> &'static str {
        match self {
            Scalar::F64 => "f64",
            Scalar::F32 => "f32",
        }
    }

    /// `double` or `float`.
    pub fn c(self) -> &'static str {
        match self {
            Scalar::F64 => "double",
            Scalar::F32 => "float",
        }
    }
}

/// QP settings baked into the generated solver (`None`: the runtime's default for the
/// precision).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct QpOptions {
    /// Interior-point iteration limit.
    pub max_iter: Option<u32>,
    /// Stationarity, equality and inequality tolerance.
    pub tol: Option<f64>,
    /// Complementarity tolerance.
    pub tol_comp: Option<f64>,
    /// Warm start from the previous step's multipliers (the runtime's RTI default is on).
    pub warm_start_dual: Option<bool>,
    /// How the QPs are solved (`None`: [`QpMethod::Auto`]). `Auto` and `Riccati` give the
    /// solver no condensing storage (`NC = 0`): with the warm active set of the real-time
    /// iteration a step costs one factorization, and the Riccati recursion's is the cheaper
    /// (condensing runs a recursion of about the same cost for `P_k` and factorizes a dense
    /// Hessian on top).
    /// `Condensed` gives it the storage (`NC = N`) and asks for condensing: the shorter
    /// feedback phase; for short horizons (QR-bench A; [`mpc_runtime::condensing_pays`])
    /// fewer operations where the interior point does the work (the warm active set off),
    /// and, for a model with control bounds only, which then has no Riccati storage
    /// (`NR = 0`), the smaller solver.
    pub method: Option<QpMethod>,
}

pub use mpc_runtime::QpMethod;

/// How the generated `Cargo.toml` refers to `mpc-runtime`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum RuntimeDep {
    /// A path, relative to the generated crate's directory (written as given).
    Path(String),
    /// A version requirement (the default: this generator's runtime version, `X.Y.Z`,
    /// which cargo reads as `^X.Y.Z`).
    Version(String),
    /// A copy of the runtime's source, written into the generated crate at
    /// `vendor/mpc-runtime` (with its own `Cargo.toml`) and depended on by path: the crate
    /// then builds with no network and no checkout of mpcc (only `nalgebra` and `libm`
    /// are fetched, or taken from a vendored registry).
    Vendored,
}

impl Default for RuntimeDep {
    fn default() -> Self {
        RuntimeDep::Version(crate::vendor::RUNTIME_VERSION.to_string())
    }
}

/// Everything that shapes the generated code besides the model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Options {
    /// Scalar type.
    pub scalar: Scalar,
    /// Crate name (and C symbol prefix); default: the model name.
    pub crate_name: Option<String>,
    /// QP settings.
    pub qp: QpOptions,
    /// Shift the trajectory before each preparation (`None`: the model's `solver { shift }`
    /// if it says, else the runtime's default, on).
    pub shift: Option<bool>,
    /// Emit the C ABI module and header.
    pub c_abi: bool,
    /// Build the crate as a `staticlib` too (adds the `std` feature, on by default, which
    /// links `std` for the panic handler on hosted targets).
    pub staticlib: bool,
    /// The `mpc-runtime` dependency of the generated `Cargo.toml`.
    pub runtime: RuntimeDep,
    /// Emit the dynamics' part of the Lagrangian Hessian (`Model::dynamics_hessian`), and the
    /// general constraints' (`Model::constraints_hessian`) for a model with any, and give
    /// the QP one Hessian per stage (`NH = N`): the full SQP ([`solve_sqp`]) then takes
    /// exact-Hessian (Newton) steps, which converge quadratically where Gauss-Newton's
    /// converge linearly. The real-time iteration stays Gauss-Newton. Costs code size and,
    /// for models whose stage Hessian would otherwise be shared, RAM and preparation time.
    ///
    /// [`solve_sqp`]: mpc_runtime::Rti::solve_sqp
    pub exact_hessian: bool,
}

impl Options {
    /// Options for a crate with the C ABI, f64.
    pub fn new() -> Options {
        Options {
            c_abi: true,
            ..Options::default()
        }
    }

    /// The crate name for model `model`.
    pub fn crate_name(&self, model: &str) -> String {
        self.crate_name.clone().unwrap_or_else(|| model.to_string())
    }

    /// A stable one-line description, part of the stamp hash.
    pub(crate) fn describe(&self) -> String {
        format!(
            "scalar={} crate={:?} qp={:?} shift={:?} c_abi={} staticlib={} runtime={:?}{}",
            self.scalar.rust(),
            self.crate_name,
            self.qp,
            self.shift,
            self.c_abi,
            self.staticlib,
            self.runtime,
            // Only when on, so the stamps of existing crates do not change.
            if self.exact_hessian {
                " exact_hessian"
            } else {
                ""
            }
        )
    }
}
