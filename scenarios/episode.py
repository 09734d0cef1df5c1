"""One update session played scan by scan by whoever drives the robot: the localisers and the
updater as the runner runs them, the running tally of correct and wrong map changes, and at the
end the session's scores in the runner's shape (``metrics.json``).

The gymnasium environment drives it; nothing here imports gymnasium. The order of the per-scan
steps and the seeds are the runner's (``runner.run_update_session``), so the same world and the
same commands give the same figures.
"""

from __future__ import annotations

import functools
import math
import resource
import time
from dataclasses import dataclass

import numpy as np

from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D

from . import evaluation as ev
from .runner import START_STD, Trajectory, _map_metrics, _session_seeds, build_initial_map


@functools.lru_cache(maxsize=8)
def initial_map(scenario, seed: int) -> OccupancyGrid:
    """M1 of ``scenario`` (a frozen, hashable ``sim.Scenario``) for ``seed``, built as the runner
    builds it and kept: mapping takes seconds, and vectorised environments share it. Treat the
    grid as read-only."""
    seeds = _session_seeds(seed, len(scenario.sessions))
    return build_initial_map(scenario, 0, seeds[0]).updated


@dataclass
class ChangeTally:
    """Map changes so far, judged against the truth as ``evaluation.change_detection`` judges
    them (one cell of slack for new obstacles)."""

    correct: int = 0
    wrong: int = 0


class UpdateSession:
    """The robot software of one session: a localiser on the reference map M_{i-1}, one on M1
    (for the runner's comparison), the updater on M_{i-1}, and the bookkeeping of the scores."""

    def __init__(self, scenario, session: int, world, reference: OccupancyGrid,
                 initial: OccupancyGrid, seed: int, updater_config=None, localizer_config=None):
        import sim
        from localization import MonteCarloLocalizer
        from updater import MapUpdater

        self.scenario, self.index, self.world = scenario, session, world
        self.reference, self.initial = reference, initial
        self.truth = world.ground_truth()
        if not reference.same_frame(self.truth):
            raise ValueError(f"the reference map ({reference.shape} cells at "
                             f"{reference.resolution} m, origin {reference.origin}) is not in "
                             f"the scenario's grid frame ({self.truth.shape} cells at "
                             f"{self.truth.resolution} m, origin {self.truth.origin})")
        self.frame = sim.grid_frame(scenario)
        self.mounts = [lidar.mount for lidar in scenario.robot.lidars]
        loc_seed = _session_seeds(seed, len(scenario.sessions))[session]["localizer"]
        start, cov = world.true_pose, np.diag(np.square(START_STD))
        self.localizer = MonteCarloLocalizer(reference, localizer_config, seed=loc_seed)
        self.localizer_initial = MonteCarloLocalizer(initial, localizer_config, seed=loc_seed)
        self.localizer.initialize(start, cov)
        self.localizer_initial.initialize(start, cov)
        self.updater = MapUpdater(reference, updater_config)
        self.counter = ev.ObservationCounter(self.frame)
        self.people_mask = np.zeros(self.frame.shape, bool)
        self.trajectory = Trajectory()
        self.cpu = {"localizer_s": 0.0, "localizer_initial_map_s": 0.0, "updater_s": 0.0}
        self.counts = {"scans": 0, "scans_processed": 0, "scans_dropped_as_lost": 0,
                       "localizer_updates": 0}
        self.last_report = None
        self.last_scan = None
        self.tally = ChangeTally()
        self._truth_free = self.truth.data == FREE
        self._near_truth_occupied = ev.near(self.truth.data == OCCUPIED)
        self._map = reference.copy()      # the updated map, refreshed after processed scans

    # --- per scan ---------------------------------------------------------------------------------
    def add_scan(self, msg) -> None:
        """One ``sim.ScanMsg``, handled while the world is at the message's time."""
        world, mount = self.world, self.mounts[msg.lidar]
        t0 = time.process_time()
        self.counts["localizer_updates"] += bool(self.localizer.update(msg.odom_pose, msg.scan,
                                                                       mount))
        est = self.localizer.estimate().pose_at(msg.odom_pose)
        t1 = time.process_time()
        self.localizer_initial.update(msg.odom_pose, msg.scan, mount)
        est_init = self.localizer_initial.estimate().pose_at(msg.odom_pose)
        t2 = time.process_time()
        report = self.updater.process(msg.scan, est.compose(mount), odometry=msg.odom_pose)
        t3 = time.process_time()
        self.cpu["localizer_s"] += t1 - t0
        self.cpu["localizer_initial_map_s"] += t2 - t1
        self.cpu["updater_s"] += t3 - t2
        self.counts["scans"] += 1
        self.counts["scans_dropped_as_lost"] += bool(report.dropped_as_lost)
        if report.processed:
            self.counts["scans_processed"] += 1
            clean = world.scan_without_people(msg.true_pose, msg.lidar)
            self.counter.add_scan(msg.true_pose.compose(mount), clean.ranges, clean.angles())
        ev.paint_people(self.people_mask, self.frame, world.people())
        self.trajectory.add(msg.time, msg.true_pose, est, est_init)
        self.last_report, self.last_scan = report, msg
        if report.processed and not report.dropped_as_lost:
            self._refresh_map()

    def _refresh_map(self) -> None:
        self._map = self.updater.updated_map()
        changed = self._map.data != self.reference.data
        correct = changed & (((self._map.data == FREE) & self._truth_free)
                             | ((self._map.data == OCCUPIED) & self._near_truth_occupied))
        n_correct = int(np.count_nonzero(correct))
        self.tally = ChangeTally(n_correct, int(np.count_nonzero(changed)) - n_correct)

    # --- now --------------------------------------------------------------------------------------
    @property
    def updated_map(self) -> OccupancyGrid:
        """M_i as it stands (kept between processed scans; do not modify)."""
        return self._map

    def estimate(self) -> Pose2D:
        """The localiser's pose of the robot at the latest odometry."""
        if not self.counts["scans"]:      # no odometry recorded yet: the initial pose holds
            return self.localizer.estimate().pose
        return self.localizer.estimate().pose_at(self.world.odom_pose)

    def localization_error(self) -> float:
        """[m] distance between the estimated and the true position now."""
        est, true = self.estimate(), self.world.true_pose
        return math.hypot(est.x - true.x, est.y - true.y)

    # --- at the end -------------------------------------------------------------------------------
    def scores(self) -> dict:
        """The session's entry of the runner's ``metrics.json``."""
        updated = self.updater.updated_map()
        observable = self.counter.observable()
        oracle = ev.oracle_map(self.reference, self.truth, observable)
        arr = self.trajectory.arrays()
        return {
            "name": self.scenario.sessions[self.index].name,
            "map_metrics": {
                "previous_vs_truth": _map_metrics(self.reference, self.truth),
                "updated_vs_truth": _map_metrics(updated, self.truth),
                "oracle_vs_truth": _map_metrics(oracle, self.truth),
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
                "updater_cpu_s": self.cpu["updater_s"],
                "localizer_cpu_s": self.cpu["localizer_s"],
                "localizer_initial_map_cpu_s": self.cpu["localizer_initial_map_s"],
                "updater_state_bytes": int(self.updater.state_bytes()),
                "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                "simulated_s": float(arr["time"][-1]) if len(arr["time"]) else 0.0,
                **self.counts,
            },
        }


def waypoints_reached(route: np.ndarray, index: int, pose: Pose2D, waypoint_tolerance: float,
                      goal_tolerance: float) -> int:
    """The index of the route's next waypoint after the robot at ``pose`` has passed those it is
    near: within ``waypoint_tolerance`` [m] of an intermediate one, ``goal_tolerance`` of the
    last. ``len(route)`` when the route is done."""
    last = len(route) - 1
    while index <= last:
        tol = goal_tolerance if index == last else waypoint_tolerance
        if math.hypot(route[index, 0] - pose.x, route[index, 1] - pose.y) >= tol:
            break
        index += 1
    return index


# --- reward ---------------------------------------------------------------------------------------
COLLISION_PENALTY = 10.0   # per move refused by a wall or object
CONTACT_PENALTY = 1.0      # per physics step that ends with a person touching the robot
LOST_PENALTY = 5.0         # per second with the estimate further than lost_distance from truth


@dataclass(frozen=True)
class StepOutcome:
    """What one environment step did: what a reward function gets."""

    dt: float                    # [s] simulated time the step covered
    correct_gain: int            # change of the correctly changed cells of the map
    wrong_gain: int              # change of the wrongly changed cells
    collisions: int              # moves refused by a wall or object during the step
    people_contacts: int         # physics steps ending with a person touching the robot
    localization_error: float    # [m] at the end of the step
    lost: bool                   # localization_error > the environment's lost_distance
    scans: int                   # scans the localiser and the updater took in the step
    route_done: bool             # every waypoint of the session's route reached


def default_reward(o: StepOutcome) -> float:
    """Cells the step changed correctly, minus those it changed wrongly, minus 10 per refused
    move, 1 per step touching a person and 5 per second lost."""
    return (float(o.correct_gain - o.wrong_gain) - COLLISION_PENALTY * o.collisions
            - CONTACT_PENALTY * o.people_contacts - LOST_PENALTY * o.dt * float(o.lost))
