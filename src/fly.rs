//! `mpcc fly`: fly a mission through PX4 over MAVLink with the generated NMPC (`mpcc sitl`,
//! the simulated PX4 vehicle to fly it against, is in `sitl.rs`).

use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use firmware_shim::messages;
use firmware_shim::pilot::{self, Pilot, PilotConfig};
use firmware_shim::profile::VehicleProfile;
use firmware_shim::setpoint::ThrustMap;
use firmware_shim::signing::SigningKey;
use firmware_shim::transport::{Address, Link, LinkOptions, LinkStats};
use firmware_shim::trust::Trust;
use mpc_mission::mission::{G, MissionKind};
use mpc_mission::report;

use crate::FlyArgs;

/// Ctrl-C sets the returned flag (once per process; a second handler cannot be installed).
pub(crate) fn interrupt_flag() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = Arc::clone(&stop);
    if let Err(e) = ctrlc::set_handler(move || s.store(true, Ordering::Relaxed)) {
        eprintln!("warning: Ctrl-C will not stop cleanly: {e}");
    }
    stop
}

/// The companion's link: locked onto PX4 (the first PX4 HEARTBEAT's sender, or
/// `--autopilot`), signed with `--signing-key`.
fn open(args: &FlyArgs) -> Result<Link, String> {
    let address = &args.connect;
    let addr: Address = address
        .parse()
        .map_err(|e| format!("--connect {address}: {e}"))?;
    let mut options = LinkOptions::companion(messages::PX4_SYSTEM);
    if let Some(a) = &args.autopilot {
        if !matches!(addr, Address::UdpIn { .. }) {
            return Err(format!(
                "--autopilot {a}: a setting of udpin links (udpout takes only its destination)"
            ));
        }
        let to: SocketAddr = a.parse().map_err(|_| {
            format!("--autopilot {a}: give HOST:PORT with a numeric host, e.g. 127.0.0.1:14580")
        })?;
        options.trust = Trust::Fixed(to);
    }
    if let Some(k) = &args.signing_key {
        options.signing = Some(SigningKey::load(k).map_err(|e| format!("--signing-key: {e}"))?);
    }
    Link::open_with(&addr, &options).map_err(|e| format!("--connect {address}: {e}"))
}

fn mission_kind(name: &str) -> Result<MissionKind, String> {
    match name {
        "flip" => Ok(MissionKind::Flip),
        "hover" => Ok(MissionKind::Hover),
        "step" => Ok(MissionKind::Step),
        "flip-throw" => Err(
            "--mission flip-throw: the probe mission flies only in the simulator (`mpcc sim`)"
                .to_string(),
        ),
        m => Err(format!("--mission {m}: unknown; use flip, hover or step")),
    }
}

fn pilot_config(args: &FlyArgs) -> Result<PilotConfig, String> {
    let kind = mission_kind(&args.mission)?;
    let mut mission = crate::sim::mission_config(kind, &args.shape)?;
    if let Some(h) = args.hover_time {
        if kind != MissionKind::Hover {
            return Err("--hover-time is a setting of --mission hover".to_string());
        }
        if !(h.is_finite() && (0.0..=3600.0).contains(&h)) {
            return Err(format!("--hover-time {h}: give 0 to 3600 s"));
        }
        mission.hover_time = h;
    }
    let mut cfg = PilotConfig::new(mission);
    if let Some(h) = args.hover_thrust {
        let map = ThrustMap {
            hover_thrust: h,
            g: G,
        };
        map.validate()
            .map_err(|e| format!("--hover-thrust {h}: {e}"))?;
        cfg.thrust_map = Some(map);
    }
    cfg.flip_rate = args.shape.flip_rate;
    if let Some(path) = &args.vehicle {
        cfg.vehicle = Some(VehicleProfile::load(path).map_err(|e| format!("--vehicle: {e}"))?);
    }
    cfg.setpoint_rate = args.rate;
    cfg.link.odometry_timeout = args.odometry_timeout;
    cfg.validate().map_err(|e| e.to_string())?;
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        return Err(format!("--timeout {}: give a time > 0 s", args.timeout));
    }
    Ok(cfg)
}

pub(crate) fn fly(args: &FlyArgs) -> ExitCode {
    let (link, mut pilot) = match prepare(args) {
        Ok(v) => v,
        Err(code) => return code,
    };
    let stop = interrupt_flag();
    if !args.json {
        eprintln!(
            "fly: {} mission on {} (Ctrl-C: land); waiting for PX4's state",
            args.mission, args.connect
        );
    }
    let started = Instant::now();
    let timed_out = run_pilot(args, &link, &mut pilot, started, &stop);
    if pilot.state().is_none() {
        eprintln!(
            "error: no ODOMETRY (nor LOCAL_POSITION_NED + ATTITUDE_QUATERNION) from PX4 (system \
             1, component 1) on {} in {:.1} s: is PX4 sending to this address?",
            args.connect,
            started.elapsed().as_secs_f64()
        );
        eprintln!("{}", link_line(&link.stats()));
        return ExitCode::FAILURE;
    }
    if timed_out {
        eprintln!(
            "error: the mission did not finish within --timeout {} s",
            args.timeout
        );
    }
    if let Some(f) = pilot.failure() {
        eprintln!("error: {f}");
        return ExitCode::FAILURE;
    }
    report_flight(args, &link, &pilot)
}

/// The link and the pilot from the options, once the solver is checked; otherwise the
/// exit status (2 for bad options), the error printed.
fn prepare(args: &FlyArgs) -> Result<(Link, Pilot), ExitCode> {
    let fail = |e: &dyn std::fmt::Display, code: ExitCode| {
        eprintln!("error: {e}");
        code
    };
    let cfg = pilot_config(args).map_err(|e| fail(&e, ExitCode::from(2)))?;
    let link = open(args).map_err(|e| fail(&e, ExitCode::from(2)))?;
    let pilot = Pilot::new(cfg).map_err(|e| fail(&e, ExitCode::from(2)))?;
    Ok((link, pilot))
}

/// Runs the pilot on the link in slices of 0.1 s, printing its events as they happen, until
/// it has finished, Ctrl-C came before any session, or the timeout: then the pilot lands
/// the vehicle (AUTO.LAND) and waits at most a minute more for PX4 to disarm. Whether the
/// timeout was reached.
fn run_pilot(
    args: &FlyArgs,
    link: &Link,
    pilot: &mut Pilot,
    started: Instant,
    stop: &AtomicBool,
) -> bool {
    const LANDING_GRACE: f64 = 60.0;
    let mut shown = 0;
    let mut timed_out = false;
    loop {
        let elapsed = started.elapsed().as_secs_f64();
        if pilot.finished() || elapsed >= args.timeout + LANDING_GRACE {
            break;
        }
        if elapsed >= args.timeout && !timed_out {
            timed_out = true;
            if pilot.session().is_none() {
                break;
            }
            eprintln!("fly: --timeout {} s reached: landing", args.timeout);
            pilot.abort();
        }
        if stop.load(Ordering::Relaxed) && pilot.session().is_none() {
            break;
        }
        let until = if timed_out {
            args.timeout + LANDING_GRACE
        } else {
            args.timeout
        };
        pilot::run(link, pilot, started, (elapsed + 0.1).min(until), stop);
        for e in pilot.events().iter().skip(shown) {
            if !args.json {
                eprintln!("{:9.3} s  {}", e.t, e.what);
            }
        }
        shown = pilot.events().len();
    }
    timed_out
}

/// Prints the flight's report (the table and the link's figures, or one JSON object),
/// writes the log, the plots and the vehicle's profile; the exit status: success only for a
/// mission that met every criterion with no failsafe.
fn report_flight(args: &FlyArgs, link: &Link, pilot: &Pilot) -> ExitCode {
    let mut rep = pilot.report();
    rep.link = Some(link.stats());
    if args.json {
        match serde_json::to_string(&rep) {
            Ok(s) => println!("{s}"),
            Err(e) => {
                eprintln!("error: JSON: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        if let Some(s) = &rep.summary {
            let run = report::aggregate(&args.mission, "nmpc", std::slice::from_ref(s));
            print!("{}", report::table(&run));
        }
        print_link_figures(&rep);
    }
    if !args.no_plots
        && !pilot.samples().is_empty()
        && let Err(e) = crate::trials::write_log_and_plots(
            &args.out,
            &format!("fly_{}", args.mission),
            &format!("{} · mpcc fly · PX4 telemetry", args.mission),
            pilot.samples(),
            args.json,
        )
    {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    if !args.no_plots
        && let Some(v) = &rep.vehicle
        && let Err(e) = v.save(&args.out.join("vehicle.json"))
    {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    if rep.summary.as_ref().is_some_and(|s| s.success) && rep.failsafes.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

fn print_link_figures(rep: &pilot::FlightReport) {
    let p = &rep.setpoint_period;
    let s = &rep.solver_period;
    println!("session: {}", rep.session);
    if let Some(v) = &rep.vehicle {
        println!("vehicle: {}", v.describe());
    }
    if let Some(f) = &rep.flip {
        println!(
            "flip: {:.1} rad/s (this vehicle: up to {:.1}), ramped at {:.0} rad/s^2, {:.2} s, \
             climbing in at {:.1} m/s",
            f.rate, f.max_rate, f.accel, f.duration, f.ascend_speed
        );
    }
    let rtt = rep
        .round_trip_ms
        .map_or("no TIMESYNC answer".to_string(), |(a, b)| {
            format!("round trip {a:.1}-{b:.1} ms")
        });
    println!(
        "clock: PX4's runs at {:.4} of the wall clock, {} jumps; {rtt}",
        rep.clock_rate, rep.clock_jumps
    );
    for (f, t) in &rep.failsafes {
        println!("failsafe: {f} at {t:.3} s");
    }
    if let Some(l) = &rep.link {
        println!("{}", link_line(l));
    }
    println!(
        "link: {} states ({} dropped: duplicate, overtaken or not finite), {} setpoints \
         ({} clamped, {} replaced)",
        rep.states,
        rep.states_dropped,
        rep.setpoints,
        rep.setpoints_clamped,
        rep.setpoints_replaced
    );
    println!(
        "setpoint period [ms]: mean {:.2}  median {:.2}  p99 {:.2}  max {:.2}  ({} periods)",
        p.mean_ms, p.median_ms, p.p99_ms, p.max_ms, p.count
    );
    println!(
        "solver period [ms]:   mean {:.2}  median {:.2}  p99 {:.2}  max {:.2}  ({} solves, {} \
         fallbacks; solver time mean {:.0} us, p99 {:.0} us)",
        s.mean_ms,
        s.median_ms,
        s.p99_ms,
        s.max_ms,
        s.count,
        rep.fallbacks,
        rep.solver_us.mean,
        rep.solver_us.p99
    );
}

/// The link's trust in one line: the peer, what was ignored, the signatures refused.
fn link_line(l: &LinkStats) -> String {
    let t = &l.trust;
    let mut out = match &t.peer {
        Some(p) => format!("autopilot: {p}"),
        None => "autopilot: none locked (no PX4 HEARTBEAT taken)".to_string(),
    };
    for r in &t.relocks {
        out += &format!(", relocked from {} to {} at {:.1} s", r.from, r.to, r.at_s);
    }
    out += &format!(
        "; ignored {} datagrams from {} other senders, {} before the lock, {} not MAVLink 2",
        t.ignored, t.ignored_senders, t.before_lock, l.malformed
    );
    if l.signing {
        out += &format!(
            "; signed, refused {} unsigned, {} with another key, {} replayed frames",
            l.unsigned, l.bad_signature, l.replayed
        );
        if l.bad_signature > 0 && t.peer.is_none() {
            out += " (is the key the one PX4 has?)";
        } else if l.unsigned > 0 && t.peer.is_none() {
            out += " (PX4 does not sign: give it the key, docs/shim.md \"Link security\")";
        }
    } else {
        out += "; not signed";
    }
    out
}
