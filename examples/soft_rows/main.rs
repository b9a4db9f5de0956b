//! The cost of the bicycle's soft obstacle row on the warm active set: the closed loop of
//! `tests/examples.rs` with the row soft (as built), hard, and off, each with the warm active
//! set on and off; a table per step of wall time, interior-point iterations and active-set
//! solves (`docs/benchmarks.md`).
//!
//! ```sh
//! cargo run --release --example soft_rows            # the table
//! cargo build --release --example soft_rows
//! valgrind --tool=callgrind target/release/examples/soft_rows soft-warm   # one case
//! ```
//!
//! With a case (`soft-warm`, `soft-ip`, `hard-warm`, `hard-ip`, `off-warm`, `off-ip`) it
//! runs that closed loop alone, for callgrind (inclusive `Solver::prepare` +
//! `Solver::feedback` over the 300 steps).

mod bicycle_loop;

use bicycle_loop::{Row, Run, STEPS, run};

/// The cases: name, row, warm active set.
const CASES: [(&str, Row, bool); 6] = [
    ("soft-warm", Row::Soft, true),
    ("soft-ip", Row::Soft, false),
    ("hard-warm", Row::Hard, true),
    ("hard-ip", Row::Hard, false),
    ("off-warm", Row::Off, true),
    ("off-ip", Row::Off, false),
];

fn settings(warm: bool) -> mpc_runtime::RtiSettings<f64> {
    let mut st = bicycle::default_settings();
    st.qp.warm_active_set = warm;
    st
}

fn main() {
    let only = std::env::args().nth(1);
    if let Some(name) = only {
        let Some(&(_, row, warm)) = CASES.iter().find(|c| c.0 == name) else {
            eprintln!(
                "unknown case {name}: one of soft-warm, soft-ip, hard-warm, hard-ip, off-warm, off-ip"
            );
            std::process::exit(2);
        };
        let r = run(settings(warm), row);
        println!("{name}: {} steps, {} not Ok", STEPS, r.not_ok);
        return;
    }
    println!(
        "| bicycle, {STEPS} steps | us/step mean | us/step max | IP iterations mean | max | steps with IP | active-set solves mean |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for (name, row, warm) in CASES {
        // Best of three runs per step (the machine is shared).
        let runs: Vec<Run> = (0..3).map(|_| run(settings(warm), row)).collect();
        let best: Vec<f64> = (0..STEPS)
            .map(|k| {
                runs.iter()
                    .map(|r| r.seconds[k])
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        let r = &runs[0];
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let its: Vec<f64> = r.iterations.iter().map(|&i| f64::from(i)).collect();
        let solves: Vec<f64> = r.active_set_solves.iter().map(|&i| f64::from(i)).collect();
        println!(
            "| {name} | {:.1} | {:.1} | {:.2} | {} | {} | {:.2} |",
            1e6 * mean(&best),
            1e6 * best.iter().cloned().fold(0.0, f64::max),
            mean(&its),
            r.iterations.iter().max().unwrap_or(&0),
            r.iterations.iter().filter(|&&i| i > 0).count(),
            mean(&solves),
        );
    }
}
