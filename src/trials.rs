//! What `mpcc sim` (the paper's missions and flip-and-throw) and `mpcc fly` share: the check
//! of the generated solver against its model, flying trials on all cores, writing a flight's
//! log and plots.

use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use indicatif::ProgressBar;
use mpc_dsl::Graph;
use mpc_dsl::lang::{ParseOptions, parse};
use mpc_sim::mission::Phase;

/// A generated solver the simulator links: its controller name, the model file it comes
/// from, the model's text and the module `mpc-models`' build script generated from it (both
/// embedded at build time: nothing is read from the checkout at run time, so an installed
/// `mpcc` runs from any directory).
struct Linked {
    controller: &'static str,
    model: &'static str,
    source: &'static str,
    module: &'static str,
}

/// The generated solvers the simulator links.
const SOLVERS: [Linked; 3] = [
    Linked {
        controller: "paper",
        model: "models/paper_pointmass.mpc",
        source: mpc_models::source::PAPER_POINTMASS,
        module: mpc_models::generated::PAPER_POINTMASS,
    },
    Linked {
        controller: "nmpc",
        model: "models/quadrotor_rates.mpc",
        source: mpc_models::source::QUADROTOR_RATES,
        module: mpc_models::generated::QUADROTOR_RATES,
    },
    Linked {
        controller: "probe",
        model: "models/quadrotor_probe.mpc",
        source: mpc_models::source::QUADROTOR_PROBE,
        module: mpc_models::generated::QUADROTOR_PROBE,
    },
];

/// Generates the controller's solver from its model with this binary's generator and
/// compares it with the module the simulator is built with (which `mpc-models`' build script
/// generated): a difference means the binary flies another controller than its model says.
pub(crate) fn check_solver(controller: &str, quiet: bool) -> Result<(), String> {
    let Some(s) = SOLVERS.iter().find(|s| s.controller == controller) else {
        return Ok(());
    };
    let t = Instant::now();
    let g = Graph::new();
    let parsed =
        parse(&g, s.source, &ParseOptions::default()).map_err(|d| d.render(s.model, s.source))?;
    let (name, generated) = mpc_codegen::Builder::from_ocp()
        .module_source(&parsed.ocp)
        .map_err(|e| format!("{}: {e}", s.model))?;
    if generated != s.module {
        return Err(format!(
            "the solver `{name}` linked is not what {} generates: rebuild mpcc (`cargo build`)",
            s.model
        ));
    }
    if !quiet {
        eprintln!(
            "solver: generated `{name}` from {} in {:.0} ms (identical to the solver linked)",
            s.model,
            t.elapsed().as_secs_f64() * 1e3
        );
    }
    Ok(())
}

/// Flies every configuration on all cores with `fly`; returns `summarize` of each trial in
/// order (trials that could not be flown are reported on stderr and left out) and the first
/// trial's full result (for the log and plots).
pub(crate) fn fly_all<C, R, S, E>(
    configs: &[C],
    bar: &ProgressBar,
    fly: impl Fn(&C) -> Result<R, E> + Sync,
    summarize: impl Fn(&R) -> S + Sync,
) -> (Vec<S>, Option<R>)
where
    C: Sync,
    R: Send,
    S: Send + Clone,
    E: std::fmt::Display,
{
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<S>>> = Mutex::new(vec![None; configs.len()]);
    let first: Mutex<Option<R>> = Mutex::new(None);
    let workers = std::thread::available_parallelism()
        .map_or(1, usize::from)
        .min(configs.len())
        .max(1);
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(cfg) = configs.get(i) else { break };
                    match fly(cfg) {
                        Ok(res) => {
                            let summary = summarize(&res);
                            if let Ok(mut o) = out.lock()
                                && let Some(slot) = o.get_mut(i)
                            {
                                *slot = Some(summary);
                            }
                            if i == 0
                                && let Ok(mut f) = first.lock()
                            {
                                *f = Some(res);
                            }
                        }
                        // Validated before flying: a trial cannot fail to start.
                        Err(e) => eprintln!("error: trial {i}: {e}"),
                    }
                    bar.inc(1);
                }
            });
        }
    });
    let summaries = out
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .flatten()
        .collect();
    (summaries, first.into_inner().unwrap_or_default())
}

/// Writes `DIR/STEM.csv` and the four plots `DIR/STEM_*.png` of a flight log; says so unless
/// `quiet`.
pub(crate) fn write_log_and_plots(
    dir: &Path,
    stem: &str,
    title: &str,
    samples: &[mpc_sim::log::Sample],
    quiet: bool,
) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let csv = dir.join(format!("{stem}.csv"));
    mpc_sim::plot::write_csv(&csv, samples).map_err(|e| e.to_string())?;
    let names = Phase::names();
    let plots = mpc_sim::plot::write_plots(dir, &format!("{stem}_"), title, samples, &names)
        .map_err(|e| e.to_string())?;
    if !quiet {
        println!(
            "wrote {}, {}, {}, {}, {}",
            csv.display(),
            plots.position.display(),
            plots.rates.display(),
            plots.thrust.display(),
            plots.solver_time.display()
        );
    }
    Ok(())
}
