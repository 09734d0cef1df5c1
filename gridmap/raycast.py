"""Ray casting on an occupancy grid: exact cell traversal and expected ranges along beams.

Public wrappers around ``gridmap._kernels``: they check arguments, convert metres to grid units
and call one kernel for the whole set of beams.
"""

from __future__ import annotations

import math

import numpy as np

from .types import GridError, OccupancyGrid, Pose2D


def _kernels():
    from . import _kernels  # numba is imported lazily so that the command line starts fast

    return _kernels


def traverse(grid: OccupancyGrid, start, end) -> tuple[np.ndarray, np.ndarray]:
    """The cells (rows, cols) the segment from ``start`` to ``end`` (world x, y [m]) passes
    through, in order, clipped to the grid."""
    k = _kernels()
    ox, oy = grid.origin
    res = grid.resolution
    gx0, gy0 = (start[0] - ox) / res, (start[1] - oy) / res
    gx1, gy1 = (end[0] - ox) / res, (end[1] - oy) / res
    if not all(math.isfinite(v) for v in (gx0, gy0, gx1, gy1)):
        raise GridError(f"segment end points must be finite, got {start} -> {end}")
    cap = int(abs(math.floor(gx1) - math.floor(gx0)) + abs(math.floor(gy1) - math.floor(gy0))) + 2
    rows = np.empty(cap, np.int64)
    cols = np.empty(cap, np.int64)
    n = k.traverse(gx0, gy0, gx1, gy1, height=grid.height, width=grid.width, rows=rows, cols=cols)
    return rows[:n], cols[:n]


def cast_rays(grid: OccupancyGrid, origin: Pose2D, angles, max_range: float,
              block_unknown: bool = False) -> np.ndarray:
    """Expected range [m] of beams from ``origin`` at ``angles`` (relative to its heading):
    the distance to where each beam enters the first occupied cell (or, with
    ``block_unknown``, occupied or unknown cell). ``inf`` where nothing blocks within
    ``max_range``; a beam that leaves the grid counts as blocked there only with
    ``block_unknown`` (outside the map is unknown)."""
    if not origin.is_finite():
        raise GridError(f"ray origin must be finite, got {origin}")
    if not (max_range > 0):
        raise GridError(f"max_range must be positive, got {max_range}")
    k = _kernels()
    angles = np.asarray(angles, dtype=np.float64)
    if angles.ndim != 1:
        angles = angles.reshape(-1)
    res = grid.resolution
    sensor = np.array([(origin.x - grid.origin[0]) / res, (origin.y - grid.origin[1]) / res,
                       origin.theta])
    ranges = np.empty(angles.size, np.float64)
    k.cast_ranges(grid.data, sensor, angles, max_len=max_range / res,
                  block_unknown=bool(block_unknown), res=res, out=ranges)
    return ranges
