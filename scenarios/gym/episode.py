"""What the gymnasium environment adds to an update session (``session.UpdateSession``, the
runner's own): the cached initial map, route following for the ready policy, and the reward.
Nothing here imports gymnasium."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from gridmap import OccupancyGrid, Pose2D

from ..runner import build_initial_map
from ..session import session_seeds


@functools.lru_cache(maxsize=8)
def initial_map(scenario, seed: int) -> OccupancyGrid:
    """M1 of ``scenario`` (a frozen, hashable ``sim.Scenario``) for ``seed``, built as the runner
    builds it and kept: mapping takes seconds, and vectorised environments share it. Treat the
    grid as read-only."""
    seeds = session_seeds(seed, len(scenario.sessions))
    return build_initial_map(scenario, 0, seeds[0]).updated


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
