"""Where the robot profile's misses lie late in a lifelong run: the targets (observable cells
M(i-1) got wrong) that M(i) leaves wrong over the last sessions of one layout and seed of
``bench_lifelong.py``, pooled, by what lies near them.

    python benchmarks/lifelong_misses.py gen101:1 [--sessions 100] [--from 80] [--out DIR]

Per kind (left to free: occupied in M(i-1), free in the truth; left to draw: free in M(i-1),
occupied in the truth), the share within 3 cells of a wall, a rack or an object the session
did not move (``bench_soak.standing_cells``), within 4 cells of a face (of M(i-1) for the
cells to draw, of the truth for those to free), wrong for five sessions or more in a row, and
new this session. Then the wrong changes of the same sessions (what precision counts against
the method), by kind: cells freed that stand in the truth (of a wall, rack or unmoved object,
of an object the session moved, or inside an object, where the truth is unknown), and cells
drawn away from the truth's surfaces (inside an object, in free space near a surface, or
further, and of those where a person walked). Last, why the faces rule (docs/algorithm.md,
"Faces a few cells off") drew none of the cells left to draw, read against the counts the
session carried to the next (``draw_reasons``). The scenario is the benchmark's (written to,
or read from, ``--out``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_lifelong as bl  # noqa: E402
import bench_soak  # noqa: E402

WRONG = (("freed: a wall, rack or unmoved object", "free_standing"),
         ("freed: an object the session moved", "free_moved"),
         ("freed: inside an object (the truth unknown)", "free_inside"),
         ("drawn: inside an object (the truth unknown, within 3 cells of its surface)",
          "draw_inside"),
         ("drawn: free space within 3 cells of a surface", "draw_near"),
         ("drawn: further", "draw_far"),
         ("... of them where a person walked", "draw_people"))
ROWS = (("within 3 cells of a wall, rack or unmoved object", "standing"),
        ("within 4 cells of a face", "face"),
        ("wrong 5 sessions or more in a row", "old"),
        ("new this session", "new"))


# why the faces rule drew no cell within one of a cell left to draw: the first of its draw
# conditions that no such cell meets (``draw_reasons``)
REASONS = (("no cell within one in the rule's reach (2 to face_band cells from M's surfaces; "
            "beside walls and racks free in M only)", "reach"),
           ("short of hits (face_min_hits beside objects, face_large_min_hits beside walls and "
            "racks)", "hits"),
           ("crossed too often (more than face_draw_ratio of the hits)", "crossed"),
           ("a candidate, waiting for the next session to agree", "waiting"),
           ("other (another rule's output there, or no hit this session)", "other"))


def grown(mask: np.ndarray, cells: int) -> np.ndarray:
    from gridmap.masks import near

    for _ in range(cells):
        mask = near(mask)
    return mask


def misses(layout: str, seed: int, n: int, first: int, out_dir: Path) -> dict:
    """Counts, pooled over sessions ``first``..n, of the targets left wrong, by kind and by
    what lies near them."""
    import evaluation as ev
    from gridmap import FREE, OCCUPIED
    from updater import UpdaterConfig

    if not bl.scenario_path(out_dir, layout, seed, n).exists():
        bl.make_scenario((layout, seed, n, str(out_dir)))
    scn, what = bl.load_scenario(out_dir, layout, seed, n)
    counts = {kind: dict.fromkeys(["targets", "left"] + [k for _, k in ROWS], 0)
              for kind in ("free", "draw")}
    counts["wrong"] = dict.fromkeys(["changes"] + [k for _, k in WRONG], 0)
    counts["why"] = {part: dict.fromkeys(["left", "uncounted"] + [k for _, k in REASONS], 0)
                     for part in ("standing", "away")}
    cfg = UpdaterConfig.profile(bl.method_options("robot")["profile"])
    age = None                  # sessions in a row each cell has been a target

    def tally(i, previous, res):
        nonlocal age
        truth, updated = res.truth.data, res.updated.data
        wrong_occ, wrong_free = ev.wrong_cells(previous, res.truth)
        observable = res.masks["observable"]
        targets = (wrong_occ | wrong_free) & observable
        age = np.where(targets, (0 if age is None else age) + 1, 0)
        if i < first:
            return
        kept = bench_soak.standing_cells(scn, i, res.truth) & (truth == OCCUPIED)
        tally_wrong(counts["wrong"], previous.data, updated, truth, kept, res.masks["people"])
        standing = grown(kept, 3)
        for kind, target, fixed, face in (
                ("free", wrong_occ & observable, updated == FREE, truth == OCCUPIED),
                ("draw", wrong_free & observable, ev.near(updated == OCCUPIED),
                 previous.data == OCCUPIED)):
            left = target & ~fixed
            c = counts[kind]
            c["targets"] += int(target.sum())
            c["left"] += int(left.sum())
            c["standing"] += int((left & standing).sum())
            c["face"] += int((left & grown(face, 4)).sum())
            c["old"] += int((left & (age >= 5)).sum())
            c["new"] += int((left & (age == 1)).sum())
            if kind == "draw":
                tally_reasons(counts["why"], previous, left, standing, res.faces, cfg)

    bench_soak.run_soak(scn, what, on_session=tally, **bl.method_options("robot"))
    return counts


def draw_reasons(ref: np.ndarray, left: np.ndarray, carried, cfg, resolution: float) -> dict:
    """Why the faces rule drew none of the cells ``left`` (to draw, as scored: no occupied
    cell of M(i) within one), for the reference map ``ref`` (M(i-1)'s cells) and the counts
    the session carried (``carried``: a ``FaceCounts``, halved): ``{key: cells}`` over
    ``REASONS`` and "uncounted" (no scan counted: the rule off, or poses given), each cell
    counted by its ``reason_map`` entry."""
    return count_reasons(reason_map(ref, carried, cfg, resolution), left)


def count_reasons(reasons: np.ndarray | None, cells: np.ndarray) -> dict:
    """``cells`` counted by their entries in ``reasons`` (a ``reason_map``; None: no scan
    counted, every cell "uncounted")."""
    out = dict.fromkeys(["uncounted"] + [k for _, k in REASONS], 0)
    if reasons is None:
        out["uncounted"] = int(cells.sum())
    else:
        found = np.bincount(reasons[cells], minlength=len(REASONS))
        out.update({key: int(n) for (_, key), n in zip(REASONS, found)})
    return out


def reason_map(ref: np.ndarray, carried, cfg, resolution: float) -> np.ndarray | None:
    """Per cell, the index in ``REASONS`` of the first of the faces rule's draw conditions
    that no cell within one of it meets, read from ``carried`` (a ``FaceCounts``, halved: a
    cell's hits are taken as at most 2h + 1 and its crossings as at least 2p, so "short of
    hits" and "crossed too often" hold of the session's own counts too); None when no scan
    counted."""
    if carried is None or carried.hits.size == 0:
        return None
    from gridmap import FREE, OCCUPIED
    from gridmap.masks import near
    from updater.faces import small_structure_bits

    def plane(bits):
        return np.unpackbits(bits, bitorder="little")[:ref.size].reshape(ref.shape) == 1

    occ = ref == OCCUPIED
    small = plane(small_structure_bits(ref, cfg.face_max_area, resolution))
    in_band = grown(occ, cfg.face_band) & ~grown(occ, 1)
    large_near = grown(occ & ~small, cfg.face_band)
    zone = in_band & (~large_near | ((ref == FREE) & cfg.face_draw_beside_large))
    need = np.where(large_near, max(cfg.face_min_hits, cfg.face_large_min_hits),
                    cfg.face_min_hits)
    hits = carried.hits.astype(np.int32) * 2 + 1
    passes = carried.passes.astype(np.int32) * 2
    enough = zone & (hits >= need)
    steep_free = enough & (passes <= cfg.face_draw_ratio * hits)
    waiting = near(plane(carried.confirmed))
    # the first condition failed, in REASONS' order: reach, hits, crossed, waiting, other
    reasons = np.full(ref.shape, len(REASONS) - 1, np.int64)
    for index, met in reversed(list(enumerate((zone, enough, steep_free)))):
        reasons[~near(met)] = index
    # beside objects a draw waits for face_draw_sessions, in front of what stands face_sessions
    waits = np.where(large_near, cfg.face_sessions, cfg.face_draw_sessions) > 1
    reasons[near(steep_free) & waiting & waits] = 3
    return reasons


def tally_reasons(why: dict, previous, left, standing, carried, cfg) -> None:
    """Add the session's cells left to draw to ``why`` by ``draw_reasons``, near what stands
    and away from it, the reasons worked out once for the map."""
    reasons = reason_map(previous.data, carried, cfg, previous.resolution)
    for part, cells in (("standing", left & standing), ("away", left & ~standing)):
        why[part]["left"] += int(cells.sum())
        for key, n in count_reasons(reasons, cells).items():
            why[part][key] += n


def tally_wrong(c: dict, previous, updated, truth, kept, people) -> None:
    """Add the session's wrong changes (as ``evaluation.change_detection`` judges them) to
    ``c`` by kind; ``kept``: the truth's cells that stand where they stood."""
    import evaluation as ev
    from gridmap import FREE, OCCUPIED, UNKNOWN

    changed = updated != previous
    freed = changed & (updated == FREE) & (truth != FREE)
    drawn = changed & (updated == OCCUPIED) & ~ev.near(truth == OCCUPIED)
    near = grown(truth == OCCUPIED, 3)
    far = drawn & ~near
    for key, cells in (("changes", changed), ("free_standing", freed & kept),
                       ("free_moved", freed & (truth == OCCUPIED) & ~kept),
                       ("free_inside", freed & (truth == UNKNOWN)),
                       ("draw_inside", drawn & near & (truth == UNKNOWN)),
                       ("draw_near", drawn & near & (truth != UNKNOWN)),
                       ("draw_far", far), ("draw_people", far & people)):
        c[key] += int(cells.sum())


def print_table(counts: dict) -> None:
    print("| of the cells left wrong | to free | to draw |")
    print("|---|---|---|")
    print(f"| targets / left wrong | {counts['free']['targets']} / {counts['free']['left']} | "
          f"{counts['draw']['targets']} / {counts['draw']['left']} |")
    for label, key in ROWS:
        cells = [f"{counts[k][key]} ({100 * counts[k][key] / max(1, counts[k]['left']):.0f} %)"
                 for k in ("free", "draw")]
        print(f"| {label} | {cells[0]} | {cells[1]} |")
    w = counts["wrong"]
    wrong = sum(w[k] for _, k in WRONG[:-1])
    print(f"\n| wrong changes, of {w['changes']} (precision {1 - wrong / max(1, w['changes']):.3f}) "
          f"| cells | share |")
    print("|---|---|---|")
    for label, key in WRONG:
        print(f"| {label} | {w[key]} | {100 * w[key] / max(1, wrong):.0f} % |")
    why = counts["why"]
    print("\n| why the faces rule drew none of the cells left to draw | within 3 cells of a wall, "
          "rack or unmoved object | further |")
    print("|---|---|---|")
    print(f"| cells left to draw | {why['standing']['left']} | {why['away']['left']} |")
    for label, key in (("no scan counted", "uncounted"),) + REASONS:
        cells = [f"{why[k][key]} ({100 * why[k][key] / max(1, why[k]['left']):.0f} %)"
                 for k in ("standing", "away")]
        print(f"| {label} | {cells[0]} | {cells[1]} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", metavar="LAYOUT:SEED", help="e.g. gen101:1")
    p.add_argument("--sessions", type=int, default=100)
    p.add_argument("--from", dest="first", type=int, default=None,
                   help="the first session pooled (default: the last fifth)")
    p.add_argument("--out", type=Path, default=Path("runs/lifelong"))
    args = p.parse_args(argv)
    layout, _, seed = args.run.partition(":")
    if not (layout == "builtin" or layout.startswith("gen") and layout[3:].isdigit()) \
            or not seed.isdigit():
        p.error(f"LAYOUT:SEED expected (builtin or gen<seed>, a whole number), got "
                f"{args.run!r}")
    if not 2 <= args.sessions <= 1000:
        p.error(f"--sessions must be 2-1000, got {args.sessions}")
    first = args.first if args.first is not None else args.sessions - args.sessions // 5
    if not 1 <= first <= args.sessions:
        p.error(f"--from must be 1-{args.sessions}, got {first}")
    if args.out.exists() and not args.out.is_dir():
        p.error(f"--out {args.out} is a file")
    (args.out / "scenarios").mkdir(parents=True, exist_ok=True)
    print_table(misses(layout, int(seed), args.sessions, first, args.out))
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except bl.ScenarioFileError as e:
        sys.exit(f"lifelong_misses.py: {e}")
