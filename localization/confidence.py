"""How far a pose can be trusted with the map: a figure a caller can gate on before it lets the
map updater change the map from that pose.

A localiser that is wrong with confidence (a persistent 10 cm or 1 deg offset, a kidnapping)
keeps a tight particle cloud, so its covariance says nothing; and most beams still pair with the
map, so the updater's own lost check (80 % of the beams) says nothing either. Yet a persistent
10 cm offset makes the updater free wall and rack cells (benchmarks/bench_mislocalisation.py).

What does tell is the scan itself. Placed at the right pose, the beams that hit what the map
knows end close to its occupied cells, and moving the pose can only make them fit worse. Placed
at a wrong pose, some nearby pose fits clearly better. So:

- ``fit`` [1]: the mean over the scan's beams of (min(d, cap) / cap)^2, d the distance [m] from
  a beam's end point to the nearest occupied cell of the map; 0 is a perfect fit, 1 no fit.
  Beams that hit something the map does not have sit at the cap wherever the pose is, so a
  changed world raises the fit but does not tilt it towards another pose.
- ``gain`` [1]: how much the best pose of a small grid around the given one (fine: +-0.2 m,
  +-2 deg; coarse: +-1 m, +-12 deg) lowers the fit. It is 0 when the given pose is the best one.
- ``correction``: the offset (dx, dy [m], dtheta [rad], map frame) to that best pose.

``PoseCheck.check`` turns these, and the localiser's covariance when there is one, into a reason
to skip the scan ("" when the pose can be trusted). It imports only ``gridmap``; the scoring is
the localiser's likelihood-field arithmetic with a table of its own, one kernel call per grid of
poses (``_kernels.grid_table_sums``, ``_kernels.grid_interpolated_fit``): an end point's map
column is found once for each x offset and its row once for each y offset, and poses that can
no longer beat the given one are dropped as their beams are added.

A refusal holds for ``retry_interval`` seconds of scan time: the scans that follow within it are
refused with the same reason and nothing is scored. The map updater does not advance its gate
past a refused scan, so without the hold it would ask again at the scan rate (every 0.1 s at
10 Hz), and the search grids would cost the most exactly where localisation is worst. Time is
the scans' own: a scan no later than the refusal (another lidar's scan of the same instant, a
stream without times) is judged afresh, and a scan earlier than the latest one seen (a new
pass over a log, a new session with the same check) ends the hold; ``reset`` ends it too.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, fields, replace

import numpy as np

from gridmap import UNKNOWN, OccupancyGrid, Pose2D, PoseVerdict, Scan
from gridmap.config import (DEFAULT_PROFILE, check_bounds, config_from_dict,
                            config_from_profile, config_from_yaml, config_to_dict)
from gridmap.distance import distance_to_occupied

from .config import LocalizationError
from .sensor import select_beams

# Why a pose was not trusted (returned by PoseCheck.check).
UNSURE_FIT = "pose unsure: a nearby pose fits the scan better"
UNSURE_COVARIANCE = "pose unsure: localiser covariance too wide"
UNSURE_LOST = "pose unsure: refused for a while, held until the scans fit the map as before"


# The range of every number (docs/reliability.md), and of the work one check may do.
POSE_CHECK_BOUNDS = {
    "max_gain": (0.0, 1.0), "min_correction": (0.0, 10.0), "min_correction_deg": (0.0, 180.0),
    "cap": (1e-3, 5.0), "slack_cells": (0, 10), "max_beams": (2, 10_000),
    "fine_step": (1e-4, 1.0), "fine_steps": (0, 50), "fine_step_deg": (1e-3, 45.0),
    "fine_steps_deg": (0, 50), "coarse_step": (1e-3, 5.0), "coarse_steps": (0, 50),
    "coarse_step_deg": (1e-3, 90.0), "coarse_steps_deg": (0, 50),
    "max_position_std": (0.0, 100.0), "max_yaw_std_deg": (0.0, 180.0),
    "retry_interval": (0.0, 3600.0), "polish_step": (1e-4, 0.5), "polish_step_deg": (1e-3, 10.0),
    "polish_steps": (0, 30), "refined_min_correction": (0.0, 10.0),
    "refined_min_correction_deg": (0.0, 180.0), "lost_after": (0.0, 3600.0),
    "lost_release_fits": (1, 1000), "lost_fit_floor": (0.0, 1.0), "lost_fit_window": (1, 10_000),
    "lost_fit_margin": (1.0, 100.0), "lost_refusals": (1, 1000),
}
MAX_POSES = 250_000
# The robot profile: the keys where it differs from the paper's (the class's defaults), each
# with why (docs/configuration.md). The defaults catch offsets from 5-7.5 cm and 0.75 deg on
# the warehouse (bench_mislocalisation), and refuse right poses by the hundred on real
# buildings and partly mapped places; the robot profile leaves smaller errors to the
# updater's own rules (free_with_neighbours, removed_skip_across) and to the correction of
# the poses that fit clearly worse than one nearby, and refuses what neither can absorb: a
# localisation a fifth of a metre or 3 deg off.
ROBOT_PROFILE = {
    "max_gain": (0.02, "a nearby pose must fit clearly better ..."),
    "min_correction": (0.2, "... and lie a fifth of a metre away ..."),
    "min_correction_deg": (3.0, "... or 3 deg: on a real building's own map (Freiburg 079) "
                           "the defaults refuse a third of the scans, whose poses made it"),
    "max_position_std": (0.3, "the localiser's spread as its tracking monitor bounds it: a "
                         "filter updated once a metre spreads past 0.15 m and is still right"),
    "max_yaw_std_deg": (10.0, "... and its heading's"),
    "refine_given": (False, "the project's own localiser's poses, a few centimetres off between "
                     "its filter updates, are placed where they fit (the warehouse's W4: "
                     "change precision 0.98, not 0.83); poses a recording or a node's tf "
                     "gives are taken as given (placed so on a real building's 5 cm map, they "
                     "drew 0.48 of Freiburg 079's added objects, not 0.73, and freed 18 wall "
                     "cells)"),
    "refined_min_correction": (0.1, "... and refused from 0.1 m or 1.5 deg off (0.2 m and 3 "
                               "deg let a localiser lost by decimetres through, whose scans, "
                               "placed where they fit best, wore a rack's face: 2 cells in "
                               "2 of 192 generated cases) ..."),
    "refined_min_correction_deg": (1.5, "... : a recording's poses keep the looser bounds "
                                   "(0.1 m refused a third more of Acapulco's partly mapped scans)"),
    "known_ends_only": (True, "in a partly mapped place the beams into the unmapped part "
                        "tilted the fit: Acapulco's update refused 380 of 474 scans"),
    "lost_after": (1.0, "a second of refusals is a localiser lost, not a pose a few centimetres "
                   "off: one that slid 1.5 m along a generated warehouse's aisle (lifelong "
                   "benchmark, gen101 seed 2, session 81) was let through again at that error, "
                   "out of the coarse grid's reach, and its scans made 979 wrong changes"),
}


@dataclass(frozen=True)
class PoseCheckConfig:
    """Thresholds of the pose check. On the warehouse's W2 route at the true poses plus an
    offset (benchmarks/bench_mislocalisation.py), the defaults refuse few scans without an
    offset or at 0.5 deg, many at 5 cm, and nearly all from 7.5 cm or 1 deg on (the fit's
    verdicts; the hold of ``retry_interval`` adds the scans that follow a refusal)."""

    max_gain: float = 0.01              # [1] a better pose this much better: the pose is off ...
    min_correction: float = 0.06        # [m] ... when it lies at least this far away
    min_correction_deg: float = 0.75    # [deg] ... or turned at least this much
    cap: float = 0.2                    # [m] beam residuals are capped here
    slack_cells: int = 0                # distances within this many cells of a surface are 0
    max_beams: int = 180                # beams scored, evenly spread over the scan
    fine_step: float = 0.025            # [m] steps of the fine search grid ...
    fine_steps: int = 8                 # ... this many each way (+-0.2 m)
    fine_step_deg: float = 0.5          # [deg] heading steps of the fine grid ...
    fine_steps_deg: int = 4             # ... this many each way (+-2 deg)
    coarse_step: float = 0.25           # [m] the coarse grid, for gross errors: +-1 m ...
    coarse_steps: int = 4
    coarse_step_deg: float = 3.0        # [deg] ... +-12 deg
    coarse_steps_deg: int = 4
    max_position_std: float = 0.15      # [m] sqrt of the largest eigenvalue of the x-y covariance
    max_yaw_std_deg: float = 5.0        # [deg]
    retry_interval: float = 0.3         # [s] of scan time a refusal holds without a new fit; 0: off
    # Score only the beams whose end point, at the given pose, lies in a known cell of the map
    # or within ``cap`` of an occupied one. A beam that ends where the map knows nothing (a
    # part of the place the map has not seen yet) is drawn to the nearest mapped surface as
    # the pose moves, and tilts the fit towards a pose that is not better.
    known_ends_only: bool = False
    # ``verdict`` hands the updater, for a trusted pose, the best fit near it (``refine``),
    # polished on a grid of +-polish_steps steps of these sizes each way
    refine: bool = True
    # ... also for poses given from outside (a recording's, a node's tf or amcl_pose); False:
    # only for the poses of the project's own localiser (``for_poses``)
    refine_given: bool = True
    # ... and a pose it refines is refused from this correction on (the nearer of this and
    # min_correction): a pose a decimetre off is not a few centimetres of odometry since the
    # last filter update, and placed where the scan fits best nearby it wore a face
    refined_min_correction: float = 0.06        # [m]
    refined_min_correction_deg: float = 0.75    # [deg]
    polish_step: float = 0.005          # [m]
    polish_step_deg: float = 0.1        # [deg]
    polish_steps: int = 5
    # A run of refusals this long [s of scan time] (0: off), and of ``lost_refusals`` verdicts
    # at least (a log that keeps a scan a metre has two a second apart), says the localiser
    # has lost the robot, not that a pose is a few centimetres off: the check then refuses
    # every scan until ``lost_release_fits`` fits in a row are at most ``lost_fit_margin``
    # times the accepted
    # scans' mean fit over the last ``lost_fit_window`` of them (or ``lost_fit_floor``, when
    # that is higher), with no better pose nearby. A localiser that has slid beyond the coarse
    # grid's reach finds none nearer the truth, and its fit is then let through; its fit stays
    # poorer than the scans' own before the slide. The margin: at the right pose, half the
    # fits lie above their mean.
    lost_after: float = 0.0
    lost_release_fits: int = 3
    lost_fit_floor: float = 0.02
    lost_fit_window: int = 50
    lost_fit_margin: float = 1.5
    lost_refusals: int = 3
    # ... also for poses given from outside (a recording's, a node's tf); False: only for the
    # project's own localiser's (``for_poses``). Where a partly mapped building's scans reach
    # what the map does not know yet, a run of refusals is the map's not knowing, not a lost
    # pose: the hold kept Acapulco's map from growing (0.976 of its new cells known and right
    # without it, 0.930 with it)
    lost_given: bool = False

    def __post_init__(self):
        for f in fields(self):
            if f.type == "bool" and not isinstance(getattr(self, f.name), bool):
                raise LocalizationError(f"pose check key '{f.name}' must be true or false, "
                                        f"got {getattr(self, f.name)!r}")
        try:
            check_bounds(self, POSE_CHECK_BOUNDS, LocalizationError)
        except LocalizationError as e:
            raise LocalizationError(str(e).replace("config key", "pose check key")) from None
        for grid in ("fine", "coarse", "polish"):
            turn = getattr(self, f"{grid}_step_deg") * getattr(self, f"{grid}_steps" if grid ==
                                                               "polish" else f"{grid}_steps_deg")
            if turn > 180.0:
                raise LocalizationError(f"pose check keys '{grid}_step_deg' x the {grid} grid's "
                                        f"steps make a search of +-{turn:g} deg; at most 180")
        if self._poses() > MAX_POSES:
            raise LocalizationError(f"pose check search grids hold {self._poses()} poses, more "
                                    f"than {MAX_POSES}: fewer or larger steps")

    def _poses(self) -> int:
        """Poses scored by one check (both grids) and by one polish."""
        return ((2 * self.fine_steps + 1) ** 2 * (2 * self.fine_steps_deg + 1)
                + (2 * self.coarse_steps + 1) ** 2 * (2 * self.coarse_steps_deg + 1)
                + (2 * self.polish_steps + 1) ** 3)

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def profile(cls, name: str = DEFAULT_PROFILE, overrides: dict | None = None,
                source: str | None = None) -> PoseCheckConfig:
        """The configuration of profile ``name`` (``paper``: the class's defaults; ``robot``:
        those with ``ROBOT_PROFILE``'s keys), with ``overrides`` laid over it key by key."""
        return config_from_profile(cls, ROBOT_PROFILE, name, overrides, LocalizationError,
                                   source)

    def for_poses(self, own_localizer: bool) -> PoseCheckConfig:
        """This configuration for scans placed by the project's own localiser
        (``own_localizer``) or at poses given from outside: for the latter ``refine`` off
        unless ``refine_given``, and ``lost_after`` off unless ``lost_given``; where it
        refines, the check refuses from ``refined_min_correction`` (``_deg``) on when that is
        the nearer bound."""
        c = self if own_localizer or self.lost_given else replace(self, lost_after=0.0)
        if not (own_localizer or c.refine_given):
            return replace(c, refine=False)
        if not c.refine:
            return c
        return replace(c, min_correction=min(c.min_correction, c.refined_min_correction),
                       min_correction_deg=min(c.min_correction_deg,
                                              c.refined_min_correction_deg))

    @classmethod
    def from_dict(cls, values: dict, source: str = "pose check config") -> PoseCheckConfig:
        """Build from a mapping; an unknown key is refused with the nearest valid name."""
        return config_from_dict(cls, values, LocalizationError, source)

    @classmethod
    def from_yaml(cls, path) -> PoseCheckConfig:
        """Load from a YAML file holding the keys at the top level (or under ``pose_check:``)."""
        return config_from_yaml(cls, path, LocalizationError, "pose_check")


class LostLatch:
    """``PoseCheckConfig.lost_after``: after a run of refusals that long, every scan is
    refused until the scans fit the map again as well as the accepted ones did before."""

    def __init__(self, config: PoseCheckConfig):
        self.config = config
        self.holding = False
        self._refusing_since: float | None = None   # [s] first refusal of the current run
        self._refusals = 0                          # fits refused in the current run
        self._fits = collections.deque(maxlen=config.lost_fit_window)  # last accepted fits
        self._good = 0                              # fits in a row good enough to release

    def judge(self, t: float, reason: str, f: PoseFit | None, better: bool) -> str:
        """The check's ``reason`` for the scan at time ``t`` with fit ``f`` (``better``: a
        better pose lies nearby), or ``UNSURE_LOST`` while the latch holds."""
        c = self.config
        if not c.lost_after:
            return reason
        if reason:
            if self._refusing_since is None or not math.isfinite(t):
                self._refusing_since, self._refusals = t, 0
            self._refusals += 1
            self.holding = self.holding or (t - self._refusing_since >= c.lost_after - 1e-9
                                            and self._refusals >= c.lost_refusals)
            self._good = 0
            return reason
        self._refusing_since = None
        if not self.holding:
            if f is not None:
                self._fits.append(f.fit)
            return ""
        if f is None:
            return UNSURE_LOST
        bar = max(c.lost_fit_floor,
                  c.lost_fit_margin * float(np.mean(self._fits)) if self._fits else 0.0)
        self._good = self._good + 1 if f.fit <= bar and not better else 0
        if self._good < c.lost_release_fits:
            return UNSURE_LOST
        self.holding, self._good = False, 0
        return ""


@dataclass(frozen=True)
class PoseFit:
    fit: float              # [1] at the given pose, 0 perfect .. 1 nothing fits
    gain: float             # [1] how much the best pose nearby lowers it
    correction: Pose2D      # offset to that best pose (dx, dy [m], dtheta [rad], map frame)
    beams: int              # beams scored


def search_grid(step: float, steps: int, step_rad: float, steps_rad: int) -> np.ndarray:
    """Offsets (N, 3) of a regular grid, (2 steps + 1)^2 positions x (2 steps_rad + 1) headings;
    row 0 is the zero offset."""
    return SearchGrid(step, steps, step_rad, steps_rad).offsets


class SearchGrid:
    """A regular grid of pose offsets, as its axes (what the kernels take: ``xy`` for x and
    for y, ``turns`` for the heading) and as rows (``offsets``, the zero offset first). The
    kernels write a score per pose in axis order, x slowest and heading fastest; ``order``
    takes those scores to the rows' order."""

    def __init__(self, step: float, steps: int, step_rad: float, steps_rad: int):
        self.xy = step * np.arange(-steps, steps + 1)
        self.turns = step_rad * np.arange(-steps_rad, steps_rad + 1)
        grid = np.array(np.meshgrid(self.xy, self.xy, self.turns, indexing="ij"))
        grid = grid.reshape(3, -1).T
        zero = np.flatnonzero(~grid.any(axis=1))
        self.order = np.concatenate([zero, np.delete(np.arange(grid.shape[0]), zero)])
        self.offsets = np.ascontiguousarray(grid[self.order])

    @property
    def size(self) -> int:
        return self.order.shape[0]


class PoseCheck:
    """The pose check on one map. ``fit`` scores a pose; ``check`` says whether to trust it."""

    def __init__(self, grid: OccupancyGrid, config: PoseCheckConfig | None = None):
        if not isinstance(grid, OccupancyGrid):
            raise LocalizationError(f"the map must be an OccupancyGrid, got {type(grid).__name__}")
        self.config = PoseCheckConfig() if config is None else config
        if not isinstance(self.config, PoseCheckConfig):
            raise LocalizationError(f"config must be a PoseCheckConfig, got "
                                    f"{type(config).__name__}")
        c = self.config
        # Slack: a beam that ends on a surface lands in the occupied cell or in the free one
        # before it, as noise has it. Scored by centre distance, that half-cell ambiguity alone
        # makes a pose 2-3 cm into the surface "fit better" by more than the default
        # ``max_gain`` on a scan of long walls, which refuses right poses where a narrow field
        # of view leaves one direction unconstrained (a 180 deg lidar along a corridor). One
        # cell of slack makes the fit flat within a cell of a surface, at the price of missing
        # errors of about 0.1 m and 1 deg (bench_mislocalisation: with slack such errors free
        # G-occupied cells, without it none; figures in benchmarks/RESULTS.md).
        slack = np.float32(grid.resolution * c.slack_cells)
        dist = np.maximum(distance_to_occupied(grid, c.cap + slack) - slack, 0.0)
        residual = dist / np.float32(c.cap)
        # The kernel sums table entries: the negative squared residual, so higher is better.
        self._table = np.ascontiguousarray(-(residual * residual), dtype=np.float32)
        self._residual = np.ascontiguousarray(residual, dtype=np.float32)
        # where a beam may end to be scored with ``known_ends_only``
        self._scored = (grid.data != UNKNOWN) | (residual < 1.0)
        self._frame = np.array([grid.origin[0], grid.origin[1], grid.resolution])
        self._grids = (
            SearchGrid(c.fine_step, c.fine_steps, math.radians(c.fine_step_deg),
                       c.fine_steps_deg),
            SearchGrid(c.coarse_step, c.coarse_steps, math.radians(c.coarse_step_deg),
                       c.coarse_steps_deg))
        fine, coarse = self._grids
        # both grids' scores in one array; the coarse grid's zero offset is the fine one's
        self._offsets = np.vstack([fine.offsets, coarse.offsets[1:]])
        self._order = np.concatenate([fine.order, fine.size + coarse.order[1:]])
        self._given = SearchGrid(0.0, 0, 0.0, 0)
        self._polish = SearchGrid(c.polish_step, c.polish_steps,
                                  math.radians(c.polish_step_deg), c.polish_steps)
        self._refused_at: float | None = None   # [s] scan time of the refusal that holds
        self._refused_reason = ""
        self._latest: float | None = None       # [s] latest scan time seen
        self._lost = LostLatch(c)

    def reset(self) -> None:
        """Forget the refusal that holds and the lost latch (e.g. before a new stream of
        scans)."""
        self._refused_at, self._refused_reason, self._latest = None, "", None
        self._lost = LostLatch(self.config)

    @property
    def lost(self) -> bool:
        """The check holds every scan as the localiser's being lost (``lost_after``)."""
        return self._lost.holding

    def fit(self, scan: Scan, robot_pose: Pose2D, sensor_mount: Pose2D) -> PoseFit | None:
        """The fit of ``scan`` taken from ``robot_pose`` (map frame) by a lidar at
        ``sensor_mount`` (robot frame), and the best pose of the search grids around it; None
        when the scan has no valid beam."""
        return self._fit(self._beams(scan, robot_pose, sensor_mount), robot_pose, sensor_mount)

    def _beams(self, scan: Scan, robot_pose: Pose2D, sensor_mount: Pose2D):
        """The scan's beams the check scores: ``max_beams`` of them, evenly spread, and with
        ``known_ends_only`` those that end in known space at ``robot_pose``."""
        beams = select_beams(scan, self.config.max_beams)
        if not self.config.known_ends_only or beams.count == 0:
            return beams
        sensor = robot_pose.compose(sensor_mount)
        c, s = math.cos(sensor.theta), math.sin(sensor.theta)
        x = sensor.x + c * beams.points[:, 0] - s * beams.points[:, 1]
        y = sensor.y + s * beams.points[:, 0] + c * beams.points[:, 1]
        ox, oy, res = self._frame
        col = np.floor((x - ox) / res).astype(np.int64)
        row = np.floor((y - oy) / res).astype(np.int64)
        h, w = self._scored.shape
        inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
        keep = np.zeros(beams.count, bool)
        keep[inside] = self._scored[row[inside], col[inside]]
        return replace(beams, points=np.ascontiguousarray(beams.points[keep]))

    def _fit(self, beams, robot_pose: Pose2D, sensor_mount: Pose2D) -> PoseFit | None:
        """``fit`` with the scan's beams already selected."""
        if beams.count == 0:
            return None
        base, mount = robot_pose.as_array(), sensor_mount.as_array()
        # The given pose's sum first: poses that cannot beat it are dropped early.
        given = self._table_sums(self._given, base, mount, beams, -np.inf, np.empty(1))
        sums = np.empty(sum(g.size for g in self._grids))
        start = 0
        for g in self._grids:
            self._table_sums(g, base, mount, beams, given[0], sums[start:start + g.size])
            start += g.size
        score = sums[self._order]
        score /= -beams.count
        best = int(np.argmin(score))
        dx, dy, dth = self._offsets[best]
        return PoseFit(float(score[0]), float(score[0] - score[best]),
                       Pose2D(float(dx), float(dy), float(dth)), beams.count)

    def _table_sums(self, g: SearchGrid, base: np.ndarray, mount: np.ndarray, beams,
                    floor: float, out: np.ndarray) -> np.ndarray:
        """The table's sums over the beams at the poses ``base`` + the offsets of ``g``, in
        axis order, those below ``floor`` possibly -inf (``_kernels.grid_table_sums``; the
        table's entries and the off-grid value are <= 0, as it asks)."""
        from . import _kernels

        _kernels.grid_table_sums(base=base, mount=mount, beams=beams.points, table=self._table,
                                 frame=self._frame, off_value=-1.0, xs=g.xy, ys=g.xy,
                                 turns=g.turns, floor=floor, out=out)
        return out

    def better_nearby(self, f: PoseFit) -> bool:
        """True when the fit found a pose on the search grids that fits the scan clearly better
        than the given one, and far enough away to say the given one is off: what ``check``
        refuses for."""
        return f.gain > self.config.max_gain and self._far(f.correction)

    def refine(self, scan: Scan, robot_pose: Pose2D, sensor_mount: Pose2D,
               cov: np.ndarray | None = None) -> str | Pose2D:
        """The check, and for a trusted pose the pose that fits the scan best near it: a
        reason to skip the scan (as ``check``), or the robot pose to use instead of
        ``robot_pose``. That pose is the search grids' best one when it lies within
        ``min_correction`` / ``min_correction_deg`` (a farther best pose that the check let
        pass gains too little to move to), polished on a grid of ``polish_step`` and
        ``polish_step_deg`` around it. A localiser's estimate between its updates carries
        the odometry's drift since the last one, a few centimetres; faces the updater draws
        from such poses land a cell or two off and are then, being within the pairing
        distance of the truth, never corrected (docs/choices.md)."""
        c = self.config
        beams = self._beams(scan, robot_pose, sensor_mount)   # once for the check and the polish
        reason, f = self._check(scan, robot_pose, sensor_mount, cov, beams)
        if reason:
            return reason
        if f is None:
            return robot_pose
        base = robot_pose.as_array()
        if not self._far(f.correction):
            base = base + f.correction.as_array()
        x, y, th = base + self._polish.offsets[self._polish_best(base, sensor_mount, beams)]
        return Pose2D(float(x), float(y), float(th))

    def _polish_best(self, base: np.ndarray, sensor_mount: Pose2D, beams) -> int:
        """The row of the polish grid's offsets whose pose (``base`` + the offset) fits the
        beams best; the first such row on a tie."""
        from . import _kernels

        g, mount, score = self._polish, sensor_mount.as_array(), np.empty(self._polish.size)
        if min(self._residual.shape) < 2:
            # (the grid kernel's flat indexing needs two cells each way to interpolate between)
            _kernels.interpolated_fit(base + g.offsets, mount, beams.points, self._residual,
                                      self._frame, score)
            return int(np.argmin(score))
        _kernels.grid_interpolated_fit(base=base, mount=mount, beams=beams.points,
                                       residual=self._residual, frame=self._frame, xs=g.xy,
                                       ys=g.xy, turns=g.turns, out=score)
        return int(np.argmin(score[g.order]))

    def verdict(self, scan: Scan, robot_pose: Pose2D, sensor_mount: Pose2D,
                cov: np.ndarray | None = None) -> PoseVerdict:
        """What ``updater.MapUpdater.process`` asks its ``pose_check``: refused with the
        reason, accepted, or, with ``refine`` on, refined to the sensor pose to use (the
        refined robot pose composed with ``sensor_mount``)."""
        if not self.config.refine:
            reason = self.check(scan, robot_pose, sensor_mount, cov)
            return PoseVerdict.refused(reason) if reason else PoseVerdict.accepted()
        better = self.refine(scan, robot_pose, sensor_mount, cov)
        if isinstance(better, str):
            return PoseVerdict.refused(better)
        return PoseVerdict.refined(better.compose(sensor_mount))

    def check(self, scan: Scan, robot_pose: Pose2D, sensor_mount: Pose2D,
              cov: np.ndarray | None = None) -> str:
        """"" when the pose can be trusted with the map, else why not (UNSURE_*). Within
        ``retry_interval`` of scan time after a refusal, the same refusal without a new fit
        (see the module docstring)."""
        return self._check(scan, robot_pose, sensor_mount, cov)[0]

    def _check(self, scan, robot_pose, sensor_mount, cov, beams=None
               ) -> tuple[str, PoseFit | None]:
        """(reason, the fit when one was made); ``beams``: the scan's selected beams, if
        the caller has them."""
        t = float(scan.time)
        if not math.isfinite(t):           # no usable time: no hold either way
            self.reset()
            return self._judge(scan, robot_pose, sensor_mount, cov, beams)
        if self._latest is not None and t < self._latest:
            self.reset()                   # time went back: a new stream
        self._latest = t
        # (a microsecond of tolerance: 10 Hz times such as 1.3 - 1.0 are not exactly 0.3)
        held = self._refused_at is not None and \
            0.0 < t - self._refused_at < self.config.retry_interval - 1e-6
        if held:
            return self._refused_reason, None
        reason, f = self._judge(scan, robot_pose, sensor_mount, cov, beams)
        reason = self._lost.judge(t, reason, f, f is not None and self.better_nearby(f))
        self._refused_at, self._refused_reason = (t, reason) if reason else (None, "")
        return reason, f

    def _judge(self, scan: Scan, robot_pose: Pose2D, sensor_mount: Pose2D,
               cov: np.ndarray | None, beams=None) -> tuple[str, PoseFit | None]:
        c = self.config
        if cov is not None:
            cov = np.asarray(cov, np.float64)
            if not np.all(np.isfinite(cov)) or \
                    np.linalg.eigvalsh(cov[:2, :2]).max() > c.max_position_std ** 2 or \
                    cov[2, 2] > math.radians(c.max_yaw_std_deg) ** 2:
                return UNSURE_COVARIANCE, None
        if beams is None:
            beams = self._beams(scan, robot_pose, sensor_mount)
        f = self._fit(beams, robot_pose, sensor_mount)
        if f is None:
            return "", None
        return (UNSURE_FIT if self.better_nearby(f) else ""), f

    def _far(self, correction: Pose2D) -> bool:
        c = self.config
        return math.hypot(correction.x, correction.y) >= c.min_correction - 1e-9 or \
            abs(correction.theta) >= math.radians(c.min_correction_deg) - 1e-9
