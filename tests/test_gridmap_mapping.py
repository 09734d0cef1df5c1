"""Log-odds mapping: the kernel against a NumPy reference, the rules by hand, and a simulated
square room whose walls the map must recover."""

import math

import numpy as np
import pytest
from test_gridmap_raycast import exact_cells

from gridmap import FREE, OCCUPIED, UNKNOWN, GridError, OccupancyGrid, Pose2D, Scan
from gridmap.mapping import LogOddsMapper, LogOddsParams, build_map, threshold_logodds
from gridmap.metrics import opdf
from gridmap.raycast import cast_rays


def reference_add_scan(logodds, sensor, angles, ranges, limits, params):
    """One scan by the rules, cell sequences from the exact NumPy traversal: hits first, then
    misses, each cell at most once, none within ``params.hit_guard`` cells of a hit."""
    h, w = logodds.shape
    gx, gy = sensor
    r_min, r_max, clearance = limits
    touched = np.zeros((h, w), bool)
    hit, miss = np.float32(params.hit), np.float32(params.miss)
    lo, hi = np.float32(params.clamp_min), np.float32(params.clamp_max)
    for a, r in zip(angles, ranges):
        if r_min <= r < r_max:
            row, col = math.floor(gy + r * math.sin(a)), math.floor(gx + r * math.cos(a))
            if 0 <= row < h and 0 <= col < w and not touched[row, col]:
                logodds[row, col] = min(logodds[row, col] + hit, hi)
                touched[row, col] = True
    g = params.hit_guard
    for a, r in zip(angles, ranges):
        if r_min <= r < r_max:
            row, col = math.floor(gy + r * math.sin(a)), math.floor(gx + r * math.cos(a))
            touched[max(row - g, 0):max(row + g + 1, 0), max(col - g, 0):max(col + g + 1, 0)] = True
    for a, r in zip(angles, ranges):
        if r_min <= r < r_max:
            length = r
        elif r >= r_max:
            length = min(clearance, r_max)
        else:
            continue
        cells, _ = exact_cells(gx, gy, gx + length * math.cos(a), gy + length * math.sin(a), h, w)
        for row, col in cells:
            if not touched[row, col]:
                logodds[row, col] = max(logodds[row, col] + miss, lo)
                touched[row, col] = True


@pytest.mark.parametrize("guard", [0, 1, 2])
def test_kernel_matches_numpy_reference(guard):
    rng = np.random.default_rng(21)
    res = 0.1
    frame = OccupancyGrid.empty(30, 20, res, origin=(-1.0, -0.5))
    params = LogOddsParams(no_return_clearance=1.2, hit_guard=guard)
    mapper = LogOddsMapper(frame, params)
    want = np.zeros(frame.shape, np.float32)
    for _ in range(40):
        n = 90
        ranges = rng.uniform(0.0, 3.0, n).astype(np.float32)
        ranges[rng.random(n) < 0.1] = np.inf
        ranges[rng.random(n) < 0.05] = np.nan
        scan = Scan(ranges, angle_min=-2.0, angle_increment=4.0 / n, range_min=0.1, range_max=2.5)
        pose = Pose2D(rng.uniform(-1.5, 2.5), rng.uniform(-1.0, 2.0), rng.uniform(-3, 3))
        mapper.add_scan(scan, pose)
        sensor = ((pose.x + 1.0) / res, (pose.y + 0.5) / res)
        reference_add_scan(want, sensor, scan.angles() + pose.theta,
                           scan.ranges.astype(np.float64) / res, (1.0, 25.0, 12.0), params)
    assert mapper.scans == 40
    assert np.array_equal(mapper.logodds, want)
    assert (want > 0).sum() > 10 and (want < 0).sum() > 150


def one_beam(r, range_max=5.0):
    return Scan(np.array([r], np.float32), 0.0, 0.01, 0.05, range_max)


def test_one_beam_by_hand():
    mapper = LogOddsMapper(OccupancyGrid.empty(10, 3, 0.1))
    # From the centre of cell (1, 0) along +x, hit at 0.6 m: cells 0..5 passed, cell 6 hit.
    mapper.add_scan(one_beam(0.6), Pose2D(0.05, 0.15, 0.0))
    p = LogOddsParams()
    np.testing.assert_allclose(mapper.logodds[1], [p.miss] * 6 + [p.hit] + [0.0] * 3, atol=1e-6)
    assert not mapper.logodds[[0, 2]].any()
    grid = mapper.to_grid()
    # One miss (-0.4) is not yet free; one hit (0.85) is occupied.
    assert grid.data[1].tolist() == [UNKNOWN] * 6 + [OCCUPIED] + [UNKNOWN] * 3
    mapper.add_scan(one_beam(0.6), Pose2D(0.05, 0.15, 0.0))
    assert mapper.to_grid().data[1].tolist() == [FREE] * 6 + [OCCUPIED] + [UNKNOWN] * 3


def test_no_return_clears_up_to_clearance_without_a_hit():
    mapper = LogOddsMapper(OccupancyGrid.empty(20, 1, 0.1), LogOddsParams(no_return_clearance=0.5))
    mapper.add_scan(one_beam(np.inf), Pose2D(0.05, 0.05, 0.0))
    # 0.05 -> 0.55 m: cells 0..5 free, nothing hit, the rest untouched.
    assert (mapper.logodds[0, :6] < 0).all() and not mapper.logodds[0, 6:].any()
    # A range at or beyond range_max is a missing return too, cleared to min(clearance, max).
    mapper = LogOddsMapper(OccupancyGrid.empty(20, 1, 0.1), LogOddsParams(no_return_clearance=5))
    mapper.add_scan(one_beam(1.0, range_max=0.8), Pose2D(0.05, 0.05, 0.0))
    assert (mapper.logodds[0, :9] < 0).all() and not mapper.logodds[0, 9:].any()


def test_invalid_ranges_are_ignored():
    mapper = LogOddsMapper(OccupancyGrid.empty(20, 1, 0.1))
    mapper.add_scan(Scan(np.array([0.01, np.nan], np.float32), 0.0, 0.1, 0.05, 5.0),
                    Pose2D(0.05, 0.05, 0.0))
    assert not mapper.logodds.any()


def test_clamping_and_once_per_scan():
    p = LogOddsParams()
    mapper = LogOddsMapper(OccupancyGrid.empty(10, 10, 0.1), p)
    # 360 beams all hitting the same cell: it changes once per scan, not 360 times.
    scan = Scan(np.full(360, 0.3, np.float32), -math.pi, 2 * math.pi / 360, 0.05, 5.0)
    mapper.add_scan(scan, Pose2D(0.55, 0.55, 0.0))
    assert mapper.logodds[5, 5] == pytest.approx(p.miss)  # the sensor's own cell, missed once
    for _ in range(20):
        mapper.add_scan(scan, Pose2D(0.55, 0.55, 0.0))
    assert mapper.logodds.max() == np.float32(p.clamp_max)
    assert mapper.logodds[5, 5] == np.float32(p.clamp_min)
    probs = mapper.probabilities()
    assert probs.max() == pytest.approx(1 / (1 + math.exp(-p.clamp_max)), rel=1e-6)


def test_params_are_validated_by_name():
    with pytest.raises(GridError, match="did you mean 'miss'"):
        LogOddsParams.from_dict({"mis": -0.3})
    with pytest.raises(GridError, match="hit must be > 0"):
        LogOddsParams(hit=-1.0)
    with pytest.raises(GridError, match="free_below must be a finite number"):
        LogOddsParams(free_below="low")
    for bad in (-1, 1.5, 11):
        with pytest.raises(GridError, match="hit_guard must be a whole number of cells"):
            LogOddsParams(hit_guard=bad)
    assert LogOddsParams.from_dict({"hit": 1.0}).hit == 1.0
    assert threshold_logodds(np.array([[-0.7, -0.5, 0.5, 0.7]])).tolist() == [[0, -1, -1, 100]]


# --- the simulated room ------------------------------------------------------------------------

def square_room():
    """6 x 6 m inside at 5 cm, 2-cell walls, a 0.6 m box; 2 cells of outside all round."""
    res = 0.05
    n = 120 + 2 * 2 + 2 * 2
    d = np.zeros((n, n), np.int8)
    d[:2], d[-2:], d[:, :2], d[:, -2:] = OCCUPIED, OCCUPIED, OCCUPIED, OCCUPIED
    d[2:4], d[-4:-2], d[:, 2:4], d[:, -4:-2] = OCCUPIED, OCCUPIED, OCCUPIED, OCCUPIED
    d[:2], d[-2:], d[:, :2], d[:, -2:] = FREE, FREE, FREE, FREE  # outside the walls
    d[70:82, 30:42] = OCCUPIED  # box
    return OccupancyGrid(d, res, origin=(-0.2, -0.2))


def simulate(truth, poses, rng, beams=720, noise=0.01):
    angles = -math.pi + 2 * math.pi / beams * np.arange(beams)
    for pose in poses:
        r = cast_rays(truth, pose, angles, 10.0)
        r = r + rng.normal(0.0, noise, r.shape)
        yield Scan(r.astype(np.float32), -math.pi, 2 * math.pi / beams, 0.05, 10.0), pose


def test_mapping_recovers_square_room():
    truth = square_room()
    rng = np.random.default_rng(4)
    poses = [Pose2D(x, y, rng.uniform(-math.pi, math.pi))
             for x in (1.0, 3.0, 5.0) for y in (1.0, 3.0, 5.0)]
    mapped = build_map(truth, simulate(truth, poses, rng)).data
    wall = truth.data == OCCUPIED
    interior = np.zeros_like(wall)
    interior[4:-4, 4:-4] = True
    inside = interior & ~wall
    # Wall and box cells the interior can see: the 4-neighbours of interior free cells.
    near_free = np.zeros_like(wall)
    near_free[1:] |= inside[:-1]
    near_free[:-1] |= inside[1:]
    near_free[:, 1:] |= inside[:, :-1]
    near_free[:, :-1] |= inside[:, 1:]
    faces = wall & near_free
    assert faces.sum() == 4 * 120 + (4 * 12 - 4)
    grown = wall.copy()
    grown[1:] |= wall[:-1]
    grown[:-1] |= wall[1:]
    grown[:, 1:] |= wall[:, :-1]
    grown[:, :-1] |= wall[:, 1:]
    assert (mapped[faces] == OCCUPIED).mean() > 0.98
    # Free space away from the walls is free; the cells just in front of a wall may read
    # occupied (range noise of 0.2 cells across a face that lies on a cell edge).
    assert (mapped[inside & ~grown] == FREE).mean() > 0.995
    assert (mapped[inside] == FREE).mean() > 0.95
    # Every occupied cell lies within one cell of a true wall, and nothing outside is known.
    assert not (mapped == OCCUPIED)[~grown].any()
    assert (mapped[:2] == UNKNOWN).all() and (mapped[:, -2:] == UNKNOWN).all()
    assert (mapped[72:80, 32:40] == UNKNOWN).all()  # the box's interior was never seen
    faces_grid = np.where(faces, OCCUPIED, np.where(inside, FREE, UNKNOWN)).astype(np.int8)
    assert opdf(mapped, faces_grid) > 97.0
