"""Synthetic rooms for the updater's tests (the helpers' own tests: test_synthetic_room.py).

A world is a list of axis-aligned rectangles and circles [m]. Scans are ray-cast analytically
from that geometry; the reference map is the geometry rasterised at 5 cm (cells a shape overlaps
are occupied; a hollow shape keeps only its outline, its interior unknown, as a lidar map has
it). The robot drives a circle at constant speed; the updater gets the sensor pose with seeded
2 cm / 1 deg noise and the true (smooth) odometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan

RES = 0.05
SIZE = 11.0                 # map side [m]; the room's inner faces are at 0.5 and 10.5
WALL = 0.15                 # wall thickness [m]


@dataclass(frozen=True)
class Rect:
    x0: float
    y0: float
    x1: float
    y1: float


@dataclass(frozen=True)
class Circle:
    cx: float
    cy: float
    radius: float


def room_walls() -> list[Rect]:
    lo, hi = 0.5, SIZE - 0.5
    return [Rect(lo - WALL, lo - WALL, lo, hi + WALL), Rect(hi, lo - WALL, hi + WALL, hi + WALL),
            Rect(lo - WALL, lo - WALL, hi + WALL, lo), Rect(lo - WALL, hi, hi + WALL, hi + WALL)]


def cast(shapes, pose: Pose2D, angles: np.ndarray, max_range: float) -> np.ndarray:
    """Exact ranges [m] from ``pose`` along ``angles`` (sensor frame) to the nearest shape;
    inf beyond ``max_range``."""
    a = pose.theta + np.asarray(angles, dtype=np.float64)
    dx, dy = np.cos(a), np.sin(a)
    best = np.full(a.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for s in shapes:
            if isinstance(s, Rect):
                t_lo = np.full(a.shape, -np.inf)
                t_hi = np.full(a.shape, np.inf)
                for p, d, lo, hi in ((pose.x, dx, s.x0, s.x1), (pose.y, dy, s.y0, s.y1)):
                    t1, t2 = (lo - p) / d, (hi - p) / d
                    inside = (p >= lo) & (p <= hi)
                    t_lo = np.maximum(t_lo, np.where(d == 0, np.where(inside, -np.inf, np.inf),
                                                     np.minimum(t1, t2)))
                    t_hi = np.minimum(t_hi, np.where(d == 0, np.where(inside, np.inf, -np.inf),
                                                     np.maximum(t1, t2)))
                t = np.where((t_hi >= t_lo) & (t_lo > 0), t_lo, np.inf)
            else:
                ox, oy = pose.x - s.cx, pose.y - s.cy
                b = dx * ox + dy * oy
                disc = b * b - (ox * ox + oy * oy - s.radius**2)
                t = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
                t = np.where(t > 0, t, np.inf)
            best = np.minimum(best, t)
    best[best > max_range] = np.inf
    return best


def _overlap(shape, res, n):
    """Boolean (n, n) mask of the cells the shape overlaps with positive area."""
    lo = np.arange(n) * res
    hi = lo + res
    if isinstance(shape, Rect):
        cols = (lo < shape.x1 - 1e-9) & (hi > shape.x0 + 1e-9)
        rows = (lo < shape.y1 - 1e-9) & (hi > shape.y0 + 1e-9)
        return rows[:, None] & cols[None, :]
    # a circle overlaps a cell when the cell's nearest point lies inside it
    qx = np.clip(shape.cx, lo, hi)
    qy = np.clip(shape.cy, lo, hi)
    return (qy[:, None] - shape.cy) ** 2 + (qx[None, :] - shape.cx) ** 2 < shape.radius**2


def rasterise(solid, hollow=(), res=RES, size=SIZE) -> OccupancyGrid:
    """The reference map: unknown outside the room, free inside, shapes occupied; ``hollow``
    shapes keep a one-cell outline around an unknown interior."""
    n = int(round(size / res))
    data = np.full((n, n), UNKNOWN, np.int8)
    inner = Rect(0.5, 0.5, size - 0.5, size - 0.5)
    data[_overlap(inner, res, n)] = FREE
    for s in list(solid) + list(hollow):
        data[_overlap(s, res, n)] = OCCUPIED
    for s in hollow:
        m = _overlap(s, res, n)
        core = m.copy()
        core[1:-1, 1:-1] &= (m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
                             & m[:-2, :-2] & m[:-2, 2:] & m[2:, :-2] & m[2:, 2:])
        data[core] = UNKNOWN
    return OccupancyGrid(data, res, (0.0, 0.0))


def cells_of(shape, res=RES, size=SIZE) -> np.ndarray:
    return _overlap(shape, res, int(round(size / res)))


@dataclass
class Drive:
    """A robot circling (cx, cy) at ``radius`` with ``speed``, heading along the circle, with
    one lidar at the robot's centre. ``steps()`` yields (true pose, noisy pose, time)."""

    cx: float = 5.5
    cy: float = 5.5
    radius: float = 3.0
    speed: float = 0.5          # [m/s]
    rate: float = 10.0          # [Hz]
    seconds: float = 80.0
    pos_noise: float = 0.02     # [m]
    yaw_noise: float = math.radians(1.0)
    seed: int = 0
    clockwise: bool = False

    def steps(self):
        rng = np.random.default_rng(self.seed)
        w = self.speed / self.radius * (-1 if self.clockwise else 1)
        for k in range(int(self.seconds * self.rate)):
            t = k / self.rate
            phi = w * t
            x, y = self.cx + self.radius * math.cos(phi), self.cy + self.radius * math.sin(phi)
            true = Pose2D(x, y, phi + math.copysign(math.pi / 2, w))
            noisy = Pose2D(x + rng.normal(0, self.pos_noise), y + rng.normal(0, self.pos_noise),
                           true.theta + rng.normal(0, self.yaw_noise))
            yield true, noisy, t


def full_scan(shapes, pose, t, beams=720, max_range=20.0) -> Scan:
    inc = 2 * math.pi / beams
    angles = -math.pi + inc * np.arange(beams)
    return Scan(cast(shapes, pose, angles, max_range), -math.pi, inc, 0.05, max_range, time=t)


def partial_scan(shapes, pose, t, fov_deg=270.0, beams=1081, max_range=20.0) -> Scan:
    """A lidar of less than 360 deg, first and last beams at -fov/2 and +fov/2."""
    inc = math.radians(fov_deg) / (beams - 1)
    angle_min = -math.radians(fov_deg) / 2
    angles = angle_min + inc * np.arange(beams)
    return Scan(cast(shapes, pose, angles, max_range), angle_min, inc, 0.05, max_range, time=t)


def hit_points(scan: Scan, pose: Pose2D) -> tuple[np.ndarray, np.ndarray]:
    ok = np.isfinite(scan.ranges)
    a = pose.theta + scan.angles()[ok]
    r = scan.ranges[ok].astype(np.float64)
    return pose.x + r * np.cos(a), pose.y + r * np.sin(a)


def dilate(mask: np.ndarray, cells: int) -> np.ndarray:
    """``mask`` grown by ``cells`` in every direction (8-neighbour steps)."""
    out = mask.copy()
    for _ in range(cells):
        grown = out.copy()
        grown[1:, :] |= out[:-1, :]
        grown[:-1, :] |= out[1:, :]
        grown[:, 1:] |= grown[:, :-1].copy()
        grown[:, :-1] |= grown[:, 1:].copy()
        out = grown
    return out


def carmen_log(path, poses, stamps):
    """A CARMEN log at ``path``: ROBOTLASER1 lines (270 deg, 1 deg apart) cast on the room's
    walls alone, at ``poses`` (laser pose = odometry pose) and ``stamps``."""
    walls = room_walls()
    lines = []
    for pose, t in zip(poses, stamps):
        scan = partial_scan(walls, pose, 0.0, fov_deg=270.0, beams=271)
        r = " ".join(f"{v:.3f}" for v in np.minimum(scan.ranges, 81.83))
        p = f"{pose.x:.6f} {pose.y:.6f} {pose.theta:.6f}"
        lines.append(f"ROBOTLASER1 0 {-math.radians(135):.6f} {math.radians(270):.6f} "
                     f"{math.radians(1):.8f} 81.83 0.01 0 271 {r} 0 {p} {p} 0 0 0 0 0 "
                     f"{t:.3f} h 0")
    path.write_text("\n".join(lines) + "\n")
    return path
