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
of :mod:`onboard.methods`, behind the same gate and pose check. Only the paper's updater has
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
from tqdm import tqdm

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, load_map, save_map
from gridmap.config import DEFAULT_PROFILE
from localization import LocalizerConfig, MonteCarloLocalizer
from localization.confidence import PoseCheck, PoseCheckConfig
from localization.smoothing import MAX_WINDOW, SMOOTH_WINDOW, PoseSmoother
from localization.tracking import TrackingMonitor
from robotlogs import LogError, Observation, log_observations
from robotlogs.tum import write_tum
from updater import MapUpdater, ScanStatus, UpdaterConfig

from .logmap import LogSource
from .methods import ROBOT_METHODS, check_method, make_method
from .pipeline import RobotPipeline, Step
from .robot_config import POSE_CHECK_ON

POSE_SOURCES = ("auto", "recorded", "localizer", "truth")
# The summary's counts of changed cells (``_changes``), each cell in one of them.
CHANGE_KEYS = ("occupied_to_free", "free_to_occupied", "unknown_to_free", "unknown_to_occupied",
               "known_to_unknown")
# Where the robot starts when the localiser has only a rough idea: std of x, y [m], yaw [rad].
INITIAL_STD = (0.25, 0.25, 0.1)
NO_MOUNT = Pose2D(0.0, 0.0, 0.0)


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

@dataclass(frozen=True)
class Placement:
    """How scans are placed on the map. ``source``: where the poses come from (``POSE_SOURCES``,
    the module's docstring). ``initial_pose`` / ``initial_std`` / ``seed``: the localiser's
    start. ``smooth_window`` [s]: recorded poses of a localisation apart from the odometry are
    smoothed with it over that window (``localization.smoothing.PoseSmoother``; 0: as
    recorded). ``pose_check``: scans whose pose the scan's own fit to the reference map (and,
    with the localiser, its covariance) calls unsure change nothing
    (``localization.confidence.PoseCheck``; None: as ``profile`` has it). The configurations:
    None for the profile's (``onboard.robot_config``)."""

    source: str = "auto"
    initial_pose: Pose2D | None = None
    initial_std: tuple[float, float, float] = INITIAL_STD
    seed: int = 0
    smooth_window: float = SMOOTH_WINDOW
    pose_check: bool | None = None
    profile: str = DEFAULT_PROFILE
    localizer_config: object | None = None       # localization.LocalizerConfig
    pose_check_config: object | None = None      # localization.confidence.PoseCheckConfig
    tracking_config: object | None = None        # localization.tracking.TrackingConfig


@dataclass(frozen=True)
class Outputs:
    """What to write: the updated map (``map``, a map_server YAML and its image); the updater's
    ``state``, loaded first when the file exists (so this recording continues the last one)
    and saved at the end; the ``trajectory``: the robot pose of each scan the update was given,
    as it was placed (smoothed, refined by the pose check where it refined; scans it refused or
    withheld while the localiser was not tracking left out), in TUM format."""

    map: Path
    state: Path | None = None
    trajectory: Path | None = None


def update_from_log(map_path, log: LogSource, outputs: Outputs,
                    placement: Placement = Placement(), *, method: str = "paper",
                    updater_config=None, progress: bool = False,
                    new_session: bool = False) -> dict:
    """Update the map at ``map_path`` with the scans of ``log``; write ``outputs``, each
    atomically. ``method``: what updates the map, one of ``methods.ROBOT_METHODS`` (a state
    only with ``"paper"``); no ``updater_config``: ``placement.profile``'s. ``progress``: a
    progress bar on stderr. ``new_session``: the state (``outputs.state``) starts the next
    session on the map (``_updater``).
    Returns what happened as a dict (``mapupdate.summaries.update_lines`` says it in words)."""
    wall0 = _time.perf_counter()
    place, state_path = placement, outputs.state
    check_update_arguments(place.source, place.smooth_window, method, state_path)
    _refuse_clashes(log.path, map_path, state_path, outputs.map, outputs.trajectory)
    grid = load_map(map_path)
    if place.initial_pose is not None:      # a mistake in it is refused before the log is read
        check_start_pose(grid, place.initial_pose)
    found = log_observations(log.path, log_format=log.format, strict=log.strict,
                             scan_topics=log.scan_topics, odom_topic=log.odom_topic,
                             pose_topic=log.pose_topic, truth_topic=log.truth_topic,
                             laser_mount=log.laser_mount, limits=log.limits)
    done = replay_observations(grid, found, place, method=method, updater_config=updater_config,
                               state_path=state_path, window=(log.start_time, log.end_time),
                               log_path=log.path, progress=progress,
                               new_session=new_session)
    updated = _save_outputs(done.updater, done.replay, outputs)
    return {
        "log": str(log.path), "format": found.format, "map": str(map_path),
        "out": str(outputs.map), "state": None if state_path is None else str(state_path),
        "state_loaded": done.state_loaded, "method": method, "pose_source": done.source,
        **_what_happened(done.pipeline, done.replay, found), **_changes(grid, updated),
        "evidence": _evidence(done.updater),
        "trajectory": None if outputs.trajectory is None else str(outputs.trajectory),
        "wall_s": _time.perf_counter() - wall0,
    }


@dataclass
class ReplayRun:
    """What a replay made: the method that updated the map (its ``updated_map()`` is the
    result), the pipeline with its counters, what the replay loop gathered, the pose source it
    used and whether the updater was loaded from a state file (True: its session continued;
    "next session": the next session started from it)."""

    updater: object
    pipeline: RobotPipeline
    replay: Replay
    source: str
    state_loaded: bool | str


def replay_observations(grid: OccupancyGrid, found, placement: Placement = Placement(), *,
                        method: str = "paper", updater_config=None, state_path=None,
                        window=(None, None), log_path="log", progress: bool = False,
                        new_session: bool = False) -> ReplayRun:
    """The update of ``grid`` from a log's observations ``found`` (a
    ``robotlogs.LogObservations``, or anything with its ``observations``, ``total`` and
    ``has``), placed as ``placement`` says, within ``window`` (start, end [s], None for
    open); nothing is written. ``update_from_log`` is this with the log read and the outputs
    saved."""
    source = _choose_source(placement.source, found.has, log_path,
                            placement.initial_pose is not None)
    updater, state_loaded = _updater(grid, updater_config, state_path, method,
                                     placement.profile, new_session)
    check = POSE_CHECK_ON[placement.profile][0] if placement.pose_check is None \
        else placement.pose_check
    # scans placed by the project's localiser are refined by the check, a log's poses only
    # as the profile says (PoseCheckConfig.refine_given)
    pipeline = _pipeline(updater, check,
                         _pose_check_config(placement).for_poses(source == "localizer"),
                         _smoother(placement.smooth_window, source, found.has))
    starter = None
    if source == "localizer":
        starter = LocalizerStart(grid, placement, found.has["map_frame"])
    replay = _replay(pipeline, found, source, starter, window,
                     f"updating from {Path(log_path).name}" if progress else None)
    _check_placed(pipeline, replay, found, log_path)
    return ReplayRun(updater, pipeline, replay, source, state_loaded)


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


def _pose_check_config(placement: Placement) -> PoseCheckConfig:
    given = placement.pose_check_config
    return PoseCheckConfig.profile(placement.profile) if given is None else given


def _pipeline(updater, pose_check: bool, pose_check_config, smoother=None) -> RobotPipeline:
    guard = None
    if pose_check:
        guard = PoseCheck(updater.reference_map, pose_check_config)
    return RobotPipeline(updater, pose_check=guard, smoother=smoother)


def _save_outputs(updater, replay: Replay, outputs: Outputs):
    """The updated map (returned), and the state and trajectory when asked, each atomically."""
    updated = updater.updated_map()
    save_map(updated, outputs.map)
    if outputs.state is not None:
        updater.save(outputs.state)
    if outputs.trajectory is not None:
        write_tum(Path(outputs.trajectory), np.asarray(replay.times),
                  np.asarray(replay.poses).reshape(-1, 3))
    return updated


def _replay(pipeline: RobotPipeline, found, source: str, starter, window,
            progress: str | None) -> Replay:
    """Feed the log's observations within ``window`` (start, end [s], None for open) to the
    pipeline; the localiser, if the poses are to come from one, starts at the first
    observation with odometry. Returns what the update used."""
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
            _note_pose(out, obs, step)
    return out


def _note_pose(out: Replay, obs: Observation, step: Step) -> None:
    """Record the robot pose the update placed the scan at (refined or not), unless the scan
    changed nothing because its pose was refused or withheld."""
    if step.report is None or step.report.status is ScanStatus.REFUSED:
        return
    # the laser's pose, as given or refined, back to the robot's (also when the log gave the
    # laser's pose and the pipeline was given no mount)
    robot = step.report.sensor_pose.compose(obs.mount.inverse())
    out.times.append(obs.time)
    out.poses.append((robot.x, robot.y, robot.theta))


def _check_placed(pipeline: RobotPipeline, replay: Replay, found, log_path) -> None:
    """Refuse a replay that placed no scan at all: no usable scan in the log, every scan
    without a pose, or a global localisation that never settled (then nothing is written)."""
    c = pipeline.counts
    if c.scans == 0:        # nothing usable: an error, not an unchanged map written
        raise LogError(f"{log_path}: no usable scan ({replay.read} read"
                       f"{', none in the time window asked for' if replay.read else ''}); "
                       f"{found.stats.summary()}")
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

    def __init__(self, grid, placement: Placement, map_frame: bool):
        config, initial_pose = placement.localizer_config, placement.initial_pose
        if config is None:
            config = LocalizerConfig.profile(placement.profile)
        elif isinstance(config, dict):
            config = LocalizerConfig.from_dict(config)
        elif isinstance(config, (str, Path)):
            config = LocalizerConfig.from_yaml(config)
        if initial_pose is not None:
            check_start_pose(grid, initial_pose)
        self.grid, self.config, self.seed = grid, config, placement.seed
        self.initial_pose, self.initial_std = initial_pose, placement.initial_std
        self.map_frame = map_frame
        self.tracking_config = placement.tracking_config
        self.pose_check_config = _pose_check_config(placement)
        self.how = ""

    def start(self, obs: Observation):
        """(localiser, its tracking monitor)."""
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


def check_start_pose(grid: OccupancyGrid, pose) -> None:
    """Refuse a start pose for the localiser that cannot be the robot's: not three finite
    numbers, off the map, or in a cell the map holds occupied or unknown (the robot stands on
    floor it has seen free). A start there would put the particles where no scan fits, and
    the update would draw what the scans see around a wrong pose."""
    if not (isinstance(pose, Pose2D) and pose.is_finite()):
        raise LogError(f"the initial pose must be three finite numbers X Y YAW, got {pose!r}")
    x0, y0, x1, y1 = grid.extent()
    where = f"the initial pose ({pose.x:g}, {pose.y:g}, {pose.theta:g})"
    if not (x0 <= pose.x < x1 and y0 <= pose.y < y1):
        raise LogError(f"{where} is off the map, which spans x {x0:g} to {x1:g} m and y {y0:g} "
                       f"to {y1:g} m; give a pose on the map's free floor")
    row, col = (int(i) for i in grid.world_to_cell(pose.x, pose.y))
    row, col = min(row, grid.height - 1), min(col, grid.width - 1)   # rounding at the far edge
    cell = int(grid.data[row, col])
    if cell != FREE:
        what = "an occupied" if cell == OCCUPIED else "an unknown"
        raise LogError(f"{where} is in {what} cell of the map (row {row}, column {col}); give "
                       "a pose on the map's free floor")


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


def _updater(grid: OccupancyGrid, config, state_path, method: str = "paper",
             profile: str = DEFAULT_PROFILE, new_session: bool = False
             ) -> tuple[object, bool | str]:
    """A fresh ``method`` on ``grid`` (with ``config``, else with ``profile``'s; the baselines
    use its gate), or the paper's updater of the state in ``state_path`` when that exists:
    the same session continued when ``grid`` is the map the state's session started from
    (True), the next session when it is the map that session made, or with ``new_session``
    (``"next session"``: a fresh updater on ``grid`` with what the state carries from session
    to session, ``MapUpdater.carried_faces``). A state holds its reference map whole, which is
    its fingerprint: it is refused for any other map (but with ``new_session``, for a map in
    another frame), and a configuration given with it must be the one it was made with (its
    buffers follow that configuration)."""
    if isinstance(config, dict):
        config = UpdaterConfig.from_dict(config)
    elif isinstance(config, (str, Path)):
        config = UpdaterConfig.from_yaml(config)
    if state_path is None or not Path(state_path).exists():
        config = config or UpdaterConfig.profile(profile)
        return make_method(method, grid, config), False
    upd = MapUpdater.load(state_path)
    ref = upd.reference_map
    if not ref.same_frame(grid):
        raise LogError(f"{state_path}: the saved updater state belongs to a map of shape "
                       f"{ref.shape} at {ref.resolution} m, origin {ref.origin}; the map "
                       f"given has shape {grid.shape} at {grid.resolution} m, origin "
                       f"{grid.origin}")
    if config is not None and config != upd.config:
        keys = [k for k, v in config.to_dict().items() if upd.config.to_dict().get(k) != v]
        raise LogError(f"{state_path}: the saved updater state was made with another updater "
                       f"configuration ({', '.join(keys)} differ); give the same one or none")
    differ = int(np.count_nonzero(ref.data != grid.data))
    if not new_session and differ:
        made = int(np.count_nonzero(upd.updated_map().data != grid.data))
        if made:
            raise LogError(f"{state_path}: the saved updater state belongs to another map "
                           f"({differ} cells differ from the map its session started from, "
                           f"{made} from the map it made); give either of those, or "
                           "--new-session to start a session on this map with what the "
                           "state carries, or no --state to start afresh")
        new_session = True          # the map the state's session made: the next session
    if new_session:
        # what one session hands the next: the faces rule's counts, halved; buffers and
        # gate start afresh on the new map, as in a chained run
        return MapUpdater(grid, upd.config, faces=upd.carried_faces()), "next session"
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
