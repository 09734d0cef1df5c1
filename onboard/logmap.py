"""A first map from a recording with corrected poses: ``mapupdate map --log LOG --out MAP.yaml``.

The same log-odds occupancy mapping that builds M1 in the simulator (``gridmap.mapping``, its
default increments and thresholds), fed every scan of the log at the laser's pose the log
gives: a corrected CARMEN log's laser poses, a bag's ``map -> odom`` tf (or ``/amcl_pose``)
composed with odometry and the laser mount, or the true poses of a simulated session. The map's
frame is the box around every hit point and every laser position, with a margin; cells no beam
reached stay unknown. The result is a map_server YAML + PGM pair, written atomically.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from gridmap import OccupancyGrid, Pose2D, save_map
from gridmap.map_io import MAX_CELLS  # the loader's limit: a map written can be read again
from gridmap.mapping import LogOddsMapper
from robotlogs import LogError, LogLimits, log_observations

MAP_SOURCES = ("recorded", "truth")
MARGIN = 1.0                 # [m] of unknown around the box of hits


@dataclass(frozen=True)
class LogSource:
    """Where the log is and how to read it: ``path`` (a ROS 1 bag, a ROS 2 bag folder or a
    CARMEN log), its ``format`` (None: detected), ``strict`` (a malformed line or message is
    an error instead of a counted skip), the topics of a bag (None: found), ``laser_mount``
    (None: the log's), ``start_time`` / ``end_time`` [s, log time] that limit the scans
    used, and ``limits``: what a CARMEN log may hold, and whether one cut short is read
    (``robotlogs.LogLimits``; None: its defaults)."""

    path: Path
    format: str | None = None
    strict: bool = False
    scan_topics: tuple[str, ...] | None = None
    odom_topic: str | None = None
    pose_topic: str | None = None
    truth_topic: str | None = None
    laser_mount: Pose2D | None = None
    start_time: float | None = None
    end_time: float | None = None
    limits: LogLimits | None = None


def map_from_log(log: LogSource | str | Path, out_path, *, resolution: float = 0.05,
                 pose_source: str = "recorded", params=None, progress: bool = True) -> dict:
    """Build a map from the scans of ``log`` (a path, or a ``LogSource``: the path and how to
    read it, the scans within its ``start_time`` / ``end_time`` [s, log time]) and save it as
    ``out_path``; returns a summary. ``params``: a ``gridmap.mapping.LogOddsParams`` (default:
    the simulator's M1)."""
    log = log if isinstance(log, LogSource) else LogSource(Path(log))
    log_path = log.path
    wall0 = _time.perf_counter()
    if pose_source not in MAP_SOURCES:
        raise LogError(f"the map's poses must be one of {', '.join(MAP_SOURCES)}, got "
                       f"{pose_source!r}")
    if not (isinstance(resolution, (int, float)) and math.isfinite(resolution)
            and 0.005 <= resolution <= 10.0):
        raise LogError(f"--resolution must be a number of metres in [0.005, 10], got "
                       f"{resolution!r}")
    _refuse_clash(log_path, out_path)
    found = log_observations(log_path, log_format=log.format, strict=log.strict,
                             scan_topics=log.scan_topics, odom_topic=log.odom_topic,
                             pose_topic=log.pose_topic, truth_topic=log.truth_topic,
                             laser_mount=log.laser_mount, limits=log.limits)
    if not found.has["recorded" if pose_source == "recorded" else "truth"]:
        raise LogError(f"{log_path}: no {'corrected' if pose_source == 'recorded' else 'true'} "
                       "poses to map with (a map needs a log whose poses are right; a raw log "
                       "can update a map with --poses localizer, not make one)")
    placed = _placed_scans(found, pose_source, (log.start_time, log.end_time))
    if not placed:
        raise LogError(f"{log_path}: no scan with a pose to map (of {found.total}); "
                       f"{found.stats.summary()}")
    frame = map_frame(placed, float(resolution), log_path)
    mapper = LogOddsMapper(frame, params)

    for scan, sensor in tqdm(placed, disable=not progress, unit="scan", leave=False,
                             desc=f"mapping {Path(log_path).name}", dynamic_ncols=True):
        mapper.add_scan(scan, sensor)
    grid = mapper.to_grid()
    save_map(grid, out_path)
    return {"log": str(log_path), "out": str(out_path), "format": found.format,
            "pose_source": pose_source, "scans": found.total, "scans_mapped": len(placed),
            "resolution": frame.resolution, "origin": list(frame.origin),
            "size": [frame.width, frame.height], **grid.counts(),
            "read": found.stats.as_dict(), "read_lines": found.stats.lines(),
            "wall_s": _time.perf_counter() - wall0}


def _placed_scans(found, pose_source: str, window) -> list:
    """(scan, laser pose in the map frame) of every observation that has the pose asked for."""
    first, last = window
    out = []
    for obs in found.observations:
        if (first is not None and obs.time < first) or (last is not None and obs.time > last):
            continue
        if pose_source == "recorded":
            sensor = obs.sensor if obs.sensor is not None else (
                None if obs.recorded is None else obs.recorded.compose(obs.mount))
        else:
            sensor = None if obs.truth is None else obs.truth.compose(obs.mount)
        if sensor is not None and sensor.is_finite():
            out.append((obs.scan, sensor))
    return out


def map_frame(placed, resolution: float, source="log") -> OccupancyGrid:
    """An unknown grid over the box of every hit point (a return within the scan's limits) and
    every laser position, ``MARGIN`` to spare on each side, corners on whole metres."""
    points = []
    for scan, sensor in placed:
        r = scan.ranges.astype(np.float64)
        with np.errstate(invalid="ignore"):
            hit = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
        a = scan.angles()[hit] + sensor.theta
        points.append(np.c_[sensor.x + r[hit] * np.cos(a), sensor.y + r[hit] * np.sin(a)])
        points.append(np.array([[sensor.x, sensor.y]]))
    p = np.concatenate(points)
    lo = np.floor(p.min(axis=0) - MARGIN)
    hi = np.ceil(p.max(axis=0) + MARGIN)
    # counted as floats: a pose of 1e308 m spans more cells than a float holds (inf), and no
    # int can be made of that
    with np.errstate(over="ignore", invalid="ignore"):
        span = hi - lo
        cells = np.ceil(span / resolution - 1e-9)
    if not (np.all(np.isfinite(cells)) and cells[0] * cells[1] <= MAX_CELLS):
        raise LogError(f"{source}: the scans span {span[0]:.6g} m x {span[1]:.6g} m, "
                       f"{cells[0]:.6g} x {cells[1]:.6g} cells at {resolution} m: more than "
                       f"{MAX_CELLS} cells; give a coarser --resolution")
    return OccupancyGrid.empty(int(cells[0]), int(cells[1]), resolution,
                               origin=(float(lo[0]), float(lo[1])))


def _refuse_clash(log_path, out_path) -> None:
    """Neither the map's YAML nor its image may be the log."""
    log = Path(log_path).resolve()
    for path in (Path(out_path), Path(out_path).with_suffix(".pgm")):
        if path.resolve() == log:
            raise LogError(f"{out_path}: the map would overwrite the log {log_path}")
