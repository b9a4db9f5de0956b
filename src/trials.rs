//! What `mpcc sim` (the paper's missions and flip-and-throw) and `mpcc fly` share: flying
//! trials on all cores, writing a flight's log and plots.

use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use indicatif::ProgressBar;
use mpc_sim::mission::Phase;

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
