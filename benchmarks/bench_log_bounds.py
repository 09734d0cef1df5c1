"""What the bounds on a CARMEN log cost and save: the time to read the real logs of
``../shared/data`` (best of three), and the time to refuse gzip bombs made here (best of
three): 2.7 GB of 10-byte comment lines in 6.6 MB, and 1 GB of 4 KB comment lines in 1.4 MB.
Bar (exit 1 when missed): each bomb refused within 3 s.
Usage: ``python benchmarks/bench_log_bounds.py``.
"""

from __future__ import annotations

import gzip
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path[:0] = [os.environ.get("BENCH_CODE_ROOT") or str(ROOT)]

from robotlogs import LogError  # noqa: E402
from robotlogs.carmen import read_carmen  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
REAL = ["intel.gfs.log", "killian.clf.gz", "radish/freiburg-079.log.gz", "radish/seattle.log.gz"]
BAR_S = 3.0


def best_of(fn, runs: int = 3) -> float:
    best = float("inf")
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def refused(path: Path) -> str:
    try:
        read_carmen(path)
    except LogError as e:
        return str(e)
    raise AssertionError(f"{path} was read")


def main() -> int:
    print(f"machine: {platform.processor() or platform.machine()}, Python "
          f"{platform.python_version()}")
    print("| log | file MB | text MB | lines | read s |")
    print("|---|---|---|---|---|")
    for name in REAL:
        path = DATA / name
        if not path.exists():
            print(f"| {name} | (not in {DATA}) | | | |")
            continue
        raw = path.read_bytes()
        text = gzip.decompress(raw) if raw[:2] == b"\x1f\x8b" else raw
        seconds, lines = best_of(lambda: read_carmen(path)), text.count(b"\n")
        print(f"| {name} | {len(raw) / 1e6:.2f} | {len(text) / 1e6:.2f} | {lines} | "
              f"{seconds:.3f} |")
    ok = True
    print()
    print("| gzip bomb | file MB | text GB | refused after s | by |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, block, copies in (("10-byte comments", b"# comment\n" * 10_000, 27_000),
                                    ("4 KB comments", (b"# " + b"x" * 4093 + b"\n") * 256,
                                     1024)):
            bomb = Path(tmp) / "bomb.clf.gz"
            bomb.write_bytes(gzip.compress(block, mtime=0) * copies)
            seconds = best_of(lambda: refused(bomb))
            why = "lines" if "lines" in refused(bomb).split(";")[0] else "bytes"
            ok &= seconds <= BAR_S
            print(f"| {name} | {bomb.stat().st_size / 1e6:.1f} | "
                  f"{len(block) * copies / 1e9:.2f} | {seconds:.2f} | {why} |")
    print(f"\nbar: each bomb refused within {BAR_S:g} s: {'met' if ok else 'MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
