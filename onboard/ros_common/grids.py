"""Occupancy grids to and from ``nav_msgs/OccupancyGrid`` fields, and the box of cells that
changed between two published maps (``map_msgs/OccupancyGridUpdate``). Plain functions over
message-like objects: no ROS import, so they are tested without ROS."""

from __future__ import annotations

import math

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, GridError, OccupancyGrid
from gridmap.map_io import MAX_CELLS, MAX_ORIGIN, MAX_RESOLUTION, MIN_RESOLUTION

# nav_msgs/OccupancyGrid holds probabilities 0-100 and -1; map_server publishes 0 / 100 / -1.
# Other publishers' probabilities are read with map_server's default thresholds.
OCCUPIED_FROM = 65      # occupied_thresh 0.65
FREE_UP_TO = 19         # free_thresh 0.196


def grid_from_message(msg) -> OccupancyGrid:
    """The trinary grid of a ``nav_msgs/OccupancyGrid``; ``GridError`` names what is wrong
    (a rotated origin, a data length that is not width x height, a bad resolution)."""
    info = msg.info
    w, h, res = int(info.width), int(info.height), float(info.resolution)
    # the limits of a map file (gridmap.map_io), so a message cannot bring what a file could not
    if not (math.isfinite(res) and MIN_RESOLUTION <= res <= MAX_RESOLUTION):
        raise GridError(f"map resolution must be in [{MIN_RESOLUTION:g}, {MAX_RESOLUTION:g}] "
                        f"m/cell, got {res!r}")
    if w * h > MAX_CELLS:
        raise GridError(f"map of {w} x {h} cells: more than the {MAX_CELLS} cells a map can "
                        "have")
    ox, oy = float(info.origin.position.x), float(info.origin.position.y)
    if not (math.isfinite(ox) and math.isfinite(oy)) or max(abs(ox), abs(oy)) > MAX_ORIGIN:
        raise GridError(f"map origin must lie within {MAX_ORIGIN:g} m of 0, got ({ox!r}, "
                        f"{oy!r})")
    q = info.origin.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    if abs(yaw) > 1e-9:
        raise GridError(f"map origin is rotated ({math.degrees(yaw):.3g} deg); only "
                        "unrotated maps can be updated")
    data = np.asarray(msg.data, dtype=np.int16)
    if data.size != w * h or w <= 0 or h <= 0:
        raise GridError(f"map data has {data.size} cells, not width x height = {w} x {h}")
    cells = np.full(data.shape, UNKNOWN, np.int8)
    cells[(data >= 0) & (data <= FREE_UP_TO)] = FREE
    cells[data >= OCCUPIED_FROM] = OCCUPIED
    return OccupancyGrid(cells.reshape(h, w), res, (ox, oy))


def message_fields(grid: OccupancyGrid) -> dict:
    """What a ``nav_msgs/OccupancyGrid`` needs of ``grid``: width, height, resolution, origin
    (x, y) and the row-major cells (row 0 at the origin, as ROS has it)."""
    h, w = grid.shape
    return {"width": w, "height": h, "resolution": float(grid.resolution),
            "origin": (float(grid.origin[0]), float(grid.origin[1])),
            "data": grid.data.reshape(-1).tolist()}


def changed_box(before: np.ndarray, after: np.ndarray) -> tuple[int, int, int, int] | None:
    """(x, y, width, height) in cells of the smallest box holding every cell that differs
    between two grids of one shape, as ``map_msgs/OccupancyGridUpdate`` carries it; None when
    nothing changed."""
    rows, cols = np.nonzero(before != after)
    if rows.size == 0:
        return None
    r0, r1, c0, c1 = int(rows.min()), int(rows.max()), int(cols.min()), int(cols.max())
    return c0, r0, c1 - c0 + 1, r1 - r0 + 1
