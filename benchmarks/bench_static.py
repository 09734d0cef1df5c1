"""Nothing that stands is freed: static cells freed and changes found, per case and profile.

Three parts, each run for the robot profile (the default of every entry point) and the paper
profile (the paper and its authors' code), with the figures a user of either would see:

**sim**: generated warehouses (``mapupdate generate``: several seeds and sizes) played in the
simulator: W1 maps the warehouse (M1), W2 rearranges it while people walk and is recorded as a
bag (the localiser's ``map -> odom`` in it, as a robot records amcl's). The bag is replayed
through the robot's update (``onboard.replay.replay_observations``, what ``mapupdate update``
runs) for each variant of the recording:

- the lidar: 360 deg with 720 beams, or 270 deg with 1081;
- people walking: 0, 4 or 8;
- the scans: every one, or one per metre of travel (or 30 deg of turn), as sparse logs keep;
- the poses: the truth, the recorded localisation, the project's localiser, or the truth
  jittered by a few centimetres from scan to scan.

Scored against the world (``sim``): a **static cell freed** is a cell occupied in M1 and free
in the update's map that is not free in G2 (a wall's or an object's cell, or a gap too narrow
to reach) and lies within one cell of a wall or of an object that did not move; a **face cell
freed** is one free in G2 that lies within one cell of such an object's cover and not within
one cell of the place of an object that moved or went (a thickened face the update thinned:
counted, not a fault). The changes found: recall and precision of
``evaluation.change_detection`` on the cells the route observes. ``before`` is the robot's
updater rules as they were before the robot profile (``BEFORE``): the baseline of recall.

**edited**: the edited-world cases of ``bench_real_changes.py`` (the seven Radish buildings,
seeds 0-2, with and without people): true walls freed (occupied in the stale map and in the
whole log's map, free after the update) against the paper profile with every scan processed
(``paper_ungated``), and the shares of removed boxes freed and added boxes drawn.

**logs**: the real logs, a map of one part updated with the next: Intel's halves and thirds,
Killian's halves and thirds, SENA's keyframe map updated from raw odometry by the localiser,
and the partly mapped Radish buildings (``bench_real_changes.partly_mapped``): the cells
occupied in both parts' maps that the update freed.

    python benchmarks/bench_static.py [--parts sim,edited,logs] [--quick] [--workers 2]
    python benchmarks/bench_static.py --parts sim --without free_with_neighbours pose_check

``--without`` adds, to the sim part, the robot profile without each guard named: which guard
stops which cells.

Exit 1 when the robot profile frees a static cell in any simulated case, its pooled recall
there is more than 0.02 below ``before``'s, it frees more true walls than ``paper_ungated`` on
an edited-world case or misses the pooled shares (removed freed >= 0.95, added drawn >= 0.85),
or frees a cell occupied in both parts of a real log.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(ROOT))
DATA = ROOT.parent / "shared" / "data"

LIDARS = {"360": {"mount": [0.0, 0.0, 0.0], "fov_deg": 360, "beams": 720},
          "270": {"mount": [0.25, 0.0, 0.0], "fov_deg": 270, "beams": 1081}}
PEOPLE = (0, 4, 8)
RATES = ("every", "metre")
POSES = ("truth", "recorded", "localizer", "jitter")
WORLDS = ((1, (20.0, 15.0)), (2, (30.0, 20.0)), (3, (40.0, 25.0)), (4, (25.0, 18.0)))
QUICK_WORLDS = ((1, (20.0, 15.0)), (2, (30.0, 20.0)))
JITTER = (0.03, math.radians(0.5))    # [m], [rad] std of the jitter of each scan's pose
SPACING = (1.0, math.radians(30.0))   # one scan per metre of travel or 30 deg of turn
SIM_PROFILES = ("paper", "robot", "before")
# The robot profile without one of its guards (``--without NAME``): which guard stops which
# cells. (updater keys, pose check keys, pose check on)
WITHOUT = {
    "free_with_neighbours": ({"free_with_neighbours": False}, {}, True),
    "removed_skip_across": ({"removed_skip_across": False}, {}, True),
    "gate_confirm_once": ({"gate_confirm_once": False}, {}, True),
    "refined_bounds": ({}, {"refined_min_correction": 0.2, "refined_min_correction_deg": 3.0},
                       True),
    "pose_check": ({}, {}, False),
}
# The robot's updater rules before the robot profile (mapupdate update's defaults then, with
# no pose check): the baseline of recall the robot profile may not fall below by more than
# 0.02 pooled.
BEFORE = {
    "grow_into_unknown": True,
    "gate_min_interval": 0.0, "gate_min_distance": 0.2, "gate_min_rotation_deg": 20.0,
    "gate_velocity_max_dt": 0.5, "gate_fast_turn_deg_s": 60.0, "gate_recovery_time": 0.5,
    "gate_recovery_distance": 0.0, "gate_turn_cover": True, "gate_turn_views": 2,
    "gate_confirm": True,
    "unanimous_min": 3, "min_run_width": 0.2, "spread_removed": True,
    "support_exact_state": True,
}


# --- the worlds ------------------------------------------------------------------------------

def world_tree(seed: int, size, lidar: str, people: int) -> dict:
    """A generated warehouse of two sessions with the lidar and the number of walkers asked."""
    from scenarios.generator import generate

    tree = generate(seed, size, sessions=2, fov=LIDARS[lidar]["fov_deg"])
    spec = tree["robot"]["lidars"][0]
    spec.update(LIDARS[lidar])
    w2 = tree["sessions"][1]
    w2["people"] = walkers(np.random.default_rng([seed, people, 17]), tree["world"]["bounds"],
                           [r[1] for r in w2["route"]], people)
    tree["name"] = f"{tree['name'].removesuffix('_360')}_{lidar}_p{people}"
    return tree


def walkers(rng, bounds, lane_ys, n: int) -> list[dict]:
    """``n`` people: half walk along lanes the route drives (a little off their centre line),
    half wander over the whole floor."""
    x0, y0, x1, y1 = bounds
    out = []
    for i in range(n):
        speed = round(float(rng.uniform(0.7, 1.3)), 3)
        if i % 2 == 0:
            y = round(float(rng.choice(lane_ys)) + float(rng.choice([-0.3, 0.3])), 3)
            xa = round(float(rng.uniform(x0 + 1.0, x1 - 5.0)), 3)
            xb = round(float(rng.uniform(xa + 4.0, x1 - 0.5)), 3)
            out.append({"route": [[xa, y], [xb, y]], "loop": True, "speed": speed})
        else:
            out.append({"wander": [x0 + 0.5, y0 + 0.5, x1 - 0.5, y1 - 0.5], "count": 1,
                        "speed": speed})
    return out


def play_world(tree: dict, work: Path) -> Path:
    """Play W1 (mapping) and W2 (recorded as a bag, the map left as it was); the run's folder."""
    import yaml

    from scenarios.options import RunOptions
    from scenarios.runner import run_scenario
    from scenarios.session_bags import SessionBagRecorder

    run_dir = work / tree["name"]
    if (run_dir / "done").exists():
        return run_dir
    work.mkdir(parents=True, exist_ok=True)
    path = work / f"{tree['name']}.yaml"
    path.write_text(yaml.safe_dump(tree, sort_keys=False))
    bags = run_dir / "bags"
    run_scenario(path, RunOptions(out=run_dir / "run", progress=False, method="none",
                                  observer=SessionBagRecorder(bags)))
    (run_dir / "done").write_text("")
    return run_dir


# --- the truth -------------------------------------------------------------------------------

def static_masks(scenario, frame) -> dict:
    """Per cell: covered by a wall or an object that stands in W2 where it stood in W1
    (``unmoved``); covered by an object of W1 that moved or went (``vacated``)."""
    from sim import geometry as geo
    from sim.groundtruth import covered_cells

    before = {o.id: o for o in scenario.obstacles(0)}
    after = {o.id: o for o in scenario.obstacles(1)}
    stayed = [o for k, o in before.items() if k in after and after[k] == o]
    went = [o for k, o in before.items() if k not in after or after[k] != o]
    walls = geo.wall_boxes(scenario.world.bounds, scenario.world.wall_thickness)
    boxes, circles = geo.obstacle_arrays(stayed)
    unmoved = covered_cells(frame, np.concatenate([boxes.reshape(-1, 5), walls]), circles)
    boxes, circles = geo.obstacle_arrays(went)
    return {"unmoved": unmoved, "vacated": covered_cells(frame, boxes, circles)}


def dilate8(mask: np.ndarray) -> np.ndarray:
    p = np.pad(mask, 1)
    h, w = mask.shape
    return np.logical_or.reduce([p[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
                                 for dr in (-1, 0, 1) for dc in (-1, 0, 1)])


def static_scores(before, after, truth, masks) -> dict:
    """Cells of M1 the update freed, split as the module's docstring says."""
    from gridmap import FREE, OCCUPIED

    freed = (before.data == OCCUPIED) & (after.data == FREE)
    near_unmoved = dilate8(masks["unmoved"])
    static = freed & (truth.data != FREE) & near_unmoved
    face = freed & (truth.data == FREE) & near_unmoved & ~dilate8(masks["vacated"])
    return {"freed": int(freed.sum()), "static_freed": int(static.sum()),
            "face_freed": int(face.sum())}


# --- the recordings --------------------------------------------------------------------------

@dataclass
class Found:
    """A log's observations, as ``replay_observations`` takes them."""

    observations: list
    total: int
    has: dict
    stats: object


def variant(found, rate: str, poses: str, seed: int) -> Found:
    """The recording as the variant asks: every scan or one per metre; the true poses given as
    the log's truth, jittered with ``JITTER`` when asked."""
    obs = list(found.observations)
    if rate == "metre":
        obs = one_per_metre(obs)
    if poses == "jitter":
        rng = np.random.default_rng([seed, 99])
        from gridmap import Pose2D

        out = []
        for o in obs:
            dx, dy = rng.normal(0.0, JITTER[0], 2)
            dt = rng.normal(0.0, JITTER[1])
            t = o.truth
            out.append(replace(o, truth=Pose2D(t.x + dx, t.y + dy, t.theta + dt)))
        obs = out
    return Found(obs, len(obs), dict(found.has), found.stats)


def one_per_metre(obs: list) -> list:
    """The scans a sparse logger keeps: the first, then one each time the odometry moved
    ``SPACING[0]`` or turned ``SPACING[1]`` since the last one kept."""
    kept, last = [], None
    for o in obs:
        p = o.odom
        if last is None or math.hypot(p.x - last.x, p.y - last.y) >= SPACING[0] or \
                abs(math.remainder(p.theta - last.theta, math.tau)) >= SPACING[1]:
            kept.append(o)
            last = p
    return kept


# --- the profiles ----------------------------------------------------------------------------
def placement_for(name: str, source: str):
    """(Placement, updater configuration or None) of a profile of the sim part: ``paper`` and
    ``robot`` as ``mapupdate update --profile`` runs them, ``before`` the rules of ``BEFORE``
    without the pose check."""
    from onboard.replay import Placement
    from updater import UpdaterConfig

    from localization.confidence import PoseCheckConfig

    if name == "before":
        return Placement(source=source, profile="robot", pose_check=False), \
            UpdaterConfig(**BEFORE)
    if name.startswith("robot-"):
        keys, check, on = WITHOUT[name.removeprefix("robot-")]
        return Placement(source=source, profile="robot", pose_check=on,
                         pose_check_config=PoseCheckConfig.profile("robot", check)), \
            UpdaterConfig.profile("robot", keys)
    return Placement(source=source, profile=name), None


# --- one world: every variant, every profile -------------------------------------------------
def one_world(job) -> list[dict]:
    from evaluation import scores as ev
    from gridmap import load_map
    from onboard.replay import replay_observations
    from robotlogs import log_observations
    from sim.groundtruth import grid_frame
    from sim.scenario import load_scenario

    (seed, size, lidar, people), work, names, rates, poses = job
    tree = world_tree(seed, size, lidar, people)
    run_dir = play_world(tree, Path(work))
    scenario = load_scenario(Path(work) / f"{tree['name']}.yaml")
    maps = run_dir / "run" / "maps"
    before, truth = load_map(maps / "M_W1.yaml"), load_map(maps / "G_W2.yaml")
    masks = static_masks(scenario, grid_frame(scenario))
    observable = np.load(maps / "masks_W2.npz")["observable"]
    found = log_observations(run_dir / "bags" / "W2.bag")
    found = Found(list(found.observations), found.total, found.has, found.stats)
    rows = []
    for rate, pose, name in itertools.product(rates, poses, names):
        rec = variant(found, rate, pose, seed)
        placement, config = placement_for(name, {"jitter": "truth"}.get(pose, pose))
        t0 = time.perf_counter()
        done = replay_observations(before, rec, placement, updater_config=config)
        after = done.updater.updated_map()
        cd = ev.change_detection(before, after, truth, observable)
        rows.append({"world": f"s{seed}_{size[0]:g}x{size[1]:g}", "lidar": lidar,
                     "people": people, "rate": rate, "poses": pose, "profile": name,
                     "scans": rec.total, "processed": done.pipeline.counts.scans_processed,
                     **static_scores(before, after, truth, masks),
                     "targets": cd["target_cells"], "fixed": cd["targets_fixed"],
                     "changes": cd["changes"], "correct": cd["correct_changes"],
                     "seconds": time.perf_counter() - t0})
    return rows


def pooled(rows) -> dict:
    t = sum(r["targets"] for r in rows)
    c = sum(r["changes"] for r in rows)
    return {"static_freed": sum(r["static_freed"] for r in rows),
            "face_freed": sum(r["face_freed"] for r in rows),
            "cases_freeing": sum(r["static_freed"] > 0 for r in rows),
            "recall": sum(r["fixed"] for r in rows) / t if t else math.nan,
            "precision": sum(r["correct"] for r in rows) / c if c else math.nan,
            "cases": len(rows)}


def sim_part(args, names) -> tuple[list, int]:
    worlds = QUICK_WORLDS if args.quick else WORLDS
    jobs = [((seed, size, lidar, n), str(args.out), names, RATES, POSES)
            for (seed, size), lidar, n in itertools.product(worlds, LIDARS, PEOPLE)]
    rows = []
    with ProcessPoolExecutor(args.workers) as pool:
        for got in progress(pool.map(one_world, jobs), len(jobs), "sim worlds"):
            rows += got
    keys = ("world", "lidar", "people", "rate", "poses")
    by = {(tuple(r[k] for k in keys), r["profile"]): r for r in rows}
    print("## sim: static cells freed / face cells freed / recall, per case\n")
    print("| world | lidar | people | scans | poses | " + " | ".join(names) + " |")
    print("|" + "---|" * (5 + len(names)))
    for case in sorted({tuple(r[k] for k in keys) for r in rows}, key=str):
        cells = []
        for n in names:
            r = by[(case, n)]
            recall = "-" if not r["targets"] else f"{r['fixed'] / r['targets']:.3f}"
            cells.append(f"{r['static_freed']} / {r['face_freed']} / {recall}")
        print("| " + " | ".join(map(str, case)) + " | " + " | ".join(cells) + " |")
    print("\n| profile | cases | cases freeing | static freed | face freed | recall | precision |")
    print("|---|---|---|---|---|---|---|")
    for n in names:
        p = pooled([r for r in rows if r["profile"] == n])
        print(f"| {n} | {p['cases']} | {p['cases_freeing']} | {p['static_freed']} | "
              f"{p['face_freed']} | {p['recall']:.3f} | {p['precision']:.3f} |")
    robot, base = (pooled([r for r in rows if r["profile"] == n]) for n in ("robot", "before"))
    lost = base["recall"] - robot["recall"]
    bad = robot["static_freed"] > 0 or lost > 0.02
    print(f"\nsim: the robot profile freed {robot['static_freed']} static cells in "
          f"{robot['cases_freeing']} of {robot['cases']} cases (bar 0); recall {robot['recall']:.3f}"
          f" against {base['recall']:.3f} before ({-lost:+.3f}, bar -0.02): "
          f"{'missed' if bad else 'met'}\n")
    return rows, int(bad)


# --- edited worlds and real logs ---------------------------------------------------------------
EDITED_METHODS = ("robot", "paper", "paper_ungated")


def edited_part(args) -> tuple[list, int]:
    import bench_real_changes as rc

    if not rc.DATA.is_dir():
        print(f"edited: skipped, {rc.DATA} not found\n")
        return [], 0
    seeds = (0,) if args.quick else (0, 1, 2)
    with tempfile.TemporaryDirectory() as tmp:
        from onboard.logmap import map_from_log

        for name in rc.LOGS:
            map_from_log(rc.DATA / f"{name}.log.gz", Path(tmp) / f"{name}.yaml", progress=False)
        jobs = [(n, s, p, tmp, {}, EDITED_METHODS) for n in rc.LOGS for s in seeds
                for p in (0, 4)]
        rows = []
        with ProcessPoolExecutor(args.workers) as pool:
            for got in progress(pool.map(rc.one_case, jobs), len(jobs), "edited cases"):
                rows += got
    print("## edited: true walls freed per case (robot / paper / paper_ungated)\n")
    print("| log | seed | people | robot | paper | paper_ungated |")
    print("|---|---|---|---|---|---|")
    worse = []
    for key in sorted({(r["log"], r["seed"], r["people"]) for r in rows}):
        w = {r["method"]: r["walls_freed"] for r in rows if (r["log"], r["seed"], r["people"])
             == key}
        print(f"| {key[0]} | {key[1]} | {key[2]} | {w['robot']} | {w['paper']} | "
              f"{w['paper_ungated']} |")
        if w["robot"] > w["paper_ungated"]:
            worse.append(key)
    print("\n| people | profile | removed freed | added drawn | walls freed | false occupied |"
          " ghosts |")
    print("|---|---|---|---|---|---|---|")
    short = []
    for people in (0, 4):
        for m in EDITED_METHODS:
            sel = [r for r in rows if r["people"] == people and r["method"] == m]
            freed = rc.pooled(sel, "removed_freed", "removed_seen_cells")
            drawn = rc.pooled(sel, "added_drawn", "added_outline_cells")
            print(f"| {people} | {m} | {freed:.3f} | {drawn:.3f} | "
                  f"{sum(r['walls_freed'] for r in sel)} | "
                  f"{sum(r['false_occupied'] for r in sel)} | {sum(r['ghosts'] for r in sel)} |")
            if m == "robot" and (freed < 0.95 or drawn < 0.85):
                short.append(people)
    bad = bool(worse or short)
    print(f"\nedited: the robot profile frees more true walls than paper_ungated on "
          f"{len(worse)} of {len(rows) // len(EDITED_METHODS)} cases {worse or ''}; pooled "
          f"shares below 0.95 / 0.85 with people {short or 'none'}: "
          f"{'missed' if bad else 'met'}\n")
    return rows, int(bad)


def logs_part(args) -> tuple[list, int]:
    import bench_real_changes as rc

    jobs = [(name, part, profile) for name, part in REAL_SPLITS for profile in ("robot", "paper")
            if (DATA / LOG_FILES[name]).exists()]
    jobs += [(f"radish:{name}", "partly", profile) for name in rc.LOGS
             for profile in ("robot", "paper") if rc.DATA.is_dir()]
    if args.quick:
        jobs = [j for j in jobs if j[0] in ("intel", "radish:aces")]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(progress(pool.map(one_split, jobs), len(jobs), "real logs"))
    print("## logs: cells occupied in both parts' maps freed by the update\n")
    print("| log | parts | occupied in both | robot freed | paper freed |")
    print("|---|---|---|---|---|")
    bad = 0
    for key in dict.fromkeys((r["log"], r["parts"]) for r in rows):
        got = {r["profile"]: r for r in rows if (r["log"], r["parts"]) == key}
        both = next(iter(got.values()))["both"]
        print(f"| {key[0]} | {key[1]} | {both} | {got['robot']['freed']} | "
              f"{got['paper']['freed']} |")
        bad += got["robot"]["freed"] > 0
    print(f"\nlogs: the robot profile frees a cell occupied in both parts on {bad} of "
          f"{len(rows) // 2} splits (bar 0): {'missed' if bad else 'met'}\n")
    return rows, int(bad > 0)


LOG_FILES = {"intel": "intel.gfs.log", "killian": "killian.clf.gz",
             "sena": "sena.odom.log"}
# (log, how it is split): "halves" (a map of the first half updated with the second),
# "thirds" (the first third's map with the second third, the second's with the last)
REAL_SPLITS = (("intel", "halves"), ("intel", "thirds"), ("killian", "halves"),
               ("killian", "thirds"), ("sena", "keyframes"))


def one_split(job) -> dict:
    """One real log's split, updated with a profile: the cells occupied in both parts' maps
    and those of them the update freed."""
    name, part, profile = job
    if name.startswith("radish:"):
        import bench_real_changes as rc

        with tempfile.TemporaryDirectory() as tmp:
            from onboard.logmap import map_from_log

            log = name.split(":", 1)[1]
            map_from_log(rc.DATA / f"{log}.log.gz", Path(tmp) / f"{log}.yaml", progress=False)
            g = rc.partly_mapped((log, tmp, {}), profile=profile)
        return {"log": name, "parts": f"first {rc.PART:.0%} / rest", "profile": profile,
                "both": g["occupied_in_both"], "freed": g["freed_also_in_whole"]}
    if name == "sena":
        return _sena(profile)
    return _split(name, part, profile)


def _split(name: str, part: str, profile: str) -> dict:
    from gridmap import FREE, OCCUPIED, save_map
    from gridmap.mapping import build_map
    from onboard.logmap import _placed_scans, map_frame
    from onboard.replay import LogSource, Outputs, Placement, update_from_log
    from robotlogs import log_observations
    from gridmap import load_map

    path = DATA / LOG_FILES[name]
    found = log_observations(path)
    placed = _placed_scans(found, "recorded", (None, None))
    times = [o.time for o in found.observations]
    k = 2 if part == "halves" else 3
    cut = [len(placed) * i // k for i in range(k + 1)]
    frame = map_frame(placed, 0.05)
    both = freed = 0
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(k - 1):
            a = build_map(frame, placed[cut[i]:cut[i + 1]])
            b = build_map(frame, placed[cut[i + 1]:cut[i + 2]])
            save_map(a, Path(tmp) / "a.yaml")
            end = times[cut[i + 2]] if cut[i + 2] < len(times) else None
            update_from_log(Path(tmp) / "a.yaml", LogSource(path, start_time=times[cut[i + 1]],
                                                             end_time=end),
                            Outputs(Path(tmp) / "u.yaml"), Placement(profile=profile))
            u = load_map(Path(tmp) / "u.yaml")
            in_both = (a.data == OCCUPIED) & (b.data == OCCUPIED)
            both += int(in_both.sum())
            freed += int((in_both & (u.data == FREE)).sum())
    return {"log": name, "parts": part, "profile": profile, "both": both, "freed": freed}


def _sena(profile: str) -> dict:
    """SENA's keyframe map updated from the raw odometry log by the localiser started over the
    whole map: the same place at the same time, so every occupied cell stands."""
    from gridmap import FREE, OCCUPIED, load_map
    from onboard.logmap import map_from_log
    from onboard.replay import LogSource, Outputs, Placement, update_from_log

    with tempfile.TemporaryDirectory() as tmp:
        map_from_log(DATA / "sena.keyframes.log", Path(tmp) / "k.yaml", progress=False)
        update_from_log(Path(tmp) / "k.yaml", LogSource(DATA / "sena.odom.log"),
                        Outputs(Path(tmp) / "u.yaml"),
                        Placement(source="localizer", profile=profile))
        k, u = load_map(Path(tmp) / "k.yaml"), load_map(Path(tmp) / "u.yaml")
    occupied = k.data == OCCUPIED
    return {"log": "sena", "parts": "keyframes / odometry", "profile": profile,
            "both": int(occupied.sum()), "freed": int((occupied & (u.data == FREE)).sum())}


def progress(results, total: int, what: str):
    t0 = time.perf_counter()
    for i, r in enumerate(results, 1):
        print(f"[{what} {i}/{total}] {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        yield r


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--parts", default="sim,edited,logs",
                    help="which parts: sim, edited, logs (default all)")
    ap.add_argument("--quick", action="store_true",
                    help="two warehouses, one seed of the edited world, Intel and one building")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "static",
                    help="where the simulated worlds are kept between runs (and results.json)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--without", nargs="+", default=[], choices=sorted(WITHOUT),
                    metavar="GUARD", help="also run the sim part with the robot profile "
                    f"without each of these guards ({', '.join(sorted(WITHOUT))})")
    args = ap.parse_args(argv)
    parts = args.parts.split(",")
    for p in parts:
        if p not in ("sim", "edited", "logs"):
            ap.error(f"unknown part {p!r} (parts: sim, edited, logs)")
    sys.path.insert(0, str(ROOT / "benchmarks"))
    results, bad = {}, 0
    for name, fn in (("sim", lambda: sim_part(
            args, SIM_PROFILES + tuple(f"robot-{g}" for g in args.without))), ("edited",
                     lambda: edited_part(args)), ("logs", lambda: logs_part(args))):
        if name in parts:
            results[name], missed = fn()
            bad = max(bad, missed)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=1))
    print(f"bars {'missed' if bad else 'met'}; wrote {args.out / 'results.json'}")
    return bad


if __name__ == "__main__":
    sys.exit(main())
