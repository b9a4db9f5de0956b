//! `mpcc`: the command-line front end of the mpcc NMPC compiler.

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod bench;
mod fly;
mod sim;
mod sitl;
mod throw;
mod trials;
use mpc_dsl::lang::{ParseOptions, parse};
use mpc_dsl::ocp::{Dynamics, Integrator, Ocp, ParamKind, Variable};
use mpc_dsl::{Expr, ExprKind, Graph, Sparsity};

/// A code-generating compiler for nonlinear model predictive control.
#[derive(Parser)]
#[command(name = "mpcc", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fly a mission in the closed-loop simulator with a generated solver; print a summary,
    /// write a CSV log and PNG plots.
    Sim(SimArgs),
    /// Parse and validate a `.mpc` file; print its dimensions, the size of the dynamics
    /// before and after common-subexpression elimination, and the Jacobian sparsity.
    Check {
        /// The `.mpc` file.
        file: PathBuf,
        /// Apply the file's `variant NAME { ... }` block.
        #[arg(long)]
        variant: Option<String>,
    },
    /// Generate a solver crate (Rust, `no_std`, with a C header) from a `.mpc` file.
    Build(BuildArgs),
    /// Run the QR-bench closed loop (the peers' benchmark) with a generated solver; print
    /// latency per phase, QP iterations and the final error; write the trajectory CSV.
    Bench(BenchArgs),
    /// Fly a mission through PX4 (a vehicle, PX4 SITL or `mpcc sitl`) over MAVLink with the
    /// generated NMPC: OFFBOARD body rates and thrust, with the failsafes; print a summary,
    /// write a CSV log and PNG plots of the telemetry.
    Fly(FlyArgs),
    /// A simulated PX4 vehicle on a MAVLink link (PX4's offboard rules, messages and frames)
    /// for `mpcc fly` to fly against.
    Sitl(SitlArgs),
}

// The doc comments below are `--help` text (clap prints them verbatim): units are written
// `[m]`, not escaped for rustdoc, which would read them as intra-doc links.
/// Where the mission flies, for `mpcc sim` and `mpcc fly`.
#[derive(clap::Args)]
#[allow(rustdoc::broken_intra_doc_links)]
struct MissionShape {
    /// Rally point, where the flip happens and which is held after it, relative to home (ENU)
    /// [m] (default 4,0,2).
    #[arg(long, value_name = "X,Y,Z")]
    rally: Option<String>,
    /// Take-off height above home [m] (default 2; also the return height).
    #[arg(long, value_name = "M")]
    altitude: Option<f64>,
    /// Pitch-rate reference of the flip [rad/s] (default 5*pi = 15.71).
    #[arg(long, value_name = "RAD_S")]
    flip_rate: Option<f64>,
}

// The doc comments below are `--help` text (clap prints them verbatim): units are written
// `[m]`, not escaped for rustdoc, which would read them as intra-doc links.
#[derive(clap::Args)]
#[allow(rustdoc::broken_intra_doc_links)]
struct FlyArgs {
    /// The link to PX4: udpin:HOST:PORT (listen, answer the sender; PX4 SITL's offboard link
    /// is udpin:127.0.0.1:14540), udpout:HOST:PORT, or serial:DEVICE:BAUD.
    #[arg(long)]
    connect: String,
    /// Mission: flip (the paper's), hover or step.
    #[arg(long, default_value = "flip")]
    mission: String,
    /// PX4's normalized hover thrust (0..1) for the thrust mapping (default: read PX4's
    /// MPC_THR_HOVER).
    #[arg(long, value_name = "THRUST")]
    hover_thrust: Option<f64>,
    /// Setpoint rate [Hz] (25..250; the solver runs at its model's 20 Hz).
    #[arg(long, default_value_t = 100.0, value_name = "HZ")]
    rate: f64,
    /// No new odometry for this long in flight commands PX4's return mode [s].
    #[arg(long, default_value_t = 0.1, value_name = "S")]
    odometry_timeout: f64,
    /// The hover mission's hold [s] (default 5).
    #[arg(long, value_name = "S")]
    hover_time: Option<f64>,
    /// The vehicle's profile (JSON: mass, rotor thrust, pitch lever and inertia, rotor time
    /// constant; docs/shim.md). Default: PX4's SIH parameters; a flip needs one or the other.
    /// The profile flown is written to OUT/vehicle.json.
    #[arg(long, value_name = "FILE")]
    vehicle: Option<PathBuf>,
    /// With a udpin link, take datagrams only from PX4 at this address (HOST:PORT; PX4
    /// SITL's offboard link sends from 127.0.0.1:14580). Default: the sender of the first
    /// PX4 HEARTBEAT.
    #[arg(long, value_name = "HOST:PORT")]
    autopilot: Option<String>,
    /// Sign every MAVLink 2 frame with this key and take only frames signed with it (a file
    /// of 32 bytes or 64 hexadecimal digits; docs/shim.md, "Link security").
    #[arg(long, value_name = "FILE")]
    signing_key: Option<PathBuf>,
    #[command(flatten)]
    shape: MissionShape,
    /// Give up (and land) after this long [s].
    #[arg(long, default_value_t = 180.0, value_name = "S")]
    timeout: f64,
    /// Output directory of the CSV log and the plots.
    #[arg(long, default_value = "fly-out")]
    out: PathBuf,
    /// Write no CSV or plots.
    #[arg(long)]
    no_plots: bool,
    /// Print the report as one JSON object on stdout (and nothing else).
    #[arg(long)]
    json: bool,
}

// The doc comments below are `--help` text (clap prints them verbatim): units are written
// `[m]`, not escaped for rustdoc, which would read them as intra-doc links.
#[derive(clap::Args)]
#[allow(rustdoc::broken_intra_doc_links)]
struct SitlArgs {
    /// Where to send (as PX4 SITL: udpout:127.0.0.1:14540), or udpin:HOST:PORT.
    #[arg(long, default_value = "udpout:127.0.0.1:14540")]
    connect: String,
    /// Stop after this long [s] (default: at Ctrl-C).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    /// Stop once the vehicle has flown and is disarmed again (2 s later: the 1 Hz HEARTBEAT
    /// shows the disarm to the controller).
    #[arg(long)]
    exit_after_flight: bool,
    /// Seed of the estimation noise (and of the default height error).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Odometry without noise, latency or height error (unless --height-bias).
    #[arg(long)]
    perfect_sensing: bool,
    /// The vehicle PX4 flies: agile (the simulator's design vehicle: thrust-to-weight 4,
    /// ~390 rad/s^2, 30 ms rotors) or stock (PX4's SIH quadrotor: 1 kg, 4 x 5 N, ~80 rad/s^2
    /// with PX4's default rate gains, MPC_THR_HOVER 0.5).
    #[arg(long, default_value = "agile", value_name = "NAME")]
    vehicle: String,
    /// The vehicle's clock in seconds per wall-clock second (0.5..2.0; PX4 SITL in
    /// lockstep ran 1.0-1.5 % slow). Its timeouts run on that clock.
    #[arg(long, default_value_t = 0.988, value_name = "R")]
    clock_rate: f64,
    /// At vehicle time AT [s], shift every timestamp from then on by BY [s] (either sign: a
    /// PX4 reboot, a restarted simulation).
    #[arg(long, value_name = "AT:BY", allow_hyphen_values = true)]
    clock_jump: Option<String>,
    /// The estimate's height error (reported minus true) [m], reached 20 s after arming
    /// (default: 0.2..0.7 m either way, drawn from the seed, as PX4's EKF2 on GNSS height;
    /// 0 with --perfect-sensing).
    #[arg(long, value_name = "M", allow_hyphen_values = true)]
    height_bias: Option<f64>,
    /// Sign every MAVLink 2 frame with this key and take only frames signed with it (the
    /// same key file as `mpcc fly --signing-key`).
    #[arg(long, value_name = "FILE")]
    signing_key: Option<PathBuf>,
    /// Print the summary as one JSON object on stdout.
    #[arg(long)]
    json: bool,
}

// The doc comments below are `--help` text (clap prints them verbatim): `<N>` is not HTML.
#[derive(clap::Args)]
#[allow(rustdoc::invalid_html_tags)]
struct BenchArgs {
    /// Benchmark problem.
    #[arg(long, default_value = "qrbench")]
    model: String,
    /// Horizon: 10 (QR-bench A, dt = 0.04), 20 (QR-bench B, dt = 0.05) or 40 (dt = 0.025).
    #[arg(long, default_value_t = 10)]
    horizon: usize,
    /// The f32 solver.
    #[arg(long)]
    f32: bool,
    /// Converged SQP at every step instead of one real-time iteration.
    #[arg(long)]
    sqp: bool,
    /// With --sqp, how the SQP's QPs are solved: loose (the interior point to 1e-3, then the
    /// active-set polish; the f64 default) or tight (the interior point to the QP
    /// tolerances; the f32 default). `RtiSettings::sqp_loose_qps`.
    #[arg(long, value_name = "loose|tight")]
    sqp_qps: Option<String>,
    /// With --sqp, the Hessian of the SQP's QPs: exact (Gauss-Newton's plus the dynamics'
    /// curvature, from the solvers generated with --exact-hessian: QR-bench A and B in f64,
    /// the default there) or gauss-newton (the real-time iteration's solvers).
    #[arg(long, value_name = "exact|gauss-newton")]
    hessian: Option<String>,
    /// With --sqp and the exact Hessian, how many Newton steps in a row the watchdog takes
    /// whole without their decreasing the merit function before it goes back (default 4;
    /// 0: a monotone line search at every step). `RtiSettings::sqp_watchdog`.
    #[arg(long, value_name = "STEPS")]
    sqp_watchdog: Option<u32>,
    /// How each QP starts: on (the default) from the last QP's active set, factorized in the
    /// preparation phase (the interior point only where that set and the active-set
    /// iterations after it miss); off: every QP by the interior point.
    /// `QpSettings::warm_active_set`.
    #[arg(long, value_name = "on|off")]
    warm_active_set: Option<String>,
    /// Closed loops to time (the figures pool every step of every round).
    #[arg(long, default_value_t = 20)]
    rounds: usize,
    /// Where to write the trajectory CSV (default bench-out/qrbench_n<N>_<scalar>.csv).
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Write no CSV.
    #[arg(long)]
    no_csv: bool,
    /// Print the figures as one JSON object on stdout.
    #[arg(long)]
    json: bool,
}

// The doc comments below are `--help` text (clap prints them verbatim): units are written
// `[m]`, not escaped for rustdoc, which would read them as intra-doc links.
#[derive(clap::Args)]
#[allow(rustdoc::broken_intra_doc_links)]
struct SimArgs {
    /// Mission: flip (the paper's), hover, step, or flip-throw (throw the tethered probe to
    /// a target --range metres away during a pitch-over, recover, return, land).
    #[arg(long, default_value = "flip")]
    mission: String,
    /// Outer loop: paper (point-mass MPC + geometric attitude; the default) or nmpc
    /// (quaternion NMPC). flip-throw always flies the swing-aware probe NMPC.
    #[arg(long)]
    controller: Option<String>,
    /// flip-throw: range from the probe's start to the target [m]; a list (5,10,15,20,25)
    /// flies each and prints one table.
    #[arg(long, value_name = "M[,M...]")]
    range: Option<String>,
    /// flip-throw: upper bound of the release speed [m/s] (default 16).
    #[arg(long, value_name = "M_S")]
    v_max: Option<f64>,
    /// flip-throw: quadratic air drag of the free probe [N/(m/s)^2] (default 0: none).
    #[arg(long, value_name = "C")]
    probe_drag: Option<f64>,
    /// Number of trials (seeds S, S+1, ...).
    #[arg(long, default_value_t = 1)]
    trials: usize,
    /// Seed of the first trial.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Monte Carlo: draw mass +-20 %, inertia +-30 %, rotor time constant 20-40 ms, sensing
    /// latency 0-10 ms and a wind gust for every trial.
    #[arg(long)]
    randomize: bool,
    /// No estimation noise or latency (the true state).
    #[arg(long)]
    perfect_sensing: bool,
    #[command(flatten)]
    shape: MissionShape,
    /// True vehicle mass [kg] (the controllers keep believing the nominal 1 kg).
    #[arg(long, value_name = "KG")]
    mass: Option<f64>,
    /// The paper's trial 9: lose the pose at this many seconds into the flip, for good.
    #[arg(long, value_name = "SECONDS")]
    pose_loss: Option<f64>,
    /// Output directory of the CSV log and the plots (of the first trial).
    #[arg(long, default_value = "sim-out")]
    out: PathBuf,
    /// Write no CSV or plots.
    #[arg(long)]
    no_plots: bool,
    /// Print the summary as one JSON object on stdout (and nothing else there).
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum QpMethodArg {
    Auto,
    Riccati,
    Condensed,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum OnOff {
    On,
    Off,
}

#[derive(clap::Args)]
struct BuildArgs {
    /// The `.mpc` file.
    file: PathBuf,
    /// Output directory of the crate (created if needed).
    #[arg(short, long)]
    out: PathBuf,
    /// Apply the file's `variant NAME { ... }` block.
    #[arg(long)]
    variant: Option<String>,
    /// Generate an f32 solver (default f64).
    #[arg(long)]
    f32: bool,
    /// Also build the crate as a staticlib (for C/C++ projects).
    #[arg(long)]
    staticlib: bool,
    /// Crate name and C symbol prefix (default: the model name).
    #[arg(long)]
    name: Option<String>,
    /// Leave out the C ABI module and header.
    #[arg(long)]
    no_c_abi: bool,
    /// Emit the dynamics' (and general constraints') Lagrangian Hessian: the full SQP
    /// (`solve_sqp`) takes exact-Hessian steps (the QP keeps one Hessian per stage; the
    /// real-time iteration stays Gauss-Newton, with general costs' Hessians convexified).
    #[arg(long)]
    exact_hessian: bool,
    /// QP iteration limit baked into the solver.
    #[arg(long)]
    qp_max_iter: Option<u32>,
    /// QP tolerance (stationarity, equality, inequality) baked into the solver.
    #[arg(long)]
    qp_tol: Option<f64>,
    /// How the QPs are solved: `auto` and `riccati` by the Riccati recursion (the cheaper
    /// step with the warm active set), `condensed` condensed (a dense QP in the controls)
    /// whenever the QP allows it: the shorter feedback, and for short horizons with control
    /// bounds only the smaller solver.
    #[arg(long, value_enum, default_value_t = QpMethodArg::Auto)]
    qp_method: QpMethodArg,
    /// The real-time iteration's shift of the trajectory by one stage before each
    /// preparation, baked into `default_settings()` (default on; `off` keeps the last
    /// solution in place, as acados' RTI does). Also at run time: `settings.shift`, C
    /// `<name>_set_settings`.
    #[arg(long, value_enum)]
    shift: Option<OnOff>,
    /// Depend on mpc-runtime by this path (as written into the generated Cargo.toml, relative
    /// to the output directory) instead of by version.
    #[arg(long, value_name = "PATH", conflicts_with = "vendor_runtime")]
    runtime_path: Option<String>,
    /// Write a copy of mpc-runtime's source (embedded in mpcc) into OUT/vendor/mpc-runtime
    /// and depend on it by path: the crate builds with no network and no checkout of mpcc.
    #[arg(long)]
    vendor_runtime: bool,
    /// Do not write: compare with what is in the output directory, exit 1 on any difference.
    #[arg(long)]
    check: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Sim(args) if args.mission == "flip-throw" => throw::run(&args),
        Command::Sim(args) => sim::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Fly(args) => fly::fly(&args),
        Command::Sitl(args) => sitl::sitl(&args),
        Command::Check { file, variant } => check(&file, variant),
        Command::Build(args) => build(&args),
    }
}

fn build(a: &BuildArgs) -> ExitCode {
    use mpc_codegen::{Options, QpMethod, QpOptions, RuntimeDep, Scalar};
    // By version unless told otherwise: the default names no path of this machine.
    let runtime = match &a.runtime_path {
        Some(p) => RuntimeDep::Path(p.clone()),
        None if a.vendor_runtime => RuntimeDep::Vendored,
        None => RuntimeDep::default(),
    };
    let opts = Options {
        scalar: if a.f32 { Scalar::F32 } else { Scalar::F64 },
        crate_name: a.name.clone(),
        qp: QpOptions {
            max_iter: a.qp_max_iter,
            tol: a.qp_tol,
            method: match a.qp_method {
                QpMethodArg::Auto => None,
                QpMethodArg::Riccati => Some(QpMethod::Riccati),
                QpMethodArg::Condensed => Some(QpMethod::Condensed),
            },
            ..QpOptions::default()
        },
        shift: a.shift.map(|s| matches!(s, OnOff::On)),
        c_abi: !a.no_c_abi,
        staticlib: a.staticlib,
        runtime,
        exact_hessian: a.exact_hessian,
    };
    let generated = match mpc_codegen::generate_file(&a.file, a.variant.as_deref(), &opts) {
        Ok(g) => g,
        Err(mpc_codegen::CodegenError::Parse(text)) => {
            eprint!("{text}");
            return ExitCode::FAILURE;
        }
        Err(e) => {
            eprintln!("error: {}: {e}", a.file.display());
            return ExitCode::FAILURE;
        }
    };
    if a.check {
        let stale = generated.check(&a.out);
        if stale.is_empty() {
            println!("{}: up to date", a.out.display());
            return ExitCode::SUCCESS;
        }
        for p in &stale {
            eprintln!(
                "{}: differs from the generator's output",
                a.out.join(p).display()
            );
        }
        eprintln!(
            "regenerate with: mpcc build {} -o {}",
            a.file.display(),
            a.out.display()
        );
        return ExitCode::FAILURE;
    }
    match generated.write_files(&a.out) {
        Ok(outcome) => {
            for ((p, written), (_, c)) in outcome.iter().zip(&generated.files) {
                println!(
                    "{} {} ({} lines)",
                    if *written { "wrote" } else { "unchanged" },
                    a.out.join(p).display(),
                    c.lines().count()
                );
            }
            if a.staticlib && !a.no_c_abi {
                let dir = a.out.display().to_string();
                print!("{}", mpc_codegen::glue::usage(&dir, &generated.name));
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn check(file: &std::path::Path, variant: Option<String>) -> ExitCode {
    let shown = file.display().to_string();
    let src = match std::fs::read_to_string(file) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: cannot read {shown}: {e}");
            return ExitCode::FAILURE;
        }
    };
    let g = Graph::new();
    let parsed = match parse(&g, &src, &ParseOptions { variant }) {
        Ok(p) => p,
        Err(diags) => {
            eprint!("{}", diags.render(&shown, &src));
            eprintln!("{shown}: {} error(s)", diags.errors().count());
            return ExitCode::FAILURE;
        }
    };
    for w in &parsed.warnings {
        eprint!("{}", w.render(&shown, &src));
    }
    // What `mpcc build` would refuse: names the generated crate cannot use, functions that
    // are not finite at the guess.
    match mpc_codegen::checks::check(&parsed.ocp, &mpc_codegen::Options::new()) {
        Ok(_) => {}
        Err(mpc_codegen::CodegenError::Check(c)) => {
            let diags = c.diagnostics(&parsed.source);
            eprint!("{}", diags.render(&shown, &src));
            eprintln!("{shown}: {} error(s)", diags.errors().count());
            return ExitCode::FAILURE;
        }
        Err(e) => {
            eprintln!("error: {shown}: {e}");
            return ExitCode::FAILURE;
        }
    }
    match report(&g, &parsed.ocp) {
        Ok(text) => {
            print!("{text}");
            println!("{shown}: ok ({} warning(s))", parsed.warnings.len());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {shown}: {e}");
            ExitCode::FAILURE
        }
    }
}

fn list(vars: &[Variable<'_>]) -> String {
    vars.iter()
        .map(|v| {
            if v.scalar {
                v.name.clone()
            } else {
                format!("{}[{}]", v.name, v.len())
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Operations in the expression trees of `roots` if nothing were shared (f64: it can be
/// astronomically large).
fn tree_ops(roots: &[Expr<'_>]) -> f64 {
    fn go(e: Expr<'_>, memo: &mut HashMap<usize, f64>) -> f64 {
        if let Some(&v) = memo.get(&e.index()) {
            return v;
        }
        let v = match e.kind() {
            ExprKind::Constant(_) | ExprKind::Symbol(_) => 0.0,
            ExprKind::Unary(_, a) | ExprKind::PowI(a, _) => 1.0 + go(a, memo),
            ExprKind::Binary(_, a, b) => 1.0 + go(a, memo) + go(b, memo),
        };
        memo.insert(e.index(), v);
        v
    }
    let mut memo = HashMap::new();
    roots.iter().map(|&r| go(r, &mut memo)).sum()
}

fn pattern(s: &Sparsity, rows: &[String], cols: usize) -> String {
    let width = rows.iter().map(String::len).max().unwrap_or(0);
    let mut out = String::new();
    for (i, name) in rows.iter().enumerate() {
        let line: String = (0..cols)
            .map(|j| if s.contains(i, j) { '*' } else { '.' })
            .collect();
        out.push_str(&format!("    {name:>width$}  {line}\n"));
    }
    out
}

/// What `mpcc check` prints of a model: its description, then its expressions' sizes and
/// Jacobians.
fn report(g: &Graph, ocp: &Ocp<'_>) -> mpc_dsl::Result<String> {
    let mut o = describe(ocp);
    o.push_str(&expressions(g, ocp)?);
    Ok(o)
}

/// The dynamics and their discretization, in words.
fn dynamics_words(dynamics: &Dynamics<'_>) -> String {
    match dynamics {
        Dynamics::Continuous {
            integrator: Integrator::Rk4 { steps },
            ..
        } => format!("ode, rk4 with {steps} substep(s)"),
        Dynamics::Continuous {
            integrator: Integrator::Euler,
            ..
        } => "ode, explicit euler".into(),
        Dynamics::Continuous {
            integrator:
                Integrator::Irk {
                    stages,
                    steps,
                    newton,
                    collocation,
                },
            ..
        } => format!(
            "ode, irk ({}) with {stages} stage(s), {steps} substep(s), {newton} Newton \
             iteration(s)",
            match collocation {
                mpc_dsl::ocp::Collocation::GaussLegendre => "Gauss-Legendre",
                mpc_dsl::ocp::Collocation::RadauIia => "Radau IIA",
            }
        ),
        Dynamics::Discrete { .. } => "discrete map".into(),
    }
}

/// The model's dimensions, horizon, cost terms, bounds and constraints.
fn describe(ocp: &Ocp<'_>) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let integ = dynamics_words(&ocp.dynamics);
    let params = ocp
        .parameters
        .iter()
        .map(|q| {
            let kind = match q.kind {
                ParamKind::Stage => "stage",
                ParamKind::Global => "global",
            };
            format!("{} ({kind})", list(std::slice::from_ref(&q.var)))
        })
        .collect::<Vec<_>>()
        .join(" ");
    let _ = writeln!(o, "model {}", ocp.name);
    let _ = writeln!(
        o,
        "  states      nx = {:<3} {}",
        ocp.nx(),
        list(&ocp.states)
    );
    let _ = writeln!(
        o,
        "  controls    nu = {:<3} {}",
        ocp.nu(),
        list(&ocp.controls)
    );
    let _ = writeln!(o, "  parameters  np = {:<3} {params}", ocp.np());
    let _ = writeln!(
        o,
        "  horizon     N = {}, dt = {} s ({integ})",
        ocp.horizon.n, ocp.horizon.dt
    );
    let c = &ocp.cost;
    let mut terms = Vec::new();
    for (name, t) in [("Q", &c.state), ("R", &c.control), ("P", &c.terminal)] {
        if let Some(t) = t {
            terms.push(format!("{name} {}x{}", t.weight.nrows(), t.weight.ncols()));
        }
    }
    for r in &c.residuals {
        terms.push(format!("residual {} ({})", r.name, r.residual.len()));
    }
    if c.input_rate.is_some() {
        terms.push("input rate".into());
    }
    for t in &c.general {
        let at = match t.stage {
            mpc_dsl::ocp::Stage::Path => "stage",
            mpc_dsl::ocp::Stage::Terminal => "terminal",
        };
        terms.push(format!("{at} {} (general)", t.name));
    }
    let _ = writeln!(o, "  cost        {}", terms.join(", "));
    let soft_of = |b: &mpc_dsl::ocp::Bounds| match b.soft_entries().len() {
        0 => String::new(),
        n => format!(" ({n} soft)"),
    };
    let _ = writeln!(
        o,
        "  bounds      x: {} of {} entries{}, u: {} of {} entries{}",
        ocp.state_bounds.active().len(),
        ocp.nx(),
        soft_of(&ocp.state_bounds),
        ocp.control_bounds.active().len(),
        ocp.nu(),
        soft_of(&ocp.control_bounds)
    );
    let soft = ocp.constraints.iter().filter(|k| k.soft.is_some()).count();
    let rows: usize = ocp.constraints.iter().map(|k| k.expr.len()).sum();
    let _ = writeln!(
        o,
        "  constraints {} general ({rows} rows, {soft} soft)",
        ocp.constraints.len()
    );
    o
}

/// The dynamics and the discrete map (operations as trees, instructions after CSE) and the
/// sparsity of their Jacobians.
fn expressions(g: &Graph, ocp: &Ocp<'_>) -> mpc_dsl::Result<String> {
    use std::fmt::Write as _;
    let mut o = String::new();
    let (x, u, p) = (ocp.x(), ocp.u(), ocp.p());
    let mut inputs: Vec<Expr<'_>> = x.to_vec();
    inputs.extend(u.iter().copied());
    inputs.extend(p.iter().copied());
    let f = ocp.dynamics_exprs();
    let prog = g.compile(f, &inputs)?;
    let _ = writeln!(
        o,
        "dynamics f(x,u,p): {} operations as trees, {} instructions after CSE",
        tree_ops(f),
        prog.instrs().len()
    );
    let mut wrt: Vec<Expr<'_>> = x.to_vec();
    wrt.extend(u.iter().copied());
    let jac = g.jacobian(f, &wrt)?;
    let names: Vec<String> = x.iter().map(ToString::to_string).collect();
    let cols: Vec<String> = wrt.iter().map(ToString::to_string).collect();
    let df_pattern = |o: &mut String| {
        let _ = writeln!(
            o,
            "jacobian df/d(x,u): {}x{}, {} structural nonzeros",
            jac.nrows(),
            jac.ncols(),
            jac.nnz()
        );
        let _ = writeln!(o, "    columns: {}", cols.join(" "));
        o.push_str(&pattern(jac.sparsity(), &names, wrt.len()));
    };
    let fd = match ocp.discrete_map() {
        Err(mpc_dsl::DslError::NoClosedForm { .. }) => {
            let _ = writeln!(
                o,
                "discrete map F(x,u,p) over dt: implicit (irk), solved by Newton iterations \
                 in the generated code; [A B] by the implicit function theorem"
            );
            df_pattern(&mut o);
            return Ok(o);
        }
        other => other?,
    };
    let prog_d = g.compile(&fd, &inputs)?;
    let _ = writeln!(
        o,
        "discrete map F(x,u,p) over dt: {:.3e} operations as trees, {} instructions after CSE",
        tree_ops(&fd),
        prog_d.instrs().len()
    );
    let jac_d = g.jacobian(&fd, &wrt)?;
    let prog_j = g.compile(jac_d.values(), &inputs)?;
    df_pattern(&mut o);
    let _ = writeln!(
        o,
        "jacobian [A B] = dF/d(x,u): {}x{}, {} structural nonzeros, {} instructions after CSE",
        jac_d.nrows(),
        jac_d.ncols(),
        jac_d.nnz(),
        prog_j.instrs().len()
    );
    o.push_str(&pattern(jac_d.sparsity(), &names, wrt.len()));
    Ok(o)
}
