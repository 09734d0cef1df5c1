"""Soak benchmark: many sessions of the built-in warehouse, each rearranged at random.

The warehouse's W1 builds M1 as in the main job; then N update sessions follow (default 50), each
on the quick route (the first 30 m of the transport loop) with people, and each moving one to
three movable objects that the route sees (a random shift of 0.5 to 1.5 m and a quarter turn or
none, drawn from a seeded generator; a placement is kept only if the scenario checks accept it:
inside the walls, overlapping nothing, the robot's start, route and the people's routes kept
clear, and if it leaves a lane of LANE_MARGIN beside the robot's path). Every session runs
exactly as the runner runs it (``runner.run_update_session``: the
localiser on M_{i-1}, the updater on its poses, scores against G_i), chaining M_i into the next.
Only M1 and the latest map are kept, as a robot would.

Per session: peak resident memory during the session (sampled every 10 ms from /proc), precision
and recall of the change detection on the observable cells, wall time, and the updater's state.
Bars (exit 1 when missed), over the sessions after the first (whose figures include compiling
the kernels): peak memory within 10 % of its median; the median wall time of the last fifth of
the sessions within 20 % of the first fifth's (a session takes about a second, so single
sessions on a shared machine scatter more than that); neither precision nor recall drifting
down (least-squares slope above -0.002 per session, i.e. less than 0.1 lost over 50 sessions).
Also listed: the target cells (observable cells M_{i-1} got wrong) and how many of them were
targets in the session before too, OPDF of M_i and of the oracle against G_i, the localiser's
APE on M_{i-1}.

    python benchmarks/bench_soak.py [--sessions N] [--seed S] [--no-pose-check] [--fill-gaps]
                                    [--lane-margin M]
"""

from __future__ import annotations

import argparse
import copy
import math
import os
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(Path(__file__).resolve().parents[1]))

# [m] length of a random move. At least 0.5 m: a face moved by less than the updater's pairing
# distance D(r) (0.15-0.30 m) pairs with where it was and is, by design, left in the map; such
# moves would pile up as target cells that no correct run can fix (measured: the targets left
# unfixed lay 0.1-0.35 m from the nearest occupied cell), which is not what a soak is after.
MIN_SHIFT, MAX_SHIFT = 0.5, 1.5
MOVES = (1, 3)           # objects moved per session, at least and at most
# [m] clear space a moved object keeps from the robot's path (its start and route legs), beyond
# the robot's radius: a warehouse keeps its transport lanes clear, and a navigation stack would
# not drive along a face a few centimetres away. The scenario checks keep only the radius, and
# the random walk of the moves then parks objects along the lanes (seed 2024, without a margin:
# from S27 on 4-6 objects within 0.25 m of the path, 1-3 of them 4-7 cm away). Such a face,
# missing from M(i-1) and filling half the scan, pulls the localiser towards the object's old
# outline (S09 and S45 went 0.3-5 m off right beside one), and in the aisle lined with them the
# pose check refuses nearly every scan (2-3 of 19 processed from S32 on), so M is never mended
# there and the next session fares worse. With 0.3 m: APE RMSE on M(i-1) over S42-S51 0.08 m
# against 1.19 m, sessions above 0.3 m 1 against 8 (seed 2025: 1 against 3). 0: no margin.
LANE_MARGIN = 0.3
SEEN_HITS = 30           # beams from the route that must end on an object for it to count as seen


@dataclass
class SessionRow:
    name: str
    moved: str           # the objects moved in this session
    peak_rss_mb: float   # [MB] peak resident memory during the session
    precision: float | None
    recall: float | None
    wall_s: float
    updater_state_mb: float
    scans_processed: int
    targets: int         # observable cells M_{i-1} got wrong
    stubborn: int        # ... of them targets of the session before too (left wrong then)
    new_targets: int     # ... of them made wrong by this session's moves (right about W_{i-1})
    recall_new: float | None   # recall on those
    changes: int         # cells the updater changed
    opdf: float          # [%] OPDF(M_i, G_i)
    opdf_oracle: float   # [%] OPDF(oracle_i, G_i)
    ape_rmse: float      # [m] of the localiser on M_{i-1}
    ghosts: int = 0      # occupied cells of M_i far from G_i's that a person covered
    g_freed: int = 0     # cells occupied in G_i that the session freed
    standing_freed: int = 0  # ... of them, cells of a wall, rack or object the session did
                             # not move
    standing_gaps: int = 0   # ... of them with no occupied cell of M_i within one cell: a gap
                             # in the map's outline, not a face drawn a cell off
    ghosts_drawn: int = 0    # ghosts the session drew (not occupied in M_{i-1})
    ghosts_oracle: int = 0   # ghosts of the oracle's map: left where the route never looked


# --- the rearrangements -------------------------------------------------------------------------
def _route_poses(scn, route) -> np.ndarray:
    """Robot poses (N, 3) every 0.5 m along the route, facing along each leg."""
    from scenarios.generator import route_poses

    return route_poses([scn.robot.start.x, scn.robot.start.y], route)


def seen_objects(scn, session: int) -> list[str]:
    """Movable objects of a session's world on which at least SEEN_HITS beams from its route
    end (people left out)."""
    import sim
    from sim import geometry as geo

    world = sim.World(scn, session, 0)
    poses = _route_poses(scn, scn.sessions[session].route)
    spec = scn.robot.lidars[0]
    ranges = world.scans_without_people(poses, 0)
    angles = spec.angle_min + spec.angle_increment * np.arange(spec.beams)
    sensors = np.array([[p[0] + math.cos(p[2]) * spec.mount.x - math.sin(p[2]) * spec.mount.y,
                         p[1] + math.sin(p[2]) * spec.mount.x + math.cos(p[2]) * spec.mount.y,
                         p[2] + spec.mount.theta] for p in poses])
    ok = np.isfinite(ranges)
    a = sensors[:, 2:3] + angles[None, :]
    reach = np.where(ok, ranges, 0.0)  # no-return beams (inf) are dropped below
    hits = np.column_stack([(sensors[:, 0:1] + reach * np.cos(a))[ok],
                            (sensors[:, 1:2] + reach * np.sin(a))[ok]])
    seen = []
    for o in scn.obstacles(session):
        if not o.movable:
            continue
        d = geo.point_circle_distance(hits, o.circle()[None])[:, 0] if o.is_circle else \
            geo.point_box_distance(hits, o.box()[None])[:, 0]
        if int((np.abs(d) < 0.05).sum()) >= SEEN_HITS:
            seen.append(o.id)
    return seen


def _world_now(base: dict, movable: dict, session: dict):
    """A one-session scenario of the world with ``movable`` objects where they are now (the
    scenario checks run on it: it raises ScenarioError for an invalid placement)."""
    import sim

    data = copy.deepcopy(base)
    data["world"]["movable"] = list(movable.values())
    data["sessions"] = [session]
    return sim.scenario_from_dict(data, "soak")


def _valid(base: dict, movable: dict, session: dict, oid: str | None = None,
           lane_margin: float = 0.0) -> bool:
    """Whether the scenario checks accept the placement, and object ``oid`` keeps
    ``lane_margin`` beyond the robot's radius from the robot's path."""
    import sim
    from sim import geometry as geo

    try:
        scn = _world_now(base, movable, session)
    except sim.ScenarioError:
        return False
    if oid is None or lane_margin <= 0:
        return True
    o = next(o for o in scn.obstacles(0) if o.id == oid)
    pts = np.vstack([[scn.robot.start.x, scn.robot.start.y], np.asarray(session["route"], float)])
    clear = scn.robot.radius + lane_margin
    for a, b in zip(pts[:-1], pts[1:]):
        d = geo.segment_circle_distance(a, b, o.circle()[None]) if o.is_circle else \
            geo.segment_box_distance(a, b, o.box()[None])
        if float(d[0]) < clear:
            return False
    return True


def soak_scenario(n_sessions: int = 50, seed: int = 2024, lane_margin: float = LANE_MARGIN):
    """The built-in warehouse with W1 and ``n_sessions`` random update sessions (a Scenario,
    already cut to quick routes) and the names of the objects each session moved. A moved
    object keeps ``lane_margin`` [m] beyond the robot's radius from the robot's path."""
    import yaml

    import sim
    from scenarios.catalog import find_scenario

    rng = np.random.default_rng(seed)
    data = yaml.safe_load(find_scenario(None).read_text())
    quick = sim.quick_variant(sim.scenario_from_dict(data, "warehouse"), max_route_length=30.0)
    route = [list(p) for p in quick.sessions[1].route]
    people = [p for s in data["sessions"][1:] for p in s.get("people", [])]
    base = {k: v for k, v in data.items() if k != "sessions"}
    movable = {o["id"]: dict(o) for o in data["world"]["movable"]}
    sessions = [data["sessions"][0]]
    moved_names = []
    for i in range(n_sessions):
        name = f"S{i + 2:02d}"
        chosen = [people[k] for k in sorted(rng.choice(len(people), size=rng.integers(2, 5),
                                                       replace=False))]
        # walkers whose way an earlier move blocked stay at home this time
        chosen = [p for p in chosen if _valid(base, movable, {"name": name, "route": route,
                                                              "people": [p]})]
        session = {"name": name, "route": route, "people": copy.deepcopy(chosen),
                   "changes": []}
        seen = seen_objects(_world_now(base, movable, {"name": name, "route": route}), 0)
        count = int(rng.integers(MOVES[0], MOVES[1] + 1))
        picked = []
        for oid in rng.permutation(seen)[:count]:
            o = movable[oid]
            for _ in range(20):       # a few tries for a valid place
                length = rng.uniform(MIN_SHIFT, MAX_SHIFT)
                heading = rng.uniform(-math.pi, math.pi)
                cx, cy = np.asarray(o["center"], float) + length * np.array(
                    [math.cos(heading), math.sin(heading)])
                trial = {**o, "center": [round(float(cx), 3), round(float(cy), 3)]}
                if "size" in o:
                    trial["yaw"] = round(float(o.get("yaw", 0.0) + rng.choice(
                        [0.0, math.pi / 2, -math.pi / 2])), 4)
                change = {"move": oid, "to": trial["center"] + ([trial["yaw"]]
                                                               if "size" in o else [])}
                if _valid(base, {**movable, oid: trial},
                          {**session, "changes": session["changes"] + [change]}, oid,
                          lane_margin):
                    movable[oid] = trial
                    session["changes"].append(change)
                    picked.append(oid)
                    break
        sessions.append(session)
        moved_names.append(", ".join(picked) or "-")
    scn = sim.scenario_from_dict({**data, "sessions": sessions}, "soak")
    return sim.quick_variant(scn, max_route_length=30.0), moved_names


# --- running -----------------------------------------------------------------------------------
class PeakMemory:
    """Peak resident memory [MB] while the ``with`` block runs, sampled from /proc every 10 ms
    (getrusage's peak only ever grows, so it cannot give one session's peak)."""

    def __enter__(self):
        self.peak = self._rss()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._rss())

    def _sample(self):
        while not self._stop.wait(0.01):
            self.peak = max(self.peak, self._rss())

    @staticmethod
    def _rss() -> float:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
        import resource

        return pages * resource.getpagesize() / 2**20


def run_soak(scn, moved: list[str], progress: bool = True, pose_check: bool | None = None,
             updater_config=None, method: str = "paper", profile: str = "robot",
             on_session=None) -> list[SessionRow]:
    """Play W1 then every update session, chaining the maps; one row per update session.
    ``pose_check``: None for the profile's. ``on_session(i, previous, result)``, when given,
    sees each session's M(i-1) and ``runner.SessionResult``."""
    from gridmap import FREE, OCCUPIED
    import evaluation as ev
    from scenarios import runner
    from scenarios.session import session_seeds

    seeds = session_seeds(scn.seed, len(scn.sessions))
    m1 = runner.build_initial_map(scn, 0, seeds[0]).updated
    previous = m1
    last_targets = np.zeros(m1.shape, bool)
    last_truth = None
    faces = None
    options = runner.RunOptions(progress=False, pose_check=pose_check, profile=profile,
                                updater_config=updater_config, method=method,
                                compare_paper=False)
    rows = []
    for i in range(1, len(scn.sessions)):
        t0 = time.perf_counter()
        with PeakMemory() as mem:
            res = runner.run_update_session(scn, i, previous, m1, seeds[i], options, faces)
        wall = time.perf_counter() - t0
        m = res.metrics
        cd, r, mm = m["change_detection"], m["resources"], m["map_metrics"]
        wrong_occ, wrong_free = ev.wrong_cells(previous, res.truth)
        targets = (wrong_occ | wrong_free) & res.masks["observable"]
        fixed = (wrong_occ & (res.updated.data == FREE)) | \
            (wrong_free & ev.near(res.updated.data == OCCUPIED))
        new = targets.copy()
        if last_truth is not None:
            was_occ, was_free = ev.wrong_cells(previous, last_truth)
            new &= ~(was_occ | was_free)
        n_new = int(new.sum())
        g_freed = ((res.truth.data == OCCUPIED) & (res.updated.data == FREE)
                   & (previous.data != FREE))
        standing_freed = g_freed & standing_cells(scn, i, res.truth)
        rows.append(SessionRow(res.name, moved[i - 1], mem.peak, cd["precision"], cd["recall"],
                               wall, r["updater_state_bytes"] / 2**20, r["scans_processed"],
                               cd["target_cells"], int((targets & last_targets).sum()),
                               n_new, int((fixed & new).sum()) / n_new if n_new else None,
                               cd["changes"],
                               mm["updated_vs_truth"]["opdf"], mm["oracle_vs_truth"]["opdf"],
                               m["localization"]["previous_map"]["rmse"], m["ghost_cells"],
                               int(g_freed.sum()), int(standing_freed.sum()),
                               int(outline_gaps(standing_freed, res.updated.data).sum()),
                               int((ghost_mask(res.updated, res.truth, res.masks["people"])
                                    & (previous.data != OCCUPIED)).sum()),
                               int(ghost_mask(ev.oracle_map(previous, res.truth,
                                                            res.masks["observable"]),
                                              res.truth, res.masks["people"]).sum())))
        if on_session is not None:
            on_session(i, previous, res)
        previous, faces = res.updated, res.faces
        last_targets = targets
        last_truth = res.truth
        del res                      # keep only what the next session needs
        if progress:
            row = rows[-1]
            print(f"  {row.name}: {row.peak_rss_mb:.0f} MB, P {_f(row.precision)}, "
                  f"R {_f(row.recall)}, {row.wall_s:.1f} s", file=sys.stderr, flush=True)
    return rows


def ghost_mask(grid, truth, people: np.ndarray) -> np.ndarray:
    """Bool (H, W): the cells ``evaluation.ghost_cells`` counts."""
    from gridmap import OCCUPIED
    import evaluation as ev

    return (grid.data == OCCUPIED) & ~ev.near(truth.data == OCCUPIED) & people


def outline_gaps(freed: np.ndarray, updated: np.ndarray) -> np.ndarray:
    """Of ``freed`` (cells of what stood that a session freed), those with no occupied cell of
    ``updated`` (M_i) within one cell: a gap in the map's outline, not a face drawn a cell off
    (the scoring's one cell of slack)."""
    import evaluation as ev
    from gridmap import OCCUPIED

    return freed & ~ev.near(updated == OCCUPIED)


def standing_cells(scn, session: int, frame) -> np.ndarray:
    """Bool (H, W) of ``frame``: the cells of the walls, the static objects and the movable
    objects that stand in session ``session`` where they stood in the session before."""
    from sim import geometry as geo
    from sim.groundtruth import covered_cells

    before = {o.id: o for o in scn.obstacles(session - 1)}
    kept = [o for o in scn.obstacles(session) if before.get(o.id) == o]
    boxes, circles = geo.obstacle_arrays(kept, scn.world.bounds, scn.world.wall_thickness)
    return covered_cells(frame, boxes, circles)


def _f(v, digits=3) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def trend(values) -> float:
    """Least-squares slope per session of the values that exist."""
    y = np.array([np.nan if v is None else v for v in values], float)
    x = np.arange(y.size, dtype=float)
    ok = np.isfinite(y)
    return float(np.polyfit(x[ok], y[ok], 1)[0]) if ok.sum() >= 2 else 0.0


def verdict(rows: list[SessionRow]) -> dict:
    """The bars of the module docstring over the sessions after the first."""
    rest = rows[1:] if len(rows) > 1 else rows
    mem = np.array([r.peak_rss_mb for r in rest])
    wall = np.array([r.wall_s for r in rest])
    k = max(1, len(rest) // 5)
    out = {
        "memory_spread": float(np.max(np.abs(mem / np.median(mem) - 1.0))),
        "memory_trend_mb": trend(list(mem)),
        "time_first_to_last": float(np.median(wall[-k:]) / np.median(wall[:k]) - 1.0),
        "precision_trend": trend([r.precision for r in rest]),
        "recall_trend": trend([r.recall for r in rest]),
        "recall_new_trend": trend([r.recall_new for r in rest]),
    }
    out["ok"] = (out["memory_spread"] <= 0.10 and abs(out["time_first_to_last"]) <= 0.20
                 and out["precision_trend"] > -0.002 and out["recall_trend"] > -0.002)
    return out


def print_table(rows: list[SessionRow]) -> None:
    print("| session | moved | peak RSS MB | precision | recall | targets | of them left "
          "from before | new | recall on new | changes | OPDF M(i) % | OPDF oracle % | "
          "APE RMSE m | wall s | scans processed |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r.name} | {r.moved} | {r.peak_rss_mb:.1f} | {_f(r.precision)} | "
              f"{_f(r.recall)} | {r.targets} | {r.stubborn} | {r.new_targets} | "
              f"{_f(r.recall_new)} | {r.changes} | {r.opdf:.2f} | "
              f"{r.opdf_oracle:.2f} | {r.ape_rmse:.3f} | {r.wall_s:.2f} | "
              f"{r.scans_processed} |")


def check_run_arguments(ap: argparse.ArgumentParser, args) -> None:
    """A one-line error for a number of sessions or a seed the soak cannot take."""
    if not 1 <= args.sessions <= 1000:
        ap.error(f"--sessions must be 1-1000, got {args.sessions}")
    if args.seed < 0:
        ap.error(f"--seed must be 0 or more, got {args.seed}")


def parse_set(ap: argparse.ArgumentParser, items: list[str]) -> dict:
    """``--set KEY=VALUE ...`` as {key: the value read as YAML}; a one-line error for an item
    without a key and "=", or a value that is not YAML."""
    import yaml

    out = {}
    for item in items:
        key, eq, value = item.partition("=")
        if not key or not eq:
            ap.error(f"--set takes KEY=VALUE, got {item!r}")
        try:
            out[key] = yaml.safe_load(value)
        except yaml.YAMLError:
            ap.error(f"--set: {key}: {value!r} is not valid YAML")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sessions", type=int, default=50)
    ap.add_argument("--seed", type=int, default=2024, help="seed of the rearrangements")
    ap.add_argument("--pose-check", action=argparse.BooleanOptionalAction, default=True,
                    help="the runner's pose check (default on, as in the runner)")
    ap.add_argument("--fill-gaps", action="store_true", help="the updater's fill_gaps on")
    ap.add_argument("--method", default="paper",
                    help="what updates the map (onboard.methods: paper, none, remap, fuse, "
                         "hybrid)")
    ap.add_argument("--lane-margin", type=float, default=LANE_MARGIN,
                    help=f"[m] clear space beside the robot's path, beyond its radius, that "
                         f"moved objects keep (default {LANE_MARGIN}; 0: the scenario checks "
                         f"only)")
    args = ap.parse_args(argv)
    check_run_arguments(ap, args)
    from onboard.methods import MethodError, check_method

    try:
        check_method(args.method, "--method")      # before minutes of generation
    except MethodError as e:
        ap.error(str(e))
    t0 = time.perf_counter()
    scn, moved = soak_scenario(args.sessions, args.seed, args.lane_margin)
    print(f"{args.sessions} sessions generated in {time.perf_counter() - t0:.0f} s",
          file=sys.stderr)
    from updater import UpdaterConfig

    rows = run_soak(scn, moved, pose_check=args.pose_check,
                    updater_config=UpdaterConfig(fill_gaps=args.fill_gaps),
                    method=args.method)
    print_table(rows)
    v = verdict(rows)
    prec = [r.precision for r in rows[1:] if r.precision is not None]
    rec = [r.recall for r in rows[1:] if r.recall is not None]
    print(f"\nOver sessions 2..{len(rows)} of the update sessions: peak RSS "
          f"{min(r.peak_rss_mb for r in rows[1:]):.1f}-{max(r.peak_rss_mb for r in rows[1:]):.1f}"
          f" MB (largest departure from the median {100 * v['memory_spread']:.1f} %, trend "
          f"{v['memory_trend_mb']:+.3f} MB/session); median wall time per session, last fifth "
          f"against first: {100 * v['time_first_to_last']:+.1f} %; precision mean "
          f"{np.mean(prec):.3f}, trend "
          f"{v['precision_trend']:+.4f}/session; recall mean {np.mean(rec):.3f}, trend "
          f"{v['recall_trend']:+.4f}/session; recall on the targets this session's moves made "
          f"mean {np.mean([r.recall_new for r in rows[1:] if r.recall_new is not None]):.3f}, "
          f"trend {v['recall_new_trend']:+.4f}/session. "
          f"Updater state {rows[-1].updater_state_mb:.2f} MB. "
          f"Total wall time {time.perf_counter() - t0:.0f} s.")
    print("bars met" if v["ok"] else f"bar missed: {v}")
    return 0 if v["ok"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
