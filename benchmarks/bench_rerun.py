"""What a rerun recording costs: ``mapupdate run --quick`` with and without ``--rerun``.

    python benchmarks/bench_rerun.py [--repeat N] [--full]

Each run is a fresh interpreter, as a user would start it (imports included), after one run that
loads the compiled kernels. Rows: median wall time without and with the recording, the
overhead, and the recording's size. The bar: a recorded run takes at most 30 % longer.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

OVERHEAD_BAR = 0.30
ROOT = Path(__file__).resolve().parents[1]
# the packages measured: this checkout's, or a revision's (run.py --baseline)
CODE = Path(os.environ.get("BENCH_CODE_ROOT") or ROOT)


def timed_run(out: Path, rrd: Path | None, quick: bool) -> float:
    cmd = [sys.executable, "-m", "mapupdate", "run", "--out", str(out), "--no-progress"]
    cmd += ["--quick"] if quick else []
    cmd += ["--rerun", str(rrd)] if rrd is not None else []
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    t = time.perf_counter()
    subprocess.run(cmd, cwd=CODE, env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=3, help="runs of each kind (default 3)")
    p.add_argument("--full", action="store_true", help="full routes instead of --quick")
    args = p.parse_args(argv)
    quick = not args.full
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        timed_run(tmp / "warm", tmp / "warm.rrd", quick)
        plain, recorded = [], []
        for k in range(args.repeat):        # interleaved, so drifts of the machine cancel
            plain.append(timed_run(tmp / f"plain{k}", None, quick))
            recorded.append(timed_run(tmp / f"rec{k}", tmp / f"rec{k}.rrd", quick))
        size_mb = (tmp / "rec0.rrd").stat().st_size / 2**20
    a, b = statistics.median(plain), statistics.median(recorded)
    overhead = b / a - 1.0
    kind = "--quick" if quick else "full routes"
    print(f"| mapupdate run {kind}, warehouse, 4 sessions | median s | bar |")
    print("|---|---|---|")
    print(f"| without --rerun | {a:.2f} | |")
    print(f"| with --rerun | {b:.2f} | |")
    print(f"| overhead | {100 * overhead:.0f} % | <= {100 * OVERHEAD_BAR:.0f} % |")
    print(f"| recording size | {size_mb:.1f} MiB | |")
    print(f"\n{args.repeat} runs of each, interleaved, fresh interpreters.")
    return 0 if overhead <= OVERHEAD_BAR else 1


if __name__ == "__main__":
    raise SystemExit(main())
