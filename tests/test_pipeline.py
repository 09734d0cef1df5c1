"""The one robot pipeline: localiser -> pose check -> mount -> updater -> counters, and the
front ends that drive it."""

from __future__ import annotations

import ast
import math
import pathlib

import numpy as np

from gridmap import FREE, OCCUPIED, Pose2D, PoseVerdict
from localization import LocalizerConfig, MonteCarloLocalizer
from localization.confidence import PoseCheck
from onboard.pipeline import RobotPipeline
from updater import MapUpdater, ScanStatus

import synthetic_room as world

ROOT = pathlib.Path(__file__).resolve().parents[1]
MOUNT = Pose2D(0.2, 0.0, 0.0)                       # lidar 0.2 m ahead of the base
BOX = world.Rect(7.0125, 5.0125, 7.6125, 5.8125)    # in the map, gone from the world


def scene():
    walls = world.room_walls()
    return walls, world.rasterise(walls + [BOX])


def drive(n=60, step=0.05):
    """Robot poses along y = 4 m (odometry = truth here) and the matching lidar scans."""
    walls, _ = scene()
    for k in range(n):
        robot = Pose2D(2.0 + step * k, 4.0, 0.2)
        yield robot, world.full_scan(walls, robot.compose(MOUNT), 0.1 * k)


class Refuse:
    """A pose check that refuses every other call and counts its calls."""

    def __init__(self):
        self.calls = 0

    def verdict(self, scan, robot, mount, cov):
        self.calls += 1
        return PoseVerdict.refused("test") if self.calls % 2 else PoseVerdict.accepted()


def test_given_poses_are_composed_with_the_mount_once_and_free_the_removed_box():
    _, ref = scene()
    via_pipeline, direct = MapUpdater(ref, profile="paper"), MapUpdater(ref, profile="paper")
    pipeline = RobotPipeline(via_pipeline)
    for robot, scan in drive():
        step = pipeline.step(scan, MOUNT, odometry=robot, pose=robot)
        report = direct.process(scan, robot.compose(MOUNT), odometry=robot)
        assert step.robot_pose == robot and step.report.status is report.status
    assert np.array_equal(via_pipeline.updated_map().data, direct.updated_map().data)
    box = world.cells_of(BOX) & (ref.data == OCCUPIED)
    freed = (via_pipeline.updated_map().data[box] == FREE).mean()
    assert freed > 0.5                                 # the face the robot sees is freed
    c = pipeline.counts
    assert c.scans == 60 and c.scans_processed == via_pipeline.stats["processed"] > 5
    assert c.scans_without_pose == c.scans_refused_by_pose_check == 0


def test_refusals_are_counted_from_the_typed_verdict_and_change_nothing():
    _, ref = scene()
    check = Refuse()
    pipeline = RobotPipeline(MapUpdater(ref, profile="paper"), pose_check=check)
    statuses = [pipeline.step(scan, MOUNT, odometry=robot, pose=robot).report.status
                for robot, scan in drive()]
    c = pipeline.counts
    assert c.scans_refused_by_pose_check == statuses.count(ScanStatus.REFUSED) == \
        math.ceil(check.calls / 2) > 3
    assert c.scans_processed == statuses.count(ScanStatus.PROCESSED) == check.calls // 2
    assert pipeline.updater.stats["skipped"] == c.scans_refused_by_pose_check


def test_without_a_pose_or_odometry_a_scan_is_counted_and_skipped():
    _, ref = scene()
    robot, scan = next(drive())
    pipeline = RobotPipeline(MapUpdater(ref, profile="paper"))
    step = pipeline.step(scan, MOUNT, odometry=robot)           # no localiser, no pose
    assert step.report is None and step.robot_pose is None
    loc = MonteCarloLocalizer(ref, LocalizerConfig(), seed=1)
    loc.initialize(robot, np.diag([1e-4, 1e-4, 1e-5]))
    pipeline.localizer = loc
    assert pipeline.step(scan, MOUNT).report is None            # the localiser needs odometry
    assert pipeline.counts.scans == 2 and pipeline.counts.scans_without_pose == 2
    assert pipeline.updater.stats["scans"] == 0


def test_with_a_localiser_the_updater_gets_its_estimate_and_the_check_its_covariance():
    _, ref = scene()
    loc = MonteCarloLocalizer(ref, LocalizerConfig(), seed=3)
    first = next(drive())[0]
    loc.initialize(first, np.diag([1e-4, 1e-4, 1e-5]))
    seen = []

    class Spy(PoseCheck):
        def verdict(self, scan, robot, mount, cov=None):
            seen.append((robot, cov))
            return super().verdict(scan, robot, mount, cov)
    pipeline = RobotPipeline(MapUpdater(ref, profile="paper"), loc, Spy(ref))
    errors = []
    for robot, scan in drive():
        step = pipeline.step(scan, MOUNT, odometry=robot, pose=Pose2D(0.0, 0.0, 0.0))
        errors.append(math.hypot(step.robot_pose.x - robot.x, step.robot_pose.y - robot.y))
    assert max(errors) < 0.1                          # the given pose is ignored
    assert pipeline.counts.localizer_updates > 3 and seen
    assert all(cov is not None and cov.shape == (3, 3) for _, cov in seen)
    assert pipeline.cpu["localizer_s"] > 0 and pipeline.cpu["updater_s"] > 0


def test_localisation_only_pipeline_has_no_updater():
    _, ref = scene()
    loc = MonteCarloLocalizer(ref, LocalizerConfig(), seed=3)
    robot, scan = next(drive())
    loc.initialize(robot, np.diag([1e-4, 1e-4, 1e-5]))
    step = RobotPipeline(localizer=loc).step(scan, MOUNT, odometry=robot)
    assert step.report is None and math.hypot(step.robot_pose.x - robot.x,
                                              step.robot_pose.y - robot.y) < 0.05


def _steps(path: pathlib.Path) -> list[str]:
    """Calls of ``<...updater...>.process(...)`` and ``<...localizer...>.update(...)``."""
    out = []
    for n in ast.walk(ast.parse(path.read_text())):
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute):
            owner = ast.unparse(n.func.value).lower()
            if (n.func.attr == "process" and "upd" in owner) or \
                    (n.func.attr == "update" and "loc" in owner):
                out.append(f"{path.relative_to(ROOT)}:{n.lineno}")
    return out


def test_only_the_pipeline_steps_the_localiser_and_the_updater():
    """Front ends (the session, the log replay, the ROS node, the gym env) go through the
    pipeline: nothing else calls ``MapUpdater.process`` or ``MonteCarloLocalizer.update``."""
    inside = _steps(ROOT / "onboard" / "pipeline.py")
    elsewhere = [c for pkg in ("onboard", "scenarios", "studies", "mapupdate")
                 for p in sorted((ROOT / pkg).rglob("*.py"))
                 if p.name != "pipeline.py" for c in _steps(p)]
    assert len(inside) == 2 and elsewhere == []
    assert all((ROOT / pkg / "__init__.py").is_file()
               for pkg in ("onboard", "scenarios", "studies", "mapupdate"))


class Shift:
    """A pose check that refines every sensor pose 3 cm to the left, or refuses every scan."""

    def __init__(self, refuse=False):
        self.refuse = refuse

    def verdict(self, scan, robot, mount, cov):
        if self.refuse:
            return PoseVerdict.refused("test")
        sensor = robot.compose(mount)
        return PoseVerdict.refined(Pose2D(sensor.x, sensor.y + 0.03, sensor.theta))


def test_the_report_carries_the_sensor_pose_the_scan_was_placed_at():
    _, ref = scene()
    (robot, scan), *_ = drive(1)
    plain = RobotPipeline(MapUpdater(ref, profile="paper")).step(scan, MOUNT, odometry=robot, pose=robot)
    assert plain.report.sensor_pose == robot.compose(MOUNT)
    refined = RobotPipeline(MapUpdater(ref, profile="paper"), pose_check=Shift()).step(scan, MOUNT,
                                                                      odometry=robot, pose=robot)
    expected = robot.compose(MOUNT)
    assert refined.report.status is ScanStatus.PROCESSED
    assert refined.report.sensor_pose == Pose2D(expected.x, expected.y + 0.03, expected.theta)
    refused = RobotPipeline(MapUpdater(ref, profile="paper"), pose_check=Shift(refuse=True)).step(
        scan, MOUNT, odometry=robot, pose=robot)
    assert refused.report.status is ScanStatus.REFUSED and refused.report.sensor_pose is None
