"""The map store at a site's scale: commits per second, the bytes each version adds, and the
time to read a version and a diff, on a 400 x 250 m map at 5 cm (8000 x 5000 cells), in an
SQLite file and in PostgreSQL (a server started for the run from Debian's binaries, as the
tests do; its row is left out, with the reason, where there is none).

SQLite runs in WAL mode with synchronous=FULL, PostgreSQL with fsync on: a finished commit is
on disk in both. Each session moves ``PALLETS`` pallets (drawn where there was floor, freed where one stood)
and flips ``SPECKS`` single cells (the noise a real update leaves), about 15 000 changed cells,
on a warehouse of rack rows whose insides the lidar never sees (unknown).
Usage: ``python benchmarks/bench_map_store.py [--commits N] [--quick]``.
"""

from __future__ import annotations

import argparse
import statistics
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
    a = p.parse_args()
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


if __name__ == "__main__":
    raise SystemExit(main())
