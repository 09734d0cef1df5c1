"""Map-updating methods behind one small interface, so that the paper's updater can be compared
with what a robot would do without it.

A method is what the robot pipeline (``scenarios.pipeline.RobotPipeline``) hands each placed
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
paper     the map updater of ALGORITHM.md (the default)
none      keeps M_{i-1}: what a robot without map updating does
remap     a fresh log-odds map from the session's own scans and the localiser's poses
          (continuous re-mapping, which the paper sets out to avoid): what the session did not
          see is unknown again
fuse      log-odds mapping continued on M_{i-1} as the prior (plain lifelong occupancy
          mapping): its occupied cells start at the clamp's top, its free cells at its bottom,
          so an old cell turns free after 11 misses and a free one occupied after 4 hits
========  ===================================================================================

Every method sees the same scans: the baselines apply the updater's gate (``UpdaterConfig``'s
gating rules) and the pose check exactly as the updater does (asked only past the gate; a
refined pose is used, a refused scan changes nothing and does not advance the gate), so the
runner's observable cells, and so its targets, are those of the same processed scans. What
differs is only what a method does with a scan. The baselines have no lost check: log-odds
mapping has none.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gridmap import FREE, OCCUPIED, MapUpdatingError, OccupancyGrid, Pose2D, PoseVerdict, Scan
from gridmap.suggest import did_you_mean

# The methods, the paper's first (the default).
METHODS = ("paper", "none", "remap", "fuse")


class MethodError(MapUpdatingError, ValueError):
    """An unknown method name, or a method that cannot be built on the map given."""


def check_method(name, source: str = "method") -> str:
    """``name`` if it names a method, else a ``MethodError`` naming the nearest one."""
    if name not in METHODS:
        raise MethodError(f"{source}: unknown method {name!r}{did_you_mean(name, METHODS)} "
                          f"(methods: {', '.join(METHODS)})")
    return name


def make_method(name: str, reference: OccupancyGrid, updater_config=None):
    """The method ``name`` on the reference map M_{i-1}. ``updater_config``: an
    ``updater.UpdaterConfig`` (None: its defaults); the baselines use its gating rules."""
    from updater import MapUpdater, UpdaterConfig

    check_method(name)
    if name == "paper":
        return MapUpdater(reference, updater_config)
    config = UpdaterConfig() if updater_config is None else updater_config
    if name == "none":
        return KeepMap(reference, config)
    return LogOddsMethod(reference, config, prior=(name == "fuse"))


class GatedMethod:
    """What the baselines share: the updater's gate and pose check in front of ``integrate``,
    and the interface's bookkeeping. Subclasses define ``integrate`` and ``current``."""

    def __init__(self, reference: OccupancyGrid, config):
        from updater.gating import Gate

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
        from updater import ScanReport, ScanStatus
        from updater.gating import SKIPPED_OFF_MAP

        self.stats["scans"] += 1
        t = float(scan.time)
        gate_pose = sensor_pose if odometry is None else odometry
        if self.config.gating:
            reason = self._gate.check(t, gate_pose, odometry is not None)
            if reason:
                self.stats["gated"] += 1
                return ScanReport(t, ScanStatus.GATED, reason)
        if not self._on_map(sensor_pose):
            self.stats["skipped"] += 1
            return ScanReport(t, ScanStatus.OFF_MAP, SKIPPED_OFF_MAP)
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
        return ScanReport(t, ScanStatus.PROCESSED, valid_beams=valid)

    def updated_map(self) -> OccupancyGrid:
        return OccupancyGrid(self.current(), self._res, self._origin)

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

    def state_bytes(self) -> int:
        return int(self._ref.nbytes)

    def _on_map(self, pose: Pose2D) -> bool:
        col = (pose.x - self._origin[0]) / self._res
        row = (pose.y - self._origin[1]) / self._res
        return 0 <= col < self._ref.shape[1] and 0 <= row < self._ref.shape[0]

    # --- what a baseline does ---------------------------------------------------------------------
    def integrate(self, scan: Scan, sensor_pose: Pose2D) -> None:
        raise NotImplementedError

    def current(self) -> np.ndarray:
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
        from gridmap.mapping import LogOddsMapper

        super().__init__(reference, config)
        self.mapper = LogOddsMapper(reference)
        if prior:
            # M_{i-1} as if every cell had saturated: the clamps are what let it change again
            p = self.mapper.params
            self.mapper.logodds[self._ref == OCCUPIED] = p.clamp_max
            self.mapper.logodds[self._ref == FREE] = p.clamp_min

    def integrate(self, scan: Scan, sensor_pose: Pose2D) -> None:
        self.mapper.add_scan(scan, sensor_pose)

    def current(self) -> np.ndarray:
        return self.mapper.to_grid().data

    def state_bytes(self) -> int:
        # M_{i-1}, the float32 log-odds and the mapper's int32 per-cell scan stamps
        return int(self._ref.nbytes + 2 * self.mapper.logodds.nbytes)
