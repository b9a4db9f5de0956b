//! `mpcc fly` against `mpcc sitl`, two processes on loopback UDP, in real time: the flip
//! mission end to end (the simulator's criteria on the telemetry, the truth from the
//! simulated PX4), the controller process killed in flight (the simulated PX4's
//! offboard-loss failsafe holds the vehicle), Ctrl-C (the controller lands the vehicle through
//! PX4 and waits for the disarm), and the errors on bad input.

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU16, Ordering};
use std::time::Duration;

use common::{mpcc, num, wait_with_timeout};

/// A loopback UDP port free now, for `mpcc fly` to bind. It comes from 20000..32000, below
/// Linux's default ephemeral range (32768..=60999), so a socket bound to port 0 meanwhile
/// (`mpcc sitl`'s client link, a test beside this one) is never given it before `fly` starts
/// and binds it.
fn free_port() -> u16 {
    static NEXT: AtomicU16 = AtomicU16::new(0);
    let start = (std::process::id() % 12_000) as u16;
    for _ in 0..256 {
        let i = NEXT.fetch_add(1, Ordering::Relaxed);
        let port = 20_000 + (start.wrapping_add(i.wrapping_mul(7)) % 12_000);
        if std::net::UdpSocket::bind(("127.0.0.1", port)).is_ok() {
            return port;
        }
    }
    panic!("no free loopback port in 20000..32000 after 256 tries")
}

fn spawn(args: &[&str]) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_mpcc"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mpcc runs")
}

fn json(text: &str) -> serde_json::Value {
    let line = text
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no JSON in\n{text}"));
    serde_json::from_str(line).unwrap()
}

#[test]
fn fly_flies_the_flip_against_sitl() {
    let port = free_port();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_fly_flip");
    let _ = std::fs::remove_dir_all(&dir);
    let mut sitl = spawn(&[
        "sitl",
        "--connect",
        &format!("udpout:127.0.0.1:{port}"),
        "--exit-after-flight",
        "--duration",
        "120",
        "--json",
    ]);
    // The hover thrust comes from the simulated PX4's MPC_THR_HOVER.
    let mut fly = spawn(&[
        "fly",
        "--connect",
        &format!("udpin:127.0.0.1:{port}"),
        "--mission",
        "flip",
        "--timeout",
        "100",
        "--out",
        dir.to_str().unwrap(),
    ]);
    let f = wait_with_timeout(&mut fly, Duration::from_secs(150));
    let s = wait_with_timeout(&mut sitl, Duration::from_secs(30));
    assert!(
        f.status.is_some_and(|c| c.success()),
        "fly: {:?}\n{}\n{}\nsitl:\n{}",
        f.status,
        f.stdout,
        f.stderr,
        s.stderr
    );
    // The simulator's table and criteria, on the telemetry.
    assert!(f.stdout.contains("1 of 1 trials succeeded"), "{}", f.stdout);
    assert!(f.stdout.contains("session: Done"), "{}", f.stdout);
    for event in [
        "PX4: MPC_THR_HOVER",
        "PX4: OFFBOARD, armed",
        "mission: flip",
        "mission: landed",
        "done: PX4 disarmed",
    ] {
        assert!(f.stderr.contains(event), "no '{event}' in\n{}", f.stderr);
    }
    assert!(f.stdout.contains("setpoint period [ms]"), "{}", f.stdout);
    let csv = std::fs::read_to_string(dir.join("fly_flip.csv")).unwrap();
    assert!(csv.lines().count() > 1500, "a 100 Hz telemetry log");
    let png = std::fs::read(dir.join("fly_flip_position.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    // The truth, from the simulated PX4.
    assert!(s.status.is_some_and(|c| c.success()), "{}", s.stderr);
    let truth = json(&s.stdout);
    assert!(truth["crashed"].is_null(), "{truth}");
    let turns = num(&truth, "offboard_pitch_rotation_rad") / std::f64::consts::TAU;
    assert!((turns - 1.0).abs() < 0.05, "{turns} turns");
    assert!(num(&truth, "offboard_max_pitch_rate_rad_s") > 0.9 * 5.0 * std::f64::consts::PI);
    let td = truth["touchdowns"].as_array().unwrap();
    let last = td.last().expect("landed");
    assert!(num(last, "vertical_speed_m_s") < 0.6, "{last}");
    assert_eq!(truth["armed"], false);
    let modes: Vec<&str> = truth["mode_changes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["to"].as_str().unwrap())
        .collect();
    assert_eq!(modes, ["OFFBOARD", "AUTO.LAND"], "{truth}");
}

#[test]
fn a_killed_controller_leaves_the_vehicle_to_px4s_offboard_loss_failsafe() {
    let port = free_port();
    // No height bias: PX4's hold keeps its estimate's height, and this test judges the hold
    // by the truth.
    let mut sitl = spawn(&[
        "sitl",
        "--connect",
        &format!("udpout:127.0.0.1:{port}"),
        "--height-bias",
        "0",
        "--duration",
        "30",
        "--json",
    ]);
    let mut fly = spawn(&[
        "fly",
        "--connect",
        &format!("udpin:127.0.0.1:{port}"),
        "--mission",
        "hover",
        "--hover-time",
        "60",
        "--no-plots",
    ]);
    // Kill the controller (SIGKILL: no chance to land) once it hovers at the take-off point.
    let (seen, _rest) = wait_for_line(&mut fly, "mission: hold");
    fly.kill().unwrap();
    let _ = fly.wait();
    assert!(
        seen.last().is_some_and(|l| l.contains("mission: hold")),
        "{seen:?}"
    );
    let s = wait_with_timeout(&mut sitl, Duration::from_secs(60));
    assert!(s.status.is_some_and(|c| c.success()), "{}", s.stderr);
    let truth = json(&s.stdout);
    assert!(truth["crashed"].is_null(), "{truth}");
    // PX4 switched to POSCTL on its own (the failsafe), is still armed and holds the
    // vehicle in the air near the take-off point.
    let failsafe = truth["mode_changes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["failsafe"] == true)
        .unwrap_or_else(|| panic!("no failsafe in {truth}"));
    assert_eq!(failsafe["from"], "OFFBOARD");
    assert_eq!(failsafe["to"], "POSCTL");
    assert!(num(&truth, "offboard_loss_failsafe_at_s") > 0.0);
    assert_eq!(truth["armed"], true);
    let p = &truth["final_position_m"];
    let z = p[2].as_f64().unwrap();
    assert!(z > 1.5 && z < 2.5, "holds its height: {p}");
    assert!(
        p[0].as_f64().unwrap().hypot(p[1].as_f64().unwrap()) < 0.5,
        "{p}"
    );
}

/// Reads `child`'s stderr until a line contains `what`; returns the lines read (the reader
/// goes on draining on a thread so the child never blocks on a full pipe).
fn wait_for_line(
    child: &mut std::process::Child,
    what: &str,
) -> (Vec<String>, std::thread::JoinHandle<Vec<String>>) {
    let stderr = BufReader::new(child.stderr.take().unwrap());
    let mut lines = stderr.lines();
    let mut seen = Vec::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        let found = line.contains(what);
        seen.push(line);
        if found {
            break;
        }
    }
    let rest = std::thread::spawn(move || lines.map_while(Result::ok).collect());
    (seen, rest)
}

#[test]
fn ctrl_c_lands_the_vehicle_instead_of_just_exiting() {
    let port = free_port();
    let mut sitl = spawn(&[
        "sitl",
        "--connect",
        &format!("udpout:127.0.0.1:{port}"),
        "--exit-after-flight",
        "--duration",
        "60",
        "--json",
    ]);
    let mut fly = spawn(&[
        "fly",
        "--connect",
        &format!("udpin:127.0.0.1:{port}"),
        "--mission",
        "hover",
        "--hover-time",
        "60",
        "--no-plots",
    ]);
    let (seen, rest) = wait_for_line(&mut fly, "mission: hold");
    assert!(
        seen.last().is_some_and(|l| l.contains("mission: hold")),
        "{seen:?}"
    );
    let interrupted = Command::new("kill")
        .args(["-INT", &fly.id().to_string()])
        .status()
        .unwrap();
    assert!(interrupted.success());
    let f = wait_with_timeout(&mut fly, Duration::from_secs(60));
    let rest = rest.join().unwrap().join("\n");
    // It landed through PX4 (AUTO.LAND), waited for the disarm, and says it did not finish
    // the mission.
    assert_eq!(f.status.and_then(|s| s.code()), Some(1), "{rest}");
    assert!(rest.contains("failsafe: Abort -> AUTO.LAND"), "{rest}");
    assert!(rest.contains("done: PX4 disarmed"), "{rest}");
    let s = wait_with_timeout(&mut sitl, Duration::from_secs(30));
    let truth = json(&s.stdout);
    assert!(truth["crashed"].is_null(), "{truth}");
    assert_eq!(truth["armed"], false, "{truth}");
    let last = truth["mode_changes"]
        .as_array()
        .unwrap()
        .last()
        .unwrap()
        .clone();
    assert_eq!(last["to"], "AUTO.LAND", "{truth}");
    assert_eq!(last["failsafe"], false, "commanded, not PX4's own failsafe");
    assert!(
        !truth["touchdowns"].as_array().unwrap().is_empty(),
        "{truth}"
    );
}

#[test]
fn fly_json_has_the_documented_fields() {
    let port = free_port();
    let mut sitl = spawn(&[
        "sitl",
        "--connect",
        &format!("udpout:127.0.0.1:{port}"),
        "--exit-after-flight",
        "--duration",
        "60",
    ]);
    let mut fly = spawn(&[
        "fly",
        "--connect",
        &format!("udpin:127.0.0.1:{port}"),
        "--mission",
        "hover",
        "--hover-time",
        "1",
        "--hover-thrust",
        "0.2503",
        "--rate",
        "50",
        "--json",
        "--no-plots",
    ]);
    let f = wait_with_timeout(&mut fly, Duration::from_secs(90));
    let _ = wait_with_timeout(&mut sitl, Duration::from_secs(30));
    assert!(
        f.status.is_some_and(|c| c.success()),
        "{}\n{}",
        f.stdout,
        f.stderr
    );
    // stdout is the one JSON object and nothing else.
    assert_eq!(f.stdout.trim().lines().count(), 1, "{}", f.stdout);
    let v = json(&f.stdout);
    assert_eq!(v["summary"]["success"], true, "{v}");
    assert_eq!(v["session"], "Done");
    assert_eq!(v["failsafes"].as_array().map(Vec::len), Some(0));
    assert!(num(&v, "states") > 500.0, "{v}");
    assert_eq!(num(&v, "states_dropped"), 0.0);
    assert_eq!(num(&v, "fallbacks"), 0.0);
    // --rate 50: a 20 ms stream.
    let period = &v["setpoint_period"];
    assert!((num(period, "median_ms") - 20.0).abs() < 2.0, "{period}");
    for key in ["mean_ms", "p99_ms", "max_ms", "count"] {
        num(period, key);
        num(&v["solver_period"], key);
    }
    assert!(
        (num(&v["solver_period"], "median_ms") - 50.0).abs() < 5.0,
        "{v}"
    );
    assert!(num(&v["solver_us"], "mean") > 0.0);
    assert!(num(&v, "setpoints") > 0.0);
    assert_eq!(
        num(&v, "setpoints_clamped"),
        0.0,
        "a hover needs no clamping"
    );
    assert!(num(&v, "setpoints_replaced") == 0.0);
    // The link locked onto the simulated PX4 and ignored nothing.
    let link = &v["link"];
    assert!(link["trust"]["peer"].as_str().is_some(), "{link}");
    assert_eq!(num(&link["trust"], "ignored"), 0.0, "{link}");
    assert_eq!(num(link, "malformed"), 0.0, "{link}");
    assert_eq!(link["signing"], false, "{link}");
}

fn key_file(name: &str, byte: u8) -> String {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    // One key as 64 hexadecimal digits, the other as raw bytes: both formats load.
    if byte.is_multiple_of(2) {
        std::fs::write(&path, format!("{}\n", format!("{byte:02x}").repeat(32))).unwrap();
    } else {
        std::fs::write(&path, [byte; 32]).unwrap();
    }
    path.to_str().unwrap().to_string()
}

/// `mpcc sitl --signing-key K` and `mpcc fly --signing-key K2` for a 1 s hover.
fn signed_hover(
    sitl_key: &str,
    fly_key: &str,
    timeout: &str,
) -> (common::Finished, serde_json::Value) {
    let port = free_port();
    let mut sitl = spawn(&[
        "sitl",
        "--connect",
        &format!("udpout:127.0.0.1:{port}"),
        "--exit-after-flight",
        "--duration",
        "60",
        "--signing-key",
        sitl_key,
    ]);
    let mut fly = spawn(&[
        "fly",
        "--connect",
        &format!("udpin:127.0.0.1:{port}"),
        "--mission",
        "hover",
        "--hover-time",
        "1",
        "--signing-key",
        fly_key,
        "--timeout",
        timeout,
        "--json",
        "--no-plots",
    ]);
    let f = wait_with_timeout(&mut fly, Duration::from_secs(90));
    let _ = sitl.kill();
    let _ = wait_with_timeout(&mut sitl, Duration::from_secs(30));
    let v = if f.stdout.contains('{') {
        json(&f.stdout)
    } else {
        serde_json::Value::Null
    };
    (f, v)
}

#[test]
fn a_signed_link_flies_and_a_peer_with_another_key_is_refused() {
    let (k1, k2) = (key_file("signing_k1", 0x5a), key_file("signing_k2", 0x33));
    let (f, v) = signed_hover(&k1, &k1, "60");
    assert!(
        f.status.is_some_and(|c| c.success()),
        "{}\n{}",
        f.stdout,
        f.stderr
    );
    assert_eq!(v["summary"]["success"], true, "{v}");
    let link = &v["link"];
    assert_eq!(link["signing"], true, "{link}");
    for refused in ["unsigned", "bad_signature", "replayed"] {
        assert_eq!(num(link, refused), 0.0, "{link}");
    }
    // The simulated PX4 signs with another key: nothing of it is taken, the flight never
    // starts, and the error says why.
    let (f, _) = signed_hover(&k2, &k1, "4");
    assert_eq!(
        f.status.and_then(|c| c.code()),
        Some(1),
        "{}\n{}",
        f.stdout,
        f.stderr
    );
    assert!(f.stderr.contains("no ODOMETRY"), "{}", f.stderr);
    assert!(f.stderr.contains("autopilot: none locked"), "{}", f.stderr);
    assert!(
        f.stderr.contains("is the key the one PX4 has?"),
        "{}",
        f.stderr
    );
    let refused: u64 = f
        .stderr
        .split("refused 0 unsigned, ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    assert!(refused > 100, "{}", f.stderr);
}

#[test]
fn fly_and_sitl_reject_bad_input_with_a_clear_message() {
    let port = free_port().to_string();
    let udpin = format!("udpin:127.0.0.1:{port}");
    for (args, want) in [
        (
            vec!["fly", "--connect", "tcp:1.2.3.4:5"],
            "--connect tcp:1.2.3.4:5",
        ),
        (
            vec!["fly", "--connect", &udpin, "--rate", "500"],
            "setpoint rate 500",
        ),
        (
            vec!["fly", "--connect", &udpin, "--mission", "flip-throw"],
            "only in the simulator",
        ),
        (
            vec!["fly", "--connect", &udpin, "--hover-time", "3"],
            "--hover-time is a setting of --mission hover",
        ),
        (
            vec!["fly", "--connect", &udpin, "--hover-thrust", "1.5"],
            "--hover-thrust 1.5",
        ),
        (vec!["sitl", "--duration", "0"], "--duration 0"),
        (
            vec!["fly", "--connect", &udpin, "--signing-key", "no/such/key"],
            "--signing-key: signing key `no/such/key`",
        ),
        (
            vec!["sitl", "--signing-key", "Cargo.toml"],
            "not 32 (nor 64 hexadecimal digits)",
        ),
        (
            vec![
                "fly",
                "--connect",
                "udpout:127.0.0.1:9",
                "--autopilot",
                "127.0.0.1:5",
            ],
            "a setting of udpin links",
        ),
        (
            vec!["fly", "--connect", &udpin, "--autopilot", "px4:14580"],
            "--autopilot px4:14580: give HOST:PORT",
        ),
    ] {
        let (code, _, err) = mpcc(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: want '{want}' in {err}");
    }
    // Nobody on the link: a timeout with the reason.
    let (code, _, err) = mpcc(&["fly", "--connect", &udpin, "--timeout", "1"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("no ODOMETRY"), "{err}");
}
