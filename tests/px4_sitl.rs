//! `mpcc fly` against the real PX4 v1.16 SITL (SIH quadrotor) in `../shared/px4-sitl/`,
//! judged by the simulator's ground truth in PX4's own flight log
//! (`scripts/px4_groundtruth.py`), not by what mpcc reports.
//!
//! The verdict that matters most: mpcc never exits 0 while the ground truth shows a crash.
//! Beyond that, a flight passes when mpcc claims success and the truth agrees (no crash,
//! airborne, landed, disarmed, and one flip of 2*pi +- 0.6 rad for the flip mission). A
//! flight where PX4 itself failed (its simulated sensors stopped: the truth's
//! `px4_sensor_stall`) and mpcc did not claim success is flown once more.
//!
//! Without `../shared/px4-sitl/run.sh` (or python3 with pyulog) the tests print that they did
//! not fly and pass, unless `MPCC_REQUIRE_PX4` is set. `MPCC_PX4_FLY_ARGS` (split on white
//! space) is appended to every `mpcc fly` command line. At most two PX4 instances run at once;
//! each test's PX4 working directory (px4.log, the flight log) stays under
//! `CARGO_TARGET_TMPDIR/px4_sitl/<test>`. The `verdict_*` tests check the verdict itself on
//! made-up ground truths (no PX4 needed).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

use common::wait_with_timeout;

/// One flight: a PX4 instance, its vehicle and speed, and the mission flown.
struct Case {
    name: &'static str,
    instance: u16,
    mission: &'static str,
    /// `PX4_SIM_SPEED_FACTOR` (none: PX4's default, lockstep real time).
    speed_factor: Option<&'static str>,
    /// PX4 parameters at boot (`PX4_PARAM_<NAME>`).
    params: &'static [(&'static str, &'static str)],
    /// Extra `mpcc fly` arguments for this vehicle.
    fly_args: &'static [&'static str],
    /// A rogue process impersonates PX4 on the companion's port during the flight
    /// ([`Rogue`]).
    rogue: bool,
}

/// The "agile vehicle": thrust-to-weight 4 (1 kg, 4 x 10 N), about 390 rad/s^2 of pitch
/// authority (0.2 m arms, 0.01 kg m^2), 30 ms rotors; PX4's hover thrust set to match.
const AGILE: &[(&str, &str)] = &[
    ("SIH_MASS", "1.0"),
    ("SIH_T_MAX", "10.0"),
    ("SIH_IXX", "0.01"),
    ("SIH_IYY", "0.01"),
    ("SIH_L_ROLL", "0.2"),
    ("SIH_L_PITCH", "0.2"),
    ("SIH_T_TAU", "0.03"),
    ("MPC_THR_HOVER", "0.25"),
];

#[test]
fn px4_hover_stock() {
    fly_and_judge(&Case {
        name: "px4_hover_stock",
        instance: 1,
        mission: "hover",
        speed_factor: None,
        params: &[],
        fly_args: &[],
        rogue: true,
    });
}

#[test]
fn px4_flip_stock() {
    fly_and_judge(&Case {
        name: "px4_flip_stock",
        instance: 2,
        mission: "flip",
        speed_factor: None,
        params: &[],
        fly_args: &[],
        rogue: false,
    });
}

#[test]
fn px4_flip_agile_speed_1_1() {
    fly_and_judge(&Case {
        name: "px4_flip_agile_speed_1_1",
        instance: 3,
        mission: "flip",
        speed_factor: Some("1.1"),
        params: AGILE,
        fly_args: &[],
        rogue: false,
    });
}

/// Flies `case` (if PX4 is here) and asserts the ground truth's verdict.
fn fly_and_judge(case: &Case) {
    if !prerequisites() {
        return;
    }
    let _slot = Slot::take();
    let mut attempt = 0;
    let (flight, truth) = loop {
        let (flight, truth) = fly_once(case, attempt);
        let claimed = flight.run.status.is_some_and(|s| s.success());
        if claimed || truth["px4_sensor_stall"].is_null() || attempt == PX4_FAULT_RETRIES {
            break (flight, truth);
        }
        // PX4 itself failed (its simulated sensors stopped): not a flight of mpcc's to judge.
        eprintln!(
            "{}: PX4 fault, flying again: {} stopped, mpcc did not claim success",
            case.name, truth["px4_sensor_stall"]
        );
        attempt += 1;
    };
    assert_verdict(case, &flight.run, &truth);
    if let Some(r) = &flight.rogue {
        assert_rogue_ignored(r, &report(&flight.run.stdout));
    }
}

/// A flight whose PX4 failed on its own (the ground truth's `px4_sensor_stall`: its
/// simulated barometer, magnetometer and GPS stopped, about 1 run in 50 at arming) and where
/// mpcc did not claim success is flown again, at most this often. A claimed success is
/// always judged.
const PX4_FAULT_RETRIES: u32 = 1;

/// One flight of `case` on a fresh PX4 (attempt `attempt` in its own directory), judged.
fn fly_once(case: &Case, attempt: u32) -> (Flight, serde_json::Value) {
    let name = match attempt {
        0 => case.name.to_string(),
        k => format!("{}-again{k}", case.name),
    };
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("px4_sitl")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let started = Instant::now();
    let mut px4 = Px4::start(&dir, case);
    let flight = fly(case);
    px4.stop();
    let wall = started.elapsed().as_secs_f64();
    let log = ulog(&dir);
    let truth = groundtruth(&log);
    eprintln!(
        "{}: mpcc {:?}; PX4 ran {wall:.1} s (wall clock) for a {} s log {}; ground truth {truth}",
        case.name,
        flight.run.status,
        truth["log_duration_s"],
        log.display()
    );
    (flight, truth)
}

// ----- prerequisites -----

/// `../shared/px4-sitl/` (relative to the repository root).
fn sitl_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/px4-sitl")
}

/// Whether PX4 SITL and the judge can run; panics if they cannot and `MPCC_REQUIRE_PX4` is set.
fn prerequisites() -> bool {
    let missing = if !sitl_dir().join("run.sh").is_file() {
        Some("../shared/px4-sitl/ not found")
    } else if !python_has_pyulog() {
        Some("python3 with pyulog (pip install pyulog==1.3.0) not found")
    } else {
        None
    };
    let Some(missing) = missing else {
        return true;
    };
    if std::env::var_os("MPCC_REQUIRE_PX4").is_some() {
        panic!("the real PX4 SITL is required (MPCC_REQUIRE_PX4 is set): {missing}");
    }
    println!("px4_sitl: {missing}: did not fly");
    false
}

fn python_has_pyulog() -> bool {
    Command::new("python3")
        .args(["-c", "import pyulog"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

// ----- at most two PX4 instances at once -----

static SLOTS: (Mutex<usize>, Condvar) = (Mutex::new(0), Condvar::new());
const MAX_PX4: usize = 2;

/// One of the `MAX_PX4` permits to run PX4, given back on drop (also when a test panics).
struct Slot;

impl Slot {
    fn take() -> Slot {
        let (lock, cvar) = &SLOTS;
        let mut used = lock.lock().unwrap_or_else(|e| e.into_inner());
        while *used >= MAX_PX4 {
            used = cvar.wait(used).unwrap_or_else(|e| e.into_inner());
        }
        *used += 1;
        Slot
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let (lock, cvar) = &SLOTS;
        *lock.lock().unwrap_or_else(|e| e.into_inner()) -= 1;
        cvar.notify_one();
    }
}

// ----- PX4 -----

/// A running PX4 SITL, stopped on drop (also when a test panics).
struct Px4 {
    pid: Option<String>,
}

impl Px4 {
    /// Starts PX4 in `dir` for `case` and waits for "Ready for takeoff!".
    fn start(dir: &Path, case: &Case) -> Px4 {
        let port = 14540 + case.instance;
        assert!(
            std::net::UdpSocket::bind(("127.0.0.1", port)).is_ok(),
            "UDP port {port} (PX4 instance {}'s offboard link) is in use",
            case.instance
        );
        let mut cmd = Command::new(sitl_dir().join("run.sh"));
        cmd.arg(dir).env("PX4_INSTANCE", case.instance.to_string());
        if let Some(speed) = case.speed_factor {
            cmd.env("PX4_SIM_SPEED_FACTOR", speed);
        }
        for (name, value) in case.params {
            cmd.env(format!("PX4_PARAM_{name}"), value);
        }
        let out = cmd.stderr(Stdio::inherit()).output().expect("run.sh runs");
        let pid = String::from_utf8_lossy(&out.stdout).trim().to_string();
        assert!(out.status.success() && !pid.is_empty(), "run.sh: {out:?}");
        let px4 = Px4 { pid: Some(pid) };
        px4.wait_ready(&dir.join("px4.log"), Duration::from_secs(30));
        px4
    }

    fn wait_ready(&self, log: &Path, timeout: Duration) {
        let start = Instant::now();
        loop {
            let text = std::fs::read_to_string(log).unwrap_or_default();
            if text.contains("Ready for takeoff!") {
                return;
            }
            assert!(
                start.elapsed() < timeout && self.alive(),
                "PX4 not ready for takeoff after {:?} (alive: {}); its log:\n{text}",
                start.elapsed(),
                self.alive()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn alive(&self) -> bool {
        let pid = self.pid.as_deref().unwrap_or("0");
        Path::new("/proc").join(pid).exists()
    }

    /// Stops PX4 (which closes its flight log); a second call does nothing.
    fn stop(&mut self) {
        if let Some(pid) = self.pid.take() {
            let _ = Command::new(sitl_dir().join("stop.sh")).arg(&pid).status();
        }
    }
}

impl Drop for Px4 {
    fn drop(&mut self) {
        self.stop();
    }
}

// ----- the flight -----

/// A flight: mpcc's exit, output, and what the rogue saw (if there was one).
struct Flight {
    run: common::Finished,
    rogue: Option<RogueSeen>,
}

/// `mpcc fly` for `case` against its PX4 instance, waited for (killed after 200 s), with
/// the rogue beside it if the case has one.
fn fly(case: &Case) -> Flight {
    let connect = format!("udpin:127.0.0.1:{}", 14540 + case.instance);
    let mut args: Vec<String> = [
        "fly",
        "--connect",
        &connect,
        "--mission",
        case.mission,
        "--json",
        "--no-plots",
        "--timeout",
        "120",
    ]
    .iter()
    .map(ToString::to_string)
    .collect();
    args.extend(case.fly_args.iter().map(ToString::to_string));
    let extra = std::env::var("MPCC_PX4_FLY_ARGS").unwrap_or_default();
    args.extend(extra.split_whitespace().map(String::from));
    let mut child = Command::new(env!("CARGO_BIN_EXE_mpcc"))
        .args(&args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mpcc runs");
    let rogue = case.rogue.then(|| Rogue::start(14540 + case.instance));
    let run = wait_with_timeout(&mut child, Duration::from_secs(200));
    Flight {
        run,
        rogue: rogue.map(Rogue::stop),
    }
}

// ----- the rogue -----

/// A second process on the companion's network (here a thread with its own UDP socket):
/// from 3 s after `mpcc fly` starts, it sends PX4's HEARTBEAT (system 1, component 1,
/// autopilot PX4) and ODOMETRY for a vehicle 30 m away with a clock 1000 s ahead every
/// 2 ms for 5 s, then random datagrams (half starting with MAVLink 2's magic byte) every
/// 2 ms for 5 s, and so on, and counts the datagrams mpcc sends it.
struct Rogue {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: std::thread::JoinHandle<RogueSeen>,
}

/// What the rogue did and got.
#[derive(Debug)]
struct RogueSeen {
    sent: u64,
    received: u64,
}

impl Rogue {
    fn start(port: u16) -> Rogue {
        use std::sync::atomic::{AtomicBool, Ordering};
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let flag = std::sync::Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            let socket = std::net::UdpSocket::bind("127.0.0.1:0").expect("a UDP socket");
            socket.set_nonblocking(true).expect("non-blocking");
            let mut rng = <rand::rngs::StdRng as rand::SeedableRng>::seed_from_u64(35);
            let mut seen = RogueSeen {
                sent: 0,
                received: 0,
            };
            let start = Instant::now();
            let mut buf = [0u8; 2048];
            while !flag.load(Ordering::Relaxed) {
                while socket.recv(&mut buf).is_ok() {
                    seen.received += 1;
                }
                let t = start.elapsed().as_secs_f64() - 3.0;
                if t >= 0.0 {
                    for d in rogue_datagrams(t, &mut rng) {
                        if socket.send_to(&d, ("127.0.0.1", port)).is_ok() {
                            seen.sent += 1;
                        }
                    }
                }
                std::thread::sleep(Duration::from_millis(2));
            }
            seen
        });
        Rogue { stop, thread }
    }

    fn stop(self) -> RogueSeen {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.join().expect("the rogue thread")
    }
}

/// What the rogue sends at `t` \[s\] into its attack: PX4 look-alikes for 5 s, junk for 5 s.
fn rogue_datagrams(t: f64, rng: &mut rand::rngs::StdRng) -> Vec<Vec<u8>> {
    use mavlink::dialects::common::{self as mc, MavMessage};
    use rand::Rng;
    if t % 10.0 >= 5.0 {
        let mut junk: Vec<u8> = (0..rng.random_range(1..300))
            .map(|_| rng.random())
            .collect();
        if rng.random_bool(0.5) {
            junk[0] = 0xFD;
        }
        return vec![junk];
    }
    let header = mavlink::MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
    let heartbeat = MavMessage::HEARTBEAT(mc::HEARTBEAT_DATA {
        mavtype: mc::MavType::MAV_TYPE_QUADROTOR,
        autopilot: mc::MavAutopilot::MAV_AUTOPILOT_PX4,
        system_status: mc::MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
        ..mc::HEARTBEAT_DATA::DEFAULT
    });
    let odometry = MavMessage::ODOMETRY(mc::ODOMETRY_DATA {
        time_usec: ((1000.0 + t) * 1e6) as u64,
        x: 30.0,
        z: -2.0,
        q: [1.0, 0.0, 0.0, 0.0],
        frame_id: mc::MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: mc::MavFrame::MAV_FRAME_LOCAL_NED,
        ..mc::ODOMETRY_DATA::DEFAULT
    });
    [heartbeat, odometry]
        .iter()
        .map(|m| {
            let mut out = Vec::new();
            mavlink::write_v2_msg(&mut out, header, m).expect("a frame");
            out
        })
        .collect()
}

/// The rogue got no setpoint, its datagrams were all ignored, and the hold never saw its
/// vehicle 30 m away.
fn assert_rogue_ignored(seen: &RogueSeen, report: &serde_json::Value) {
    let link = &report["link"]["trust"];
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    eprintln!("rogue: {seen:?}; mpcc's link: {}", report["link"]);
    assert!(seen.sent > 1000, "the rogue sent only {seen:?}");
    assert_eq!(seen.received, 0, "mpcc sent the rogue {seen:?} datagrams");
    assert_eq!(num(&link["ignored_senders"]), 1.0, "{link}");
    assert!(
        num(&link["ignored"]) >= 0.9 * seen.sent as f64,
        "mpcc ignored {} of {} rogue datagrams: {link}",
        link["ignored"],
        seen.sent
    );
    assert_eq!(link["relocks"].as_array().map(Vec::len), Some(0), "{link}");
    let hold = report["summary"]["phases"]
        .as_array()
        .and_then(|p| p.iter().find(|p| p["phase"] == "hold"))
        .unwrap_or_else(|| panic!("no hold phase in {}", report["summary"]));
    let err = num(&hold["max_tracking_error_m"]);
    eprintln!("the hold's largest error with the rogue: {err:.3} m");
    assert!(
        err < 1.0,
        "the hold's largest error {err} m (the rogue's vehicle is 30 m away)"
    );
}

/// The flight log PX4 wrote in `dir` (`log/<date>/<time>.ulg`; the newest if several).
fn ulog(dir: &Path) -> PathBuf {
    let mut logs: Vec<PathBuf> = std::fs::read_dir(dir.join("log"))
        .into_iter()
        .flatten()
        .flatten()
        .flat_map(|day| {
            std::fs::read_dir(day.path())
                .into_iter()
                .flatten()
                .flatten()
        })
        .map(|f| f.path())
        .filter(|p| p.extension().is_some_and(|e| e == "ulg"))
        .collect();
    logs.sort();
    logs.pop()
        .unwrap_or_else(|| panic!("no PX4 flight log (*.ulg) under {}", dir.display()))
}

/// The ground truth's verdict on `log` (scripts/px4_groundtruth.py --json).
fn groundtruth(log: &Path) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/px4_groundtruth.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(log)
        .arg("--json")
        .output()
        .expect("python3 runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "px4_groundtruth.py failed on {}: {}",
        log.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"))
}

// ----- the verdict -----

/// What the ground truth says is wrong with the flight (empty: nothing).
fn truth_failures(case: &Case, truth: &serde_json::Value) -> Vec<String> {
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let mut failures = Vec::new();
    if truth["crashed"] != false {
        failures.push(format!("crashed: {}", truth["crash_reasons"]));
    }
    let airborne = num(&truth["max_height_m"]) > 0.5 && num(&truth["airborne_s"]) > 1.0;
    if !airborne {
        failures.push("never airborne (above 0.5 m for more than 1 s)".into());
    }
    if truth["touchdowns"].as_array().is_none_or(Vec::is_empty) {
        failures.push("no touchdown: did not come back to the ground".into());
    }
    if truth["final"]["landed"] != true {
        failures.push("PX4's land detector does not show the vehicle landed at the end".into());
    }
    if truth["final"]["armed"] != false {
        failures.push("still armed at the end".into());
    }
    let rotation = num(&truth["pitch_rotation_offboard_rad"]);
    let one_flip = (rotation.abs() - std::f64::consts::TAU).abs() <= 0.6;
    if case.mission == "flip" && !one_flip {
        failures.push(format!(
            "pitch rotation in OFFBOARD {rotation:.3} rad, not 2*pi +- 0.6"
        ));
    }
    failures
}

/// mpcc's JSON report: the last stdout line that starts with `{` (null if none).
fn report(stdout: &str) -> serde_json::Value {
    stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .and_then(|l| serde_json::from_str(l).ok())
        .unwrap_or(serde_json::Value::Null)
}

fn assert_verdict(case: &Case, flight: &common::Finished, truth: &serde_json::Value) {
    let claimed = flight.status.is_some_and(|s| s.success());
    let failures = truth_failures(case, truth);
    let context = format!(
        "{}\nground truth: {truth}\nmpcc session: {}\nmpcc stderr:\n{}",
        case.name,
        report(&flight.stdout)["session"],
        flight.stderr
    );
    // The most important verdict: never a claimed success on a crashed vehicle.
    assert!(
        !(claimed && truth["crashed"] != false),
        "FALSE SUCCESS: mpcc exited 0 but the ground truth shows a crash: {}\n{context}",
        truth["crash_reasons"]
    );
    assert!(
        !claimed || failures.is_empty(),
        "FALSE SUCCESS: mpcc exited 0 but the ground truth disagrees: {failures:?}\n{context}"
    );
    assert!(
        claimed,
        "mpcc fly did not succeed (exit {:?}, None: killed after 200 s); ground truth: \
         {failures:?}\n{context}",
        flight.status.and_then(|s| s.code())
    );
}

// ----- the verdict's own checks (no PX4 needed) -----

/// A ground truth as px4_groundtruth.py prints it: a clean one-flip flight, or a crash.
fn sample_truth(crashed: bool) -> serde_json::Value {
    let reasons: &[&str] = if crashed {
        &["touchdown at 20.6 s at 5.0 m/s (> 2.0 m/s)"]
    } else {
        &[]
    };
    serde_json::json!({
        "crashed": crashed,
        "crash_reasons": reasons,
        "max_height_m": 4.0,
        "airborne_s": 30.0,
        "touchdowns": [{"t": 40.0, "impact_speed_m_s": 0.4}],
        "final": {"landed": true, "armed": false},
        "pitch_rotation_offboard_rad": -6.2,
    })
}

#[cfg(unix)]
fn exited(code: i32) -> common::Finished {
    use std::os::unix::process::ExitStatusExt;
    common::Finished {
        status: Some(std::process::ExitStatus::from_raw(code << 8)),
        stdout: "{\"session\":\"done\"}".into(),
        stderr: String::new(),
    }
}

const FLIP: Case = Case {
    name: "verdict",
    instance: 0,
    mission: "flip",
    speed_factor: None,
    params: &[],
    fly_args: &[],
    rogue: false,
};

#[test]
#[cfg(unix)]
#[should_panic(expected = "FALSE SUCCESS: mpcc exited 0 but the ground truth shows a crash")]
fn verdict_a_claimed_success_on_a_crash_fails() {
    assert_verdict(&FLIP, &exited(0), &sample_truth(true));
}

#[test]
#[cfg(unix)]
fn verdict_accepts_a_clean_flip_and_names_what_is_wrong() {
    assert_verdict(&FLIP, &exited(0), &sample_truth(false));
    assert!(truth_failures(&FLIP, &sample_truth(false)).is_empty());
    let mut truth = sample_truth(false);
    truth["pitch_rotation_offboard_rad"] = serde_json::json!(-5.5);
    truth["final"]["armed"] = serde_json::json!(true);
    let failures = truth_failures(&FLIP, &truth);
    assert_eq!(failures.len(), 2, "{failures:?}");
    assert!(failures[0].contains("still armed") && failures[1].contains("pitch rotation"));
}

#[test]
#[cfg(unix)]
#[should_panic(expected = "mpcc fly did not succeed")]
fn verdict_an_honest_failure_still_fails_the_test() {
    assert_verdict(&FLIP, &exited(1), &sample_truth(true));
}
