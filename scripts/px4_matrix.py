#!/usr/bin/env python3
"""Fly the mission x vehicle x speed-factor matrix against the real PX4 SITL, judge every run
by the simulator's ground truth (scripts/px4_groundtruth.py), print a markdown table.

    python3 scripts/px4_matrix.py [-n N] [options] [-- extra mpcc fly args]

Run it from the repository root with a built target/release/mpcc; PX4 is ../shared/px4-sitl/
(relative to the repository root); PX4 instance i listens on 14580+i, sends to 14540+i and is
MAVLink system i+1. Defaults: missions hover, flip; vehicles stock, agile;
speed factors 0.9, 1.0, 1.1; 10 runs each; PX4 instances 1 and 2 (at most two PX4 at once).
Every run keeps its PX4 log, flight log, mpcc output and verdict under one temporary
directory (printed at the start and the end; --out to choose it).

A run's ground-truth success: no crash, airborne (above 0.5 m for more than 1 s), back on the
ground, PX4 shows it landed and disarmed, and for the flip |pitch rotation in OFFBOARD| within
2*pi +- 0.6 rad. A false success is a run where mpcc exited 0 but the ground truth says fail.
A run where PX4 itself failed (its simulated barometer, magnetometer and GPS stopped while the
log went on: PX4 SITL does this in about 1 run in 50, at arming) and mpcc did not claim
success is flown again, at most twice; the table counts these PX4 faults in their own column
(their logs stay, named <run>-again<k> for the flights after them).

Vehicles (PX4 parameters at boot) and their extra mpcc fly arguments:
- stock: PX4's SIH quadrotor (1 kg, T/W 2, about 80 rad/s^2 of pitch authority).
- agile: T/W 4, about 390 rad/s^2 of pitch authority, 30 ms rotors, MPC_THR_HOVER 0.25.
Per-vehicle mpcc arguments: --stock-args "..." / --agile-args "..." (or the environment
variables MPCC_FLY_ARGS_STOCK / MPCC_FLY_ARGS_AGILE); arguments after `--` go to every run.
"""

import argparse
import json
import math
import os
import queue
import shlex
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SITL = os.path.join(ROOT, "..", "shared", "px4-sitl")
JUDGE = os.path.join(ROOT, "scripts", "px4_groundtruth.py")

VEHICLES = {
    "stock": {},
    "agile": {
        "SIH_MASS": "1.0", "SIH_T_MAX": "10.0", "SIH_IXX": "0.01", "SIH_IYY": "0.01",
        "SIH_L_ROLL": "0.2", "SIH_L_PITCH": "0.2", "SIH_T_TAU": "0.03",
        "MPC_THR_HOVER": "0.25",
    },
}
VEHICLE_ARGS = {
    "stock": os.environ.get("MPCC_FLY_ARGS_STOCK", ""),
    "agile": os.environ.get("MPCC_FLY_ARGS_AGILE", ""),
}

# A run whose PX4 failed on its own (its simulated sensors stopped: px4_groundtruth.py's
# px4_sensor_stall) says nothing about mpcc; it is flown again, at most this often.
PX4_FAULT_RETRIES = 2
RUNNING = set()  # PX4 PIDs and mpcc Popen objects this script started, for Ctrl-C
RUNNING_LOCK = threading.Lock()
STOP = threading.Event()  # set on Ctrl-C: start no more runs


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("-n", type=int, default=10, help="runs per cell (default 10)")
    p.add_argument("--missions", default="hover,flip")
    p.add_argument("--vehicles", default="stock,agile")
    p.add_argument("--speeds", default="0.9,1.0,1.1", help="PX4_SIM_SPEED_FACTOR values")
    p.add_argument("--instances", default="1,2", help="PX4 instances (at most two)")
    p.add_argument("--mpcc", default=os.path.join(ROOT, "target", "release", "mpcc"))
    p.add_argument("--timeout", type=float, default=120.0, help="mpcc fly --timeout [s]")
    p.add_argument("--stock-args", default=None, help="extra mpcc fly args for stock")
    p.add_argument("--agile-args", default=None, help="extra mpcc fly args for agile")
    p.add_argument("--out", default=None, help="directory for the logs (default: a temp dir)")
    p.add_argument("extra", nargs="*", help="after --: extra mpcc fly args for every run")
    args = p.parse_args(argv)
    for vehicle in ("stock", "agile"):
        given = getattr(args, f"{vehicle}_args")
        if given is not None:
            VEHICLE_ARGS[vehicle] = given
    args.instances = [int(i) for i in args.instances.split(",") if i]
    if not 1 <= len(args.instances) <= 2:
        p.error("--instances: one or two PX4 instances")
    for v in args.vehicles.split(","):
        if v not in VEHICLES:
            p.error(f"unknown vehicle {v} (known: {', '.join(VEHICLES)})")
    return args


def check_prerequisites(args):
    problems = []
    if not os.path.isfile(os.path.join(SITL, "run.sh")):
        problems.append("../shared/px4-sitl/run.sh not found (relative to the repository root)")
    if not os.access(args.mpcc, os.X_OK):
        problems.append(f"{args.mpcc} not built (cargo build --release)")
    if subprocess.run([sys.executable, "-c", "import pyulog"], capture_output=True).returncode:
        problems.append("pyulog missing (python3 -m pip install pyulog==1.3.0)")
    for p in problems:
        print(f"px4_matrix: {p}", file=sys.stderr)
    return not problems


def track(item, add):
    with RUNNING_LOCK:
        (RUNNING.add if add else RUNNING.discard)(item)


def start_px4(workdir, instance, vehicle, speed):
    """Starts PX4 in workdir; returns its PID once it is ready for takeoff."""
    env = dict(os.environ, PX4_INSTANCE=str(instance), PX4_SIM_SPEED_FACTOR=speed)
    env.update({f"PX4_PARAM_{k}": v for k, v in VEHICLES[vehicle].items()})
    out = subprocess.run([os.path.join(SITL, "run.sh"), workdir], env=env,
                         capture_output=True, text=True)
    pid = out.stdout.strip()
    if out.returncode or not pid:
        raise RuntimeError(f"run.sh failed: {out.stderr.strip()}")
    track(pid, True)
    log = os.path.join(workdir, "px4.log")
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        with open(log, errors="replace") as f:
            if "Ready for takeoff!" in f.read():
                return pid
        time.sleep(0.1)
    stop_px4(pid)
    raise RuntimeError(f"PX4 not ready for takeoff in 30 s (see {log})")


def stop_px4(pid):
    subprocess.run([os.path.join(SITL, "stop.sh"), pid], capture_output=True)
    track(pid, False)


def port_free(port):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


def fly(args, run_dir, instance, job):
    """Runs mpcc fly; returns its exit code (None: killed after the timeout)."""
    cmd = [args.mpcc, "fly", "--connect", f"udpin:127.0.0.1:{14540 + instance}",
           "--mission", job["mission"], "--json", "--no-plots", "--timeout", str(args.timeout)]
    cmd += shlex.split(VEHICLE_ARGS[job["vehicle"]]) + args.extra
    with open(os.path.join(run_dir, "mpcc.out"), "w") as out, \
            open(os.path.join(run_dir, "mpcc.err"), "w") as err:
        err.write(shlex.join(cmd) + "\n")
        err.flush()
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=out, stderr=err)
        track(proc, True)
        try:
            return proc.wait(timeout=args.timeout + 60.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            return None
        finally:
            track(proc, False)


def judge(workdir):
    """The ground truth of the run's flight log (or {"error": ...})."""
    logs = sorted(os.path.join(d, f) for d, _, fs in os.walk(os.path.join(workdir, "log"))
                  for f in fs if f.endswith(".ulg"))
    if not logs:
        return {"error": "no flight log"}
    out = subprocess.run([sys.executable, JUDGE, logs[-1], "--json"],
                         capture_output=True, text=True)
    if out.returncode:
        return {"error": out.stderr.strip()}
    return json.loads(out.stdout)


def truth_ok(mission, truth):
    """Whether the ground truth shows a successful flight (see the docstring)."""
    if "error" in truth or truth["crashed"]:
        return False
    flown = truth["max_height_m"] > 0.5 and truth["airborne_s"] > 1.0
    home = bool(truth["touchdowns"]) and truth["final"]["landed"] and not truth["final"]["armed"]
    flip = abs(abs(truth["pitch_rotation_offboard_rad"]) - 2 * math.pi) <= 0.6
    return flown and home and (mission != "flip" or flip)


def run_one(args, job, instances):
    """One run, flown again (up to PX4_FAULT_RETRIES times) when PX4 itself failed: its
    simulated sensors stopped (the truth's px4_sensor_stall) and mpcc did not claim success.
    A claimed success is never flown again. The faulted attempts are kept and counted."""
    faults = []
    for attempt in range(PX4_FAULT_RETRIES + 1):
        name = job["name"] if attempt == 0 else f"{job['name']}-again{attempt}"
        result = run_attempt(args, dict(job, name=name), instances)
        if result["claimed"] or not result["truth"].get("px4_sensor_stall"):
            break
        faults.append(name)
    result["px4_faults"] = faults
    return result


def run_attempt(args, job, instances):
    """One flight on a free PX4 instance: start, fly, stop, judge."""
    instance = instances.get()
    if STOP.is_set():
        instances.put(instance)
        return dict(job, instance=instance, rc=None, truth={"error": "interrupted"},
                    claimed=False, ok=False)
    run_dir = os.path.join(args.out, job["name"])
    os.makedirs(run_dir, exist_ok=True)
    result = dict(job, instance=instance, rc=None, truth={})
    try:
        if not port_free(14540 + instance):
            raise RuntimeError(f"UDP port {14540 + instance} in use")
        pid = start_px4(run_dir, instance, job["vehicle"], job["speed"])
        try:
            result["rc"] = fly(args, run_dir, instance, job)
        finally:
            stop_px4(pid)
        result["truth"] = judge(run_dir)
    except Exception as e:  # a broken run is reported, the matrix goes on
        result["truth"] = {"error": str(e)}
    finally:
        instances.put(instance)
    result["claimed"] = result["rc"] == 0
    result["ok"] = truth_ok(job["mission"], result["truth"])
    with open(os.path.join(run_dir, "result.json"), "w") as f:
        json.dump(result, f, indent=1)
    print(progress_line(result), file=sys.stderr, flush=True)
    return result


def progress_line(r):
    t = r["truth"]
    verdict = "OK" if r["ok"] else ("CRASH" if t.get("crashed") else "FAIL")
    if t.get("px4_sensor_stall") and not r["claimed"]:
        stall = t["px4_sensor_stall"]
        verdict += f" (PX4 FAULT: {', '.join(stall['topics'])} stopped at {stall['at_s']} s)"
    if r["claimed"] and not r["ok"]:
        verdict += " (FALSE SUCCESS)"
    detail = t.get("error") or "; ".join(t.get("crash_reasons", [])) or (
        f"max height {t.get('max_height_m')} m, rotation {t.get('pitch_rotation_offboard_rad')}"
        " rad")
    return f"{r['name']}: mpcc exit {r['rc']}, truth {verdict}: {detail}"


def median(values):
    values = [v for v in values if v is not None]
    return f"{statistics.median(values):.2f}" if values else "-"


def table(results, args):
    lines = [
        "| mission | vehicle | speed factor | runs | mpcc success claimed | ground-truth success"
        " | false successes | crashes | PX4 faults flown again | median max height [m]"
        " | median flip rotation [rad] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for mission in args.missions.split(","):
        for vehicle in args.vehicles.split(","):
            for speed in args.speeds.split(","):
                cell = [r for r in results if (r["mission"], r["vehicle"], r["speed"])
                        == (mission, vehicle, speed)]
                truths = [r["truth"] for r in cell]
                lines.append("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |".format(
                    mission, vehicle, speed, len(cell),
                    sum(r["claimed"] for r in cell), sum(r["ok"] for r in cell),
                    sum(r["claimed"] and not r["ok"] for r in cell),
                    sum(bool(t.get("crashed")) for t in truths),
                    sum(len(r.get("px4_faults", [])) for r in cell),
                    median(t.get("max_height_m") for t in truths),
                    median(t.get("pitch_rotation_offboard_rad") for t in truths)
                    if mission == "flip" else "-"))
    return "\n".join(lines)


def jobs(args):
    out = []
    for mission in args.missions.split(","):
        for vehicle in args.vehicles.split(","):
            for speed in args.speeds.split(","):
                for i in range(1, args.n + 1):
                    name = f"{mission}-{vehicle}-{speed}-{i:02d}"
                    out.append({"name": name, "mission": mission, "vehicle": vehicle,
                                "speed": speed, "run": i})
    return out


def stop_everything():
    """Ctrl-C: stop the mpcc processes and PX4 instances this script started."""
    with RUNNING_LOCK:
        items = list(RUNNING)
    for item in items:
        if isinstance(item, subprocess.Popen):
            item.kill()
        else:
            subprocess.run([os.path.join(SITL, "stop.sh"), item], capture_output=True)


def main(argv):
    args = parse_args(argv)
    if not check_prerequisites(args):
        return 2
    args.out = os.path.abspath(args.out or tempfile.mkdtemp(prefix="px4-matrix."))
    os.makedirs(args.out, exist_ok=True)
    todo = jobs(args)
    print(f"px4_matrix: {len(todo)} runs on PX4 instances {args.instances}; logs in {args.out}",
          file=sys.stderr, flush=True)
    instances = queue.Queue()
    for i in args.instances:
        instances.put(i)
    pool = ThreadPoolExecutor(max_workers=len(args.instances))
    try:
        results = list(pool.map(lambda j: run_one(args, j, instances), todo))
    except KeyboardInterrupt:
        STOP.set()
        pool.shutdown(wait=False, cancel_futures=True)
        stop_everything()
        print(f"px4_matrix: interrupted; logs in {args.out}", file=sys.stderr)
        return 130
    pool.shutdown()
    text = table(results, args)
    with open(os.path.join(args.out, "table.md"), "w") as f:
        f.write(text + "\n")
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    print(text)
    print(f"\nlogs, flight logs and verdicts: {args.out} (table.md, results.json)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
