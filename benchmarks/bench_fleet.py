"""Several robots, one map: the fleet of ``scenarios.fleet`` in the built-in warehouse, N = 1..4
robots, each way of updating the map, sessions W2-W4 chained from one M1.

    python benchmarks/bench_fleet.py [--robots 1 2 3 4] [--seeds 7] [--modes shared store]
        [--out runs/bench_fleet]

Prints one row per run and session, then the mean over the update sessions per N and mode:
precision, recall, OPDF, ghosts, and how soon the map showed the target cells right (median
and 90th percentile of the time from the session's start; for the per-robot mode, the
robots' maps merged at that moment: its map is committed only at the session's end).
"""

from __future__ import annotations

import os

for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import sim  # noqa: E402
from scenarios.catalog import find_scenario  # noqa: E402
from scenarios.fleet import FleetOptions, format_table, mode_label, run_fleet  # noqa: E402
from scenarios.runner import build_initial_map  # noqa: E402
from scenarios.session import session_seeds  # noqa: E402

# (mode, merge rule, other robots hidden from the update)
VARIANTS = (("shared", "vote", True), ("per-robot", "vote", True), ("per-robot", "union", True),
            ("shared", "vote", False), ("per-robot", "union", False), ("store", "vote", True))
MEAN_KEYS = ("precision", "recall", "opdf", "ghosts", "ghosts_of_robots", "targets",
             "targets_fixed", "latency_median_s", "latency_p90_s", "committed_at_s",
             "scans_processed", "cpu_s", "commits", "merges", "conflicts")


def mean_rows(rows: list[dict]) -> list[dict]:
    """Per (N, mode, rule): the mean of each score over the sessions (and seeds)."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["robots"], mode_label(r)), []).append(r)
    out = []
    for (n, _), group in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1])):
        row = {"robots": n, "mode": group[0]["mode"], "merge_rule": group[0]["merge_rule"],
               "mask_robots": group[0]["mask_robots"], "session": "mean"}
        for key in MEAN_KEYS:
            values = [g[key] for g in group if g.get(key) is not None]
            row[key] = float(np.mean(values)) if values else None
        out.append(row)
    return out


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--robots", type=int, nargs="+", default=[1, 2, 3, 4])
    p.add_argument("--seeds", type=int, nargs="+", default=[7])
    p.add_argument("--sessions", type=int, default=None)
    p.add_argument("--out", type=Path, default=Path("runs/bench_fleet"))
    p.add_argument("--modes", nargs="+", default=None, choices=("shared", "per-robot", "store"),
                   help="only these modes (default every variant); the store mode commits to "
                        "an SQLite store of its own per run")
    args = p.parse_args()
    scn = sim.load_scenario(find_scenario("aws_small_warehouse"))
    rows = []
    wall = time.perf_counter()
    for seed in args.seeds:
        m1 = build_initial_map(scn, 0, session_seeds(seed, len(scn.sessions))[0]).updated
        for n in args.robots:
            for mode, rule, mask in VARIANTS:
                if args.modes and mode not in args.modes:
                    continue
                store = None
                if mode == "store":
                    args.out.mkdir(parents=True, exist_ok=True)
                    store = args.out / f"site-{seed}-{n}.db"
                    for old in args.out.glob(store.name + "*"):
                        old.unlink()
                opts = FleetOptions(robots=n, mode=mode, merge_rule=rule, seed=seed,
                                    mask_robots=mask, sessions=args.sessions, progress=False,
                                    store=None if store is None else str(store))
                record = run_fleet("aws_small_warehouse", opts, initial=m1)
                for row in record["sessions"]:
                    row["seed"] = seed
                rows.extend(record["sessions"])
                print(f"seed {seed} N={n} {mode} ({rule}, mask {mask}): "
                      f"{time.perf_counter() - wall:.0f} s", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "rows.json").write_text(json.dumps(rows, indent=1))
    print(format_table(rows))
    print()
    print(format_table(mean_rows(rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
