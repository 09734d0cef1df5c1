"""One update session played scan by scan: the localiser on M_{i-1} (and one on M1 for the
comparison), the updater on M_{i-1} fed the localiser's scan-time poses, the bookkeeping the
scores need, and at the end the session's scores in the shape of ``metrics.json``.

Whoever drives the robot feeds it scans: the runner (the robot follows its route) and the
gymnasium environment (an agent drives) share this one implementation, so the same world and
the same commands give the same figures.
"""

from __future__ import annotations

import math
import resource
from dataclasses import dataclass, field

import numpy as np

import evaluation as ev
import sim
from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D
from gridmap.metrics import compare_maps
from localization import LocalizerConfig, MonteCarloLocalizer
from localization.confidence import PoseCheck, PoseCheckConfig
from onboard.methods import make_method
from onboard.pipeline import RobotPipeline

# The robot starts each session at its dock, whose pose is known to about this precision.
START_STD = (0.05, 0.05, 0.02)  # x [m], y [m], yaw [rad]


def session_seeds(seed: int, n_sessions: int) -> list[dict[str, np.random.SeedSequence]]:
    """One SeedSequence per component and session, so any session can be re-run alone."""
    out = []
    for seq in np.random.SeedSequence(seed).spawn(n_sessions):
        world, localizer, _spare = seq.spawn(3)
        out.append({"world": world, "localizer": localizer})
    return out


def map_metrics(a: OccupancyGrid, b: OccupancyGrid) -> dict:
    return {k: float(v) for k, v in compare_maps(a, b).items()}


@dataclass
class Trajectory:
    """Robot poses at scan times: true, estimated on M_{i-1}, estimated on M1."""

    time: list = field(default_factory=list)
    true: list = field(default_factory=list)
    previous_map: list = field(default_factory=list)
    initial_map: list = field(default_factory=list)

    def add(self, t: float, true: Pose2D, est_prev: Pose2D, est_init: Pose2D) -> None:
        self.time.append(t)
        self.true.append(true.as_array())
        self.previous_map.append(est_prev.as_array())
        self.initial_map.append(est_init.as_array())

    def arrays(self) -> dict[str, np.ndarray]:
        return {"time": np.asarray(self.time, np.float64),
                "true": np.asarray(self.true, np.float64).reshape(-1, 3),
                "previous_map": np.asarray(self.previous_map, np.float64).reshape(-1, 3),
                "initial_map": np.asarray(self.initial_map, np.float64).reshape(-1, 3)}


@dataclass
class SessionResult:
    """What one session produced. A full result (``UpdateSession.result``) has every field;
    the mapping session W1 has no ``previous``, ``oracle``, ``trajectory`` or ``masks``.

    Once a session's outputs are on disk, a run keeps it only in part (see ``RunResult``): a
    light result has its ``name`` and ``metrics``, maybe its ``updated`` map, and ``None`` or
    empty in every other field. What it dropped is in the run's folder (``maps/``,
    ``trajectories/``, ``state/``).
    """

    name: str
    updated: OccupancyGrid | None          # M_i
    truth: OccupancyGrid | None            # G_i
    previous: OccupancyGrid | None = None  # M_{i-1}
    oracle: OccupancyGrid | None = None
    trajectory: Trajectory | None = None
    metrics: dict = field(default_factory=dict)
    masks: dict = field(default_factory=dict)  # per-cell arrays: observable, people, ...
    # what the updater carries to the next session (``MapUpdater.carried_faces``), or None
    faces: object | None = None


@dataclass
class ChangeTally:
    """Map changes so far, judged against the truth as ``evaluation.change_detection`` judges
    them (one cell of slack for new obstacles)."""

    correct: int = 0
    wrong: int = 0


def localizer_config_for(scenario):
    """The localiser's defaults with its motion model set to the robot's odometry noise, as
    one tunes AMCL's alphas for a robot: nav2's default alphas (0.2) are four to twenty times
    this robot's, and so wide a motion model lets the estimate slide along an aisle towards an
    old outline where the map is stale."""
    a1, a2, a3, a4 = scenario.robot.odometry_noise
    return LocalizerConfig(alpha1=a1, alpha2=a2, alpha3=a3, alpha4=a4)


class UpdateSession:
    """The robot software of one session: a localiser on the reference map M_{i-1}, one on M1
    (for the comparison), the updater on M_{i-1}, and the bookkeeping of the scores.

    ``localizer_seed``: both localisers use it, as the evaluation asks. ``localizer_config``:
    by default ``localizer_config_for(scenario)`` (the robot's odometry noise as alphas).
    ``pose_check``: the safeguard of ``localization.confidence`` (scans whose pose looks unsure
    change nothing): off (False), on with its defaults (True) or on with a
    ``PoseCheckConfig``. ``method``: what updates the map, a name of
    ``onboard.methods.METHODS`` (default the paper's updater); ``self.updater`` is that
    method. ``faces``: what the last session's updater carried over.
    """

    def __init__(self, scenario, session: int, world, reference: OccupancyGrid,
                 initial: OccupancyGrid, localizer_seed, updater_config=None,
                 localizer_config=None, pose_check=True, method: str = "paper",
                 comparison=None, faces=None):

        self.scenario, self.index, self.world = scenario, session, world
        self.name = scenario.sessions[session].name
        self.reference, self.initial = reference, initial
        self.truth = world.ground_truth()
        if not reference.same_frame(self.truth):
            raise ValueError(f"the reference map ({reference.shape} cells at "
                             f"{reference.resolution} m, origin {reference.origin}) is not in "
                             f"the scenario's grid frame ({self.truth.shape} cells at "
                             f"{self.truth.resolution} m, origin {self.truth.origin})")
        self.frame = sim.grid_frame(scenario)
        self.mounts = [lidar.mount for lidar in scenario.robot.lidars]
        start, cov = world.true_pose, np.diag(np.square(START_STD))
        if localizer_config is None:
            localizer_config = localizer_config_for(scenario)
        self.localizer = MonteCarloLocalizer(reference, localizer_config, seed=localizer_seed)
        self.localizer.initialize(start, cov)
        self.updater = make_method(method, reference, updater_config, faces)
        # the project's own localiser places the scans: refined as the profile says
        check = pose_check if isinstance(pose_check, PoseCheckConfig) else PoseCheckConfig()
        guard = PoseCheck(reference, check.for_poses(own_localizer=True)) if pose_check else None
        self.pipeline = RobotPipeline(self.updater, self.localizer, guard)
        # ``comparison``: an updater configuration run beside, on the same scans at the same
        # poses, with no pose check (the report's comparison columns)
        self.comparison = None if comparison is None else make_method("paper", reference,
                                                                      comparison)
        # the comparison of the evaluation: the same localiser on M1, feeding no updater
        initial_localizer = MonteCarloLocalizer(initial, localizer_config, seed=localizer_seed)
        initial_localizer.initialize(start, cov)
        self.pipeline_initial = RobotPipeline(localizer=initial_localizer)
        self.counter = ev.ObservationCounter(self.frame)
        self.people_mask = np.zeros(self.frame.shape, bool)
        self.trajectory = Trajectory()
        self.last_report = None
        self.last_scan = None
        self.last_estimate: Pose2D | None = None
        self._truth_free = self.truth.data == FREE
        self._near_truth_occupied = ev.near(self.truth.data == OCCUPIED)
        self._map = reference
        self._tally = ChangeTally()
        self._stale = False       # the updater processed a scan since _map was taken

    # --- per scan ---------------------------------------------------------------------------------
    def add_scan(self, msg):
        """One ``sim.ScanMsg``, handled while the world is at the message's time; returns the
        updater's report."""
        world, mount = self.world, self.mounts[msg.lidar]
        step = self.pipeline.step(msg.scan, mount, odometry=msg.odom_pose)
        est, report = step.robot_pose, step.report
        est_init = self.pipeline_initial.step(msg.scan, mount, odometry=msg.odom_pose).robot_pose
        if self.comparison is not None and est is not None and step.report is not None:
            self.comparison.process(msg.scan, est.compose(mount), odometry=msg.odom_pose)
        if report.processed:
            clean = world.scan_without_people(msg.true_pose, msg.lidar)
            self.counter.add_scan(msg.true_pose.compose(mount), clean.ranges, clean.angles())
            self._stale = self._stale or not report.dropped_as_lost
        ev.paint_people(self.people_mask, self.frame, world.people())
        self.trajectory.add(msg.time, msg.true_pose, est, est_init)
        self.last_report, self.last_scan, self.last_estimate = report, msg, est
        return report

    def _refresh(self) -> None:
        # O(map): done only when someone asks, not per scan
        if not self._stale:
            return
        self._map = self.updater.updated_map()
        changed = self._map.data != self.reference.data
        correct = changed & (((self._map.data == FREE) & self._truth_free)
                             | ((self._map.data == OCCUPIED) & self._near_truth_occupied))
        n_correct = int(np.count_nonzero(correct))
        self._tally = ChangeTally(n_correct, int(np.count_nonzero(changed)) - n_correct)
        self._stale = False

    @property
    def counts(self) -> dict:
        """The pipeline's counters, as ``metrics.json`` keeps them."""
        c = self.pipeline.counts
        return {"scans": c.scans, "scans_processed": c.scans_processed,
                "scans_dropped_as_lost": c.scans_dropped_as_lost,
                "scans_refused_by_pose_check": c.scans_refused_by_pose_check,
                "scans_corrected_by_pose_check": c.scans_corrected_by_pose_check,
                "localizer_updates": c.localizer_updates}

    # --- now --------------------------------------------------------------------------------------
    @property
    def updated_map(self) -> OccupancyGrid:
        """M_i as it stands (do not modify)."""
        self._refresh()
        return self._map

    @property
    def tally(self) -> ChangeTally:
        """Correct and wrong map changes so far."""
        self._refresh()
        return self._tally

    def estimate(self) -> Pose2D:
        """The localiser's pose of the robot at the latest odometry."""
        if not self.pipeline.counts.scans:  # no odometry recorded yet: the initial pose holds
            return self.localizer.estimate().pose
        return self.localizer.estimate().pose_at(self.world.odom_pose)

    def localization_error(self) -> float:
        """[m] distance between the estimated and the true position now."""
        est, true = self.estimate(), self.world.true_pose
        return math.hypot(est.x - true.x, est.y - true.y)

    # --- at the end -------------------------------------------------------------------------------
    def result(self) -> SessionResult:
        """M_i, the truth, the oracle, the trajectories, the masks and the session's entry of
        ``metrics.json``."""
        updated = self.updater.updated_map()
        observable = self.counter.observable()
        oracle = ev.oracle_map(self.reference, self.truth, observable)
        arr = self.trajectory.arrays()
        metrics = {
            "name": self.name,
            "map_metrics": {
                "previous_vs_truth": map_metrics(self.reference, self.truth),
                "updated_vs_truth": map_metrics(updated, self.truth),
                "oracle_vs_truth": map_metrics(oracle, self.truth),
            },
            "change_detection": ev.change_detection(self.reference, updated, self.truth,
                                                    observable),
            "ghost_cells": ev.ghost_cells(updated, self.truth, self.people_mask),
            "localization": {
                "initial_map": ev.ape_statistics(arr["initial_map"][:, :2], arr["true"][:, :2]),
                "previous_map": ev.ape_statistics(arr["previous_map"][:, :2],
                                                  arr["true"][:, :2]),
            },
            "resources": {
                "updater_cpu_s": self.pipeline.cpu["updater_s"],
                "localizer_cpu_s": self.pipeline.cpu["localizer_s"],
                "localizer_initial_map_cpu_s": self.pipeline_initial.cpu["localizer_s"],
                "updater_state_bytes": int(self.updater.state_bytes()),
                "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                "simulated_s": float(arr["time"][-1]) if len(arr["time"]) else 0.0,
                **self.counts,
            },
        }
        if self.comparison is not None:
            other = self.comparison.updated_map()
            metrics["comparison"] = {
                "profile": "paper",
                "map_metrics": {"updated_vs_truth": map_metrics(other, self.truth)},
                "change_detection": ev.change_detection(self.reference, other, self.truth,
                                                        observable),
                "ghost_cells": ev.ghost_cells(other, self.truth, self.people_mask)}
        carried = getattr(self.updater, "carried_faces", None)
        return SessionResult(self.name, updated, self.truth, previous=self.reference,
                             oracle=oracle, trajectory=self.trajectory, metrics=metrics,
                             masks={"observable": observable, "people": self.people_mask,
                                    "observations": self.counter.counts},
                             faces=None if carried is None else carried())

    def scores(self) -> dict:
        """The session's entry of ``metrics.json``."""
        return self.result().metrics
