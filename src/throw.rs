//! `mpcc sim --mission flip-throw`: throw the tethered probe to a target and recover.

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use mpc_sim::estimator::EstimatorConfig;
use mpc_sim::throw::{
    self as th, LANDING_TOL_M, ThrowConfig, ThrowRunSummary, ThrowSimConfig, ThrowTrial,
};

use crate::SimArgs;

/// The ranges of `--range` (default 20 m).
fn ranges(args: &SimArgs) -> Result<Vec<f64>, String> {
    let Some(r) = &args.range else {
        return Ok(vec![20.0]);
    };
    let v: Vec<f64> = r
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("--range {r}: {e}; give metres, e.g. 20 or 5,10,15,20,25"))?;
    if v.is_empty() || v.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
        return Err(format!("--range {r}: give positive distances in m"));
    }
    Ok(v)
}

/// The trial settings of the arguments (other than the range).
fn base(args: &SimArgs) -> Result<ThrowSimConfig, String> {
    if let Some(c) = &args.controller {
        return Err(format!(
            "--controller {c}: flip-throw flies the swing-aware probe NMPC \
             (models/quadrotor_probe.mpc); leave --controller out"
        ));
    }
    for (set, flag) in [
        (args.shape.rally.is_some(), "--rally"),
        (args.shape.altitude.is_some(), "--altitude"),
        (args.shape.flip_rate.is_some(), "--flip-rate"),
        (args.pose_loss.is_some(), "--pose-loss"),
        (args.randomize, "--randomize"),
    ] {
        if set {
            return Err(format!("{flag} is not a flip-throw setting"));
        }
    }
    if args.trials == 0 {
        return Err("--trials 0: fly at least one trial".to_string());
    }
    let mut tc = ThrowConfig::default();
    if let Some(v) = args.v_max {
        if !(v.is_finite() && v > 0.0) {
            return Err(format!("--v-max {v}: give a speed in m/s (> 0)"));
        }
        tc.bounds.v_max = v;
    }
    if let Some(d) = args.probe_drag {
        if !(d.is_finite() && d >= 0.0) {
            return Err(format!("--probe-drag {d}: give a coefficient >= 0"));
        }
        tc.probe.drag = d;
    }
    let mut cfg = ThrowSimConfig::new(tc);
    if let Some(m) = args.mass {
        if !(m.is_finite() && m > 0.0) {
            return Err(format!("--mass {m}: give the vehicle's mass in kg (> 0)"));
        }
        cfg.plant.mass = m;
    }
    if args.perfect_sensing {
        cfg.estimator = EstimatorConfig::perfect();
        cfg.throw.angle_noise = 0.0;
        cfg.throw.rate_noise = 0.0;
    }
    cfg.seed = args.seed;
    cfg.throw.validate().map_err(|e| e.to_string())?;
    Ok(cfg)
}

pub(crate) fn run(args: &SimArgs) -> ExitCode {
    let (ranges, base) = match ranges(args).and_then(|r| Ok((r, base(args)?))) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let started = Instant::now();
    let mut rows: Vec<(f64, Result<ThrowRunSummary, String>)> = Vec::new();
    let mut firsts: Vec<(f64, ThrowTrial)> = Vec::new();
    for &range in &ranges {
        let mut cfg = base.clone();
        cfg.throw.range = range;
        // Plan once up front: an unreachable range is reported, not flown.
        if let Err(e) = th::plan_throw(&cfg.throw, cfg.nominal.mass) {
            rows.push((range, Err(e.to_string())));
            continue;
        }
        let configs: Vec<ThrowSimConfig> = (0..args.trials)
            .map(|i| ThrowSimConfig {
                seed: args.seed.wrapping_add(i as u64),
                ..cfg.clone()
            })
            .collect();
        let bar = if args.trials > 1 && !args.json {
            let b = ProgressBar::new(args.trials as u64);
            if let Ok(style) = ProgressStyle::with_template(&format!(
                "{{bar:40}} {{pos}}/{{len}} trials at {range} m, {{elapsed}} elapsed, eta {{eta}}"
            )) {
                b.set_style(style);
            }
            b
        } else {
            ProgressBar::hidden()
        };
        let (summaries, first) =
            crate::trials::fly_all(&configs, &bar, th::run_throw_trial, th::summarize_throw);
        bar.finish_and_clear();
        if summaries.len() != configs.len() {
            rows.push((
                range,
                Err(format!(
                    "only {} of {} trials could be flown",
                    summaries.len(),
                    configs.len()
                )),
            ));
            continue;
        }
        rows.push((range, Ok(th::aggregate_throw(range, &summaries))));
        if let Some(f) = first {
            firsts.push((range, f));
        }
    }
    let success = rows
        .iter()
        .all(|(_, r)| r.as_ref().is_ok_and(|r| r.success));
    if args.json {
        let value = if let [(range, row)] = rows.as_slice() {
            row_json(*range, row)
        } else {
            serde_json::json!({
                "mission": "flip-throw",
                "success": success,
                "ranges": rows.iter().map(|(r, row)| row_json(*r, row)).collect::<Vec<_>>(),
            })
        };
        println!("{value}");
    } else {
        print!("{}", th::throw_table(&rows));
        println!(
            "{} range(s) x {} trial(s) in {:.1} s wall-clock",
            ranges.len(),
            args.trials,
            started.elapsed().as_secs_f64()
        );
    }
    if !args.no_plots {
        for (range, first) in &firsts {
            if let Err(e) = write_outputs(&args.out, *range, first, args.json) {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    if success {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

fn row_json(range: f64, row: &Result<ThrowRunSummary, String>) -> serde_json::Value {
    match row {
        Ok(r) => serde_json::to_value(r).unwrap_or_else(
            |e| serde_json::json!({"range_m": range, "success": false, "error": e.to_string()}),
        ),
        Err(e) => serde_json::json!({
            "mission": "flip-throw",
            "range_m": range,
            "success": false,
            "error": e,
        }),
    }
}

fn write_outputs(dir: &Path, range: f64, res: &ThrowTrial, quiet: bool) -> Result<(), String> {
    let stem = format!("flip-throw_{range}m");
    let title = format!(
        "flip-throw {range} m · probe NMPC · seed {}",
        res.config.seed
    );
    crate::trials::write_log_and_plots(dir, &stem, &title, &res.samples, quiet)?;
    let side = dir.join(format!("{stem}_probe.png"));
    mpc_sim::plot::write_throw_plot(
        &side,
        &format!("{title}: side view (target ± {LANDING_TOL_M} m)"),
        &th::side_view(res),
    )
    .map_err(|e| e.to_string())?;
    if !quiet {
        println!("wrote {}", side.display());
    }
    Ok(())
}
