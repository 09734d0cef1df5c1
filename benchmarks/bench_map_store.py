"""The map store at a site's scale: commits per second, the bytes each version adds, and the
time to read a version and a diff, on a 400 x 250 m map at 5 cm (8000 x 5000 cells), in an
SQLite file and in PostgreSQL (a server started for the run from Debian's binaries, as the
tests do; its row is left out, with the reason, where there is none).

SQLite runs in WAL mode with synchronous=FULL, PostgreSQL with fsync on: a finished commit is
on disk in both. Each session moves ``PALLETS`` pallets (drawn where there was floor, freed where one stood)
and flips ``SPECKS`` single cells (the noise a real update leaves), about 15 000 changed cells,
on a warehouse of rack rows whose insides the lidar never sees (unknown).

``--fleet 8 32``: that many robots (processes) commit at once to one PostgreSQL server (fsync
on), each ``--fleet-commits`` sessions on a 200 x 200 m site at 5 cm (4000 x 4000 cells): a
robot reads the site's latest version, works for a while (0.2-1 s), moves pallets in a part
of the site it shares with one neighbour and commits from the version it read, so that most
commits are merged with what others committed meanwhile. Printed: commits per second, the
time of a commit with and without a merge, the conflicts, and whether the site map equals
the robots' own changes replayed in commit order (nothing lost).

Usage: ``python benchmarks/bench_map_store.py [--commits N] [--quick] [--fleet N ...]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid  # noqa: E402
from mapstore import cells, open_store  # noqa: E402
from mapstore.store import TABLES  # noqa: E402

PALLETS, SPECKS = 30, 500


def site_map(width: int, height: int, noise: float, seed: int = 0) -> np.ndarray:
    """A warehouse: outer walls, bays of rack rows (1.2 m deep, outline seen, inside unknown)
    along 3 m aisles, pillars, unknown outside the building, and a share ``noise`` of its
    floor cells unknown or occupied at random (what makes a real map compress less)."""
    rng = np.random.default_rng(seed)
    d = np.full((height, width), UNKNOWN, np.int8)
    d[40:-40, 40:-40] = OCCUPIED
    d[44:-44, 44:-44] = FREE
    bay_w = (width - 88) // 4
    for bay in range(4):
        c0, c1 = 44 + bay * bay_w + 100, 44 + (bay + 1) * bay_w - 100
        for r0 in range(140, height - 140, 84):          # 24 cells of rack, 60 of aisle
            d[r0:r0 + 24, c0:c1] = OCCUPIED
            d[r0 + 2:r0 + 22, c0 + 2:c1 - 2] = UNKNOWN
            gaps = rng.integers(c0, c1, 40)               # scan shadows along the faces
            d[r0, gaps] = UNKNOWN
    d[44:-44:200, 44:-44:200] = OCCUPIED                  # pillars every 10 m
    speck = (rng.random(d.shape) < noise) & (d == FREE)
    d[speck] = np.where(rng.random(int(speck.sum())) < 0.5, UNKNOWN, OCCUPIED)
    return d


def session(d: np.ndarray, rng) -> np.ndarray:
    """The next session's map: pallets drawn on floor or freed, specks flipped."""
    d = d.copy()
    h, w = d.shape
    for _ in range(PALLETS):
        r, c = int(rng.integers(60, h - 90)), int(rng.integers(60, w - 90))
        patch = d[r:r + 24, c:c + 20]
        if (patch == FREE).mean() > 0.8:
            patch[...] = OCCUPIED
            patch[2:-2, 2:-2] = UNKNOWN
        elif (patch != UNKNOWN).any():
            patch[...] = FREE
    idx = rng.integers(0, d.size, SPECKS)
    flat = d.reshape(-1)
    flat[idx] = np.where(flat[idx] == FREE, OCCUPIED, FREE)
    return d


def measure(target, maps: list[np.ndarray], size_of) -> dict:
    times, reads, diffs = [], [], []
    with open_store(target, create=True) as store:
        before = size_of(store)
        parent = None
        for d in maps:
            t0 = time.perf_counter()
            parent = store.commit(OccupancyGrid(d, 0.05), parent, {"robot": "bench"})
            times.append(time.perf_counter() - t0)
        for v in range(2, len(maps) + 1):
            t0 = time.perf_counter()
            store.get(v)
            reads.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            store.diff(v - 1, v)
            diffs.append(time.perf_counter() - t0)
        per_version = (size_of(store) - before) / len(maps)
    return {"commit_s": statistics.median(times[1:]), "first_s": times[0],
            "read_s": statistics.median(reads), "diff_s": statistics.median(diffs),
            "bytes": per_version}


def sqlite_size(path: Path):
    def size(store) -> int:
        store.db.run("PRAGMA wal_checkpoint(TRUNCATE)")
        return sum(p.stat().st_size for p in path.parent.glob(path.name + "*"))
    return size


def postgres_size(store) -> int:
    store.db.run("CHECKPOINT")
    return int(store.db.rows("SELECT SUM(pg_total_relation_size(c.oid)) FROM pg_class c "
                             "WHERE c.relname = ANY(?) AND c.relkind = 'r'",
                             (list(TABLES),))[0][0] or 0)


# the floor noise of the two maps: nearly clean, and rough enough to pack to about what the
# maps updated from real recordings pack to (0.13 to 0.23 bytes per known cell)
NOISE = {"clean": 5e-4, "rough": 0.06}


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--commits", type=int, default=8)
    p.add_argument("--quick", action="store_true", help="a 100 x 62.5 m map")
    p.add_argument("--fleet", type=int, nargs="*", default=None, metavar="N",
                   help="only the fleet: N robots committing at once to PostgreSQL")
    p.add_argument("--fleet-commits", type=int, default=3)
    p.add_argument("--fleet-size", type=int, default=4000, help="cells a side (default 4000)")
    a = p.parse_args()
    if a.fleet is not None:
        return fleet_table(a.fleet or [8, 32], a.fleet_commits, a.fleet_size)
    width, height = (2000, 1250) if a.quick else (8000, 5000)
    print("| map | store | commits/s | commit s | first commit s | MB per version | read s | "
          "parent diff ms |")
    print("|---|---|---|---|---|---|---|---|")
    notes = []
    for kind, noise in NOISE.items():
        maps = sessions(width, height, noise, a.commits)
        packed = cells.pack_cells(maps[0])
        known = int((maps[0] != UNKNOWN).sum())
        notes.append(f"{kind}: {width} x {height} cells, packed {len(packed) / 1e6:.2f} MB "
                     f"({len(packed) / known:.3f} bytes per known cell); "
                     f"{statistics.median(int((m != n).sum()) for m, n in zip(maps, maps[1:]))}"
                     " cells changed per session")
        for name, m in (("SQLite", _sqlite(maps)), ("PostgreSQL 15", _postgres(maps))):
            if isinstance(m, str):
                print(f"| {kind} | {name} | {m} | | | | | |")
                continue
            print(f"| {kind} | {name} | {1 / m['commit_s']:.2f} | {m['commit_s']:.2f} | "
                  f"{m['first_s']:.2f} | {m['bytes'] / 1e6:.2f} | {m['read_s']:.2f} | "
                  f"{m['diff_s'] * 1e3:.1f} |", flush=True)
    print("\n" + "\n".join(notes))
    return 0


def sessions(width: int, height: int, noise: float, count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(1)
    maps = [site_map(width, height, noise)]
    for _ in range(count - 1):
        maps.append(session(maps[-1], rng))
    return maps


def _sqlite(maps):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "maps.db"
        return measure(path, maps, sqlite_size(path))


def _postgres(maps):
    import postgres_tools
    srv, why = postgres_tools.server(fsync=True)
    if srv is None:
        return f"not measured: {why}"
    try:
        return measure(srv.new_database(), maps, postgres_size)
    finally:
        srv.stop()


# --- a fleet committing at once --------------------------------------------------------------------
ROBOT = """
import json, sys, time, numpy as np
from gridmap import OccupancyGrid
from mapstore import open_store
target, k, n, commits, go = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
rng = np.random.default_rng(100 + k)
import os
while not os.path.exists(go):
    time.sleep(0.01)
out = []
marks = {}
def hook(step):
    marks[step] = time.perf_counter()
with open_store(target) as s:
    s.hook = hook
    for c in range(commits):
        parent = s.latest()
        start = s.get(parent)
        time.sleep(rng.uniform(0.2, 1.0))                 # the session
        d = start.data.copy()
        h, w = d.shape
        band = h // n                                     # this robot's part, and its neighbour's
        for _ in range(12):
            r = int(rng.integers(k * band, min(h - 30, (k + 2) * band)))
            col = int(rng.integers(10, w - 30))
            d[r:r + 24, col:col + 20] = rng.choice([0, 100, -1])
        t0 = time.perf_counter()
        number = s.commit(start.with_data(d), parent, {"robot": f"robot{k}"})
        dt = time.perf_counter() - t0
        merged = s.merged
        out.append({"commit_s": dt, "merged": merged is not None,
                    "lock_s": marks["committed"] - marks["locked"],
                    "conflicts": len(s.conflicts(merged)) if merged else 0})
print(json.dumps(out), flush=True)
"""


def fleet_table(sizes: list[int], commits: int, side: int) -> int:
    import postgres_tools
    srv, why = postgres_tools.server(fsync=True)
    if srv is None:
        print(f"fleet not measured: {why}")
        return 1
    print(f"{side} x {side} cells at 5 cm, {commits} sessions a robot, PostgreSQL 15, fsync on")
    print("| robots | commits | commits/s | merged | commit s (no merge) | commit s (merge), "
          "median / p90 | lock held s, median / p90 | conflicts per merge | cells lost |")
    print("|---|---|---|---|---|---|---|---|---|")
    try:
        for n in sizes:
            row = fleet_run(srv, n, commits, side)
            print(f"| {n} | {row['commits']} | {row['per_s']:.2f} | {row['merged']} | "
                  f"{row['plain_s']} | {row['merge_s']} | {row['lock_s']} | {row['conflicts']} | "
                  f"{row['lost']} |", flush=True)
    finally:
        srv.stop()
    return 0


def fleet_run(srv, n: int, commits: int, side: int) -> dict:
    target = srv.new_database()
    base = site_map(side, side, NOISE["clean"])
    with open_store(target, create=True) as store:
        store.commit(OccupancyGrid(base, 0.05), None, {"method": "import"})
    with tempfile.TemporaryDirectory() as tmp:
        go = Path(tmp) / "go"
        procs = [subprocess.Popen([sys.executable, "-c", ROBOT, target, str(k), str(n),
                                   str(commits), str(go)], stdout=subprocess.PIPE, text=True,
                                  cwd=ROOT) for k in range(n)]
        time.sleep(2.0 + 0.1 * n)                 # every robot connected and waiting
        t0 = time.perf_counter()
        go.touch()
        rows = [r for p in procs for r in json.loads(p.communicate(timeout=3600)[0])]
        wall = time.perf_counter() - t0
    plain = [r["commit_s"] for r in rows if not r["merged"]]
    merged = [r for r in rows if r["merged"]]
    lost = _cells_lost(target)

    def spread(xs):
        return (f"{statistics.median(xs):.2f} / {np.percentile(xs, 90):.2f}" if xs else "-")
    return {"commits": len(rows), "per_s": len(rows) / wall, "merged": len(merged),
            "plain_s": spread(plain), "merge_s": spread([r["commit_s"] for r in merged]),
            "lock_s": spread([r["lock_s"] for r in rows]),
            "conflicts": f"{statistics.median(r['conflicts'] for r in merged):.0f}"
            if merged else "-", "lost": lost}


def _cells_lost(target) -> int:
    """Cells where the site map differs from the robots' own changes replayed in commit
    order on the first map, the last change of a cell winning (what the merges promise)."""
    with open_store(target) as store:
        log = store.log()
        site = store.get(log[0].number).data.copy()
        for v in log[1:]:
            if v.merge_parent is None:
                before, after = store.get(v.parent).data, store.get(v.number).data
                site[before != after] = after[before != after]
        return int((store.get(store.latest()).data != site).sum())


if __name__ == "__main__":
    raise SystemExit(main())
