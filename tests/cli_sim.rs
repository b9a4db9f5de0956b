//! `mpcc sim`: the README's main command, its JSON summary, its files and its errors.

mod common;

use std::path::Path;

use common::{mpcc, num};

#[test]
fn default_run_flies_the_flip_and_writes_log_and_plots() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_sim_default");
    let _ = std::fs::remove_dir_all(&dir);
    let (code, out, err) = mpcc(&["sim", "--out", dir.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{out}\n{err}");
    assert!(out.contains("mission flip"), "{out}");
    assert!(out.contains("1 of 1 trials succeeded"), "{out}");
    for phase in [
        "takeoff", "rally", "ascend", "flip", "recover", "hold", "return", "land",
    ] {
        assert!(
            out.lines().any(|l| l.starts_with(phase)),
            "no {phase} row in\n{out}"
        );
    }
    let csv = std::fs::read_to_string(dir.join("flip.csv")).unwrap();
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert!(
        header.starts_with("t,phase,failsafe,pose_valid,x,y,z,"),
        "{header}"
    );
    assert!(lines.count() > 10_000, "a 1 kHz log of a ~20 s mission");
    for f in ["position", "rates", "thrust", "solver_time"] {
        let png = std::fs::read(dir.join(format!("flip_{f}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{f}");
        assert!(png.len() > 20_000, "{f}.png is nearly empty");
    }
}

#[test]
fn json_summary_has_the_documented_fields() {
    let (code, out, err) = mpcc(&[
        "sim",
        "--controller",
        "nmpc",
        "--trials",
        "2",
        "--seed",
        "5",
        "--json",
        "--no-plots",
    ]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
    assert_eq!(v["success"], serde_json::Value::Bool(true));
    assert_eq!(num(&v, "trials"), 2.0);
    assert_eq!(num(&v, "successes"), 2.0);
    assert_eq!(v["controller"], "nmpc");
    let phases = v["phases"].as_array().unwrap();
    let flip = phases.iter().find(|p| p["phase"] == "flip").unwrap();
    assert!(num(flip, "peak_pitch_rate_rad_s") >= 0.9 * 5.0 * std::f64::consts::PI);
    let recover = phases.iter().find(|p| p["phase"] == "recover").unwrap();
    assert!(num(recover, "recovery_time_s") <= 3.0);
    for p in phases {
        for key in [
            "max_tracking_error_m",
            "min_altitude_m",
            "peak_pitch_rate_rad_s",
        ] {
            assert!(num(p, key).is_finite(), "{key} in {p}");
        }
        let st = &p["solver_time_us"];
        if p["phase"] != "landed" {
            assert!(num(st, "mean") > 0.0 && num(st, "p99") >= num(st, "mean") * 0.5);
            assert!(num(st, "max") >= num(st, "p99"));
        }
    }
    assert_eq!(v["first"]["seed"], 5);
}

#[test]
fn pose_loss_scenario_reports_return_mode() {
    let (code, out, err) = mpcc(&["sim", "--pose-loss", "0.2", "--no-plots"]);
    assert_eq!(code, Some(0), "{out}\n{err}");
    assert!(out.contains("return mode engaged after"), "{out}");
}

#[test]
fn bad_arguments_are_refused_with_a_reason() {
    for (args, want) in [
        (vec!["sim", "--mission", "loop"], "--mission loop: unknown"),
        (
            vec!["sim", "--controller", "pid"],
            "--controller pid: unknown",
        ),
        (vec!["sim", "--trials", "0"], "at least one trial"),
        (
            vec!["sim", "--mission", "flip-throw", "--range=-3"],
            "--range -3: give positive distances",
        ),
        (
            vec!["sim", "--mission", "flip-throw", "--pose-loss", "0.1"],
            "--pose-loss is not a flip-throw setting",
        ),
        (vec!["sim", "--pose-loss=-1"], "--pose-loss -1"),
        (
            vec!["sim", "--mission", "hover", "--pose-loss", "0.1"],
            "flip-mission scenario",
        ),
    ] {
        let (code, _, err) = mpcc(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}

#[test]
fn a_failed_mission_exits_one_and_says_why() {
    // Three times the mass the controllers believe: thrust-to-weight 1.3, no 5 pi flip.
    let (code, out, err) = mpcc(&["sim", "--mass", "3", "--no-plots"]);
    assert_eq!(code, Some(1), "{out}\n{err}");
    assert!(out.contains("0 of 1 trials succeeded"), "{out}");
    assert!(out.contains("FAILED seed 0 (mass 3.00 kg"), "{out}");
    let (code, _, err) = mpcc(&["sim", "--mass", "0"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--mass 0"), "{err}");
}

#[test]
fn mission_options_move_the_rally_point() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_sim_rally");
    let _ = std::fs::remove_dir_all(&dir);
    let (code, out, err) = mpcc(&[
        "sim",
        "--controller",
        "nmpc",
        "--rally",
        "2,1,3",
        "--flip-rate",
        "12",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{out}\n{err}");
    let mut rdr = csv::Reader::from_path(dir.join("flip.csv")).unwrap();
    let headers = rdr.headers().unwrap().clone();
    let col = |name: &str| headers.iter().position(|h| h == name).unwrap();
    let (ix, iy, iz, iw, iphase) = (
        col("x_ref"),
        col("y_ref"),
        col("z_ref"),
        col("wy_ref"),
        col("phase"),
    );
    let mut held = false;
    let mut rate = 0.0f64;
    for rec in rdr.records() {
        let r = rec.unwrap();
        let f = |i: usize| r[i].parse::<f64>().unwrap();
        rate = rate.max(f(iw));
        // The hold after the flip (phase 5) is at the given rally point.
        if r[iphase].parse::<u8>().unwrap() == 5 {
            held = true;
            assert_eq!((f(ix), f(iy), f(iz)), (2.0, 1.0, 3.0));
        }
    }
    assert!(held, "no hold phase in the log");
    assert_eq!(rate, 12.0);
}

#[test]
fn flip_throw_reports_the_landing_points_and_draws_the_side_view() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_sim_throw");
    let _ = std::fs::remove_dir_all(&dir);
    let (code, out, err) = mpcc(&[
        "sim",
        "--mission",
        "flip-throw",
        "--range",
        "20",
        "--trials",
        "2",
        "--json",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{out}\n{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
    assert_eq!(v["mission"], "flip-throw");
    assert_eq!(v["success"], true);
    assert_eq!(num(&v, "range_m"), 20.0);
    let xs = v["probe_landing_x_m"].as_array().unwrap();
    assert_eq!(xs.len(), 2);
    for x in xs {
        let x = x.as_f64().unwrap();
        assert!((x - 20.0).abs() < 0.5, "{x}");
    }
    let errs = &v["probe_landing_error_m"];
    assert_eq!(errs["per_trial"].as_array().unwrap().len(), 2);
    assert!(num(errs, "worst") < 0.5);
    for key in ["release_speed_m_s", "release_angle_rad"] {
        let a = v[key].as_array().unwrap();
        assert_eq!(a.len(), 2, "{key}");
        assert!(
            a.iter().all(|e| e.as_f64().is_some_and(f64::is_finite)),
            "{key}"
        );
    }
    for f in ["probe", "position", "rates", "thrust", "solver_time"] {
        let png = std::fs::read(dir.join(format!("flip-throw_20m_{f}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{f}");
        assert!(png.len() > 20_000, "{f}.png is nearly empty");
    }
    assert!(dir.join("flip-throw_20m.csv").is_file());
}

#[test]
fn flip_throw_says_when_a_range_is_out_of_reach() {
    let (code, out, err) = mpcc(&[
        "sim",
        "--mission",
        "flip-throw",
        "--range",
        "45",
        "--no-plots",
    ]);
    assert_eq!(code, Some(1), "{out}\n{err}");
    assert!(out.contains("unreachable"), "{out}");
    assert!(out.contains("maximum range"), "{out}");
    let (code, _, err) = mpcc(&["sim", "--mission", "flip-throw", "--controller", "paper"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--controller"), "{err}");
    let (code, _, err) = mpcc(&["sim", "--range", "20"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("flip-throw"), "{err}");
}
