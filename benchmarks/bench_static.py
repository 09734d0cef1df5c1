"""Nothing that stands is freed: static cells freed and changes found, per case and profile.

Generated warehouses (``mapupdate generate``: several seeds and sizes) are played in the
simulator: W1 maps the warehouse (M1), W2 rearranges it while people walk and is recorded as
a bag (the localiser's ``map -> odom`` in it, as a robot records amcl's). The bag is then
replayed through the robot's update (``robot.replay.replay_observations``, what ``mapupdate
update`` runs) with each profile, for each variant of the recording:

- the lidar: 360 deg with 720 beams, or 270 deg with 1081;
- people walking: 0, 4 or 8;
- the scans: every one, or one per metre of travel (or 30 deg of turn), as sparse logs keep;
- the poses: the truth, the recorded localisation, the project's localiser, or the truth
  jittered by a few centimetres from scan to scan.

Scored against the world (``sim``): a **static cell freed** is a cell occupied in M1 and
free in the update's map that is not free in G2 (a wall's or an object's cell, or a gap too
narrow to reach) and lies within one cell of a wall or of an object that did not move; a
**face cell freed** is one free in G2 that lies within one cell of such an object's cover
and not within one cell of the place of an object that moved or went (a thickened face the
update thinned: counted, not a fault). The changes found: recall and precision of
``evaluation.change_detection`` on the cells the route observes.

    python benchmarks/bench_static.py [--quick] [--workers 2] [--out runs/static]

Exit 1 when the robot profile frees a static cell in any case, or its pooled recall is more
than 0.02 below ``--baseline``'s (the robot rules before this benchmark existed).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

LIDARS = {"360": {"mount": [0.0, 0.0, 0.0], "fov_deg": 360, "beams": 720},
          "270": {"mount": [0.25, 0.0, 0.0], "fov_deg": 270, "beams": 1081}}
PEOPLE = (0, 4, 8)
RATES = ("every", "metre")
POSES = ("truth", "recorded", "localizer", "jitter")
WORLDS = ((1, (20.0, 15.0)), (2, (30.0, 20.0)), (3, (40.0, 25.0)), (4, (25.0, 18.0)))
QUICK_WORLDS = ((1, (20.0, 15.0)), (2, (30.0, 20.0)))
JITTER = (0.03, math.radians(0.5))    # [m], [rad] std of the jitter of each scan's pose
SPACING = (1.0, math.radians(30.0))   # one scan per metre of travel or 30 deg of turn


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

def profiles(names, overrides: dict, pc_overrides: dict | None = None) -> dict:
    """Name -> (UpdaterConfig, pose check on, PoseCheckConfig or None); a name ending in
    ``+pc`` turns the pose check on (its keys ``pc_overrides``)."""
    from localization.confidence import PoseCheckConfig
    from robot.robot_config import ROBOT_UPDATER_DEFAULTS
    from updater import UpdaterConfig

    out = {}
    for name in names:
        base, check = (name[:-3], True) if name.endswith("+pc") else (name, False)
        if base == "paper":
            cfg = UpdaterConfig()
        elif base == "before":
            cfg = UpdaterConfig(**BEFORE)
        elif base == "robot":
            cfg = UpdaterConfig(**{**ROBOT_UPDATER_DEFAULTS, **overrides})
        else:
            raise SystemExit(f"unknown profile {name!r}")
        out[name] = (cfg, check, PoseCheckConfig(**(pc_overrides or {})) if check else None)
    return out


# The robot's updater rules before this benchmark (mapupdate update's defaults then): the
# baseline of recall the robot profile may not fall below by more than 0.02 pooled.
BEFORE = {
    "grow_into_unknown": True,
    "gate_min_interval": 0.0, "gate_min_distance": 0.2, "gate_min_rotation_deg": 20.0,
    "gate_velocity_max_dt": 0.5, "gate_fast_turn_deg_s": 60.0, "gate_recovery_time": 0.5,
    "gate_recovery_distance": 0.0, "gate_turn_cover": True, "gate_turn_views": 2,
    "gate_confirm": True,
    "unanimous_min": 3, "min_run_width": 0.2, "spread_removed": True,
    "support_exact_state": True,
}


# --- one world: every variant, every profile -------------------------------------------------

def one_world(job) -> list[dict]:
    from evaluation import scores as ev
    from gridmap import load_map
    from robot.replay import Placement, replay_observations
    from robotlogs import log_observations
    from sim.groundtruth import grid_frame
    from sim.scenario import load_scenario

    (seed, size, lidar, people), work, names, overrides, rates, poses, pc = job
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
    for rate, pose, (name, (cfg, check, check_cfg)) in itertools.product(
            rates, poses, profiles(names, overrides, pc).items()):
        rec = variant(found, rate, pose, seed)
        source = {"jitter": "truth"}.get(pose, pose)
        t0 = time.perf_counter()
        done = replay_observations(before, rec, Placement(source=source, pose_check=check,
                                                          pose_check_config=check_cfg),
                                   updater_config=cfg)
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


# --- the table -------------------------------------------------------------------------------

def pooled(rows) -> dict:
    t = sum(r["targets"] for r in rows)
    c = sum(r["changes"] for r in rows)
    return {"static_freed": sum(r["static_freed"] for r in rows),
            "face_freed": sum(r["face_freed"] for r in rows),
            "cases_freeing": sum(r["static_freed"] > 0 for r in rows),
            "recall": sum(r["fixed"] for r in rows) / t if t else math.nan,
            "precision": sum(r["correct"] for r in rows) / c if c else math.nan,
            "cases": len(rows)}


def print_tables(rows, names) -> None:
    keys = ("world", "lidar", "people", "rate", "poses")
    cases = sorted({tuple(r[k] for k in keys) for r in rows}, key=str)
    by = {(tuple(r[k] for k in keys), r["profile"]): r for r in rows}
    head = "| world | lidar | people | scans | poses | " + " | ".join(
        f"{n}: static freed / face / recall" for n in names) + " |"
    print(head)
    print("|" + "---|" * (5 + len(names)))
    for case in cases:
        cells = []
        for n in names:
            r = by.get((case, n))
            cells.append("-" if r is None else
                         f"{r['static_freed']} / {r['face_freed']} / "
                         + ("-" if not r["targets"] else f"{r['fixed'] / r['targets']:.3f}"))
        print(f"| {case[0]} | {case[1]} | {case[2]} | {case[3]} | {case[4]} | "
              + " | ".join(cells) + " |")
    print()
    print("| profile | cases | cases freeing | static freed | face freed | recall | precision |")
    print("|---|---|---|---|---|---|---|")
    for n in names:
        p = pooled([r for r in rows if r["profile"] == n])
        print(f"| {n} | {p['cases']} | {p['cases_freeing']} | {p['static_freed']} | "
              f"{p['face_freed']} | {p['recall']:.3f} | {p['precision']:.3f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="two worlds, one lidar, 8 people")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "static")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--profiles", default="paper,before,robot")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a key of the robot profile's updater, for experiments")
    ap.add_argument("--pc-set", action="append", default=[], metavar="KEY=VALUE",
                    help="a key of the pose check of the +pc profiles, for experiments")
    ap.add_argument("--poses", default=",".join(POSES))
    ap.add_argument("--rates", default=",".join(RATES))
    ap.add_argument("--people", default=",".join(map(str, PEOPLE)))
    ap.add_argument("--lidars", default=",".join(LIDARS))
    ap.add_argument("--worlds", type=int, default=None, help="the first N worlds only")
    args = ap.parse_args(argv)
    import yaml

    overrides = {k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.set)}
    names = args.profiles.split(",")
    worlds = QUICK_WORLDS if args.quick else WORLDS[:args.worlds]
    people = [int(p) for p in args.people.split(",")]
    pc = {k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.pc_set)}
    jobs = [((seed, size, lidar, n), str(args.out), names, overrides, args.rates.split(","),
             args.poses.split(","), pc)
            for (seed, size), lidar, n in itertools.product(worlds, args.lidars.split(","),
                                                            people)]
    rows = []
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        for i, got in enumerate(pool.map(one_world, jobs), 1):
            rows += got
            print(f"[{i}/{len(jobs)}] {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.json").write_text(json.dumps(rows, indent=1))
    print_tables(rows, names)
    robot = [r for r in rows if r["profile"] == "robot"]
    base = [r for r in rows if r["profile"] == "before"]
    bad = sum(r["static_freed"] for r in robot)
    lost = (pooled(base)["recall"] - pooled(robot)["recall"]) if robot and base else 0.0
    print(f"\nrobot profile: {bad} static cells freed; recall {lost:+.3f} below the rules "
          "before" if robot else "")
    return 1 if bad or lost > 0.02 else 0


if __name__ == "__main__":
    sys.exit(main())
