"""The robot's per-scan software, once: localiser -> pose check -> lidar mount -> updater ->
counters. The simulated session, the log replay, the gymnasium environment and the live ROS
node all drive this one class; they only turn their inputs (a simulator message, a log record,
a ROS message) into ``step`` calls and its answer into their outputs.

    pipeline = RobotPipeline(updater=MapUpdater(m), localizer=loc, pose_check=PoseCheck(m))
    step = pipeline.step(scan, mount, odometry=odom)     # once per scan
    step.report.status, step.robot_pose, pipeline.counts.scans_processed

Where the robot's pose comes from: the localiser when the pipeline has one (it is updated with
the scan and its estimate is carried to the scan's odometry, the map -> odom convention of
ROS), else the pose the caller gives (a recorded localisation, the truth), smoothed with the
odometry when the pipeline has a ``localization.smoothing.PoseSmoother``. The pose check's
answer is a typed ``gridmap.PoseVerdict`` and the updater's a ``ScanReport`` with a
``ScanStatus``; the counters read those, never a text.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from functools import partial

import numpy as np

from gridmap import OccupancyGrid, Pose2D, Scan
from localization.modes import StartWatch
from updater import MapMethod, ScanReport, ScanStatus


@dataclass
class PipelineCounts:
    """What the pipeline did with the scans it was given."""

    scans: int = 0                        # given to ``step``
    scans_without_pose: int = 0           # no pose to place them at (no localiser, none given)
    scans_processed: int = 0              # classified by the updater (lost ones included)
    scans_dropped_as_lost: int = 0        # classified, then dropped by the lost check
    scans_refused_by_pose_check: int = 0  # the pose check refused their pose
    scans_corrected_by_pose_check: int = 0   # ... placed them at a pose that fits better
    scans_gated: int = 0                  # not processed: the updater's gate refused them
    gated_by: dict = field(default_factory=dict)   # ... by the gate's rule (ScanReport.reason)
    scans_confirming: int = 0             # ... of them, used to confirm M (gate_confirm)
    scans_off_map: int = 0                # not processed: the sensor pose lay off the map
    localizer_updates: int = 0            # scans the localiser ran a filter update on
    scans_not_tracking: int = 0           # withheld: the localiser was lost or converging

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Step:
    """One ``step``: the robot pose the scan was placed at (map frame, before any refinement by
    the pose check; None when there was none) and the updater's report (None without an
    updater or a pose, or when the localiser was not tracking), whose ``sensor_pose`` is the
    pose the updater used (the pose check's refinement when it refined)."""

    robot_pose: Pose2D | None
    report: ScanReport | None


class RobotPipeline:
    """Localiser (optional), pose check (optional), mount and updater (optional) of one robot
    on one reference map.

    ``updater``: an ``updater.MapUpdater``, or any ``updater.MapMethod`` (the baselines and
    the hybrid of ``onboard.methods``); None: localisation only, as the runner's second
    localiser on M1. ``localizer``: a ``localization.MonteCarloLocalizer`` already initialised
    (None: poses come with each scan; it may be set later, once a start is known).
    ``pose_check``: a ``localization.confidence.PoseCheck`` on the updater's reference map.
    ``tracking``: a ``localization.tracking.TrackingMonitor``, judging the localiser after each
    filter update; while it is not tracking, scans are withheld from the updater. After a
    start over the whole map, a ``localization.modes.StartWatch`` follows the places of
    similar weight the particles go through until the monitor first trusts the filter, and
    ``step`` then raises ``localization.modes.AmbiguousStart`` when the scans fit another of
    them as well (``refuse_ambiguous_start``, on by default): a symmetric room's mirror pose
    would otherwise be trusted and the map updated from it.
    ``smoother``: a ``localization.smoothing.PoseSmoother`` for the poses given with the scans
    (a recorded localisation that jitters), used only without a localiser. ``cpu`` holds
    the process time spent in the localiser (tracking verdict included) and in the updater
    (pose check included) [s].
    """

    def __init__(self, updater: MapMethod | None = None, localizer=None, pose_check=None,
                 tracking=None, smoother=None):
        self.updater = updater
        self.localizer = localizer
        self.pose_check = pose_check
        self.tracking = tracking
        self.smoother = smoother
        self.counts = PipelineCounts()
        self.cpu = {"localizer_s": 0.0, "updater_s": 0.0}
        self.refuse_ambiguous_start = True
        self.start_watch: StartWatch | None = None
        self._start_odometry: Pose2D | None = None   # the localiser's first odometry

    def step(self, scan: Scan, mount: Pose2D, odometry: Pose2D | None = None,
             pose: Pose2D | None = None) -> Step:
        """Place one scan and hand it to the updater. ``mount``: the lidar on the robot (base
        frame); ``odometry``: the robot's odom-frame pose at the scan's time (the localiser's
        motion input and the updater's gate); ``pose``: the robot's map-frame pose, used only
        when the pipeline has no localiser (through its smoother, when it has one)."""
        self.counts.scans += 1
        robot, cov = self._locate(scan, mount, odometry, pose)
        if robot is None:
            self.counts.scans_without_pose += 1
            return Step(None, None)
        if self.updater is None:
            return Step(robot, None)
        if self.tracking is not None and self.localizer is not None \
                and not self.tracking.tracking:
            self.counts.scans_not_tracking += 1
            return Step(robot, None)
        t0 = time.process_time()
        check = None if self.pose_check is None else partial(
            self.pose_check.verdict, scan, robot, mount, cov)
        given = robot.compose(mount)
        report = self.updater.process(scan, given, odometry=odometry, pose_check=check)
        self.cpu["updater_s"] += time.process_time() - t0
        self._count(report)
        self.counts.scans_corrected_by_pose_check += (
            report.processed and report.sensor_pose is not None and report.sensor_pose != given)
        if self.tracking is not None and report.processed:
            self.tracking.observe_lost(report.dropped_as_lost, float(scan.time))
        return Step(robot, report)

    def _locate(self, scan, mount, odometry, pose):
        """(robot pose in the map frame, its covariance or None)."""
        if self.localizer is None:
            if self.smoother is not None and pose is not None:
                pose = self.smoother(float(scan.time), pose, odometry)
            return pose, None
        if odometry is None:
            return None, None
        t0 = time.process_time()
        if self._start_odometry is None:
            self._start_odometry = odometry
        updated = bool(self.localizer.update(odometry, scan, mount))
        self.counts.localizer_updates += updated
        est = self.localizer.estimate()
        robot = est.pose_at(odometry)
        if updated and self.tracking is not None:
            self._judge(scan, mount, odometry, robot)
        self.cpu["localizer_s"] += time.process_time() - t0
        return robot, est.cov

    def _judge(self, scan: Scan, mount: Pose2D, odometry: Pose2D, robot: Pose2D) -> None:
        """The tracking verdict on a filter update; until a start over the whole map is first
        trusted, the start watch too, which raises ``AmbiguousStart`` at that moment when the
        scans fit another place as well."""
        watching = self.refuse_ambiguous_start and self.tracking.never_tracked
        self.tracking.observe(self.localizer, scan, robot, mount)
        if not watching:
            return
        if self.start_watch is None:
            self.start_watch = StartWatch(self.localizer.grid, self._start_odometry)
        self.start_watch.observe(self.localizer, scan, mount, odometry, robot)
        if self.tracking.tracking:
            self.start_watch.refuse(robot)

    def _count(self, report: ScanReport) -> None:
        c = self.counts
        c.scans_processed += report.processed
        c.scans_dropped_as_lost += report.status is ScanStatus.LOST
        c.scans_refused_by_pose_check += report.status is ScanStatus.REFUSED
        c.scans_off_map += report.status is ScanStatus.OFF_MAP
        if report.status is ScanStatus.GATED:
            c.scans_gated += 1
            c.gated_by[report.reason] = c.gated_by.get(report.reason, 0) + 1
            c.scans_confirming += report.unchanged_flags > 0


def warm_up(build, resolution: float = 0.05) -> None:
    """Run a throwaway pipeline, ``build(grid)``, over a few scans in a small walled room at
    ``resolution`` (one block in it that the scans see through, a removed object), so that
    numba has compiled (or loaded) the kernels before a live node's first real scan: a first
    scan that compiles holds the node for seconds, and a lidar's best-effort queue drops what
    arrives meanwhile. The kernels' compiled forms depend on the types, not on the map: a
    node warms up once, before it subscribes."""
    n = 80
    data = np.zeros((n, n), np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    data[30:34, 50:54] = 100
    grid = OccupancyGrid(data, resolution, (0.0, 0.0))
    pipeline = build(grid)
    inner = (2 * resolution, (n - 2) * resolution)           # the walls' faces
    angles = -math.pi + np.arange(360) * (2 * math.pi / 360)
    for k in range(6):
        x, y, th = inner[1] * (0.3 + 0.03 * k), inner[1] * 0.5, 0.2 * k
        c, s = np.cos(angles + th), np.sin(angles + th)
        with np.errstate(divide="ignore"):
            tx = np.where(c > 0, (inner[1] - x) / c, (inner[0] - x) / c)
            ty = np.where(s > 0, (inner[1] - y) / s, (inner[0] - y) / s)
        ranges = np.minimum(np.abs(tx), np.abs(ty)).astype(np.float32)
        scan = Scan(ranges, -math.pi, 2 * math.pi / 360, 0.0, 2 * n * resolution, time=k)
        robot = Pose2D(x, y, th)
        pipeline.step(scan, Pose2D(0.0, 0.0, 0.0), odometry=robot, pose=robot)
    if getattr(pipeline, "updater", None) is not None:
        pipeline.updater.updated_map()      # what a node publishes, with its own kernels
