"""Run every ``benchmarks/bench_*.py`` script and print their tables.

Each script runs in its own interpreter (so one package's compile and memory do not colour
another's figures) and prints its own table; a script exits non-zero when it misses a bar.
Usage: ``python benchmarks/run.py [NAME ...]`` where NAME filters scripts by substring.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str] | None = None) -> int:
    names = sys.argv[1:] if argv is None else argv
    scripts = sorted(HERE.glob("bench_*.py"))
    if names:
        scripts = [s for s in scripts if any(n in s.stem for n in names)]
    if not scripts:
        print(f"no benchmark scripts matched in {HERE}", file=sys.stderr)
        return 2
    summary = []
    for script in scripts:
        print(f"== {script.stem} ==", flush=True)
        t0 = time.perf_counter()
        code = subprocess.call([sys.executable, str(script)], cwd=HERE.parent)
        summary.append((script.stem, code, time.perf_counter() - t0))
        print(flush=True)
    print("| script | result | wall s |")
    print("|---|---|---|")
    for name, code, wall in summary:
        result = "ok" if code == 0 else ("missed a bar" if code == 1 else f"failed ({code})")
        print(f"| {name} | {result} | {wall:.1f} |")
    return 0 if all(code == 0 for _, code, _ in summary) else 1


if __name__ == "__main__":
    raise SystemExit(main())
