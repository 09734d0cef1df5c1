"""The map store's side of a fleet: the scan-time queue that merges the robots' uploads, the
per-robot gate in front of one shared updater, and the merge of per-robot updated maps.

Two ways for N robots to update one map (docs/fleet.md measures both):

- **shared**: one ``MapUpdater`` takes every robot's scans in scan-time order. Its rolling
  buffers then hold each cell's latest N_b flags whoever made them, as one robot's buffers
  hold its latest N_b. The gate is per robot (it judges one robot's motion from its odometry),
  so the shared updater runs with its gate off and each robot has a ``SharedGate`` in front
  of it, with the updater's own ``updater.gating.Gate`` rules.
- **per robot**: one ``MapUpdater`` each, their maps merged at commit by ``merge_maps``.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, PoseVerdict, Scan
from updater import MapUpdater, ScanReport, ScanStatus, UpdaterConfig
from updater.gating import CONFIRMING, Gate

MERGE_RULES = ("vote", "union")
# [m] beyond a robot's radius, how far from another robot's latest pose a return is taken for
# that robot: the pose is up to one scan period old (0.06 m at 0.6 m/s and 10 Hz) and off by
# the localiser's error (a few cm)
ROBOT_MASK_MARGIN = 0.2


class ScanQueue:
    """Merges the robots' message streams into scan-time order.

    Each robot's messages arrive in its own time order, but the robots upload at their own
    moments (a batch every second, a link that stalls), so across robots they arrive out of
    order. ``push`` takes a robot's message as it arrives; ``pop_ready`` returns, in time order
    (ties by robot number, then arrival), every message no later robot upload can precede:
    those at or before the oldest of the robots' latest times (the watermark). A robot that has
    sent everything calls ``close`` so that it holds nobody back; ``drain`` empties the queue
    at the end."""

    def __init__(self, n_robots: int):
        self._heap: list = []
        self._latest = [-math.inf] * n_robots
        self._open = [True] * n_robots
        self._count = 0

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, robot: int, time: float, item) -> None:
        if time < self._latest[robot]:
            raise ValueError(f"robot {robot}: message at {time} s after one at "
                             f"{self._latest[robot]} s (each robot uploads in time order)")
        self._latest[robot] = time
        heapq.heappush(self._heap, (time, robot, self._count, item))
        self._count += 1

    def close(self, robot: int) -> None:
        self._open[robot] = False

    @property
    def watermark(self) -> float:
        """[s] every message up to this time has arrived."""
        times = [t for t, is_open in zip(self._latest, self._open) if is_open]
        return min(times) if times else math.inf

    def pop_ready(self) -> list[tuple[int, float, object]]:
        """(robot, time, item) of every message at or before the watermark, in time order."""
        mark, out = self.watermark, []
        while self._heap and self._heap[0][0] <= mark:
            time, robot, _, item = heapq.heappop(self._heap)
            out.append((robot, time, item))
        return out

    def drain(self) -> list[tuple[int, float, object]]:
        for k in range(len(self._open)):
            self.close(k)
        return self.pop_ready()


def shared_updater(reference: OccupancyGrid, config: UpdaterConfig | None = None) -> MapUpdater:
    """The one updater of the shared mode: the configuration's rules with its gate off (the
    robots' ``SharedGate`` objects gate instead)."""
    config = UpdaterConfig() if config is None else config
    return MapUpdater(reference, replace(config, gating=False))


class SharedGate:
    """One robot's way into the shared updater: that robot's gate (``updater.gating.Gate``,
    the rules of ``config``), then the shared updater. A ``updater.MapMethod``, so the robot's
    ``RobotPipeline`` drives it as it drives an updater of its own.

    With ``gate_confirm``, a scan this robot's gate holds back as a view already taken
    still confirms M's surfaces in the shared updater (``MapUpdater.confirm``)."""

    def __init__(self, shared: MapUpdater, config: UpdaterConfig | None = None):
        config = UpdaterConfig() if config is None else config
        if config.gate_confirm and not shared.config.gate_confirm:
            raise ValueError("gate_confirm needs a shared updater made with it "
                             "(shared_updater(reference, config))")
        if shared.config.gating:
            raise ValueError("the shared updater's own gate must be off (shared_updater())")
        self.shared, self.config = shared, config
        self._gate = Gate(config)
        self.stats = {"scans": 0, "gated": 0}

    def process(self, scan: Scan, sensor_pose: Pose2D, odometry: Pose2D | None = None,
                pose_check: Callable[[], PoseVerdict] | None = None) -> ScanReport:
        """Gate the scan on this robot's motion; a scan let through goes to the shared
        updater, and only one it processed and kept advances this robot's gate."""
        self.stats["scans"] += 1
        t = float(scan.time)
        gate_pose = sensor_pose if odometry is None else odometry
        if self.config.gating:
            reason = self._gate.check(t, gate_pose, odometry is not None,
                                      math.degrees(scan.fov()))
            if reason:
                self.stats["gated"] += 1
                n_un = self.shared.confirm(scan, sensor_pose) \
                    if self.config.gate_confirm and reason in CONFIRMING else 0
                return ScanReport(t, ScanStatus.GATED, reason, unchanged_flags=n_un,
                                  changed_cells=self.shared.n_changed, sensor_pose=sensor_pose)
        report = self.shared.process(scan, sensor_pose, odometry, pose_check)
        if self.config.gating and report.status is ScanStatus.PROCESSED:
            self._gate.mark_processed(t, gate_pose)
        return report

    def updated_map(self) -> OccupancyGrid:
        return self.shared.updated_map()

    def state_bytes(self) -> int:
        return self.shared.state_bytes()

    @property
    def n_changed(self) -> int:
        return self.shared.n_changed


class FleetBoard:
    """Where each robot of the fleet was at its latest handled scan (its localiser's
    estimate): what the robots report to the map store with their scans."""

    def __init__(self, n_robots: int, radius: float):
        self.xy = np.full((n_robots, 2), np.nan)
        self.radius = float(radius)

    def report(self, robot: int, pose: Pose2D | None) -> None:
        if pose is not None:
            self.xy[robot] = (pose.x, pose.y)

    def others(self, robot: int) -> np.ndarray:
        """(M, 2) the latest known positions of every other robot."""
        xy = np.delete(self.xy, robot, axis=0)
        return xy[np.isfinite(xy).all(axis=1)]


class RobotMask:
    """A method (``updater.MapMethod``) in front of another that hides the other robots from
    it: the returns of a scan that land within the robot radius (plus
    ``ROBOT_MASK_MARGIN``) of another robot's latest reported position become invalid beams,
    so a robot waiting in an aisle is neither drawn into the map nor a reason to free what
    it hides. Only the map update is spared them; the robot's localiser sees the scan as
    taken."""

    def __init__(self, inner, robot: int, board: FleetBoard,
                 margin: float = ROBOT_MASK_MARGIN):
        self.inner, self.robot, self.board = inner, robot, board
        self.margin = float(margin)
        self.masked_beams = 0

    def process(self, scan: Scan, sensor_pose: Pose2D, odometry: Pose2D | None = None,
                pose_check: Callable[[], PoseVerdict] | None = None) -> ScanReport:
        return self.inner.process(self.mask(scan, sensor_pose), sensor_pose, odometry,
                                  pose_check)

    def mask(self, scan: Scan, sensor_pose: Pose2D) -> Scan:
        others = self.board.others(self.robot)
        if not len(others):
            return scan
        r = scan.ranges.astype(np.float64)
        a = scan.angles() + sensor_pose.theta
        hx, hy = sensor_pose.x + r * np.cos(a), sensor_pose.y + r * np.sin(a)
        reach = self.board.radius + self.margin
        with np.errstate(invalid="ignore"):
            near_robot = ((hx[:, None] - others[:, 0]) ** 2 + (hy[:, None] - others[:, 1]) ** 2
                          <= reach * reach).any(axis=1) & np.isfinite(r)
        if not near_robot.any():
            return scan
        self.masked_beams += int(near_robot.sum())
        return replace(scan, ranges=np.where(near_robot, np.float32(np.nan), scan.ranges))

    def updated_map(self) -> OccupancyGrid:
        return self.inner.updated_map()

    def state_bytes(self) -> int:
        return self.inner.state_bytes()

    @property
    def n_changed(self) -> int:
        return self.inner.n_changed


def merge_maps(reference: OccupancyGrid, maps, observed=None, min_observations: int = 7,
               ) -> OccupancyGrid:
    """One map from the robots' updated maps of the same reference.

    A cell takes a value some robot's map gives it. With ``observed`` (per robot, how many of
    its own processed scans saw each cell), the robots that saw the cell at least
    ``min_observations`` times vote with their map's value and the most votes win ("vote");
    without, or where no robot saw the cell that often, every robot's value is a candidate and
    none outvotes another ("union"). Ties go to a change from ``reference`` over no change
    (a robot that saw a change enough to decide it is believed until more robots contradict
    it), and between changes to occupied over free over unknown (a wrong obstacle costs a
    detour, a wrong free cell a collision)."""
    stack = np.stack([m.data for m in maps])
    ref = reference.data
    voters = None if observed is None else \
        np.stack([np.asarray(o) for o in observed]) >= min_observations
    best = np.full(ref.shape, -1, np.int64)
    out = ref.copy()
    for value, rank in ((UNKNOWN, 0), (FREE, 1), (OCCUPIED, 2)):
        has = stack == value
        present = has.any(axis=0)
        votes = (has & voters).sum(axis=0) if voters is not None else 0
        score = np.where(present, votes * 8 + (ref != value) * 4 + rank, -1)
        take = score > best
        out[take] = value
        best = np.maximum(best, score)
    return reference.with_data(out.astype(ref.dtype))


def check_merge_rule(rule: str) -> str:
    if rule not in MERGE_RULES:
        raise ValueError(f"unknown merge rule {rule!r} (rules: {', '.join(MERGE_RULES)})")
    return rule


__all__ = ["MERGE_RULES", "FleetBoard", "RobotMask", "ScanQueue", "SharedGate",
           "check_merge_rule", "merge_maps", "shared_updater"]
