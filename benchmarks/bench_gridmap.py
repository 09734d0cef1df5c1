"""Benchmarks of the grid core on the paper's warehouse size: 280 x 420 cells at 5 cm.

The grid is a plausible small warehouse (outer walls, rack rows, pallets, drums) rasterised the
way ground truth is: occupied outlines, unknown interiors and outside. Times are medians of many
runs after compilation. Run: ``python benchmarks/bench_gridmap.py``.
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

import numpy as np

# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(Path(__file__).resolve().parents[1]))

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan  # noqa: E402

RES = 0.05
WIDTH, HEIGHT = 280, 420           # cells: 14.0 x 21.0 m
ORIGIN = (-7.0, -10.5)
BOUNDS = (-6.85, -10.32, 6.85, 10.32)  # inner faces of the outer walls [m]


def warehouse(pallets, drums) -> OccupancyGrid:
    """Free = cell centres inside the walls and outside every object; occupied = object or wall
    cells touching free space (8-neighbours); unknown elsewhere."""
    xs = ORIGIN[0] + (np.arange(WIDTH) + 0.5) * RES
    ys = ORIGIN[1] + (np.arange(HEIGHT) + 0.5) * RES
    x, y = np.meshgrid(xs, ys)
    x0, y0, x1, y1 = BOUNDS
    inside = (x > x0) & (x < x1) & (y > y0) & (y < y1)
    solid = ~inside
    racks = [(-5.8, cy, 2.1, 0.9) for cy in np.arange(-7.5, 8.0, 2.5)]
    racks += [(5.8, cy, 2.1, 0.9) for cy in np.arange(-7.5, 8.0, 2.5)]
    racks += [(cx, cy, 3.6, 0.9) for cx in (-2.2, 2.2) for cy in (-4.0, -1.0, 2.0, 5.0)]
    for cx, cy, w, h in racks + list(pallets):
        solid |= (np.abs(x - cx) < w / 2) & (np.abs(y - cy) < h / 2)
    for cx, cy, r in drums:
        solid |= np.hypot(x - cx, y - cy) < r
    free = inside & ~solid
    near = free.copy()
    near[1:] |= free[:-1]
    near[:-1] |= free[1:]
    near[:, 1:] |= near[:, :-1].copy()
    near[:, :-1] |= near[:, 1:].copy()
    data = np.full((HEIGHT, WIDTH), UNKNOWN, np.int8)
    data[free] = FREE
    data[solid & near] = OCCUPIED
    return OccupancyGrid(data, RES, ORIGIN)


PALLETS = [(0.0, 8.5, 1.2, 0.8), (-3.5, 8.8, 1.2, 0.8), (3.0, -8.8, 0.8, 1.2), (0.3, 0.5, 1.2, 0.8)]
DRUMS = [(0.4, 9.6, 0.3), (-0.5, -6.0, 0.3)]
# The same warehouse a session later: two pallets moved, a drum gone, a pallet added.
PALLETS_2 = [(0.0, 8.5, 1.2, 0.8), (-1.0, 7.0, 1.2, 0.8), (3.0, -8.8, 0.8, 1.2),
             (1.0, -2.5, 0.8, 1.2), (-4.0, -9.0, 1.2, 0.8)]
DRUMS_2 = [(0.4, 9.6, 0.3)]


def median_ms(fn, runs: int) -> float:
    fn()  # compile / warm up
    t = np.empty(runs)
    for i in range(runs):
        t0 = time.perf_counter()
        fn()
        t[i] = time.perf_counter() - t0
    return float(np.median(t) * 1e3)


def random_free_poses(grid: OccupancyGrid, n: int, rng) -> list[Pose2D]:
    rows, cols = np.nonzero(grid.data == FREE)
    pick = rng.choice(rows.size, n, replace=False)
    x, y = grid.cell_to_world(rows[pick], cols[pick])
    return [Pose2D(float(a), float(b), float(t)) for a, b, t in
            zip(x, y, rng.uniform(-math.pi, math.pi, n))]


def main() -> int:
    from gridmap.mapping import LogOddsMapper
    from gridmap.metrics import compare_maps, opdf
    from gridmap.raycast import cast_rays

    g1 = warehouse(PALLETS, DRUMS)
    g2 = warehouse(PALLETS_2, DRUMS_2)
    beams = 1081
    angles = np.linspace(-0.75 * math.pi, 0.75 * math.pi, beams)
    aisle = Pose2D(0.25, -8.0, math.pi / 2)  # the robot's start, looking down the main aisle
    poses = random_free_poses(g1, 50, np.random.default_rng(1))
    r = cast_rays(g1, aisle, angles, 20.0)
    mean_range = float(r[np.isfinite(r)].mean())

    rows = []

    def add(name, ms, bar=None):
        ok = "" if bar is None else ("yes" if ms <= bar else "NO")
        rows.append((name, ms, "" if bar is None else f"<= {bar:g}", ok))

    add(f"cast_rays {beams} beams, 20 m, aisle pose (mean range {mean_range:.1f} m)",
        median_ms(lambda: cast_rays(g1, aisle, angles, 20.0), 3000), 0.5)
    add(f"cast_rays {beams} beams, occupied or unknown blocks",
        median_ms(lambda: cast_rays(g1, aisle, angles, 20.0, True), 3000))
    per_pose = [median_ms(lambda p=p: cast_rays(g1, p, angles, 20.0), 200) for p in poses]
    add(f"cast_rays {beams} beams, median of 50 random free poses", float(np.median(per_pose)),
        0.5)
    add("cast_rays worst of those 50 poses", float(np.max(per_pose)))
    add("opdf of two 280 x 420 maps", median_ms(lambda: opdf(g1, g2), 300), 50.0)
    add("compare_maps (CC, MS, OPDF)", median_ms(lambda: compare_maps(g1, g2), 100))

    # One scan integrated into a log-odds map (simulated 1081-beam scan, 20 m).
    ranges = cast_rays(g1, aisle, angles, 20.0).astype(np.float32)
    scan = Scan(ranges, float(angles[0]), float(angles[1] - angles[0]), 0.05, 20.0)
    mapper = LogOddsMapper(g1)
    add(f"log-odds mapping, one {beams}-beam scan", median_ms(lambda: mapper.add_scan(scan, aisle),
                                                               500))

    m = compare_maps(g1, g2)
    width = max(len(r[0]) for r in rows)
    print(f"gridmap: {WIDTH} x {HEIGHT} cells at {RES * 100:g} cm, warehouse with "
          f"{(g1.data == OCCUPIED).sum()} occupied cells; g1 vs g2: CC {m['cc']:.2f} %, "
          f"MS {m['ms']:.2f} %, OPDF {m['opdf']:.2f} %")
    print(f"| {'benchmark':<{width}} | median ms | bar ms  | ok  |")
    print(f"|{'-' * (width + 2)}|-----------|---------|-----|")
    for name, ms, bar, ok in rows:
        print(f"| {name:<{width}} | {ms:9.3f} | {bar:<7} | {ok:<3} |")
    return 0 if all(r[3] != "NO" for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
