"""Benchmark of the map updater: time per scan, against the code before the fused walks, and
memory.

A 10 x 10 m room mapped at 5 cm (200 x 200 cells), one box removed and one added since the map
was made. Scans are ray-cast on a 1 cm grid of the true room from poses on a circle, with 2 cm /
1 deg pose noise (seeded). Every scan is processed (gating off); timings are taken after the
kernels are compiled, as the median over all scans, best of three passes (the machine is shared).
The same scans then run on a 2000 x 2000 map holding the same room, to show that a scan costs
the same whatever the map's size. One more pass with timers around the kernels says where the
time of a 720-beam scan goes. Memory: the bytes of the updater's arrays for the 2000 x 2000
map, and the peak resident memory of a process that does only that (resource.getrusage).

The updater on the scans of ``mapupdate update``: on the room (720 and 1440 beams) and on the
real logs when they are at ../shared/data: the Intel lab (a map of the first half of the scans,
updated with the second half) and MIT Killian Court (the first third, updated with the last
third), with ``mapupdate update``'s updater configuration (the robot profile), timing the
updater's ``process`` calls alone (the scans and poses the pipeline gave it, recorded once),
``--passes`` passes on the same calls: the median per processed scan of each pass, the median
of those, and the median over the scans of each scan's best pass. Times are the scan's thread
CPU time. Then, in 5 more passes, the time of each scan split into the kernels that Python
calls (a timer around each call) and the Python around them.

Before and after: ``python benchmarks/run.py --baseline REV updater`` runs this script on a git
revision's packages and on the working tree's, and sets the figures side by side, with whether
the output maps are the same (``--json``: the figures and the maps' digests).

    python benchmarks/bench_updater.py [--scans N] [--passes N] [--no-logs] [--json PATH]

Exits with 1 when a median per scan misses its budget, or the state of a 2000 x 2000 map its
16 MB.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(ROOT))

from figures import Figures, add_option  # noqa: E402
from gridmap import OccupancyGrid, Pose2D, Scan  # noqa: E402
from gridmap.raycast import cast_rays  # noqa: E402
from updater import MapUpdater, UpdaterConfig  # noqa: E402

DATA = ROOT.parent / "shared/data"
LOGS = {"Intel": (DATA / "intel.gfs.log", 2), "Killian": (DATA / "killian.clf.gz", 3)}
STATE_BAR = 16e6        # [bytes] the state of a 2000 x 2000 map, every configuration
# A scan's own processor time, not the time it waited for a core: the machine is shared, and a
# scan preempted halfway would count the other process's work.
CLOCK = time.thread_time

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
            t0 = CLOCK()
            report = updater.process(scan, pose)
            times.append(CLOCK() - t0)
            lost += report.dropped_as_lost
        medians.append(float(np.median(times)))
        all_times.append(times)
    best = int(np.argmin(medians))
    times = np.array(all_times[best]) * 1e3
    return {"median_ms": float(np.median(times)), "p90_ms": float(np.percentile(times, 90)),
            "mean_ms": float(times.mean()), "pass_medians_ms": [m * 1e3 for m in medians],
            "lost": lost, "changed_cells": updater.n_changed, "state_bytes": updater.state_bytes()}


# The kernels a scan goes through: one call for a scan past the gate, and the pushes that
# are left to calls of their own when the workspace lacks room.
PARTS = (("classifier, flags (guard, walks, hit cells), push and decide in one call "
          "(process_scan)", ("process_scan", "push_and_decide", "push_hits")),)


def time_parts(ref: OccupancyGrid, scans) -> dict:
    """Mean time per scan [ms] of each part of ``PARTS``, from timers wrapped around the
    kernels for one pass, and of the Python around them (the rest of the mean per scan)."""
    from updater import steps

    kernels = steps.kernels()
    spent = {name: 0.0 for _, names in PARTS for name in names}
    originals = {name: getattr(kernels, name) for name in spent}

    def timed(name, fn):
        def call(*args, **kwargs):
            t0 = CLOCK()
            out = fn(*args, **kwargs)
            spent[name] += CLOCK() - t0
            return out
        return call

    updater = MapUpdater(ref, UpdaterConfig(gating=False))
    for scan, pose in scans[:10]:
        updater.process(scan, pose)
    updater = MapUpdater(ref, UpdaterConfig(gating=False))
    for name, fn in originals.items():
        setattr(kernels, name, timed(name, fn))
    try:
        t0 = CLOCK()
        for scan, pose in scans:
            updater.process(scan, pose)
        total = CLOCK() - t0
    finally:
        for name, fn in originals.items():
            setattr(kernels, name, fn)
    n = len(scans)
    parts = {label: sum(spent[k] for k in names) / n * 1e3 for label, names in PARTS}
    parts["Python around the kernels"] = total / n * 1e3 - sum(parts.values())
    return parts


def time_inner(ref: OccupancyGrid, scans) -> dict:
    """Mean time per scan [ms] of the heaviest work inside ``process_scan``, run again alone
    on each scan's recorded inputs, best of three passes: the classifier, of it the virtual
    beams' cast, and the walks (each from the marks it met in the scan: the free walks from
    the unchanged-flag marks of the settled free cells, the others from none)."""
    import inspect

    from updater import steps

    kernels = steps.kernels()
    seen = []
    original = kernels.process_scan
    names = list(inspect.signature(original.py_func).parameters)

    def record(*args):
        # the inputs as the call found them, the workspace's per-beam arrays as it left them
        got = {k: copied(v) for k, v in zip(names, args)}
        out = original(*args)
        seen.append(got | {"left": copied(args[names.index("work")])})
        return out

    updater = MapUpdater(ref, UpdaterConfig(gating=False))
    kernels.process_scan = record
    try:
        for scan, pose in scans:
            updater.process(scan, pose)
    finally:
        kernels.process_scan = original
    run_inner(seen, kernels, ref)       # compile (or load the cache) first
    runs = [run_inner(seen, kernels, ref) for _ in range(3)]
    return {label: min(r[label] for r in runs) / len(scans) * 1e3 for label in runs[0]}


def copied(value):
    """An array, or a named tuple of arrays, copied; anything else as it is."""
    if isinstance(value, np.ndarray):
        return np.copy(value)
    if isinstance(value, tuple):
        return type(value)(*(copied(v) for v in value))
    return value


def run_inner(seen, kernels, ref: OccupancyGrid) -> dict:
    """The classifier, the cast and the walks of ``time_inner``'s recorded calls: seconds in
    all, by part (the free walks with the reckoning of where each may start)."""
    from updater.steps import Workspace

    spent = {"classifier (run_classifier: prepare_beams, classify_scan)": 0.0,
             "virtual beams cast (cast_virtual)": 0.0, "free walks (walk_beams)": 0.0,
             "removed-obstacle walks (walk_beams)": 0.0}
    marks = np.zeros((ref.data.size + 7) // 8, np.uint8)
    out = np.zeros(ref.data.size + 1, np.int32)
    for kw in seen:
        cells, lay = kw["cells"], kw["layout"][0]
        work = copied(kw["work"])
        t0 = CLOCK()
        kernels.run_classifier(kw["ranges"], kw["sensor"], kw["layout"], kw["settings"], cells,
                               work)
        spent["classifier (run_classifier: prepare_beams, classify_scan)"] += CLOCK() - t0
        beams = {name: row for key, names in Workspace.ROWS
                 for name, row in zip(names, getattr(kw["left"], key))}
        t0 = CLOCK()
        kernels.cast_virtual(cells.ref, cells.clear, kw["sensor"], beams["virtual"],
                             lay["max_len"], beams["expected"], work.found)
        spent["virtual beams cast (cast_virtual)"] += CLOCK() - t0
        skips = np.zeros(len(beams["hits"]))
        cap = int(lay["walk_room"])
        for label, reach, want, drop, kind in (
                ("free walks (walk_beams)", "free_reach", kernels.UNCHANGED, False,
                 kernels.WALK_FREE),
                ("removed-obstacle walks (walk_beams)", "removed_reach", kernels.CHANGE, True,
                 kernels.WALK_BLOCKED)):
            marks[:] = kw["state"].unchanged_marks if kind == kernels.WALK_FREE else 0
            t0 = CLOCK()
            if kind == kernels.WALK_FREE:
                kernels.free_walk_skips(kw["sensor"], beams["hits"], beams[reach],
                                        beams["verdict"], want, abs(lay["angle_increment"]),
                                        bool(lay["even_wrap"]), cap, skips)
            kernels.walk_beams(cells.ref, cells.enclosed, cells.clear, kw["sensor"],
                               beams["hits"], beams[reach], select=beams["verdict"], want=want,
                               drop_last=drop, cap=cap, kind=kind, marks=marks, out=out, n=0,
                               skip=skips if kind == kernels.WALK_FREE else kernels.NO_SKIPS)
            spent[label] += CLOCK() - t0
    return spent


# --- the scans of mapupdate update -----------------------------------------------------------
def replay(ref: OccupancyGrid, config: UpdaterConfig, calls) -> tuple[np.ndarray, np.ndarray]:
    """A fresh updater fed ``calls`` ((scan, sensor pose, odometry) each): (ms per call, NaN
    for a scan it did not process; its output map)."""
    updater = MapUpdater(ref, config)
    times = np.full(len(calls), np.nan)
    for k, (scan, pose, odometry) in enumerate(calls):
        t0 = CLOCK()
        report = updater.process(scan, pose, odometry)
        dt = CLOCK() - t0
        if report.processed:
            times[k] = dt * 1e3
    return times, updater.updated_map().data


def measure(ref: OccupancyGrid, config: UpdaterConfig, calls, passes: int) -> dict:
    """``passes`` passes on the same calls, back to back: the median of the passes' medians
    per processed scan, and, less touched by the other work of a shared machine, the median
    over the scans of each scan's best pass; the output map (the same in every pass)."""
    replay(ref, config, calls[:20])          # compile (or load the cache) first
    times, maps = [], []
    for _ in range(passes):
        ms, out = replay(ref, config, calls)
        times.append(ms)
        maps.append(out)
    medians = [float(np.nanmedian(t)) for t in times]
    if any(not np.array_equal(m, maps[0]) for m in maps):
        raise SystemExit("the passes gave different maps: the timings compare nothing")
    return {"ms": float(np.median(medians)), "best_ms": float(np.nanmedian(np.min(times, 0))),
            "passes": medians, "processed": int(np.count_nonzero(~np.isnan(times[0]))),
            "map": maps[0]}


def kernel_modules() -> list:
    """The kernel modules whose functions the updater's Python calls: the modules of
    ``updater`` and ``gridmap`` whose names hold "kernels" (as imported by now)."""
    return [m for name, m in sorted(sys.modules.items()) if m is not None
            and name.split(".")[0] in ("updater", "gridmap") and "kernels" in name]


def python_split(ref: OccupancyGrid, config: UpdaterConfig, calls) -> dict:
    """One pass on ``calls``, the medians per processed scan [ms]: of the whole call ("all"),
    of the kernels that Python calls, each timed around its call ("kernels": their work and
    the cost of calling them), and of the rest ("Python")."""
    from numba.core.registry import CPUDispatcher

    kernels = {(m, name): f for m in kernel_modules() for name, f in vars(m).items()
               if isinstance(f, CPUDispatcher)}
    spent = [0.0]

    def timed(fn):
        def call(*args, **kwargs):
            t0 = time.perf_counter()
            out = fn(*args, **kwargs)
            spent[0] += time.perf_counter() - t0
            return out
        return call

    for (module, name), fn in kernels.items():
        setattr(module, name, timed(fn))
    updater, per_scan = MapUpdater(ref, config), []
    try:
        for scan, pose, odometry in calls:
            spent[0] = 0.0
            t0 = time.perf_counter()
            report = updater.process(scan, pose, odometry)
            total = time.perf_counter() - t0
            if report.processed:
                per_scan.append((total * 1e3, spent[0] * 1e3))
    finally:
        for (module, name), fn in kernels.items():
            setattr(module, name, fn)
    total, kernel = np.array(per_scan).T
    return {"all": float(np.median(total)), "kernels": float(np.median(kernel)),
            "Python": float(np.median(total - kernel))}


def log_calls(path: Path, parts: int, tmp: Path):
    """A map of the first 1/``parts`` of a log's scans (at their recorded poses) and the calls
    ``mapupdate update`` makes of the updater when updating it with the last 1/``parts``:
    (reference map, the updater configuration, [(scan, sensor pose, odometry)])."""
    from gridmap import save_map
    from gridmap.mapping import build_map
    from onboard.logmap import _placed_scans, map_frame
    from onboard.replay import LogSource, Outputs, update_from_log
    from robotlogs import log_observations

    found = log_observations(path)
    placed = _placed_scans(found, "recorded", (None, None))
    share = len(placed) // parts
    first = build_map(map_frame(placed, RES), placed[:share])
    save_map(first, tmp / "first.yaml")
    start = [o.time for o in found.observations][-share]
    calls = []

    def record(self, scan, sensor_pose, odometry=None, pose_check=None):
        calls.append((scan, sensor_pose, odometry))
        return plain_process(self, scan, sensor_pose, odometry, pose_check)

    plain_process = MapUpdater.process
    MapUpdater.process = record
    try:
        update_from_log(tmp / "first.yaml", LogSource(path, start_time=start),
                        Outputs(tmp / "updated.yaml"))
    finally:
        MapUpdater.process = plain_process
    return first, UpdaterConfig.profile("robot"), calls


def case_rows(scans_count: int, passes: int, logs: bool) -> list[tuple[str, dict]]:
    """The room at 720 and 1440 beams (the paper's rules, every scan processed), then the
    real logs found (``mapupdate update``'s configuration)."""
    import tempfile

    rows = []
    for beams in (720, 1440):
        calls = [(scan, pose, None) for scan, pose in make_scans(beams, scans_count)]
        row = measure(reference(200), UpdaterConfig(gating=False), calls, passes)
        row["split"] = splits(reference(200), UpdaterConfig(gating=False), calls)
        rows.append((f"room, {beams} beams, 200 x 200", row))
    for name, (path, parts) in LOGS.items():
        if not logs or not path.exists():
            continue
        with tempfile.TemporaryDirectory() as tmp:
            ref, config, calls = log_calls(path, parts, Path(tmp))
        row = measure(ref, config, calls, passes)
        row["split"] = splits(ref, config, calls)
        rows.append((f"{name}, 180 beams, {ref.width} x {ref.height}", row))
    return rows


def splits(ref: OccupancyGrid, config: UpdaterConfig, calls, passes: int = 5) -> dict:
    """``python_split`` in ``passes`` passes: the median of the passes' medians."""
    runs = [python_split(ref, config, calls) for _ in range(passes)]
    return {key: float(np.median([p[key] for p in runs])) for key in runs[0]}


def print_cases(rows, passes: int) -> None:
    print(f"The updater on mapupdate update's scans, {passes} passes, median ms per processed "
          f"scan (thread CPU time); the kernels and the Python around them, 5 more passes "
          f"(wall time, timers around each kernel called from Python):")
    print()
    print("| case | scans processed | ms | passes | each scan's best pass ms "
          "| all | kernels | Python |")
    print("|---|---:|---:|---|---:|---:|---:|---:|")
    for label, r in rows:
        s = r["split"]
        print(f"| {label} | {r['processed']} | {r['ms']:.3f} | "
              f"{' / '.join(f'{m:.3f}' for m in r['passes'])} | {r['best_ms']:.3f} "
              f"| {s['all']:.3f} | {s['kernels']:.3f} | {s['Python']:.3f} |")
    print()


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
    out = {"state_bytes": updater.state_bytes(), "rss_before_kb": rss_before,
           "rss_after_kb": rss_kb(), "peak_before_kb": peak_before,
           "peak_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}
    del updater
    # the state of mapupdate update's configurations, after the resident figures above
    out["other_states"] = {}
    for label, config in other_configs().items():
        updater = MapUpdater(reference(2000), config)
        for scan, pose in scans:
            updater.process(scan, pose)
        out["other_states"][label] = updater.state_bytes()
        del updater
    print(json.dumps(out))


def other_configs() -> dict:
    """mapupdate update's defaults, and their rule for cells observed a few times alone (its
    flag counts, without the hit buffers of the growth into the unknown), every scan processed
    as in the rows of the table."""
    return {"the paper's with unanimous_min": UpdaterConfig(
                gating=False, unanimous_min=UpdaterConfig.profile("robot").unanimous_min),
            "mapupdate update's defaults": UpdaterConfig.profile("robot", {"gating": False})}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=400)
    parser.add_argument("--passes", "--pairs", type=int, default=5, dest="passes",
                        help="passes on the scans of mapupdate update (default 5)")
    parser.add_argument("--no-logs", action="store_true", help="the room only")
    parser.add_argument("--memory-child", action="store_true", help=argparse.SUPPRESS)
    add_option(parser)
    args = parser.parse_args()
    if args.memory_child:
        memory_child(args.scans)
        return 0
    # first, while this process is small: a child inherits its peak resident memory
    child = subprocess.run([sys.executable, __file__, "--memory-child", "--scans", "100"],
                           check=True, capture_output=True, text=True)
    mem = json.loads(child.stdout.strip().splitlines()[-1])
    cases = case_rows(args.scans, args.passes, not args.no_logs)
    rows = []
    for beams, budget in ((720, 1.0), (1440, 2.0)):
        scans = make_scans(beams, args.scans)
        for size in (200, 2000):
            rows.append((beams, size, budget, time_scans(reference(size), scans)))
    parts = internals(time_parts, reference(200), make_scans(720, args.scans))
    inner = internals(time_inner, reference(200), make_scans(720, args.scans))

    print_cases(cases, args.passes)
    print_table(rows, parts, inner, mem, args.scans)
    figures(cases, rows, mem).write(args.json)
    states = [mem["state_bytes"], *mem["other_states"].values()]
    return int(max(states) > STATE_BAR or any(r["median_ms"] > budget
                                              for _, _, budget, r in rows))


def internals(timer, *args) -> dict:
    """``timer``'s figures, or none when the code measured lacks the internals it times
    inside (another revision's, with run.py --baseline)."""
    try:
        return timer(*args)
    except (AttributeError, KeyError, TypeError, ValueError) as e:
        print(f"({timer.__name__}: not measured on this code: {type(e).__name__}: {e})")
        return {}


def figures(cases, rows, mem) -> Figures:
    """What run.py --baseline sets beside a revision's: the cases' times and output maps,
    the room's times per map size and the states' bytes."""
    out = Figures()
    for label, r in cases:
        out.add(f"{label}: median per processed scan", r["ms"], "ms")
        out.add(f"{label}: each scan's best pass", r["best_ms"], "ms")
        out.add(f"{label}: kernels (wall)", r["split"]["kernels"], "ms")
        out.add(f"{label}: Python around them (wall)", r["split"]["Python"], "ms")
        out.output(f"{label}: output map", r["map"])
    for beams, size, _, r in rows:
        out.add(f"room, {beams} beams, {size} x {size}, every scan: median", r["median_ms"], "ms")
    out.add("2000 x 2000 map: updater state", mem["state_bytes"], "bytes")
    for label, n_bytes in mem["other_states"].items():
        out.add(f"2000 x 2000 map, {label}: updater state", n_bytes, "bytes")
    return out


def print_table(rows, parts, inner, mem, scans_count: int) -> None:
    print(f"Map updater, {ROOM:.0f} x {ROOM:.0f} m room at {RES * 100:.0f} cm, 360 deg scans, "
          f"every scan processed (gating off), {scans_count} scans, best of 3 passes")
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
    total = sum(parts.values()) or math.nan
    for label, ms in parts.items():
        print(f"| {label} | {ms:.3f} | {ms / total:.0%} |")
    for label, ms in inner.items():
        print(f"| of which, run alone on the recorded inputs: {label} | {ms:.3f} "
              f"| {ms / total:.0%} |")
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
    for label, n_bytes in mem["other_states"].items():
        print(f"2000 x 2000 map, {label}: updater state {n_bytes:,d} bytes "
              f"({n_bytes / 2**20:.2f} MiB)")


if __name__ == "__main__":
    sys.exit(main())
