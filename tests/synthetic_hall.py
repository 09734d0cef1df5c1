"""A synthetic 17 x 11 m hall recorded as a real robot would record it, for the log replay's
tests: a ROS bag with smooth wheel odometry, a localisation whose poses jitter from scan to
scan (``map -> odom`` in tf, as amcl sends it) and a 270 deg lidar, in a hall where, since the
map was made, objects were removed, moved and added and people walk.

Geometry is exact (rectangles and circles, ray-cast analytically by ``synthetic_room.cast``);
the reference map M is the hall before the changes rasterised at 5 cm, each object's outline
occupied around an unknown interior, as a lidar map has it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan

import synthetic_room as room

Rect, Circle = room.Rect, room.Circle
RES = 0.05
WIDTH, HEIGHT = 17.0, 11.0          # inner faces of the walls at 0 and 17, 0 and 11 [m]
WALL = 0.15
ORIGIN = (-0.5, -0.5)
MOUNT = Pose2D(0.2, 0.0, 0.0)
RATE = 10.0                          # [Hz] scans
SPEED = 0.5                          # [m/s]

# Everything stands a quarter cell off the grid: a face then lies a quarter of a cell inside
# its cell on one side of an object and three quarters on the other, half a cell on average,
# as faces of a real place fall anywhere in their cells (a face on a cell border would split
# its hits between two cells, one at a cell's centre would never).
Q = RES / 4


def _box(x0, y0, x1, y1) -> Rect:
    return Rect(x0 + Q, y0 + Q, x1 + Q, y1 + Q)


WALLS = [_box(-WALL, -WALL, 0.0, HEIGHT + WALL), _box(WIDTH, -WALL, WIDTH + WALL, HEIGHT + WALL),
         _box(-WALL, -WALL, WIDTH + WALL, 0.0), _box(-WALL, HEIGHT, WIDTH + WALL, HEIGHT + WALL)]

STATIC = [_box(3.0, 5.2, 14.0, 5.8),                       # a long rack down the middle
          _box(1.0, 1.0, 1.4, 1.4), _box(15.6, 9.6, 16.0, 10.0),   # pillars
          _box(8.3, 0.0, 8.7, 1.2), _box(12.0, 9.8, 13.5, 11.0)]   # a column, a cabinet
# Objects that were there when M was made; REMOVED are gone, MOVED stand elsewhere now.
REMOVED = {"pallet_r": _box(5.0, 2.0, 6.2, 2.8), "drum_r": Circle(11.5 + Q, 8.5 + Q, 0.3)}
MOVED = {"pallet_m": (_box(10.0, 1.4, 10.8, 2.6), _box(12.2, 1.6, 13.0, 2.8))}
KEPT = {"crate_k": _box(4.0, 8.0, 4.6, 8.6)}
ADDED = {"pallet_a": _box(7.0, 8.2, 8.2, 9.0), "box_a": _box(14.4, 7.4, 15.0, 8.0)}
# The route: a loop around the rack, driven twice, 1.5-2 m clear of everything.
ROUTE = [(2.0, 3.6), (15.5, 3.6), (15.5, 7.2), (2.0, 7.2), (2.0, 3.6)]


def before() -> list:
    return STATIC + list(REMOVED.values()) + [a for a, _ in MOVED.values()] + list(KEPT.values())


def after() -> list:
    return STATIC + [b for _, b in MOVED.values()] + list(KEPT.values()) + list(ADDED.values())


def frame() -> tuple[np.ndarray, np.ndarray]:
    """Cell centres (x, y), each (H, W), of the hall's grid."""
    w = int(round((WIDTH + 1.0) / RES))
    h = int(round((HEIGHT + 1.0) / RES))
    x = ORIGIN[0] + (np.arange(w) + 0.5) * RES
    y = ORIGIN[1] + (np.arange(h) + 0.5) * RES
    return np.meshgrid(x, y)


def _covers(shape, x, y) -> np.ndarray:
    """Cells the shape overlaps with positive area (a cell is RES wide around its centre)."""
    h = RES / 2
    if isinstance(shape, Rect):
        return (x + h > shape.x0 + 1e-9) & (x - h < shape.x1 - 1e-9) & \
            (y + h > shape.y0 + 1e-9) & (y - h < shape.y1 - 1e-9)
    qx = np.clip(shape.cx, x - h, x + h)
    qy = np.clip(shape.cy, y - h, y + h)
    return (qx - shape.cx) ** 2 + (qy - shape.cy) ** 2 < shape.radius ** 2


def outline(shape) -> np.ndarray:
    """The cells of ``shape`` that touch (8-neighbours) a cell it does not cover."""
    x, y = frame()
    m = _covers(shape, x, y)
    p = np.pad(m, 1)
    inner = np.ones_like(m)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            inner &= p[1 + dr:p.shape[0] - 1 + dr, 1 + dc:p.shape[1] - 1 + dc]
    return m & ~inner


def rasterise(shapes) -> OccupancyGrid:
    """Free inside the hall, walls and shapes' outlines occupied, interiors and outside unknown."""
    x, y = frame()
    data = np.full(x.shape, UNKNOWN, np.int8)
    data[(x > Q) & (x < WIDTH + Q) & (y > Q) & (y < HEIGHT + Q)] = FREE
    for s in WALLS:
        data[_covers(s, x, y) & _near_inside(x, y)] = OCCUPIED
    for s in shapes:
        data[_covers(s, x, y)] = UNKNOWN
        data[outline(s)] = OCCUPIED
    return OccupancyGrid(data, RES, ORIGIN)


def _near_inside(x, y) -> np.ndarray:
    """Wall cells within a cell of the hall's inside (the faces a lidar sees)."""
    return (x > Q - RES) & (x < WIDTH + Q + RES) & (y > Q - RES) & (y < HEIGHT + Q + RES)


def route_poses(laps: int = 2) -> list[Pose2D]:
    """True robot poses at RATE along the route at SPEED; corners turned at 30 deg/s."""
    pts = [np.asarray(p, float) for p in ROUTE]
    step, turn = SPEED / RATE, math.radians(30.0) / RATE
    heading = math.atan2(*(pts[1] - pts[0])[::-1])
    poses = []
    for _ in range(laps):
        for a, b in zip(pts[:-1], pts[1:]):
            target = math.atan2(b[1] - a[1], b[0] - a[0])
            d = (target - heading + math.pi) % (2 * math.pi) - math.pi
            for k in range(int(abs(d) / turn)):
                poses.append(Pose2D(a[0], a[1], heading + math.copysign((k + 1) * turn, d)))
            heading = target
            n = int(round(float(np.hypot(*(b - a))) / step))
            poses += [Pose2D(*(a + (b - a) * k / n), heading) for k in range(n)]
    return poses


@dataclass(frozen=True)
class Walker:
    """A person walking back and forth between two points at ``speed`` [m/s]."""

    a: tuple
    b: tuple
    speed: float = 1.0
    radius: float = 0.25

    def at(self, t: float) -> Circle:
        length = math.dist(self.a, self.b)
        s = (t * self.speed) % (2 * length)
        f = (s if s <= length else 2 * length - s) / length
        return Circle(self.a[0] + f * (self.b[0] - self.a[0]),
                      self.a[1] + f * (self.b[1] - self.a[1]), self.radius)


PEOPLE = [Walker((1.0, 9.5), (10.0, 9.5), 1.1), Walker((16.0, 1.0), (16.0, 9.0), 0.9),
          Walker((6.0, 0.8), (14.0, 0.8), 1.2)]


def record(seed: int = 0, jitter=(0.02, math.radians(0.5)), laps: int = 2,
           odometry_noise: float = 0.002):
    """(time, true pose, odometry pose, recorded pose, scan) at each scan: odometry from the
    true motion with ``odometry_noise`` of relative error per step (smooth, drifting slowly),
    the recorded localisation the true pose with ``jitter`` (std of x and y [m], of yaw [rad])
    drawn afresh at every scan, the scan ray-cast in the world after the changes, people in."""
    rng = np.random.default_rng(seed)
    fov, beams = math.radians(270.0), 541
    angle_min, inc = -fov / 2, fov / (beams - 1)
    angles = angle_min + inc * np.arange(beams)
    world = WALLS + after()
    out, odom = [], Pose2D(3.0, -1.0, 0.4)     # the odometry frame is not the map's
    poses = route_poses(laps)
    for k, true in enumerate(poses):
        t = 100.0 + k / RATE
        if k:
            d = poses[k - 1].inverse().compose(true)
            n = odometry_noise * rng.standard_normal(3)
            odom = odom.compose(Pose2D(d.x * (1 + n[0]), d.y + abs(d.x) * n[1],
                                       d.theta + abs(d.x) * n[2]))
        shapes = world + [p.at(t) for p in PEOPLE]
        ranges = room.cast(shapes, true.compose(MOUNT), angles, 20.0)
        ranges = ranges + 0.01 * rng.standard_normal(beams)
        scan = Scan(ranges.astype(np.float32), angle_min, inc, 0.05, 20.0, t)
        dx, dy = jitter[0] * rng.standard_normal(2)
        recorded = Pose2D(true.x + dx, true.y + dy, true.theta + jitter[1] * rng.standard_normal())
        out.append((t, true, odom, recorded, scan))
    return out


def bag_records(steps) -> list:
    """The recording as bag records: the mount in /tf_static, odometry in /odom and /tf, the
    localisation as map -> odom in /tf at each scan, the scans in /scan."""
    from robotlogs.records import OdomRecord, ScanRecord, TransformRecord

    recs = [TransformRecord(steps[0][0], "base_link", "laser", MOUNT, static=True)]
    for t, _, odom, recorded, scan in steps:
        recs += [OdomRecord(t, odom), TransformRecord(t, "odom", "base_link", odom),
                 TransformRecord(t, "map", "odom", recorded.compose(odom.inverse())),
                 ScanRecord(t, scan)]
    return recs


def gated(steps) -> list:
    """The steps the updater's gate (default configuration, on the odometry) lets through."""
    from updater import UpdaterConfig
    from updater.gating import Gate

    gate, out = Gate(UpdaterConfig()), []
    for step in steps:
        t, odom = step[0], step[2]
        if not gate.check(t, odom, True):
            gate.mark_processed(t, odom)
            out.append(step)
    return out


def visible(steps, cells: np.ndarray, hits: int = 7) -> np.ndarray:
    """The cells of ``cells`` in which noise-free beams from the true poses of the scans the
    gate lets through end in at least ``hits`` scans (people left out): what the updater can
    see often enough to decide (docs/evaluation.md's observable cells, for hits)."""
    fov, beams = math.radians(270.0), 541
    angles = -fov / 2 + fov / (beams - 1) * np.arange(beams)
    world = WALLS + after()
    count = np.zeros(cells.shape, np.int32)
    grid = OccupancyGrid.empty(cells.shape[1], cells.shape[0], RES, ORIGIN)
    for _, true, _, _, _ in gated(steps):
        sensor = true.compose(MOUNT)
        r = room.cast(world, sensor, angles, 18.0)
        ok = np.isfinite(r)
        a = angles[ok] + sensor.theta
        # a hair inside the surface, so a hit on a cell edge counts for the cell it hit
        rr = r[ok] + 1e-3
        rows, cols = grid.world_to_cell(sensor.x + rr * np.cos(a), sensor.y + rr * np.sin(a))
        inside = grid.contains(rows, cols)
        seen = np.zeros(cells.shape, bool)
        seen[rows[inside], cols[inside]] = True
        count += seen
    return cells & (count >= hits)
