#!/usr/bin/env python3
"""The true flight in a PX4 SITL (SIH) flight log: a judge that does not trust the controller.

    python3 scripts/px4_groundtruth.py LOG.ulg [--json]

PX4 (../shared/px4-sitl/, logger mode=all, logging from boot) writes WORKDIR/log/<date>/<time>.ulg.
With SIH the log holds the simulator's ground truth, which this script reads:
`vehicle_local_position_groundtruth` (NED x, y, z, vx, vy, vz), `vehicle_attitude_groundtruth`
(q = w, x, y, z, FRD body to NED), `vehicle_angular_velocity_groundtruth` (FRD body rates), and
PX4's own view: `vehicle_status` (nav_state, arming_state), `vehicle_land_detected` and
`vehicle_local_position` (EKF2's estimate). It prints one JSON object (indented; one line with
--json). Times are seconds since PX4's boot (the log's timestamps: the simulated clock).

Definitions and thresholds:
- Height: -z above the ground-truth start height (the median z of the first 0.5 s of the log).
  SIH's ground is at its reference altitude, which is the start height.
- Airborne: height > 0.3 m (AIRBORNE_M); `airborne_s` is the time spent so.
- Ground contact: height < 0.1 m (GROUND_M). SIH's ground only pushes back while the net
  force points down, so a vehicle still braking (thrust above weight) sinks below the start
  height; each touchdown's `lowest_height_m` shows how far (a real ground would have stopped it).
- Touchdown: the first ground contact after being airborne, at `t`; it comes to rest at
  `rest_t`, the first sample from there with |vz| < 0.2 m/s (STILL_M_S), at most 1 s
  (SETTLE_S) later. Its impact speed is the largest downward speed (NED vz) from 0.3 s
  (IMPACT_WINDOW_S) before `t` to `rest_t`; its tilt the largest from `t` to `rest_t`; its
  position and EKF2 height error are taken at `rest_t`.
- Tilt: the angle between the body z axis and the down axis (0 upright, 180 upside down);
  inverted intervals are where tilt > 90 deg.
- Crash (any of): a touchdown faster than 2.0 m/s (CRASH_SPEED_M_S); tilt > 60 deg
  (CRASH_TILT_DEG) at a touchdown or at any time in ground contact (before take-off too); the
  log ending in ground contact with tilt > 30 deg (UPRIGHT_DEG, "not upright").
- Pitch rotation: the trapezoid integral of the true FRD pitch rate over the OFFBOARD intervals
  (nav_state 14); one clean flip is about 2*pi rad (less where the flip also rolls or yaws).
- EKF2 height error at a touchdown: -vehicle_local_position.z (EKF2) minus the true height,
  at rest (EKF2's local origin is where it initialised: the error at the start is reported).

Exit status: 0 when parsed, 2 for a file that cannot be read or lacks a topic.
"""

import json
import math
import sys

try:
    import numpy as np
    from pyulog import ULog
except ImportError as _e:  # reported by load(), with exit status 2
    np = ULog = None
    IMPORT_ERROR = _e

AIRBORNE_M = 0.3
GROUND_M = 0.1
STILL_M_S = 0.2
IMPACT_WINDOW_S = 0.3
SETTLE_S = 1.0
CRASH_SPEED_M_S = 2.0
CRASH_TILT_DEG = 60.0
UPRIGHT_DEG = 30.0
START_WINDOW_S = 0.5

OFFBOARD = 14
ARMED = 2  # vehicle_status.arming_state: 1 disarmed, 2 armed
NAV_STATES = {
    0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "AUTO.MISSION", 4: "AUTO.LOITER",
    5: "AUTO.RTL", 6: "POSITION_SLOW", 10: "ACRO", 12: "DESCEND", 13: "TERMINATION",
    14: "OFFBOARD", 15: "STAB", 17: "AUTO.TAKEOFF", 18: "AUTO.LAND",
    19: "AUTO.FOLLOW_TARGET", 20: "AUTO.PRECLAND", 21: "ORBIT", 22: "AUTO.VTOL_TAKEOFF",
}
TOPICS = {
    "vehicle_local_position_groundtruth": ["x", "y", "z", "vx", "vy", "vz"],
    "vehicle_attitude_groundtruth": ["q[0]", "q[1]", "q[2]", "q[3]"],
    "vehicle_angular_velocity_groundtruth": ["xyz[0]", "xyz[1]", "xyz[2]"],
    "vehicle_status": ["nav_state", "arming_state"],
    "vehicle_land_detected": ["landed"],
    "vehicle_local_position": ["z"],
}
# PX4's simulated sensors besides the IMU: when they stop publishing while the log goes on,
# PX4 itself has failed (its estimator loses height, heading and position), not the flight
# controller it was flying for.
SIM_SENSORS = ["sensor_baro", "sensor_mag", "sensor_gps"]
SENSOR_STALL_S = 2.0


class LogError(Exception):
    """A log that cannot be judged (unreadable, or a topic missing)."""


def load(path):
    """The needed topics as {topic: {field: numpy array, "t": seconds}}."""
    if ULog is None:
        raise LogError(f"pyulog is not installed (pip install pyulog==1.3.0): {IMPORT_ERROR}")
    try:
        ulog = ULog(path, list(TOPICS) + SIM_SENSORS)
    except Exception as e:  # pyulog raises plain exceptions on a bad file
        raise LogError(f"cannot read {path} as a ULog: {e}") from e
    topics = {}
    for name, fields in TOPICS.items():
        found = [d for d in ulog.data_list if d.name == name and d.multi_id == 0]
        if not found or len(found[0].data["timestamp"]) == 0:
            raise LogError(f"{path}: topic {name} missing (is this an SIH log, logger mode=all?)")
        data = found[0].data
        missing = [f for f in fields if f not in data]
        if missing:
            raise LogError(f"{path}: topic {name} lacks fields {missing}")
        topics[name] = {f: data[f].astype(float) for f in fields}
        topics[name]["t"] = data["timestamp"].astype(float) / 1e6
    for name in SIM_SENSORS:
        found = [d for d in ulog.data_list if d.name == name and d.multi_id == 0]
        if found and len(found[0].data["timestamp"]):
            topics[name] = {"t": found[0].data["timestamp"].astype(float) / 1e6}
    return topics


def sensor_stall(topics, t_start, t_end):
    """PX4's simulated sensors that stopped more than SENSOR_STALL_S before the log's end:
    {"at_s": when the first stopped (log time), "topics": [...]}, or None."""
    stopped = {name: float(topics[name]["t"][-1]) for name in SIM_SENSORS
               if name in topics and t_end - topics[name]["t"][-1] > SENSOR_STALL_S}
    if not stopped:
        return None
    return {"at_s": round(min(stopped.values()) - t_start, 3), "topics": sorted(stopped)}


def intervals(t, mask, t_end):
    """[[t0, t1], ...] where the step signal `mask` (sampled at t, held until the next sample)
    is true; the last sample holds until t_end."""
    out = []
    start = None
    for ti, m in zip(t, mask):
        if m and start is None:
            start = ti
        elif not m and start is not None:
            out.append([round(start, 3), round(ti, 3)])
            start = None
    if start is not None:
        out.append([round(start, 3), round(t_end, 3)])
    return out


def mode_sequence(status):
    """The nav_state changes: [{t, nav_state, name}]."""
    out = []
    for t, s in zip(status["t"], status["nav_state"]):
        s = int(s)
        if not out or out[-1]["nav_state"] != s:
            out.append({"t": round(t, 3), "nav_state": s, "name": NAV_STATES.get(s, f"NAV_{s}")})
    return out


def tilt_deg(att):
    """Tilt of each attitude sample [deg]: acos of the body z axis' down component."""
    qx, qy = att["q[1]"], att["q[2]"]
    return np.degrees(np.arccos(np.clip(1.0 - 2.0 * (qx * qx + qy * qy), -1.0, 1.0)))


def trapezoid(y, x):
    """The trapezoid integral of y over x (numpy 1 and 2 alike)."""
    return np.sum((y[1:] + y[:-1]) * np.diff(x)) / 2.0


def pitch_rotation(rates, spans):
    """Trapezoid integral of the FRD pitch rate inside the spans, and the peak |rate| there."""
    t, wy = rates["t"], rates["xyz[1]"]
    total, peak = 0.0, 0.0
    for t0, t1 in spans:
        m = (t >= t0) & (t <= t1)
        if m.sum() >= 2:
            total += float(trapezoid(wy[m], t[m]))
            peak = max(peak, float(np.max(np.abs(wy[m]))))
    return total, peak


def start_height_z(pos):
    """The ground-truth start z: the median over the first START_WINDOW_S of the log."""
    t = pos["t"]
    return float(np.median(pos["z"][t <= t[0] + START_WINDOW_S]))


def touchdowns(pos, height, tilt, ekf):
    """Every first ground contact after being airborne (see the module docstring), and the
    ground-contact mask."""
    contact = height < GROUND_M
    out, airborne = [], False
    for i in range(len(height)):
        if height[i] > AIRBORNE_M:
            airborne = True
        elif airborne and contact[i]:
            airborne = False
            out.append(touchdown(pos, height, tilt, ekf, i))
    return out, contact


def touchdown(pos, height, tilt, ekf, i):
    """The touchdown whose ground contact begins at sample i."""
    t, vz = pos["t"], pos["vz"]
    rest = i
    while (rest + 1 < len(t) and abs(vz[rest]) >= STILL_M_S
           and t[rest + 1] <= t[i] + SETTLE_S and height[rest + 1] <= AIRBORNE_M):
        rest += 1
    episode = i
    while episode + 1 < len(t) and height[episode + 1] <= AIRBORNE_M:
        episode += 1
    window = (t >= t[i] - IMPACT_WINDOW_S) & (t <= t[rest])
    ekf_h = -float(np.interp(t[rest], ekf["t"], ekf["z"]))
    return {
        "t": round(float(t[i]), 3),
        "rest_t": round(float(t[rest]), 3),
        "impact_speed_m_s": round(max(0.0, float(np.max(vz[window]))), 3),
        "tilt_deg": round(float(np.max(tilt[i:rest + 1])), 1),
        "x_m": round(float(pos["x"][rest]), 3),
        "y_m": round(float(pos["y"][rest]), 3),
        "lowest_height_m": round(float(np.min(height[i:episode + 1])), 3),
        "estimator_height_error_m": round(ekf_h - float(height[rest]), 3),
    }


def crash_reasons(tds, contact, tilt, t):
    """Why the flight counts as a crash (empty: it does not)."""
    reasons = []
    for td in tds:
        if td["impact_speed_m_s"] > CRASH_SPEED_M_S:
            reasons.append(f"touchdown at {td['t']} s at {td['impact_speed_m_s']} m/s "
                           f"(> {CRASH_SPEED_M_S} m/s)")
        if td["tilt_deg"] > CRASH_TILT_DEG:
            reasons.append(f"touchdown at {td['t']} s tilted {td['tilt_deg']} deg "
                           f"(> {CRASH_TILT_DEG} deg)")
    on_ground_tilted = contact & (tilt > CRASH_TILT_DEG)
    if on_ground_tilted.any():
        first = float(t[on_ground_tilted][0])
        worst = float(tilt[on_ground_tilted].max())
        reasons.append(f"on the ground tilted {worst:.1f} deg (> {CRASH_TILT_DEG} deg) "
                       f"from {first:.3f} s")
    if contact[-1] and tilt[-1] > UPRIGHT_DEG:
        reasons.append(f"ended on the ground not upright (tilt {tilt[-1]:.1f} deg "
                       f"> {UPRIGHT_DEG} deg)")
    return reasons


def final_state(topics, height, tilt):
    """Where and how the log ends."""
    pos = topics["vehicle_local_position_groundtruth"]
    return {
        "t": round(float(pos["t"][-1]), 3),
        "x_m": round(float(pos["x"][-1]), 3),
        "y_m": round(float(pos["y"][-1]), 3),
        "z_m": round(float(pos["z"][-1]), 3),
        "height_m": round(float(height[-1]), 3),
        "tilt_deg": round(float(tilt[-1]), 1),
        "armed": bool(topics["vehicle_status"]["arming_state"][-1] == ARMED),
        "landed": bool(topics["vehicle_land_detected"]["landed"][-1]),
    }


def airborne_seconds(t, height):
    """Time spent above AIRBORNE_M (each sample held until the next)."""
    dt = np.diff(t, append=t[-1])
    return float(np.sum(dt[height > AIRBORNE_M]))


def judge(topics):
    """The JSON-ready verdict on the flight."""
    pos = topics["vehicle_local_position_groundtruth"]
    att = topics["vehicle_attitude_groundtruth"]
    status = topics["vehicle_status"]
    t_end = float(max(pos["t"][-1], att["t"][-1], status["t"][-1]))
    z0 = start_height_z(pos)
    height = z0 - pos["z"]
    tilt_att = tilt_deg(att)
    tilt = np.interp(pos["t"], att["t"], tilt_att)
    offboard = intervals(status["t"], status["nav_state"] == OFFBOARD, t_end)
    rotation, peak = pitch_rotation(topics["vehicle_angular_velocity_groundtruth"], offboard)
    tds, contact = touchdowns(pos, height, tilt, topics["vehicle_local_position"])
    reasons = crash_reasons(tds, contact, tilt, pos["t"])
    ekf0 = -float(np.interp(pos["t"][0], topics["vehicle_local_position"]["t"],
                            topics["vehicle_local_position"]["z"]))
    return {
        "log_duration_s": round(t_end - float(pos["t"][0]), 3),
        "start_z_m": round(z0, 4),
        "armed_intervals": intervals(status["t"], status["arming_state"] == ARMED, t_end),
        "offboard_intervals": offboard,
        "modes": mode_sequence(status),
        "max_height_m": round(float(np.max(height)), 3),
        "min_height_m": round(float(np.min(height)), 3),
        "airborne_s": round(airborne_seconds(pos["t"], height), 3),
        "pitch_rotation_offboard_rad": round(rotation, 3),
        "pitch_rotation_offboard_turns": round(rotation / (2 * math.pi), 3),
        "peak_pitch_rate_rad_s": round(peak, 3),
        "max_tilt_deg": round(float(np.max(tilt_att)), 1),
        "inverted_intervals": intervals(att["t"], tilt_att > 90.0, float(att["t"][-1])),
        "touchdowns": tds,
        "crashed": bool(reasons),
        "crash_reasons": reasons,
        "final": final_state(topics, height, tilt),
        "estimator_height_error_at_start_m": round(ekf0 - float(height[0]), 3),
        "estimator_height_error_at_touchdown_m": [td["estimator_height_error_m"] for td in tds],
        "px4_sensor_stall": sensor_stall(topics, float(pos["t"][0]), t_end),
    }


def main(argv):
    args = [a for a in argv[1:] if a != "--json"]
    if len(args) != 1 or args[0].startswith("-"):
        print("usage: " + __doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    try:
        verdict = judge(load(args[0]))
    except LogError as e:
        print(f"px4_groundtruth: {e}", file=sys.stderr)
        return 2
    print(json.dumps(verdict, indent=None if "--json" in argv else 2))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
