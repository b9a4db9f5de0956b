#!/usr/bin/env python3
"""An excerpt of a PX4 SITL (SIH) flight log: the rate and thrust setpoints and SIH's true rates.

    python3 scripts/px4_stock_excerpt.py LOG.ulg OUT_PREFIX [--start S] [--duration S] [--lag]

Writes OUT_PREFIX_setpoints.csv and OUT_PREFIX_truth.csv for the time from --start to
--start + --duration (seconds since PX4's boot, the log's clock). The default start is a flip's:
0.25 s before SIH's true pitch rate first exceeds 5 rad/s (ONSET_RAD_S, LEAD_IN_S), for 1.7 s,
from the last full-thrust climb through the flip and the recovery. firmware-shim/tests/vehicle.rs
replays the excerpts of firmware-shim/tests/data/ (its README.md names their logs) through the
simulated stock vehicle.

- setpoints: `vehicle_rates_setpoint` as logged (PX4's default logging profile samples it about
  every 20 ms; `mpcc fly` sends 100 Hz, so a value was in force from 0 to 10 ms before its
  logged timestamp): t [s], roll, pitch, yaw [rad/s, FRD], thrust (normalized, 0..1:
  -thrust_body[2]). Includes the last sample before the start.
- truth: `vehicle_angular_velocity_groundtruth` (SIH's own state, logged every 8 ms):
  t [s] (timestamp_sample), wx, wy, wz [rad/s, FRD].

With --lag it also prints how far EKF2's attitude (`vehicle_attitude`, what PX4's ODOMETRY
carries) lags SIH's true one (`vehicle_attitude_groundtruth`) over the excerpt: the RMS angle
between them with the truth delayed by -10 to 10 ms, and the delay where it is least.

Exit status: 0 when written, 2 for a file that cannot be read or lacks a topic.
"""

import argparse
import csv
import sys

try:
    import numpy as np
    from pyulog import ULog
except ImportError as e:  # pragma: no cover
    sys.exit(f"numpy and pyulog are needed: {e}")

SETPOINTS = "vehicle_rates_setpoint"
TRUTH = "vehicle_angular_velocity_groundtruth"
ATTITUDE = "vehicle_attitude"
ONSET_RAD_S = 5.0
LEAD_IN_S = 0.25
TRUE_ATTITUDE = "vehicle_attitude_groundtruth"


def topic(ulog, name):
    """The data of topic `name` (its first instance)."""
    try:
        return ulog.get_dataset(name).data
    except (KeyError, IndexError, ValueError) as e:
        raise LookupError(f"{name}: not in the log ({e})") from e


def flip_start(truth):
    """LEAD_IN_S before SIH's true pitch rate first exceeds ONSET_RAD_S."""
    for t, w in zip(truth["timestamp_sample"], truth["xyz[1]"]):
        if abs(w) > ONSET_RAD_S:
            return t * 1e-6 - LEAD_IN_S
    raise LookupError(f"the pitch rate never exceeds {ONSET_RAD_S} rad/s: no flip")


def setpoint_rows(data, start, end):
    """Rows t, roll, pitch, yaw, thrust from the last sample before `start` to `end`."""
    times = [t * 1e-6 for t in data["timestamp"]]
    first = max((i for i, t in enumerate(times) if t <= start), default=0)
    return [
        [times[i], data["roll"][i], data["pitch"][i], data["yaw"][i], -data["thrust_body[2]"][i]]
        for i in range(first, len(times))
        if times[i] <= end
    ]


def truth_rows(data, start, end):
    """Rows t, wx, wy, wz within [start, end]."""
    times = [t * 1e-6 for t in data["timestamp_sample"]]
    return [
        [t, data["xyz[0]"][i], data["xyz[1]"][i], data["xyz[2]"][i]]
        for i, t in enumerate(times)
        if start <= t <= end
    ]


def quaternions(data):
    """Times [s] (timestamp_sample) and unit quaternions (w, x, y, z) of an attitude topic."""
    t = np.asarray(data["timestamp_sample"], dtype=float) * 1e-6
    q = np.stack([np.asarray(data[f"q[{i}]"], dtype=float) for i in range(4)], axis=1)
    return t, q / np.linalg.norm(q, axis=1)[:, None]


def interpolate(t, times, q):
    """Quaternions `q` at `times`, linearly interpolated (same hemisphere) at `t`."""
    i = np.clip(np.searchsorted(times, t), 1, len(times) - 1)
    a, b = q[i - 1], q[i]
    b = b * np.sign(np.sum(a * b, axis=1))[:, None]
    f = ((t - times[i - 1]) / (times[i] - times[i - 1]))[:, None]
    m = a * (1 - f) + b * f
    return m / np.linalg.norm(m, axis=1)[:, None]


def attitude_lag(ulog, start, end):
    """(lag [ms], RMS angle [rad]) of EKF2's attitude against the truth delayed by each lag."""
    t_est, q_est = quaternions(topic(ulog, ATTITUDE))
    t_true, q_true = quaternions(topic(ulog, TRUE_ATTITUDE))
    inside = (t_est >= start) & (t_est <= end)
    out = []
    for lag_ms in range(-10, 11):
        q = interpolate(t_est[inside] - lag_ms * 1e-3, t_true, q_true)
        dot = np.abs(np.sum(q * q_est[inside], axis=1)).clip(0.0, 1.0)
        out.append((lag_ms, float(np.sqrt(np.mean((2.0 * np.arccos(dot)) ** 2)))))
    return out


def print_lag(rows):
    best = min(rows, key=lambda r: r[1])
    by_lag = dict(rows)
    print(
        f"EKF2 attitude vs SIH truth: least RMS {best[1]:.4f} rad at {best[0]:+d} ms; "
        f"{by_lag[0]:.4f} rad at 0 ms, {by_lag[5]:.4f} rad at +5 ms"
    )


def write(path, header, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        for r in rows:
            w.writerow([f"{r[0]:.6f}"] + [f"{float(x):.6g}" for x in r[1:]])


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("out_prefix")
    ap.add_argument("--start", type=float, help="default: the flip's (see above)")
    ap.add_argument("--duration", type=float, default=1.7)
    ap.add_argument("--lag", action="store_true", help="print EKF2's attitude lag")
    args = ap.parse_args(argv)
    try:
        ulog = ULog(args.log, [SETPOINTS, TRUTH, ATTITUDE, TRUE_ATTITUDE])
        start = args.start if args.start is not None else flip_start(topic(ulog, TRUTH))
        end = start + args.duration
        sp = setpoint_rows(topic(ulog, SETPOINTS), start, end)
        truth = truth_rows(topic(ulog, TRUTH), start, end)
        if args.lag:
            print_lag(attitude_lag(ulog, start, end))
    except (OSError, LookupError, ValueError) as e:
        print(f"{args.log}: {e}", file=sys.stderr)
        return 2
    write(f"{args.out_prefix}_setpoints.csv", ["t", "roll", "pitch", "yaw", "thrust"], sp)
    write(f"{args.out_prefix}_truth.csv", ["t", "wx", "wy", "wz"], truth)
    print(f"{len(sp)} setpoints, {len(truth)} true rates, {start:.3f} to {end:.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
