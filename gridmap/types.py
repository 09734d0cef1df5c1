"""The few types every package shares: the occupancy grid, a 2D pose and a lidar scan.

Conventions (REP 103): x forward, y left, yaw counter-clockwise, metres and radians.
Grids are indexed ``data[row, col]`` with row = y and col = x; cell (r, c) covers
x in [ox + c*res, ox + (c+1)*res) and y in [oy + r*res, oy + (r+1)*res), so its
centre is at (ox + (c + 0.5)*res, oy + (r + 0.5)*res).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .cells import FREE, OCCUPIED, UNKNOWN
from .errors import MapUpdatingError


class GridError(MapUpdatingError, ValueError):
    """A grid, map file or grid argument that cannot be used; the message names the problem."""


@dataclass(frozen=True)
class Pose2D:
    """A pose in the plane: position [m] and heading [rad]."""

    x: float
    y: float
    theta: float

    def compose(self, other: Pose2D) -> Pose2D:
        """``self (+) other``: ``other`` expressed in this pose's frame, returned in the parent frame."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            wrap_angle(self.theta + other.theta),
        )

    def inverse(self) -> Pose2D:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(-c * self.x - s * self.y, s * self.x - c * self.y, wrap_angle(-self.theta))

    def relative_to(self, base: Pose2D) -> Pose2D:
        """This pose expressed in ``base``'s frame: ``base^-1 (+) self``."""
        return base.inverse().compose(self)

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.theta], dtype=np.float64)

    @staticmethod
    def from_array(a) -> Pose2D:
        a = np.asarray(a, dtype=np.float64).reshape(3)
        return Pose2D(float(a[0]), float(a[1]), float(a[2]))

    def is_finite(self) -> bool:
        return math.isfinite(self.x) and math.isfinite(self.y) and math.isfinite(self.theta)


def wrap_angle(a):
    """Wrap an angle (or array of angles) to [-pi, pi)."""
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi if isinstance(a, np.ndarray) \
        else (a + math.pi) % (2 * math.pi) - math.pi


@dataclass
class Scan:
    """One 2D lidar scan. ``ranges`` [m] float32, ``inf`` where the beam had no return.

    A scan carries no mounting pose: the caller passes the sensor's pose in the map frame.
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    time: float = 0.0

    def __post_init__(self):
        self.ranges = np.ascontiguousarray(self.ranges, dtype=np.float32).reshape(-1)
        if not (math.isfinite(self.angle_min) and math.isfinite(self.angle_increment)):
            raise GridError(f"scan angles must be finite (angle_min={self.angle_min}, "
                            f"angle_increment={self.angle_increment})")
        if self.angle_increment == 0:
            # (a one-beam scan too: its beam has no width to search a window in)
            raise GridError("scan angle_increment is 0")
        if not (self.range_max > 0) or not (self.range_min >= 0) or self.range_min >= self.range_max:
            raise GridError(f"scan range limits are invalid (range_min={self.range_min}, "
                            f"range_max={self.range_max})")

    @property
    def beams(self) -> int:
        return int(self.ranges.size)

    def angles(self) -> np.ndarray:
        """Beam angles in the sensor frame [rad], float64."""
        return self.angle_min + self.angle_increment * np.arange(self.ranges.size, dtype=np.float64)

    def fov(self) -> float:
        """The angle the beams cover, counting one increment per beam [rad]."""
        return abs(self.angle_increment) * self.ranges.size

    def covers_full_circle(self) -> bool:
        """True when the beams cover 360 degrees, so the first and last beams are neighbours."""
        return self.fov() >= 2 * math.pi - 1e-3 * abs(self.angle_increment) - 1e-9


@dataclass
class OccupancyGrid:
    """A trinary occupancy grid: int8 cells, 0 free, 100 occupied, -1 unknown (ROS convention)."""

    data: np.ndarray
    resolution: float
    origin: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        data = np.asarray(self.data)
        if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] == 0:
            raise GridError(f"grid data must be a non-empty 2D array, got shape {data.shape}")
        if data.dtype != np.int8:
            if not np.all(np.isin(data, (FREE, OCCUPIED, UNKNOWN))):
                raise GridError("grid cells must be 0 (free), 100 (occupied) or -1 (unknown)")
            data = data.astype(np.int8)
        self.data = np.ascontiguousarray(data)
        if not (isinstance(self.resolution, (int, float, np.floating)) and self.resolution > 0
                and math.isfinite(self.resolution)):
            raise GridError(f"grid resolution must be a positive number, got {self.resolution!r}")
        self.resolution = float(self.resolution)
        ox, oy = (float(v) for v in self.origin)
        if not (math.isfinite(ox) and math.isfinite(oy)):
            raise GridError(f"grid origin must be finite, got {self.origin!r}")
        self.origin = (ox, oy)

    # --- shape -------------------------------------------------------------------------------
    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def shape(self) -> tuple[int, int]:
        return self.height, self.width

    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the grid's outer edges [m]."""
        ox, oy = self.origin
        return ox, oy, ox + self.width * self.resolution, oy + self.height * self.resolution

    # --- world <-> cell: the one place these conversions live ---------------------------------
    def world_to_cell(self, x, y):
        """Cell indices (row, col) of world points; not clipped (check with ``contains``)."""
        col = np.floor((np.asarray(x, dtype=np.float64) - self.origin[0]) / self.resolution)
        row = np.floor((np.asarray(y, dtype=np.float64) - self.origin[1]) / self.resolution)
        return row.astype(np.int64), col.astype(np.int64)

    def cell_to_world(self, row, col):
        """World coordinates (x, y) of cell centres."""
        x = self.origin[0] + (np.asarray(col, dtype=np.float64) + 0.5) * self.resolution
        y = self.origin[1] + (np.asarray(row, dtype=np.float64) + 0.5) * self.resolution
        return x, y

    def contains(self, row, col):
        row, col = np.asarray(row), np.asarray(col)
        return (row >= 0) & (row < self.height) & (col >= 0) & (col < self.width)

    # --- helpers -----------------------------------------------------------------------------
    def copy(self) -> OccupancyGrid:
        return OccupancyGrid(self.data.copy(), self.resolution, self.origin)

    def with_data(self, data: np.ndarray) -> OccupancyGrid:
        """A grid in the same frame with other cells."""
        if data.shape != self.data.shape:
            raise GridError(f"cells of shape {data.shape} do not fit a grid of shape {self.shape}")
        return OccupancyGrid(data, self.resolution, self.origin)

    def same_frame(self, other: OccupancyGrid) -> bool:
        return (self.shape == other.shape and abs(self.resolution - other.resolution) < 1e-9
                and abs(self.origin[0] - other.origin[0]) < 1e-9
                and abs(self.origin[1] - other.origin[1]) < 1e-9)

    def counts(self) -> dict[str, int]:
        d = self.data
        return {"free": int((d == FREE).sum()), "occupied": int((d == OCCUPIED).sum()),
                "unknown": int((d == UNKNOWN).sum())}

    @staticmethod
    def empty(width: int, height: int, resolution: float, origin=(0.0, 0.0),
              value: int = UNKNOWN) -> OccupancyGrid:
        return OccupancyGrid(np.full((height, width), value, dtype=np.int8), resolution, origin)
