"""Benchmark: the pose check and its refinement (``PoseCheck.verdict``) on the main job's own
calls, before and after its grid kernels.

The main job (``mapupdate run``, by default its quick variant) runs once with
``PoseCheck.verdict`` wrapped to record every call: the check's map, the scan, the robot pose,
the lidar mount and the localiser's covariance, in order. Those calls are then replayed on
fresh checks of the same maps, by the frozen copy of the code before
(``benchmarks/pose_check_before``) and by the live ``localization.confidence``, call by call,
the two alternating which goes first. Each call is timed with the thread's CPU time
(``time.thread_time``), so that other work on the machine counts as little as it can.

Every replayed verdict (refused with its reason, or refined with its sensor pose) must equal
the other's and the one the main job got; so must every ``PoseCheck.fit`` (the fit, the gain
and the correction, compared exactly).

    python benchmarks/bench_pose_check.py [--full] [--sessions K] [--repeats N] [--bar 2.0]

Exit 1 when a verdict or a fit differs, or when the median over the repeats of the ratio of
the summed CPU times (before / after) is below the bar.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numba  # noqa: E402
import numpy as np  # noqa: E402

import localization.confidence as live  # noqa: E402
from benchmarks import pose_check_before as before  # noqa: E402  (the frozen copy)


def record(full: bool, sessions: int | None) -> tuple[list, list]:
    """Run the main job with ``PoseCheck.verdict`` wrapped: (the checks' maps, the calls
    (check index, scan, robot pose, mount, covariance, verdict) in order)."""
    from mapupdate.main import main

    grids, calls, index = [], [], {}
    verdict = live.PoseCheck.verdict

    def wrapped(self, scan, robot_pose, sensor_mount, cov=None):
        if id(self) not in index:
            index[id(self)] = len(grids)
            grids.append(self._grid_for_bench)
        v = verdict(self, scan, robot_pose, sensor_mount, cov)
        calls.append((index[id(self)], scan, robot_pose, sensor_mount,
                      None if cov is None else np.array(cov), v))
        return v

    init = live.PoseCheck.__init__

    def keep_grid(self, grid, config=None):
        init(self, grid, config)
        self._grid_for_bench = grid

    live.PoseCheck.__init__, live.PoseCheck.verdict = keep_grid, wrapped
    try:
        with tempfile.TemporaryDirectory() as out:
            argv = ["run", "--no-progress", "--out", out] + ([] if full else ["--quick"])
            argv += [] if sessions is None else ["--sessions", str(sessions)]
            main(argv)
    finally:
        live.PoseCheck.__init__, live.PoseCheck.verdict = init, verdict
    return grids, calls


def same_fit(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return (a.fit, a.gain, a.correction, a.beams) == (b.fit, b.gain, b.correction, b.beams)


def replay(grids, calls, repeat: int) -> tuple[float, float, list[str]]:
    """One pass over the calls on fresh checks: (before's CPU seconds, after's, differences).
    Odd passes call the live check first."""
    checks = {"before": [before.PoseCheck(g) for g in grids],
              "after": [live.PoseCheck(g) for g in grids]}
    order = ("after", "before") if repeat % 2 else ("before", "after")
    spent = {"before": 0.0, "after": 0.0}
    diffs = []
    for n, (k, scan, pose, mount, cov, want) in enumerate(calls):
        got = {}
        for which in order:
            t0 = time.thread_time()
            got[which] = checks[which][k].verdict(scan, pose, mount, cov)
            spent[which] += time.thread_time() - t0
        if not got["before"] == got["after"] == want:
            diffs.append(f"call {n}: before {got['before']}, after {got['after']}, "
                         f"main job {want}")
        if repeat == 0 and not same_fit(checks["before"][k].fit(scan, pose, mount),
                                        checks["after"][k].fit(scan, pose, mount)):
            diffs.append(f"call {n}: the fits differ")
    return spent["before"], spent["after"], diffs


def machine() -> str:
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in subprocess.run(
            ["lscpu"], capture_output=True, text=True).stdout.splitlines()
            if line.startswith("Model name"))
    except (OSError, StopIteration):
        cpu = platform.processor() or "unknown CPU"
    return (f"{cpu}; Python {platform.python_version()}, numpy {np.__version__}, "
            f"numba {numba.__version__}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--full", action="store_true", help="the full main job, not --quick")
    ap.add_argument("--sessions", type=int, default=None, help="only the first K sessions")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--bar", type=float, default=2.0, help="least before / after CPU ratio")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    grids, calls = record(args.full, args.sessions)
    kinds = [c[5].verdict.value for c in calls]
    print(f"{machine()}\n{len(calls)} calls of PoseCheck.verdict on {len(grids)} maps "
          f"({', '.join(f'{kinds.count(v)} {v}' for v in sorted(set(kinds)))}), recorded in "
          f"{time.perf_counter() - t0:.0f} s")
    replay(grids, calls[:5], 0)               # compile or load both before timing
    ratios, diffs = [], []
    print("| pass | before s | after s | before ms / call | after ms / call | before / after |\n"
          "|---|---|---|---|---|---|")
    for r in range(args.repeats):
        b, a, d = replay(grids, calls, r)
        diffs += d
        ratios.append(b / a)
        print(f"| {r + 1} | {b:.3f} | {a:.3f} | {1e3 * b / len(calls):.3f} | "
              f"{1e3 * a / len(calls):.3f} | {b / a:.2f} |")
    ratio = statistics.median(ratios)
    print(f"\nmedian before / after {ratio:.2f} (bar {args.bar:g}); "
          f"{'no verdict or fit differs' if not diffs else f'{len(diffs)} differences'}")
    for d in diffs[:10]:
        print(d)
    return 1 if diffs or ratio < args.bar else 0


if __name__ == "__main__":
    raise SystemExit(main())
