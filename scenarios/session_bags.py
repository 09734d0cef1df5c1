"""Simulated sessions written as ROS bags, so they replay in ROS tools and in
``mapupdate update`` like a real robot's recordings.

Per scan: the LaserScan, the odometry (``/odom`` and ``odom -> base_link``), the localiser's
``map -> odom`` and ``/amcl_pose``, and the simulator's true pose on ``/ground_truth/pose``;
each lidar's mount once on ``/tf_static``. One bag per update session:
``DIR/<session>.bag`` (ROS 1) or ``DIR/<session>/`` (ROS 2).

Stamps are the session's time from a fixed date: session i starts ``i`` days after
``BAG_EPOCH`` (2023-11-14), as sessions of a warehouse would. ROS 1 reads a stamp of 0 as "the
latest" in tf lookups, so a clock that starts at 0 cannot be replayed to a live node, and
sessions that all started at one time would look to a running node like time going back.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from gridmap import Pose2D
from onboard.outputs import OutputClash
from robotlogs.records import MapRecord, OdomRecord, PoseRecord, ScanRecord, TransformRecord
from robotlogs.rosbag import BagWriter

BAG_EPOCH = 1_700_000_000.0   # [s] the bags' clock at the start of session 0
DAY = 86_400.0


def lidar_frame(index: int) -> str:
    return "laser" if index == 0 else f"laser_{index}"


def lidar_topic(index: int) -> str:
    return "/scan" if index == 0 else f"/scan_{index}"


def check_bag_folder(out_dir, resume: bool = False) -> None:
    """Before a run: its bags go into a new or empty folder, since each session's bag replaces
    any of its name there (another run's ``W2.bag``); a resumed run's folder holds its own
    finished bags, which it keeps. Raises ``OutputClash`` naming the folder."""
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise OutputClash(f"--bag {folder}: is a file, not a folder; the bags go into a new or "
                          "empty folder")
    if resume or not folder.is_dir():
        return
    others = sorted(p.name for p in folder.iterdir())
    if others:
        raise OutputClash(f"--bag {folder}: holds other files ({', '.join(others[:3])}"
                          f"{', ...' if len(others) > 3 else ''}), which this run's bags would "
                          "overwrite; the bags go into a new or empty folder (or --resume the "
                          "run that wrote them)")


class SessionBagRecorder:
    """A session observer (see ``scenarios.runner.SessionObserver``) that writes bags."""

    def __init__(self, out_dir, fmt: str = "ros1"):
        self.out_dir = Path(out_dir)
        self.fmt = fmt
        self.paths: dict[str, Path] = {}
        self._bag: BagWriter | None = None

    def session_start(self, scenario, session, world, previous, initial, updater,
                      localizer) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        name = scenario.sessions[session].name
        path = self.out_dir / (f"{name}.bag" if self.fmt == "ros1" else name)
        self._start = BAG_EPOCH + DAY * session     # [s] this session's clock at 0
        # Written under a partial name and renamed when the session ends: a killed run leaves
        # no bag that looks whole, and its resumed session writes the partial one anew. A ROS 2
        # bag names its data file after its folder (metadata.yaml lists it), so it is written
        # with its final name inside a partial folder: .partial-W2/W2/W2.db3 -> W2/W2.db3.
        partial = path.with_name(f".partial-{path.name}")
        _remove(partial)
        writing = partial if self.fmt == "ros1" else partial / path.name
        self._bag = BagWriter(writing, self.fmt).__enter__()
        self._partial, self._writing, self.paths[name] = partial, writing, path
        self._bag.write_transforms([
            TransformRecord(self._start, "base_link", lidar_frame(i), lidar.mount, static=True)
            for i, lidar in enumerate(scenario.robot.lidars)])
        # the map the session starts from, as a map server would offer it to the robot
        self._bag.write(MapRecord(self._start, previous))

    def scan(self, msg, estimate: Pose2D, report, world, updater, localizer) -> None:
        est = localizer.estimate()
        t = self._start + msg.time
        bag = self._bag
        bag.write(OdomRecord(t, msg.odom_pose))
        bag.write_transforms([TransformRecord(t, "map", "odom", est.map_to_odom()),
                              TransformRecord(t, "odom", "base_link", msg.odom_pose)])
        bag.write(PoseRecord(t, estimate, covariance=est.cov))
        bag.write(PoseRecord(t, msg.true_pose, topic="/ground_truth/pose"))
        bag.write(ScanRecord(t, msg.scan, frame_id=lidar_frame(msg.lidar),
                             topic=lidar_topic(msg.lidar)))

    def session_end(self, result) -> None:
        if self._bag is not None:
            self._bag.close()
            self._bag = None
            final = self.paths[result.name]
            _remove(final)                  # an earlier run's bag of this session
            self._writing.rename(final)
            _remove(self._partial)          # the emptied partial folder (ROS 2)


def _remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
