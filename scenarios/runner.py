"""The session runner: the experiment of the paper's section V, session after session.

W1 builds M1 by log-odds mapping with true poses. Each later session i applies its changes,
lets the people walk and drives the robot along its route; the Monte Carlo localiser runs on
M_{i-1} (and, with the same seed, on M1 for the comparison); a fresh updater on M_{i-1} takes
the scan-time poses of the localiser on M_{i-1}, never the simulator's truth; its output is
committed as M_i and scored against the ground truth G_i.
"""

from __future__ import annotations

import datetime as _dt
import resource
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Protocol

import numpy as np

from gridmap import OccupancyGrid, Pose2D

from . import evaluation as ev
from .catalog import find_scenario

# The robot starts each session at its dock, whose pose is known to about this precision.
START_STD = (0.05, 0.05, 0.02)  # x [m], y [m], yaw [rad]


@dataclass
class RunOptions:
    out: Path | None = None
    seed: int | None = None
    sessions: int | None = None
    quick: bool = False
    progress: bool = True
    updater_config: object | None = None
    localizer_config: object | None = None
    observer: SessionObserver | None = None   # told of every update session's scans
    # The safeguard against mislocalisation (localization.confidence): scans whose pose the
    # localiser's covariance or the scan's own fit to M_{i-1} calls unsure change nothing.
    pose_check: bool = False
    pose_check_config: object | None = None   # a localization.confidence.PoseCheckConfig
    resume: bool = False       # continue the run in ``out`` after its last finished session


class SessionObserver(Protocol):
    """What ``RunOptions.observer`` is told, e.g. to record a run (``rerun_log``). Its calls
    happen outside the timed parts of the session, so its cost never shows in the scores."""

    def session_start(self, scenario, session: int, world, previous: OccupancyGrid,
                      initial: OccupancyGrid, updater, localizer) -> None: ...

    def scan(self, msg, estimate: Pose2D, report, world, updater, localizer) -> None: ...

    def session_end(self, result: SessionResult) -> None: ...


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
    name: str
    updated: OccupancyGrid                 # M_i
    truth: OccupancyGrid                   # G_i
    previous: OccupancyGrid | None = None  # M_{i-1}
    oracle: OccupancyGrid | None = None
    trajectory: Trajectory | None = None
    metrics: dict = field(default_factory=dict)
    masks: dict = field(default_factory=dict)  # per-cell arrays: observable, people, ...


@dataclass
class RunResult:
    scenario: str
    seed: int
    out_dir: Path
    sessions: list[SessionResult]
    metrics: dict


def _session_seeds(seed: int, n_sessions: int) -> list[dict[str, np.random.SeedSequence]]:
    """One SeedSequence per component and session, so any session can be re-run alone."""
    out = []
    for seq in np.random.SeedSequence(seed).spawn(n_sessions):
        world, localizer, _spare = seq.spawn(3)
        out.append({"world": world, "localizer": localizer})
    return out


def _progress(enabled: bool, **kw):
    from tqdm import tqdm

    return tqdm(disable=not enabled, dynamic_ncols=True, leave=False, **kw)


def _route_length(route) -> float:
    pts = np.asarray(route, np.float64)
    return float(np.hypot(*np.diff(pts, axis=0).T).sum()) if len(pts) > 1 else 0.0


def build_initial_map(scenario, session: int, seeds: dict, progress: bool = False):
    """M1: log-odds mapping along the mapping route with the true sensor poses."""
    import sim
    from gridmap.mapping import LogOddsMapper

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
        "map_metrics": {"initial_vs_truth": _map_metrics(grid, world.ground_truth())},
        "resources": {"mapping_cpu_s": time.process_time() - t_cpu, "scans": n_scans},
    }
    return SessionResult(scenario.sessions[session].name, grid, world.ground_truth(),
                         metrics=metrics)


def _map_metrics(a: OccupancyGrid, b: OccupancyGrid) -> dict:
    from gridmap.metrics import compare_maps

    return {k: float(v) for k, v in compare_maps(a, b).items()}


def run_update_session(scenario, session: int, previous: OccupancyGrid, initial: OccupancyGrid,
                       seeds: dict, options: RunOptions) -> SessionResult:
    """One session i >= 2: localise, update M_{i-1} into M_i, score against G_i."""
    import sim
    from localization import MonteCarloLocalizer
    from localization.confidence import PoseCheck
    from updater import MapUpdater

    name = scenario.sessions[session].name
    world = sim.World(scenario, session, seeds["world"])
    truth = world.ground_truth()
    frame = sim.grid_frame(scenario)
    mounts = [lidar.mount for lidar in scenario.robot.lidars]

    start = world.true_pose
    cov = np.diag(np.square(START_STD))
    loc_prev = MonteCarloLocalizer(previous, options.localizer_config, seed=seeds["localizer"])
    loc_init = MonteCarloLocalizer(initial, options.localizer_config, seed=seeds["localizer"])
    loc_prev.initialize(start, cov)
    loc_init.initialize(start, cov)
    upd = MapUpdater(previous, options.updater_config)
    guard = PoseCheck(previous, options.pose_check_config) if options.pose_check else None
    observer = options.observer
    if observer is not None:
        observer.session_start(scenario, session, world, previous, initial, upd, loc_prev)
    counter = ev.ObservationCounter(frame)
    people_mask = np.zeros(frame.shape, bool)
    traj = Trajectory()
    cpu = {"localizer_s": 0.0, "localizer_initial_map_s": 0.0, "updater_s": 0.0}
    counts = {"scans": 0, "scans_processed": 0, "scans_dropped_as_lost": 0,
              "scans_refused_by_pose_check": 0, "localizer_updates": 0}

    expected = _route_length(scenario.sessions[session].route) / scenario.robot.max_speed
    with _progress(options.progress, desc=f"{name}", unit="sim-s", total=round(expected)) as bar:
        for msg in world.run():
            if not isinstance(msg, sim.ScanMsg):
                continue
            mount = mounts[msg.lidar]
            t0 = time.process_time()
            counts["localizer_updates"] += bool(loc_prev.update(msg.odom_pose, msg.scan, mount))
            est_prev = loc_prev.estimate().pose_at(msg.odom_pose)
            t1 = time.process_time()
            loc_init.update(msg.odom_pose, msg.scan, mount)
            est_init = loc_init.estimate().pose_at(msg.odom_pose)
            t2 = time.process_time()
            # asked by the updater only for scans that pass its gate
            check = None if guard is None else partial(guard.check, msg.scan, est_prev, mount,
                                                       loc_prev.estimate().cov)
            report = upd.process(msg.scan, est_prev.compose(mount), odometry=msg.odom_pose,
                                 pose_check=check)
            t3 = time.process_time()
            cpu["localizer_s"] += t1 - t0
            cpu["localizer_initial_map_s"] += t2 - t1
            cpu["updater_s"] += t3 - t2
            counts["scans"] += 1
            counts["scans_dropped_as_lost"] += bool(report.dropped_as_lost)
            counts["scans_refused_by_pose_check"] += report.reason.startswith("pose unsure")
            if report.processed:
                counts["scans_processed"] += 1
                clean = world.scan_without_people(msg.true_pose, msg.lidar)
                counter.add_scan(msg.true_pose.compose(mount), clean.ranges, clean.angles())
            ev.paint_people(people_mask, frame, world.people())
            traj.add(msg.time, msg.true_pose, est_prev, est_init)
            if observer is not None:
                observer.scan(msg, est_prev, report, world, upd, loc_prev)
            bar.update(max(0.0, round(msg.time) - bar.n))

    updated = upd.updated_map()
    observable = counter.observable()
    oracle = ev.oracle_map(previous, truth, observable)
    arr = traj.arrays()
    metrics = {
        "name": name,
        "map_metrics": {
            "previous_vs_truth": _map_metrics(previous, truth),
            "updated_vs_truth": _map_metrics(updated, truth),
            "oracle_vs_truth": _map_metrics(oracle, truth),
        },
        "change_detection": ev.change_detection(previous, updated, truth, observable),
        "ghost_cells": ev.ghost_cells(updated, truth, people_mask),
        "localization": {
            "initial_map": ev.ape_statistics(arr["initial_map"][:, :2], arr["true"][:, :2]),
            "previous_map": ev.ape_statistics(arr["previous_map"][:, :2], arr["true"][:, :2]),
        },
        "resources": {
            "updater_cpu_s": cpu["updater_s"],
            "localizer_cpu_s": cpu["localizer_s"],
            "localizer_initial_map_cpu_s": cpu["localizer_initial_map_s"],
            "updater_state_bytes": int(getattr(upd, "state_bytes", lambda: 0)()),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "simulated_s": float(arr["time"][-1]) if len(arr["time"]) else 0.0,
            **counts,
        },
    }
    result = SessionResult(name, updated, truth, previous=previous, oracle=oracle,
                           trajectory=traj, metrics=metrics,
                           masks={"observable": observable, "people": people_mask,
                                  "observations": counter.counts})
    if observer is not None:
        observer.session_end(result)
    return result


def default_out_dir(scenario_name: str) -> Path:
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"{scenario_name}-{stamp}"


def run_scenario(scenario: str | Path | None = None, options: RunOptions | None = None) -> RunResult:
    """Play every session of a scenario, write the outputs and return the results."""
    import sim

    from . import checkpoint
    from .report import write_outputs, write_session_maps

    options = options or RunOptions()
    if options.resume:
        scenario, options = checkpoint.resume_options(scenario, options)
    path = find_scenario(scenario)
    scn = sim.load_scenario(path)
    if options.quick:
        scn = sim.quick_variant(scn)
    seed = scn.seed if options.seed is None else options.seed
    n = len(scn.sessions) if options.sessions is None else max(1, min(options.sessions,
                                                                       len(scn.sessions)))
    out_dir = Path(options.out) if options.out else default_out_dir(scn.name)
    out_dir.mkdir(parents=True, exist_ok=True)
    seeds = _session_seeds(seed, len(scn.sessions))
    wall0 = time.perf_counter()

    results: list[SessionResult] = []
    wall_before = 0.0
    if options.resume:
        results, wall_before = checkpoint.finished_sessions(out_dir, scn, n)
    else:
        checkpoint.write_manifest(out_dir, path, seed, options)
    with _progress(options.progress, desc="sessions", total=n, unit="session",
                   initial=len(results)) as bar:
        for i in range(len(results), n):
            if i == 0:
                res = build_initial_map(scn, 0, seeds[0], options.progress)
            else:
                res = run_update_session(scn, i, results[-1].updated, results[0].updated,
                                         seeds[i], options)
            write_session_maps(out_dir, res)
            results.append(res)
            checkpoint.save_session(out_dir, results, wall_before + time.perf_counter() - wall0)
            bar.update(1)

    metrics = {
        "scenario": scn.name, "seed": seed, "quick": options.quick,
        "sessions": [r.metrics for r in results],
        "wall_time_s": wall_before + time.perf_counter() - wall0,
    }
    run = RunResult(scn.name, seed, out_dir, results, metrics)
    write_outputs(run)
    return run
