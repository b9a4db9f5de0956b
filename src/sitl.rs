//! `mpcc sitl`: the simulated PX4 vehicle (`px4_sim::vehicle`) on a MAVLink link, for
//! `mpcc fly` to fly against.

use std::path::Path;
use std::process::ExitCode;

use firmware_shim::messages;
use firmware_shim::signing::SigningKey;
use firmware_shim::transport::{Address, Link, LinkOptions};
use mpc_mission::estimate::EstimatorConfig;
use px4_sim::vehicle::{
    Airframe, ClockJump, HEIGHT_BIAS_RAMP, SimVehicle, VehicleConfig, VehicleConfigError,
};

use crate::SitlArgs;
use crate::fly::interrupt_flag;

/// The link, sending as PX4 (system 1, component 1), signed with `key` if given.
fn open_as_px4(address: &str, key: Option<&Path>) -> Result<Link, String> {
    let addr: Address = address
        .parse()
        .map_err(|e| format!("--connect {address}: {e}"))?;
    let mut options = LinkOptions::autopilot(messages::PX4_SYSTEM, messages::PX4_COMPONENT);
    if let Some(k) = key {
        options.signing = Some(SigningKey::load(k).map_err(|e| format!("--signing-key: {e}"))?);
    }
    Link::open_with(&addr, &options).map_err(|e| format!("--connect {address}: {e}"))
}

/// The option a bad vehicle setting came from.
fn option_of(e: &VehicleConfigError) -> &'static str {
    match e {
        VehicleConfigError::ClockRate(_) => "--clock-rate",
        VehicleConfigError::ClockJump(_) => "--clock-jump",
        VehicleConfigError::HeightBias(_) => "--height-bias",
        VehicleConfigError::Airframe(_) => "--vehicle",
    }
}

fn option_error(e: &VehicleConfigError) -> String {
    format!("{}: {e}", option_of(e))
}

/// The vehicle's settings from the options, or the message naming the option to fix.
fn vehicle_config(args: &SitlArgs) -> Result<VehicleConfig, String> {
    if let Some(d) = args.duration
        && !(d.is_finite() && d > 0.0)
    {
        return Err(format!("--duration {d}: give a time > 0 s"));
    }
    let airframe: Airframe = args.vehicle.parse().map_err(|e| option_error(&e))?;
    let mut cfg = airframe.config();
    cfg.seed = args.seed;
    cfg.clock_rate = args.clock_rate;
    if let Some(j) = &args.clock_jump {
        cfg.clock_jump = Some(j.parse::<ClockJump>().map_err(|e| option_error(&e))?);
    }
    if args.perfect_sensing {
        cfg.estimator = EstimatorConfig::perfect();
        cfg.height_bias = Some(0.0);
    }
    if let Some(b) = args.height_bias {
        cfg.height_bias = Some(b);
    }
    cfg.validate().map_err(|e| option_error(&e))?;
    Ok(cfg)
}

/// The opening line: where, which vehicle, its clock and its estimate's height error.
fn announce(vehicle: &SimVehicle, args: &SitlArgs) {
    let cfg = vehicle.config();
    let jump = cfg.clock_jump.map_or(String::new(), |j| {
        format!(", jumping by {:+} s at {} s", j.by, j.at)
    });
    eprintln!(
        "sitl: simulated PX4 (system 1, component 1) on {}; vehicle {} (MPC_THR_HOVER {:.4}, \
         true hover thrust {:.4}); clock {} of the wall clock's rate{jump}; height error of \
         the estimate {:+.2} m (reached {HEIGHT_BIAS_RAMP} s after arming); Ctrl-C to stop",
        args.connect,
        args.vehicle,
        vehicle.hover_thrust_param(),
        vehicle.thrust_map().hover_thrust,
        cfg.clock_rate,
        cfg.final_height_bias(),
    );
}

/// What has been printed while serving, and when the vehicle was last seen disarmed after
/// a flight.
#[derive(Default)]
struct Progress {
    modes_shown: usize,
    disarms_shown: usize,
    disarmed_since: Option<f64>,
}

impl Progress {
    /// Prints the new events; false when serving should end (a crash, or
    /// `--exit-after-flight` once the controller has seen the disarm).
    fn on_tick(&mut self, v: &SimVehicle, json: bool, exit_after_flight: bool) -> bool {
        let r = v.record();
        if !json {
            for m in r.mode_changes.iter().skip(self.modes_shown) {
                eprintln!("{:9.3} s  {m}", m.time);
            }
            for t in r.auto_disarmed_at.iter().skip(self.disarms_shown) {
                eprintln!("{t:9.3} s  disarmed by PX4: its land detector said landed");
            }
        }
        self.modes_shown = r.mode_changes.len();
        self.disarms_shown = r.auto_disarmed_at.len();
        if r.crashed.is_some() {
            return false;
        }
        // --exit-after-flight: flown, disarmed again, and two heartbeats later (1 Hz) so that
        // the controller has seen the disarm.
        if r.first_liftoff.is_none() || v.commander().armed() {
            self.disarmed_since = None;
            return true;
        }
        let since = *self.disarmed_since.get_or_insert(v.time());
        !(exit_after_flight && v.time() - since > 2.1)
    }
}

pub(crate) fn sitl(args: &SitlArgs) -> ExitCode {
    let cfg = match vehicle_config(args) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let link = match open_as_px4(&args.connect, args.signing_key.as_deref()) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let mut vehicle = SimVehicle::new(cfg);
    let stop = interrupt_flag();
    if !args.json {
        announce(&vehicle, args);
    }
    let duration = args.duration.unwrap_or(f64::INFINITY);
    let mut progress = Progress::default();
    px4_sim::vehicle::serve_with(&link, &mut vehicle, duration, &stop, |v| {
        progress.on_tick(v, args.json, args.exit_after_flight)
    });
    sitl_summary(&vehicle, &args.vehicle, args.json)
}

/// The summary as one JSON object.
fn summary_json(vehicle: &SimVehicle, airframe: &str) -> serde_json::Value {
    let r = vehicle.record();
    let cfg = vehicle.config();
    let v3 = |p: &mpc_mission::nalgebra::Vector3<f64>| [p.x, p.y, p.z];
    serde_json::json!({
        "vehicle": airframe,
        "clock_rate": cfg.clock_rate,
        "clock_jump": cfg.clock_jump.map(|j| serde_json::json!({"at_s": j.at, "by_s": j.by})),
        "time_s": r.time,
        "crashed": r.crashed,
        "crash_time_s": r.crash_time,
        "airborne_time_s": r.airborne_time,
        "first_liftoff_s": r.first_liftoff,
        "max_height_m": r.max_height,
        "offboard_pitch_rotation_rad": r.offboard_pitch_rotation,
        "offboard_max_pitch_rate_rad_s": r.offboard_max_pitch_rate,
        "touchdowns": r.touchdowns.iter().map(|t| serde_json::json!({
            "time_s": t.time,
            "vertical_speed_m_s": t.vertical_speed,
            "position_m": v3(&t.position),
            "estimated_height_m": t.estimated_height,
        })).collect::<Vec<_>>(),
        "mode_changes": r.mode_changes.iter().map(|m| serde_json::json!({
            "time_s": m.time,
            "from": m.from.to_string(),
            "to": m.to.to_string(),
            "failsafe": m.failsafe,
        })).collect::<Vec<_>>(),
        "armed_at_s": r.armed_at,
        "disarmed_at_s": r.disarmed_at,
        "auto_disarmed_at_s": r.auto_disarmed_at,
        "armed": vehicle.commander().armed(),
        "mode": vehicle.commander().mode().to_string(),
        "offboard_loss_failsafe_at_s": vehicle.commander().failsafe_at(),
        "height_bias_m": r.height_bias,
        "final_position_m": v3(&r.final_position),
    })
}

fn sitl_summary(vehicle: &SimVehicle, airframe: &str, json: bool) -> ExitCode {
    let r = vehicle.record();
    if json {
        println!("{}", summary_json(vehicle, airframe));
    } else {
        for line in r.summary_lines() {
            println!("sitl: {line}");
        }
    }
    if r.crashed.is_some() {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
