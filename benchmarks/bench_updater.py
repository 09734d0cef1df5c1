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

Before and after: the updater as it was before the fused walks (a frozen copy in
``benchmarks/updater_before``) and as it is, run on the same scans in alternating passes, back to
back (``--pairs`` passes each): the median per scan of each pass, the median of those, their
ratio, and whether the two gave the same output map. On the room (720 and 1440 beams) and on
the real logs when they are at ../shared/data: the Intel lab (a map of the first half of the
scans, updated with the second half) and MIT Killian Court (the first third, updated with the
last third), with ``mapupdate update``'s updater configuration, timing the updater's
``process`` calls alone (the scans and poses the pipeline gave it, recorded once), the median
over the scans it processed past the gate. Times are the scan's thread CPU time.
Then, in 5 more alternating passes each, the time of each scan split into the kernels that
Python calls (a timer around each call) and the Python around them: where the ratio comes
from, and where it falls short.

    python benchmarks/bench_updater.py [--scans N] [--pairs N] [--no-logs]

Exits with 1 when a median per scan misses its budget, or when the 720-beam room or a real log
is not at least twice as fast as before (the bar of "speed, round two") or gives another map.
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
sys.path.insert(0, str(Path(__file__).resolve().parent))

from gridmap import OccupancyGrid, Pose2D, Scan  # noqa: E402
from gridmap.raycast import cast_rays  # noqa: E402
from updater import MapUpdater, UpdaterConfig  # noqa: E402
from updater_before import AS_BEFORE  # noqa: E402
from updater_before import MapUpdater as BeforeMapUpdater  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared/data"
LOGS = {"Intel": (DATA / "intel.gfs.log", 2), "Killian": (DATA / "killian.clf.gz", 3)}
SPEEDUP_BAR = 2.0       # before / after, median per scan
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
        # the inputs as the call found them, the per-beam arrays as it left them
        got = {k: np.copy(v) if isinstance(v, np.ndarray) else v for k, v in zip(names, args)}
        out = original(*args)
        left = {k: np.copy(v) for k, v in zip(names, args) if k in PER_BEAM}
        seen.append(got | left | beam_views(left))
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


def run_inner(seen, kernels, ref: OccupancyGrid) -> dict:
    """The classifier, the cast and the walks of ``time_inner``'s recorded calls: seconds in
    all, by part (the free walks with the reckoning of where each may start)."""
    spent = {"classifier (prepare_beams, classify_scan)": 0.0,
             "virtual beams cast (cast_virtual)": 0.0, "free walks (walk_beams)": 0.0,
             "removed-obstacle walks (walk_beams)": 0.0}
    marks = np.zeros((ref.data.size + 7) // 8, np.uint8)
    out = np.zeros(ref.data.size + 1, np.int32)
    for kw in seen:
        t0 = CLOCK()
        classify_alone(kernels, kw)
        spent["classifier (prepare_beams, classify_scan)"] += CLOCK() - t0
        t0 = CLOCK()
        kernels.cast_virtual(kw["ref"], kw["clear"], kw["sensor"], kw["virtual"],
                             kw["max_len"], kw["expected"], kw["out_found"])
        spent["virtual beams cast (cast_virtual)"] += CLOCK() - t0
        skips = np.zeros(len(kw["hits"]))
        for label, reach, want, drop, kind in (
                ("free walks (walk_beams)", "free_reach", kernels.UNCHANGED, False,
                 kernels.WALK_FREE),
                ("removed-obstacle walks (walk_beams)", "reach", kernels.CHANGE, True,
                 kernels.WALK_BLOCKED)):
            marks[:] = kw["un_marks"] if kind == kernels.WALK_FREE else 0
            t0 = CLOCK()
            if kind == kernels.WALK_FREE:
                kernels.free_walk_skips(kw["sensor"], kw["hits"], kw[reach], kw["verdict"],
                                        want, abs(kw["increment"]), kw["even"], kw["cap"],
                                        skips)
            kernels.walk_beams(kw["ref"], kw["enclosed"], kw["clear"], kw["sensor"],
                               kw["hits"], kw[reach], select=kw["verdict"], want=want,
                               drop_last=drop, cap=kw["cap"], kind=kind, marks=marks, out=out,
                               n=0,
                               skip=skips if kind == kernels.WALK_FREE else kernels.NO_SKIPS)
            spent[label] += CLOCK() - t0
    return spent


# ``process_scan``'s per-beam arguments: rows of these, named by ``Workspace``
PER_BEAM = ("floats", "bits", "verdicts", "points", "rays", "out_found")


def beam_views(arrays: dict) -> dict:
    """The per-beam arrays of ``process_scan``'s arguments by name (views of their rows)."""
    from updater.steps import Workspace

    return {name: row for key, names in Workspace.ROWS for name, row in zip(names, arrays[key])}


def classify_alone(kernels, kw) -> None:
    """Step 1 of a recorded ``process_scan`` call (into its recorded outputs)."""
    kernels.prepare_beams(kw["ranges"], kw["r_lo"], kw["r_hi"], kw["sensor"], kw["angle_min"],
                          kw["step"], kw["increment"], kw["ratio"], kw["res"], kw["dist"],
                          kw["r"], kw["valid"], kw["virtual"], kw["measured"], kw["hits"],
                          kw["pairing"], kw["tol"], kw["skip"], kw["reach"], kw["free_reach"])
    kernels.classify_scan(kw["ref"], kw["clear"], kw["sensor"], kw["virtual"], kw["max_len"],
                          kw["hits"], kw["valid"], kw["pairing"], kw["half_window"],
                          kw["wrap"], kw["min_run"], kw["n_skip"], kw["expected"],
                          kw["out_found"], kw["change"], kw["keep"], kw["verdict"],
                          kw["min_width"])


# --- before and after -------------------------------------------------------------------------
def replay(cls, ref: OccupancyGrid, config: UpdaterConfig,
           calls) -> tuple[np.ndarray, np.ndarray]:
    """A fresh updater of class ``cls`` fed ``calls`` ((scan, sensor pose, odometry) each):
    (ms per call, NaN for a scan it did not process; its output map)."""
    updater = cls(ref, config)
    times = np.full(len(calls), np.nan)
    for k, (scan, pose, odometry) in enumerate(calls):
        t0 = CLOCK()
        report = updater.process(scan, pose, odometry)
        dt = CLOCK() - t0
        if report.processed:
            times[k] = dt * 1e3
    return times, updater.updated_map().data


def before_after(ref: OccupancyGrid, config: UpdaterConfig, calls, pairs: int) -> dict:
    """The code before and after on the same calls, in alternating passes, back to back: the
    median of the passes' medians per processed scan, and, less touched by the other work of
    a shared machine, the median over the scans of each scan's best pass."""
    for cls in (BeforeMapUpdater, MapUpdater):      # compile (or load the cache) first
        replay(cls, ref, config, calls[:20])
    times = {"before": [], "after": []}
    maps = {}
    for _ in range(pairs):
        for name, cls in (("before", BeforeMapUpdater), ("after", MapUpdater)):
            ms, maps[name] = replay(cls, ref, config, calls)
            times[name].append(ms)
    medians = {k: [float(np.nanmedian(t)) for t in v] for k, v in times.items()}
    before, after = (float(np.median(medians[k])) for k in ("before", "after"))
    best = {k: float(np.nanmedian(np.min(v, axis=0))) for k, v in times.items()}
    return {"before_ms": before, "after_ms": after, "ratio": before / after,
            "best_before_ms": best["before"], "best_after_ms": best["after"],
            "best_ratio": best["before"] / best["after"],
            "passes": medians, "identical": bool(np.array_equal(maps["before"], maps["after"]))}


def kernel_modules(cls) -> list:
    """The kernel modules whose functions ``cls``'s Python calls: its package's, and gridmap's."""
    import importlib

    from gridmap import _kernels as grid

    package = cls.__module__.rsplit(".", 1)[0]
    found = [importlib.import_module(f"{package}._kernels"), grid]
    try:
        found.append(importlib.import_module(f"{package}._grid_kernels"))
    except ImportError:
        pass
    return found


def python_split(cls, ref: OccupancyGrid, config: UpdaterConfig, calls) -> dict:
    """One pass of ``cls`` on ``calls``, the medians per processed scan [ms]: of the whole
    call ("all"), of the kernels that Python calls, each timed around its call ("kernels":
    their work and the cost of calling them), and of the rest ("Python")."""
    from numba.core.registry import CPUDispatcher

    kernels = {(m, name): f for m in kernel_modules(cls) for name, f in vars(m).items()
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
    updater, per_scan = cls(ref, config), []
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
    from robot.logmap import _placed_scans, map_frame
    from robot.replay import LogSource, Outputs, update_from_log
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
    # update's rules as the code kept from before can run them
    return first, UpdaterConfig.profile("robot", {**AS_BEFORE}), calls


def compare_rows(scans_count: int, pairs: int, logs: bool) -> list[tuple[str, dict]]:
    """Before and after: the room at 720 and 1440 beams, then the real logs found."""
    import tempfile

    rows = []
    for beams in (720, 1440):
        calls = [(scan, pose, None) for scan, pose in make_scans(beams, scans_count)]
        rows.append((f"room, {beams} beams", before_after(
            reference(200), UpdaterConfig(gating=False), calls, pairs)))
        rows[-1][1]["split"] = splits(reference(200), UpdaterConfig(gating=False), calls)
    for name, (path, parts) in LOGS.items():
        if not logs or not path.exists():
            continue
        with tempfile.TemporaryDirectory() as tmp:
            ref, config, calls = log_calls(path, parts, Path(tmp))
        row = before_after(ref, config, calls, pairs)
        row["scans"] = len(calls)
        row["split"] = splits(ref, config, calls)
        rows.append((f"{name}, 180 beams, {ref.width} x {ref.height}", row))
    return rows


def splits(ref: OccupancyGrid, config: UpdaterConfig, calls, passes: int = 5) -> dict:
    """``python_split`` of the code before and after in alternating passes: the median of
    the passes' medians."""
    codes = (("before", BeforeMapUpdater), ("after", MapUpdater))
    got = {name: [] for name, _ in codes}
    for _ in range(passes):
        for name, cls in codes:
            got[name].append(python_split(cls, ref, config, calls))
    return {name: {key: float(np.median([p[key] for p in runs])) for key in runs[0]}
            for name, runs in got.items()}


def print_split(rows) -> None:
    print("The Python around the kernels and the kernels, before and after: median ms per "
          "processed scan of the whole call, of the kernels called from Python (timers around "
          "each call: their work and the cost of the call) and of the rest, 5 alternating "
          "passes each (wall time), the median of the passes:")
    print()
    print("| case | before: all | kernels | Python | after: all | kernels | Python "
          "| ratio: kernels | Python |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for label, r in rows:
        b, a = r["split"]["before"], r["split"]["after"]
        print(f"| {label} | {b['all']:.3f} | {b['kernels']:.3f} | {b['Python']:.3f} "
              f"| {a['all']:.3f} | {a['kernels']:.3f} | {a['Python']:.3f} "
              f"| {b['kernels'] / a['kernels']:.2f} | {b['Python'] / a['Python']:.2f} |")
    print()


def print_comparison(rows, pairs: int) -> None:
    print(f"Before (benchmarks/updater_before) and after, {pairs} alternating passes each, "
          f"median ms per processed scan (thread CPU time), median of the passes:")
    print()
    print("| case | before ms | after ms | before / after | bar | same map | passes before "
          "| passes after | best pass per scan, before / after ms | ratio |")
    print("|---|---:|---:|---:|---:|---|---|---|---|---:|")
    for label, r in rows:
        bar = f">= {SPEEDUP_BAR:.0f}" if not label.startswith("room, 1440") else ""
        print(f"| {label} | {r['before_ms']:.3f} | {r['after_ms']:.3f} | {r['ratio']:.2f} | "
              f"{bar} | {'yes' if r['identical'] else 'NO'} | "
              f"{' / '.join(f'{m:.3f}' for m in r['passes']['before'])} | "
              f"{' / '.join(f'{m:.3f}' for m in r['passes']['after'])} | "
              f"{r['best_before_ms']:.3f} / {r['best_after_ms']:.3f} | {r['best_ratio']:.2f} |")
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
    parser.add_argument("--pairs", type=int, default=5,
                        help="alternating passes of the code before and after, each")
    parser.add_argument("--no-logs", action="store_true", help="the room only")
    parser.add_argument("--memory-child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.memory_child:
        memory_child(args.scans)
        return 0
    # first, while this process is small: a child inherits its peak resident memory
    child = subprocess.run([sys.executable, __file__, "--memory-child", "--scans", "100"],
                           check=True, capture_output=True, text=True)
    mem = json.loads(child.stdout.strip().splitlines()[-1])
    compared = compare_rows(args.scans, args.pairs, not args.no_logs)
    rows = []
    for beams, budget in ((720, 1.0), (1440, 2.0)):
        scans = make_scans(beams, args.scans)
        for size in (200, 2000):
            rows.append((beams, size, budget, time_scans(reference(size), scans)))
    parts = time_parts(reference(200), make_scans(720, args.scans))
    inner = time_inner(reference(200), make_scans(720, args.scans))

    print_comparison(compared, args.pairs)
    print_split(compared)
    print_table(rows, parts, inner, mem, args.scans)
    missed_bar = any(r["ratio"] < SPEEDUP_BAR or not r["identical"]
                     for label, r in compared if not label.startswith("room, 1440"))
    states = [mem["state_bytes"], *mem["other_states"].values()]
    missed_bar = missed_bar or max(states) > STATE_BAR
    return int(missed_bar or any(r["median_ms"] > budget for _, _, budget, r in rows))


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
    total = sum(parts.values())
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
