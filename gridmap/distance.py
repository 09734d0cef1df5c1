"""Distance fields: the Euclidean distance from every cell to the nearest occupied cell.

The public wrapper around ``gridmap._distance_kernels``: it checks arguments, calls one kernel for
the whole grid and converts cells to metres. The localiser's likelihood field is built on it.
"""

from __future__ import annotations

import math

import numpy as np

from .types import GridError, OccupancyGrid


def _kernels():
    from . import _distance_kernels  # numba is imported lazily so that the command line starts fast

    return _distance_kernels


def distance_to_occupied(grid: OccupancyGrid, max_distance: float | None = None) -> np.ndarray:
    """Exact Euclidean distance [m] from each cell centre to the nearest occupied cell centre,
    as a float32 array of the grid's shape.

    Only occupied cells (100) are obstacles: free and unknown cells alike get their distance to
    the nearest occupied one. With ``max_distance`` [m] every distance is capped there (cells
    farther away, and every cell of a grid with no occupied cell, get ``max_distance``); without
    it those cells are ``inf``.
    """
    if max_distance is not None:
        if not (isinstance(max_distance, (int, float, np.floating)) and math.isfinite(max_distance)
                and max_distance >= 0):
            raise GridError(f"max_distance must be a finite number >= 0 [m], got {max_distance!r}")
    d2 = _kernels().squared_edt(grid.data)
    dist = np.sqrt(d2) * grid.resolution
    if max_distance is not None:
        np.minimum(dist, float(max_distance), out=dist)
    return dist.astype(np.float32)
