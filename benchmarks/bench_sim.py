"""Timings of the simulator in the built-in warehouse, single thread, after compilation.

    python benchmarks/bench_sim.py [--sessions W2 W4] [--repeat N]

Rows: one 1081-beam scan (the exact beam caster against the walls, objects and people, median
over poses along the route), its noise and packing, many scans in one call, the ground-truth
map, and whole sessions (physics, people, robot, odometry, one lidar at 10 Hz; no localiser or
updater) as a multiple of real time, by wall clock and by CPU time.
"""

from __future__ import annotations

import os

for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

import sim  # noqa: E402
from sim import lidar as lid  # noqa: E402

WAREHOUSE = Path(__file__).resolve().parents[1] / "scenarios" / "aws_small_warehouse.yaml"
SCAN_BAR_MS = 1.5
SESSION_BAR_X = 50.0


def route_poses(scn, session: str) -> tuple[np.ndarray, np.ndarray]:
    """Robot poses and people (x, y, r) at every scan of a session's run."""
    world = sim.World(scn, session, seed=0)
    poses, people = [], []
    for msg in world.run():
        if isinstance(msg, sim.ScanMsg):
            poses.append(msg.true_pose.as_array())
            people.append(world.people())
    return np.array(poses), people


def scan_rows(scn, repeat: int) -> list[tuple[str, float, str]]:
    world = sim.World(scn, "W4", seed=0)
    spec = scn.robot.lidars[0]
    poses, people = route_poses(scn, "W4")
    pick = np.linspace(0, len(poses) - 1, min(repeat, len(poses))).astype(int)
    sensors = lid.sensor_poses(poses, spec.mount)
    circles = [np.concatenate([world.circles, people[i]]) for i in pick]
    lid.cast_ranges(sensors[:1], spec, world.segments, circles[0])      # compile / load
    times = []
    for k, i in enumerate(pick):
        t = time.perf_counter()
        lid.cast_ranges(sensors[i:i + 1], spec, world.segments, circles[k])
        times.append(time.perf_counter() - t)
    cast_ms = 1e3 * float(np.median(times))
    rng = np.random.default_rng(0)
    exact = lid.cast_ranges(sensors[:1], spec, world.segments, circles[0])[0]
    t = time.perf_counter()
    for _ in range(repeat):
        lid.make_scan(lid.measure(exact, spec, rng), spec, 0.0)
    noise_ms = 1e3 * (time.perf_counter() - t) / repeat
    t = time.perf_counter()
    world.scans_without_people(poses[pick])
    batch_ms = 1e3 * (time.perf_counter() - t) / len(pick)
    t = time.perf_counter()
    world.ground_truth()
    truth_ms = 1e3 * (time.perf_counter() - t)
    bar = f"<= {SCAN_BAR_MS} {'ok' if cast_ms <= SCAN_BAR_MS else 'OVER'}"
    return [
        (f"1081-beam scan, W4 world + {len(world.people())} people (median of {len(pick)})",
         cast_ms, bar),
        ("  range noise + Scan packing", noise_ms, ""),
        (f"  scans_without_people, {len(pick)} poses in one call, per scan", batch_ms, ""),
        ("ground truth G of a session (280 x 418 cells)", truth_ms, ""),
    ]


def session_rows(scn, names, repeat: int) -> list[tuple[str, float, str]]:
    rows = []
    for name in names:
        speeds, cpu_speeds = [], []
        for r in range(repeat):
            world = sim.World(scn, name, seed=r)
            t, c = time.perf_counter(), time.process_time()
            scans = sum(isinstance(m, sim.ScanMsg) for m in world.run())
            wall, cpu = time.perf_counter() - t, time.process_time() - c
            speeds.append(world.time / wall)
            cpu_speeds.append(world.time / cpu)
        x = float(np.median(speeds))
        people = len(world.people())
        bar = f">= {SESSION_BAR_X:.0f} {'ok' if x >= SESSION_BAR_X else 'UNDER'}"
        rows.append((f"session {name}: {world.time:.0f} s simulated, {people} people, "
                     f"{scans} scans; x real time (wall)", x, bar))
        rows.append(("  same, x real time (CPU)", float(np.median(cpu_speeds)), ""))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", nargs="*", default=["W1", "W2", "W3", "W4"])
    parser.add_argument("--repeat", type=int, default=2, help="runs per session row")
    parser.add_argument("--scans", type=int, default=1000, help="timed scans")
    args = parser.parse_args(argv)
    scn = sim.load_scenario(WAREHOUSE)
    warm = sim.World(scn, "W4", seed=0)          # compile or load every kernel once
    for m in warm.run():
        if m.time > 2.0:
            break
    rows = scan_rows(scn, args.scans) + session_rows(scn, args.sessions, args.repeat)
    width = max(len(name) for name, _, _ in rows)
    print(f"{'simulator (single thread)':<{width}}  {'value':>9}  bar")
    ok = True
    for name, value, bar in rows:
        unit = "x" if "real time" in name else "ms"
        print(f"{name:<{width}}  {value:8.3f}{unit:>1}  {bar}")
        ok &= "OVER" not in bar and "UNDER" not in bar
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
