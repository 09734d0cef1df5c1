"""Several robots, one map: a fleet of N robots in one warehouse session, each with its own
lidar, odometry noise, localiser and start on a one-way loop, seeing each other as moving
obstacles, and one of two ways to update the map they share (``scenarios.fleet_store``):

- ``shared``: one updater fed every robot's scans in scan-time order through a ``ScanQueue``,
  a gate per robot in front of it;
- ``per-robot``: one updater each, their maps merged at commit (``merge_rule``: ``vote`` or
  ``union``, see ``merge_maps``);
- ``store``: one updater each, as robots with the live node: each commits its map to a map
  store (``FleetOptions.store``: an SQLite file or a PostgreSQL URL) every
  ``commit_interval`` seconds and at the end of the session, the store merges it with what
  the others committed meanwhile, and each takes up the site's newer versions every
  ``poll_interval`` seconds.

A run maps the warehouse in W1 with one robot (as ``mapupdate run`` does) and then plays the
update sessions with the fleet, each from the last session's map, scoring each session as the
single robot's (precision, recall, OPDF, ghosts) and by how soon the map showed each target
cell right. Results and the choice between the modes: docs/fleet.md.

    python -m scenarios.fleet --robots 3 --mode shared --out runs/fleet3
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

import evaluation as ev
import sim
from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D
from gridmap.config import DEFAULT_PROFILE, check_profile
from gridmap.map_io import save_map
from localization import LocalizerConfig, MonteCarloLocalizer
from localization.confidence import PoseCheck, PoseCheckConfig
from onboard.pipeline import RobotPipeline
from onboard.ros_common.store_link import rebased
from onboard.robot_config import POSE_CHECK_ON
from sim.fleet import FleetMember, FleetWorld
from updater import MapUpdater, UpdaterConfig

from .catalog import find_scenario
from .fleet_store import (FleetBoard, RobotMask, ScanQueue, SharedGate, check_merge_rule,
                          merge_maps, shared_updater)
from .runner import build_initial_map
from .session import START_STD, localizer_config_for, map_metrics, session_seeds

MODES = ("shared", "per-robot", "store")
MAX_ROBOTS = 8
PROBE_INTERVAL = 1.0   # [s] of simulated time between looks at the map, for the latencies
# [s] of simulated time: a robot of the store mode commits this often and looks for the
# site's newer versions this often (the live node's store_poll_period is 10 s; a fleet
# session of the quick routes lasts a minute or two)
COMMIT_INTERVAL = 30.0
POLL_INTERVAL = 10.0
UPLINK_INTERVAL = 1.0  # [s] a robot uploads its scans in batches this far apart

# One-way loops: the transport loop of the built-in warehouse rearranged so that no two legs
# meet head on or cross (robots yield to robots ahead of them, and two robots that each see
# the other ahead would wait for ever): up the centre aisle's east lane, down its west lane,
# across at y = -1, up the rack aisle's east lane, down its west lane to the south end, back
# up the east lane to y = -4.6 and across to the dock. Parallel lanes are 0.9 m or more apart,
# more than two robots' radii and their margin.
FLEET_LOOPS = {
    "aws_small_warehouse": ((0.0, -8.0), (1.5, -7.0), (1.5, 7.0), (0.4, 7.0), (0.4, -1.0),
                            (-3.05, -1.0), (-3.05, 8.6), (-3.95, 8.6), (-3.95, -8.6),
                            (-3.05, -8.6), (-3.05, -4.6), (0.0, -4.6), (0.0, -8.0)),
}


# --- routes ---------------------------------------------------------------------------------------
def fleet_loop(scenario, session: int, quick: bool = False) -> np.ndarray:
    """(K, 2) closed loop from the robot's start back to it: the scenario's one-way fleet loop,
    or (``quick``, or a scenario without one) the session's route closed at the start."""
    st = scenario.robot.start
    if not quick and scenario.name in FLEET_LOOPS:
        return np.asarray(FLEET_LOOPS[scenario.name], np.float64)
    spec = scenario.sessions[session]
    route = spec.quick_route if quick and getattr(spec, "quick_route", None) else spec.route
    pts = np.vstack([[st.x, st.y], np.asarray(route, np.float64)])
    if np.hypot(*(pts[-1] - pts[0])) > 1e-6:
        pts = np.vstack([pts, pts[:1]])
    return pts


def fleet_members(scenario, session: int, n: int, quick: bool = False) -> list[FleetMember]:
    """``n`` robots spread evenly along the fleet loop, each driving it once round from where
    it starts; robot 0 starts at the dock as the single robot does. Their lidars fire a
    ``1 / (n * rate)`` apart, as unsynchronised clocks do."""
    loop = fleet_loop(scenario, session, quick)
    seg = np.hypot(*np.diff(loop, axis=0).T)
    ends = np.cumsum(seg)
    total = float(ends[-1])
    rate = scenario.robot.lidars[0].rate_hz
    out = []
    for k in range(n):
        s = total * k / n
        j = min(int(np.searchsorted(ends, s, side="right")), len(seg) - 1)
        u = (s - (ends[j] - seg[j])) / max(seg[j], 1e-12)
        xy = loop[j] + u * (loop[j + 1] - loop[j])
        heading = math.atan2(*(loop[j + 1] - loop[j])[::-1])
        start = scenario.robot.start if k == 0 else Pose2D(float(xy[0]), float(xy[1]), heading)
        route = [tuple(p) for p in loop[j + 1:]] + [tuple(p) for p in loop[1:j + 1]]
        if k:
            route.append((float(xy[0]), float(xy[1])))
        out.append(FleetMember(start, tuple(route), lidar_phase=k / (n * rate)))
    return out


# --- one robot ------------------------------------------------------------------------------------
class FleetRobot:
    """One robot's software: its localiser on M_{i-1}, its pose check, its pipeline into its
    own updater or into the shared one, what its own processed scans saw (for the vote of the
    merge), and its trajectory."""

    def __init__(self, scenario, reference: OccupancyGrid, start: Pose2D, seed, updater,
                 count_views: bool, board: FleetBoard | None = None, index: int = 0,
                 profile: str = DEFAULT_PROFILE):
        alphas = localizer_config_for(scenario)
        config = LocalizerConfig.profile(profile, {k: getattr(alphas, k) for k in (
            "alpha1", "alpha2", "alpha3", "alpha4")})
        self.localizer = MonteCarloLocalizer(reference, config, seed=seed)
        self.localizer.initialize(start, np.diag(np.square(START_STD)))
        self.board, self.index = board, index
        self.updater = updater if board is None else RobotMask(updater, index, board)
        # the check of the profile, as the runner's sessions have it
        check = PoseCheck(reference, PoseCheckConfig.profile(profile).for_poses(
            own_localizer=True)) if POSE_CHECK_ON[profile][0] else None
        self.pipeline = RobotPipeline(self.updater, self.localizer, check)
        self.profile = profile
        self.version: int | None = None      # the store mode: the version the robot is on
        self.processed_before = 0             # scans its earlier pipelines processed
        self.views = ev.ObservationCounter(reference) if count_views else None
        self.true: list = []
        self.estimated: list = []

    def step(self, msg, mount: Pose2D):
        step = self.pipeline.step(msg.scan, mount, odometry=msg.odom_pose)
        self.true.append(msg.true_pose.as_array()[:2])
        self.estimated.append(step.robot_pose.as_array()[:2])
        if self.board is not None:
            self.board.report(self.index, step.robot_pose)
        report = step.report
        if self.views is not None and report is not None and report.processed \
                and not report.dropped_as_lost:
            self.views.add_scan(report.sensor_pose, msg.scan.ranges.astype(np.float64),
                                msg.scan.angles())
        return report

    def adopt(self, reference: OccupancyGrid, config: UpdaterConfig) -> None:
        """Go on from ``reference`` (a version of the store), buffers afresh, as the live
        node does when it takes up a newer version; the localiser keeps its map."""
        self.processed_before += self.pipeline.counts.scans_processed
        updater = MapUpdater(reference, config)
        self.updater = updater if self.board is None else RobotMask(updater, self.index,
                                                                    self.board)
        check = PoseCheck(reference, PoseCheckConfig.profile(self.profile).for_poses(
            own_localizer=True)) if POSE_CHECK_ON[self.profile][0] else None
        self.pipeline = RobotPipeline(self.updater, self.localizer, check)

    def ape_rmse(self) -> float:
        return ev.ape_statistics(np.asarray(self.estimated), np.asarray(self.true))["rmse"]


# --- one session ----------------------------------------------------------------------------------
@dataclass
class FleetOptions:
    """What a fleet run plays: how many robots, which way they update the map, and the run's
    usual knobs."""

    robots: int = 2
    mode: str = "shared"
    merge_rule: str = "vote"            # per-robot mode only
    mask_robots: bool = True            # hide the other robots from the map update
    quick: bool = False
    sessions: int | None = None         # W1 and this many minus one update sessions
    seed: int | None = None
    updater_config: UpdaterConfig | None = None     # None: the profile's
    profile: str = DEFAULT_PROFILE      # the defaults of the robots' software
    progress: bool = True
    probe_interval: float = PROBE_INTERVAL
    uplink_interval: float = UPLINK_INTERVAL
    store: str | None = None            # the store mode's map store (a file or a URL)
    commit_interval: float = COMMIT_INTERVAL
    poll_interval: float = POLL_INTERVAL

    def check(self) -> None:
        if isinstance(self.robots, bool) or not isinstance(self.robots, int) \
                or not 1 <= self.robots <= MAX_ROBOTS:
            raise ValueError(f"robots must be a whole number in 1..{MAX_ROBOTS}, "
                             f"got {self.robots!r}")
        if self.mode not in MODES:
            raise ValueError(f"unknown mode {self.mode!r} (modes: {', '.join(MODES)})")
        check_merge_rule(self.merge_rule)
        check_profile(self.profile, ValueError, "--profile")
        if (self.mode == "store") != (self.store is not None):
            raise ValueError("the store mode needs a store (--store) and a store needs the "
                             "store mode" if self.mode == "store" else
                             f"--store goes with the store mode, not --mode {self.mode}")


class FleetSession:
    """One update session of a fleet: messages in (``arrive``, in world time order), through
    the robots' uplinks and the scan-time queue into the robots' pipelines; the map looked at
    every ``probe_interval`` for the latencies; ``result`` at the end."""

    def __init__(self, scenario, session: int, world: FleetWorld, reference: OccupancyGrid,
                 localizer_seed, options: FleetOptions):
        self.scenario, self.world, self.options = scenario, world, options
        self.name = scenario.sessions[session].name
        self.reference, self.truth = reference, world.ground_truth()
        self.mounts = [ld.mount for ld in scenario.robot.lidars]
        cfg = options.updater_config or UpdaterConfig.profile(options.profile)
        self.threshold = cfg.threshold
        self.shared = shared_updater(reference, cfg) if options.mode == "shared" else None
        self.board = FleetBoard(len(world.members), scenario.robot.radius) \
            if options.mask_robots else None
        self.robots = []
        for k, member in enumerate(world.members):
            seed = localizer_seed if k == 0 else np.random.SeedSequence(
                localizer_seed.entropy, spawn_key=tuple(localizer_seed.spawn_key) + (k,))
            upd = SharedGate(self.shared, cfg) if self.shared else MapUpdater(reference, cfg)
            self.robots.append(FleetRobot(scenario, reference, member.start, seed, upd,
                                          count_views=options.mode == "per-robot"
                                          and options.merge_rule == "vote",
                                          board=self.board, index=k,
                                          profile=options.profile))
        self.config = cfg
        self.site = reference                # the store mode: the site's latest version
        self.store_counts = {"commits": 0, "merges": 0, "conflicts": 0, "taken": 0}
        self.store_s = 0.0
        if options.mode == "store":         # the site's latest version, scored against
            self._join_store(reference)
            reference = self.reference = self.site
        self.queue = ScanQueue(len(self.robots))
        self._outbox = [[] for _ in self.robots]
        n = len(self.robots)
        self._next_upload = [options.uplink_interval * (1 + k / n) for k in range(n)]
        self.counter = ev.ObservationCounter(reference)
        self.people_mask = np.zeros(reference.shape, bool)
        self.robot_mask = np.zeros(reference.shape, bool)
        self._wrong_occ, self._wrong_free = ev.wrong_cells(reference, self.truth)
        self.first_right = np.full(reference.shape, np.inf)
        self._next_probe = 0.0
        self.handled: list[tuple[float, int]] = []    # (time, robot) in the order handled
        self.cpu_s = 0.0

    # --- messages -----------------------------------------------------------------------------
    def arrive(self, k: int, msg) -> None:
        """A world message of robot ``k``, while the world is at its time."""
        ev.paint_people(self.people_mask, self.reference, self.world.people())
        ev.paint_people(self.robot_mask, self.reference, self.world.robot_discs())
        if not isinstance(msg, sim.ScanMsg):
            return
        self._outbox[k].append(msg)
        if msg.time >= self._next_upload[k]:
            self._upload(k)
            self._next_upload[k] += self.options.uplink_interval
            self._handle(self.queue.pop_ready())

    def _upload(self, k: int) -> None:
        for msg in self._outbox[k]:
            self.queue.push(k, msg.time, msg)
        self._outbox[k].clear()

    def finish(self) -> None:
        """The end of the session: every robot's last batch, and the queue emptied; in the
        store mode every robot commits what it has."""
        for k in range(len(self.robots)):
            self._upload(k)
        self._handle(self.queue.drain())
        if self.options.mode == "store":
            for k in range(len(self.robots)):
                self._commit(k)
        self._probe(math.inf)

    # --- the store mode ------------------------------------------------------------------------
    def _join_store(self, reference: OccupancyGrid) -> None:
        """Each robot starts from the store's latest approved version (an empty store takes
        ``reference`` as its first map, once)."""
        from mapstore import open_store
        t0 = time.perf_counter()
        with open_store(self.options.store, create=True) as store:
            latest = store.latest()
            if latest is None:
                latest = store.commit(reference, None, {"method": "import", "source":
                                                        "fleet W1", "robot": "robot1"})
            self.site = store.get(latest)
        for robot in self.robots:
            robot.version = latest
            robot.adopt(self.site, self.config)
        n = len(self.robots)
        self._next_commit = [self.options.commit_interval * (1 + k / n) for k in range(n)]
        self._next_poll = [self.options.poll_interval] * n
        self.store_s += time.perf_counter() - t0

    def _store_turn(self, k: int, t: float) -> None:
        if t >= self._next_commit[k]:
            self._commit(k)
            self._next_commit[k] += self.options.commit_interval
        elif t >= self._next_poll[k]:
            self._poll(k)
            self._next_poll[k] += self.options.poll_interval

    def _commit(self, k: int) -> None:
        """Robot ``k`` commits its map on the version it is on; the store merges it with the
        site's latest when that moved on, and the robot goes on from the result."""
        from mapstore import open_store
        robot, t0 = self.robots[k], time.perf_counter()
        updated = robot.updater.updated_map()
        if np.array_equal(updated.data, self._reference_of(robot).data):
            return self._poll(k)                # nothing new to commit
        with open_store(self.options.store) as store:
            number = store.commit(updated, robot.version, {
                "robot": f"robot{k + 1}", "method": f"fleet, {self.options.profile} profile",
                "session": self.name, "scans": robot.pipeline.counts.as_dict()})
            merged = store.merged
            robot.version = number if merged is None else merged
            mine = store.get(robot.version)
            if merged is not None:
                self.store_counts["merges"] += 1
                self.store_counts["conflicts"] += len(store.conflicts(merged))
            self.site = store.get(store.latest())
        self.store_counts["commits"] += 1
        robot.adopt(mine, self.config)
        self.store_s += time.perf_counter() - t0

    def _reference_of(self, robot) -> OccupancyGrid:
        inner = robot.updater.inner if self.board is not None else robot.updater
        return inner.reference_map

    def _poll(self, k: int) -> None:
        from mapstore import open_store
        robot, t0 = self.robots[k], time.perf_counter()
        with open_store(self.options.store) as store:
            latest = store.latest()
            if latest is not None and latest > robot.version:
                grid, updated = store.get(latest), robot.updater.updated_map()
                if not np.array_equal(updated.data, self._reference_of(robot).data):
                    # changes not committed yet: laid on the newer version, as the node does
                    grid = grid.with_data(rebased(store.get(robot.version).data, grid.data,
                                                  updated.data))
                robot.version = latest
                robot.adopt(grid, self.config)
                self.store_counts["taken"] += 1
        self.store_s += time.perf_counter() - t0

    def _handle(self, ready) -> None:
        t0 = time.process_time()
        for k, t, msg in ready:
            if t >= self._next_probe:
                self._probe(t)
            report = self.robots[k].step(msg, self.mounts[msg.lidar])
            self.handled.append((t, k))
            if self.options.mode == "store":
                self._store_turn(k, t)
            if report is not None and report.processed:
                clean = self.world.scan_without_people(msg.true_pose, msg.lidar)
                self.counter.add_scan(msg.true_pose.compose(self.mounts[msg.lidar]),
                                      clean.ranges, clean.angles())
        self.cpu_s += time.process_time() - t0

    # --- the map -----------------------------------------------------------------------------
    def current_map(self) -> OccupancyGrid:
        """The fleet's map now: the shared updater's, or the merge of the robots' maps."""
        if self.shared is not None:
            return self.shared.updated_map()
        if self.options.mode == "store":
            return self.site
        maps = [r.updater.updated_map() for r in self.robots]
        views = None if self.options.merge_rule == "union" else \
            [r.views.counts for r in self.robots]
        return merge_maps(self.reference, maps, views, self.threshold)

    def _probe(self, t: float) -> None:
        m = self.current_map().data
        right = (self._wrong_occ & (m == FREE)) | (self._wrong_free & ev.near(m == OCCUPIED))
        t_end = self.handled[-1][0] if self.handled else 0.0
        newly = right & np.isinf(self.first_right)
        self.first_right[newly] = min(t, t_end)
        while self._next_probe <= t and math.isfinite(t):
            self._next_probe += self.options.probe_interval

    def result(self) -> tuple[OccupancyGrid, dict]:
        """M_i and the session's row."""
        updated = self.current_map()
        observable = self.counter.observable()
        targets = (self._wrong_occ | self._wrong_free) & observable
        times = self.first_right[targets]
        shown = times[np.isfinite(times)]
        duration = self.handled[-1][0] if self.handled else 0.0
        cd = ev.change_detection(self.reference, updated, self.truth, observable)
        processed = sum(r.processed_before + r.pipeline.counts.scans_processed
                        for r in self.robots)
        row = {
            "session": self.name, "robots": len(self.robots), "mode": self.options.mode,
            "merge_rule": self.options.merge_rule if self.options.mode == "per-robot"
            else None,
            "precision": cd["precision"], "recall": cd["recall"], "f1": cd["f1"],
            "changes": cd["changes"], "targets": cd["target_cells"],
            "opdf": map_metrics(updated, self.truth)["opdf"],
            "opdf_previous": map_metrics(self.reference, self.truth)["opdf"],
            "ghosts": ev.ghost_cells(updated, self.truth, self.people_mask | self.robot_mask),
            "ghosts_of_robots": ev.ghost_cells(updated, self.truth, self.robot_mask),
            "targets_fixed": cd["targets_fixed"], "mask_robots": self.options.mask_robots,
            "latency_median_s": float(np.median(shown)) if len(shown) else None,
            "latency_p90_s": float(np.percentile(shown, 90)) if len(shown) else None,
            "targets_shown": int(len(shown)),
            "committed_at_s": duration, "duration_s": duration,
            "scans": len(self.handled), "scans_processed": processed,
            "ape_rmse_m": float(np.mean([r.ape_rmse() for r in self.robots])),
            "cpu_s": self.cpu_s, "world_finished": bool(self.world.finished),
        }
        if self.options.mode == "store":
            row.update(self.store_counts, store_s=self.store_s)
        return updated, row


# --- a run ----------------------------------------------------------------------------------------
def play_session(scenario, session: int, reference: OccupancyGrid, seeds: dict,
                 options: FleetOptions) -> tuple[OccupancyGrid, dict]:
    """One fleet session from M_{i-1}: (M_i, its row)."""
    members = fleet_members(scenario, session, options.robots, options.quick)
    world = FleetWorld(scenario, session, members, seeds["world"])
    fs = FleetSession(scenario, session, world, reference, seeds["localizer"], options)
    name = scenario.sessions[session].name
    wall = time.perf_counter()
    with tqdm(disable=not options.progress, desc=f"{name} x{options.robots} {options.mode}",
              unit="sim-s", leave=False, dynamic_ncols=True, file=sys.stderr) as bar:
        for k, msg in world.run():
            fs.arrive(k, msg)
            bar.update(max(0.0, round(msg.time) - bar.n))
    fs.finish()
    updated, row = fs.result()
    row["wall_s"] = time.perf_counter() - wall
    return updated, row


def run_fleet(scenario=None, options: FleetOptions | None = None, out: Path | None = None,
              initial: OccupancyGrid | None = None) -> dict:
    """Map W1 with one robot (or take ``initial`` as M1), then play the update sessions with
    the fleet; write ``fleet.json`` and the maps to ``out`` when given. Returns the run's
    record: its options and one row per update session."""
    options = options or FleetOptions()
    options.check()
    if options.store is not None:       # a store that cannot be used is said before any work
        from mapstore import open_store
        open_store(options.store, create=True).close()
    scn = sim.load_scenario(find_scenario(scenario))
    if options.quick:
        scn = sim.quick_variant(scn)
    seed = scn.seed if options.seed is None else options.seed
    n = len(scn.sessions) if options.sessions is None else max(2, min(options.sessions,
                                                                       len(scn.sessions)))
    seeds = session_seeds(seed, len(scn.sessions))
    if initial is None:
        initial = build_initial_map(scn, 0, seeds[0], options.progress).updated
    rows, previous = [], initial
    for i in range(1, n):
        previous, row = play_session(scn, i, previous, seeds[i], options)
        rows.append(row)
        if out is not None:
            (Path(out) / "maps").mkdir(parents=True, exist_ok=True)
            save_map(previous, Path(out) / "maps" / f"M_{row['session']}.yaml")
    record = {"scenario": scn.name, "seed": seed, "robots": options.robots,
              "mode": options.mode, "merge_rule": options.merge_rule, "quick": options.quick,
              "mask_robots": options.mask_robots,
              "sessions": rows}
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        save_map(initial, Path(out) / "maps" / "M_W1.yaml")
        (Path(out) / "fleet.json").write_text(json.dumps(record, indent=1))
    return record


# --- the table ------------------------------------------------------------------------------------
COLUMNS = (("robots", "N", "{}"), ("mode", "mode", "{}"), ("session", "session", "{}"),
           ("precision", "precision", "{:.3f}"), ("recall", "recall", "{:.3f}"),
           ("opdf", "OPDF", "{:.2f}"), ("ghosts", "ghosts", "{:.0f}"),
           ("targets", "targets", "{:.0f}"), ("targets_fixed", "fixed", "{:.0f}"),
           ("latency_median_s", "shown, median [s]", "{:.0f}"),
           ("latency_p90_s", "shown, p90 [s]", "{:.0f}"),
           ("committed_at_s", "session [s]", "{:.0f}"),
           ("scans_processed", "scans used", "{:.0f}"), ("cpu_s", "CPU [s]", "{:.1f}"),
           ("commits", "commits", "{:.0f}"), ("merges", "merges", "{:.0f}"),
           ("conflicts", "conflicts", "{:.0f}"))


def mode_label(row: dict) -> str:
    label = row["mode"] if row.get("merge_rule") is None else \
        f"{row['mode']} ({row['merge_rule']})"
    return label if row.get("mask_robots", True) else f"{label}, robots unmasked"


def format_table(rows) -> str:
    """A markdown table of session rows."""
    head = "| " + " | ".join(h for _, h, _ in COLUMNS) + " |"
    lines = [head, "|" + "---|" * len(COLUMNS)]
    for row in rows:
        cells = []
        for key, _, fmt in COLUMNS:
            value = mode_label(row) if key == "mode" else row.get(key)
            cells.append("-" if value is None else fmt.format(value))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m scenarios.fleet", description=(
        "Several robots update one map in the simulated warehouse; prints the scores of "
        "each update session."))
    p.add_argument("--scenario", default=None, help="built-in name or scenario file")
    p.add_argument("--robots", type=int, default=2, help=f"1..{MAX_ROBOTS} (default 2)")
    p.add_argument("--mode", choices=MODES, default=None,
                   help="default shared; store with --store")
    p.add_argument("--store", default=None, help="the store mode's map store")
    p.add_argument("--merge", choices=("vote", "union"), default="vote",
                   help="merge rule of the per-robot mode (default vote)")
    p.add_argument("--sessions", type=int, default=None, help="W1 and this many minus one")
    p.add_argument("--quick", action="store_true", help="the short routes")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--out", type=Path, default=None, help="folder for fleet.json and maps")
    p.add_argument("--unmasked", action="store_true",
                   help="give the updater the other robots' returns too")
    p.add_argument("--no-progress", action="store_true")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    options = FleetOptions(robots=args.robots, merge_rule=args.merge,
                           mode=args.mode or ("store" if args.store else "shared"),
                           quick=args.quick, sessions=args.sessions, seed=args.seed,
                           mask_robots=not args.unmasked, progress=not args.no_progress,
                           store=args.store)
    try:
        record = run_fleet(args.scenario, options, args.out)
    except (ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(format_table(record["sessions"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
