"""Timings of the Monte Carlo localiser, single thread, after compilation; medians.

    python benchmarks/bench_localization.py [--repeat N] [--json PATH]

Rows: the sensor update alone (likelihood field, all particles x 60 beams), a full filter update
(odometry motion model, sensor update, cluster estimate, KLD resampling) at 2000 and 10 000
particles, its parts, and filterpy's systematic resampler (tests/filterpy_reference.py) against
the reimplementation used. Exits 1 when a bar is missed. The world is synthetic_warehouse's
warehouse (5 cm map, 1081-beam lidar).

Before and after: ``python benchmarks/run.py --baseline REV localization`` runs this script on
a git revision's packages and on the working tree's and sets the rows side by side, with
whether the full updates left the same particles and weights (``--json``: the times and the
particles' digests).
"""

from __future__ import annotations

import os

for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(HERE.parent))

import synthetic_warehouse as syn  # noqa: E402  (the tests' synthetic warehouse)
from figures import Figures, add_option  # noqa: E402

from gridmap import Pose2D  # noqa: E402
from localization import LocalizerConfig, MonteCarloLocalizer  # noqa: E402
from localization.estimate import estimate  # noqa: E402
from localization.motion import sample_motion  # noqa: E402
from localization.resample import Scratch, kld_resample, resample_indices  # noqa: E402
from localization.sensor import likelihood_field, select_beams  # noqa: E402

BARS = {"sensor update, 2000 particles x 60 beams": 2.0,
        "full update, 2000 particles": 4.0,
        "full update, 10000 particles": 4.0}


def median_ms(fn, repeat: int) -> float:
    """Median ms of ``repeat`` calls of ``fn``, after one call to compile."""
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * float(np.median(times))


def tour(n_scans: int):
    layout = syn.warehouse()
    truth, grid = syn.truth_grid(layout), syn.map_grid(layout)
    rng = np.random.default_rng(0)
    poses = syn.route_poses(syn.ROUTE)[:n_scans]
    odom = syn.corrupt_odometry(poses, (0.05, 0.01, 0.05, 0.01), rng)
    lidar = syn.Lidar()
    return grid, lidar, poses, odom, [lidar.scan(truth, p, rng) for p in poses]


def full_update_ms(grid, lidar, poses, odom, scans, n: int, repeat: int,
                   figures: Figures) -> float:
    """loc.update() on scans 0.3 m apart, so every call is a filter update; the particle count
    is pinned (min = max) so the row measures n particles. The particles and weights after
    the last update go to ``figures`` as an output."""
    config = LocalizerConfig(min_particles=n, max_particles=n)
    loc = MonteCarloLocalizer(grid, config, seed=0)
    times, i = [], len(scans)
    while len(times) < repeat + 3:
        i += 5
        if i >= len(scans):                  # (re)start the tour
            loc.initialize(poses[0], np.diag([0.01, 0.01, 0.0025]))
            loc.update(odom[0], scans[0], lidar.mount)
            i = 5
        t = time.perf_counter()
        updated = loc.update(odom[i], scans[i], lidar.mount)
        times.append(time.perf_counter() - t)
        if not updated:                      # odometry noise can leave a step under 0.25 m
            times.pop()
    figures.output(f"full update, {n} particles: particles and weights after the last",
                   loc.particles, loc.weights)
    return 1e3 * float(np.median(times[3:]))


def part_rows(loc, lidar, beams, pose, n: int, repeat: int, rng) -> list:
    """(name, ms) of each part of an update on n particles around ``pose``."""
    parts = pose.as_array() + rng.normal(0, [0.1, 0.1, 0.05], (n, 3))
    w = rng.random(n)
    w /= w.sum()
    kld = type(loc._kld)(n, n, 0.05, 0.99, loc._kld.bin_size)
    scratch, noise = Scratch(), np.empty((n, 3))
    step = (Pose2D(0, 0, 0), Pose2D(0.3, 0.01, 0.05), (0.2,) * 4)
    rows = [
        (f"sensor update, {n} particles x {beams.count} beams",
         median_ms(lambda: likelihood_field(loc._field, parts, lidar.mount, beams), repeat)),
        (f"  motion model, {n} particles",
         median_ms(lambda: sample_motion(parts.copy(), *step, rng, noise), repeat)),
        (f"  cluster estimate, {n} particles",
         median_ms(lambda: estimate(parts, w, kld, scratch), repeat)),
        (f"  KLD resample, {n} particles",
         median_ms(lambda: kld_resample(parts, w, kld, rng, scratch=scratch), repeat)),
        (f"  systematic indices (ours), {n}",
         median_ms(lambda: resample_indices(w, n, rng), repeat))]
    try:
        from filterpy_reference import filterpy_indices
    except ImportError:                      # filterpy is a test dependency
        return rows
    return rows + [(f"  systematic indices (filterpy, seeded), {n}",
                    median_ms(lambda: filterpy_indices(w, rng), max(10, repeat // 10)))]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=200, help="timed runs per row")
    add_option(parser)
    args = parser.parse_args(argv)
    grid, lidar, poses, odom, scans = tour(400)
    rows, figures = [], Figures()
    rng = np.random.default_rng(1)
    loc = MonteCarloLocalizer(grid, seed=0)
    beams = select_beams(scans[50], 60)
    for n in (2000, 10000):
        rows += part_rows(loc, lidar, beams, poses[50], n, args.repeat, rng)
        rows.append((f"full update, {n} particles",
                     full_update_ms(grid, lidar, poses, odom, scans, n, args.repeat, figures)))
    for name, ms in rows:
        figures.add(name.strip(), ms, "ms")
    figures.write(args.json)
    return report(rows, beams, scans, grid)


def report(rows, beams, scans, grid) -> int:
    width = max(len(name) for name, _ in rows)
    print(f"{'localiser (single thread, median ms)':<{width}}  {'ms':>8}  {'bar':>6}")
    missed = []
    for name, ms in rows:
        bar = BARS.get(name.replace(f"x {beams.count} beams", "x 60 beams"))
        mark = "" if bar is None else f"{bar:6.1f} {'ok' if ms <= bar else 'OVER'}"
        if bar is not None and ms > bar:
            missed.append(name)
        print(f"{name:<{width}}  {ms:8.3f}  {mark}")
    print(f"(beams used: {beams.count}; scan of {scans[50].beams} beams; "
          f"map {grid.width} x {grid.height} cells at {grid.resolution} m; {len(scans)} scans)")
    if missed:
        print("bar missed: " + "; ".join(missed))
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
