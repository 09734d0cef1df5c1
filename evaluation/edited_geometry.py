"""The geometry of an edited world: boxes and people (discs) against the beams of a scan.

``box_entry`` / ``disc_entry`` give, for every beam of a scan at once, the distance at which it
first crosses each box's boundary or each disc; ``edit_scans`` cuts boxes and discs into a scan's
ranges (a beam that crosses one ends on it when that is nearer than what the laser measured).
Imports only ``gridmap``; used by :mod:`evaluation.edited_world`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gridmap import OccupancyGrid, Pose2D, Scan


# --- boxes -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Box:
    """A rectangle: centre (cx, cy) [m], sides w (along its yaw) and h [m], yaw [rad]."""

    cx: float
    cy: float
    w: float
    h: float
    yaw: float

    def local(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Points in the box's frame (origin at its centre, x along w)."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = np.asarray(x, np.float64) - self.cx, np.asarray(y, np.float64) - self.cy
        return c * dx + s * dy, -s * dx + c * dy

    def distance(self, x, y) -> np.ndarray:
        """Euclidean distance [m] from points to the box (0 inside and on its boundary)."""
        lx, ly = self.local(x, y)
        return np.hypot(np.maximum(np.abs(lx) - self.w / 2, 0.0),
                        np.maximum(np.abs(ly) - self.h / 2, 0.0))

    def corners(self) -> np.ndarray:
        """The four corners, (4, 2), counter-clockwise."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        u = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64) * [self.w / 2, self.h / 2]
        return np.c_[self.cx + c * u[:, 0] - s * u[:, 1], self.cy + s * u[:, 0] + c * u[:, 1]]

    def window(self, grid: OccupancyGrid, margin: float = 0.0):
        """Cells whose centres are within ``margin`` of the box: (row0, col0, local mask), and
        whether the grid's edge cut the window (the box then does not fit on the grid)."""
        reach = math.hypot(self.w, self.h) / 2 + margin + grid.resolution
        r0, c0 = grid.world_to_cell(self.cx - reach, self.cy - reach)
        r1, c1 = grid.world_to_cell(self.cx + reach, self.cy + reach)
        clipped = r0 < 0 or c0 < 0 or r1 >= grid.height or c1 >= grid.width
        r0, c0 = max(int(r0), 0), max(int(c0), 0)
        r1, c1 = min(int(r1), grid.height - 1), min(int(c1), grid.width - 1)
        if r1 < r0 or c1 < c0:
            return r0, c0, np.zeros((0, 0), bool), True
        rows, cols = np.mgrid[r0:r1 + 1, c0:c1 + 1]
        x, y = grid.cell_to_world(rows, cols)
        return r0, c0, self.distance(x, y) <= margin, bool(clipped)

    def masks(self, grid: OccupancyGrid) -> tuple[np.ndarray, np.ndarray]:
        """(outline, interior) on ``grid``: the cells whose centres the box covers, split into
        those with an 8-neighbour it does not cover and the rest."""
        r0, c0, covered, _ = self.window(grid)
        padded = np.pad(covered, 1)
        inner = covered.copy()
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                inner &= padded[1 + dr:padded.shape[0] - 1 + dr, 1 + dc:padded.shape[1] - 1 + dc]
        outline = np.zeros(grid.shape, bool)
        interior = np.zeros(grid.shape, bool)
        h, w = covered.shape
        outline[r0:r0 + h, c0:c0 + w] = covered & ~inner
        interior[r0:r0 + h, c0:c0 + w] = inner
        return outline, interior


def box_params(boxes) -> np.ndarray:
    """Boxes as rows (cx, cy, w, h, yaw); an array of such rows passes through."""
    if isinstance(boxes, np.ndarray):
        return boxes.astype(np.float64).reshape(-1, 5)
    return np.array([[b.cx, b.cy, b.w, b.h, b.yaw] for b in boxes], np.float64).reshape(-1, 5)


def box_entry(ox, oy, angle, boxes) -> np.ndarray:
    """Distance along each ray (origin ``ox, oy``, heading ``angle`` in the world, arrays of
    one shape (N,) or scalars) to its first crossing of each box's boundary (boxes: a sequence
    of ``Box`` or rows cx, cy, w, h, yaw): (len(boxes), N), ``inf`` where the ray misses the
    box. From inside a box the first crossing is where it leaves."""
    a = np.asarray(angle, np.float64)
    return ray_entry(ox, oy, np.cos(a), np.sin(a), box_params(boxes))


def ray_entry(ox, oy, ca, sa, p: np.ndarray) -> np.ndarray:
    """``box_entry`` for rays given by their direction's cosine and sine, boxes as rows."""
    cx, cy, hw, hh, yaw = (p[:, k, None] for k in range(5))
    hw, hh = hw / 2, hh / 2
    c, s = np.cos(yaw), np.sin(yaw)
    px, py = np.asarray(ox, np.float64) - cx, np.asarray(oy, np.float64) - cy
    lx, ly = c * px + s * py, -s * px + c * py
    dx, dy = c * ca + s * sa, -s * ca + c * sa
    tiny = 1e-12
    dx = np.where(np.abs(dx) < tiny, tiny, dx)
    dy = np.where(np.abs(dy) < tiny, tiny, dy)
    tx1, tx2 = (-hw - lx) / dx, (hw - lx) / dx
    ty1, ty2 = (-hh - ly) / dy, (hh - ly) / dy
    t_in = np.maximum(np.minimum(tx1, tx2), np.minimum(ty1, ty2))
    t_out = np.minimum(np.maximum(tx1, tx2), np.maximum(ty1, ty2))
    hit = (t_in <= t_out) & (t_out > 0)
    return np.where(hit, np.where(t_in > 0, t_in, t_out), np.inf)


def disc_entry(ox, oy, angle, discs) -> np.ndarray:
    """Distance along each ray to its first crossing of each disc (rows x, y, radius):
    (len(discs), N), ``inf`` where it misses; a disc holding the ray's origin is ignored
    (a person cannot stand where the laser is)."""
    d = np.asarray(discs, np.float64).reshape(-1, 3)
    px = np.asarray(ox, np.float64) - d[:, 0, None]
    py = np.asarray(oy, np.float64) - d[:, 1, None]
    a = np.asarray(angle, np.float64)
    b = px * np.cos(a) + py * np.sin(a)
    c = px * px + py * py - d[:, 2, None] ** 2
    disc = b * b - c
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    return np.where((disc >= 0) & (c > 0) & (t > 0), t, np.inf)


def cut_ranges(ranges: np.ndarray, t: np.ndarray, range_min: float, range_max: float):
    """``ranges`` with each beam ending at ``t`` where that is nearer than the reading (or the
    reading is no return) and the laser could measure it: (float32 ranges, cut mask). An
    invalid reading (NaN, or below ``range_min``) stays as it is."""
    r = np.asarray(ranges, np.float64)
    with np.errstate(invalid="ignore"):
        cut = (t < r) & (t >= range_min) & (t < range_max)
    return np.where(cut, t, r).astype(np.float32), cut


def edit_scans(scan: Scan, sensor: Pose2D, boxes: Sequence[Box] = (), discs=None) -> np.ndarray:
    """The ranges ``scan`` would have had, its laser at ``sensor`` (map frame), with ``boxes``
    and the discs (rows x, y, radius: the people at this scan's time) in the world."""
    return cut_in(scan, sensor, box_params(boxes), discs)[0]


def cut_in(scan: Scan, sensor: Pose2D, boxes, discs):
    """(edited ranges, cut, first box entry, which box, from a box) of one scan."""
    angles = scan.angles() + sensor.theta
    n = angles.size
    boxes = box_params(boxes)
    tb = box_entry(sensor.x, sensor.y, angles, boxes) if len(boxes) else np.full((0, n), np.inf)
    tp = disc_entry(sensor.x, sensor.y, angles, discs) if discs is not None and len(discs) \
        else np.full((0, n), np.inf)
    box_t = tb.min(axis=0) if len(tb) else np.full(n, np.inf)
    which = tb.argmin(axis=0) if len(tb) else np.zeros(n, np.int64)
    people_t = tp.min(axis=0) if len(tp) else np.full(n, np.inf)
    ranges, cut = cut_ranges(scan.ranges, np.minimum(box_t, people_t), scan.range_min,
                             scan.range_max)
    return ranges, cut, box_t, which, cut & (box_t <= people_t)
