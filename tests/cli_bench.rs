//! `mpcc bench`: the QR-bench closed loop against the peers' closed loops (CasADi's converged
//! SQP, acados' RTI), its JSON and its errors.

mod common;

use std::path::Path;

use common::mpcc;

/// Rows of a closed-loop CSV: the 10 states of each row.
fn states(path: &Path) -> Vec<[f64; 10]> {
    let mut rdr =
        csv::Reader::from_path(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    rdr.records()
        .map(|r| {
            let r = r.unwrap();
            let mut x = [0.0; 10];
            for (i, v) in x.iter_mut().enumerate() {
                *v = r[i + 1].parse().unwrap();
            }
            x
        })
        .collect()
}

fn max_position_difference(a: &[[f64; 10]], b: &[[f64; 10]]) -> f64 {
    assert_eq!(a.len(), b.len(), "different numbers of rows");
    a.iter()
        .zip(b)
        .map(|(x, y)| (0..3).map(|i| (x[i] - y[i]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max)
}

fn tmp(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(name)
}

/// Same problem, same answer: our converged SQP closed loop equals CasADi's (the paper's
/// tool) for QR-bench A and B, with the exact Hessian (the default, from the solvers generated
/// with it) and with Gauss-Newton's; the exact Hessian's Newton steps take fewer iterations.
#[test]
fn converged_sqp_closed_loop_matches_casadi() {
    for (horizon, anchor) in [
        ("10", "casadi_qrbench_A.csv"),
        ("20", "casadi_qrbench_B.csv"),
    ] {
        let mut iterations = Vec::new();
        for hessian in ["exact", "gauss-newton"] {
            let csv = tmp(&format!("bench_sqp_{horizon}_{hessian}.csv"));
            let mut args = vec![
                "bench",
                "--horizon",
                horizon,
                "--sqp",
                "--rounds",
                "1",
                "--json",
                "--csv",
                csv.to_str().unwrap(),
            ];
            // The default is the exact Hessian: name only the other.
            if hessian == "gauss-newton" {
                args.extend(["--hessian", hessian]);
            }
            let (code, out, err) = mpcc(&args);
            assert_eq!(code, Some(0), "{out}\n{err}");
            let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
            assert_eq!(v["hessian"], hessian, "{v}");
            assert_eq!(v["all_ok"], true, "{v}");
            if hessian == "exact" {
                // Gauss-Newton's first step of A stops at the limit (50), on the way.
                assert_eq!(v["sqp_limit_steps"], 0, "{v}");
            }
            iterations.push(v["sqp_iterations_mean"].as_f64().unwrap());
            let ours = states(&csv);
            let theirs = states(
                &Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("tests/data")
                    .join(anchor),
            );
            let d = max_position_difference(&ours, &theirs);
            println!("N = {horizon}, {hessian}: {d:.1e} m from CasADi's closed loop");
            // The issue asks for 1e-3 m; the two converged solutions agree far closer.
            assert!(
                d < 1e-6,
                "N = {horizon}, {hessian}: {d} m from CasADi's closed loop"
            );
        }
        // Measured: A 2.65 against 7.79, B 2.54 against 5.88. CasADi's exact-Hessian SQP
        // took 2.69 on A (its reference runs, docs/benchmarks.md): the KKT exit and the watchdog's whole Newton
        // steps (from the hover guess, the first step of A converges in 7 QPs instead of 30)
        // bring ours under 3.
        assert!(
            iterations[0] * 1.5 < iterations[1],
            "N = {horizon}: SQP iterations per step, exact {} vs Gauss-Newton {}",
            iterations[0],
            iterations[1]
        );
        assert!(
            iterations[0] < 3.0,
            "N = {horizon}: {} exact-Hessian SQP iterations per step",
            iterations[0]
        );
    }
}

/// Without the watchdog (`--sqp-watchdog 0`: a monotone line search at every step) the
/// exact-Hessian SQP flies the same converged closed loop, CasADi's, but its first step
/// crawls: the most iterations in a step, measured 30 against the watchdog's 7 on A
/// (13 against 8 on B).
#[test]
fn the_watchdog_changes_the_iterations_not_the_closed_loop() {
    for (horizon, anchor) in [
        ("10", "casadi_qrbench_A.csv"),
        ("20", "casadi_qrbench_B.csv"),
    ] {
        let mut most = Vec::new();
        for watchdog in ["4", "0"] {
            let csv = tmp(&format!("bench_sqp_{horizon}_watchdog_{watchdog}.csv"));
            let (code, out, err) = mpcc(&[
                "bench",
                "--horizon",
                horizon,
                "--sqp",
                "--sqp-watchdog",
                watchdog,
                "--rounds",
                "1",
                "--json",
                "--csv",
                csv.to_str().unwrap(),
            ]);
            assert_eq!(code, Some(0), "{out}\n{err}");
            let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
            assert_eq!(v["all_ok"], true, "{v}");
            assert_eq!(v["sqp_limit_steps"], 0, "{v}");
            most.push(v["sqp_iterations_max"].as_u64().unwrap());
            let theirs = states(
                &Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("tests/data")
                    .join(anchor),
            );
            let d = max_position_difference(&states(&csv), &theirs);
            assert!(
                d < 1e-6,
                "N = {horizon}, watchdog {watchdog}: {d} m from CasADi's closed loop"
            );
        }
        assert!(
            most[0] < most[1],
            "N = {horizon}: most iterations in a step, with the watchdog {}, without {}",
            most[0],
            most[1]
        );
    }
}

/// The SQP's QPs solved to the QP tolerances instead of loosely and polished (`--sqp-qps
/// tight`, `RtiSettings::sqp_loose_qps = false`) converge to the same closed loop: CasADi's,
/// and the default's within the SQP tolerance. With the warm active set (the default) every
/// QP of QR-bench A is solved exactly on an active set either way; with every QP by the
/// interior point (`--warm-active-set off`) the two differ, but not beyond the tolerance.
#[test]
fn tightly_solved_sqp_qps_fly_the_same_converged_closed_loop() {
    let run = |mode: &str, warm: &str| {
        let csv = tmp(&format!("bench_sqp_a_{mode}_{warm}.csv"));
        let (code, out, err) = mpcc(&[
            "bench",
            "--sqp",
            "--sqp-qps",
            mode,
            "--warm-active-set",
            warm,
            "--rounds",
            "1",
            "--csv",
            csv.to_str().unwrap(),
        ]);
        assert_eq!(code, Some(0), "{out}\n{err}");
        states(&csv)
    };
    let (tight, loose) = (run("tight", "on"), run("loose", "on"));
    let theirs = states(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data")
            .join("casadi_qrbench_A.csv"),
    );
    let d = max_position_difference(&tight, &theirs);
    assert!(d < 1e-6, "tight: {d} m from CasADi's closed loop");
    let d = max_position_difference(&tight, &loose);
    assert!(d < 1e-6, "tight and loose QPs: {d} m apart");
    let (tight, loose) = (run("tight", "off"), run("loose", "off"));
    let d = max_position_difference(&tight, &theirs);
    assert!(
        d < 1e-6,
        "tight, interior point: {d} m from CasADi's closed loop"
    );
    let d = max_position_difference(&tight, &loose);
    assert!(d < 1e-6, "tight and loose QPs, interior point: {d} m apart");
    // Different QP solutions (the polished ones are exact): the flag took effect.
    assert!(
        d > 0.0,
        "--sqp-qps tight flew the loose closed loop bit for bit"
    );
}

#[test]
fn rti_json_and_csv_match_acados() {
    let csv = tmp("bench_rti_a.csv");
    let (code, out, err) = mpcc(&[
        "bench",
        "--rounds",
        "2",
        "--json",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
    for phase in ["prepare_us", "feedback_us", "total_us"] {
        let s = &v[phase];
        let get = |k: &str| {
            s[k].as_f64()
                .unwrap_or_else(|| panic!("{phase}.{k} in {v}"))
        };
        assert!(get("mean") > 0.0 && get("median") > 0.0);
        assert!(get("median") <= get("p99") && get("p99") <= get("max"));
    }
    assert_eq!(v["steps"], 100);
    assert_eq!(v["all_ok"], serde_json::Value::Bool(true));
    // The warm active set (the default): active-set moves from the empty set in the first
    // step, then one solve on the last step's active set, a few more where it changes; no
    // step needs the interior point.
    assert_eq!(v["qp_iterations_mean"].as_f64(), Some(0.0), "{v}");
    assert_eq!(v["qp_interior_point_steps"], 0, "{v}");
    let solves = v["qp_active_set_solves_mean"].as_f64().unwrap();
    assert!((0.99..1.5).contains(&solves), "{solves}");
    // acados' final position error for A is 2.37e-3 m.
    let e = v["final_position_error_m"].as_f64().unwrap();
    assert!((e - 2.37e-3).abs() < 1e-5, "{e}");
    let acados =
        states(&Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/acados_qrbench_A.csv"));
    let d = max_position_difference(&states(&csv), &acados);
    assert!(d < 1e-4, "{d} m from acados' RTI closed loop");

    // Every QP by the interior point: its iterations, no active-set solve, the same closed
    // loop to the interior point's tolerance.
    let off = tmp("bench_rti_a_off.csv");
    let (code, out, err) = mpcc(&[
        "bench",
        "--rounds",
        "1",
        "--json",
        "--warm-active-set",
        "off",
        "--csv",
        off.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
    let iters = v["qp_iterations_mean"].as_f64().unwrap();
    assert!((1.0..10.0).contains(&iters), "{iters}");
    assert_eq!(v["qp_interior_point_steps"], 100, "{v}");
    assert_eq!(v["qp_active_set_solves_mean"].as_f64(), Some(0.0), "{v}");
    let d = max_position_difference(&states(&off), &states(&csv));
    assert!(
        d < 1e-5 && d > 0.0,
        "{d} m from the warm active set's closed loop"
    );
    let (code, _, err) = mpcc(&["bench", "--rounds", "1", "--warm-active-set", "maybe"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("use on or off"), "{err}");
}

#[test]
fn f32_solver_flies_the_same_closed_loop() {
    let a = tmp("bench_f64.csv");
    let b = tmp("bench_f32.csv");
    for (path, extra) in [(&a, None), (&b, Some("--f32"))] {
        let mut args = vec!["bench", "--rounds", "1", "--csv", path.to_str().unwrap()];
        args.extend(extra);
        let (code, out, err) = mpcc(&args);
        assert_eq!(code, Some(0), "{out}\n{err}");
    }
    let d = max_position_difference(&states(&a), &states(&b));
    assert!(d < 1e-3, "f32 closed loop {d} m from f64");
}

/// `--model pointmass`: the paper's point-mass MPC flies its closed loop, in RTI and in SQP
/// mode. The CSV has the point mass's columns, and every row follows from the one before
/// by the exact triple integrator under the applied jerk (recomputed here in closed form);
/// the jerk and the acceleration stay within the model's bounds (50, 20); the JSON's final
/// error is the CSV's last row's distance from the target (1, 0, 0), and the mass has come
/// most of the way from the origin.
#[test]
fn pointmass_closed_loop_follows_the_plant_within_the_bounds() {
    for mode in [None, Some("--sqp")] {
        let csv = tmp(&format!("bench_pointmass{}.csv", mode.unwrap_or("")));
        let mut args = vec![
            "bench",
            "--model",
            "pointmass",
            "--rounds",
            "1",
            "--json",
            "--csv",
            csv.to_str().unwrap(),
        ];
        args.extend(mode);
        let (code, out, err) = mpcc(&args);
        assert_eq!(code, Some(0), "{mode:?}: {err}");
        let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
        assert_eq!(v["model"], "pointmass");
        assert_eq!(v["steps"], 100);
        assert_eq!(v["all_ok"], serde_json::Value::Bool(true));
        let mut rdr = csv::Reader::from_path(&csv).unwrap();
        let header: Vec<String> = rdr.headers().unwrap().iter().map(String::from).collect();
        assert_eq!(header.join(","), "t,px,py,pz,vx,vy,vz,ax,ay,az,jx,jy,jz");
        let rows: Vec<Vec<Option<f64>>> = rdr
            .records()
            .map(|r| r.unwrap().iter().map(|f| f.parse().ok()).collect())
            .collect();
        assert_eq!(rows.len(), 101);
        let dt = 0.04;
        for (k, pair) in rows.windows(2).enumerate() {
            let (x, j) = (&pair[0][1..10], &pair[0][10..13]);
            let next = &pair[1][1..10];
            for i in 0..3 {
                let (p, vel, a, jerk) = (
                    x[i].unwrap(),
                    x[3 + i].unwrap(),
                    x[6 + i].unwrap(),
                    j[i].unwrap(),
                );
                let want = [
                    p + vel * dt + a * dt * dt / 2.0 + jerk * dt.powi(3) / 6.0,
                    vel + a * dt + jerk * dt * dt / 2.0,
                    a + jerk * dt,
                ];
                for (w, got) in want.iter().zip([next[i], next[3 + i], next[6 + i]]) {
                    let got = got.unwrap();
                    assert!(
                        (w - got).abs() <= 1e-12 * w.abs().max(1.0),
                        "{mode:?} row {k}"
                    );
                }
                assert!(jerk.abs() <= 50.0 + 1e-6, "{mode:?} row {k}: jerk {jerk}");
                assert!(a.abs() <= 20.0 + 1e-6, "{mode:?} row {k}: acceleration {a}");
            }
        }
        let last = &rows[100];
        assert!(
            last[10..].iter().all(Option::is_none),
            "the last row holds the state only"
        );
        let p: Vec<f64> = last[1..4].iter().map(|v| v.unwrap()).collect();
        let dist = ((p[0] - 1.0).powi(2) + p[1].powi(2) + p[2].powi(2)).sqrt();
        let e = v["final_position_error_m"].as_f64().unwrap();
        assert!((e - dist).abs() < 1e-9, "{mode:?}: {e} against {dist}");
        assert!(e < 0.2, "{mode:?}: {e} m from the target after 4 s");
    }
}

#[test]
fn unsupported_cases_are_refused_with_what_exists() {
    for (args, want) in [
        (
            vec!["bench", "--horizon", "30"],
            "compiled in: --horizon 10, --horizon 20, --horizon 40, --horizon 10 --f32",
        ),
        (
            vec!["bench", "--horizon", "15", "--f32"],
            "--horizon 15 --f32: no solver",
        ),
        (
            vec!["bench", "--model", "pendulum"],
            "--model pendulum: unknown; the benchmark problems are qrbench",
        ),
        (
            vec!["bench", "--model", "pointmass", "--f32"],
            "compiled in: --horizon 10 (f64)",
        ),
        (vec!["bench", "--rounds", "0"], "--rounds 0"),
        (
            vec!["bench", "--sqp-qps", "tight"],
            "--sqp-qps applies to the full SQP: add --sqp",
        ),
        (
            vec!["bench", "--sqp", "--sqp-qps", "exact"],
            "--sqp-qps exact: use loose or tight",
        ),
        (
            vec!["bench", "--hessian", "exact"],
            "--hessian applies to the full SQP",
        ),
        (
            vec!["bench", "--sqp", "--hessian", "exact", "--f32"],
            "--hessian exact: no solver generated with the exact Hessian for this case",
        ),
        (
            vec!["bench", "--sqp", "--hessian", "newton"],
            "--hessian newton: use exact or gauss-newton",
        ),
        (
            vec!["bench", "--sqp-watchdog", "2"],
            "--sqp-watchdog applies to the full SQP with the exact Hessian",
        ),
        (
            vec![
                "bench",
                "--sqp",
                "--hessian",
                "gauss-newton",
                "--sqp-watchdog",
                "2",
            ],
            "--sqp-watchdog applies to the full SQP with the exact Hessian",
        ),
    ] {
        let (code, _, err) = mpcc(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}
