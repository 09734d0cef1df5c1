"""A recording's scans with every pose the log gives at each: the recorded localisation, the
odometry, the truth (when the log has them) and the laser's mount on the robot.

``log_observations(path)`` reads a CARMEN log or a ROS 1/2 bag (the format detected from the
file) and returns the observations in log order, how many there are, and what the log offers.
Imports only ``gridmap`` and this package.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gridmap import Pose2D, Scan
from gridmap.files import FileInputError, check_regular_file

from .carmen import read_carmen
from .frames import PoseTimeline, TransformTree
from .records import LogError, OdomRecord, PoseRecord, ReadStats, ScanRecord, TransformRecord
from .rosbag import bag_topics, read_bag, resolve_topics, scan_count
from .text_lines import GZIP_MAGIC, LogLimits, gzip_head

FORMATS = ("carmen", "ros1", "ros2")
# How far laser-to-odometry offsets may spread and still be one fixed mount: logs print poses
# to a micrometre or so, a localisation's corrections move by centimetres.
FIXED_MOUNT_M = 1e-3
FIXED_MOUNT_RAD = 1e-3


@dataclass(frozen=True)
class Observation:
    """One scan with every pose the log gives at its time (None where it gives none)."""

    time: float
    scan: Scan
    mount: Pose2D                 # the laser on the robot (base frame)
    odom: Pose2D | None           # the robot in the odometry frame
    recorded: Pose2D | None       # the robot in the map frame, from the recorded localisation
    truth: Pose2D | None          # the robot's true pose, when the log has it
    sensor: Pose2D | None = None  # the laser in the map frame as the log gives it (CARMEN)
    topic: str = ""               # which lidar: a bag's scan topic, a CARMEN line's message


# --- format ------------------------------------------------------------------------------------

def detect_format(path) -> str:
    """``"carmen"``, ``"ros1"`` or ``"ros2"`` from the path and the file's first bytes."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such log")
    if p.is_dir():
        if (p / "metadata.yaml").exists():
            return "ros2"
        raise LogError(f"{p}: a directory without metadata.yaml is not a ROS 2 bag")
    with p.open("rb") as f:
        head = f.read(4096)
    if head.startswith(b"#ROSBAG"):
        return "ros1"
    if p.suffix in (".mcap", ".db3") or head.startswith((b"\x89MCAP", b"SQLite format 3")):
        if p.suffix not in (".mcap", ".db3"):
            raise LogError(f"{p}: a ROS 2 storage file must end in .mcap or .db3 to be read")
        return "ros2"
    if p.suffix == ".bag":
        raise LogError(f"{p}: not a ROS 1 bag (no '#ROSBAG' header)")
    if head.startswith(GZIP_MAGIC):
        head = _gunzipped_head(p)
    if b"\x00" in head or not _is_text(head):
        raise LogError(f"{p}: neither a ROS bag nor a CARMEN text log")
    return "carmen"


def _gunzipped_head(path: Path) -> bytes:
    """The first 4 KB of a gzip file's content (a compressed CARMEN log, as killian.clf.gz),
    also of one cut short."""
    try:
        return gzip_head(path, 4096)
    except (OSError, EOFError, zlib.error) as e:
        raise LogError(f"{path}: a damaged gzip file: {e}") from None


def _is_text(head: bytes) -> bool:
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as e:
        return e.start >= len(head) - 3  # a multi-byte character cut off by the 4 KB read
    return True


# --- observations from a CARMEN log ------------------------------------------------------------

def carmen_observations(path, *, strict: bool = False, laser_mount: Pose2D | None = None,
                        stats: ReadStats | None = None, limits: LogLimits | None = None
                        ) -> tuple[list[Observation], dict]:
    """The scans of a CARMEN log with their poses, and what the log offers (``has``).

    The laser line's ``x y theta`` is the laser's pose (recorded localisation in corrected
    logs) and ``odom_*`` the robot's odometry; the mount is their difference (in raw logs the
    front-laser offset), unless ``laser_mount`` is given. When the laser poses are a
    localisation apart from the odometry, their difference from it is not the mount (it holds
    the map's offset from the odometry's frame) and the log says nothing else of it: the
    laser is taken to sit at the robot's origin, so the robot's recorded pose is the laser's,
    in the map's frame. ``limits``: what the file may hold (``read_carmen``).
    """
    log = read_carmen(path, strict=strict, limits=limits)
    if stats is not None:
        stats.merge(log.stats)
    truth = PoseTimeline()
    odom = PoseTimeline()
    for r in log.records:
        if isinstance(r, PoseRecord):
            truth.add(r.time, r.pose)
        elif isinstance(r, OdomRecord):
            odom.add(r.time, r.pose)
    map_frame = not laser_poses_are_odometry(log)
    out = []
    for r in log.scans():
        robot_odom = r.odom_pose if r.odom_pose is not None else odom.at(r.time)
        if laser_mount is not None:
            mount = laser_mount
        elif r.laser_pose is not None and r.odom_pose is not None and not map_frame:
            mount = r.laser_pose.relative_to(r.odom_pose)
        else:
            mount = Pose2D(0.0, 0.0, 0.0)
        recorded = None if r.laser_pose is None else r.laser_pose.compose(mount.inverse())
        out.append(Observation(r.time, r.scan, mount, robot_odom, recorded, truth.at(r.time),
                               sensor=r.laser_pose, topic=r.topic))
    recorded = any(o.sensor is not None for o in out)
    has = {"recorded": recorded, "map_frame": recorded and map_frame,
           "odometry": any(o.odom is not None for o in out), "truth": len(truth) > 0}
    return out, has


def laser_poses_are_odometry(log) -> bool:
    """True when every laser line's laser pose is its odometry pose moved by one fixed mount
    (zero included): the log then has one stream of poses, which serves as its odometry, and
    nothing says it is in the frame of a map. A raw log is so (CARMEN's logger writes the
    odometry carried to the laser: sena.odom.log), and so is a corrected log that wrote its
    poses in both places (intel.gfs.log, killian.clf.gz). Laser poses that differ from the
    odometry by a varying offset are a localisation's, beside the raw odometry."""
    mounts = np.array([r.laser_pose.relative_to(r.odom_pose).as_array() for r in log.scans()
                       if r.laser_pose is not None and r.odom_pose is not None])
    if mounts.size == 0:
        return False
    return bool(np.ptp(mounts[:, :2], axis=0).max() <= FIXED_MOUNT_M
                and np.ptp(np.unwrap(mounts[:, 2])) <= FIXED_MOUNT_RAD)


# --- observations from a bag -------------------------------------------------------------------

@dataclass
class BagPoses:
    """What the small topics of a bag say: the tf tree (with odometry and the recorded
    localisation added as edges) and the frames to look poses up in."""

    tree: TransformTree
    map_frame: str
    odom_frame: str
    base_frame: str
    amcl: PoseTimeline
    truth: PoseTimeline


def bag_poses(path, *, odom_topic=None, pose_topic=None, truth_topic=None, map_frame=None,
              odom_frame=None, base_frame=None, strict=False, stats=None) -> BagPoses:
    """First pass over a bag: tf, odometry, the localiser's and the true poses."""
    tree, amcl, truth = TransformTree(), PoseTimeline(), PoseTimeline()
    odometry: list[OdomRecord] = []
    amcl_records: list[PoseRecord] = []
    topics = resolve_topics(bag_topics(path), odom_topic=odom_topic, pose_topic=pose_topic,
                            truth_topic=truth_topic, source=str(path))
    for r in read_bag(path, odom_topic=odom_topic, pose_topic=pose_topic,
                      truth_topic=truth_topic, kinds=("odom", "tf", "pose", "truth"),
                      strict=strict, stats=stats):
        if isinstance(r, TransformRecord):
            tree.add(r)
        elif isinstance(r, OdomRecord):
            odometry.append(r)
        elif isinstance(r, PoseRecord) and r.topic == topics.truth:
            truth.add(r.time, r.pose)
        elif isinstance(r, PoseRecord):
            amcl_records.append(r)
            amcl.add(r.time, r.pose)
    first_odom = odometry[0] if odometry else None
    odom_frame = odom_frame or (first_odom.frame_id if first_odom else "odom")
    if base_frame is None:
        # Without odometry messages the base is odom's one child in tf (base_footprint, ...).
        children = sorted(c for c, p in tree.parent.items() if p == odom_frame)
        base_frame = first_odom.child_frame_id if first_odom else \
            children[0] if len(children) == 1 else "base_link"
    map_frame = map_frame or (amcl_records[0].frame_id if amcl_records else "map")
    # Odometry messages stand in for the odom -> base tf when the bag has no such tf.
    if odometry and tree.parent.get(base_frame) is None:
        for r in odometry:
            tree.add(TransformRecord(r.time, r.frame_id, r.child_frame_id, r.pose))
    # Without a map -> odom tf, /amcl_pose and odometry give it, as amcl computes it:
    # map->odom = pose (+) odom^-1 at the pose's stamp, held until the next pose.
    if amcl_records and tree.parent.get(odom_frame) is None:
        for r in amcl_records:
            o = tree.lookup(odom_frame, base_frame, r.time)
            if o is not None:
                tree.add(TransformRecord(r.time, map_frame, odom_frame,
                                         r.pose.compose(o.inverse())), hold_after=math.inf,
                         steps=True)
    return BagPoses(tree, map_frame, odom_frame, base_frame, amcl, truth)


def bag_observations(path, poses: BagPoses, *, scan_topics=None, laser_mount=None,
                     strict=False, stats=None):
    """Second pass over a bag: each scan with its poses looked up at its stamp."""
    mounts: dict[str, Pose2D] = {}
    tree = poses.tree
    for r in read_bag(path, scan_topics=scan_topics, kinds=("scan",), strict=strict,
                      stats=stats):
        t = r.time
        mount = mounts.get(r.frame_id)
        if mount is None:
            mount = _mount(poses, r, laser_mount)
            mounts[r.frame_id] = mount
        recorded = tree.lookup(poses.map_frame, poses.base_frame, t)
        if recorded is None and tree.parent.get(poses.base_frame) is None:
            recorded = poses.amcl.at(t)  # no odometry to carry the pose: the nearest estimate
        yield Observation(t, r.scan, mount, tree.lookup(poses.odom_frame, poses.base_frame, t),
                          recorded, poses.truth.at(t), topic=r.topic)


def _mount(poses: BagPoses, r: ScanRecord, laser_mount) -> Pose2D:
    if laser_mount is not None:
        return laser_mount
    if r.frame_id == poses.base_frame:
        return Pose2D(0.0, 0.0, 0.0)
    m = poses.tree.lookup(poses.base_frame, r.frame_id, r.time, hold=math.inf)
    if m is None:
        raise LogError(f"no transform from {poses.base_frame!r} to the scan frame "
                       f"{r.frame_id!r} (topic {r.topic}) in the bag's tf; give the laser "
                       "mount (laser_mount)")
    return m


# --- either ------------------------------------------------------------------------------------

@dataclass
class LogObservations:
    """What ``log_observations`` found: the observations (a list, or a generator over a bag's
    scans), their number, the format, what the log offers and what the readers skipped
    (``stats``). ``has``: "recorded" (poses the log gives for the scans, taken to be in the
    map frame), "map_frame" (they are a localisation's, apart from the odometry: see
    ``laser_poses_are_odometry``; a localiser may start at them), "odometry", "truth"."""

    observations: Iterable[Observation]
    total: int
    format: str
    has: dict
    stats: ReadStats


def log_observations(path, *, log_format: str | None = None, strict: bool = False,
                     scan_topics=None, odom_topic=None, pose_topic=None, truth_topic=None,
                     laser_mount: Pose2D | None = None, limits: LogLimits | None = None
                     ) -> LogObservations:
    """The observations of the log at ``path``, in log order (see ``LogObservations``).
    ``limits``: what a CARMEN log may hold, and whether one cut short is read
    (``text_lines.LogLimits``; a bag is read message by message)."""
    if not Path(path).is_dir():
        # a FIFO or a device would block the first read for ever, or never end
        try:
            check_regular_file(path, "log")
        except FileInputError as e:
            raise LogError(str(e)) from None
    fmt = log_format or detect_format(path)
    if fmt not in FORMATS:
        raise LogError(f"log format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    stats = ReadStats()
    if fmt == "carmen":
        observations, has = carmen_observations(path, strict=strict, laser_mount=laser_mount,
                                                stats=stats, limits=limits)
        return LogObservations(observations, len(observations), fmt, has, stats)
    poses = bag_poses(path, odom_topic=odom_topic, pose_topic=pose_topic,
                      truth_topic=truth_topic, strict=strict, stats=stats)
    observations = bag_observations(path, poses, scan_topics=scan_topics,
                                    laser_mount=laser_mount, strict=strict, stats=stats)
    recorded = poses.tree.parent.get(poses.odom_frame) is not None or len(poses.amcl) > 0
    has = {"recorded": recorded, "map_frame": recorded,
           "odometry": poses.tree.parent.get(poses.base_frame) is not None,
           "truth": len(poses.truth) > 0}
    return LogObservations(observations, scan_count(path, scan_topics), fmt, has, stats)
