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

import time as _time
from functools import partial
from pathlib import Path

import numpy as np

from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D
from robotlogs import LogError, Observation, log_observations

from .pipeline import RobotPipeline

POSE_SOURCES = ("auto", "recorded", "localizer", "truth")
# Where the robot starts when the localiser has only a rough idea: std of x, y [m], yaw [rad].
INITIAL_STD = (0.25, 0.25, 0.1)
NO_MOUNT = Pose2D(0.0, 0.0, 0.0)

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
    grid = load_map(map_path)
    found = log_observations(log_path, log_format=log_format, strict=strict,
                             scan_topics=scan_topics, odom_topic=odom_topic,
                             pose_topic=pose_topic, truth_topic=truth_topic,
                             laser_mount=laser_mount)
    source = _choose_source(pose_source, found.has, log_path)
    updater, state_loaded = _updater(grid, updater_config, state_path)
    guard = None
    if pose_check:
        from localization.confidence import PoseCheck

        guard = PoseCheck(updater.reference_map, pose_check_config)
    pipeline = RobotPipeline(updater, pose_check=guard)
    start = partial(_start_localizer, grid, config=localizer_config, initial_pose=initial_pose,
                    initial_std=initial_std, seed=seed) if source == "localizer" else None
    n_read = _replay(pipeline, found, source, start, (start_time, end_time),
                     f"updating from {Path(log_path).name}" if progress else None)
    c = pipeline.counts
    if c.scans == c.scans_without_pose:
        raise LogError(f"{log_path}: no scan could be placed ({n_read} read, "
                       f"{c.scans_without_pose} without a pose); {found.stats.summary()}")
    updated = updater.updated_map()
    save_map(updated, out_path)
    if state_path is not None:
        updater.save(state_path)
    counts = {"scans": n_read, "scans_used": c.scans - c.scans_without_pose,
              **{k: v for k, v in c.as_dict().items() if k != "scans"}}
    return {
        "log": str(log_path), "format": found.format, "map": str(map_path),
        "out": str(out_path), "state": None if state_path is None else str(state_path),
        "state_loaded": state_loaded, "pose_source": source, **counts,
        **_changes(grid, updated), "read": found.stats.as_dict(),
        "wall_s": _time.perf_counter() - wall0,
    }


def _replay(pipeline: RobotPipeline, found, source: str, start_localizer, window,
            progress: str | None) -> int:
    """Feed the log's observations within ``window`` (start, end [s], None for open) to the
    pipeline; the localiser, if the poses are to come from one, starts at the first
    observation with odometry. Returns the number of observations read."""
    from tqdm import tqdm

    first, last = window
    n_read = 0
    with tqdm(total=found.total, disable=progress is None, unit="scan", dynamic_ncols=True,
              desc=progress, leave=False) as bar:
        for obs in found.observations:
            bar.update(1)
            n_read += 1
            if (first is not None and obs.time < first) or (last is not None and obs.time > last):
                continue
            if start_localizer is not None and pipeline.localizer is None \
                    and obs.odom is not None:
                pipeline.localizer = start_localizer(obs)
            pose, mount = _given_pose(obs, source)
            pipeline.step(obs.scan, mount, odometry=obs.odom, pose=pose)
    return n_read


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


def _given_pose(obs: Observation, source: str) -> tuple[Pose2D | None, Pose2D]:
    """(pose, mount): the robot's map-frame pose the log gives (None with the localiser, which
    makes its own) and the laser's mount on it, whose composition, made once, is the laser's
    pose; a log that gives the laser pose itself gives it as the pose, with no mount."""
    if source == "recorded" and obs.sensor is not None:
        return obs.sensor, NO_MOUNT
    if source == "recorded":
        return obs.recorded, obs.mount
    if source == "truth":
        return obs.truth, obs.mount
    return None, obs.mount


def _start_localizer(grid, obs: Observation, *, config, initial_pose, initial_std, seed):
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
    """A fresh updater on ``grid``, or the one saved in ``state_path`` when that exists. A
    state holds its reference map whole, which is its fingerprint: it is refused for any other
    map, and a configuration given with it must be the one it was made with (its buffers
    follow that configuration)."""
    from updater import MapUpdater, UpdaterConfig

    if isinstance(config, dict):
        config = UpdaterConfig.from_dict(config)
    elif isinstance(config, (str, Path)):
        config = UpdaterConfig.from_yaml(config)
    if state_path is None or not Path(state_path).exists():
        return MapUpdater(grid, config), False
    upd = MapUpdater.load(state_path)
    ref = upd.reference_map
    if not ref.same_frame(grid):
        raise LogError(f"{state_path}: the saved updater state belongs to a map of shape "
                       f"{ref.shape} at {ref.resolution} m, origin {ref.origin}; the map "
                       f"given has shape {grid.shape} at {grid.resolution} m, origin "
                       f"{grid.origin}")
    differ = int(np.count_nonzero(ref.data != grid.data))
    if differ:
        raise LogError(f"{state_path}: the saved updater state belongs to another map "
                       f"({differ} cells differ from the map given); give the map it was "
                       "made on, or no --state to start afresh")
    if config is not None and config != upd.config:
        keys = [k for k, v in config.to_dict().items() if upd.config.to_dict().get(k) != v]
        raise LogError(f"{state_path}: the saved updater state was made with another updater "
                       f"configuration ({', '.join(keys)} differ); give the same one or none")
    return upd, True


def _changes(before: OccupancyGrid, after: OccupancyGrid) -> dict:
    a, b = before.data, after.data
    return {"cells_freed": int(((a != FREE) & (b == FREE)).sum()),
            "cells_occupied": int(((a != OCCUPIED) & (b == OCCUPIED)).sum())}
