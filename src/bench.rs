//! `mpcc bench`: the QR-bench closed loop exactly as the peers were measured on it
//! (`docs/bench.md`): x0 = (0,0,2, 1,0,0,0, 0,0,0), reference (4,0,2) hover, first guess
//! x_k = x0 and u_k = 0 as acados' (`--sqp`: u_k = hover, CasADi's), u0 held for one period,
//! plant = the same ODE with RK4 in 10 substeps, 4 s. Times the preparation and feedback
//! phases of every step over several rounds.
//! `--model pointmass`: the paper's point-mass MPC from rest to a 1 m step in x, the exact
//! triple-integrator plant, 4 s (the generated solver feeds the applied jerk back as its
//! `u_prev` itself).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use mpc_runtime::RtiStatus;
use serde::Serialize;

use mpc_sim::qrbench::{X0, plant};

use crate::BenchArgs;

/// Seconds flown in every round.
const DURATION: f64 = 4.0;

/// The problems `--model` selects.
const MODELS: &str = "qrbench (QR-bench of docs/bench.md), pointmass (the paper's point-mass MPC)";

/// CSV header of the QR-bench closed loops (the reference data's columns, `tests/data/README.md`).
const QRBENCH_COLUMNS: &str = "t,px,py,pz,qw,qx,qy,qz,vx,vy,vz,c,wx,wy,wz";

/// CSV header of the point-mass closed loop.
const POINTMASS_COLUMNS: &str = "t,px,py,pz,vx,vy,vz,ax,ay,az,jx,jy,jz";

/// One closed loop: the states (row k at t = k dt) and controls, and per-step figures.
pub(crate) struct ClosedLoop {
    pub dt: f64,
    /// The CSV header: `t`, the states, the controls.
    pub columns: &'static str,
    pub states: Vec<Vec<f64>>,
    pub controls: Vec<Vec<f64>>,
    pub prepare_us: Vec<f64>,
    pub feedback_us: Vec<f64>,
    pub qp_iterations: Vec<u32>,
    /// Active-set solves of each step's (last) QP (`QpInfo::active_set_solves`).
    pub active_set_solves: Vec<u32>,
    pub sqp_iterations: Vec<u32>,
    /// Steps whose full SQP stopped at its iteration limit (SQP mode; the iterate is kept).
    pub sqp_limit_steps: usize,
    /// Every step solved (RTI: status Ok; SQP: no fallback to the previous plan).
    pub all_ok: bool,
}

/// What one step took and gave: its status, its QP's and SQP's iterations, and when it
/// started, finished preparing and finished.
struct Step {
    status: RtiStatus,
    qp_iterations: u32,
    active_set_solves: u32,
    sqp_iterations: u32,
    times: [Instant; 3],
}

impl ClosedLoop {
    /// A closed loop at its start `x0`, no step yet.
    fn new(dt: f64, columns: &'static str, x0: Vec<f64>) -> Self {
        ClosedLoop {
            dt,
            columns,
            states: vec![x0],
            controls: Vec::new(),
            prepare_us: Vec::new(),
            feedback_us: Vec::new(),
            qp_iterations: Vec::new(),
            active_set_solves: Vec::new(),
            sqp_iterations: Vec::new(),
            sqp_limit_steps: 0,
            all_ok: true,
        }
    }

    /// Records a step (`sqp`: in SQP mode, where the iteration limit keeps the iterate), the
    /// control it applied and the state it led to.
    fn record(&mut self, sqp: bool, step: &Step, u: Vec<f64>, x: Vec<f64>) {
        match step.status {
            RtiStatus::Ok => {}
            RtiStatus::MaxIterations if sqp => self.sqp_limit_steps += 1,
            _ => self.all_ok = false,
        }
        let [t0, t1, t2] = step.times;
        self.sqp_iterations.push(step.sqp_iterations);
        self.prepare_us.push((t1 - t0).as_secs_f64() * 1e6);
        self.feedback_us.push((t2 - t1).as_secs_f64() * 1e6);
        self.qp_iterations.push(step.qp_iterations);
        self.active_set_solves.push(step.active_set_solves);
        self.controls.push(u);
        self.states.push(x);
    }
}

/// Settings the command line overrides (else the solver's defaults).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Overrides {
    /// `RtiSettings::sqp_loose_qps` (`--sqp-qps`).
    pub loose: Option<bool>,
    /// `QpSettings::warm_active_set` (`--warm-active-set`).
    pub warm_active_set: Option<bool>,
    /// `RtiSettings::sqp_watchdog` (`--sqp-watchdog`).
    pub watchdog: Option<u32>,
}

/// CasADi's first guess of the controls in QR-bench: the reference, hover.
const U_HOVER: [f64; 4] = [9.81, 0.0, 0.0, 0.0];

/// Flies QR-bench once with solver crate `$m` (its `Real` may be f32 or f64).
macro_rules! fly {
    ($m:ident, $sqp:expr, $over:expr) => {{
        use mpc_models::$m as m;
        let mut s = Box::new(m::Solver::new());
        let over: Overrides = $over;
        if let Some(loose) = over.loose {
            s.settings_mut().sqp_loose_qps = loose;
        }
        if let Some(warm) = over.warm_active_set {
            s.settings_mut().qp.warm_active_set = warm;
        }
        if let Some(steps) = over.watchdog {
            s.settings_mut().sqp_watchdog = steps;
        }
        // acados' QR-bench runs keep the last solution in place (no shift): so does this
        // one, to be compared with them.
        s.settings_mut().shift = false;
        let cast = |v: f64| v as m::Real;
        let x0: [m::Real; 10] = X0.map(cast);
        // Each mode starts where the peer it is compared with did: the real-time iteration
        // from acados' u = 0, the full SQP from CasADi's u = hover.
        let u_guess = if $sqp { U_HOVER } else { [0.0; 4] };
        let _ = s.set_guess(&x0, &u_guess.map(cast));
        let steps = (DURATION / f64::from(m::DT)).round() as usize;
        let dt = f64::from(m::DT);
        let mut out = ClosedLoop::new(dt, QRBENCH_COLUMNS, X0.to_vec());
        let mut x = X0;
        for _ in 0..steps {
            let t0 = Instant::now();
            // The full SQP linearizes for itself, and QR-bench's solvers do not shift: the
            // preparation phase would be work thrown away.
            if !$sqp {
                s.prepare();
            }
            let t1 = Instant::now();
            let _ = s.set_x0(&x.map(cast));
            let info = if $sqp { s.solve_sqp() } else { s.feedback() };
            let step = Step {
                status: info.status,
                qp_iterations: info.qp.iterations,
                active_set_solves: info.qp.active_set_solves,
                sqp_iterations: info.sqp_iterations,
                times: [t0, t1, Instant::now()],
            };
            let u = s.u0().map(f64::from);
            x = plant(&x, &u, dt, 10);
            out.record($sqp, &step, u.to_vec(), x.to_vec());
        }
        out
    }};
}

/// The point-mass solver compiled in.
const POINTMASS: &str = "paper_pointmass (the paper's point-mass MPC: N = 10, dt = 0.04, f64)";

/// Flies the point mass once: from rest at the origin to the reference 1 m along x (the
/// closed loop of `cargo bench --bench generated -- pointmass`).
fn fly_pointmass(sqp: bool, over: Overrides) -> ClosedLoop {
    use mpc_models::paper_pointmass as m;
    let mut s = Box::new(m::Solver::new());
    if let Some(loose) = over.loose {
        s.settings_mut().sqp_loose_qps = loose;
    }
    if let Some(warm) = over.warm_active_set {
        s.settings_mut().qp.warm_active_set = warm;
    }
    let mut xref = [0.0; 9];
    xref[0] = 1.0;
    let mut out = ClosedLoop::new(m::DT, POINTMASS_COLUMNS, vec![0.0; 9]);
    out.all_ok = s.set_xref_all(&xref).is_ok();
    let mut x = [0.0; 9];
    for _ in 0..(DURATION / m::DT).round() as usize {
        let t0 = Instant::now();
        s.prepare();
        let t1 = Instant::now();
        let _ = s.set_x0(&x);
        let info = if sqp { s.solve_sqp() } else { s.feedback() };
        let step = Step {
            status: info.status,
            qp_iterations: info.qp.iterations,
            active_set_solves: info.qp.active_set_solves,
            sqp_iterations: info.sqp_iterations,
            times: [t0, t1, Instant::now()],
        };
        let j = s.u0();
        x = mpc_sim::pointmass::plant(&x, &j, m::DT);
        out.record(sqp, &step, j.to_vec(), x.to_vec());
    }
    out
}

/// The cases compiled in: (horizon, f32).
pub(crate) const CASES: [(usize, bool, &str); 6] = [
    (
        10,
        false,
        "quadrotor_rates_a (QR-bench A: N = 10, dt = 0.04, f64)",
    ),
    (
        20,
        false,
        "quadrotor_rates (QR-bench B: N = 20, dt = 0.05, f64)",
    ),
    (40, false, "quadrotor_rates_n40 (N = 40, dt = 0.025, f64)"),
    (
        10,
        true,
        "quadrotor_rates_f32 (QR-bench A: N = 10, dt = 0.04, f32)",
    ),
    (
        20,
        true,
        "quadrotor_rates_b_f32 (QR-bench B: N = 20, dt = 0.05, f32)",
    ),
    (
        40,
        true,
        "quadrotor_rates_n40_f32 (N = 40, dt = 0.025, f32)",
    ),
];

/// The cases with a solver generated with the exact Hessian (`--exact-hessian`), for the
/// full SQP: (horizon, solver).
pub(crate) const EXACT_CASES: [(usize, &str); 2] = [
    (
        10,
        "quadrotor_rates_a_exact (QR-bench A: N = 10, dt = 0.04, f64, exact Hessian)",
    ),
    (
        20,
        "quadrotor_rates_b_exact (QR-bench B: N = 20, dt = 0.05, f64, exact Hessian)",
    ),
];

/// Flies the closed loop of the given case (`exact`: the solver generated with the exact
/// Hessian, where there is one).
/// `over`: settings to override (else the solver's defaults).
pub(crate) fn fly_case(
    horizon: usize,
    f32: bool,
    sqp: bool,
    exact: bool,
    over: Overrides,
) -> Option<ClosedLoop> {
    if exact {
        return match (horizon, f32) {
            (10, false) => Some(fly!(quadrotor_rates_a_exact, sqp, over)),
            (20, false) => Some(fly!(quadrotor_rates_b_exact, sqp, over)),
            _ => None,
        };
    }
    match (horizon, f32) {
        (10, false) => Some(fly!(quadrotor_rates_a, sqp, over)),
        (20, false) => Some(fly!(quadrotor_rates, sqp, over)),
        (40, false) => Some(fly!(quadrotor_rates_n40, sqp, over)),
        (10, true) => Some(fly!(quadrotor_rates_f32, sqp, over)),
        (20, true) => Some(fly!(quadrotor_rates_b_f32, sqp, over)),
        (40, true) => Some(fly!(quadrotor_rates_n40_f32, sqp, over)),
        _ => None,
    }
}

/// Mean, median, 99th percentile, maximum.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub(crate) struct Stats {
    pub mean: f64,
    pub median: f64,
    pub p99: f64,
    pub max: f64,
}

impl Stats {
    fn of(values: &[f64]) -> Self {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let at = |q: f64| v[((q * n as f64).ceil() as usize).clamp(1, n) - 1];
        Self {
            mean: v.iter().sum::<f64>() / n as f64,
            median: at(0.5),
            p99: at(0.99),
            max: v[n - 1],
        }
    }
}

/// The JSON of `mpcc bench --json`.
#[derive(Clone, Debug, Serialize)]
struct Report {
    model: String,
    solver: String,
    horizon: usize,
    scalar: &'static str,
    mode: &'static str,
    /// The full SQP's Hessian: `exact` or `gauss-newton` (the real-time iteration's).
    hessian: &'static str,
    rounds: usize,
    steps: usize,
    prepare_us: Stats,
    feedback_us: Stats,
    total_us: Stats,
    qp_iterations_mean: f64,
    qp_iterations_max: u32,
    /// Steps whose (last) QP needed the interior point.
    qp_interior_point_steps: usize,
    /// Active-set solves per step (`QpInfo::active_set_solves`): the warm active set and
    /// the active-set iterations after it.
    qp_active_set_solves_mean: f64,
    sqp_iterations_mean: f64,
    sqp_iterations_max: u32,
    sqp_limit_steps: usize,
    final_position_error_m: f64,
    all_ok: bool,
    csv: Option<PathBuf>,
}

/// Writes the closed loop in the reference data's columns: row k is the state at t = k dt and the
/// control applied then; the last row holds the state only.
pub(crate) fn write_csv(path: &Path, run: &ClosedLoop) -> std::io::Result<()> {
    use std::fmt::Write as _;
    let mut s = format!("{}\n", run.columns);
    for (k, x) in run.states.iter().enumerate() {
        let _ = write!(s, "{}", k as f64 * run.dt);
        for v in x {
            let _ = write!(s, ",{v:e}");
        }
        match run.controls.get(k) {
            Some(u) => {
                for v in u {
                    let _ = write!(s, ",{v:e}");
                }
            }
            None => {
                for _ in 0..run.controls.first().map_or(0, Vec::len) {
                    s.push(',');
                }
            }
        }
        s.push('\n');
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, s)
}

pub(crate) fn run(args: &BenchArgs) -> ExitCode {
    let case = match case_of(args) {
        Ok(case) => case,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let Some(rounds) = fly_rounds(args, &case) else {
        return ExitCode::FAILURE;
    };
    let csv = if args.no_csv {
        None
    } else {
        let path = args
            .csv
            .clone()
            .unwrap_or_else(|| default_csv(args, case.pointmass));
        if let Err(e) = write_csv(&path, &rounds.last) {
            eprintln!("error: {}: {e}", path.display());
            return ExitCode::FAILURE;
        }
        Some(path)
    };
    let report = report(args, &case, &rounds, csv);
    if args.json {
        match serde_json::to_string(&report) {
            Ok(s) => println!("{s}"),
            Err(e) => {
                eprintln!("error: JSON: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        print_summary(args, &case, &report);
    }
    if report.all_ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

/// What `mpcc bench` flies, from its command line.
struct Case {
    /// The point mass (`--model pointmass`), else QR-bench.
    pointmass: bool,
    /// The solver, described.
    solver: &'static str,
    /// The full SQP's Hessian is the exact one (the solver generated with it).
    exact: bool,
    /// The settings the command line overrides.
    over: Overrides,
}

/// The case the command line asks for, or the message saying why there is none (checked
/// in this order: the model, the horizon and scalar, the rounds, the QP settings, the
/// Hessian, the watchdog).
fn case_of(args: &BenchArgs) -> Result<Case, String> {
    let (pointmass, solver) = problem(args)?;
    if args.rounds == 0 {
        return Err("--rounds 0: run at least one round".into());
    }
    let loose = match args.sqp_qps.as_deref() {
        None => None,
        Some(_) if !args.sqp => return Err("--sqp-qps applies to the full SQP: add --sqp".into()),
        Some("loose") => Some(true),
        Some("tight") => Some(false),
        Some(other) => return Err(format!("--sqp-qps {other}: use loose or tight")),
    };
    let warm_active_set = match args.warm_active_set.as_deref() {
        None => None,
        Some("on") => Some(true),
        Some("off") => Some(false),
        Some(other) => return Err(format!("--warm-active-set {other}: use on or off")),
    };
    let (exact, solver) = hessian(args, pointmass, solver)?;
    if args.sqp_watchdog.is_some() && !(args.sqp && exact) {
        return Err(
            "--sqp-watchdog applies to the full SQP with the exact Hessian: add --sqp \
                    (and leave out --hessian gauss-newton)"
                .into(),
        );
    }
    Ok(Case {
        pointmass,
        solver,
        exact,
        over: Overrides {
            loose,
            warm_active_set,
            watchdog: args.sqp_watchdog,
        },
    })
}

/// The problem (`true`: the point mass) and the real-time iteration's solver compiled in
/// for it, its horizon and scalar.
fn problem(args: &BenchArgs) -> Result<(bool, &'static str), String> {
    let f32_flag = if args.f32 { " --f32" } else { "" };
    match args.model.as_str() {
        "qrbench" => {}
        "pointmass" if args.horizon != 10 || args.f32 => {
            return Err(format!(
                "--model pointmass --horizon {}{f32_flag}: no solver generated for this case; \
                 compiled in: --horizon 10 (f64)",
                args.horizon,
            ));
        }
        "pointmass" => return Ok((true, POINTMASS)),
        other => {
            return Err(format!(
                "--model {other}: unknown; the benchmark problems are {MODELS}"
            ));
        }
    }
    let Some(&(_, _, solver)) = CASES
        .iter()
        .find(|c| c.0 == args.horizon && c.1 == args.f32)
    else {
        let have: Vec<String> = CASES
            .iter()
            .map(|c| format!("--horizon {}{}", c.0, if c.1 { " --f32" } else { "" }))
            .collect();
        return Err(format!(
            "--horizon {}{f32_flag}: no solver generated for this case; compiled in: {}",
            args.horizon,
            have.join(", ")
        ));
    };
    Ok((false, solver))
}

/// Whether the full SQP's Hessian is the exact one, and the solver then: exact where a
/// solver generated with it is compiled in (unless `--hessian gauss-newton`), else
/// `solver`, the real-time iteration's.
fn hessian(
    args: &BenchArgs,
    pointmass: bool,
    solver: &'static str,
) -> Result<(bool, &'static str), String> {
    let exact_solver = EXACT_CASES
        .iter()
        .find(|c| !pointmass && !args.f32 && c.0 == args.horizon)
        .map(|c| c.1);
    match (args.hessian.as_deref(), exact_solver) {
        (Some(_), _) if !args.sqp => Err("--hessian applies to the full SQP (the real-time \
                                          iteration is Gauss-Newton): add --sqp"
            .into()),
        (None | Some("exact"), Some(s)) if args.sqp => Ok((true, s)),
        (None | Some("gauss-newton"), _) => Ok((false, solver)),
        (Some("exact"), _) => Err("--hessian exact: no solver generated with the exact \
                                   Hessian for this case; compiled in: --model qrbench \
                                   --horizon 10 and --horizon 20 (f64)"
            .into()),
        (Some(other), _) => Err(format!("--hessian {other}: use exact or gauss-newton")),
    }
}

/// Every round's step times, pooled, and the last round's closed loop.
struct Rounds {
    prepare_us: Vec<f64>,
    feedback_us: Vec<f64>,
    total_us: Vec<f64>,
    last: ClosedLoop,
}

/// Flies `args.rounds` closed loops of `case`; `None` where its solver is not compiled in
/// (or no round was flown).
fn fly_rounds(args: &BenchArgs, case: &Case) -> Option<Rounds> {
    let mut prepare_us = Vec::new();
    let mut feedback_us = Vec::new();
    let mut total_us = Vec::new();
    let mut last = None;
    for _ in 0..args.rounds {
        let run = if case.pointmass {
            fly_pointmass(args.sqp, case.over)
        } else {
            fly_case(args.horizon, args.f32, args.sqp, case.exact, case.over)?
        };
        prepare_us.extend(&run.prepare_us);
        feedback_us.extend(&run.feedback_us);
        total_us.extend(
            run.prepare_us
                .iter()
                .zip(&run.feedback_us)
                .map(|(a, b)| a + b),
        );
        last = Some(run);
    }
    Some(Rounds {
        prepare_us,
        feedback_us,
        total_us,
        last: last?,
    })
}

/// The CSV's path without `--csv`: `bench-out/`, the problem, `_sqp` in SQP mode.
fn default_csv(args: &BenchArgs, pointmass: bool) -> PathBuf {
    let sqp = if args.sqp { "_sqp" } else { "" };
    PathBuf::from(if pointmass {
        format!("bench-out/pointmass_f64{sqp}.csv")
    } else {
        format!(
            "bench-out/qrbench_n{}_{}{sqp}.csv",
            args.horizon,
            if args.f32 { "f32" } else { "f64" },
        )
    })
}

/// The figures of the rounds flown.
fn report(args: &BenchArgs, case: &Case, rounds: &Rounds, csv: Option<PathBuf>) -> Report {
    let run = &rounds.last;
    // The distance of the final position from the target: (4, 0, 2) or (1, 0, 0).
    let target = if case.pointmass {
        [1.0, 0.0, 0.0]
    } else {
        [4.0, 0.0, 2.0]
    };
    let err = run.states.last().map_or(f64::INFINITY, |x| {
        x.iter()
            .zip(target)
            .map(|(p, t)| (p - t).powi(2))
            .sum::<f64>()
            .sqrt()
    });
    let mean = |v: &[u32]| v.iter().map(|&i| f64::from(i)).sum::<f64>() / v.len().max(1) as f64;
    Report {
        model: args.model.clone(),
        solver: case.solver.to_string(),
        horizon: args.horizon,
        scalar: if args.f32 { "f32" } else { "f64" },
        mode: if args.sqp { "sqp" } else { "rti" },
        hessian: if case.exact { "exact" } else { "gauss-newton" },
        rounds: args.rounds,
        steps: run.controls.len(),
        prepare_us: Stats::of(&rounds.prepare_us),
        feedback_us: Stats::of(&rounds.feedback_us),
        total_us: Stats::of(&rounds.total_us),
        qp_iterations_mean: mean(&run.qp_iterations),
        qp_iterations_max: run.qp_iterations.iter().copied().max().unwrap_or(0),
        qp_interior_point_steps: run.qp_iterations.iter().filter(|&&i| i > 0).count(),
        qp_active_set_solves_mean: mean(&run.active_set_solves),
        sqp_iterations_mean: mean(&run.sqp_iterations),
        sqp_iterations_max: run.sqp_iterations.iter().copied().max().unwrap_or(0),
        sqp_limit_steps: run.sqp_limit_steps,
        final_position_error_m: err,
        all_ok: run.all_ok,
        csv,
    }
}

/// The figures as text: the times, the iterations, the final error, the CSV written.
fn print_summary(args: &BenchArgs, case: &Case, report: &Report) {
    println!(
        "{}, {}, {} mode: {} rounds x {} steps",
        if case.pointmass {
            "Point mass"
        } else {
            "QR-bench"
        },
        case.solver,
        report.mode,
        report.rounds,
        report.steps
    );
    println!(
        "{:<10} {:>10} {:>10} {:>10} {:>10}",
        "phase [us]", "mean", "median", "p99", "max"
    );
    for (name, s) in [
        ("prepare", report.prepare_us),
        ("feedback", report.feedback_us),
        ("total", report.total_us),
    ] {
        println!(
            "{name:<10} {:>10.1} {:>10.1} {:>10.1} {:>10.1}",
            s.mean, s.median, s.p99, s.max
        );
    }
    if args.sqp {
        println!(
            "SQP iterations per step ({} Hessian): mean {:.2}, max {}; {} steps stopped at \
             the iteration limit (their iterate is kept)",
            report.hessian,
            report.sqp_iterations_mean,
            report.sqp_iterations_max,
            report.sqp_limit_steps
        );
    }
    println!(
        "QP per step{}: interior-point iterations mean {:.2}, max {} (in {} of {} steps); \
         active-set solves mean {:.2}",
        if args.sqp {
            " (last QP of each step)"
        } else {
            ""
        },
        report.qp_iterations_mean,
        report.qp_iterations_max,
        report.qp_interior_point_steps,
        report.steps,
        report.qp_active_set_solves_mean,
    );
    println!(
        "final position error {:.3e} m{}",
        report.final_position_error_m,
        if report.all_ok {
            String::new()
        } else {
            "; SOME STEPS DID NOT SOLVE".to_string()
        }
    );
    if let Some(p) = &report.csv {
        println!("wrote {}", p.display());
    }
}
