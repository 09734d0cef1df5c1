"""Log-odds occupancy mapping from scans with known sensor poses (Probabilistic Robotics, ch. 9).

Each cell holds the log-odds l = log(p / (1 - p)) of being occupied, starting at 0 (p = 0.5).
A beam with a return lowers every cell it passes through by ``miss`` and raises the cell of its
end point by ``hit``; a beam with no return (inf, or at or beyond range_max) lowers the cells up
to ``no_return_clearance`` and raises none. With ``hit_guard`` g > 0 a scan gives no miss to
the cells within g cells of one of its returns (rays grazing a face the same scan hits are no
evidence that it is gone; M1 is mapped without it). Values are clamped to [clamp_min,
clamp_max] so that the map can still change later. Thresholding gives the trinary map:
occupied above ``occupied_above``, free below ``free_below``, unknown in between (which
includes every cell no beam ever reached).

This is how the initial map M1 is built from the mapping session's scans and true poses::

    mapper = LogOddsMapper(OccupancyGrid.empty(280, 420, 0.05, origin=(-7.0, -10.5)))
    for scan, sensor_pose in observations:
        mapper.add_scan(scan, sensor_pose)
    m1 = mapper.to_grid()
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from .cells import FREE, OCCUPIED, UNKNOWN
from .config import config_from_dict
from .types import GridError, OccupancyGrid, Pose2D, Scan


@dataclass(frozen=True)
class LogOddsParams:
    """Increments and thresholds of log-odds mapping (log-odds units unless stated)."""

    hit: float = 0.85                 # end cell of a return: p = 0.7 per observation
    miss: float = -0.4                # cells the beam passed through: p = 0.4
    clamp_min: float = -2.0           # p = 0.12: a freed cell turns occupied after 3 hits
    clamp_max: float = 3.5            # p = 0.97: an occupied cell turns free after ~11 misses
    occupied_above: float = 0.6       # p > 0.65: one hit marks a cell occupied
    free_below: float = -0.6          # p < 0.35: two misses mark a cell free
    no_return_clearance: float = 5.0  # [m] free space assumed along a beam with no return
    hit_guard: int = 0                # [cells] around a return that the same scan gives no miss

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value):
                raise GridError(f"log-odds mapping: {f.name} must be a finite number, "
                                f"got {value!r}")
        rules = {
            "hit": (self.hit > 0, "> 0"), "miss": (self.miss < 0, "< 0"),
            "clamp_min": (self.clamp_min < 0, "< 0"), "clamp_max": (self.clamp_max > 0, "> 0"),
            "occupied_above": (0 <= self.occupied_above < self.clamp_max, "in [0, clamp_max)"),
            "free_below": (self.clamp_min < self.free_below <= 0, "in (clamp_min, 0]"),
            "no_return_clearance": (self.no_return_clearance >= 0, ">= 0"),
            "hit_guard": (self.hit_guard == int(self.hit_guard) and 0 <= self.hit_guard <= 10,
                          "a whole number of cells in [0, 10]"),
        }
        for key, (ok, rule) in rules.items():
            if not ok:
                raise GridError(f"log-odds mapping: {key} must be {rule}, "
                                f"got {getattr(self, key)!r}")

    @classmethod
    def from_dict(cls, d: dict) -> LogOddsParams:
        """Build from a mapping (e.g. parsed YAML); unknown keys are refused by name."""
        return config_from_dict(cls, d, GridError, "log-odds mapping")


class LogOddsMapper:
    """Accumulates scans into a log-odds grid in the frame (origin, resolution, size) of
    ``frame``; ``frame``'s cells are not used."""

    def __init__(self, frame: OccupancyGrid, params: LogOddsParams | None = None):
        self.params = params or LogOddsParams()
        self.resolution = frame.resolution
        self.origin = frame.origin
        self.logodds = np.zeros(frame.shape, np.float32)
        # Which scan last touched each cell, so a scan changes each cell at most once.
        self._stamp = np.zeros(frame.shape, np.int32)
        self._scans = 0
        p = self.params
        self._increments = np.array([p.hit, p.miss, p.clamp_min, p.clamp_max], np.float32)

    @property
    def scans(self) -> int:
        """Number of scans integrated so far."""
        return self._scans

    def add_scan(self, scan: Scan, sensor_pose: Pose2D) -> None:
        """Add one scan taken from ``sensor_pose`` (the lidar's pose in the map frame)."""
        if not isinstance(sensor_pose, Pose2D):
            sensor_pose = Pose2D.from_array(sensor_pose)
        if not sensor_pose.is_finite():
            raise GridError(f"sensor pose must be finite, got {sensor_pose}")
        from . import _mapping_kernels as k  # numba only when mapping

        res = self.resolution
        sensor = np.array([(sensor_pose.x - self.origin[0]) / res,
                           (sensor_pose.y - self.origin[1]) / res])
        angles = scan.angles() + sensor_pose.theta
        ranges = scan.ranges.astype(np.float64) / res
        clearance = self.params.no_return_clearance
        limits = np.array([scan.range_min / res, scan.range_max / res, clearance / res,
                           self.params.hit_guard])
        # A walk of length L grid units visits at most |dx| + |dy| + 2 <= sqrt(2) L + 2 cells,
        # and a walk clipped to the grid at most its height + width: the bound for a scan whose
        # range_max is absurd (1e300, inf), which no walk reaches
        longest = math.sqrt(2.0) * max(scan.range_max, clearance) / res
        cap = int(math.ceil(min(longest, float(sum(self.logodds.shape))))) + 4
        rows = np.empty(cap, np.int64)
        cols = np.empty(cap, np.int64)
        self._scans += 1
        k.integrate_scan(self.logodds, self._stamp, scan_id=self._scans, sensor=sensor,
                         angles=angles, ranges=ranges, limits=limits,
                         increments=self._increments, rows=rows, cols=cols)

    def probabilities(self) -> np.ndarray:
        """Occupancy probability of every cell (float64)."""
        return 1.0 / (1.0 + np.exp(-self.logodds.astype(np.float64)))

    def to_grid(self) -> OccupancyGrid:
        """The trinary map: occupied, free, or unknown where the evidence is weak or absent."""
        return OccupancyGrid(threshold_logodds(self.logodds, self.params), self.resolution,
                             self.origin)


def threshold_logodds(logodds: np.ndarray, params: LogOddsParams | None = None) -> np.ndarray:
    """Trinary int8 cells from log-odds: occupied above ``occupied_above``, free below
    ``free_below``, unknown otherwise."""
    params = params or LogOddsParams()
    cells = np.full(logodds.shape, UNKNOWN, np.int8)
    cells[logodds > params.occupied_above] = OCCUPIED
    cells[logodds < params.free_below] = FREE
    return cells


def build_map(frame: OccupancyGrid, observations, params: LogOddsParams | None = None
              ) -> OccupancyGrid:
    """Map from an iterable of (scan, sensor pose) pairs in one call."""
    mapper = LogOddsMapper(frame, params)
    for scan, pose in observations:
        mapper.add_scan(scan, pose)
    return mapper.to_grid()
