"""Run the ``benchmarks/bench_*.py`` scripts and print their tables; with ``--baseline REV``, run
them on a git revision's code too and set the figures of the two side by side.

    python benchmarks/run.py [NAME ...] [-- ARG ...]
    python benchmarks/run.py --baseline REV [--rounds N] [NAME ...] [-- ARG ...]

NAME filters the scripts by substring; the ARGs after ``--`` go to every script run (e.g.
``python benchmarks/run.py --baseline 0245a5db9269 updater -- --no-logs --passes 3``). Each
script runs in its own interpreter (so one package's compile and memory do not colour
another's figures) and prints its own table; a script exits 1 when it misses a bar.

With ``--baseline REV``: a temporary ``git worktree`` of REV (removed at the end, on an error,
Ctrl-C or SIGTERM too), and each script run twice, back to back: first on the worktree's
packages, then on this checkout's (uncommitted changes included). Both times it is this
checkout's script: the inputs, the timers and the statistics are the same code, and only the
packages measured differ (``BENCH_CODE_ROOT`` and ``PYTHONPATH`` point at the worktree; data
files and outputs stay this checkout's). The revision's own copy of the script is not used:
its inputs or its way of timing may differ from today's, and the figures would then differ
for more than the code. A script that needs something REV's packages lack fails in the
baseline run, and the summary says so. ``--rounds N`` repeats the pair N times, alternating.
A script that writes its figures (``--json``, ``benchmarks/figures.py``) also gets one table:
per figure the median over the rounds before and after, and their ratio; per output it
digests (a map, the particles) whether the two runs gave the same. A script must take the
measured packages from ``BENCH_CODE_ROOT`` to be run against a baseline.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from worktree import RevisionError, checked_out, describe_working_tree, exit_on_sigterm, resolve

HERE = Path(__file__).resolve().parent


def parse(argv: list[str]) -> argparse.Namespace:
    script_args = []
    if "--" in argv:
        at = argv.index("--")
        argv, script_args = argv[:at], argv[at + 1:]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("names", nargs="*", metavar="NAME", help="run the scripts named so")
    ap.add_argument("--baseline", metavar="REV", help="a git revision to compare with")
    ap.add_argument("--rounds", type=int, default=1,
                    help="with --baseline: runs of each script on each side (default 1)")
    args = ap.parse_args(argv)
    args.script_args = script_args
    if args.rounds < 1:
        ap.error("--rounds must be at least 1")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    scripts = sorted(HERE.glob("bench_*.py"))
    if args.names:
        scripts = [s for s in scripts if any(n in s.stem for n in args.names)]
    if not scripts:
        print(f"no benchmark scripts matched in {HERE}", file=sys.stderr)
        return 2
    if args.baseline:
        return against_baseline(scripts, args)
    summary = []
    for script in scripts:
        print(f"== {script.stem} ==", flush=True)
        code, wall = run(script, args.script_args)
        summary.append((script.stem, code, wall))
        print(flush=True)
    print_summary(summary)
    return 0 if all(code == 0 for _, code, _ in summary) else 1


def run(script: Path, script_args: list[str], code_root: Path | None = None,
        json_path: Path | None = None) -> tuple[int, float]:
    """Run ``script`` (on ``code_root``'s packages, or this checkout's): (exit code, wall s)."""
    env = dict(os.environ)
    if code_root is not None:
        env["BENCH_CODE_ROOT"] = str(code_root)
        env["PYTHONPATH"] = os.pathsep.join(
            [str(code_root)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    cmd = [sys.executable, str(script), *script_args]
    if json_path is not None:
        cmd += ["--json", str(json_path)]
    t0 = time.perf_counter()
    code = subprocess.call(cmd, cwd=HERE.parent, env=env)
    return code, time.perf_counter() - t0


def print_summary(summary) -> None:
    print("| script | result | wall s |")
    print("|---|---|---|")
    for name, code, wall in summary:
        print(f"| {name} | {result(code)} | {wall:.1f} |")


def result(code: int) -> str:
    return "ok" if code == 0 else ("missed a bar" if code == 1 else f"failed ({code})")


# --- against a baseline -----------------------------------------------------------------------
def against_baseline(scripts: list[Path], args) -> int:
    refused = [s.stem for s in scripts if "BENCH_CODE_ROOT" not in s.read_text()]
    if refused:
        print(f"not run against a baseline: {', '.join(refused)} (they import this "
              f"checkout's packages whatever the revision)", file=sys.stderr)
        scripts = [s for s in scripts if s.stem not in refused]
        if not scripts:
            return 2
    exit_on_sigterm()
    try:
        commit = resolve(args.baseline)
        now = describe_working_tree()
        with checked_out(commit) as tree, tempfile.TemporaryDirectory() as tmp:
            print(f"baseline {commit[:10]} ({args.baseline}) in {tree}; after: the working "
                  f"tree ({now})", flush=True)
            imported_from(tree)
            rows = [compare(script, args, tree, Path(tmp)) for script in scripts]
    except RevisionError as e:
        print(e, file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted (the worktree is removed)", file=sys.stderr)
        return 130
    print("| script | before | after | before wall s | after wall s |")
    print("|---|---|---|---|---|")
    for name, runs in rows:
        b, a = ([r for side, r in runs if side == which] for which in ("before", "after"))
        print(f"| {name} | {', '.join(result(c) for c, _ in b)} "
              f"| {', '.join(result(c) for c, _ in a)} "
              f"| {' / '.join(f'{w:.1f}' for _, w in b)} "
              f"| {' / '.join(f'{w:.1f}' for _, w in a)} |")
    after_ok = all(c == 0 for _, runs in rows for side, (c, _) in runs if side == "after")
    before_ran = all(c in (0, 1) for _, runs in rows for side, (c, _) in runs
                     if side == "before")
    return 0 if after_ok and before_ran else 1


def imported_from(tree: Path) -> None:
    """Check that an interpreter started as ``run`` starts the scripts of the baseline
    imports the packages from ``tree``."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    found = subprocess.run([sys.executable, "-c", "import gridmap; print(gridmap.__file__)"],
                           cwd=tree.parent, env=env, capture_output=True, text=True)
    where = Path(found.stdout.strip() or ".").resolve()
    if found.returncode or not where.is_relative_to(tree.resolve()):
        raise RevisionError(f"the baseline's interpreter imports gridmap from {where}, not "
                            f"from the worktree {tree}: {found.stderr.strip()}")


def compare(script: Path, args, tree: Path, tmp: Path):
    """``script`` on the baseline's packages and on this checkout's, ``args.rounds`` times
    each, alternating; its figures side by side when it writes them."""
    writes = "--json" in script.read_text()
    runs, found = [], {"before": [], "after": []}
    for k in range(args.rounds):
        for side, root in (("before", tree), ("after", None)):
            print(f"== {script.stem}, {side} (round {k + 1} of {args.rounds}) ==", flush=True)
            out = tmp / f"{script.stem}-{side}-{k}.json" if writes else None
            code, wall = run(script, args.script_args, root, out)
            runs.append((side, (code, wall)))
            if out is not None and out.exists():
                found[side].append(json.loads(out.read_text()))
            print(flush=True)
    if found["before"] and found["after"]:
        print_comparison(script.stem, args, found)
    return script.stem, runs


def print_comparison(name: str, args, found: dict) -> None:
    """Per figure, the median over the rounds before and after and their ratio; per output,
    whether every run gave the same."""
    before, after = (merged(found[side]) for side in ("before", "after"))
    print(f"{name}: {args.baseline} (before) and the working tree (after), "
          f"{args.rounds} round{'s' if args.rounds > 1 else ''} each, medians over the rounds")
    print()
    print("| figure | unit | before | after | before / after |")
    print("|---|---|---:|---:|---:|")
    for key in list(before["figures"]) + [k for k in after["figures"]
                                          if k not in before["figures"]]:
        b, a = before["figures"].get(key), after["figures"].get(key)
        unit = (b or a)["unit"]
        ratio = f"{b['value'] / a['value']:.2f}" if b and a and a["value"] else ""
        print(f"| {key} | {unit} | {number(b)} | {number(a)} | {ratio} |")
    outputs = list(before["outputs"]) + [k for k in after["outputs"]
                                         if k not in before["outputs"]]
    if outputs:
        print()
        print("| output | the same before and after |")
        print("|---|---|")
        for key in outputs:
            digests = before["outputs"].get(key, set()) | after["outputs"].get(key, set())
            same = "yes" if len(digests) == 1 and key in before["outputs"] and \
                key in after["outputs"] else "NO"
            print(f"| {key} | {same} |")
    print(flush=True)


def merged(runs: list[dict]) -> dict:
    """The figures' medians over ``runs``, and each output's set of digests."""
    figures, outputs = {}, {}
    for r in runs:
        for key, f in r.get("figures", {}).items():
            figures.setdefault(key, {"unit": f["unit"], "values": []})["values"].append(
                f["value"])
        for key, digest in r.get("outputs", {}).items():
            outputs.setdefault(key, set()).add(digest)
    return {"figures": {k: {"unit": f["unit"], "value": statistics.median(f["values"])}
                        for k, f in figures.items()},
            "outputs": outputs}


def number(figure: dict | None) -> str:
    if figure is None:
        return ""
    v = figure["value"]
    return f"{v:,.0f}" if figure["unit"] == "bytes" or abs(v) >= 1000 else f"{v:.3f}"


if __name__ == "__main__":
    raise SystemExit(main())
