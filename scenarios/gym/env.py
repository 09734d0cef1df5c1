"""The gymnasium environment ``WarehouseMapUpdate-v0``: one update session of a scenario, with the
robot driven by the agent. The only module of the project that imports gymnasium.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium import spaces

import sim
from gridmap import MapUpdatingError, OccupancyGrid, Pose2D, load_map
from gridmap.map_io import trinary_image
from gridmap.suggest import did_you_mean
from onboard.methods import check_method
from onboard.robot_config import ConfigError, load_robot_config

from ..catalog import find_scenario
from ..options import RunOptions
from ..runner import resolve_profile
from ..session import UpdateSession, session_seeds
from ..topview import scan_points, top_view
from .episode import StepOutcome, default_reward, initial_map, waypoints_reached


class EnvOptionsError(MapUpdatingError, ValueError):
    """A setting the environment does not have; the message names it and the nearest one.
    (Not a ``TypeError``: ``gymnasium.make`` would append every keyword's value to it.)"""


@dataclass(frozen=True)
class EnvOptions:
    """The settings of ``WarehouseMapUpdateEnv`` beside its scenario and session. They are
    given as keywords, ``gymnasium.make("WarehouseMapUpdate-v0", quick=True, profile="paper")``,
    or as a record, ``options=EnvOptions(quick=True)``, which keywords given beside it override;
    the environment keeps the result as ``env.options``. The environment refuses a bad value
    with a ``ValueError`` naming it and its value, before any work."""

    quick: bool = False                 # cut the update routes as ``mapupdate run --quick`` does
    # M_{i-1}: an OccupancyGrid or a map_server YAML path; None: M1, built by the mapping session
    # as the runner builds it (kept per scenario and seed)
    reference_map: OccupancyGrid | str | Path | None = None
    # M1 for the runner's second localiser, in the same forms; None: the reference map if one is
    # given, else M1
    initial_map: OccupancyGrid | str | Path | None = None
    # seed of the mapping run that builds M1, an integer >= 0; None: the episode's seed
    map_seed: int | None = None
    # [s] how long an action is held: a whole number of physics steps, in (0, 60]
    # (MAX_CONTROL_PERIOD; not NaN or inf); None: one step (0.05 s in the warehouse, the rate
    # the runner's robot is driven at)
    control_period: float | None = None
    map_observation: bool = False       # add the map image, ``map``, to the observation
    # ``reward_fn(StepOutcome) -> float`` (see the environment's Rewards); None:
    # ``episode.default_reward``
    reward_fn: Callable[[StepOutcome], float] | None = None
    # [m] an estimate this far from the truth is lost (costs reward); >= 0, not NaN; inf: never
    lost_distance: float = 0.5
    # [m] a route waypoint is passed within this distance, the last within ``goal_tolerance``
    # (see the environment's Episode End); each finite and >= 0
    waypoint_tolerance: float = 0.3
    goal_tolerance: float = 0.05        # [m]
    # the updater's configuration as the runner takes it (an ``UpdaterConfig``); None: the
    # profile's, with ``config``'s keys; not beside ``config["updater"]``
    updater_config: object | None = None
    # the localiser's configuration as the runner takes it (a ``LocalizerConfig`` or a mapping
    # of its keys); None: the profile's, with ``config``'s keys; not beside ``config["localizer"]``
    localizer_config: object | None = None
    # whether the pose check runs; None: as the profile has it (on for robot, off for paper)
    pose_check: bool | None = None
    # the robot software's configuration as ``mapupdate run --config`` reads it: a dict
    # ``{"updater": {...}, "localizer": {...}, "pose_check": {...}}`` (each section optional;
    # keys the fields of UpdaterConfig, LocalizerConfig, PoseCheckConfig), a YAML path or an
    # ``onboard.robot_config.RobotConfig``; an unknown section or key is refused
    # (``ConfigError``) with the nearest valid name. None: no keys
    config: object | None = None
    # the defaults the configuration starts from, as ``mapupdate run --profile``: "robot" (what
    # a robot should run) or "paper" (the paper and its authors' code); ``config``'s keys are
    # laid over it key by key. None: robot
    profile: str | None = None
    render_mode: str | None = None      # "rgb_array": ``render()`` draws a top view; None: none
    # [px per cell] of the top view: a whole number >= 1 that keeps the picture within 4096 px
    # a side (MAX_RENDER_SIDE)
    render_scale: int = 2
    # what updates the map, as ``mapupdate run --method``: "paper" (the updater), "none",
    # "remap", "fuse" or "hybrid" (``onboard.methods``); an unknown name is refused
    # (``MethodError``) with the nearest valid one
    method: str = "paper"


class WarehouseMapUpdateEnv(gym.Env):
    """
    ## Description

    One session of a simulated warehouse (the paper's section V testbed): the session's changes
    are applied to the world, people walk, and the agent drives the robot. Inside the
    environment a Monte Carlo localiser tracks the robot on the reference map M_{i-1} and the
    map updater turns that map into M_i from every scan, exactly as ``mapupdate run`` does; the
    session is scored against the ground truth G_i with the runner's figures. The agent's job is
    to drive so that the map gets updated well (and safely); ``RouteFollowingPolicy`` drives the
    session's route as the runner's robot does.

    ## Action Space

    ``Box(2,)`` float32: ``[v, w]``, linear speed [m/s] in ``[-max_speed, max_speed]`` and turn
    rate [rad/s] in ``[-max_turn_rate, max_turn_rate]`` of the scenario's robot (0.6 m/s and
    1 rad/s in the built-in warehouse). Values outside are clipped. The command is held for
    ``control_period`` seconds; a move into a wall or object is refused (the robot stays, and
    may still turn) and counted as a collision. The robot pushes people aside.

    ## Observation Space

    A ``Dict``:

    | key          | shape      | dtype   | low, high                 | unit        | what |
    |--------------|------------|---------|---------------------------|-------------|------|
    | ``scan``     | (beams,)   | float32 | 0, range_max              | m           | latest scan of lidar 0, no return = range_max |
    | ``scan_k``   | (beams_k,) | float32 | 0, range_max_k            | m           | latest scan of lidar k >= 1, if any |
    | ``odometry`` | (3,)       | float32 | world bounds +- diagonal; -pi, pi | m, m, rad | x, y, yaw in the drifting odom frame |
    | ``estimate`` | (3,)       | float32 | world bounds +- diagonal; -pi, pi | m, m, rad | localiser's pose in the map frame |
    | ``map``      | (H, W)     | uint8   | 0, 255                    | -           | with ``map_observation=True``: M_i as it stands, north up, 0 occupied, 205 unknown, 254 free |

    At reset, before the first step, ``scan`` is the noise-free scan from the start pose.

    ## Rewards

    ``reward_fn(StepOutcome) -> float``; the default, ``episode.default_reward``, is the number
    of map cells the step changed correctly minus those it changed wrongly (judged against G_i
    as the change-detection score judges them), minus 10 per refused move, 1 per physics step
    that ends with a person touching the robot, and 5 per second during which the estimate is
    more than ``lost_distance`` from the truth.

    ## Starting State

    The robot at the scenario's dock (``robot.start``); the localiser initialised around it with
    the runner's spread; people where the session's seed puts them. ``reset(seed=s)`` plays the
    session the runner plays with ``--seed s`` (the same world, odometry, lidar noise and
    localiser draws); without a seed, the episode's seed is drawn from ``self.np_random``.

    ## Episode End

    Terminated when the robot has passed the session's route waypoints in order (within
    ``waypoint_tolerance``, the last within ``goal_tolerance``) and is commanded to stand still
    (``v = w = 0``), as the runner's robot ends its session. Truncated at the session's time
    limit (``max_duration``, or three times the route at full speed plus time for turns). The
    last step's ``info["scores"]`` holds the session's entry of the runner's ``metrics.json``.

    Info of every step: ``time`` [s], ``true_pose``, ``estimated_pose``, ``odometry_pose``
    (3,) arrays, ``localization_error`` [m], ``cells_changed``, ``correct_changes``,
    ``wrong_changes``, ``updater_changed_cells`` (the decision rule's count), ``collisions``,
    ``people_contacts`` (so far), ``scans`` (this step), ``waypoints_reached``, ``seed``.

    ## Arguments

    ```python
    gymnasium.make("WarehouseMapUpdate-v0", scenario="aws_small_warehouse", session="W2")
    ```

    * ``scenario``: built-in name, YAML path or ``sim.Scenario`` (default: the warehouse).
    * ``session``: an update session's name or index (default 1, the first after mapping).
    * every other setting by keyword (``quick=True``, ``profile="paper"``, ...), each a field of
      ``EnvOptions``, where each is described; or a whole record, ``options=EnvOptions(...)``,
      which keywords given beside it override. An unknown keyword is refused
      (``EnvOptionsError``, a ``ValueError``) in one line with the nearest setting's name; a
      bad value as ``EnvOptions`` says, before any work.

    ## Version History

    * v0: initial version.

    ## Example

    >>> import gymnasium, scenarios
    >>> env = gymnasium.make("WarehouseMapUpdate-v0", session="W2", quick=True)  # doctest: +SKIP
    >>> obs, info = env.reset(seed=7)                                           # doctest: +SKIP
    >>> obs, reward, terminated, truncated, info = env.step([0.3, 0.0])         # doctest: +SKIP
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, scenario=None, session: int | str = 1, *,
                 options: EnvOptions | Mapping | None = None, **settings):
        self.options = o = _env_options(options, settings)
        _check_arguments(control_period=o.control_period, map_seed=o.map_seed,
                         render_mode=o.render_mode, render_modes=self.metadata["render_modes"],
                         render_scale=o.render_scale, lost_distance=o.lost_distance,
                         waypoint_tolerance=o.waypoint_tolerance,
                         goal_tolerance=o.goal_tolerance)
        robot = load_robot_config(o.config, source="config", profile=o.profile)
        self.method = check_method(o.method, "method")
        self.scenario = _load_scenario(scenario, o.quick)
        self.session_index = self.scenario.session_index(session)
        if self.scenario.sessions[self.session_index].mapping:
            raise sim.ScenarioError(f"session {self.scenario.sessions[self.session_index].name!r}"
                                    f" builds the initial map; choose an update session")
        self.render_mode, self.render_scale = o.render_mode, int(o.render_scale)
        self._reference = _load_grid(o.reference_map, "reference_map")
        self._initial = _load_grid(o.initial_map, "initial_map")
        if o.render_mode is not None:
            _check_render_size(self.render_scale, sim.grid_frame(self.scenario)
                               if self._reference is None else self._reference)
        self._map_seed = o.map_seed
        dt = 1.0 / self.scenario.physics_hz
        period = dt if o.control_period is None else float(o.control_period)
        self._n_physics = round(period / dt)
        if self._n_physics < 1 or abs(self._n_physics * dt - period) > 1e-9:
            raise ValueError(f"control_period {period} s is not a whole number of physics steps "
                             f"of {dt} s")
        self.control_period = self._n_physics * dt
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.control_period}
        self._map_observation = bool(o.map_observation)
        self._reward_fn = default_reward if o.reward_fn is None else o.reward_fn
        self.lost_distance = float(o.lost_distance)
        self.waypoint_tolerance, self.goal_tolerance = float(o.waypoint_tolerance), \
            float(o.goal_tolerance)
        # as the runner has them: the profile's, the keys given over it
        keys = robot.given
        self._run_options = resolve_profile(self.scenario, RunOptions(
            profile=robot.profile,
            updater_config=_given_once("updater", o.updater_config,
                                       robot.updater if "updater" in keys else None),
            localizer_config=_given_once("localizer", o.localizer_config,
                                         keys.get("localizer")),
            pose_check=o.pose_check, pose_check_config=robot.pose_check))
        self._route = np.asarray(self.scenario.sessions[self.session_index].route, np.float64)
        self.action_space, self.observation_space = self._spaces()
        self.world = None
        self.session = None
        self._done = True

    # --- spaces ---------------------------------------------------------------------------------
    def _spaces(self):
        robot = self.scenario.robot
        high = np.array([robot.max_speed, robot.max_turn_rate], np.float32)
        action = spaces.Box(-high, high, dtype=np.float32)
        x0, y0, x1, y1 = self.scenario.world.bounds
        diag = math.hypot(x1 - x0, y1 - y0)
        self._pose_low = np.array([x0 - diag, y0 - diag, -math.pi], np.float32)
        self._pose_high = np.array([x1 + diag, y1 + diag, math.pi], np.float32)
        obs = {}
        for k, lidar in enumerate(robot.lidars):
            obs["scan" if k == 0 else f"scan_{k}"] = spaces.Box(
                0.0, np.float32(lidar.range_max), (lidar.beams,), np.float32)
        pose = spaces.Box(self._pose_low, self._pose_high, dtype=np.float32)
        obs["odometry"] = pose
        obs["estimate"] = pose
        if self._map_observation:
            obs["map"] = spaces.Box(0, 255, sim.grid_frame(self.scenario).shape, np.uint8)
        return action, spaces.Dict(obs)

    # --- the gymnasium API ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if options:
            raise ValueError(f"reset() takes no options, got {sorted(options)}")
        episode_seed = int(seed) if seed is not None else int(self.np_random.integers(2**31 - 1))
        scn, i = self.scenario, self.session_index
        reference = self._reference
        if reference is None:
            reference = initial_map(scn, episode_seed if self._map_seed is None
                                    else int(self._map_seed))
        initial = self._initial if self._initial is not None else reference
        seeds = session_seeds(episode_seed, len(scn.sessions))
        self.world = sim.World(scn, i, seeds[i]["world"])
        self.session = UpdateSession(scn, i, self.world, reference, initial,
                                     seeds[i]["localizer"], self._run_options.updater_config,
                                     self._run_options.localizer_config,
                                     pose_check=self._run_options.pose_check and (
                                         self._run_options.pose_check_config or True),
                                     method=self.method)
        self._seed = episode_seed
        self._scans = [self.world.exact_scan(k) for k in range(len(scn.robot.lidars))]
        self._next_waypoint = 0
        self._done = False
        return self._observation(), self._info(0)

    def step(self, action):
        if self._done:
            raise RuntimeError("the episode has ended (or never started): call reset()")
        a = np.asarray(action, dtype=np.float64).reshape(2)   # float64: commands kept exact
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {action!r}")
        robot = self.scenario.robot
        v = min(max(float(a[0]), -robot.max_speed), robot.max_speed)
        w = min(max(float(a[1]), -robot.max_turn_rate), robot.max_turn_rate)
        world, session = self.world, self.session
        # waypoints are checked at the pose the command starts from, as the route follower does
        self._next_waypoint = waypoints_reached(self._route, self._next_waypoint,
                                                world.robot_pose, self.waypoint_tolerance,
                                                self.goal_tolerance)
        collisions, contacts, tally = world.collisions, world.people_contacts, session.tally
        scans = 0
        for msg in world.drive(v, w, self._n_physics):
            if isinstance(msg, sim.ScanMsg):
                session.add_scan(msg)
                self._scans[msg.lidar] = msg.scan
                scans += 1
        route_done = self._next_waypoint >= len(self._route)
        terminated = route_done and v == 0.0 and w == 0.0
        truncated = not terminated and world.elapsed >= world.time_limit - 1e-9
        error = session.localization_error()
        outcome = StepOutcome(
            dt=self.control_period, correct_gain=session.tally.correct - tally.correct,
            wrong_gain=session.tally.wrong - tally.wrong,
            collisions=world.collisions - collisions,
            people_contacts=world.people_contacts - contacts, localization_error=error,
            lost=error > self.lost_distance, scans=scans, route_done=route_done)
        reward = float(self._reward_fn(outcome))
        info = self._info(scans)
        if terminated or truncated:
            self._done = True
            info["scores"] = session.scores()
        return self._observation(), reward, terminated, truncated, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None

        session, world = self.session, self.world
        if session is None:
            raise RuntimeError("call reset() before render()")
        points = verdicts = None
        msg, report = session.last_scan, session.last_report
        if msg is not None:
            est = session.trajectory.previous_map[-1]
            sensor = Pose2D.from_array(est).compose(session.mounts[msg.lidar])
            points = scan_points(msg.scan.ranges, msg.scan.angles(), sensor)
            verdicts = report.verdicts
        return top_view(session.updated_map, session.reference, people=world.people(),
                        robot=world.true_pose, robot_radius=self.scenario.robot.radius,
                        estimate=session.estimate(), points=points, verdicts=verdicts,
                        scale=self.render_scale)

    # --- observation and info -------------------------------------------------------------------
    def _pose_obs(self, pose: Pose2D) -> np.ndarray:
        return np.clip(pose.as_array(), self._pose_low, self._pose_high).astype(np.float32)

    def _observation(self) -> dict:
        obs = {}
        for k, scan in enumerate(self._scans):
            r = np.where(np.isfinite(scan.ranges), scan.ranges, scan.range_max)
            obs["scan" if k == 0 else f"scan_{k}"] = np.clip(r, 0.0, scan.range_max).astype(
                np.float32)
        obs["odometry"] = self._pose_obs(self.world.odom_pose)
        obs["estimate"] = self._pose_obs(self.session.estimate())
        if self._map_observation:
            obs["map"] = trinary_image(self.session.updated_map)
        return obs

    def _info(self, scans: int) -> dict:
        world, session = self.world, self.session
        tally = session.tally
        return {
            "time": float(world.time),
            "true_pose": world.true_pose.as_array(),
            "estimated_pose": session.estimate().as_array(),
            "odometry_pose": world.odom_pose.as_array(),
            "localization_error": session.localization_error(),
            "cells_changed": tally.correct + tally.wrong,
            "correct_changes": tally.correct,
            "wrong_changes": tally.wrong,
            "updater_changed_cells": int(session.updater.n_changed),
            "collisions": int(world.collisions),
            "people_contacts": int(world.people_contacts),
            "scans": int(scans),
            "waypoints_reached": int(self._next_waypoint),
            "seed": self._seed,
        }


def _env_options(options, settings: dict) -> EnvOptions:
    """``options`` (an ``EnvOptions``, a mapping of its fields or None) with ``settings`` laid
    over it; an unknown name is refused in one line with the nearest setting's."""
    names = [f.name for f in fields(EnvOptions)]
    if isinstance(options, Mapping):
        settings = {**options, **settings}
        options = None
    elif options is not None and not isinstance(options, EnvOptions):
        raise EnvOptionsError(f"options must be an EnvOptions or a mapping of its fields, got "
                              f"{type(options).__name__}")
    for key in settings:
        if key not in names:
            hint = did_you_mean(key, names) or f" (settings: {', '.join(names)})"
            raise EnvOptionsError(f"WarehouseMapUpdateEnv: unknown setting {key!r}{hint}")
    return replace(EnvOptions() if options is None else options, **settings)


MAX_CONTROL_PERIOD = 60.0     # [s] an action held longer than a minute is a mistake (1e6 hangs)
MAX_RENDER_SIDE = 4096        # [px] the longest side of a rendered top view


def _real(value, name: str) -> float:
    """``value`` as a float; anything that is not a real number (or is a bool) is refused."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number, got {value!r}")
    return float(value)


def _check_arguments(*, control_period, map_seed, render_mode, render_modes, render_scale,
                     lost_distance, waypoint_tolerance, goal_tolerance) -> None:
    """Refuse a bad constructor argument, naming it and its value, before any work."""
    if control_period is not None:
        period = _real(control_period, "control_period")
        if not (math.isfinite(period) and 0.0 < period <= MAX_CONTROL_PERIOD):
            raise ValueError(f"control_period must be in (0, {MAX_CONTROL_PERIOD:g}] s, got "
                             f"{control_period!r}")
    if map_seed is not None and (isinstance(map_seed, bool)
                                 or not isinstance(map_seed, numbers.Integral) or map_seed < 0):
        raise ValueError(f"map_seed must be a non-negative integer, got {map_seed!r}")
    if render_mode is not None and render_mode not in render_modes:
        raise ValueError(f"render_mode {render_mode!r} is not one of {render_modes} or None")
    if isinstance(render_scale, bool) or not isinstance(render_scale, numbers.Integral) \
            or not 1 <= render_scale <= MAX_RENDER_SIDE:
        raise ValueError(f"render_scale must be a whole number of pixels per cell in "
                         f"[1, {MAX_RENDER_SIDE}], got {render_scale!r}")
    if math.isnan(_real(lost_distance, "lost_distance")) or lost_distance < 0:
        raise ValueError(f"lost_distance must be >= 0 m (inf: never lost), got "
                         f"{lost_distance!r}")
    for name, value in (("waypoint_tolerance", waypoint_tolerance),
                        ("goal_tolerance", goal_tolerance)):
        tol = _real(value, name)
        if not (math.isfinite(tol) and tol >= 0.0):
            raise ValueError(f"{name} must be a finite distance >= 0 m, got {value!r}")


def _check_render_size(scale: int, grid: OccupancyGrid) -> None:
    """Refuse a ``render_scale`` whose top view of ``grid`` would exceed ``MAX_RENDER_SIDE``."""
    cells = max(grid.width, grid.height)
    if scale * cells > MAX_RENDER_SIDE:
        raise ValueError(f"render_scale {scale} draws {scale * cells} px a side (the map is "
                         f"{cells} cells), over {MAX_RENDER_SIDE}; use at most "
                         f"{max(1, MAX_RENDER_SIDE // cells)}")


def _given_once(section: str, argument, from_config):
    if argument is not None and from_config is not None:
        raise ConfigError(f"the {section} configuration is given twice: as {section}_config= "
                          f"and as config['{section}']")
    return from_config if argument is None else argument


def _load_scenario(scenario, quick: bool):
    scn = scenario if isinstance(scenario, sim.Scenario) else \
        sim.load_scenario(find_scenario(scenario))
    return sim.quick_variant(scn) if quick else scn


def _load_grid(value, name: str) -> OccupancyGrid | None:
    if value is None or isinstance(value, OccupancyGrid):
        return value
    if isinstance(value, (str, Path)):
        return load_map(value)
    raise TypeError(f"{name} must be an OccupancyGrid or a map_server YAML path, got "
                    f"{type(value).__name__}")
