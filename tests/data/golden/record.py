"""Record the golden files of this folder from a git revision that still holds the code before:
``benchmarks/updater_before``, ``localization_before`` and ``pose_check_before`` (README.md
names the revision they were recorded from).

    python tests/data/golden/record.py --rev REV [GROUP ...]

GROUP: ``updater``, ``updater_state``, ``localization``, ``pose_check`` (every group when none
is given). A temporary git worktree of REV is made (and removed at the end, on an error or
Ctrl-C too), and this script runs again in a fresh interpreter with the worktree first on
its path: the code before and every package it imports (the updater's configuration and
gate, gridmap, the localiser's configuration) are REV's, as they were when that code was
compared with the live code. The inputs are made by the test modules of this checkout, so
they are the ones the tests make; each file keeps their fingerprint, and REV.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import types
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
GROUPS = ("updater", "updater_state", "localization", "pose_check")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rev", required=True, help="a revision that holds benchmarks/*_before")
    ap.add_argument("groups", nargs="*", metavar="GROUP", help=", ".join(GROUPS))
    ap.add_argument("--inside", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    unknown = sorted(set(args.groups) - set(GROUPS))
    if unknown:
        ap.error(f"unknown group {', '.join(unknown)} (groups: {', '.join(GROUPS)})")
    groups = args.groups or list(GROUPS)
    if args.inside:
        return record_inside(Path(args.inside), args.rev, groups)
    worktree = benchmarks_worktree()
    worktree.exit_on_sigterm()
    try:
        commit = worktree.resolve(args.rev)
        with worktree.checked_out(commit) as tree:
            if not (tree / "benchmarks" / "updater_before").is_dir():
                print(f"{commit[:10]} has no benchmarks/updater_before: give a revision "
                      f"that holds the code before (README.md)", file=sys.stderr)
                return 2
            # the worktree's packages and the code before; this checkout's test helpers
            env = {**os.environ, "PYTHONPATH": os.pathsep.join(
                [str(tree), str(tree / "benchmarks"), str(ROOT / "tests")])}
            return subprocess.call([sys.executable, __file__, "--rev", commit, "--inside",
                                    str(tree), *groups], env=env)
    except worktree.RevisionError as e:
        print(e, file=sys.stderr)
        return 2


def benchmarks_worktree():
    """``benchmarks/worktree.py`` (the worktree of a revision), loaded from its file."""
    spec = importlib.util.spec_from_file_location("worktree", ROOT / "benchmarks" / "worktree.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def record_inside(tree: Path, commit: str, groups: list[str]) -> int:
    """In the interpreter whose path starts at the worktree ``tree``."""
    # ``tests`` (for tests.data.golden) is this checkout's, as are the test modules and their
    # helpers (by name, from PYTHONPATH): the inputs; every package under test the worktree's
    tests = types.ModuleType("tests")
    tests.__path__ = [str(ROOT / "tests")]
    sys.modules["tests"] = tests
    import gridmap
    import localization
    import localization_before
    import pose_check_before
    import updater
    import updater_before

    for module in (gridmap, updater, localization, updater_before, localization_before,
                   pose_check_before):
        if not Path(module.__file__).resolve().is_relative_to(tree.resolve()):
            raise SystemExit(f"{module.__name__} came from {module.__file__}, not from {tree}")
    recorders = {"updater": record_updater, "updater_state": record_updater_state,
                 "localization": record_localization, "pose_check": record_pose_check}
    for group in groups:
        for path in recorders[group](commit):
            print(f"{path.relative_to(ROOT)}: {path.stat().st_size:,d} bytes", flush=True)
    return 0


def facts(commit: str, inputs: str, **more) -> dict:
    return {"revision": commit, "inputs": inputs,
            "recorded_by": f"python tests/data/golden/record.py --rev {commit[:10]}", **more}


# --- the updater ------------------------------------------------------------------------------
def record_updater(commit: str) -> list[Path]:
    """Per run of ``ROOM_CASES``: the reports of the code before and, per scan, how many of
    its flags would have changed nothing (the unchanged flags on settled free cells, the
    changed and new-obstacle flags in buffers full of changes); then its buffers, hit
    buffers, flag counts, statistics and output map."""
    import numpy as np
    import updater_before

    from gridmap import FREE
    from tests.data.golden import golden
    from test_updater_speedup import ROOM_CASES, room_case, settled_free_cells
    from updater import steps

    out = []
    for seed, robot in ROOM_CASES:
        ref, scans, cfg = room_case(seed, robot)
        before = updater_before.MapUpdater(ref, cfg)
        mask = np.uint16(steps.buffer_mask(cfg))
        reports, verdicts, counts = [], [], {"settled": [], "changed": [], "news": []}
        for scan, noisy, true in scans:
            quiet = settled_free_cells(ref.data, before._hist,
                                       before._seen if before._seen.size else None, cfg)
            full = (before._hist.reshape(-1) & mask) == mask
            b = before.process(scan, noisy, odometry=true)
            changed = before._ws.changed[:b.changed_flags]
            quiet[changed] = False
            news = changed[ref.data.reshape(-1)[changed] == FREE]
            assert news.size == b.new_obstacle_flags
            counts["settled"].append(np.count_nonzero(
                quiet[before._ws.unchanged[:b.unchanged_flags]]))
            counts["changed"].append(np.count_nonzero(full[changed]))
            counts["news"].append(np.count_nonzero(full[news]))
            reports.append(b.summary())
            verdicts.append(b.verdicts)
        values, lengths = golden.pack(verdicts)
        out.append(golden.save(
            f"updater_room_seed{seed}",
            facts(commit, golden.fingerprint(ref.data, scans), config=cfg.to_dict(),
                  reports=reports, stats=before.stats, n_changed=before.n_changed),
            verdicts=values.astype(np.int8), verdict_lengths=lengths,
            settled_unchanged=np.array(counts["settled"], np.int64),
            full_changed=np.array(counts["changed"], np.int64),
            full_new_obstacle=np.array(counts["news"], np.int64),
            map=before.updated_map().data, hist=before._hist, hits=before._hitbuf,
            seen=before._seen))
    return out


def continued(before, scans) -> tuple[dict, dict]:
    """``before`` fed ``scans``: (its reports, evidence; its output map and change counts)."""
    reports = [before.process(scan, noisy, odometry=true).summary()
               for scan, noisy, true in scans]
    return ({"reports": reports, "evidence": before.evidence_summary()},
            {"map": before.updated_map().data, "change_counts": before.change_counts()})


def record_updater_state(commit: str) -> list[Path]:
    """The format-1 state file (the first half of ``format1_session``'s scans) and what the
    code before did with the second half; the twins of the save-and-load test (N_b 10 and
    14), the second half of ``twin_session``'s scans after the first."""
    import updater_before

    from tests.data.golden import golden
    from test_updater_memory import (ROBOT_AS_BEFORE, STATE_FORMAT_1, format1_session,
                                     twin_session)
    from updater import UpdaterConfig

    ref, scans = format1_session()
    config = UpdaterConfig(**ROBOT_AS_BEFORE)
    before = updater_before.MapUpdater(ref, config)
    half = len(scans) // 2
    for scan, noisy, true in scans[:half]:
        before.process(scan, noisy, odometry=true)
    assert before._seen.max() > 0xFFFF >> 10        # counts past the packed field's top
    before.save(STATE_FORMAT_1)
    info, arrays = continued(before, scans[half:])
    out = [STATE_FORMAT_1, golden.save(
        "updater_state_format1_continued",
        facts(commit, golden.fingerprint(ref.data, scans), config=config.to_dict(), **info),
        **arrays)]
    ref, scans = twin_session()
    for buffer_size in (10, 14):
        config = UpdaterConfig(**{**ROBOT_AS_BEFORE, "buffer_size": buffer_size})
        twin = updater_before.MapUpdater(ref, config)
        half = len(scans) // 2
        for scan, noisy, true in scans[:half]:
            twin.process(scan, noisy, odometry=true)
        info, arrays = continued(twin, scans[half:])
        out.append(golden.save(
            f"updater_twin_buffer{buffer_size}",
            facts(commit, golden.fingerprint(ref.data, scans), config=config.to_dict(), **info),
            **arrays))
    return out


# --- the localiser and the pose check ---------------------------------------------------------
def record_localization(commit: str) -> list[Path]:
    """Per run of ``FILTER_CASES``, after each update: what ``update`` returned, the digests
    of the particles and weights, the estimate's pose, covariance and cluster weight."""
    import localization_before
    import numpy as np

    from localization import LocalizerConfig
    from tests.data.golden import golden
    from test_localization_speedup import FILTER_CASES, make_tour, run_filter, tour_fingerprint

    tour = make_tour()
    out = []
    for case, (config, start) in enumerate(FILTER_CASES):
        loc = localization_before.MonteCarloLocalizer(tour[0], LocalizerConfig(**config),
                                                      seed=11)
        rows = [(updated, golden.array_digest(loc.particles), golden.array_digest(loc.weights),
                 est.pose.as_array(), est.cov, est.cluster_weight)
                for updated, est in run_filter(loc, tour, start)]
        updated, particles, weights, pose, cov, weight = zip(*rows)
        out.append(golden.save(
            f"localization_filter_case{case}",
            facts(commit, tour_fingerprint(tour), case=[config, start]),
            updated=np.array(updated, bool), particles=np.array(particles),
            weights=np.array(weights), pose=np.array(pose), cov=np.array(cov),
            cluster_weight=np.array(weight, np.float64)))
    return out


def record_pose_check(commit: str) -> list[Path]:
    """Per run of ``CHECK_CASES``: each call's verdict, refined pose and fit; and the verdict
    on a map one cell wide."""
    import pose_check_before

    from localization.confidence import PoseCheckConfig
    from tests.data.golden import golden
    from test_pose_check_speedup import CHECK_CASES, check_calls, check_case, one_cell_wide

    out = []
    for case, (seed, config) in enumerate(CHECK_CASES):
        ref, mount, calls = check_case(seed)
        check = pose_check_before.PoseCheck(ref, PoseCheckConfig(**config))
        out.append(golden.save(
            f"pose_check_case{case}",
            facts(commit, golden.fingerprint(ref.data, mount, calls), case=[seed, config],
                  calls=check_calls(check, calls, mount))))
    grid, scan, pose, mount = one_cell_wide()
    out.append(golden.save(
        "pose_check_one_cell_wide",
        facts(commit, golden.fingerprint(grid.data, scan, pose, mount),
              verdict=pose_check_before.PoseCheck(grid).verdict(scan, pose, mount))))
    return out


if __name__ == "__main__":
    raise SystemExit(main())
