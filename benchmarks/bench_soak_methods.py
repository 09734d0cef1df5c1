"""The 50-session soak (``bench_soak.py``) for each method, side by side: the same random
rearrangements, people and seeds, the map updated by the paper's method or by a baseline
(``onboard.methods``), each chaining its own maps from session to session.

Every column runs behind the robot profile's localiser and pose check, as ``bench_soak.py``
does. ``paper`` is the paper's updater with the paper's settings (``bench_soak.py``'s own
run, to the digit); ``robot`` is the same updater with the robot profile's; ``hybrid``,
``fuse`` and ``remap`` take the robot profile's gating rules; ``none`` keeps M(i-1).

Per method, over the sessions after the first: precision and recall (mean and least-squares
trend per session; precision pooled over the sessions' changes too), recall on the targets the
session's own moves made, target cells, ghosts, cells occupied in the truth that a session
freed, cells drawn inside objects and in free space within 3 cells of a surface (as
``lifelong_misses.py`` counts them), OPDF of M(i) and of the oracle, the localiser's error
(APE) and the time per session. No bars: this compares, it does not judge. ``--set`` lays
updater keys over every column's settings, to try one rule off:

    python benchmarks/bench_soak_methods.py [--sessions N] [--seed S] [--methods paper,robot,...]
        [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(Path(__file__).resolve().parents[1]))

import bench_soak  # noqa: E402  (beside this file)
import lifelong_misses  # noqa: E402

METHODS = ("paper", "robot", "hybrid", "fuse", "remap", "none")


def run_options(method: str, overrides: dict | None = None) -> dict:
    """``bench_soak.run_soak``'s method and updater settings for a column, with ``overrides``
    (updater keys) laid over the settings."""
    from updater import UpdaterConfig

    profile = "paper" if method == "paper" else "robot"
    config = UpdaterConfig.profile(profile, overrides or None, "--set")
    return {"method": "paper" if method in ("paper", "robot") else method,
            "updater_config": config}


def wrong_draws(scn) -> tuple[dict, callable]:
    """Counts of the sessions' wrong changes by kind (``lifelong_misses.tally_wrong``) and the
    ``run_soak`` hook that adds each session's, after the first."""
    from gridmap import OCCUPIED

    counts = dict.fromkeys(["changes"] + [k for _, k in lifelong_misses.WRONG], 0)

    def tally(i, previous, res):
        if i < 2:
            return
        kept = bench_soak.standing_cells(scn, i, res.truth) & (res.truth.data == OCCUPIED)
        lifelong_misses.tally_wrong(counts, previous.data, res.updated.data, res.truth.data,
                                    kept, res.masks["people"])
    return counts, tally


def _mean(values) -> float:
    v = [x for x in values if x is not None]
    return float(np.mean(v)) if v else float("nan")


def summary(rows, wrong: dict) -> dict:
    rest = rows[1:] if len(rows) > 1 else rows
    k = max(1, len(rest) // 5)
    bad = sum(wrong[key] for _, key in lifelong_misses.WRONG[:-1])
    return {
        "precision": _mean(r.precision for r in rest),
        "pooled": 1 - bad / wrong["changes"] if wrong["changes"] else float("nan"),
        "changes": wrong["changes"], "draw_inside": wrong["draw_inside"],
        "draw_near": wrong["draw_near"], "ape": _mean(r.ape_rmse for r in rest),
        "precision_trend": bench_soak.trend([r.precision for r in rest]),
        "recall": _mean(r.recall for r in rest),
        "recall_trend": bench_soak.trend([r.recall for r in rest]),
        "recall_first": _mean(r.recall for r in rest[:k]),
        "recall_last": _mean(r.recall for r in rest[-k:]),
        "recall_new": _mean(r.recall_new for r in rest),
        "recall_new_trend": bench_soak.trend([r.recall_new for r in rest]),
        "targets": _mean(r.targets for r in rest),
        "ghosts": sum(r.ghosts for r in rest), "ghosts_max": max(r.ghosts for r in rest),
        "g_freed": sum(r.g_freed for r in rest),
        "opdf": _mean(r.opdf for r in rest), "opdf_last": _mean(r.opdf for r in rest[-k:]),
        "opdf_oracle": _mean(r.opdf_oracle for r in rest),
        "wall_s": _mean(r.wall_s for r in rest)}


ROWS = [("precision (trend per session)", "{precision:.3f} ({precision_trend:+.4f})"),
        ("precision pooled (changes)", "{pooled:.3f} ({changes})"),
        ("recall on all targets (trend)", "{recall:.3f} ({recall_trend:+.4f})"),
        ("recall, first / last fifth", "{recall_first:.3f} / {recall_last:.3f}"),
        ("recall on new targets (trend)", "{recall_new:.3f} ({recall_new_trend:+.4f})"),
        ("target cells per session", "{targets:.0f}"),
        ("ghost cells, all sessions (most in one)", "{ghosts} ({ghosts_max})"),
        ("G-occupied cells freed, all sessions", "{g_freed}"),
        ("cells drawn inside objects / 2-3 cells from a surface", "{draw_inside} / {draw_near}"),
        ("OPDF M(i) %, mean / last fifth", "{opdf:.2f} / {opdf_last:.2f}"),
        ("OPDF oracle %", "{opdf_oracle:.2f}"),
        ("APE m per session", "{ape:.3f}"),
        ("wall s per session", "{wall_s:.2f}")]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sessions", type=int, default=50)
    ap.add_argument("--seed", type=int, default=2024, help="seed of the rearrangements")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help=f"comma-separated, of {', '.join(METHODS)}")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                    help="updater keys over every column's settings (YAML values)")
    args = ap.parse_args(argv)
    bench_soak.check_run_arguments(ap, args)
    from onboard.methods import MethodError, check_method
    from updater import UpdaterError

    try:
        methods = [check_method(m.strip(), "--methods", METHODS)
                   for m in args.methods.split(",")]
    except MethodError as e:
        ap.error(str(e))
    overrides = bench_soak.parse_set(ap, args.set)
    try:
        options = {m: run_options(m, overrides) for m in methods}
    except UpdaterError as e:
        ap.error(str(e).splitlines()[0])
    t0 = time.perf_counter()
    scn, moved = bench_soak.soak_scenario(args.sessions, args.seed)
    results = {}
    for method in methods:
        print(f"{method} ...", file=sys.stderr, flush=True)
        wrong, tally = wrong_draws(scn)
        rows = bench_soak.run_soak(scn, moved, progress=False, on_session=tally,
                                   **options[method])
        results[method] = summary(rows, wrong)
    print(f"| {args.sessions} sessions, seed {args.seed} | " + " | ".join(methods) + " |")
    print("|---|" + "---|" * len(methods))
    for label, fmt in ROWS:
        cells = [fmt.format(**results[m]) for m in methods]
        # a column that changed nothing has no precision
        cells = ["n/a" if c.startswith("nan") else c for c in cells]
        print(f"| {label} | " + " | ".join(cells) + " |")
    print(f"\nTotal wall time {time.perf_counter() - t0:.0f} s.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
