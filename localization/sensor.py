"""The likelihood-field sensor model (Probabilistic Robotics table 6.3), scored as nav2 AMCL does.

Per beam, pz = z_hit * exp(-d^2 / (2 sigma_hit^2)) + z_rand / range_max, where d is the distance
from the beam's end point to the nearest occupied cell, capped at laser_likelihood_max_dist.
The beams of a particle combine as in one of nav2's two laser models:
- ``likelihood_field``: AMCL's ad-hoc ``1 + sum(pz^3)``. Robust, but so flat that the particle
  cloud stays some 10 cm wide and so does the error (localization/README.md);
- ``likelihood_field_prob``: the product of pz, each raised to importance_factor (Probabilistic
  Robotics 6.3.4: beams of one scan are not independent, so each counts for less than one).
Scores are returned as log-likelihoods, since a product of 60 beams underflows easily.

What AMCL does, and so this module does, with beams and cells:
- a beam is used when its range is finite and range_min < r < range_max; max-range and
  short readings carry no information about where the obstacle is and are skipped;
- only occupied cells are obstacles: an end point in an unknown cell scores by its distance to
  the nearest occupied cell like one in a free cell;
- an end point off the map scores as if at the maximum distance (no obstacle nearby).
The per-beam term is precomputed per cell (one table lookup per beam, no exp or log), for the
scan's range_max.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from gridmap import OccupancyGrid, Pose2D, Scan
from gridmap.distance import distance_to_occupied

from .config import MODELS, LocalizationError


def _kernels():
    from . import _kernels

    return _kernels


@dataclass
class Beams:
    """The beams of one scan that the sensor model uses: end points in the sensor frame [m]."""

    points: np.ndarray       # (B, 2) float64
    range_max: float         # [m] the range limit in force; z_rand's density is 1 / range_max

    @property
    def count(self) -> int:
        return int(self.points.shape[0])


def select_beams(scan: Scan, max_beams: int, min_range: float = -1.0,
                 max_range: float = -1.0) -> Beams:
    """AMCL's beam choice: ``max_beams`` evenly spaced over the scan, then the invalid ones
    dropped. ``min_range`` / ``max_range`` > 0 tighten the scan's own limits (nav2's
    laser_min_range / laser_max_range)."""
    range_min = max(scan.range_min, min_range) if min_range > 0 else scan.range_min
    range_max = min(scan.range_max, max_range) if max_range > 0 else scan.range_max
    idx = _spread(scan.beams, max_beams)
    r = scan.ranges[idx].astype(np.float64)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r > range_min) & (r < range_max)
    # scan.angles() at the chosen beams only: the same product and sum per beam
    a = (scan.angle_min + scan.angle_increment * idx.astype(np.float64))[ok]
    points = np.column_stack((r[ok] * np.cos(a), r[ok] * np.sin(a)))
    return Beams(np.ascontiguousarray(points), float(range_max))


@lru_cache(maxsize=32)
def _spread(n: int, max_beams: int) -> np.ndarray:
    """``max_beams`` indices evenly spread over ``n`` beams; a scan's size and the beam count
    rarely change, so the choice is made once for each pair."""
    idx = np.unique(np.round(np.linspace(0, n - 1, min(max_beams, n))).astype(np.int64))
    idx.flags.writeable = False
    return idx


@dataclass
class LikelihoodField:
    """The map as the sensor model sees it: distances to obstacles and a per-cell table."""

    grid: OccupancyGrid
    max_dist: float
    z_hit: float
    z_rand: float
    sigma_hit: float
    model: str = "likelihood_field"
    importance_factor: float = 1.0
    distance: np.ndarray = field(init=False, repr=False)     # (H, W) float32 [m]
    frame: np.ndarray = field(init=False, repr=False)        # (origin x, origin y, resolution)
    _cache: tuple | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        if self.model not in MODELS:
            raise LocalizationError(f"unknown laser model {self.model!r}; one of {MODELS}")
        self.distance = distance_to_occupied(self.grid, self.max_dist)
        self.frame = np.array([self.grid.origin[0], self.grid.origin[1], self.grid.resolution])

    def pz(self, d, range_max: float):
        """The beam likelihood at obstacle distance ``d`` [m] (not normalised, as in AMCL)."""
        d = np.asarray(d, dtype=np.float64)
        return self.z_hit * np.exp(-(d * d) / (2 * self.sigma_hit ** 2)) + self.z_rand / range_max

    def table(self, range_max: float) -> tuple[np.ndarray, float, float]:
        """(per-cell term as float32, term off the map, base) for this range limit: pz^3 and 1
        for AMCL's sum, importance_factor * log(pz) and 0 for the product. Cached because
        range_max only changes when the sensor does."""
        if self._cache is None or self._cache[0] != range_max:
            if self.model == "likelihood_field":
                def term(d): return self.pz(d, range_max) ** 3
                base = 1.0
            else:
                def term(d): return self.importance_factor * np.log(self.pz(d, range_max))
                base = 0.0
            table = np.ascontiguousarray(term(self.distance), dtype=np.float32)
            self._cache = (range_max, table, float(term(self.max_dist)), base)
        return self._cache[1:]


def likelihood_field(lf: LikelihoodField, poses: np.ndarray, sensor_mount: Pose2D,
                     beams: Beams) -> np.ndarray:
    """The log-likelihood (N,) of the beams from each particle pose (N, 3): ``log(1 +
    sum(pz^3))`` for AMCL's likelihood_field, ``importance_factor * sum(log pz)`` for
    likelihood_field_prob."""
    table, off_value, base = lf.table(beams.range_max)
    out = np.empty(poses.shape[0], np.float64)
    _kernels().likelihood_field(poses, sensor_mount.as_array(), beams.points, table=table,
                                frame=lf.frame, off_value=off_value, base=base, out=out)
    return np.log(out) if lf.model == "likelihood_field" else out
