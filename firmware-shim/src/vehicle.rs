//! The simulated PX4 vehicle: the [`crate::sitl::Commander`] around the simulator's plant
//! and PX4-like rate loop (`mpc-sim`), speaking MAVLink messages in PX4's frames. The UDP
//! endpoint (`mpcc sitl`) is the next step; this is its vehicle, stepped by the caller.
//!
//! * OFFBOARD: the last SET_ATTITUDE_TARGET flies it: FRD rates -> FLU, normalized thrust ->
//!   collective acceleration with the [`ThrustMap`] (the vehicle's hover thrust), through the
//!   1 kHz rate loop.
//! * POSCTL (hold), AUTO.LAND, AUTO.RTL: a PX4-like position controller (PD on position and
//!   velocity, thrust vector -> attitude -> body rates) holds the point where the mode began,
//!   descends at [`VehicleConfig::land_speed`], or flies home at the current height and lands.
//! * Out: PX4's HEARTBEAT (1 Hz), ODOMETRY (LOCAL_NED / LOCAL_NED, every
//!   [`VehicleConfig::odometry_period`]), EXTENDED_SYS_STATE (1 Hz), and the commander's
//!   COMMAND_ACKs.

use mavlink::dialects::common::{self as mc, MavFrame, MavLandedState, MavMessage, MavVtolState};
use mpc_sim::controller::attitude_rates;
use mpc_sim::estimator::{Estimate, Estimator, EstimatorConfig};
use mpc_sim::mission::attitude_from_thrust;
use mpc_sim::plant::{Contact, Disturbance, Plant, QuadParams, QuadState};
use mpc_sim::rate_loop::{RateController, RateGains};
use nalgebra::Vector3;

use crate::frames::{enu_to_ned, flu_to_frd, frd_to_flu, quat_enu_flu_to_ned_frd, quat_to_mavlink};
use crate::messages::Px4Mode;
use crate::setpoint::ThrustMap;
use crate::sitl::{Commander, CommanderConfig, Control, VehicleStatus};

/// Settings of the simulated vehicle.
#[derive(Clone, Debug, PartialEq)]
pub struct VehicleConfig {
    /// The commander's timing.
    pub commander: CommanderConfig,
    /// The vehicle (true and as the rate loop believes it).
    pub params: QuadParams,
    /// Estimation noise and latency of the odometry.
    pub estimator: EstimatorConfig,
    /// Noise seed.
    pub seed: u64,
    /// Where it starts, on the ground (ENU) [m]; also home for AUTO.RTL.
    pub home: Vector3<f64>,
    /// ODOMETRY period [s] (PX4 streams it at up to ~100 Hz when asked).
    pub odometry_period: f64,
    /// AUTO.LAND descent speed [m/s].
    pub land_speed: f64,
}

impl Default for VehicleConfig {
    /// The simulator's default quadrotor at the origin, motion-capture-like noise, odometry
    /// at 100 Hz, landing at 0.5 m/s.
    fn default() -> Self {
        Self {
            commander: CommanderConfig::default(),
            params: QuadParams::default(),
            estimator: EstimatorConfig::noisy(),
            seed: 0,
            home: Vector3::zeros(),
            odometry_period: 0.01,
            land_speed: 0.5,
        }
    }
}

/// The simulated PX4 vehicle.
pub struct SimVehicle {
    cfg: VehicleConfig,
    plant: Plant,
    rate: RateController,
    est: Estimator,
    commander: Commander,
    map: ThrustMap,
    t: f64,
    landed: bool,
    hold: Option<(Px4Mode, Vector3<f64>)>,
    last_odometry: Option<f64>,
    last_sys_state: Option<f64>,
}

const STEP: f64 = 0.001;

impl SimVehicle {
    /// A disarmed vehicle on the ground at `cfg.home`.
    pub fn new(cfg: VehicleConfig) -> Self {
        let p = &cfg.params;
        // The hover thrust of this vehicle as PX4 would have calibrated it: hover over the
        // maximum collective thrust (linear thrust model, as PX4's).
        let hover_thrust = p.mass * p.g / (4.0 * p.rotor_thrust_max());
        Self {
            plant: Plant::new(p.clone(), QuadState::at_rest(cfg.home)),
            rate: RateController::new(p, RateGains::default()),
            est: Estimator::new(cfg.estimator.clone(), cfg.seed),
            commander: Commander::new(cfg.commander),
            map: ThrustMap {
                hover_thrust,
                g: p.g,
            },
            t: 0.0,
            landed: true,
            hold: None,
            last_odometry: None,
            last_sys_state: None,
            cfg,
        }
    }

    /// The thrust map a client must use for this vehicle.
    pub fn thrust_map(&self) -> ThrustMap {
        self.map
    }

    /// Simulated time [s].
    pub fn time(&self) -> f64 {
        self.t
    }

    /// The true state (ENU/FLU).
    pub fn state(&self) -> &QuadState {
        self.plant.state()
    }

    /// The commander.
    pub fn commander(&self) -> &Commander {
        &self.commander
    }

    /// Whether the plant crashed.
    pub fn crashed(&self) -> bool {
        self.plant.crashed().is_some()
    }

    /// A message from the companion; returns PX4's answers.
    pub fn handle(&mut self, msg: &MavMessage) -> Vec<MavMessage> {
        self.commander.on_message(msg, self.t)
    }

    /// PX4's position controller: body rates and collective acceleration towards `p_ref`
    /// with velocity `v_ref`.
    fn position_control(
        &self,
        e: &Estimate,
        p_ref: &Vector3<f64>,
        v_ref: &Vector3<f64>,
    ) -> (Vector3<f64>, f64) {
        let (kp, kd) = (Vector3::new(2.0, 2.0, 4.0), Vector3::new(3.0, 3.0, 4.0));
        let mut a = kp.component_mul(&(p_ref - e.p)) + kd.component_mul(&(v_ref - e.v));
        // Tilt at most ~35 degrees, as PX4's MPC_TILTMAX_AIR.
        let lim = 0.7 * self.cfg.params.g;
        let h = a.xy().norm();
        if h > lim {
            a.x *= lim / h;
            a.y *= lim / h;
        }
        let f = a + Vector3::z() * self.cfg.params.g;
        let (_, _, yaw) = e.q.euler_angles();
        let qd = attitude_from_thrust(&f, yaw);
        let rates = attitude_rates(&e.q, &qd, 0.15);
        let bz = e.q * Vector3::z();
        (rates, f.dot(&bz).max(0.0))
    }

    /// Advances by `duration` seconds (1 kHz steps); returns PX4's messages of that time.
    pub fn step(&mut self, duration: f64) -> Vec<MavMessage> {
        let mut out = Vec::new();
        let steps = (duration / STEP).round().max(1.0) as usize;
        for _ in 0..steps {
            let truth = self.plant.state().clone();
            let e = self.est.update(self.t, &truth);
            let status = VehicleStatus {
                pose_valid: e.pose_valid,
                landed: self.landed,
            };
            let (control, msgs) = self.commander.tick(self.t, status);
            out.extend(msgs);
            let (rates, c) = match control {
                Control::Disarmed => {
                    self.hold = None;
                    (None, 0.0)
                }
                Control::Offboard(sp) => {
                    self.hold = None;
                    let r = sp.rates_frd.map(f64::from);
                    (
                        Some(frd_to_flu(&Vector3::new(r[0], r[1], r[2]))),
                        self.map.acceleration(f64::from(sp.thrust)),
                    )
                }
                Control::Px4(mode) => {
                    let hold = match self.hold {
                        Some((m, p)) if m == mode => p,
                        _ => {
                            let p = match mode {
                                Px4Mode::Return => Vector3::new(
                                    self.cfg.home.x,
                                    self.cfg.home.y,
                                    e.p.z.max(self.cfg.home.z + 2.0),
                                ),
                                _ => e.p,
                            };
                            self.hold = Some((mode, p));
                            p
                        }
                    };
                    let descend = match mode {
                        Px4Mode::Land => true,
                        Px4Mode::Return => (e.p.xy() - hold.xy()).norm() < 0.3,
                        _ => false,
                    };
                    let (p_ref, v_ref) = if descend {
                        let v = Vector3::new(0.0, 0.0, -self.cfg.land_speed);
                        (Vector3::new(hold.x, hold.y, e.p.z), v)
                    } else {
                        (hold, Vector3::zeros())
                    };
                    if self.landed && descend {
                        (None, 0.0)
                    } else {
                        let (r, c) = self.position_control(&e, &p_ref, &v_ref);
                        (Some(r), c)
                    }
                }
            };
            let rotor_cmd = match rates {
                Some(r) => {
                    let thrust = self.cfg.params.mass * c;
                    self.rate.update(&r, thrust, &e.w, STEP).rotor_cmd
                }
                None => {
                    self.rate.reset();
                    [0.0; 4]
                }
            };
            match self.plant.step(&rotor_cmd, &Disturbance::default(), STEP) {
                Contact::OnGround | Contact::Touchdown { .. } => self.landed = true,
                Contact::Airborne => self.landed = false,
                Contact::Crash { .. } => {}
            }
            self.t += STEP;
            if self
                .last_odometry
                .is_none_or(|t| self.t - t >= self.cfg.odometry_period - 1e-9)
            {
                self.last_odometry = Some(self.t);
                out.push(odometry(&e, self.t));
            }
            if self.last_sys_state.is_none_or(|t| self.t - t >= 1.0) {
                self.last_sys_state = Some(self.t);
                out.push(MavMessage::EXTENDED_SYS_STATE(
                    mc::EXTENDED_SYS_STATE_DATA {
                        vtol_state: MavVtolState::MAV_VTOL_STATE_UNDEFINED,
                        landed_state: if self.landed {
                            MavLandedState::MAV_LANDED_STATE_ON_GROUND
                        } else {
                            MavLandedState::MAV_LANDED_STATE_IN_AIR
                        },
                    },
                ));
            }
        }
        out
    }
}

/// ODOMETRY as PX4 sends it: LOCAL_NED position and velocity, NED->FRD attitude, FRD rates.
fn odometry(e: &Estimate, t: f64) -> MavMessage {
    let p = enu_to_ned(&e.p);
    let v = enu_to_ned(&e.v);
    let w = flu_to_frd(&e.w);
    MavMessage::ODOMETRY(mc::ODOMETRY_DATA {
        time_usec: (t * 1e6) as u64,
        x: p.x as f32,
        y: p.y as f32,
        z: p.z as f32,
        q: quat_to_mavlink(&quat_enu_flu_to_ned_frd(&e.q)),
        vx: v.x as f32,
        vy: v.y as f32,
        vz: v.z as f32,
        rollspeed: w.x as f32,
        pitchspeed: w.y as f32,
        yawspeed: w.z as f32,
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        ..mc::ODOMETRY_DATA::DEFAULT
    })
}

/// Serves `vehicle` on `link` in real time (the vehicle's clock follows the wall clock in
/// 4 ms steps, as PX4's SIH at 250 Hz) until `duration` seconds have passed or `stop` is
/// set: what arrives is handled at once, what the vehicle sends goes out as it is produced.
/// Sending before anyone has been heard on a `udpin` link fails; such messages are dropped
/// (PX4 does the same until a client appears). Returns the number of messages received.
pub fn serve(
    link: &crate::transport::Link,
    vehicle: &mut SimVehicle,
    duration: f64,
    stop: &std::sync::atomic::AtomicBool,
) -> usize {
    use std::time::{Duration, Instant};
    const TICK: f64 = 0.004;
    let start = Instant::now();
    let t0 = vehicle.time();
    let mut received = 0;
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        let now = start.elapsed().as_secs_f64();
        if now >= duration {
            break;
        }
        while let Some((_, msg)) = link.try_recv() {
            received += 1;
            for reply in vehicle.handle(&msg) {
                let _ = link.send(&reply);
            }
        }
        // Catch up with the wall clock, 4 ms at a time.
        while vehicle.time() - t0 + TICK <= now + 1e-9 {
            for m in vehicle.step(TICK) {
                let _ = link.send(&m);
            }
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    received
}
