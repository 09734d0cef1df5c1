"""Timings of the Monte Carlo localiser, single thread, after compilation; medians, before and
after its fused kernels side by side.

    python benchmarks/bench_localization.py [--repeat N]

Rows: the sensor update alone (likelihood field, all particles x 60 beams), a full filter update
(odometry motion model, sensor update, cluster estimate, KLD resampling) at 2000 and 10 000
particles, its parts, and filterpy's systematic resampler against the reimplementation used.
"before" is the frozen copy of the code before the fused kernels (benchmarks/localization_before),
timed in the same process, the two calls alternating, so that load from other work on the
machine falls on both alike. The full updates of both filters are checked to give the same
particles and estimates. Exits 1 when a bar is missed. The world is synthetic_warehouse's
warehouse (5 cm map, 1081-beam lidar).
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
sys.path.insert(0, str(HERE))

import localization_before as before  # noqa: E402  (the frozen copy)
import synthetic_warehouse as syn  # noqa: E402  (the tests' synthetic warehouse)
from localization_before import estimate as before_estimate  # noqa: E402
from localization_before import motion as before_motion  # noqa: E402
from localization_before import resample as before_resample  # noqa: E402
from localization_before import sensor as before_sensor  # noqa: E402

from gridmap import Pose2D  # noqa: E402
from localization import LocalizerConfig, MonteCarloLocalizer  # noqa: E402
from localization.estimate import estimate  # noqa: E402
from localization.motion import sample_motion  # noqa: E402
from localization.resample import (Scratch, filterpy_indices, kld_resample,  # noqa: E402
                                   resample_indices)
from localization.sensor import likelihood_field, select_beams  # noqa: E402

BARS = {"sensor update, 2000 particles x 60 beams": 2.0,
        "full update, 2000 particles": 4.0,
        "full update, 10000 particles": 4.0}


def median_pair(fn_before, fn_after, repeat: int) -> tuple[float, float]:
    """Median ms of each function, the calls alternating, after one call each to compile."""
    fn_before(), fn_after()
    times = ([], [])
    for _ in range(repeat):
        for k, fn in enumerate((fn_before, fn_after)):
            t = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t)
    return tuple(1e3 * float(np.median(ts)) for ts in times)


def median_ms(fn, repeat: int) -> float:
    return median_pair(fn, fn, (repeat + 1) // 2)[0]


def tour(n_scans: int):
    layout = syn.warehouse()
    truth, grid = syn.truth_grid(layout), syn.map_grid(layout)
    rng = np.random.default_rng(0)
    poses = syn.route_poses(syn.ROUTE)[:n_scans]
    odom = syn.corrupt_odometry(poses, (0.05, 0.01, 0.05, 0.01), rng)
    lidar = syn.Lidar()
    return grid, lidar, poses, odom, [lidar.scan(truth, p, rng) for p in poses]


def full_update_ms(grid, lidar, poses, odom, scans, n: int, repeat: int) -> tuple[float, float]:
    """loc.update() of the filter before and after on scans 0.3 m apart, so every call is a
    filter update, the two alternating; the particle count is pinned (min = max) so the row
    measures n particles. Both must hold the same particles and estimate after every update."""
    config = LocalizerConfig(min_particles=n, max_particles=n)
    pair = (before.MonteCarloLocalizer(grid, config, seed=0),
            MonteCarloLocalizer(grid, config, seed=0))
    times, i = ([], []), len(scans)
    while len(times[1]) < repeat + 3:
        i += 5
        if i >= len(scans):                  # (re)start the tour
            for loc in pair:
                loc.initialize(poses[0], np.diag([0.01, 0.01, 0.0025]))
                loc.update(odom[0], scans[0], lidar.mount)
            i = 5
        updated = []
        for k, loc in enumerate(pair):
            t = time.perf_counter()
            updated.append(loc.update(odom[i], scans[i], lidar.mount))
            times[k].append(time.perf_counter() - t)
        same_filter(*pair)
        if not all(updated):                 # odometry noise can leave a step under 0.25 m
            for ts in times:
                ts.pop()
    return tuple(1e3 * float(np.median(ts[3:])) for ts in times)


def same_filter(old, new) -> None:
    e_old, e_new = old.estimate(), new.estimate()
    if not (np.array_equal(old._particles, new._particles)
            and np.array_equal(old._weights, new._weights) and e_old.pose == e_new.pose
            and np.array_equal(e_old.cov, e_new.cov)):
        raise SystemExit("the filters before and after differ: the timings compare nothing")


def part_rows(loc, lidar, beams, pose, n: int, repeat: int, rng) -> list:
    """(name, ms before, ms after) of each part of an update on n particles around ``pose``."""
    parts = pose.as_array() + rng.normal(0, [0.1, 0.1, 0.05], (n, 3))
    w = rng.random(n)
    w /= w.sum()
    old_field = before_sensor.LikelihoodField(loc.grid, *[getattr(loc._field, a) for a in (
        "max_dist", "z_hit", "z_rand", "sigma_hit", "model", "importance_factor")])
    kld = type(loc._kld)(n, n, 0.05, 0.99, loc._kld.bin_size)
    old_kld = before_resample.KldParameters(n, n, 0.05, 0.99, loc._kld.bin_size)
    scratch, noise = Scratch(), np.empty((n, 3))
    step = (Pose2D(0, 0, 0), Pose2D(0.3, 0.01, 0.05), (0.2,) * 4)
    return [
        (f"sensor update, {n} particles x {beams.count} beams", *median_pair(
            lambda: before_sensor.likelihood_field(old_field, parts, lidar.mount, beams),
            lambda: likelihood_field(loc._field, parts, lidar.mount, beams), repeat)),
        (f"  motion model, {n} particles", *median_pair(
            lambda: before_motion.sample_motion(parts.copy(), *step, rng),
            lambda: sample_motion(parts.copy(), *step, rng, noise), repeat)),
        (f"  cluster estimate, {n} particles", *median_pair(
            lambda: before_estimate.estimate(parts, w, old_kld),
            lambda: estimate(parts, w, kld, scratch), repeat)),
        (f"  KLD resample, {n} particles", *median_pair(
            lambda: before_resample.kld_resample(parts, w, old_kld, rng),
            lambda: kld_resample(parts, w, kld, rng, scratch=scratch), repeat)),
        (f"  systematic indices (ours), {n}", *median_pair(
            lambda: before_resample.resample_indices(w, n, rng),
            lambda: resample_indices(w, n, rng), repeat)),
        (f"  systematic indices (filterpy, seeded), {n}", None,
         median_ms(lambda: filterpy_indices(w, rng), max(10, repeat // 10)))]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=200, help="timed runs per row")
    args = parser.parse_args(argv)
    grid, lidar, poses, odom, scans = tour(400)
    rows = []
    rng = np.random.default_rng(1)
    loc = MonteCarloLocalizer(grid, seed=0)
    beams = select_beams(scans[50], 60)
    for n in (2000, 10000):
        rows += part_rows(loc, lidar, beams, poses[50], n, args.repeat, rng)
        rows.append((f"full update, {n} particles",
                     *full_update_ms(grid, lidar, poses, odom, scans, n, args.repeat)))
    return report(rows, beams, scans, grid)


def report(rows, beams, scans, grid) -> int:
    width = max(len(name) for name, *_ in rows)
    print(f"{'localiser (single thread, median ms)':<{width}}  {'before':>8}  {'after':>8}  "
          f"{'bar':>6}")
    missed = []
    for name, old_ms, new_ms in rows:
        bar = BARS.get(name.replace(f"x {beams.count} beams", "x 60 beams"))
        mark = "" if bar is None else f"{bar:6.1f} {'ok' if new_ms <= bar else 'OVER'}"
        if bar is not None and new_ms > bar:
            missed.append(name)
        old = "" if old_ms is None else f"{old_ms:8.3f}"
        print(f"{name:<{width}}  {old:>8}  {new_ms:8.3f}  {mark}")
    print(f"(beams used: {beams.count}; scan of {scans[50].beams} beams; "
          f"map {grid.width} x {grid.height} cells at {grid.resolution} m; "
          f"{len(scans)} scans; the filters before and after gave the same particles and "
          f"estimates at every update)")
    if missed:
        print("bar missed: " + "; ".join(missed))
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
