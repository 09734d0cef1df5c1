"""The session runner: the experiment of the paper's section V, session after session.

W1 builds M1 by log-odds mapping with true poses. Each later session i applies its changes,
lets the people walk and drives the robot along its route; the Monte Carlo localiser runs on
M_{i-1} (and, with the same seed, on M1 for the comparison); a fresh updater on M_{i-1} takes
the scan-time poses of the localiser on M_{i-1}, never the simulator's truth; its output is
committed as M_i and scored against the ground truth G_i.
"""

from __future__ import annotations

import datetime as _dt
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

import sim
from gridmap import OccupancyGrid
from gridmap.config import DEFAULT_PROFILE, check_profile
from gridmap.mapping import LogOddsMapper
from localization import LocalizerConfig
from localization.confidence import PoseCheckConfig
from onboard.robot_config import POSE_CHECK_ON, differences
from updater import UpdaterConfig

from . import checkpoint
from .catalog import find_scenario
from .options import RunError, RunOptions, SessionObserver
from .report import write_outputs, write_session_maps, write_session_outputs
from .session import (SessionResult, UpdateSession, localizer_config_for, map_metrics,
                      session_seeds)

MAX_SEED = 2**63 - 1

__all__ = ["RunOptions", "RunResult", "SessionObserver", "build_initial_map", "run_scenario",
           "run_update_session"]


@dataclass
class RunResult:
    """A played run. ``sessions`` has one ``SessionResult`` per session, in order, but keeps
    whole only what the run's memory can afford whatever the number of sessions:

    - ``sessions[0]`` (W1): its name, metrics and M1 (``updated``), on which every later
      session localises; G1 is dropped once the next session starts;
    - ``sessions[-1]``: the last session's full result (M_i, G_i, M_{i-1}, the oracle, the
      trajectories, the evaluation masks);
    - every session between: a light result, its name and metrics only.

    A run of one session keeps it whole. What a light result dropped is in ``out_dir``
    (``maps/M_<name>.yaml``, ``maps/G_<name>.yaml``, ``maps/masks_<name>.npz``,
    ``trajectories/``); ``metrics`` is ``metrics.json``, with every session's entry.
    """

    scenario: str
    seed: int
    out_dir: Path
    sessions: list[SessionResult]
    metrics: dict


def _progress(enabled: bool, **kw):
    return tqdm(disable=not enabled, dynamic_ncols=True, leave=False, **kw)


def _route_length(route) -> float:
    pts = np.asarray(route, np.float64)
    return float(np.hypot(*np.diff(pts, axis=0).T).sum()) if len(pts) > 1 else 0.0


def build_initial_map(scenario, session: int, seeds: dict, progress: bool = False):
    """M1: log-odds mapping along the mapping route with the true sensor poses."""
    world = sim.World(scenario, session, seeds["world"])
    mapper = LogOddsMapper(sim.grid_frame(scenario))
    mounts = [lidar.mount for lidar in scenario.robot.lidars]
    t_cpu = time.process_time()
    n_scans = 0
    with _progress(progress, desc=f"{scenario.sessions[session].name} mapping",
                   unit="sim-s") as bar:
        for msg in world.run():
            if isinstance(msg, sim.ScanMsg):
                mapper.add_scan(msg.scan, msg.true_pose.compose(mounts[msg.lidar]))
                n_scans += 1
                bar.update(max(0.0, msg.time - bar.n))
    grid = mapper.to_grid()
    metrics = {
        "name": scenario.sessions[session].name,
        "map_metrics": {"initial_vs_truth": map_metrics(grid, world.ground_truth())},
        "resources": {"mapping_cpu_s": time.process_time() - t_cpu, "scans": n_scans},
    }
    return SessionResult(scenario.sessions[session].name, grid, world.ground_truth(),
                         metrics=metrics)


def run_update_session(scenario, session: int, previous: OccupancyGrid, initial: OccupancyGrid,
                       seeds: dict, options: RunOptions, faces=None) -> SessionResult:
    """One session i >= 2: the robot follows its route; localise, update M_{i-1} into M_i,
    score against G_i. ``faces``: what the updater of session i - 1 carried over
    (``SessionResult.faces``)."""
    world = sim.World(scenario, session, seeds["world"])
    options = resolve_profile(scenario, options)
    compare = options.compare_paper and options.profile != "paper" and options.method == "paper"
    us = UpdateSession(scenario, session, world, previous, initial, seeds["localizer"],
                       options.updater_config, options.localizer_config,
                       pose_check=options.pose_check and (options.pose_check_config or True),
                       method=options.method,
                       comparison=UpdaterConfig.profile("paper") if compare else None,
                       faces=faces)
    observer = options.observer
    if observer is not None:
        observer.session_start(scenario, session, world, previous, initial, us.updater,
                               us.localizer)
    expected = _route_length(scenario.sessions[session].route) / scenario.robot.max_speed
    with _progress(options.progress, desc=us.name, unit="sim-s", total=round(expected)) as bar:
        for msg in world.run():
            if not isinstance(msg, sim.ScanMsg):
                continue
            report = us.add_scan(msg)
            if observer is not None:
                observer.scan(msg, us.last_estimate, report, world, us.updater, us.localizer)
            bar.update(max(0.0, round(msg.time) - bar.n))
    result = us.result()
    if observer is not None:
        observer.session_end(result)
    return result


def resolve_profile(scenario, options: RunOptions) -> RunOptions:
    """``options`` with every configuration left None (or given as a mapping of keys) made
    the profile's: the updater's, the pose check's and whether it runs, and the localiser's
    with the scenario's odometry noise as its alphas (the robot's own, as one tunes AMCL's
    alphas for a robot) and the keys given laid over it."""
    profile = options.profile or DEFAULT_PROFILE
    check_profile(profile, RunError, "profile")
    loc = options.localizer_config
    if loc is None or isinstance(loc, dict):
        alphas = localizer_config_for(scenario)
        base = {k: getattr(alphas, k) for k in ("alpha1", "alpha2", "alpha3", "alpha4")}
        loc = LocalizerConfig.profile(profile, {**base, **(loc or {})})
    return replace(
        options, profile=profile, localizer_config=loc,
        updater_config=options.updater_config or UpdaterConfig.profile(profile),
        pose_check_config=options.pose_check_config or PoseCheckConfig.profile(profile),
        pose_check=POSE_CHECK_ON[profile][0] if options.pose_check is None
        else options.pose_check)


def light_result(res: SessionResult, keep_map: bool = False) -> SessionResult:
    """``res`` as a run keeps it once its outputs are on disk: name and metrics, and M_i (with
    what its updater carries over) if ``keep_map``. A new object, so whoever else holds ``res`` (an observer) still has it whole."""
    return SessionResult(res.name, res.updated if keep_map else None, None,
                         metrics=res.metrics, faces=res.faces if keep_map else None)


def default_out_dir(scenario_name: str) -> Path:
    """``runs/<scenario>-<time>``, with a number added when a run started in the same second
    (the scenario's name is checked to be fit for a file name when the scenario is read)."""
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    out = Path("runs") / f"{scenario_name}-{stamp}"
    k = 2
    while out.exists():
        out, k = Path("runs") / f"{scenario_name}-{stamp}-{k}", k + 1
    return out


def run_scenario(scenario: str | Path | None = None, options: RunOptions | None = None) -> RunResult:
    """Play every session of a scenario, write the outputs and return the results."""
    options = options or RunOptions()
    check_options(options)
    if options.resume:
        scenario, options = checkpoint.resume_options(scenario, options)
    elif options.out:
        checkpoint.check_new_run_folder(options.out)     # refused before anything is read
    path = find_scenario(scenario)
    scn = sim.load_scenario(path)
    if options.quick:
        scn = sim.quick_variant(scn)
    options = resolve_profile(scn, options)
    seed = scn.seed if options.seed is None else options.seed
    n = len(scn.sessions) if options.sessions is None else max(1, min(options.sessions,
                                                                       len(scn.sessions)))
    out_dir = Path(options.out) if options.out else default_out_dir(scn.name)
    out_dir.mkdir(parents=True, exist_ok=True)
    with checkpoint.RunFolderLock(out_dir):
        if not options.resume:       # again, now that no other run can start here
            checkpoint.check_new_run_folder(out_dir)
        return _play(scn, path, seed, n, out_dir, options)


def check_options(options: RunOptions) -> None:
    """Options no run can have, refused before anything is read or written."""
    if options.sessions is not None and (isinstance(options.sessions, bool) or
                                         not isinstance(options.sessions, int) or
                                         options.sessions < 1):
        raise RunError(f"sessions must be a whole number of at least 1, got {options.sessions!r}")
    if options.seed is not None and (isinstance(options.seed, bool) or
                                     not isinstance(options.seed, int) or
                                     not 0 <= options.seed <= MAX_SEED):
        raise RunError(f"seed must be a whole number in [0, {MAX_SEED}], got {options.seed!r}")


def _play(scn, path: Path, seed: int, n: int, out_dir: Path, options: RunOptions) -> RunResult:
    """The sessions of a run whose folder is locked (see ``run_scenario``)."""
    seeds = session_seeds(seed, len(scn.sessions))
    wall0 = time.perf_counter()

    results: list[SessionResult] = []
    wall_before = 0.0
    if options.resume:
        checkpoint.remove_partial_files(out_dir)     # what the killed run was writing
        results, wall_before = checkpoint.finished_sessions(out_dir, scn, n)
        checkpoint.restore_session_outputs(out_dir, [r.name for r in results])
    else:
        checkpoint.write_manifest(out_dir, path, seed, options)
    # Memory per session is bounded: a finished session's outputs go to disk at once, and the
    # run keeps of it only what later sessions need (see RunResult).
    with _progress(options.progress, desc="sessions", total=n, unit="session",
                   initial=len(results)) as bar:
        for i in range(len(results), n):
            if i == 0:
                res = build_initial_map(scn, 0, seeds[0], options.progress)
            else:
                # M_{i-1} is all this session needs of the last one
                results[-1] = light_result(results[-1], keep_map=True)
                res = run_update_session(scn, i, results[-1].updated, results[0].updated,
                                         seeds[i], options, results[-1].faces)
            # everything of the session on disk before save_session commits it
            write_session_maps(out_dir, res)
            write_session_outputs(out_dir, res)
            results.append(res)
            checkpoint.save_session(out_dir, results, wall_before + time.perf_counter() - wall0)
            if len(results) > 2:   # the one before: name and metrics (M_{i-1} is res.previous)
                results[-2] = light_result(results[-2])
            bar.update(1)

    metrics = {
        "scenario": scn.name, "seed": seed, "quick": options.quick, "method": options.method,
        "profile": options.profile, "differences": differences(
            options.profile, options.updater_config, options.localizer_config,
            options.pose_check_config),
        "pose_check": options.pose_check,
        "sessions": [r.metrics for r in results],
        "wall_time_s": wall_before + time.perf_counter() - wall0,
    }
    run = RunResult(scn.name, seed, out_dir, results, metrics)
    write_outputs(run)
    return run
