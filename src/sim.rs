//! `mpcc sim`: fly a mission in the closed-loop simulator.

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use mpc_sim::controller::ControllerKind;
use mpc_sim::estimator::EstimatorConfig;
use mpc_sim::mission::{MissionConfig, MissionKind, Phase};
use mpc_sim::report;
use mpc_sim::run::{SimConfig, TrialResult, run_trial};

use crate::SimArgs;
use crate::trials::{fly_all, write_log_and_plots};

/// The mission configuration of `kind` with the command line's `--rally`, `--altitude` and
/// `--flip-rate` (shared by `mpcc sim` and `mpcc fly`).
pub(crate) fn mission_config(
    kind: MissionKind,
    shape: &crate::MissionShape,
) -> Result<MissionConfig, String> {
    let (rally, altitude, flip_rate) = (shape.rally.as_deref(), shape.altitude, shape.flip_rate);
    let mut m = MissionConfig::for_kind(kind);
    if let Some(r) = rally {
        let v: Vec<f64> = r
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("--rally {r}: {e}; give X,Y,Z in m, e.g. 4,0,2"))?;
        match v.as_slice() {
            [x, y, z] if v.iter().all(|e| e.is_finite()) && *z >= 1.5 => {
                m.rally_point = mpc_sim::nalgebra::Vector3::new(*x, *y, *z);
            }
            [_, _, z] if *z < 1.5 => {
                return Err(format!(
                    "--rally {r}: the flip needs room: a height of at least 1.5 m"
                ));
            }
            _ => return Err(format!("--rally {r}: give three finite numbers X,Y,Z")),
        }
    }
    if let Some(a) = altitude {
        if !(a.is_finite() && a >= 0.5) {
            return Err(format!("--altitude {a}: give a height of at least 0.5 m"));
        }
        m.takeoff_point.z = m.home.z + a;
        if rally.is_none() {
            m.rally_point.z = m.home.z + a;
        }
    }
    if let Some(w) = flip_rate {
        if !(w.is_finite() && w > 1.0 && w <= 20.0) {
            return Err(format!(
                "--flip-rate {w}: give a pitch rate in (1, 20] rad/s (the NMPC's rate bound is 20)"
            ));
        }
        m.flip_rate = w;
    }
    Ok(m)
}

fn parse(args: &SimArgs) -> Result<(MissionKind, ControllerKind), String> {
    let mission = match args.mission.as_str() {
        "flip" => MissionKind::Flip,
        "hover" => MissionKind::Hover,
        "step" => MissionKind::Step,
        m => {
            return Err(format!(
                "--mission {m}: unknown; use flip, hover, step or flip-throw"
            ));
        }
    };
    let controller = match args.controller.as_deref().unwrap_or("paper") {
        "paper" => ControllerKind::Paper,
        "nmpc" => ControllerKind::Nmpc,
        c => return Err(format!("--controller {c}: unknown; use paper or nmpc")),
    };
    if args.trials == 0 {
        return Err("--trials 0: fly at least one trial".to_string());
    }
    for (set, flag) in [
        (args.range.is_some(), "--range"),
        (args.v_max.is_some(), "--v-max"),
        (args.probe_drag.is_some(), "--probe-drag"),
    ] {
        if set {
            return Err(format!(
                "{flag} is a flip-throw setting (--mission flip-throw)"
            ));
        }
    }
    if let Some(m) = args.mass
        && !(m.is_finite() && m > 0.0)
    {
        return Err(format!("--mass {m}: give the vehicle's mass in kg (> 0)"));
    }
    if let Some(s) = args.pose_loss {
        if !(s.is_finite() && s >= 0.0) {
            return Err(format!(
                "--pose-loss {s}: give the seconds after the flip's start (>= 0)"
            ));
        }
        if mission != MissionKind::Flip {
            return Err("--pose-loss is a flip-mission scenario".to_string());
        }
    }
    Ok((mission, controller))
}

/// The time of the flip's start in a nominal run, for `--pose-loss`: found by flying the
/// mission once without the loss (deterministic).
fn flip_start(cfg: &SimConfig) -> Option<f64> {
    let res = run_trial(cfg).ok()?;
    res.transitions
        .iter()
        .find(|t| t.phase == Phase::Flip)
        .map(|t| t.t)
}

pub(crate) fn run(args: &SimArgs) -> ExitCode {
    let (_, controller, mission_cfg) = match parse(args).and_then(|(m, c)| {
        let cfg = mission_config(m, &args.shape)?;
        Ok((m, c, cfg))
    }) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let mut base = SimConfig::new(mission_cfg, controller);
    base.seed = args.seed;
    if let Some(m) = args.mass {
        base.plant.mass = m;
    }
    if args.perfect_sensing {
        base.estimator = EstimatorConfig::perfect();
    }
    if let Err(e) = base.validate() {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    if let Some(after) = args.pose_loss {
        match flip_start(&base) {
            Some(t) => base = base.with_pose_loss_in_flip(t + after),
            None => {
                eprintln!("error: --pose-loss: the nominal run never reached the flip");
                return ExitCode::FAILURE;
            }
        }
    }
    let configs: Vec<SimConfig> = (0..args.trials)
        .map(|i| {
            let seed = args.seed.wrapping_add(i as u64);
            if args.randomize {
                base.randomized(seed)
            } else {
                SimConfig {
                    seed,
                    ..base.clone()
                }
            }
        })
        .collect();
    let started = Instant::now();
    let bar = if args.trials > 1 && !args.json {
        let b = ProgressBar::new(args.trials as u64);
        if let Ok(style) = ProgressStyle::with_template(
            "{bar:40} {pos}/{len} trials, {elapsed} elapsed, eta {eta}",
        ) {
            b.set_style(style);
        }
        b
    } else {
        ProgressBar::hidden()
    };
    let (summaries, first) = fly_all(&configs, &bar, run_trial, report::summarize);
    bar.finish_and_clear();
    if summaries.len() != configs.len() {
        eprintln!(
            "error: only {} of {} trials could be flown",
            summaries.len(),
            configs.len()
        );
        return ExitCode::FAILURE;
    }
    let run = report::aggregate(&args.mission, controller.name(), &summaries);
    if args.json {
        match serde_json::to_string(&run) {
            Ok(s) => println!("{s}"),
            Err(e) => {
                eprintln!("error: JSON: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        print!("{}", report::table(&run));
        println!(
            "{} trial(s) in {:.1} s wall-clock",
            args.trials,
            started.elapsed().as_secs_f64()
        );
    }
    if !args.no_plots
        && let Some(first) = &first
        && let Err(e) = write_outputs(&args.out, first, &run.mission, args.json)
    {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    if run.success {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

fn write_outputs(dir: &Path, res: &TrialResult, mission: &str, quiet: bool) -> Result<(), String> {
    let title = format!(
        "{mission} · {} controller · seed {}",
        res.config.controller.name(),
        res.config.seed
    );
    write_log_and_plots(dir, mission, &title, &res.samples, quiet)
}
