"""The pose check's grid kernels against plain NumPy written from their definitions and against
the per-pose kernels they replace, on seeded random inputs; and the whole check (verdict,
refine, fit) on random scans in a synthetic room against what the code before the grid
kernels gave on them, recorded in ``tests/data/golden/pose_check_*.npz``
(tests/data/golden/README.md): the same verdicts, refined poses and fits, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D, Scan
from localization import _kernels as k
from localization.confidence import PoseCheck, PoseCheckConfig, SearchGrid, search_grid
from tests.data.golden import golden

import synthetic_room as world


def random_grid(rng, h=41, w=57):
    data = np.where(rng.random((h, w)) < 0.12, OCCUPIED, FREE).astype(np.int8)
    return OccupancyGrid(data, 0.05, (-0.4, -0.3))


def random_case(rng, grid, n_beams=40):
    """A base pose on, near or off the map, a mount, beams reaching off every side, and a
    grid of offsets with steps below and above a cell."""
    base = np.array([rng.uniform(-1.0, 3.2), rng.uniform(-0.8, 2.3), rng.uniform(-4, 4)])
    mount = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.1, 0.1), rng.uniform(-0.5, 0.5)])
    beams = rng.uniform(-2.0, 2.0, (n_beams, 2))
    g = SearchGrid(rng.choice([0.005, 0.025, 0.07]), int(rng.integers(0, 5)),
                   math.radians(rng.choice([0.1, 0.5, 3.0])), int(rng.integers(0, 4)))
    return base, mount, beams, g


def grid_poses(base, g: SearchGrid) -> np.ndarray:
    """The grid's poses in the kernels' axis order (x slowest, heading fastest)."""
    xs, ys, ts = np.meshgrid(g.xy, g.xy, g.turns, indexing="ij")
    return np.column_stack((base[0] + xs.ravel(), base[1] + ys.ravel(), base[2] + ts.ravel()))


def end_points(pose, mount, beams):
    """The beams' end points in the map frame, straight from the poses' definition."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    sx, sy = x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1]
    a = th + mount[2]
    return (sx + math.cos(a) * beams[:, 0] - math.sin(a) * beams[:, 1],
            sy + math.sin(a) * beams[:, 0] + math.cos(a) * beams[:, 1])


def reference_sums(poses, mount, beams, table, frame, off_value):
    """Plain NumPy: the table at each end point's cell, off_value off the grid, summed."""
    ox, oy, res = frame
    h, w = table.shape
    out = []
    for pose in poses:
        px, py = end_points(pose, mount, beams)
        gx, gy = np.floor((px - ox) / res), np.floor((py - oy) / res)
        inside = (gx >= 0) & (gy >= 0) & (gx < w) & (gy < h)
        vals = np.full(len(beams), off_value)
        vals[inside] = table[gy[inside].astype(int), gx[inside].astype(int)]
        out.append(vals.sum())
    return np.array(out)


def reference_interpolated(poses, mount, beams, residual, frame):
    """Plain NumPy: the residual interpolated bilinearly between cell centres, squared and
    averaged; 1 off the grid."""
    ox, oy, res = frame
    h, w = residual.shape
    out = []
    for pose in poses:
        px, py = end_points(pose, mount, beams)
        gx, gy = (px - ox) / res - 0.5, (py - oy) / res - 0.5
        inside = (gx >= 0) & (gy >= 0) & (gx <= w - 1) & (gy <= h - 1)
        c0 = np.minimum(np.floor(gx[inside]), w - 2).astype(int)
        r0 = np.minimum(np.floor(gy[inside]), h - 2).astype(int)
        fx, fy = gx[inside] - c0, gy[inside] - r0
        r = residual.astype(np.float64)
        v = (r[r0, c0] * (1 - fx) + r[r0, c0 + 1] * fx) * (1 - fy) + \
            (r[r0 + 1, c0] * (1 - fx) + r[r0 + 1, c0 + 1] * fx) * fy
        out.append((np.sum(v * v) + np.count_nonzero(~inside)) / len(beams))
    return np.array(out)


def table_sums(base, mount, beams, table, frame, g, floor=-np.inf):
    out = np.empty(g.size)
    k.grid_table_sums(base=base, mount=mount, beams=beams, table=table, frame=frame,
                      off_value=-1.0, xs=g.xy, ys=g.xy, turns=g.turns, floor=floor, out=out)
    return out


@pytest.mark.parametrize("seed", range(8))
def test_grid_table_sums_are_the_likelihood_field_sums(seed):
    rng = np.random.default_rng(seed)
    grid = random_grid(rng)
    check = PoseCheck(grid)
    table, frame = check._table, check._frame
    base, mount, beams, g = random_case(rng, grid)
    got = table_sums(base, mount, beams, table, frame, g)
    poses = grid_poses(base, g)
    np.testing.assert_allclose(got, reference_sums(poses, mount, beams, table, frame, -1.0),
                               rtol=1e-12, atol=1e-12)
    per_pose = np.empty(len(poses))
    k.likelihood_field(poses, mount, beams, table=table, frame=frame, off_value=-1.0, base=0.0,
                       out=per_pose)
    assert np.array_equal(got, per_pose)            # the same sums to the bit


@pytest.mark.parametrize("seed", range(8))
def test_a_floor_drops_only_poses_that_cannot_reach_it(seed):
    rng = np.random.default_rng(100 + seed)
    grid = random_grid(rng)
    check = PoseCheck(grid)
    base, mount, beams, g = random_case(rng, grid, n_beams=int(rng.integers(1, 90)))
    full = table_sums(base, mount, beams, check._table, check._frame, g)
    floor = full[rng.integers(g.size)]
    got = table_sums(base, mount, beams, check._table, check._frame, g, floor)
    dropped = np.isneginf(got)
    assert np.array_equal(got[~dropped], full[~dropped])
    assert (full[dropped] < floor - k.FLOOR_SLACK).all()
    assert got.max() == full.max() and np.argmax(got[g.order]) == np.argmax(full[g.order])


@pytest.mark.parametrize("seed", range(8))
def test_grid_interpolated_fit_is_the_interpolated_fit(seed):
    rng = np.random.default_rng(200 + seed)
    grid = random_grid(rng)
    residual = np.ascontiguousarray(rng.uniform(0, 1, grid.shape), np.float32)
    frame = np.array([grid.origin[0], grid.origin[1], grid.resolution])
    base, mount, beams, g = random_case(rng, grid)
    got = np.empty(g.size)
    k.grid_interpolated_fit(base=base, mount=mount, beams=beams, residual=residual, frame=frame,
                            xs=g.xy, ys=g.xy, turns=g.turns, out=got)
    poses = grid_poses(base, g)
    np.testing.assert_allclose(got, reference_interpolated(poses, mount, beams, residual, frame),
                               rtol=1e-12, atol=1e-12)
    per_pose = np.empty(len(poses))
    k.interpolated_fit(poses, mount, beams, residual, frame, per_pose)
    assert np.array_equal(got, per_pose)


def test_search_grid_rows_are_the_axes_in_order():
    g = SearchGrid(0.025, 3, math.radians(0.5), 2)
    assert np.array_equal(search_grid(0.025, 3, math.radians(0.5), 2), g.offsets)
    raw = grid_poses(np.zeros(3), g)
    assert np.array_equal(raw[g.order], g.offsets) and not g.offsets[0].any()


# --- the whole check against the code before -----------------------------------------------
def room_world(rng):
    boxes = [world.Rect(x, y, x + rng.uniform(0.3, 1.2), y + rng.uniform(0.3, 1.2))
             for x, y in rng.uniform(1.5, 8.5, (4, 2))]
    walls = world.room_walls()
    return walls + boxes, world.rasterise(walls + boxes[:3])    # one box the map lacks


def random_calls(rng, shapes, mount, n=40):
    """Scans at random poses of the room, given with errors from none to gross, a few with a
    covariance, their times mostly rising (a refusal's hold) with one step back."""
    t = 0.0
    for i in range(n):
        true = Pose2D(rng.uniform(1.5, 9.5), rng.uniform(1.5, 9.5), rng.uniform(-math.pi, math.pi))
        err = rng.choice([0.0, 0.02, 0.05, 0.1, 0.4]) * rng.normal(size=3) * (1, 1, 0.3)
        told = Pose2D(true.x + err[0], true.y + err[1], true.theta + err[2])
        t = t + rng.choice([0.1, 0.2, 0.5]) if i != n // 2 else 0.0
        scan = (world.full_scan if i % 3 else world.partial_scan)(shapes, true.compose(mount), t)
        cov = None if i % 4 else np.diag([rng.uniform(0, 0.2), 0.01, rng.uniform(0, 0.01)])
        yield scan, told, cov


# (seed, configuration) of the runs recorded in pose_check_case{index}.npz
CHECK_CASES = [(0, {}), (1, {}), (2, {"slack_cells": 1}),
               (3, {"max_beams": 97, "polish_steps": 3}), (4, {"refine": False}),
               (5, {"fine_step": 0.04, "coarse_steps_deg": 2, "cap": 0.3})]


def check_case(seed: int):
    """The room's map, the lidar mount and the calls (scan, pose given, covariance) of a run
    of ``CHECK_CASES``."""
    rng = np.random.default_rng(300 + seed)
    shapes, ref = room_world(rng)
    mount = Pose2D(0.1, -0.02, 0.05) if seed % 2 else Pose2D(0.0, 0.0, 0.0)
    return ref, mount, list(random_calls(rng, shapes, mount))


def check_calls(check, calls, mount) -> list:
    """Per call: the verdict, the refined pose and the fit (its value, gain, correction and
    beams), as the golden files hold them."""
    out = []
    for scan, told, cov in calls:          # in this order: a refusal holds for a while
        verdict = check.verdict(scan, told, mount, cov)
        refined = check.refine(scan, told, mount)
        f = check.fit(scan, told, mount)
        out.append(golden.as_recorded({"verdict": verdict, "refine": refined,
                                       "fit": [f.fit, f.gain, f.correction, f.beams]}))
    return out


@pytest.mark.parametrize("case", range(len(CHECK_CASES)))
def test_the_check_gives_the_verdicts_of_the_code_before(case):
    seed, config = CHECK_CASES[case]
    ref, mount, calls = check_case(seed)
    want = golden.Golden(f"pose_check_case{case}")
    want.check_inputs(golden.fingerprint(ref.data, mount, calls))
    assert want.facts["case"] == golden.as_recorded([seed, config])
    cfg = PoseCheckConfig(**config)
    got = check_calls(PoseCheck(ref, cfg), calls, mount)
    for n, (a, b) in enumerate(zip(got, want.facts["calls"], strict=True)):
        assert a == b, f"call {n}"
    kinds = {c["verdict"]["verdict"] for c in got}
    assert "refused" in kinds and ({"accepted"} if not cfg.refine else {"refined"}) <= kinds


def one_cell_wide():
    data = np.full((1, 80), FREE, np.int8)
    data[0, 40] = OCCUPIED
    grid = OccupancyGrid(data, 0.05, (0.0, 0.0))
    scan = Scan(np.full(90, 1.0, np.float32), -math.pi / 4, math.pi / 180, 0.05, 20.0, time=1.0)
    return grid, scan, Pose2D(1.0, 0.02, 0.0), Pose2D(0.0, 0.0, 0.0)


def test_a_map_one_cell_wide_still_refines_as_before():
    grid, scan, pose, mount = one_cell_wide()
    want = golden.Golden("pose_check_one_cell_wide")
    want.check_inputs(golden.fingerprint(grid.data, scan, pose, mount))
    assert golden.as_recorded(PoseCheck(grid).verdict(scan, pose, mount)) == \
        want.facts["verdict"]
