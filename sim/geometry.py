"""Plane geometry of the world: boxes and circles as arrays, and the exact tests between them.

A world is two arrays, so that the kernels can take it whole:

- ``boxes (B, 5)``: centre x, centre y [m], half width (along the box's own x), half depth [m],
  yaw [rad];
- ``circles (C, 3)``: centre x, centre y, radius [m].

Box outlines become ``segments (4B, 4)`` (x0, y0, x1, y1) wound counter-clockwise, so the
outward normal of a segment is on its right; the lidar kernel relies on that to skip faces
that look away from the sensor.
"""

from __future__ import annotations

import math

import numpy as np

# Shapes that merely touch are not overlapping: a rack standing against a wall is legal.
TOUCH_TOL = 1e-6


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """Corners (B, 4, 2) of boxes (B, 5), counter-clockwise."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 5)
    cx, cy, hw, hh, yaw = boxes.T
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    lx = local[None, :, 0] * hw[:, None]
    ly = local[None, :, 1] * hh[:, None]
    x = cx[:, None] + c[:, None] * lx - s[:, None] * ly
    y = cy[:, None] + s[:, None] * lx + c[:, None] * ly
    return np.stack([x, y], axis=-1)


def box_segments(boxes: np.ndarray) -> np.ndarray:
    """The outline segments (4B, 4) of boxes, each box counter-clockwise."""
    corners = box_corners(boxes)
    nxt = np.roll(corners, -1, axis=1)
    return np.concatenate([corners, nxt], axis=-1).reshape(-1, 4)


def box_extent(boxes: np.ndarray) -> np.ndarray:
    """Axis-aligned bounds (B, 4) x_min, y_min, x_max, y_max of boxes."""
    corners = box_corners(boxes)
    return np.concatenate([corners.min(axis=1), corners.max(axis=1)], axis=1)


def wall_boxes(bounds, thickness: float) -> np.ndarray:
    """Four boxes (4, 5) whose inner faces are the rectangle ``bounds`` (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = (float(v) for v in bounds)
    t = float(thickness)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    half_w, half_h = (x1 - x0) / 2 + t, (y1 - y0) / 2 + t
    return np.array([
        [cx, y0 - t / 2, half_w, t / 2, 0.0],      # south, full length so the corners are closed
        [cx, y1 + t / 2, half_w, t / 2, 0.0],      # north
        [x0 - t / 2, cy, t / 2, half_h - t, 0.0],  # west, between the south and north walls
        [x1 + t / 2, cy, t / 2, half_h - t, 0.0],  # east
    ])


# --- distances -----------------------------------------------------------------------------------

def point_box_distance(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Signed distance (P, B) from points (P, 2) to boxes: negative inside."""
    points = np.asarray(points, np.float64).reshape(-1, 2)
    boxes = np.asarray(boxes, np.float64).reshape(-1, 5)
    dx = points[:, None, 0] - boxes[None, :, 0]
    dy = points[:, None, 1] - boxes[None, :, 1]
    c, s = np.cos(boxes[:, 4]), np.sin(boxes[:, 4])
    # the point in each box's own frame, folded into its first quadrant
    u = np.abs(c * dx + s * dy) - boxes[:, 2]
    v = np.abs(-s * dx + c * dy) - boxes[:, 3]
    outside = np.hypot(np.maximum(u, 0.0), np.maximum(v, 0.0))
    inside = np.minimum(np.maximum(u, v), 0.0)
    return outside + inside


def point_circle_distance(points: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Signed distance (P, C) from points (P, 2) to circles: negative inside."""
    points = np.asarray(points, np.float64).reshape(-1, 2)
    circles = np.asarray(circles, np.float64).reshape(-1, 3)
    d = np.hypot(points[:, None, 0] - circles[None, :, 0], points[:, None, 1] - circles[None, :, 1])
    return d - circles[None, :, 2]


def segment_box_distance(a, b, boxes: np.ndarray) -> np.ndarray:
    """Distance (B,) from the segment a-b to each box (0 when they intersect)."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 5)
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    if boxes.shape[0] == 0:
        return np.zeros(0)
    # The segment meets a box if an end point is inside or it crosses an edge; otherwise the
    # distance is attained at an end point of the segment or at a corner of the box.
    d_ends = np.minimum(point_box_distance(a[None], boxes)[0], point_box_distance(b[None], boxes)[0])
    corners = box_corners(boxes)
    d_corners = _point_segment_distance(corners.reshape(-1, 2), a, b).reshape(-1, 4).min(axis=1)
    segs = box_segments(boxes).reshape(-1, 4, 4)
    crosses = _segments_cross(a, b, segs).any(axis=1)
    d = np.minimum(np.maximum(d_ends, 0.0), d_corners)
    return np.where(crosses | (d_ends <= 0), 0.0, d)


def segment_circle_distance(a, b, circles: np.ndarray) -> np.ndarray:
    """Distance (C,) from the segment a-b to each circle (0 when they intersect)."""
    circles = np.asarray(circles, np.float64).reshape(-1, 3)
    d = _point_segment_distance(circles[:, :2], np.asarray(a, float), np.asarray(b, float))
    return np.maximum(d - circles[:, 2], 0.0)


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    L2 = float(ab @ ab)
    t = np.zeros(len(p)) if L2 == 0 else np.clip(((p - a) @ ab) / L2, 0.0, 1.0)
    q = a + t[:, None] * ab
    return np.hypot(p[:, 0] - q[:, 0], p[:, 1] - q[:, 1])


def _segments_cross(a, b, segs: np.ndarray) -> np.ndarray:
    """Whether segment a-b properly crosses each segment of ``segs (..., 4)``."""
    p, q = segs[..., :2], segs[..., 2:]

    def orient(o, u, v):
        return (u[..., 0] - o[..., 0]) * (v[..., 1] - o[..., 1]) - \
            (u[..., 1] - o[..., 1]) * (v[..., 0] - o[..., 0])

    a = np.broadcast_to(a, p.shape)
    b = np.broadcast_to(b, p.shape)
    d1, d2 = orient(p, q, a), orient(p, q, b)
    d3, d4 = orient(a, b, p), orient(a, b, q)
    return (d1 * d2 < 0) & (d3 * d4 < 0)


# --- overlaps between shapes (positive area in common) -------------------------------------------

def boxes_overlap(b1, b2, tol: float = TOUCH_TOL) -> bool:
    """Whether two boxes (5,) share area, by the separating axis test."""
    c1, c2 = box_corners(np.array([b1, b2]))
    for yaw in (b1[4], b2[4]):
        for ax in ((math.cos(yaw), math.sin(yaw)), (-math.sin(yaw), math.cos(yaw))):
            p1, p2 = c1 @ ax, c2 @ ax
            if min(p1.max(), p2.max()) - max(p1.min(), p2.min()) <= tol:
                return False
    return True


def box_circle_overlap(box, circle, tol: float = TOUCH_TOL) -> bool:
    return bool(point_box_distance(np.asarray(circle[:2])[None], np.asarray(box)[None])[0, 0]
                < circle[2] - tol)


def circles_overlap(c1, c2, tol: float = TOUCH_TOL) -> bool:
    return math.hypot(c1[0] - c2[0], c1[1] - c2[1]) < c1[2] + c2[2] - tol


def box_inside(box, bounds, tol: float = TOUCH_TOL) -> bool:
    """Whether a box lies within the rectangle ``bounds`` (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = box_extent(np.asarray(box)[None])[0]
    return x0 >= bounds[0] - tol and y0 >= bounds[1] - tol and x1 <= bounds[2] + tol \
        and y1 <= bounds[3] + tol


def circle_inside(circle, bounds, tol: float = TOUCH_TOL) -> bool:
    x, y, r = circle
    return x - r >= bounds[0] - tol and y - r >= bounds[1] - tol and x + r <= bounds[2] + tol \
        and y + r <= bounds[3] + tol


def obstacle_arrays(obstacles, bounds=None, wall_thickness: float = 0.0):
    """``boxes (B, 5)`` and ``circles (C, 3)`` of objects (anything with ``is_circle``,
    ``box()`` and ``circle()``), with the four outer walls first when ``bounds`` is given."""
    boxes = [wall_boxes(bounds, wall_thickness)] if bounds is not None else []
    boxes += [o.box()[None] for o in obstacles if not o.is_circle]
    circles = [o.circle()[None] for o in obstacles if o.is_circle]
    b = np.concatenate(boxes) if boxes else np.zeros((0, 5))
    c = np.concatenate(circles) if circles else np.zeros((0, 3))
    return np.ascontiguousarray(b, np.float64), np.ascontiguousarray(c, np.float64)
