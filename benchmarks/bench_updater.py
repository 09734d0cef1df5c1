"""Benchmark of the map updater: time per scan, and memory.

A 10 x 10 m room mapped at 5 cm (200 x 200 cells), one box removed and one added since the map
was made. Scans are ray-cast on a 1 cm grid of the true room from poses on a circle, with 2 cm /
1 deg pose noise (seeded). Every scan is processed (gating off); timings are taken after the
kernels are compiled, as the median over all scans, best of three passes (the machine is shared).
The same scans then run on a 2000 x 2000 map holding the same room, to show that a scan costs
the same whatever the map's size. One more pass with timers around the kernels says where the
time of a 720-beam scan goes. Memory: the bytes of the updater's arrays for the 2000 x 2000
map, and the peak resident memory of a process that does only that (resource.getrusage).

    python benchmarks/bench_updater.py [--scans N]

Exits with 1 when a median per scan misses its budget.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gridmap import OccupancyGrid, Pose2D, Scan  # noqa: E402
from gridmap.raycast import cast_rays  # noqa: E402
from updater import MapUpdater, UpdaterConfig  # noqa: E402

RES = 0.05
ROOM = 10.0                                   # [m]
REMOVED = (4.4, 4.6, 5.6, 5.4)                # x0, y0, x1, y1 [m]: in the map, not the world
ADDED = (7.6, 7.6, 8.4, 8.8)                  # in the world, not the map
KEPT = (1.2, 7.8, 2.0, 8.4)                   # in both


def room(res: float, boxes) -> np.ndarray:
    n = int(round(ROOM / res))
    data = np.zeros((n, n), np.int8)
    wall = int(round(0.15 / res))
    data[:wall, :] = data[-wall:, :] = data[:, :wall] = data[:, -wall:] = 100
    for x0, y0, x1, y1 in boxes:
        data[int(y0 / res):int(math.ceil(y1 / res)), int(x0 / res):int(math.ceil(x1 / res))] = 100
    return data


def make_scans(beams: int, count: int, seed: int = 0):
    """Scans of the true room (1 cm grid) and the noisy sensor poses the updater is told."""
    truth = OccupancyGrid(room(0.01, [ADDED, KEPT]), 0.01)
    rng = np.random.default_rng(seed)
    inc = 2 * math.pi / beams
    angles = -math.pi + inc * np.arange(beams)
    out = []
    for k in range(count):
        phi = 2 * math.pi * k / count
        true = Pose2D(5.0 + 2.8 * math.cos(phi), 5.0 + 2.8 * math.sin(phi), phi + math.pi / 2)
        ranges = cast_rays(truth, true, angles, 20.0) + rng.normal(0, 0.005, beams)
        told = Pose2D(true.x + rng.normal(0, 0.02), true.y + rng.normal(0, 0.02),
                      true.theta + rng.normal(0, math.radians(1.0)))
        out.append((Scan(ranges.astype(np.float32), -math.pi, inc, 0.05, 20.0, 0.1 * k), told))
    return out


def reference(size: int) -> OccupancyGrid:
    """The 200 x 200 room map, alone or in the middle of a larger map of unknown cells."""
    small = room(RES, [REMOVED, KEPT])
    if size == small.shape[0]:
        return OccupancyGrid(small, RES)
    data = np.full((size, size), -1, np.int8)
    k = (size - small.shape[0]) // 2
    data[k:k + small.shape[0], k:k + small.shape[1]] = small
    return OccupancyGrid(data, RES, (-k * RES, -k * RES))


def time_scans(ref: OccupancyGrid, scans, passes: int = 3) -> dict:
    config = UpdaterConfig(gating=False)
    warm = MapUpdater(ref, config)
    for scan, pose in scans[:10]:              # compile (or load the cache) first
        warm.process(scan, pose)
    medians, all_times, lost = [], [], 0
    for _ in range(passes):
        updater = MapUpdater(ref, config)
        times = []
        for scan, pose in scans:
            t0 = time.perf_counter()
            report = updater.process(scan, pose)
            times.append(time.perf_counter() - t0)
            lost += report.dropped_as_lost
        medians.append(float(np.median(times)))
        all_times.append(times)
    best = int(np.argmin(medians))
    times = np.array(all_times[best]) * 1e3
    return {"median_ms": float(np.median(times)), "p90_ms": float(np.percentile(times, 90)),
            "mean_ms": float(times.mean()), "pass_medians_ms": [m * 1e3 for m in medians],
            "lost": lost, "changed_cells": updater.n_changed, "state_bytes": updater.state_bytes()}


# The kernels a scan goes through, by the step of docs/algorithm.md they belong to.
PARTS = (("virtual beams cast (cast_virtual)", ("cast_virtual",)),
         ("rest of the classifier", ("valid_ranges", "beam_directions", "beam_endpoints",
                                     "classify", "run_filter", "beam_verdicts")),
         ("seen-surface guard", ("mark_seen_surfaces", "clear_bits")),
         ("changed cells: removed-obstacle walks", ("flag_removed_obstacles",)),
         ("changed cells: new obstacles", ("flag_new_obstacles",)),
         ("unchanged cells: free walks", ("flag_free_unchanged",)),
         ("unchanged cells: occupied", ("flag_occupied_unchanged",)),
         ("unchanged cells: hits of changes", ("flag_hit_surfaces",)),
         ("push and decide", ("push_flags", "decide")))


def time_parts(ref: OccupancyGrid, scans) -> dict:
    """Mean time per scan [ms] of each part of ``PARTS``, from timers wrapped around the
    kernels for one pass, and of the Python around them (the rest of the mean per scan)."""
    from updater import steps

    kernels = steps.kernels()
    spent = {name: 0.0 for _, names in PARTS for name in names}
    originals = {name: getattr(kernels, name) for name in spent}

    def timed(name, fn):
        def call(*args, **kwargs):
            t0 = time.perf_counter()
            out = fn(*args, **kwargs)
            spent[name] += time.perf_counter() - t0
            return out
        return call

    updater = MapUpdater(ref, UpdaterConfig(gating=False))
    for scan, pose in scans[:10]:
        updater.process(scan, pose)
    updater = MapUpdater(ref, UpdaterConfig(gating=False))
    for name, fn in originals.items():
        setattr(kernels, name, timed(name, fn))
    try:
        t0 = time.perf_counter()
        for scan, pose in scans:
            updater.process(scan, pose)
        total = time.perf_counter() - t0
    finally:
        for name, fn in originals.items():
            setattr(kernels, name, fn)
    n = len(scans)
    parts = {label: sum(spent[k] for k in names) / n * 1e3 for label, names in PARTS}
    parts["Python around the kernels"] = total / n * 1e3 - sum(parts.values())
    return parts


def rss_kb() -> float:
    """The process's current resident memory [KiB] (Linux), NaN elsewhere."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, ValueError, IndexError):
        return math.nan
    return pages * resource.getpagesize() / 1024


def memory_child(scans_count: int) -> None:
    """Run in a fresh process: memory of an updater on the 2000 x 2000 map."""
    scans = make_scans(720, scans_count)
    MapUpdater(reference(200), UpdaterConfig(gating=False)).process(*scans[0])  # load kernels
    rss_before = rss_kb()
    peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    updater = MapUpdater(reference(2000), UpdaterConfig(gating=False))
    for scan, pose in scans:
        updater.process(scan, pose)
    print(json.dumps({"state_bytes": updater.state_bytes(), "rss_before_kb": rss_before,
                      "rss_after_kb": rss_kb(), "peak_before_kb": peak_before,
                      "peak_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=400)
    parser.add_argument("--memory-child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.memory_child:
        memory_child(args.scans)
        return 0
    rows = []
    for beams, budget in ((720, 1.0), (1440, 2.0)):
        scans = make_scans(beams, args.scans)
        for size in (200, 2000):
            rows.append((beams, size, budget, time_scans(reference(size), scans)))
    parts = time_parts(reference(200), make_scans(720, args.scans))
    child = subprocess.run([sys.executable, __file__, "--memory-child", "--scans", "100"],
                           check=True, capture_output=True, text=True)
    mem = json.loads(child.stdout.strip().splitlines()[-1])

    print(f"Map updater, {ROOM:.0f} x {ROOM:.0f} m room at {RES * 100:.0f} cm, 360 deg scans, "
          f"every scan processed (gating off), {args.scans} scans, best of 3 passes")
    print()
    print("| beams | map         | median ms | p90 ms | mean ms | pass medians ms       "
          "| budget ms | lost | state bytes |")
    print("|------:|-------------|----------:|-------:|--------:|-----------------------"
          "|----------:|-----:|------------:|")
    for beams, size, budget, r in rows:
        passes = " / ".join(f"{m:.3f}" for m in r["pass_medians_ms"])
        label = f"{size} x {size}"
        print(f"| {beams:5d} | {label:<11s} | {r['median_ms']:9.3f} | {r['p90_ms']:6.3f} "
              f"| {r['mean_ms']:7.3f} | {passes:21s} | {budget:9.1f} | {r['lost']:4d} "
              f"| {r['state_bytes']:11,d} |")
    print()
    print("Where the time of a 720-beam scan goes (200 x 200 map, mean ms per scan, timers "
          "around the kernels):")
    print()
    print("| part | ms | share |")
    print("|---|---:|---:|")
    total = sum(parts.values())
    for label, ms in parts.items():
        print(f"| {label} | {ms:.3f} | {ms / total:.0%} |")
    print()
    for beams in (720, 1440):
        small, large = (r for b, s, _, r in rows if b == beams)
        print(f"{beams} beams: 2000 x 2000 / 200 x 200 = "
              f"{large['median_ms'] / small['median_ms']:.3f} (median per scan)")
    print(f"2000 x 2000 map: updater state {mem['state_bytes']:,d} bytes "
          f"({mem['state_bytes'] / 2**20:.2f} MiB); in a process doing only that, resident "
          f"memory grew by {(mem['rss_after_kb'] - mem['rss_before_kb']) / 1024:.1f} MiB "
          f"over 100 scans (untouched pages of its zeroed arrays stay unmapped); peak RSS "
          f"(getrusage) {mem['peak_kb'] / 1024:.1f} MiB at the end, "
          f"{mem['peak_before_kb'] / 1024:.1f} MiB before the updater was made (Python, NumPy, "
          f"numba, compiled kernels, scan generation), resident then "
          f"{mem['rss_before_kb'] / 1024:.1f} MiB")
    return int(any(r["median_ms"] > budget for _, _, budget, r in rows))


if __name__ == "__main__":
    sys.exit(main())
