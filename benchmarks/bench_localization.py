"""Timings of the Monte Carlo localiser, single thread, after compilation; medians.

    python benchmarks/bench_localization.py [--repeat N]

Rows: the sensor update alone (likelihood field, all particles x 60 beams), a full filter update
(odometry motion model, sensor update, cluster estimate, KLD resampling) at 2000 and 10 000
particles, its parts, and filterpy's systematic resampler against the reimplementation used.
The world is synthetic_warehouse's warehouse (5 cm map, 1081-beam lidar).
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

from gridmap import Pose2D  # noqa: E402
from localization import LocalizerConfig, MonteCarloLocalizer  # noqa: E402
from localization.estimate import estimate  # noqa: E402
from localization.motion import sample_motion  # noqa: E402
from localization.resample import (filterpy_indices, kld_resample,  # noqa: E402
                                   resample_indices)
from localization.sensor import likelihood_field, select_beams  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import synthetic_warehouse as syn  # noqa: E402  (the tests' synthetic warehouse)

BARS = {"sensor update, 2000 particles x 60 beams": 2.0,
        "full update, 2000 particles": 4.0,
        "full update, 10000 particles": 10.0}


def median_ms(fn, repeat: int) -> float:
    fn()                                      # compile / warm caches
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


def full_update_ms(grid, lidar, poses, odom, scans, n: int, repeat: int) -> float:
    """loc.update() on scans 0.3 m apart, so every call is a filter update; the particle count
    is pinned (min = max) so the row measures n particles."""
    config = LocalizerConfig(min_particles=n, max_particles=n)
    loc = MonteCarloLocalizer(grid, config, seed=0)
    loc.initialize(poses[0], np.diag([0.01, 0.01, 0.0025]))
    loc.update(odom[0], scans[0], lidar.mount)
    times, i = [], 0
    while len(times) < repeat + 3:
        i += 5
        if i >= len(scans):                  # start the tour again
            loc.initialize(poses[0], np.diag([0.01, 0.01, 0.0025]))
            loc.update(odom[0], scans[0], lidar.mount)
            i = 5
        t = time.perf_counter()
        updated = loc.update(odom[i], scans[i], lidar.mount)
        dt = time.perf_counter() - t
        if updated:                          # odometry noise can leave a step under 0.25 m
            assert loc.particle_count == n
            times.append(dt)
    return 1e3 * float(np.median(times[3:]))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=200, help="timed runs per row")
    args = parser.parse_args(argv)
    grid, lidar, poses, odom, scans = tour(400)
    rows = []
    rng = np.random.default_rng(1)
    loc = MonteCarloLocalizer(grid, seed=0)
    beams = select_beams(scans[50], 60)
    for n in (2000, 10000):
        parts = poses[50].as_array() + rng.normal(0, [0.1, 0.1, 0.05], (n, 3))
        w = rng.random(n)
        w /= w.sum()
        rows.append((f"sensor update, {n} particles x {beams.count} beams", median_ms(
            lambda: likelihood_field(loc._field, parts, lidar.mount, beams), args.repeat)))
        rows.append((f"  motion model, {n} particles", median_ms(
            lambda: sample_motion(parts.copy(), Pose2D(0, 0, 0), Pose2D(0.3, 0.01, 0.05),
                                  (0.2,) * 4, rng), args.repeat)))
        rows.append((f"  cluster estimate, {n} particles", median_ms(
            lambda: estimate(parts, w, loc._kld), args.repeat)))
        kld = type(loc._kld)(n, n, 0.05, 0.99, loc._kld.bin_size)
        rows.append((f"  KLD resample, {n} particles", median_ms(
            lambda: kld_resample(parts, w, kld, rng), args.repeat)))
        rows.append((f"  systematic indices (ours), {n}", median_ms(
            lambda: resample_indices(w, n, rng), args.repeat)))
        rows.append((f"  systematic indices (filterpy, seeded), {n}", median_ms(
            lambda: filterpy_indices(w, rng), max(10, args.repeat // 10))))
        rows.append((f"full update, {n} particles",
                     full_update_ms(grid, lidar, poses, odom, scans, n, args.repeat)))
    width = max(len(name) for name, _ in rows)
    print(f"{'localiser (single thread, median)':<{width}}  {'ms':>8}  {'bar':>6}")
    for name, ms in rows:
        bar = BARS.get(name.replace(f"x {beams.count} beams", "x 60 beams"))
        mark = "" if bar is None else f"{bar:6.1f} {'ok' if ms <= bar else 'OVER'}"
        print(f"{name:<{width}}  {ms:8.3f}  {mark}")
    print(f"(beams used: {beams.count}; scan of {scans[50].beams} beams; "
          f"map {grid.width} x {grid.height} cells at {grid.resolution} m; "
          f"{len(scans)} scans)")


if __name__ == "__main__":
    main()
