"""Lifelong benchmark: a hundred sessions of a warehouse, each rearranged, per method.

Layouts: the built-in warehouse (``builtin``) and generated warehouses (``gen<seed>``, 30 x 20 m,
``mapupdate generate --seed <seed>``), each with W1 mapped as in the main job and N update sessions
after it (default 100) on quick routes (the built-in's first 30 m of the transport loop; a
generated one's own quick route of each session, with its people). Each session rearranges one
to three movable objects that its route sees: nudged by 5-30 cm (within the pairing distance,
where the paper's rules call the old face unchanged), moved by 0.5-3 m, removed, or added (a
pallet, drum or box set down beside the route); every placement passes the scenario checks and
keeps a lane of 0.3 m beside the robot's path. Run seeds: each layout and seed draws its own
rearrangements and the run's noise and people.

Methods: ``paper`` (the paper profile), ``robot`` (the robot profile), ``hybrid`` and ``fuse``
(with the robot profile's gate and pose check). Each chains its own maps from session to
session, exactly as ``mapupdate run`` does (``runner.run_update_session``).

Per session (``bench_soak.SessionRow``): precision and recall on the observable cells M(i-1) got
wrong (the targets, new and left over), recall on the new ones, ghosts (occupied cells of M(i)
far from the truth's that a person covered; split into those the session drew and those the
oracle keeps too, cells of M(i-1) the route never showed), cells occupied in the
truth that the session freed (a wall, rack or unmoved object), OPDF of M(i) and of the oracle,
the localiser's APE, wall time and peak memory. Per run: trends (least squares per session) and
first / last fifth; the bars of the robot profile checked per layout and seed.

Each run (layout, seed, method) is written to ``<out>/<layout>_s<seed>_<method>.json`` when it
ends, and a run already there is not run again (``--out`` keeps them: kill and start again to
resume). Runs go in ``--workers`` processes.

    python benchmarks/bench_lifelong.py [--sessions N] [--layouts builtin,gen101,gen202]
        [--seeds 1,2,3] [--methods paper,robot,hybrid,fuse] [--workers 2] [--out DIR]
        [--figure FILE.png] [--config FILE.yaml]
    python benchmarks/bench_lifelong.py --recordings builtin:1 [--sessions N]
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import json
import math
import os
import shutil
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(Path(__file__).resolve().parents[1]))

import bench_soak  # noqa: E402  (beside this file)

LAYOUTS = ("builtin", "gen101", "gen202")
SEEDS = (1, 2, 3)
METHODS = ("paper", "robot", "hybrid", "fuse")
# [m] a nudge: an object pushed a little, its new face within the pairing distance D(r) of the
# old one (0.15-0.30 m) at the short end, just beyond it at the long end
NUDGE = (0.05, 0.30)
MOVE = (0.5, 3.0)        # [m] a move
KINDS = ("nudge", "move", "move", "remove", "add")
MIN_MOVABLE = 6          # objects the world keeps at least (removals stop below it)
ADD_KINDS = {"pallet": {"size": [1.2, 1.0]}, "drum": {"radius": 0.3},
             "box": {"size": [0.6, 0.6]}}

# The bars of the robot profile over the sessions (docs: benchmarks/RESULTS.md, "Lifelong").
BARS = {"recall_trend": -0.001, "last_fifth": 0.85, "fifth_drop": 0.05, "precision": 0.98,
        "g_freed": 0, "ghosts_median": 0, "opdf_gap": 0.05, "flat": 0.10}


# --- the sessions -------------------------------------------------------------------------------
def base_scenario(layout: str, n_sessions: int) -> tuple[dict, list[dict]]:
    """The scenario tree of a layout without its update sessions, and N sessions' routes and
    people (the built-in's transport loop cut to 30 m, a generated layout's quick routes)."""
    import yaml

    import sim
    from scenarios.catalog import find_scenario
    from scenarios.generator import generate

    if layout == "builtin":
        data = yaml.safe_load(find_scenario(None).read_text())
        quick = sim.quick_variant(sim.scenario_from_dict(data, "warehouse"),
                                  max_route_length=30.0)
        route = [list(p) for p in quick.sessions[1].route]
        people = [p for s in data["sessions"][1:] for p in s.get("people", [])]
        rng = np.random.default_rng(len(people))
        plans = [{"route": route, "people": [people[k] for k in sorted(rng.choice(
            len(people), size=rng.integers(2, 5), replace=False))]} for _ in range(n_sessions)]
    elif layout.startswith("gen") and layout[3:].isdigit():
        data = generate(int(layout[3:]), sessions=min(n_sessions + 1, 100))
        upd = data["sessions"][1:]
        plans = [{"route": upd[i % len(upd)]["quick_route"],
                  "people": upd[i % len(upd)].get("people", [])} for i in range(n_sessions)]
    else:
        raise SystemExit(f"unknown layout {layout!r}: builtin or gen<seed>")
    base = {k: v for k, v in data.items() if k != "sessions"}
    return {**base, "w1": data["sessions"][0]}, plans


def _shifted(o: dict, rng, lengths: tuple[float, float], nudge: bool) -> dict:
    """``o`` moved by a length drawn from ``lengths`` [m] in a random direction; a nudge
    turns a box a little now and then, a move by a quarter turn or none."""
    length = rng.uniform(*lengths)
    heading = rng.uniform(-math.pi, math.pi)
    cx, cy = np.asarray(o["center"], float) + length * np.array([math.cos(heading),
                                                                 math.sin(heading)])
    out = {**o, "center": [round(float(cx), 3), round(float(cy), 3)]}
    if "size" in o and nudge and rng.random() < 0.3:
        out["yaw"] = round(float(o.get("yaw", 0.0) + rng.uniform(-0.15, 0.15)), 4)
    elif "size" in o and not nudge:
        out["yaw"] = round(float(o.get("yaw", 0.0) + rng.choice([0.0, math.pi / 2,
                                                                 -math.pi / 2])), 4)
    return out


def _added(rng, route, counter: int) -> dict:
    kind = str(rng.choice(["pallet", "pallet", "drum", "box"]))
    pts = np.asarray(route, float)
    k = int(rng.integers(0, len(pts) - 1))
    t = rng.uniform()
    x, y = pts[k] + t * (pts[k + 1] - pts[k])
    side = rng.uniform(1.0, 3.5) * rng.choice([-1.0, 1.0])
    along = rng.uniform(-2.0, 2.0)
    d = pts[k + 1] - pts[k]
    d = d / max(1e-9, float(np.hypot(*d)))
    cx, cy = np.array([x, y]) + along * d + side * np.array([-d[1], d[0]])
    o = {"id": f"{kind}_life{counter}", "center": [round(float(cx), 3), round(float(cy), 3)],
         "kind": kind, **copy.deepcopy(ADD_KINDS[kind])}
    if "size" in o:
        o["yaw"] = round(float(rng.uniform(-math.pi, math.pi)), 4)
    return o


def lifelong_scenario(layout: str, n_sessions: int = 100, seed: int = 1):
    """The layout with W1 and ``n_sessions`` rearranged update sessions (a scenario tree whose
    sessions drive quick routes), what each session changed, as text, and how many changes
    of each kind were drawn and made."""
    import sim

    rng = np.random.default_rng([seed, sum(map(ord, layout))])
    tree, plans = base_scenario(layout, n_sessions)
    w1 = tree.pop("w1")
    movable = {o["id"]: dict(o) for o in tree["world"]["movable"]}
    sessions, what = [w1], []
    added = 0
    tally = {}
    for i, plan in enumerate(plans):
        name = f"S{i + 2:03d}"
        # a route an earlier change blocked is given up for the next one the world allows
        routes = [plan["route"]] + [q["route"] for q in plans[i + 1:] + plans[:i]]
        route = next((list(map(list, r)) for r in routes if bench_soak._valid(
            tree, movable, {"name": name, "route": [list(p) for p in r]})), None)
        if route is None:
            raise RuntimeError(f"{layout}, seed {seed}, {name}: every route is blocked")
        chosen = [p for p in plan["people"] if bench_soak._valid(
            tree, movable, {"name": name, "route": route, "people": [p]})]
        session = {"name": name, "route": route, "people": copy.deepcopy(chosen),
                   "changes": []}
        seen = bench_soak.seen_objects(bench_soak._world_now(
            tree, movable, {"name": name, "route": route}), 0)
        done, notes = [], []
        for _ in range(int(rng.integers(1, 4))):
            kind = str(rng.choice(KINDS))
            pool = [o for o in seen if o not in done and o in movable]
            if kind != "add" and not pool:
                kind = "add"
            if kind == "remove" and len(movable) <= MIN_MOVABLE:
                kind = "move"
            tally[kind] = tally.get(kind, 0) + 1
            for _ in range(20):        # a few tries for a valid place
                if kind == "add":
                    o = _added(rng, route, added + 1)
                    trial, change = {**movable, o["id"]: o}, {"add": o}
                    oid = o["id"]
                elif kind == "remove":
                    oid = str(rng.choice(pool))
                    trial = {k: v for k, v in movable.items() if k != oid}
                    change = {"remove": oid}
                else:
                    oid = str(rng.choice(pool))
                    o = _shifted(movable[oid], rng, NUDGE if kind == "nudge" else MOVE,
                                 kind == "nudge")
                    trial = {**movable, oid: o}
                    change = {"move": oid, "to": o["center"] + ([o["yaw"]] if "size" in o
                                                                else [])}
                # the world with the session's changes made (``trial``) checked as it stands
                if bench_soak._valid(tree, trial, {**session, "changes": []},
                                     None if kind == "remove" else oid,
                                     bench_soak.LANE_MARGIN):
                    movable = trial
                    session["changes"].append(change)
                    done.append(oid)
                    added += kind == "add"
                    notes.append(f"{kind} {oid}")
                    tally[kind + " done"] = tally.get(kind + " done", 0) + 1
                    break
        what.append(", ".join(notes) or "-")
        sessions.append(session)
    tree = {**tree, "seed": int(seed), "sessions": sessions}
    sim.scenario_from_dict(tree, f"lifelong-{layout}")      # the scenario checks, once more
    return tree, what, tally


# --- one run ------------------------------------------------------------------------------------
def method_options(method: str) -> dict:
    """run_soak's method and profile for a method of this benchmark."""
    return {"paper": {"method": "paper", "profile": "paper"},
            "robot": {"method": "paper", "profile": "robot"},
            "hybrid": {"method": "hybrid", "profile": "robot"},
            "fuse": {"method": "fuse", "profile": "robot"}}[method]


def scenario_path(out_dir, layout: str, seed: int, n: int) -> Path:
    return Path(out_dir) / "scenarios" / f"{layout}_s{seed}_n{n}.json"


def make_scenario(job) -> str:
    """Write a layout and seed's sessions once (``scenario_path``), for every method's run."""
    layout, seed, n, out_dir = job
    path = scenario_path(out_dir, layout, seed, n)
    if path.exists():
        return f"{path.name}: kept"
    t0 = time.perf_counter()
    tree, what, tally = lifelong_scenario(layout, n, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"tree": tree, "what": what, "tally": tally}) + "\n")
    os.replace(tmp, path)
    return f"{path.name}: {time.perf_counter() - t0:.0f} s, changes {tally}"


class ScenarioFileError(Exception):
    """A scenario file of ``--out`` that cannot be read."""


def load_scenario(out_dir, layout: str, seed: int, n: int):
    import sim

    path = scenario_path(out_dir, layout, seed, n)
    try:
        data = json.loads(path.read_text())
        return sim.scenario_from_dict(data["tree"], f"lifelong-{layout}"), data["what"]
    except Exception as e:  # noqa: BLE001 - whatever is wrong with it, the file is damaged
        raise ScenarioFileError(f"{path}: not a readable lifelong scenario "
                                f"({type(e).__name__}: {' '.join(str(e).split())[:200]}); "
                                "delete it to write it again") from None


def run_one(job) -> str:
    layout, seed, method, n, out_dir, config = job
    path = Path(out_dir) / f"{layout}_s{seed}_{method}.json"
    if path.exists():
        return f"{path.name}: kept"
    t0 = time.perf_counter()
    scn, what = load_scenario(out_dir, layout, seed, n)
    updater_config = None
    if config:
        from updater import UpdaterConfig

        opts = method_options(method)
        updater_config = UpdaterConfig.profile(opts["profile"], _updater_keys(config))
    rows = bench_soak.run_soak(scn, what, progress=False, updater_config=updater_config,
                               **method_options(method))
    out = {"layout": layout, "seed": seed, "method": method, "sessions": n,
           "run_s": time.perf_counter() - t0, "config": config,
           "rows": [asdict(r) for r in rows]}
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(out) + "\n")
    os.replace(tmp, path)
    return f"{path.name}: {out['run_s']:.0f} s"


def _updater_keys(config_path) -> dict:
    import yaml

    data = yaml.safe_load(Path(config_path).read_text()) or {}
    return data.get("updater", data)


# --- summaries ----------------------------------------------------------------------------------
def _vals(rows, key):
    return [r[key] for r in rows]


def _mean(values) -> float:
    v = [x for x in values if x is not None]
    return float(np.mean(v)) if v else float("nan")


def summarise(run: dict) -> dict:
    """A run's figures over its sessions after the first (whose time includes compiling)."""
    rows = run["rows"][1:]
    k = max(1, len(rows) // 5)
    rec = _vals(rows, "recall")
    first, last = _mean(rec[:k]), _mean(rec[-k:])
    wall, mem = np.array(_vals(rows, "wall_s")), np.array(_vals(rows, "peak_rss_mb"))
    opdf_gap = np.array(_vals(rows, "opdf_oracle")) - np.array(_vals(rows, "opdf"))
    return {
        "recall": _mean(rec), "recall_trend": bench_soak.trend(rec),
        "recall_first": first, "recall_last": last,
        "recall_new": _mean(_vals(rows, "recall_new")),
        "precision": _mean(_vals(rows, "precision")),
        "precision_trend": bench_soak.trend(_vals(rows, "precision")),
        "precision_last": _mean(_vals(rows, "precision")[-k:]),
        "g_freed": int(sum(_vals(rows, "g_freed"))),
        # rows written before standing_freed was counted: None
        "standing_freed": int(sum(r["standing_freed"] for r in rows))
        if all("standing_freed" in r for r in rows) else None,
        "standing_gaps": int(sum(r["standing_gaps"] for r in rows))
        if all("standing_gaps" in r for r in rows) else None,
        "ghosts_median": float(np.median(_vals(rows, "ghosts"))),
        "ghosts": int(sum(_vals(rows, "ghosts"))),
        # rows written before the ghosts were split: None
        "ghosts_drawn_median": float(np.median(_vals(rows, "ghosts_drawn")))
        if all("ghosts_drawn" in r for r in rows) else None,
        "ghosts_oracle_median": float(np.median(_vals(rows, "ghosts_oracle")))
        if all("ghosts_oracle" in r for r in rows) else None,
        "opdf_last": float(np.mean(_vals(rows, "opdf")[-k:])),
        "opdf_gap_last": float(np.mean(opdf_gap[-k:])),
        "ape": _mean(_vals(rows, "ape_rmse")),
        "targets_last": _mean(_vals(rows, "targets")[-k:]),
        "wall_s": float(np.mean(wall)),
        "time_change": float(np.median(wall[-k:]) / np.median(wall[:k]) - 1.0),
        "memory_change": float(np.median(mem[-k:]) / np.median(mem[:k]) - 1.0),
        "peak_mb": float(mem.max()),
        "idle_sessions": sum(1 for r in rows if r["scans_processed"] == 0),
    }


def bars(s: dict) -> dict:
    """Which bars of BARS a run's summary meets."""
    return {
        "recall trend": s["recall_trend"] >= BARS["recall_trend"],
        "last fifth": s["recall_last"] >= BARS["last_fifth"]
        and s["recall_first"] - s["recall_last"] <= BARS["fifth_drop"],
        "precision": s["precision"] >= BARS["precision"],
        "nothing standing freed": (s["g_freed"] if s["standing_freed"] is None
                                   else s["standing_freed"]) <= BARS["g_freed"],
        "ghosts": s["ghosts_median"] <= BARS["ghosts_median"],
        "OPDF": s["opdf_gap_last"] <= BARS["opdf_gap"],
        "flat": abs(s["time_change"]) <= BARS["flat"] and abs(s["memory_change"]) <= BARS["flat"],
    }


def _standing(s: dict) -> str:
    if s["standing_freed"] is None:
        return "n/a"
    gaps = "" if s["standing_gaps"] is None else f"; {s['standing_gaps']}"
    return f"{s['standing_freed']}{gaps}"


def _split(s: dict) -> str:
    if s["ghosts_drawn_median"] is None:
        return ""
    return f"; {s['ghosts_drawn_median']:.0f} / {s['ghosts_oracle_median']:.0f}"


def print_tables(runs: list[dict]) -> None:
    print("| layout | seed | method | recall (trend/session) | first / last fifth | recall on new "
          "| precision (trend) | cells of G freed (of a wall, rack or unmoved object; of them "
          "leaving a gap) | "
          "ghosts (median/session; drawn / oracle's) | OPDF last fifth "
          "(oracle - M) | APE m | s/session (last/first fifth) | peak MB (last/first) | "
          "bars missed |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    summaries = [summarise(run) for run in runs]
    for run, s in zip(runs, summaries):
        missed = [k for k, ok in bars(s).items() if not ok] if run["method"] == "robot" else []
        print(f"| {run['layout']} | {run['seed']} | {run['method']} | {s['recall']:.3f} "
              f"({s['recall_trend']:+.4f}) | {s['recall_first']:.3f} / {s['recall_last']:.3f} | "
              f"{s['recall_new']:.3f} | {s['precision']:.3f} ({s['precision_trend']:+.4f}) | "
              f"{s['g_freed']} ({_standing(s)})"
              f" | {s['ghosts']} ({s['ghosts_median']:.0f}{_split(s)}) | "
              f"{s['opdf_last']:.2f} ({s['opdf_gap_last']:+.2f}) | {s['ape']:.3f} | "
              f"{s['wall_s']:.2f} ({100 * s['time_change']:+.0f} %) | {s['peak_mb']:.0f} "
              f"({100 * s['memory_change']:+.1f} %) | "
              f"{', '.join(missed) if run['method'] == 'robot' else 'n/a'} |")
    print()
    print("| method | runs | recall | trend | first / last fifth | precision | G freed "
          "| ghosts median | OPDF gap last fifth |")
    print("|---|---|---|---|---|---|---|---|---|")
    for method in dict.fromkeys(r["method"] for r in runs):
        ss = [s for r, s in zip(runs, summaries) if r["method"] == method]
        # a run whose last fifth processed no scan has no recall there: left out of the mean
        m = {k: float(np.nanmean([s[k] for s in ss])) for k in ss[0]
             if k not in ("standing_freed", "standing_gaps", "ghosts_drawn_median",
                          "ghosts_oracle_median")}
        print(f"| {method} | {len(ss)} | {m['recall']:.3f} | {m['recall_trend']:+.4f} | "
              f"{m['recall_first']:.3f} / {m['recall_last']:.3f} | {m['precision']:.3f} | "
              f"{m['g_freed']:.1f} | {m['ghosts_median']:.1f} | {m['opdf_gap_last']:+.2f} |")
    for run, s in zip(runs, summaries):
        if s["idle_sessions"]:
            print(f"{run['layout']} seed {run['seed']}, {run['method']}: {s['idle_sessions']} "
                  f"sessions processed no scan (a pose check that refused them all)")


def figure(runs: list[dict], path: Path) -> None:
    """Recall and precision over the sessions, per method: each run thin, the mean thick."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4), sharex=True)
    labels = list(dict.fromkeys(r["method"] for r in runs))
    colours = dict(zip(labels, ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple",
                                "tab:brown", "tab:grey")))
    for method in labels:
        mine = [r for r in runs if r["method"] == method]
        if not mine:
            continue
        for ax, key in zip(axes, ("recall", "precision")):
            series = []
            for r in mine:
                y = np.array([np.nan if v is None else v for v in _vals(r["rows"], key)], float)
                ax.plot(np.arange(2, y.size + 2), y, color=colours[method], lw=0.4, alpha=0.3)
                series.append(y)
            n = min(len(y) for y in series)
            mean = np.nanmean(np.vstack([y[:n] for y in series]), axis=0)
            k = min(9, n)           # a moving mean over 9 sessions (fewer in a short run)
            ok = np.isfinite(mean)      # a session with no change has no precision
            total = np.convolve(np.where(ok, mean, 0.0), np.ones(k), mode="valid")
            smooth = total / np.maximum(np.convolve(ok.astype(float), np.ones(k), mode="valid"),
                                        1.0)
            ax.plot(np.arange(2, n + 2)[k // 2: k // 2 + smooth.size], smooth,
                    color=colours[method], lw=2, label=f"{method} ({len(mine)} runs)")
    axes[0].set_title("recall on the observable wrong cells")
    axes[1].set_title("precision")
    for ax in axes:
        ax.set_xlabel("session")
        ax.grid(alpha=0.3)
    axes[0].axhline(BARS["last_fifth"], color="k", lw=0.8, ls="--")
    axes[1].axhline(BARS["precision"], color="k", lw=0.8, ls="--")
    axes[0].legend(fontsize=8)
    tmp = path.with_name(path.stem + ".tmp.png")
    fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    os.replace(tmp, path)


def recordings(layout: str, seed: int, n: int, out_dir: Path) -> bool:
    """The sessions of a layout and seed (robot profile) as ``mapupdate run`` plays them, each
    recorded as a ROS 1 bag, then played again one recording a session through ``mapupdate
    update --state FILE --new-session`` from the last one's map. Prints, per session, whether
    the map equals the run's and the state file's size; True when every map does."""
    import yaml

    from gridmap import load_map
    from mapupdate import main as cli
    from scenarios.runner import RunOptions, run_scenario
    from scenarios.session_bags import SessionBagRecorder

    folder = Path(out_dir) / f"recordings_{layout}_s{seed}_n{n}"
    folder.mkdir(parents=True, exist_ok=True)
    if not scenario_path(out_dir, layout, seed, n).exists():
        make_scenario((layout, seed, n, str(out_dir)))
    tree = json.loads(scenario_path(out_dir, layout, seed, n).read_text())["tree"]
    (folder / "scenario.yaml").write_text(yaml.safe_dump(tree, sort_keys=False))
    rec = SessionBagRecorder(folder / "bags", "ros1")
    t0 = time.perf_counter()
    # afresh each time: a run left by other code would not be this code's chained run
    for old in ("run", "bags", "replayed"):
        shutil.rmtree(folder / old, ignore_errors=True)
    run_scenario(folder / "scenario.yaml", RunOptions(out=folder / "run", progress=False,
                                                      observer=rec))
    t_run = time.perf_counter() - t0
    # the recorded poses replayed as the run placed them: refined and held by the pose check
    # as the run's own localiser's were, and not smoothed
    (folder / "config.yaml").write_text("pose_check:\n  refine_given: true\n  lost_given: true\n")
    state, previous = folder / "life.npz", folder / "run" / "maps" / "M_W1.yaml"
    state.unlink(missing_ok=True)
    names = [s["name"] for s in tree["sessions"][1:]]
    print("| session | same map as the run | cells differing | state file KB |")
    print("|---|---|---|---|")
    same = 0
    for name in names:
        out = folder / "replayed" / f"{name}.yaml"
        out.parent.mkdir(exist_ok=True)
        with open(os.devnull, "w") as quiet, contextlib.redirect_stdout(quiet):
            code = cli(["update", "--map", str(previous), "--log", str(rec.paths[name]),
                        "--out", str(out), "--state", str(state), "--new-session",
                        "--config", str(folder / "config.yaml"), "--smooth-poses", "0",
                        "--no-progress"])
        if code != 0:
            raise SystemExit(f"update of {name} failed ({code})")
        differ = int(np.count_nonzero(load_map(out).data != load_map(
            folder / "run" / "maps" / f"M_{name}.yaml").data))
        same += differ == 0
        print(f"| {name} | {'yes' if differ == 0 else 'no'} | {differ} | "
              f"{state.stat().st_size / 1024:.0f} |", flush=True)
        previous = out
    print(f"\n{same} of {len(names)} maps the same; the run {t_run:.0f} s, the replays "
          f"{time.perf_counter() - t0 - t_run:.0f} s")
    return same == len(names)


def _pool_map(fn, jobs, workers: int, t0: float) -> None:
    """``fn`` over ``jobs`` in ``workers`` processes, a line on stderr as each ends."""
    if workers > 1:
        import multiprocessing as mp

        with mp.get_context("spawn").Pool(workers, maxtasksperchild=1) as pool:
            for k, msg in enumerate(pool.imap_unordered(fn, jobs), 1):
                print(f"[{k}/{len(jobs)}, {time.perf_counter() - t0:.0f} s] {msg}",
                      file=sys.stderr, flush=True)
        return
    for k, job in enumerate(jobs, 1):
        print(f"[{k}/{len(jobs)}, {time.perf_counter() - t0:.0f} s] {fn(job)}",
              file=sys.stderr, flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sessions", type=int, default=100)
    ap.add_argument("--layouts", default=",".join(LAYOUTS))
    ap.add_argument("--seeds", default=",".join(map(str, SEEDS)))
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("runs/lifelong"))
    ap.add_argument("--figure", type=Path, default=None,
                    help="PNG of recall and precision over the sessions (default "
                         "<out>/lifelong.png)")
    ap.add_argument("--config", type=Path, default=None,
                    help="YAML of updater keys laid over each method's profile")
    ap.add_argument("--recordings", metavar="LAYOUT:SEED", default=None,
                    help="instead: the robot profile's sessions of one layout and seed recorded "
                         "as bags and replayed one a session through `mapupdate update --state "
                         "--new-session`, each map checked against the run's")
    args = ap.parse_args(argv)
    if args.out.exists() and not args.out.is_dir():
        ap.error(f"--out {args.out}: a file, not a folder")
    if not 2 <= args.sessions <= 1000:
        ap.error(f"--sessions must be a whole number from 2 to 1000, got {args.sessions}")
    if args.recordings:
        layout, _, seed = args.recordings.partition(":")
        if not (seed or "1").isdigit():
            ap.error(f"--recordings takes LAYOUT:SEED with a whole seed, got "
                     f"{args.recordings!r}")
        return 0 if recordings(layout, int(seed or 1), args.sessions, args.out) else 1
    methods = args.methods.split(",")
    bad = [m for m in methods if m not in METHODS]
    if bad:
        ap.error(f"unknown method {bad[0]!r} (methods: {', '.join(METHODS)})")
    args.out.mkdir(parents=True, exist_ok=True)
    # method by method, seed by seed: a run cut short has every layout of the first ones
    jobs = [(layout, int(seed), method, args.sessions, str(args.out),
             str(args.config) if args.config else None)
            for method in methods for seed in args.seeds.split(",")
            for layout in args.layouts.split(",")]
    t0 = time.perf_counter()
    scenarios = sorted({(j[0], j[1], args.sessions, str(args.out)) for j in jobs})
    _pool_map(make_scenario, scenarios, args.workers, t0)
    _pool_map(run_one, jobs, args.workers, t0)
    runs = [json.loads((args.out / f"{j[0]}_s{j[1]}_{j[2]}.json").read_text()) for j in jobs]
    print_tables(runs)
    figure(runs, args.figure or args.out / "lifelong.png")
    robot = [r for r in runs if r["method"] == "robot"]
    missed = sum(not all(bars(summarise(r)).values()) for r in robot)
    print(f"\nrobot profile: {len(robot) - missed} of {len(robot)} runs meet every bar; "
          f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    try:
        raise SystemExit(main())
    except ScenarioFileError as e:
        raise SystemExit(f"bench_lifelong.py: {e}") from None
