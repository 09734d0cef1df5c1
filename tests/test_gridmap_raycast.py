"""Grid traversal and ray casting against plain NumPy references."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from gridmap import OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D
from gridmap import _kernels as k
from gridmap.raycast import cast_rays, traverse

# --- references --------------------------------------------------------------------------------


def clip(x0, y0, x1, y1, xmin, ymin, xmax, ymax):
    """Parameter range [t0, t1] of the segment inside the closed box (t0 > t1: outside)."""
    t0, t1 = 0.0, 1.0
    for p, q in ((-(x1 - x0), x0 - xmin), (x1 - x0, xmax - x0),
                 (-(y1 - y0), y0 - ymin), (y1 - y0, ymax - y0)):
        if p == 0:
            if q < 0:
                return 1.0, 0.0
        elif p < 0:
            t0 = max(t0, q / p)
        else:
            t1 = min(t1, q / p)
    return t0, t1


def touches(cell, seg, eps=1e-9):
    """True when the closed square of cell (row, col) meets the segment."""
    r, c = cell
    t0, t1 = clip(*seg, c - eps, r - eps, c + 1 + eps, r + 1 + eps)
    return t0 <= t1


def dense_cells(x0, y0, x1, y1, height, width, per_cell=40):
    """Cells (row, col) that points sampled densely along the segment fall in, in order.

    A sample within rounding of a grid line it moves across is left out: which side of the line
    it falls on is rounding, not geometry (the end points are checked on their own)."""
    n = int(math.ceil(max(abs(x1 - x0), abs(y1 - y0)) * per_cell)) + 2
    t = np.linspace(0.0, 1.0, n)
    xs, ys = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
    on_line = (((x1 != x0) & (np.abs(xs - np.round(xs)) < 1e-9))
               | ((y1 != y0) & (np.abs(ys - np.round(ys)) < 1e-9)))
    inside = (xs >= 0) & (xs < width) & (ys >= 0) & (ys < height) & ~on_line
    cells = np.stack([np.floor(ys[inside]), np.floor(xs[inside])], axis=1).astype(int)
    if len(cells) == 0:
        return []
    keep = np.ones(len(cells), bool)
    keep[1:] = np.any(cells[1:] != cells[:-1], axis=1)
    return [tuple(c) for c in cells[keep]]


def exact_cells(x0, y0, x1, y1, height, width):
    """Cells of a segment in general position (through no cell corner), with the parameter at
    which it enters each: every crossing of a grid line, sorted, clipped to the grid."""
    ta, tb = clip(x0, y0, x1, y1, 0, 0, width, height)
    if ta > tb:
        return [], []
    dx, dy = x1 - x0, y1 - y0
    ts = [ta, tb]
    for d, p0 in ((dx, x0), (dy, y0)):
        if d != 0:
            lo, hi = sorted((p0, p0 + d))
            for g in range(math.ceil(lo), math.floor(hi) + 1):
                t = (g - p0) / d
                if ta < t < tb:
                    ts.append(t)
    ts = np.unique(ts)
    if len(ts) == 1:  # zero length
        ts = np.array([ts[0], ts[0]])
    mids = (ts[:-1] + ts[1:]) / 2
    rows = np.floor(y0 + mids * dy).astype(int)
    cols = np.floor(x0 + mids * dx).astype(int)
    return list(zip(rows.tolist(), cols.tolist())), ts[:-1].tolist()


def kernel_walk(x0, y0, x1, y1, height, width):
    cap = int(abs(math.floor(x1) - math.floor(x0)) + abs(math.floor(y1) - math.floor(y0))) + 8
    rows, cols = np.empty(cap, np.int64), np.empty(cap, np.int64)
    n = k.traverse(x0, y0, x1, y1, height, width, rows, cols)
    return list(zip(rows[:n].tolist(), cols[:n].tolist()))


def is_subsequence(small, big):
    it = iter(big)
    return all(any(c == b for b in it) for c in small)


def check_walk(x0, y0, x1, y1, height, width):
    walk = kernel_walk(x0, y0, x1, y1, height, width)
    seg = (x0, y0, x1, y1)
    dense = dense_cells(x0, y0, x1, y1, height, width)
    assert is_subsequence(dense, walk), (seg, dense, walk)
    assert len(set(walk)) == len(walk)
    for (r0, c0), (r1, c1) in zip(walk, walk[1:]):
        assert abs(r1 - r0) + abs(c1 - c0) == 1, (seg, walk)
    for cell in walk:
        assert 0 <= cell[0] < height and 0 <= cell[1] < width
        assert touches(cell, seg), (seg, cell, walk)
    if 0 <= x0 < width and 0 <= y0 < height:
        assert walk[0] == (math.floor(y0), math.floor(x0))
    if 0 <= x1 < width and 0 <= y1 < height:
        assert walk[-1] == (math.floor(y1), math.floor(x1))
    if dense:
        assert len(walk) >= len(dense)
    return walk


# --- traversal ---------------------------------------------------------------------------------

H, W = 9, 13
# Coordinates from a mix of arbitrary floats, grid-line integers and half cells, so that many
# segments run along grid lines or through exact cell corners.
coord_x = st.one_of(st.floats(-3, W + 3, allow_nan=False), st.integers(-2, W + 2).map(float),
                    st.integers(-4, 2 * W + 4).map(lambda v: v / 2))
coord_y = st.one_of(st.floats(-3, H + 3, allow_nan=False), st.integers(-2, H + 2).map(float),
                    st.integers(-4, 2 * H + 4).map(lambda v: v / 2))


@settings(max_examples=3000, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(coord_x, coord_y, coord_x, coord_y)
@example(-2.7215667277052717, 0.0, 2.0, 0.0)  # x0 + 1.0 * (x1 - x0) rounds below x1 = 2.0
def test_traverse_covers_dense_sampling(x0, y0, x1, y1):
    check_walk(x0, y0, x1, y1, H, W)


@pytest.mark.parametrize("seg", [
    (0.5, 0.5, 5.5, 5.5),      # diagonal through the corners (1, 1) ... (5, 5)
    (5.5, 5.5, 0.5, 0.5),      # the same, backwards
    (0.5, 5.5, 5.5, 0.5),      # anti-diagonal through corners
    (1.0, 1.0, 4.0, 4.0),      # starting and ending on corners
    (0.0, 0.0, 13.0, 9.0),     # corner to corner of the whole grid
    (2.0, 0.0, 2.0, 9.0),      # along a vertical grid line
    (0.0, 3.0, 13.0, 3.0),     # along a horizontal grid line
    (-2.0, -1.0, 4.0, 2.0),    # from outside, through corners (0, 0)... on the way in
])
def test_traverse_through_corners(seg):
    walk = check_walk(*seg, H, W)
    x0, y0, x1, y1 = seg
    if seg == (0.5, 0.5, 5.5, 5.5):
        # At each corner the cell beside it in x comes first: (0,0) (0,1) (1,1) (1,2) ...
        assert walk[:5] == [(0, 0), (0, 1), (1, 1), (1, 2), (2, 2)]
        assert len(walk) == 11


def test_traverse_matches_exact_reference_on_random_segments():
    rng = np.random.default_rng(12)
    for _ in range(5000):
        x0, x1 = rng.uniform(-4, W + 4, 2)
        y0, y1 = rng.uniform(-4, H + 4, 2)
        expected, _ = exact_cells(x0, y0, x1, y1, H, W)
        assert kernel_walk(x0, y0, x1, y1, H, W) == expected


def test_traverse_wrapper_converts_metres():
    grid = OccupancyGrid.empty(10, 5, 0.1, origin=(-1.0, 2.0))
    rows, cols = traverse(grid, (-0.95, 2.05), (-0.55, 2.25))
    # grid units (0.5, 0.5) -> (4.5, 2.5), slope 1/2
    walk = list(zip(rows.tolist(), cols.tolist()))
    assert walk == [(0, 0), (0, 1), (1, 1), (1, 2), (1, 3), (2, 3), (2, 4)]


# --- ray casting ---------------------------------------------------------------------------------

def reference_ranges(data, gx, gy, angles, max_len, block_unknown):
    """Expected ranges [grid units] by the exact cell sequence of each beam."""
    height, width = data.shape
    out = np.full(len(angles), np.inf)
    for i, a in enumerate(angles):
        x1, y1 = gx + max_len * math.cos(a), gy + max_len * math.sin(a)
        cells, ts = exact_cells(gx, gy, x1, y1, height, width)
        for (r, c), t in zip(cells, ts):
            v = data[r, c]
            if v == OCCUPIED or (block_unknown and v == UNKNOWN):
                out[i] = t * max_len
                break
        else:
            _, t_exit = clip(gx, gy, x1, y1, 0, 0, width, height)
            if block_unknown and t_exit < 1.0:
                out[i] = max(t_exit, 0.0) * max_len
        if block_unknown and not (0 <= gx < width and 0 <= gy < height):
            out[i] = 0.0  # outside the map is unknown
    return out


def random_grid(rng, height, width):
    data = np.zeros((height, width), np.int8)
    u = rng.random((height, width))
    data[u < 0.08] = OCCUPIED
    data[(u >= 0.08) & (u < 0.12)] = UNKNOWN
    return data


@pytest.mark.parametrize("block_unknown", [False, True])
def test_cast_rays_matches_numpy_reference(block_unknown):
    rng = np.random.default_rng(3)
    res = 0.05
    hits = 0
    for _ in range(30):
        data = random_grid(rng, 40, 60)
        grid = OccupancyGrid(data, res, origin=(-1.0, 0.5))
        # Poses inside and outside the grid, generic positions (no beam through a corner).
        x, y = rng.uniform(-1.5, 2.5), rng.uniform(0.0, 3.0)
        pose = Pose2D(x, y, rng.uniform(-math.pi, math.pi))
        angles = np.sort(rng.uniform(-2.4, 2.4, 200))
        max_range = rng.uniform(0.3, 4.0)
        got = cast_rays(grid, pose, angles, max_range, block_unknown)
        gx, gy = (x + 1.0) / res, (y - 0.5) / res
        want = reference_ranges(data, gx, gy, angles + pose.theta, max_range / res,
                                block_unknown) * res
        assert np.array_equal(np.isinf(got), np.isinf(want))
        fin = np.isfinite(want)
        np.testing.assert_allclose(got[fin], want[fin], rtol=0, atol=1e-9)
        hits += fin.sum()
    assert hits > 1000


def test_cast_rays_square_room_by_hand():
    data = np.zeros((20, 20), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = OCCUPIED
    grid = OccupancyGrid(data, 0.1)
    # From the centre (1.0, 1.0) the inner wall faces are at 0.1 and 1.9 m.
    got = cast_rays(grid, Pose2D(1.0, 1.0, 0.0), [0.0, math.pi / 2, math.pi, -math.pi / 2], 5.0)
    np.testing.assert_allclose(got, [0.9, 0.9, 0.9, 0.9], atol=1e-12)
    diag = cast_rays(grid, Pose2D(1.0, 1.0, 0.0), [math.pi / 4], 5.0)
    np.testing.assert_allclose(diag, [0.9 * math.sqrt(2)], atol=1e-12)
    assert np.isinf(cast_rays(grid, Pose2D(1.0, 1.0, 0.0), [0.0], 0.5))[0]


def test_first_hit_axis_aligned_and_limits():
    data = np.zeros((4, 10), np.int8)
    data[:, 7] = OCCUPIED
    data[3, :] = UNKNOWN
    # Exactly along +x from a cell edge: enters column 7 at t = 7 - 2 = 5.
    assert k.first_hit(data, 2.0, 1.5, 1.0, 0.0, 20.0, False) == (5.0, k.HIT)
    # max_len short of the wall: nothing within reach.
    assert k.first_hit(data, 2.0, 1.5, 1.0, 0.0, 4.5, False) == (4.5, k.NO_HIT)
    # Along +y (cos exactly 0): unknown row 3 blocks only when asked; else the beam leaves.
    assert k.first_hit(data, 0.5, 0.25, 0.0, 1.0, 20.0, True) == (2.75, k.HIT)
    assert k.first_hit(data, 0.5, 0.25, 0.0, 1.0, 20.0, False) == (3.75, k.LEFT_GRID)
    # Along -x to the left edge.
    assert k.first_hit(data, 3.5, 0.5, -1.0, 0.0, 20.0, False) == (3.5, k.LEFT_GRID)
    # Starting outside: walks in from x = 0; blocked at once when unknown blocks.
    assert k.first_hit(data, -2.0, 1.5, 1.0, 0.0, 20.0, False) == (9.0, k.HIT)
    assert k.first_hit(data, -2.0, 1.5, 1.0, 0.0, 20.0, True) == (0.0, k.LEFT_GRID)
    # Starting inside a wall.
    assert k.first_hit(data, 7.5, 1.5, 1.0, 0.0, 20.0, False) == (0.0, k.HIT)
