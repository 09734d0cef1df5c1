"""Map-updating methods behind one small interface, so that the paper's updater can be compared
with what a robot would do without it.

A method is what the robot pipeline (``onboard.pipeline.RobotPipeline``) hands each placed
scan to. It has

- ``process(scan, sensor_pose, odometry=None, pose_check=None) -> updater.ScanReport``: one
  scan at the lidar's pose in the map frame;
- ``updated_map() -> OccupancyGrid``: the map as it stands, M_i at the session's end;
- ``state_bytes() -> int``: the memory its state holds;
- ``n_changed``: cells that differ from the reference map M_{i-1}.

``updater.MapUpdater`` has exactly this interface: the method ``paper`` is that class, as it
is. The baselines:

========  ===================================================================================
name      what it does
========  ===================================================================================
paper     the map updater of docs/algorithm.md (the default)
none      keeps M_{i-1}: what a robot without map updating does
remap     a fresh log-odds map from the session's own scans and the localiser's poses
          (continuous re-mapping, which the paper sets out to avoid): what the session did not
          see is unknown again
fuse      log-odds mapping continued on M_{i-1} as the prior (plain lifelong occupancy
          mapping): its occupied cells start at the clamp's top, its free cells at its bottom,
          so an old cell turns free after 11 misses and a free one occupied after 4 hits
hybrid    the paper's detector decides where, occupancy evidence decides what: ``fuse``'s
          log-odds map, fed the scans the paper's updater processed (past its gate, pose
          check and lost check, at the pose it used), sets the cells within
          ``HYBRID_RADIUS`` of the hits of the beams the paper's classifier found changed
          and of the cells the paper's map changed; everywhere else the map is the paper's
========  ===================================================================================

Every method sees the same scans: the baselines apply the updater's gate (``UpdaterConfig``'s
gating rules) and the pose check exactly as the updater does (asked only past the gate; a
refined pose is used, a refused scan changes nothing and does not advance the gate), so the
runner's observable cells, and so its targets, are those of the same processed scans. What
differs is only what a method does with a scan. The baselines have no lost check: log-odds
mapping has none (the hybrid has the paper's, since the paper's updater runs inside it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from gridmap import (FREE, OCCUPIED, UNKNOWN, MapUpdatingError, OccupancyGrid, Pose2D, PoseVerdict,
                     Scan)
from gridmap.distance import distance_to_occupied
from gridmap.mapping import LogOddsMapper, LogOddsParams
from gridmap.masks import near
from gridmap.suggest import did_you_mean
from updater import BeamVerdict, MapUpdater, ScanReport, ScanStatus, UpdaterConfig
from updater.gating import SKIPPED_OFF_MAP, Gate

# The methods, the paper's first (the default).
METHODS = ("paper", "none", "remap", "fuse", "hybrid")
# The methods that update a robot's map (``mapupdate update --method``, the ROS node's
# ``~method``): ``none`` would write the map unchanged and ``remap`` forget what a recording
# did not see, which only the study's comparisons want.
ROBOT_METHODS = ("paper", "fuse", "hybrid")

# [m] how far from the paper's detected changes the hybrid lets occupancy evidence decide: the
# pairing distance D(r) at its shortest, within which the paper reads a face as unchanged
HYBRID_RADIUS = 0.15


class MethodError(MapUpdatingError, ValueError):
    """An unknown method name, or a method that cannot be built on the map given."""


def check_method(name, source: str = "method", choices=METHODS) -> str:
    """``name`` if it names one of ``choices``, else a ``MethodError`` naming the nearest."""
    if name not in choices:
        raise MethodError(f"{source}: unknown method {name!r}{did_you_mean(name, choices)} "
                          f"(methods: {', '.join(choices)})")
    return name


def make_method(name: str, reference: OccupancyGrid, updater_config=None, faces=None):
    """The method ``name`` on the reference map M_{i-1}. ``updater_config``: an
    ``updater.UpdaterConfig`` (None: the robot profile's); the baselines use its gating
    rules. ``faces``: what the last session's updater carried over (``carried_faces``), for
    the paper's updater and the hybrid's."""
    check_method(name)
    config = UpdaterConfig.profile() if updater_config is None else updater_config
    if name == "paper":
        return MapUpdater(reference, config, faces=faces)
    if name == "none":
        return KeepMap(reference, config)
    if name == "hybrid":
        return HybridMethod(reference, config, faces=faces)
    return LogOddsMethod(reference, config, prior=(name == "fuse"))


def next_session(name: str, last, reference: OccupancyGrid, updater_config=None):
    """The method ``name`` on ``reference`` as the session after ``last`` (a method, or None):
    buffers and gate afresh, with what ``last`` carries from session to session
    (``carried_faces``: the faces rule's counts, halved) when it has any and ``reference`` is
    in its map's frame. Without it, as ``make_method``."""
    carry = getattr(last, "carried_faces", None)
    faces = carry() if carry is not None and last.reference_map.same_frame(reference) else None
    return make_method(name, reference, updater_config, faces=faces)


def face_cells(method) -> int:
    """Cells the faces rule holds counts for in ``method`` (0 for a method without it)."""
    cells = getattr(method, "face_cells", None)
    return 0 if cells is None else cells()


class MapOutput:
    """The interface's map side, from a method's reference map (``_ref``, ``_res``,
    ``_origin``) and the map as it stands (``current()``): what the baselines and the hybrid
    share."""

    _ref: np.ndarray
    _res: float
    _origin: tuple

    def current(self) -> np.ndarray:
        raise NotImplementedError

    def updated_map(self) -> OccupancyGrid:
        return OccupancyGrid(self.current().copy(), self._res, self._origin)

    @property
    def reference_map(self) -> OccupancyGrid:
        return OccupancyGrid(self._ref.copy(), self._res, self._origin)

    @property
    def n_changed(self) -> int:
        return int(np.count_nonzero(self.current() != self._ref))

    def changed_cells(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the cells that differ from the reference map."""
        return np.nonzero(self.current() != self._ref)

    def change_counts(self) -> np.ndarray:
        """No flag buffers here: 1 where the map differs from the reference, else 0."""
        return (self.current() != self._ref).astype(np.uint8)


class GatedMethod(MapOutput):
    """What the baselines share: the updater's gate and pose check in front of ``integrate``,
    and the interface's bookkeeping. Subclasses define ``integrate`` and ``current``."""

    def __init__(self, reference: OccupancyGrid, config):
        if not isinstance(reference, OccupancyGrid):
            raise MethodError(f"the reference map must be a gridmap.OccupancyGrid, got "
                              f"{type(reference).__name__}")
        self.config = config
        self._ref = reference.data.copy()
        self._res, self._origin = reference.resolution, reference.origin
        self._gate = Gate(config)
        self.stats = {"scans": 0, "processed": 0, "gated": 0, "lost": 0, "skipped": 0}

    # --- the interface --------------------------------------------------------------------------
    def process(self, scan: Scan, sensor_pose: Pose2D, odometry: Pose2D | None = None,
                pose_check: Callable[[], PoseVerdict] | None = None):
        """Gate, check the pose, then integrate the scan; the report as the updater's."""
        self.stats["scans"] += 1
        t = float(scan.time)
        gate_pose = sensor_pose if odometry is None else odometry
        if self.config.gating:
            reason = self._gate.check(t, gate_pose, odometry is not None,
                                      math.degrees(scan.fov()))
            if reason:
                self.stats["gated"] += 1
                return ScanReport(t, ScanStatus.GATED, reason, sensor_pose=sensor_pose)
        if not self._on_map(sensor_pose):
            self.stats["skipped"] += 1
            return ScanReport(t, ScanStatus.OFF_MAP, SKIPPED_OFF_MAP, sensor_pose=sensor_pose)
        verdict = PoseVerdict.accepted() if pose_check is None else pose_check()
        if verdict.is_refused:
            self.stats["skipped"] += 1
            return ScanReport(t, ScanStatus.REFUSED, verdict.reason)
        pose = verdict.sensor_pose if verdict.sensor_pose is not None else sensor_pose
        self.integrate(scan, pose)
        self.stats["processed"] += 1
        if self.config.gating:
            self._gate.mark_processed(t, gate_pose)
        valid = int(np.count_nonzero(np.isfinite(scan.ranges)))
        return ScanReport(t, ScanStatus.PROCESSED, valid_beams=valid, sensor_pose=pose)

    def state_bytes(self) -> int:
        return int(self._ref.nbytes)

    def _on_map(self, pose: Pose2D) -> bool:
        col = (pose.x - self._origin[0]) / self._res
        row = (pose.y - self._origin[1]) / self._res
        return 0 <= col < self._ref.shape[1] and 0 <= row < self._ref.shape[0]

    # --- what a baseline does ---------------------------------------------------------------------
    def integrate(self, scan: Scan, sensor_pose: Pose2D) -> None:
        raise NotImplementedError


class KeepMap(GatedMethod):
    """``none``: sees the scans (so the session is scored on the same cells) and keeps M_{i-1}."""

    def integrate(self, scan: Scan, sensor_pose: Pose2D) -> None:
        pass

    def current(self) -> np.ndarray:
        return self._ref


class LogOddsMethod(GatedMethod):
    """``remap`` (``prior=False``: starts from nothing) and ``fuse`` (``prior=True``: starts
    from M_{i-1}), both with ``gridmap.mapping.LogOddsMapper``'s increments and clamps."""

    def __init__(self, reference: OccupancyGrid, config, prior: bool):
        super().__init__(reference, config)
        self.mapper = LogOddsMapper(reference)
        if prior:
            _start_from(self.mapper, self._ref)

    def integrate(self, scan: Scan, sensor_pose: Pose2D) -> None:
        self.mapper.add_scan(scan, sensor_pose)

    def current(self) -> np.ndarray:
        return self.mapper.to_grid().data

    def state_bytes(self) -> int:
        # M_{i-1}, the float32 log-odds and the mapper's int32 per-cell scan stamps
        return int(self._ref.nbytes + 2 * self.mapper.logodds.nbytes)


class HybridMethod(MapOutput):
    """``hybrid``: the paper's updater, as it is, decides where the map may change; a log-odds
    map continued on M_{i-1} (``fuse``'s), fed the scans the updater processed at the poses it
    used, decides what the cells there become.

    Where: cells within ``radius`` of the hit of a beam the paper's classifier kept as a
    detected change, or of a cell the paper's map changed. Beams that agree with M open no
    place to change, so the evidence cannot free a wall far from any change, nor draw what
    the detector calls unchanged; near a change it finishes a face that the new-obstacle
    tolerance tol(r) leaves in pieces and frees what is left of an old face inside the pairing
    distance D(r), which the paper's rules never touch. What: the log-odds map's state where
    it has evidence, else the paper's. Three rules keep the evidence from undoing the paper's
    care (measured in benchmarks/RESULTS.md, "The hybrid"): a scan's rays give no miss to the
    cells beside its own returns (``LogOddsParams.hit_guard``, as the paper's seen-surface
    guard); a cell the paper's map has occupied is not freed beside a cell the evidence has
    occupied (with one cell of slack that only thins a face); and the evidence sets only
    cells M knows: M's unknown cells stay the paper's (its removed-obstacle walk frees the
    inside of an object that is gone, its last check closes outlines), since the evidence
    would free an object's inside from the rays of one scan placed a few centimetres off, and
    draw a wall's far side from hits behind it.
    """

    def __init__(self, reference: OccupancyGrid, config, radius: float = HYBRID_RADIUS,
                 faces=None):
        if isinstance(radius, bool) or not isinstance(radius, (int, float)) \
                or not 0 < radius <= 5.0:
            raise MethodError(f"hybrid: radius must be a number in (0, 5] m, got {radius!r}")
        self.paper = MapUpdater(reference, config, faces=faces)
        self.carried_faces = self.paper.carried_faces
        self.face_cells = self.paper.face_cells
        self.config = self.paper.config
        self.radius = float(radius)
        self.mapper = LogOddsMapper(reference, LogOddsParams(hit_guard=1))
        _start_from(self.mapper, reference.data)
        self._ref = reference.data.copy()
        self._res, self._origin = reference.resolution, reference.origin
        self._frame = OccupancyGrid(self._ref, self._res, self._origin)   # for conversions
        self._detected = np.zeros(self._ref.shape, bool)   # hit cells of detected changes
        self._cache: np.ndarray | None = None

    def process(self, scan: Scan, sensor_pose: Pose2D, odometry: Pose2D | None = None,
                pose_check: Callable[[], PoseVerdict] | None = None):
        """The paper's updater on the scan (gate, pose check, lost check and all); a scan it
        processed and kept goes into the evidence at the pose it used."""
        report = self.paper.process(scan, sensor_pose, odometry, pose_check)
        if report.status is ScanStatus.PROCESSED:
            self.mapper.add_scan(self._within_range(scan), report.sensor_pose)
            self._mark_hits(scan, report.sensor_pose, report.verdicts == BeamVerdict.CHANGE)
            self._cache = None
        return report

    def _within_range(self, scan: Scan) -> Scan:
        """The scan with the beams the paper's updater takes as invalid (at or beyond
        ``max_range``) made invalid for the evidence too."""
        far = scan.ranges >= min(self.config.max_range, scan.range_max)
        if not np.any(far):
            return scan
        return replace(scan, ranges=np.where(far, np.float32(np.nan), scan.ranges))

    def _mark_hits(self, scan: Scan, pose: Pose2D, beams: np.ndarray) -> None:
        r = scan.ranges[beams].astype(np.float64)
        a = scan.angles()[beams] + pose.theta
        row, col = self._frame.world_to_cell(pose.x + r * np.cos(a), pose.y + r * np.sin(a))
        inside = self._frame.contains(row, col)
        self._detected[row[inside], col[inside]] = True

    def current(self) -> np.ndarray:
        """The map as it stands (computed when a scan was processed since the last call)."""
        if self._cache is None:
            paper = self.paper.updated_map().data
            seeds = self._detected | (paper != self._ref)
            marks = OccupancyGrid(np.where(seeds, OCCUPIED, FREE).astype(np.int8), self._res,
                                  self._origin)
            where = distance_to_occupied(marks, 2 * self.radius) <= self.radius + 1e-6
            what = self.mapper.to_grid().data
            take = where & (what != UNKNOWN) & (self._ref != UNKNOWN)
            # (the cell itself is free in the evidence, so "near" is its 8 neighbours)
            take &= ~((what == FREE) & (paper == OCCUPIED) & near(what == OCCUPIED))
            paper[take] = what[take]
            self._cache = paper
        return self._cache

    @property
    def stats(self) -> dict:
        return self.paper.stats

    def state_bytes(self) -> int:
        # the paper's state, the float32 log-odds and int32 scan stamps, the detected hits,
        # the output kept between scans
        return int(self.paper.state_bytes() + 2 * self.mapper.logodds.nbytes
                   + self._detected.nbytes + self._ref.nbytes)


def _start_from(mapper, reference: np.ndarray) -> None:
    """M_{i-1} as the mapper's prior, as if every known cell had saturated: its occupied cells
    at the clamp's top, its free ones at its bottom (the clamps are what let them change)."""
    p = mapper.params
    mapper.logodds[reference == OCCUPIED] = p.clamp_max
    mapper.logodds[reference == FREE] = p.clamp_min

