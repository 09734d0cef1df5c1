"""Update a map from a recording: the updater on a real robot's data, no simulator involved.

The way through: read the log -> the robot's pose at each scan (the recorded localisation, or
this project's localiser run on odometry and scans) -> sensor pose = robot pose composed with
the laser mount, once -> updater -> the output map (written atomically) and, on request, the
updater's state so the next recording continues where this one stopped, and the trajectory the
update used (TUM).

Where the poses come from (``pose_source``):

- ``"recorded"``: a CARMEN log's laser poses (corrected logs carry the SLAM poses; a raw log's
  are dead-reckoned); a bag's ``map -> odom`` tf composed with odometry at scan time, or,
  without that tf, ``/amcl_pose`` carried to scan time by odometry (the ``map -> odom`` amcl
  would have sent).
- ``"localizer"``: :class:`localization.MonteCarloLocalizer` on the map, fed odometry and scans.
  It starts at ``initial_pose`` when one is given; else at the first recorded pose when the log
  has a localisation apart from its odometry (a bag's ``map -> odom`` or ``/amcl_pose``, a
  CARMEN log whose laser poses are not its odometry moved by one mount); else over the whole
  map's free space (global localisation). A :class:`localization.tracking.TrackingMonitor`
  judges it after every filter update: while it has not settled (after a global start) or has
  lost track (an odometry jump), its scans change nothing, and one unsure for long is started
  again over the whole map.
- ``"truth"``: a bag's true pose topic (simulated sessions), a CARMEN log's ``TRUEPOS``.
- ``"auto"``: ``"recorded"`` when the log has poses for its scans and no ``initial_pose`` is
  given, else ``"localizer"``.

What updates the map (``method``): the paper's updater (the default), or ``fuse`` / ``hybrid``
of :mod:`scenarios.methods`, behind the same gate and pose check. Only the paper's updater has
a state to save and load.

Scan times: the gate and the pose smoother need time to pass between scans. A log whose stamps
stay equal from scan to scan, or go back, is given a clock from scan order instead
(:class:`ScanClock`), and the summary says for how many scans.
"""

from __future__ import annotations

import math
import time as _time
from collections import deque
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D
from robotlogs import LogError, Observation, log_observations

from localization.smoothing import MAX_WINDOW, SMOOTH_WINDOW, PoseSmoother

from .methods import ROBOT_METHODS, check_method
from .pipeline import RobotPipeline

POSE_SOURCES = ("auto", "recorded", "localizer", "truth")
# The summary's counts of changed cells (``_changes``), each cell in one of them.
CHANGE_KEYS = ("occupied_to_free", "free_to_occupied", "unknown_to_free", "unknown_to_occupied",
               "known_to_unknown")
# Where the robot starts when the localiser has only a rough idea: std of x, y [m], yaw [rad].
INITIAL_STD = (0.25, 0.25, 0.1)
NO_MOUNT = Pose2D(0.0, 0.0, 0.0)
# The localiser's configuration when none is given: nav2's, but a filter update every 0.1 m
# rather than 0.25 m. A scan placed between updates carries the odometry since the last one,
# and a recording's odometry can lag its scans (on the SENA log by up to 0.2 m at 4 Hz: 0.30 m
# of error at one scan with updates every 0.25 m, 0.17 m with every 0.1 m); a log replays
# far faster than it was recorded, so the extra updates cost little.
LOCALIZER_DEFAULTS = {"update_min_d": 0.1}


class ScanClock:
    """Times for the scans of a log whose stamps do not always increase: all equal (a logger
    that wrote no time, or 0), repeated (stamps coarser than the scan rate), or going back (a
    clock set back while recording).

    ``clock(stamp, lidar)`` once per scan, in log order, gives the time to use. While a lidar's
    stamps increase, its scans keep them (moved by the offset of any earlier repair). A scan
    whose stamp is not later than the lidar's previous one is placed one nominal period after
    the time that previous scan got, and the lidar's later stamps keep that offset, so a jump
    back moves the rest of the log as a whole and no later stamp is repaired for it. The
    nominal period is the median of the lidar's intervals per scan so far (a stamp that
    increases after k repeats of the one before counts its interval over k + 1 scans; the
    last ``keep`` intervals), or ``DEFAULT_PERIOD`` before any. Scans of different lidars may
    share a stamp. Memory: ``keep`` intervals per lidar, whatever the log's length.
    """

    DEFAULT_PERIOD = 1.0     # [s] between scans when the log gives no interval at all

    def __init__(self, keep: int = 1001):
        self.keep = keep
        self._lidars: dict = {}     # lidar -> _LidarTimes
        self.scans = 0              # scans timed
        self.same = 0               # ... whose stamp equals the lidar's previous one
        self.earlier = 0            # ... whose stamp precedes it
        self.period: float | None = None   # [s] the last period a scan was placed with
        self.measured = False       # ... the median of the log's intervals (else the default)

    def __call__(self, stamp: float, lidar="") -> float:
        self.scans += 1
        own = self._lidars.get(lidar)
        if own is None:
            self._lidars[lidar] = _LidarTimes(stamp, deque(maxlen=self.keep))
            return stamp
        last, own.stamp = own.stamp, stamp
        if stamp > last:
            own.intervals.append((stamp - last) / (own.repeats + 1))
            own.repeats = 0
            own.time = stamp + own.offset
            return own.time
        if stamp == last:
            self.same += 1
            own.repeats += 1
        else:
            self.earlier += 1
            own.repeats = 0
        self.measured = bool(own.intervals)
        self.period = float(np.median(own.intervals)) if own.intervals else self.DEFAULT_PERIOD
        own.time += self.period
        own.offset = own.time - stamp
        return own.time

    @property
    def placed(self) -> int:
        """Scans given a time from scan order instead of their stamp."""
        return self.same + self.earlier

    def summary(self) -> dict:
        return {"scans": self.scans, "same_as_before": self.same,
                "earlier_than_before": self.earlier, "period_s": self.period,
                "period_measured": self.measured}


@dataclass
class _LidarTimes:
    """One lidar's side of a :class:`ScanClock`."""

    stamp: float                 # its last stamp, as logged
    intervals: deque             # [s] its recent intervals per scan
    offset: float = 0.0          # [s] added to its stamps since the last repair
    repeats: int = 0             # scans since its stamp last increased, all with that stamp
    time: float = field(init=False)   # [s] the time its last scan got

    def __post_init__(self):
        self.time = self.stamp


@dataclass
class Replay:
    """What the replay loop gathers besides the pipeline's counters."""

    read: int = 0                                        # observations read from the log
    clock: ScanClock = field(default_factory=ScanClock)  # the scans' times
    first_time: float | None = None                      # [s] of the first scan replayed
    times: list = field(default_factory=list)            # [s] of the scans the update used
    poses: list = field(default_factory=list)            # robot poses (x, y, yaw) it used
    start: str = ""                                      # how the localiser started


# --- the replay --------------------------------------------------------------------------------

def update_from_log(map_path, log_path, out_path, state_path=None, *, pose_source: str = "auto",
                    updater_config=None, localizer_config=None, progress: bool = True,
                    log_format: str | None = None, strict: bool = False, scan_topics=None,
                    odom_topic=None, pose_topic=None, truth_topic=None,
                    laser_mount: Pose2D | None = None, initial_pose: Pose2D | None = None,
                    initial_std=INITIAL_STD, start_time: float | None = None,
                    end_time: float | None = None, seed: int = 0,
                    pose_check: bool = False, pose_check_config=None,
                    trajectory_path=None, tracking_config=None,
                    smooth_window: float = SMOOTH_WINDOW, method: str = "paper") -> dict:
    """Update the map at ``map_path`` with the scans of ``log_path``; write ``out_path``.

    With ``state_path``, the updater's state is loaded from it when the file exists (so this
    recording continues the last one) and saved to it at the end. ``start_time`` /
    ``end_time`` [s, log time] limit the scans used. ``pose_check``: scans whose pose the
    scan's own fit to the reference map (and, with the localiser, its covariance) calls unsure
    change nothing (``localization.confidence.PoseCheck``). ``strict``: a malformed log line or
    message is an error instead of a counted skip. ``smooth_window`` [s]: recorded poses of a
    localisation apart from the odometry are smoothed with it over that window
    (``localization.smoothing.PoseSmoother``; 0: used as recorded). ``trajectory_path``: the
    robot pose of each scan the update was given, as it was placed (smoothed, and the pose
    check's refinement where it refined; scans it refused and scans withheld while the
    localiser was not tracking are left out), in TUM format. No ``updater_config``: the robot's
    defaults (``robot_config.ROBOT_UPDATER_DEFAULTS``). ``method``: what updates the map, one
    of ``methods.ROBOT_METHODS``; ``state_path`` only with ``"paper"``. Returns a summary for
    people (``summary_lines``)."""
    from gridmap import load_map

    wall0 = _time.perf_counter()
    check_update_arguments(pose_source, smooth_window, method, state_path)
    _refuse_clashes(log_path, map_path, state_path, out_path, trajectory_path)
    grid = load_map(map_path)
    found = log_observations(log_path, log_format=log_format, strict=strict,
                             scan_topics=scan_topics, odom_topic=odom_topic,
                             pose_topic=pose_topic, truth_topic=truth_topic,
                             laser_mount=laser_mount)
    source = _choose_source(pose_source, found.has, log_path, initial_pose is not None)
    updater, state_loaded = _updater(grid, updater_config, state_path, method)
    pipeline = _pipeline(updater, pose_check, pose_check_config,
                         _smoother(smooth_window, source, found.has))
    starter = None
    if source == "localizer":
        starter = LocalizerStart(grid, localizer_config, initial_pose, initial_std, seed,
                                 found.has["map_frame"], tracking_config, pose_check_config)
    replay = _replay(pipeline, found, source, starter, (start_time, end_time),
                     f"updating from {Path(log_path).name}" if progress else None)
    _check_placed(pipeline, replay, found, log_path)
    updated = _save_outputs(updater, replay, out_path, state_path, trajectory_path)
    return {
        "log": str(log_path), "format": found.format, "map": str(map_path),
        "out": str(out_path), "state": None if state_path is None else str(state_path),
        "state_loaded": state_loaded, "method": method, "pose_source": source,
        **_what_happened(pipeline, replay, found), **_changes(grid, updated),
        "evidence": _evidence(updater),
        "trajectory": None if trajectory_path is None else str(trajectory_path),
        "wall_s": _time.perf_counter() - wall0,
    }


def _what_happened(pipeline: RobotPipeline, replay: Replay, found) -> dict:
    """The summary's account of the scans: read, used, the pipeline's counters, their times,
    what the readers skipped, the localiser's and the smoother's doings."""
    c = pipeline.counts
    return {"scans": replay.read,
            "scans_used": c.scans - c.scans_without_pose - c.scans_not_tracking,
            **{k: v for k, v in c.as_dict().items() if k != "scans"},
            "timestamps": replay.clock.summary(), "read": found.stats.as_dict(),
            "read_lines": found.stats.lines(), "tracking": _tracking_summary(pipeline, replay),
            "smoothing": _smoothing_summary(pipeline.smoother)}


def check_update_arguments(pose_source, smooth_window, method="paper", state_path=None
                           ) -> None:
    """Refuse arguments that cannot go together, before anything is read."""
    check_method(method, "--method", ROBOT_METHODS)
    if state_path is not None and method != "paper":
        raise LogError(f"--state {state_path}: only the paper's updater has a state to save and "
                       f"load, --method {method} has none; leave out --state or use --method "
                       "paper")
    if pose_source not in POSE_SOURCES:
        raise LogError(f"pose_source must be one of {', '.join(POSE_SOURCES)}, "
                       f"got {pose_source!r}")
    if isinstance(smooth_window, bool) or not isinstance(smooth_window, (int, float)) \
            or not 0 <= smooth_window <= MAX_WINDOW:
        raise LogError(f"the smoothing window must be 0 (off) to {MAX_WINDOW:g} s, got "
                       f"{smooth_window!r}")


def _smoother(window: float, source: str, has: dict) -> PoseSmoother | None:
    """The smoother of recorded poses: only for a localisation apart from the odometry."""
    if window > 0 and source == "recorded" and has["map_frame"] and has["odometry"]:
        return PoseSmoother(window)
    return None


def _smoothing_summary(smoother: PoseSmoother | None) -> dict:
    if smoother is None:
        return {"window_s": 0.0, "scans_smoothed": 0, "restarts": 0}
    return {"window_s": smoother.window, "scans_smoothed": smoother.smoothed,
            "restarts": smoother.restarts}


def _pipeline(updater, pose_check: bool, pose_check_config, smoother=None) -> RobotPipeline:
    guard = None
    if pose_check:
        from localization.confidence import PoseCheck

        guard = PoseCheck(updater.reference_map, pose_check_config)
    return RobotPipeline(updater, pose_check=guard, smoother=smoother)


def _save_outputs(updater, replay: Replay, out_path, state_path, trajectory_path):
    """The updated map (returned), and the state and trajectory when asked, each atomically."""
    from gridmap import save_map

    updated = updater.updated_map()
    save_map(updated, out_path)
    if state_path is not None:
        updater.save(state_path)
    if trajectory_path is not None:
        from .report import write_tum

        write_tum(Path(trajectory_path), np.asarray(replay.times),
                  np.asarray(replay.poses).reshape(-1, 3))
    return updated


def _replay(pipeline: RobotPipeline, found, source: str, starter, window,
            progress: str | None) -> Replay:
    """Feed the log's observations within ``window`` (start, end [s], None for open) to the
    pipeline; the localiser, if the poses are to come from one, starts at the first
    observation with odometry. Returns what the update used."""
    from tqdm import tqdm

    first, last = window
    out = Replay()
    with tqdm(total=found.total, disable=progress is None, unit="scan", dynamic_ncols=True,
              desc=progress, leave=False) as bar:
        for obs in found.observations:
            bar.update(1)
            out.read += 1
            if (first is not None and obs.time < first) or (last is not None and obs.time > last):
                continue
            t = out.clock(obs.time, obs.topic)
            if t != obs.time:
                obs = replace(obs, time=t, scan=replace(obs.scan, time=t))
            if starter is not None and pipeline.localizer is None and obs.odom is not None:
                pipeline.localizer, pipeline.tracking = starter.start(obs)
                out.start = starter.how
            if out.first_time is None:
                out.first_time = obs.time
            pose, mount = _given_pose(obs, source, pipeline.smoother is not None)
            step = pipeline.step(obs.scan, mount, odometry=obs.odom, pose=pose)
            _note_pose(out, obs, step, mount)
    return out


def _note_pose(out: Replay, obs: Observation, step, mount: Pose2D) -> None:
    """Record the robot pose the update placed the scan at (refined or not), unless the scan
    changed nothing because its pose was refused or withheld."""
    from updater import ScanStatus

    if step.report is None or step.report.status is ScanStatus.REFUSED:
        return
    robot = step.sensor_pose.compose(mount.inverse())
    if mount is NO_MOUNT:            # the log gave the laser's pose: back to the robot's
        robot = robot.compose(obs.mount.inverse())
    out.times.append(obs.time)
    out.poses.append((robot.x, robot.y, robot.theta))


def _check_placed(pipeline: RobotPipeline, replay: Replay, found, log_path) -> None:
    """Refuse a replay that placed no scan at all: every scan without a pose, or a global
    localisation that never settled (then nothing is written)."""
    c = pipeline.counts
    if c.scans and c.scans == c.scans_without_pose:
        raise LogError(f"{log_path}: no scan could be placed ({replay.read} read, "
                       f"{c.scans_without_pose} without a pose); {found.stats.summary()}")
    monitor = pipeline.tracking
    if monitor is not None and monitor.never_tracked:
        doubt = monitor.doubt(pipeline.localizer.estimate()) or "its scans fit a pose nearby " \
                                                                "better"
        raise LogError(f"{log_path}: the localiser ({replay.start}) never settled on a pose in "
                       f"the {c.scans} scans ({c.localizer_updates} filter updates; at the end "
                       f"{doubt}); give the start with --initial-pose X Y YAW")


def _choose_source(asked: str, has: dict, log_path, start_given: bool = False) -> str:
    """The pose source to use: ``asked``, or for "auto" the recorded poses when the log has
    them and no start was given for the localiser."""
    if asked == "auto":
        asked = "recorded" if has["recorded"] and not start_given else "localizer"
    if start_given and asked != "localizer":
        raise LogError(f"a start pose is for the localiser (--poses localizer), not for "
                       f"--poses {asked}")
    if asked == "recorded" and not has["recorded"]:
        raise LogError(f"{log_path}: no recorded localisation (map -> odom tf, pose topic or "
                       "corrected laser poses); use the localiser")
    if asked == "localizer" and not has["odometry"]:
        raise LogError(f"{log_path}: no odometry, which the localiser needs")
    if asked == "truth" and not has["truth"]:
        raise LogError(f"{log_path}: no true poses (ground-truth topic or TRUEPOS lines)")
    return asked


def _given_pose(obs: Observation, source: str, smoothed: bool = False
                ) -> tuple[Pose2D | None, Pose2D]:
    """(pose, mount): the robot's map-frame pose the log gives (None with the localiser, which
    makes its own) and the laser's mount on it, whose composition, made once, is the laser's
    pose; a log that gives the laser pose itself gives it as the pose, with no mount, unless
    the pose is to be ``smoothed`` with the odometry, which moves the robot, not the laser."""
    if source == "recorded" and smoothed and obs.odom is not None:
        return obs.recorded, obs.mount
    if source == "recorded" and obs.sensor is not None:
        return obs.sensor, NO_MOUNT
    if source == "recorded":
        return obs.recorded, obs.mount
    if source == "truth":
        return obs.truth, obs.mount
    return None, obs.mount


class LocalizerStart:
    """Starts the localiser at the first observation with odometry: at ``initial_pose``, else
    at the observation's recorded pose when the log's poses are a localisation
    (``map_frame``), else over the whole map. ``how`` says which, for the summary."""

    def __init__(self, grid, config, initial_pose, initial_std, seed, map_frame,
                 tracking_config=None, pose_check_config=None):
        from localization import LocalizerConfig

        if config is None:
            config = LocalizerConfig(**LOCALIZER_DEFAULTS)
        elif isinstance(config, dict):
            config = LocalizerConfig.from_dict(config)
        elif isinstance(config, (str, Path)):
            config = LocalizerConfig.from_yaml(config)
        if initial_pose is not None and not (isinstance(initial_pose, Pose2D)
                                             and initial_pose.is_finite()):
            raise LogError(f"the initial pose must be three finite numbers X Y YAW, got "
                           f"{initial_pose!r}")
        self.grid, self.config, self.seed = grid, config, seed
        self.initial_pose, self.initial_std, self.map_frame = initial_pose, initial_std, map_frame
        self.tracking_config, self.pose_check_config = tracking_config, pose_check_config
        self.how = ""

    def start(self, obs: Observation):
        """(localiser, its tracking monitor)."""
        from localization import MonteCarloLocalizer
        from localization.tracking import TrackingMonitor

        loc = MonteCarloLocalizer(self.grid, self.config, seed=self.seed)
        pose = self.initial_pose or (obs.recorded if self.map_frame else None)
        monitor = TrackingMonitor(self.grid, self.tracking_config, self.pose_check_config,
                                  converging=pose is None)
        if pose is None:
            monitor.start_global(loc, obs.time, "no start given, and the log's poses are "
                                                "not a localisation in the map")
            self.how = f"started over the whole map, {loc.particle_count} particles"
        else:
            loc.initialize(pose, np.diag(np.square(np.asarray(self.initial_std, np.float64))))
            self.how = "started at the given pose" if self.initial_pose else \
                "started at the first recorded pose"
        return loc, monitor


def _tracking_summary(pipeline: RobotPipeline, replay: Replay) -> dict | None:
    monitor = pipeline.tracking
    if monitor is None:
        return None
    t0 = replay.first_time or 0.0
    return {"start": replay.start, "state": monitor.state.value, "restarts": monitor.restarts,
            "events": [{"time": e.time, "after": e.time - t0, "state": e.state.value,
                        "reason": e.reason} for e in monitor.events]}


def _refuse_clashes(log_path, map_path, state_path, out_path, trajectory_path) -> None:
    """The trajectory must not land on an input or on another output (the map's YAML and
    image, the state)."""
    if trajectory_path is None:
        return
    taken = {"--log": log_path, "--map": map_path, "--state": state_path, "--out": out_path,
             "--out's image": Path(out_path).with_suffix(".pgm")}
    mine = Path(trajectory_path).resolve()
    for name, path in taken.items():
        if path is not None and Path(path).resolve() == mine:
            raise LogError(f"{trajectory_path}: the trajectory would overwrite {name}; give "
                           "it a path of its own")


def _updater(grid: OccupancyGrid, config, state_path, method: str = "paper"
             ) -> tuple[object, bool]:
    """A fresh ``method`` on ``grid`` (with ``config``, else with the robot's defaults,
    ``robot_config.ROBOT_UPDATER_DEFAULTS``; the baselines use its gate), or the paper's
    updater saved in ``state_path`` when that exists. A state holds its reference map whole,
    which is its fingerprint: it is refused for any other map, and a configuration given with
    it must be the one it was made with (its buffers follow that configuration)."""
    from updater import MapUpdater, UpdaterConfig

    from .methods import make_method
    from .robot_config import ROBOT_UPDATER_DEFAULTS

    if isinstance(config, dict):
        config = UpdaterConfig.from_dict(config)
    elif isinstance(config, (str, Path)):
        config = UpdaterConfig.from_yaml(config)
    if state_path is None or not Path(state_path).exists():
        config = config or UpdaterConfig(**ROBOT_UPDATER_DEFAULTS)
        return make_method(method, grid, config), False
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
    """The cells the output changed, by what they were and what they are now.
    ``cells_freed`` / ``cells_occupied``: every cell now free / occupied that was not (an
    unknown cell made known included)."""
    a, b = before.data, after.data

    def count(was, now) -> int:
        return int(np.count_nonzero(was & now))

    out = {"occupied_to_free": count(a == OCCUPIED, b == FREE),
           "free_to_occupied": count(a == FREE, b == OCCUPIED),
           "unknown_to_free": count(a == UNKNOWN, b == FREE),
           "unknown_to_occupied": count(a == UNKNOWN, b == OCCUPIED),
           "known_to_unknown": count(a != UNKNOWN, b == UNKNOWN)}
    out["cells_freed"] = out["occupied_to_free"] + out["unknown_to_free"]
    out["cells_occupied"] = out["free_to_occupied"] + out["unknown_to_occupied"]
    return out


def _evidence(updater) -> dict | None:
    """Cells whose evidence of change stayed below the threshold (``pending_cells``, of them
    ``pending_few_observations`` seen by fewer than ``threshold`` processed scans and
    ``pending_outvoted`` outvoted), for a method that keeps such evidence; else None."""
    summary = getattr(updater, "evidence_summary", None)
    if summary is None:
        return None
    return {**summary(), "threshold": int(updater.config.threshold)}


# --- the summary, for people --------------------------------------------------------------------

def summary_lines(s: dict) -> list[str]:
    """The summary of ``update_from_log`` as lines for the command line: the map written and
    its cells changed by kind, the scans and what became of them, what the readers skipped
    (one line per kind), the gate's refusals by rule, the evidence of change left below the
    threshold, how the localiser fared, warnings. When no cell changed, a line says why."""
    g = s.get
    changed = sum(g(k, 0) for k in CHANGE_KEYS)
    used = f"method {g('method', 'paper')}, poses {g('pose_source')}"
    out = [f"wrote {g('out')}: {_changes_text(s) if changed else '0 cells changed'}; {used}"]
    skipped = sum((g("read") or {}).get("skipped", {}).values())
    out.append(f"  {g('scans', 0)} scans read" + (f" ({skipped} lines or messages of the log "
                                                   "skipped, below)" if skipped else "")
               + f", {g('scans_used', g('scans', 0))} used; {g('scans_processed', 0)} "
               f"processed past the gate, {g('scans_dropped_as_lost', 0)} dropped as lost, "
               f"{g('scans_refused_by_pose_check', 0)} refused by the pose check"
               + (f", {g('scans_off_map')} off the map" if g("scans_off_map") else ""))
    out += [f"  {line}" for line in g("read_lines") or []]
    if not changed:
        out.append(f"  0 cells changed: {_why_unchanged(s)}")
    else:
        out += [f"  {part}" for part in (_gate_text(s), _pending_text(s)) if part]
    smooth = g("smoothing") or {}
    if smooth.get("scans_smoothed"):
        out.append(f"  {smooth['scans_smoothed']} recorded poses jittered against the odometry "
                   f"and were smoothed over {smooth['window_s']:g} s (--smooth-poses 0: as "
                   f"recorded)" + (f"; {smooth['restarts']} jumps of the localisation restarted "
                                   f"the smoothing" if smooth.get("restarts") else ""))
    out += [f"  warning: {w}" for w in _warnings(s)]
    track = g("tracking")
    if track:
        out.append(f"  localiser: {track['start']}")
        out += [f"  localiser {e['state']} {e['after']:.1f} s into the log: {e['reason']}"
                for e in track["events"]]
        if g("scans_not_tracking"):
            out.append(f"  warning: {g('scans_not_tracking')} scans were not used: the "
                       "localiser was not tracking")
    if g("trajectory"):
        out.append(f"  wrote {g('trajectory')} (TUM)")
    return out


def _changes_text(s: dict) -> str:
    """"12 occupied cells freed, 40 free cells occupied, 8795 unknown cells now known (8790
    free, 5 occupied)"."""
    g = s.get
    known = g("unknown_to_free", 0) + g("unknown_to_occupied", 0)
    text = (f"{g('occupied_to_free', 0)} occupied cells freed, {g('free_to_occupied', 0)} free "
            f"cells occupied, {known} unknown cells now known ({g('unknown_to_free', 0)} free, "
            f"{g('unknown_to_occupied', 0)} occupied)")
    if g("known_to_unknown"):
        text += f", {g('known_to_unknown')} known cells now unknown"
    return text


def _gate_text(s: dict, brief: bool = False) -> str:
    """"the gate refused 380 of 406 scans: fast turn 300, no motion 80" ("" when it refused
    none); ``brief``: the rules in parentheses."""
    gated = s.get("scans_gated", 0)
    if not gated:
        return ""
    rules = sorted((s.get("gated_by") or {}).items(), key=lambda kv: (-kv[1], kv[0]))
    listed = ", ".join(f"{rule} {n}" for rule, n in rules)
    head = f"the gate refused {gated} of {s.get('scans_used', gated)} scans"
    text = f"{head} ({listed})" if brief else f"{head}: {listed}"
    if s.get("scans_confirming"):
        text += (f"; {s['scans_confirming']} of them, views already taken, confirmed the "
                 "map's surfaces")
    return text


def _pending_text(s: dict, brief: bool = False) -> str:
    """The cells whose evidence of change stayed below the threshold ("" for none, or for a
    method that keeps no such evidence)."""
    e = s.get("evidence")
    if not e or not e.get("pending_cells"):
        return ""
    head = f"{e['pending_cells']} cells collected evidence of change below the threshold"
    if e.get("pending_few_observations") is None:      # the updater did not count flags
        return head
    few = f"{e['pending_few_observations']} seen by fewer than {e['threshold']} processed scans"
    if brief:
        return f"{head} ({few})"
    return f"{head}: {few}, {e['pending_outvoted']} outvoted by scans that saw them unchanged"


def _why_unchanged(s: dict) -> str:
    """Why the output changed no cell: the evidence left below the threshold and the scans
    that never reached the map, each counted."""
    g = s.get
    why = [part for part in (_pending_text(s, brief=True), _gate_text(s, brief=True)) if part]
    for key, text in (("scans_refused_by_pose_check", "the pose check refused {} scans"),
                      ("scans_dropped_as_lost", "the lost check dropped {} scans"),
                      ("scans_off_map", "{} scans lay off the map"),
                      ("scans_not_tracking", "{} scans came while the localiser was not "
                                             "tracking")):
        if g(key):
            why.append(text.format(g(key)))
    processed = g("scans_processed", 0)
    if not processed:
        why.insert(0, "no scan was processed")
    elif not why:
        why.append(f"the {processed} scans processed found no evidence of change"
                   if g("evidence") is not None else
                   f"the {processed} scans processed gave no cell evidence enough to change it")
    return "; ".join(why)


def _warnings(s: dict) -> list[str]:
    """What a user should look at: scans whose poses disagree with the map, mostly, and stamps
    that do not tell time."""
    g = s.get
    asked = g("scans_processed", 0) + g("scans_refused_by_pose_check", 0)
    stamps = _stamps_text(g("timestamps"))
    out = [stamps] if stamps else []
    if asked and g("scans_refused_by_pose_check", 0) > 0.5 * asked:
        out.append(f"the pose check refused {g('scans_refused_by_pose_check')} of the {asked} "
                   "scans past the gate: their poses disagree with the map (drifted odometry? "
                   "try --poses localizer)")
    if g("format") in ("ros1", "ros2") and (g("timestamps") or {}).get("earlier_than_before"):
        out.append("the bag's clock went back: tf and odometry are looked up at the scans' "
                   "stamps, which now stand for two moments of the recording, so scans may be "
                   "placed at poses of the other; check the trajectory (--trajectory)")
    if g("scans_processed", 0) and g("scans_dropped_as_lost", 0) > 0.5 * g("scans_processed"):
        out.append(f"the lost check dropped {g('scans_dropped_as_lost')} of the "
                   f"{g('scans_processed')} scans processed: most beams disagree with the map "
                   "there (wrong poses, or a place the map does not cover)")
    return out


def _stamps_text(t: dict | None) -> str:
    """"404 of 406 scans have the same timestamp as the scan before; ...", or "" when every
    stamp increased."""
    if not t or not (t["same_as_before"] or t["earlier_than_before"]):
        return ""
    same, earlier, n = t["same_as_before"], t["earlier_than_before"], t["scans"]
    if same and earlier:
        what = f"{same} of {n} scans have the same timestamp as the scan before and {earlier} " \
               "an earlier one"
    elif same:
        what = f"{same} of {n} scans have the same timestamp as the scan before"
    else:
        what = f"{earlier} of {n} scans have an earlier timestamp than the scan before"
    period = "the median interval between the log's scans" if t["period_measured"] else \
        "the log gives no interval between its scans"
    return f"{what}; their times were taken from scan order, {t['period_s']:g} s after the " \
           f"scan before ({period}), for the gate and the pose smoothing"


def parse_pose(values) -> Pose2D:
    """``X Y YAW`` [m, m, rad] from the command line as a finite pose."""
    try:
        x, y, yaw = (float(v) for v in values)
    except (TypeError, ValueError):
        x = y = yaw = math.nan
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise LogError(f"--initial-pose must be three finite numbers X Y YAW, got "
                       f"{' '.join(map(str, values))}")
    return Pose2D(x, y, yaw)
