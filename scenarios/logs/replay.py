"""Update a map from a recording: the updater on a real robot's data, no simulator involved.

The way through: read the log -> the robot's pose at each scan (the recorded localisation, or
this project's localiser run on odometry and scans) -> sensor pose = robot pose composed with
the laser mount, once -> updater -> the output map (written atomically) and, on request, the
updater's state so the next recording continues where this one stopped.

Where the poses come from (``pose_source``):

- ``"recorded"``: a CARMEN log's laser poses (corrected logs carry the SLAM poses); a bag's
  ``map -> odom`` tf composed with odometry at scan time, or, without that tf, ``/amcl_pose``
  carried to scan time by odometry (the ``map -> odom`` amcl would have sent).
- ``"localizer"``: :class:`localization.MonteCarloLocalizer` on the map, fed odometry and scans,
  started at ``initial_pose`` (default: the first recorded pose, else the first odometry pose).
- ``"truth"``: a bag's true pose topic (simulated sessions), a CARMEN log's ``TRUEPOS``.
- ``"auto"``: ``"recorded"`` when the log has a localisation, else ``"localizer"``.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D, Scan

from .carmen import read_carmen
from .frames import PoseTimeline, TransformTree
from .records import LogError, OdomRecord, PoseRecord, ReadStats, ScanRecord, TransformRecord
from .rosbag import bag_topics, read_bag, resolve_topics, scan_count

POSE_SOURCES = ("auto", "recorded", "localizer", "truth")
FORMATS = ("carmen", "ros1", "ros2")
# Where the robot starts when the localiser has only a rough idea: std of x, y [m], yaw [rad].
INITIAL_STD = (0.25, 0.25, 0.1)
NO_MOUNT = Pose2D(0.0, 0.0, 0.0)


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
    if b"\x00" in head or not _is_text(head):
        raise LogError(f"{p}: neither a ROS bag nor a CARMEN text log")
    return "carmen"


def _is_text(head: bytes) -> bool:
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as e:
        return e.start >= len(head) - 3  # a multi-byte character cut off by the 4 KB read
    return True


# --- observations from a CARMEN log ------------------------------------------------------------

def carmen_observations(path, *, strict: bool = False, laser_mount: Pose2D | None = None,
                        stats: ReadStats | None = None) -> tuple[list[Observation], dict]:
    """The scans of a CARMEN log with their poses, and what the log offers (``has``).

    The laser line's ``x y theta`` is the laser's pose (recorded localisation in corrected
    logs) and ``odom_*`` the robot's odometry; the mount is their difference (in raw logs the
    front-laser offset), unless ``laser_mount`` is given.
    """
    log = read_carmen(path, strict=strict)
    if stats is not None:
        stats.skipped.update(log.stats.skipped)
        stats.ignored.update(log.stats.ignored)
        stats.problems.extend(log.stats.problems)
    truth = PoseTimeline()
    odom = PoseTimeline()
    for r in log.records:
        if isinstance(r, PoseRecord):
            truth.add(r.time, r.pose)
        elif isinstance(r, OdomRecord):
            odom.add(r.time, r.pose)
    out = []
    for r in log.scans():
        robot_odom = r.odom_pose if r.odom_pose is not None else odom.at(r.time)
        if laser_mount is not None:
            mount = laser_mount
        elif r.laser_pose is not None and r.odom_pose is not None:
            mount = r.laser_pose.relative_to(r.odom_pose)
        else:
            mount = Pose2D(0.0, 0.0, 0.0)
        recorded = None if r.laser_pose is None else r.laser_pose.compose(mount.inverse())
        out.append(Observation(r.time, r.scan, mount, robot_odom, recorded, truth.at(r.time),
                               sensor=r.laser_pose))
    has = {"recorded": any(o.sensor is not None for o in out),
           "odometry": any(o.odom is not None for o in out), "truth": len(truth) > 0}
    return out, has


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
                                         r.pose.compose(o.inverse())), hold_after=math.inf)
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
                          recorded, poses.truth.at(t))


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


# --- the replay --------------------------------------------------------------------------------

def update_from_log(map_path, log_path, out_path, state_path=None, *, pose_source: str = "auto",
                    updater_config=None, localizer_config=None, progress: bool = True,
                    log_format: str | None = None, strict: bool = False, scan_topics=None,
                    odom_topic=None, pose_topic=None, truth_topic=None,
                    laser_mount: Pose2D | None = None, initial_pose: Pose2D | None = None,
                    initial_std=INITIAL_STD, start_time: float | None = None,
                    end_time: float | None = None, seed: int = 0,
                    pose_check: bool = False, pose_check_config=None) -> dict:
    """Update the map at ``map_path`` with the scans of ``log_path``; write ``out_path``.

    With ``state_path``, the updater's state is loaded from it when the file exists (so this
    recording continues the last one) and saved to it at the end. ``start_time`` /
    ``end_time`` [s, log time] limit the scans used. ``pose_check``: scans whose pose the
    scan's own fit to the reference map (and, with the localiser, its covariance) calls unsure
    change nothing (``localization.confidence.PoseCheck``). Returns a summary (counts, the pose
    source used, what was skipped, cells changed, wall time).
    """
    from gridmap import load_map, save_map

    wall0 = _time.perf_counter()
    if pose_source not in POSE_SOURCES:
        raise LogError(f"pose_source must be one of {', '.join(POSE_SOURCES)}, "
                       f"got {pose_source!r}")
    fmt = log_format or detect_format(log_path)
    if fmt not in FORMATS:
        raise LogError(f"log format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    grid = load_map(map_path)
    stats = ReadStats()
    if fmt == "carmen":
        observations, has = carmen_observations(log_path, strict=strict,
                                                laser_mount=laser_mount, stats=stats)
        total = len(observations)
    else:
        poses = bag_poses(log_path, odom_topic=odom_topic, pose_topic=pose_topic,
                          truth_topic=truth_topic, strict=strict, stats=stats)
        observations = bag_observations(log_path, poses, scan_topics=scan_topics,
                                        laser_mount=laser_mount, strict=strict, stats=stats)
        total = scan_count(log_path, scan_topics)
        has = {"recorded": poses.tree.parent.get(poses.odom_frame) is not None
               or len(poses.amcl) > 0,
               "odometry": poses.tree.parent.get(poses.base_frame) is not None,
               "truth": len(poses.truth) > 0}
    source = _choose_source(pose_source, has, log_path)

    updater, state_loaded = _updater(grid, updater_config, state_path)
    counts = {"scans": 0, "scans_used": 0, "scans_without_pose": 0, "scans_processed": 0,
              "scans_dropped_as_lost": 0, "scans_refused_by_pose_check": 0,
              "localizer_updates": 0}
    guard = None
    if pose_check:
        from localization.confidence import PoseCheck

        guard = PoseCheck(updater.reference_map, pose_check_config)
    localizer = None
    from tqdm import tqdm

    with tqdm(total=total, disable=not progress, unit="scan", dynamic_ncols=True,
              desc=f"updating from {Path(log_path).name}", leave=False) as bar:
        for obs in observations:
            bar.update(1)
            counts["scans"] += 1
            if (start_time is not None and obs.time < start_time) or \
                    (end_time is not None and obs.time > end_time):
                continue
            if source == "localizer" and localizer is None and obs.odom is not None:
                localizer = _start_localizer(grid, obs, localizer_config, initial_pose,
                                             initial_std, seed)
            posed = _robot_pose(obs, source, localizer, counts)
            if posed is None:
                counts["scans_without_pose"] += 1
                continue
            robot, mount = posed
            sensor = robot.compose(mount)
            counts["scans_used"] += 1
            check = None
            if guard is not None:
                cov = localizer.estimate().cov if source == "localizer" else None
                check = partial(guard.for_updater, obs.scan, robot, mount, cov)
            report = updater.process(obs.scan, sensor, odometry=obs.odom, pose_check=check)
            counts["scans_processed"] += bool(report.processed)
            counts["scans_refused_by_pose_check"] += report.reason.startswith("pose unsure")
            counts["scans_dropped_as_lost"] += bool(report.dropped_as_lost)
    if counts["scans_used"] == 0:
        raise LogError(f"{log_path}: no scan could be placed ({counts['scans']} read, "
                       f"{counts['scans_without_pose']} without a pose); {stats.summary()}")

    updated = updater.updated_map()
    save_map(updated, out_path)
    if state_path is not None:
        updater.save(state_path)
    return {
        "log": str(log_path), "format": fmt, "map": str(map_path), "out": str(out_path),
        "state": None if state_path is None else str(state_path), "state_loaded": state_loaded,
        "pose_source": source, **counts, **_changes(grid, updated),
        "read": stats.as_dict(), "wall_s": _time.perf_counter() - wall0,
    }


def _choose_source(asked: str, has: dict, log_path) -> str:
    if asked == "auto":
        asked = "recorded" if has["recorded"] else "localizer"
    if asked == "recorded" and not has["recorded"]:
        raise LogError(f"{log_path}: no recorded localisation (map -> odom tf, pose topic or "
                       "corrected laser poses); use the localiser")
    if asked == "localizer" and not has["odometry"]:
        raise LogError(f"{log_path}: no odometry, which the localiser needs")
    if asked == "truth" and not has["truth"]:
        raise LogError(f"{log_path}: no true poses (ground-truth topic or TRUEPOS lines)")
    return asked


def _robot_pose(obs: Observation, source: str, localizer, counts: dict
                ) -> tuple[Pose2D, Pose2D] | None:
    """(pose, mount): the robot's pose in the map frame and the laser's mount on it, whose
    composition, made once, is the laser's pose; a log that gives the laser pose itself gives
    it as the pose, with no mount."""
    if source == "recorded":
        if obs.sensor is not None:
            return obs.sensor, NO_MOUNT
        return None if obs.recorded is None else (obs.recorded, obs.mount)
    if source == "truth":
        return None if obs.truth is None else (obs.truth, obs.mount)
    if obs.odom is None or localizer is None:
        return None
    counts["localizer_updates"] += bool(localizer.update(obs.odom, obs.scan, obs.mount))
    return localizer.estimate().pose_at(obs.odom), obs.mount


def _start_localizer(grid, obs: Observation, config, initial_pose, initial_std, seed):
    from localization import LocalizerConfig, MonteCarloLocalizer

    if isinstance(config, dict):
        config = LocalizerConfig.from_dict(config)
    elif isinstance(config, (str, Path)):
        config = LocalizerConfig.from_yaml(config)
    start = initial_pose or obs.recorded or obs.odom
    if start is None:
        raise LogError("the localiser needs a starting pose (initial_pose)")
    loc = MonteCarloLocalizer(grid, config, seed=seed)
    loc.initialize(start, np.diag(np.square(np.asarray(initial_std, np.float64))))
    return loc


def _updater(grid: OccupancyGrid, config, state_path) -> tuple[object, bool]:
    from updater import MapUpdater, UpdaterConfig

    if state_path is not None and Path(state_path).exists():
        upd = MapUpdater.load(state_path)
        ref = upd.reference_map
        if not ref.same_frame(grid):
            raise LogError(f"{state_path}: the saved updater state belongs to a map of shape "
                           f"{ref.shape} at {ref.resolution} m, origin {ref.origin}; the map "
                           f"given has shape {grid.shape} at {grid.resolution} m, origin "
                           f"{grid.origin}")
        return upd, True
    if isinstance(config, dict):
        config = UpdaterConfig.from_dict(config)
    elif isinstance(config, (str, Path)):
        config = UpdaterConfig.from_yaml(config)
    return MapUpdater(grid, config), False


def _changes(before: OccupancyGrid, after: OccupancyGrid) -> dict:
    a, b = before.data, after.data
    return {"cells_freed": int(((a != FREE) & (b == FREE)).sum()),
            "cells_occupied": int(((a != OCCUPIED) & (b == OCCUPIED)).sum())}
