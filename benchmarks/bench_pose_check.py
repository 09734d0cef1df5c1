"""Benchmark: the pose check and its refinement (``PoseCheck.verdict``) on the main job's own
calls.

The main job (``mapupdate run``, by default its quick variant) runs once with
``PoseCheck.verdict`` wrapped to record every call: the check's map, the scan, the robot pose,
the lidar mount and the localiser's covariance, in order. Those calls are then replayed on
fresh checks of the same maps, ``--repeats`` times, each call timed with the thread's CPU time
(``time.thread_time``), so that other work on the machine counts as little as it can. Every
replayed verdict (refused with its reason, or refined with its sensor pose) must equal the one
the main job got.

Before and after: ``python benchmarks/run.py --baseline REV pose_check`` runs this script on a
git revision's packages and on the working tree's and sets the CPU times side by side, with
whether the verdicts and the fits (``PoseCheck.fit``: the fit, the gain and the correction,
to the bit) are the same (``--json``: the times and the digests of the verdicts and fits).

    python benchmarks/bench_pose_check.py [--full] [--sessions K] [--repeats N] [--json PATH]

Exit 1 when a replayed verdict differs from the main job's.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(Path(__file__).resolve().parents[1]))

import numba  # noqa: E402
import numpy as np  # noqa: E402

import localization.confidence as live  # noqa: E402
from figures import Figures, add_option  # noqa: E402


def record(full: bool, sessions: int | None) -> tuple[list, list]:
    """Run the main job with ``PoseCheck.verdict`` wrapped: (the checks' maps and
    configurations, the calls (check index, scan, robot pose, mount, covariance, verdict) in
    order)."""
    from mapupdate.main import main

    grids, calls, index = [], [], {}
    verdict = live.PoseCheck.verdict

    def wrapped(self, scan, robot_pose, sensor_mount, cov=None):
        if id(self) not in index:
            index[id(self)] = len(grids)
            grids.append((self._grid_for_bench, self._config_for_bench))
        v = verdict(self, scan, robot_pose, sensor_mount, cov)
        calls.append((index[id(self)], scan, robot_pose, sensor_mount,
                      None if cov is None else np.array(cov), v))
        return v

    init = live.PoseCheck.__init__

    def keep_grid(self, grid, config=None):
        init(self, grid, config)
        self._grid_for_bench, self._config_for_bench = grid, config

    live.PoseCheck.__init__, live.PoseCheck.verdict = keep_grid, wrapped
    try:
        with tempfile.TemporaryDirectory() as out:
            argv = ["run", "--no-progress", "--out", out] + ([] if full else ["--quick"])
            argv += [] if sessions is None else ["--sessions", str(sessions)]
            main(argv)
    finally:
        live.PoseCheck.__init__, live.PoseCheck.verdict = init, verdict
    return grids, calls


def fit_values(fit) -> tuple | None:
    return None if fit is None else (fit.fit, fit.gain, fit.correction, fit.beams)


def replay(grids, calls, first: bool) -> tuple[float, list[str], list]:
    """One pass over the calls on fresh checks: (CPU seconds, differences from the main
    job's verdicts, and on the ``first`` pass the verdicts and fits)."""
    checks = [live.PoseCheck(grid, config) for grid, config in grids]
    spent, diffs, got = 0.0, [], []
    for n, (k, scan, pose, mount, cov, want) in enumerate(calls):
        t0 = time.thread_time()
        verdict = checks[k].verdict(scan, pose, mount, cov)
        spent += time.thread_time() - t0
        if verdict != want:
            diffs.append(f"call {n}: replayed {verdict}, main job {want}")
        if first:
            got.append((verdict, fit_values(checks[k].fit(scan, pose, mount))))
    return spent, diffs, got


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
    add_option(ap)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    grids, calls = record(args.full, args.sessions)
    kinds = [c[5].verdict.value for c in calls]
    print(f"{machine()}\n{len(calls)} calls of PoseCheck.verdict on {len(grids)} maps "
          f"({', '.join(f'{kinds.count(v)} {v}' for v in sorted(set(kinds)))}), recorded in "
          f"{time.perf_counter() - t0:.0f} s")
    if not calls:
        print("nothing to time: the sessions run made no pose check (the first maps M1)")
        return 2
    replay(grids, calls[:5], False)           # compile or load before timing
    seconds, diffs, got = [], [], []
    print("| pass | CPU s | ms / call |\n|---|---|---|")
    for r in range(args.repeats):
        spent, d, g = replay(grids, calls, r == 0)
        seconds.append(spent)
        diffs += d
        got += g
        print(f"| {r + 1} | {spent:.3f} | {1e3 * spent / len(calls):.3f} |")
    median = statistics.median(seconds)
    print(f"\nmedian {median:.3f} s, {1e3 * median / len(calls):.3f} ms per call; "
          f"{'no verdict differs from the main job' if not diffs else f'{len(diffs)} differ'}")
    for d in diffs[:10]:
        print(d)
    out = Figures()
    out.add("CPU per pass over the calls (median)", median, "s")
    out.add("CPU per call (median pass)", 1e3 * median / len(calls), "ms")
    out.output(f"verdicts of the {len(calls)} calls", [v for v, _ in got])
    out.output(f"fits of the {len(calls)} calls", [f for _, f in got])
    out.write(args.json)
    return 1 if diffs else 0


if __name__ == "__main__":
    raise SystemExit(main())
