"""A top view of a session as an RGB array: the updated map with its changes, the people, the
robot where it is and where it thinks it is, and the latest scan coloured by the classifier.

Numpy and Pillow only (no figure machinery), so the environment can render every step. North is
up: image row 0 is the map's last row.
"""

from __future__ import annotations

import math

import numpy as np

from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D

# Per-beam verdicts of the classifier, in the order of updater.BEAM_* (invalid, unchanged,
# skipped, detected change); rerun_log uses the same colours.
VERDICT_COLORS = np.array([[150, 150, 150], [0, 130, 200], [255, 190, 0], [230, 25, 75]],
                          np.uint8)
UNCLASSIFIED = (0, 170, 170)   # points of a scan the updater gated or skipped
CELL_COLORS = {"free": (255, 255, 255), "occupied": (40, 40, 40), "unknown": (190, 190, 190),
               "freed": (150, 230, 150), "added": (220, 60, 200)}
PERSON, ROBOT, ESTIMATE = (245, 130, 48), (31, 119, 180), (60, 180, 75)


def map_colors(grid: OccupancyGrid, reference: OccupancyGrid | None = None) -> np.ndarray:
    """(H, W, 3) uint8 colours of the cells, rows as in the grid (row 0 = south): changes from
    ``reference`` stand out (freed green, newly occupied magenta)."""
    d = grid.data
    out = np.empty(d.shape + (3,), np.uint8)
    out[...] = CELL_COLORS["unknown"]
    out[d == FREE] = CELL_COLORS["free"]
    out[d == OCCUPIED] = CELL_COLORS["occupied"]
    if reference is not None:
        changed = d != reference.data
        out[changed & (d == FREE)] = CELL_COLORS["freed"]
        out[changed & (d == OCCUPIED)] = CELL_COLORS["added"]
    return out


def scan_points(ranges: np.ndarray, angles: np.ndarray, sensor: Pose2D) -> np.ndarray:
    """End points (N, 2) [m] in the map frame of the finite ranges, NaN rows for the others."""
    r = np.where(np.isfinite(ranges), ranges, np.nan).astype(np.float64)
    a = angles + sensor.theta
    return np.column_stack([sensor.x + r * np.cos(a), sensor.y + r * np.sin(a)])


def top_view(grid: OccupancyGrid, reference: OccupancyGrid | None = None, *,
             people: np.ndarray | None = None, robot: Pose2D | None = None,
             robot_radius: float = 0.35, estimate: Pose2D | None = None,
             points: np.ndarray | None = None, verdicts: np.ndarray | None = None,
             scale: int = 2) -> np.ndarray:
    """The picture (H * scale, W * scale, 3) uint8. ``people`` (N, 3) x, y, radius [m];
    ``points`` (N, 2) [m] scan end points (NaN rows skipped) coloured by ``verdicts``."""
    from PIL import Image, ImageDraw

    cells = map_colors(grid, reference)[::-1]
    img = Image.fromarray(np.ascontiguousarray(cells)).resize(
        (grid.width * scale, grid.height * scale), Image.NEAREST)
    draw = ImageDraw.Draw(img)
    ox, oy = grid.origin
    k = scale / grid.resolution
    top = grid.height * scale

    def px(x, y):
        return (x - ox) * k, top - (y - oy) * k

    if points is not None and len(points):
        ok = np.isfinite(points).all(axis=1)
        u, v = px(points[ok, 0], points[ok, 1])
        if verdicts is None:
            colors = np.tile(np.array(UNCLASSIFIED, np.uint8), (len(u), 1))
        else:
            codes = np.asarray(verdicts)[ok].astype(np.int64)
            colors = VERDICT_COLORS[np.clip(codes, 0, len(VERDICT_COLORS) - 1)]
        h = max(1, scale)
        for x, y, c in zip(u.tolist(), v.tolist(), colors.tolist()):
            draw.rectangle((x - h, y - h, x + h, y + h), fill=tuple(c))
    for x, y, r in (people if people is not None else np.zeros((0, 3))).tolist():
        cx, cy = px(x, y)
        draw.ellipse((cx - r * k, cy - r * k, cx + r * k, cy + r * k), fill=PERSON)
    for pose, color, fill in ((estimate, ESTIMATE, None), (robot, ROBOT, ROBOT)):
        if pose is None:
            continue
        cx, cy = px(pose.x, pose.y)
        rr = robot_radius * k
        draw.ellipse((cx - rr, cy - rr, cx + rr, cy + rr), outline=color, fill=fill,
                     width=max(1, scale))
        hx, hy = px(pose.x + 1.5 * robot_radius * math.cos(pose.theta),
                    pose.y + 1.5 * robot_radius * math.sin(pose.theta))
        draw.line((cx, cy, hx, hy), fill=color if fill is None else (0, 0, 0),
                  width=max(1, scale))
    return np.asarray(img, np.uint8)
