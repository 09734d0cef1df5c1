"""A synthetic warehouse, a route, noisy odometry and a ray-cast lidar: enough world to test and
benchmark the localiser on its own, without the simulator.

The warehouse is about the size of AWS's small warehouse (13.7 m x 20.6 m) with racks, pillars,
pallets and drums. Two rasterisations of it: ``truth_grid`` (solid, fine cells) that the lidar
is cast against, and ``map_grid`` (the outlines a lidar can see, object interiors and the
outside unknown, 5 cm) that the localiser is given, like a SLAM map. Odometry is corrupted with
the odometry motion model itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan, wrap_angle
from gridmap.raycast import cast_rays

from localization.motion import motion_sigmas, odometry_delta


@dataclass(frozen=True)
class Box:
    cx: float
    cy: float
    w: float           # extent along x [m]
    h: float           # extent along y [m]

    def covers(self, x, y):
        return (np.abs(x - self.cx) <= self.w / 2) & (np.abs(y - self.cy) <= self.h / 2)

    def moved(self, dx: float, dy: float) -> Box:
        return replace(self, cx=self.cx + dx, cy=self.cy + dy)


@dataclass(frozen=True)
class Circle:
    cx: float
    cy: float
    r: float

    def covers(self, x, y):
        return (x - self.cx) ** 2 + (y - self.cy) ** 2 <= self.r ** 2

    def moved(self, dx: float, dy: float) -> Circle:
        return replace(self, cx=self.cx + dx, cy=self.cy + dy)


@dataclass(frozen=True)
class Layout:
    bounds: tuple[float, float, float, float]      # inner faces of the outer walls [m]
    wall: float
    static: tuple = ()
    movable: dict = field(default_factory=dict)

    def shapes(self):
        return list(self.static) + list(self.movable.values())

    def with_moves(self, moves: dict) -> Layout:
        """The layout with movable objects shifted: ``{name: (dx, dy)}``."""
        movable = dict(self.movable)
        for name, (dx, dy) in moves.items():
            movable[name] = movable[name].moved(dx, dy)
        return replace(self, movable=movable)


def warehouse() -> Layout:
    """A warehouse with irregular racks, so that its places look different from each other."""
    static = (
        Box(-5.0, -4.0, 1.0, 8.0), Box(-5.0, 5.5, 1.0, 5.0),      # left racks
        Box(-1.5, -3.0, 1.0, 7.0), Box(-1.5, 6.0, 1.0, 4.0),      # middle racks
        Box(2.0, -5.0, 1.0, 5.0), Box(2.0, 3.5, 1.0, 6.0),        # right racks
        Box(3.5, 9.6, 4.0, 0.6),                                  # shelf by the top wall
        Box(5.65, -8.9, 2.4, 2.84),                               # office in a corner
        Box(4.8, -0.5, 0.3, 0.3), Box(-4.1, 1.8, 0.3, 0.3),       # pillars
    )
    movable = {
        "pallet_1": Box(0.25, 1.8, 1.2, 0.8),
        "pallet_2": Box(4.5, 4.0, 1.0, 1.2),
        "pallet_3": Box(-5.6, -9.3, 1.2, 0.8),
        "pallet_4": Box(-6.0, 1.6, 0.8, 1.2),
        "box_1": Box(5.5, 7.5, 0.6, 0.6),
        "drum_1": Circle(-0.55, -7.8, 0.3),
        "drum_2": Circle(4.2, -2.2, 0.3),
    }
    return Layout((-6.85, -10.32, 6.85, 10.32), 0.13, static, movable)


# A 51.6 m tour of the aisles, clear of every object by more than the robot's radius.
ROUTE = ((0.3, -9.2), (0.3, -1.0), (3.5, -1.0), (3.5, 8.5), (-3.2, 8.6), (-3.2, -9.0),
         (3.5, -9.2))


def _covered(layout: Layout, resolution: float):
    """Cell grid over the building and its walls, and which cell centres an object covers."""
    x0, y0, x1, y1 = layout.bounds
    t = layout.wall
    origin = (x0 - t - resolution, y0 - t - resolution)
    w = int(math.ceil((x1 - x0 + 2 * t) / resolution)) + 2
    h = int(math.ceil((y1 - y0 + 2 * t) / resolution)) + 2
    xs = origin[0] + (np.arange(w) + 0.5) * resolution
    ys = origin[1] + (np.arange(h) + 0.5) * resolution
    x, y = np.meshgrid(xs, ys)
    inside = (x > x0) & (x < x1) & (y > y0) & (y < y1)
    walls = ~inside & (x > x0 - t) & (x < x1 + t) & (y > y0 - t) & (y < y1 + t)
    covered = walls.copy()
    for shape in layout.shapes():
        covered |= shape.covers(x, y)
    return origin, inside & ~covered, covered


def truth_grid(layout: Layout, resolution: float = 0.02) -> OccupancyGrid:
    """Solid objects and walls, for ray casting the lidar."""
    origin, free, covered = _covered(layout, resolution)
    data = np.where(covered, OCCUPIED, FREE).astype(np.int8)
    return OccupancyGrid(data, resolution, origin)


def map_grid(layout: Layout, resolution: float = 0.05) -> OccupancyGrid:
    """What a mapped warehouse looks like: free space, occupied outlines (object cells touching
    free space, 8-neighbours), everything else unknown."""
    origin, free, covered = _covered(layout, resolution)
    near_free = free.copy()
    padded = np.pad(free, 1)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            near_free |= padded[1 + dr:padded.shape[0] - 1 + dr, 1 + dc:padded.shape[1] - 1 + dc]
    data = np.full(free.shape, UNKNOWN, np.int8)
    data[free] = FREE
    data[covered & near_free] = OCCUPIED
    return OccupancyGrid(data, resolution, origin)


def route_poses(waypoints, step: float = 0.06, turn_step: float = 0.15) -> list[Pose2D]:
    """True poses of a differential-drive robot driving the waypoints: straight at ``step`` [m]
    per scan, turning on the spot at ``turn_step`` [rad] per scan at each corner."""
    pts = [np.asarray(p, dtype=np.float64) for p in waypoints]
    heading = math.atan2(*(pts[1] - pts[0])[::-1])
    poses = [Pose2D(pts[0][0], pts[0][1], heading)]
    for a, b in zip(pts[:-1], pts[1:]):
        target = math.atan2(b[1] - a[1], b[0] - a[0])
        turn = (target - heading + math.pi) % (2 * math.pi) - math.pi
        for k in range(1, int(math.ceil(abs(turn) / turn_step)) + 1):
            f = min(1.0, k * turn_step / abs(turn))
            poses.append(Pose2D(a[0], a[1], heading + f * turn))
        heading = target
        length = float(np.hypot(*(b - a)))
        for k in range(1, int(math.ceil(length / step)) + 1):
            f = min(1.0, k * step / length)
            p = a + f * (b - a)
            poses.append(Pose2D(p[0], p[1], heading))
    return poses


def corrupt_odometry(true_poses, alphas, rng: np.random.Generator,
                     start: Pose2D = Pose2D(0.0, 0.0, 0.0)) -> list[Pose2D]:
    """Odometry poses (starting at ``start``): each true step (rot1, trans, rot2) perturbed with
    the odometry motion model's noise (variances from ``alphas``)."""
    odom = [start]
    for a, b in zip(true_poses[:-1], true_poses[1:]):
        delta = np.array(odometry_delta(a, b))
        rot1, trans, rot2 = delta + motion_sigmas(delta, alphas) * rng.standard_normal(3)
        last = odom[-1]
        odom.append(Pose2D(last.x + trans * math.cos(last.theta + rot1),
                           last.y + trans * math.sin(last.theta + rot1),
                           wrap_angle(last.theta + rot1 + rot2)))
    return odom


@dataclass(frozen=True)
class Lidar:
    mount: Pose2D = Pose2D(0.25, 0.0, 0.0)
    fov: float = math.radians(270)
    beams: int = 1081
    range_min: float = 0.05
    range_max: float = 20.0
    noise: float = 0.01          # range noise std [m]

    def scan(self, truth: OccupancyGrid, robot: Pose2D, rng: np.random.Generator,
             time: float = 0.0) -> Scan:
        angle_min = -self.fov / 2
        inc = self.fov / (self.beams - 1)
        angles = angle_min + inc * np.arange(self.beams)
        r = cast_rays(truth, robot.compose(self.mount), angles, self.range_max)
        r = r + self.noise * rng.standard_normal(r.size)
        r[~(r < self.range_max)] = np.inf
        return Scan(r.astype(np.float32), angle_min, inc, self.range_min, self.range_max, time)
