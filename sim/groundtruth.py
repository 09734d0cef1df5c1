"""The ground-truth map G of a world, rasterised from its geometry (never from scans).

As the evaluation document defines it: free = cells whose centre lies inside the building and
outside every object, 4-connected to the robot's start; occupied = cells covered by an object or
wall that touch (8-neighbour) that free space; everything else unknown. A cell is *covered* when
an object shares area with its square, however little: a lidar hitting that object's face ends its
beam in that cell, so a correct map has it occupied. Such a cell is never free, even when its
centre is outside the object.
"""

from __future__ import annotations

import math

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from gridmap.masks import near

from . import geometry as geo

# Area shared with a cell below this (in metres of overlap along an axis) is a touch, not cover:
# a box edge that lies on a cell boundary covers only the cells on its own side.
COVER_TOL = 1e-9


def grid_frame(scenario, margin: float = 0.1) -> OccupancyGrid:
    """An all-unknown grid at the scenario's resolution covering the outer walls plus ``margin``
    [m]; its origin is a whole number of cells, so cell edges fall on round coordinates."""
    res = scenario.resolution
    x0, y0, x1, y1 = scenario.world.bounds
    pad = scenario.world.wall_thickness + margin
    # rounding first keeps a bound like -7.1 / 0.05 = -141.99999999999997 at -142
    c0 = math.floor(round((x0 - pad) / res, 6))
    r0 = math.floor(round((y0 - pad) / res, 6))
    c1 = math.ceil(round((x1 + pad) / res, 6))
    r1 = math.ceil(round((y1 + pad) / res, 6))
    return OccupancyGrid.empty(c1 - c0, r1 - r0, res, (c0 * res, r0 * res))


def covered_cells(frame: OccupancyGrid, boxes: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Bool (H, W): cells whose square shares area with any box (B, 5) or circle (C, 3)."""
    cover = np.zeros(frame.shape, bool)
    res = frame.resolution
    for b in np.asarray(boxes, np.float64).reshape(-1, 5):
        rows, cols, x0, y0 = _window(frame, geo.box_extent(b[None])[0])
        cover[rows, cols] |= _square_meets_box(x0, y0, res, b)
    for cx, cy, r in np.asarray(circles, np.float64).reshape(-1, 3):
        rows, cols, x0, y0 = _window(frame, np.array([cx - r, cy - r, cx + r, cy + r]))
        dx = np.maximum(np.maximum(x0 - cx, 0.0), cx - (x0 + res))
        dy = np.maximum(np.maximum(y0 - cy, 0.0), cy - (y0 + res))
        cover[rows, cols] |= dx * dx + dy * dy < (r - COVER_TOL) ** 2
    return cover


def _window(frame: OccupancyGrid, extent: np.ndarray):
    """Index arrays of the cells under an axis-aligned extent, and their lower-left corners."""
    res = frame.resolution
    ox, oy = frame.origin
    c0 = max(int(math.floor((extent[0] - ox) / res)) - 1, 0)
    r0 = max(int(math.floor((extent[1] - oy) / res)) - 1, 0)
    c1 = min(int(math.ceil((extent[2] - ox) / res)) + 1, frame.width)
    r1 = min(int(math.ceil((extent[3] - oy) / res)) + 1, frame.height)
    rows = np.arange(r0, max(r1, r0))[:, None]
    cols = np.arange(c0, max(c1, c0))[None, :]
    return rows, cols, ox + cols * res, oy + rows * res


def _square_meets_box(x0, y0, res, box) -> np.ndarray:
    """Separating-axis test between cell squares (lower-left x0, y0, side res) and a box."""
    cx, cy, hw, hh, yaw = box
    c, s = math.cos(yaw), math.sin(yaw)
    ex = hw * abs(c) + hh * abs(s)          # the box's half extent along x and y
    ey = hw * abs(s) + hh * abs(c)
    ok = (np.minimum(x0 + res, cx + ex) - np.maximum(x0, cx - ex) > COVER_TOL) \
        & (np.minimum(y0 + res, cy + ey) - np.maximum(y0, cy - ey) > COVER_TOL)
    mx, my = x0 + res / 2 - cx, y0 + res / 2 - cy
    half = res / 2 * (abs(c) + abs(s))      # the square's half extent along the box's axes
    for (ax, ay), h in (((c, s), hw), ((-s, c), hh)):
        m = mx * ax + my * ay
        ok &= np.minimum(m + half, h) - np.maximum(m - half, -h) > COVER_TOL
    return ok


def rasterise(frame: OccupancyGrid, boxes: np.ndarray, circles: np.ndarray, bounds,
              start_xy) -> OccupancyGrid:
    """G in ``frame`` of the world made of boxes (walls included) and circles, seen from the
    free space connected to ``start_xy``."""
    from ._kernels import flood_fill4

    cover = covered_cells(frame, boxes, circles)
    rows, cols = np.indices(frame.shape)
    x, y = frame.cell_to_world(rows, cols)
    inside = (x > bounds[0]) & (x < bounds[2]) & (y > bounds[1]) & (y < bounds[3])
    free = np.zeros(frame.shape, bool)
    r0, c0 = frame.world_to_cell(start_xy[0], start_xy[1])
    flood_fill4(inside & ~cover, int(r0), int(c0), free)
    data = np.full(frame.shape, UNKNOWN, np.int8)
    data[free] = FREE
    data[cover & near(free)] = OCCUPIED
    return frame.with_data(data)
