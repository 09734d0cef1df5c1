"""The case folder of an edited-world case: writing it (the stale map, the edited log as a
CARMEN text log, the truth, ``case.yaml``), reading it back and scoring an updated map against
it (docs/edited_world.md). Imports only ``gridmap`` and :mod:`evaluation.edited_world`.
"""

from __future__ import annotations

import io
import json
import math
import os
import zipfile
from pathlib import Path

import numpy as np
import yaml

from gridmap import (FREE, OCCUPIED, UNKNOWN, MapUpdatingError, OccupancyGrid, Pose2D, Scan,
                     load_map, save_map)
from gridmap.atomic import write_atomically
from gridmap.map_io import read_map_yaml
from gridmap.masks import near

from .edited_world import (CARMEN_RANGE_MIN, CASE_FILES, FEW_VIEWS, FLASER_NO_RETURN, TRUTH_MASKS,
                           ZIP_TIME, Case, CaseError)

__all__ = ["CASE_FILES", "case_lines", "case_record", "check_case_dir", "load_case", "log_text",
           "score_case", "score_lines", "write_case", "write_scores"]


# --- the case folder ---------------------------------------------------------------------------

def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.resolve() == b.resolve():
            return True
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _map_files(map_path) -> list[Path]:
    """The map's YAML and, when its YAML can be read, its image."""
    try:
        return [Path(map_path), Path(read_map_yaml(map_path).image)]
    except (MapUpdatingError, OSError):
        return [Path(map_path)]


def check_case_dir(out_dir, map_path=None, log_path=None) -> None:
    """Refuse a case folder that is the map or the log, a file, or a folder with something in
    it (a case is written into a new or empty folder, so nothing is ever overwritten)."""
    out = Path(out_dir)
    inputs = ([("map", f) for f in _map_files(map_path)] if map_path is not None else []) + \
        ([("log", Path(log_path))] if log_path is not None else [])
    for what, f in inputs:
        if _same_file(out, f):
            raise CaseError(f"{out}: the case folder is the {what} {f}; choose another folder")
    if out.exists() and not out.is_dir():
        raise CaseError(f"{out}: is a file; the case needs a new or empty folder")
    if out.is_dir() and any(out.iterdir()):
        raise CaseError(f"{out}: the folder exists and is not empty; the case needs a new or "
                        "empty folder")


def write_case(case: Case, out_dir, *, map_path, log_path) -> Path:
    """Write the case folder: ``stale.yaml`` + ``stale.pgm``, ``log.clf``, ``truth.npz`` and,
    last, ``case.yaml``; each file through a temporary file in the folder, renamed into place."""
    out = Path(out_dir)
    check_case_dir(out, map_path, log_path)
    out.mkdir(parents=True, exist_ok=True)
    save_map(case.stale, out / "stale.yaml")
    write_atomically(out / "log.clf", log_text(case))
    write_atomically(out / "truth.npz", npz_bytes(case.truth))
    record = case_record(case, map_path, log_path)
    write_atomically(out / "case.yaml", yaml.safe_dump(record, sort_keys=False,
                                                       default_flow_style=None))
    return out


def npz_bytes(arrays: dict) -> bytes:
    """``numpy.savez_compressed``'s format with fixed member times: the same arrays give the
    same bytes (``np.load`` reads it)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, a in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asanyarray(a), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, member.getvalue())
    return buf.getvalue()


def case_record(case: Case, map_path, log_path) -> dict:
    """What ``case.yaml`` holds."""
    boxes = []
    for b in case.boxes:
        entry = {"kind": b.kind, "centre": [b.box.cx, b.box.cy], "size": [b.box.w, b.box.h],
                 "yaw": b.box.yaw, "views": b.views}
        if b.pair is not None:
            entry["pair"] = b.pair
        boxes.append(entry)
    return {"seed": case.seed, "map": str(Path(map_path).resolve()),
            "log": str(Path(log_path).resolve()), "scans": len(case.observations),
            "scans_without_pose": case.dropped, "min_views": case.min_views,
            "asked": dict(case.asked), "placed": case.placed(), "boxes": boxes,
            "people": len(case.people),
            "people_radius": [round(p.radius, 3) for p in case.people],
            "notes": list(case.notes)}


# --- the edited log ----------------------------------------------------------------------------

def is_flaser(scan: Scan) -> bool:
    """True when the scan has the geometry the CARMEN reader gives a FLASER line of its beams."""
    n = scan.beams
    inc = math.pi / max(n - 1, 1) if n % 2 == 1 else math.pi / max(n, 1)
    return (abs(scan.angle_min + math.pi / 2) < 1e-12 and abs(scan.angle_increment - inc) < 1e-12
            and scan.range_max == FLASER_NO_RETURN and scan.range_min == CARMEN_RANGE_MIN)


def range_words(ranges: np.ndarray, no_return: float, below: float | None = None) -> str:
    """Readings as CARMEN text: the fewest digits that read back as the same float32, no return
    (inf or at least ``no_return``) as ``no_return``, NaN as ``nan``, and readings below
    ``below`` (invalid in the scan) as 0."""
    a = np.asarray(ranges, np.float32).astype(np.float64)
    with np.errstate(invalid="ignore"):
        none = a >= no_return
        if below is not None:
            a = np.where(a < below, 0.0, a)
    a = np.where(none, 0.0, a)
    short = np.char.mod("%.6g", a)
    exact = (short.astype(np.float32) == a.astype(np.float32)) | np.isnan(a)
    words = short.astype(object)
    words[~exact] = np.char.mod("%.9g", a[~exact]).astype(object)
    words[none] = repr(float(no_return))
    return " ".join(words.tolist())


def laser_line(obs, sensor: Pose2D, ranges: np.ndarray) -> str:
    """One scan as a CARMEN line the reader gives back at the same laser and odometry poses:
    FLASER for its geometry, ROBOTLASER1 (own angles and range limit) for any other."""
    scan = obs.scan
    odom = obs.odom if obs.odom is not None else sensor
    t = repr(float(obs.time))
    poses = " ".join(repr(float(v)) for v in (sensor.x, sensor.y, sensor.theta,
                                              odom.x, odom.y, odom.theta))
    if is_flaser(scan):
        return f"FLASER {scan.beams} {range_words(ranges, FLASER_NO_RETURN)} {poses} {t} inject {t}"
    fov = (scan.beams - 1) * scan.angle_increment
    head = (f"ROBOTLASER1 0 {scan.angle_min!r} {fov!r} {scan.angle_increment!r} "
            f"{float(scan.range_max)!r} 0 0 {scan.beams}")
    words = range_words(ranges, float(scan.range_max), float(scan.range_min))
    return f"{head} {words} 0 {poses} 0 0 0 0 0 {t} inject {t}"


def log_text(case: Case) -> str:
    """The edited log: a comment, then one laser line per scan in the log's order."""
    head = [f"# edited-world case, seed {case.seed}: {len(case.boxes)} boxes and "
            f"{len(case.people)} people cut into the scans of the recording"]
    lines = [laser_line(o, p, r) for o, p, r in zip(case.observations, case.sensors, case.ranges)]
    return "\n".join(head + lines) + "\n"


def case_lines(case: Case, out_dir) -> list[str]:
    """What the command line prints after writing a case."""
    flaser = sum(is_flaser(o.scan) for o in case.observations)
    kinds = "FLASER" if flaser == len(case.observations) else \
        "ROBOTLASER1" if flaser == 0 else "FLASER and ROBOTLASER1"
    p = case.placed()
    out = [f"wrote {out_dir}: stale.yaml, log.clf ({len(case.observations)} scans, {kinds}), "
           f"truth.npz, case.yaml",
           f"  placed {p['removed']} removed, {p['added']} added, {p['moved']} moved boxes and "
           f"{p['people']} people (asked {case.asked['removed']}, {case.asked['added']}, "
           f"{case.asked['moved']}, {case.asked['people']})"]
    for b in case.boxes:
        pair = "" if b.pair is None else f" (pair {b.pair + 1})"
        out.append(f"  {b.kind + pair:<16} centre ({b.box.cx:8.3f}, {b.box.cy:8.3f}) m  "
                   f"{b.box.w:.2f} x {b.box.h:.2f} m  yaw {math.degrees(b.box.yaw):5.1f} deg  "
                   f"seen by {b.views} scans")
    if case.dropped:
        out.append(f"  {case.dropped} scans without a recorded pose left out")
    return out + [f"  note: {n}" for n in case.notes]


# --- scoring -----------------------------------------------------------------------------------

def load_case(case_dir) -> tuple[OccupancyGrid, dict]:
    """The stale map and the truth arrays of a case folder."""
    d = Path(case_dir)
    if not d.is_dir():
        raise CaseError(f"{d}: no such case folder")
    for name in ("stale.yaml", "truth.npz"):
        if not (d / name).is_file():
            raise CaseError(f"{d}: not a case folder (no {name})")
    stale = load_map(d / "stale.yaml")
    try:
        with np.load(d / "truth.npz", allow_pickle=False) as z:
            truth = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise CaseError(f"{d / 'truth.npz'}: cannot read it ({' '.join(str(e).split())})") \
            from None
    for k in (*TRUTH_MASKS, "removed_views", "added_views", "reference"):
        if k not in truth or truth[k].shape != stale.shape:
            raise CaseError(f"{d / 'truth.npz'}: no {k} of the stale map's {stale.width} x "
                            f"{stale.height} cells")
    return stale, truth


def _share(hits: np.ndarray) -> float | None:
    return float(np.mean(hits)) if hits.size else None


def score_case(case_dir, updated: OccupancyGrid) -> dict:
    """Scores of an updated map against a case (see docs/edited_world.md): removed_freed (of
    the removed boxes' outline cells a beam passes through), removed_freed_all (of their whole
    outline), added_drawn (shares, None with no cell to score), false_occupied, walls_freed, ghosts
    (cells), and the number of cells in each truth mask."""
    stale, truth = load_case(case_dir)
    if not updated.same_frame(stale):
        raise CaseError(f"the updated map ({_frame(updated)}) is not on the case's grid "
                        f"({_frame(stale)})")
    u, s = updated.data, stale.data
    occupied = u == OCCUPIED
    removed_few = truth["removed_views"] >= FEW_VIEWS
    added_few = truth["added_views"] >= FEW_VIEWS
    # where the user's map does not know the floor, a drawn cell is growth, not an error
    drawn = occupied & (s != OCCUPIED) & ~near(truth["added_all"])
    false_occupied = drawn & (truth["reference"] != UNKNOWN)
    walls = (s == OCCUPIED) & (truth["reference"] == OCCUPIED)
    scores = {
        "removed_freed": _share(u[truth["removed_seen"]] == FREE),
        "removed_freed_all": _share(u[truth["removed_outline"]] == FREE),
        f"removed_freed_{FEW_VIEWS}": _share(u[removed_few] == FREE),
        f"added_drawn_{FEW_VIEWS}": _share(near(occupied)[added_few]),
        "added_drawn": _share(near(occupied)[truth["added_outline"]]),
        "false_occupied": int(false_occupied.sum()),
        "walls_freed": int((walls & (u == FREE)).sum()),
        "ghosts": int((false_occupied & truth["people"]).sum()),
        "grown_occupied": int((drawn & (truth["reference"] == UNKNOWN)).sum()),
    }
    return scores | {f"{k}_cells": int(truth[k].sum()) for k in TRUTH_MASKS} | {
        f"removed_seen_{FEW_VIEWS}_cells": int(removed_few.sum()),
        f"added_outline_{FEW_VIEWS}_cells": int(added_few.sum())}


def _frame(g: OccupancyGrid) -> str:
    return (f"{g.width} x {g.height} cells at {g.resolution:g} m, origin "
            f"({g.origin[0]:g}, {g.origin[1]:g})")


def score_lines(scores: dict) -> list[str]:
    """The scores as a short table."""
    def share(v):
        return "     -" if v is None else f"{v:6.3f}"

    return [f"{'score':<16}{'value':>8}  of",
            f"{'removed_freed':<16}{share(scores['removed_freed']):>8}  "
            f"{scores['removed_seen_cells']} seen outline cells of removed boxes",
            f"{'  all outline':<16}{share(scores['removed_freed_all']):>8}  "
            f"{scores['removed_outline_cells']} outline cells, seen through or not",
            f"{'  seen 3+ times':<16}{share(scores[f'removed_freed_{FEW_VIEWS}']):>8}  "
            f"{scores[f'removed_seen_{FEW_VIEWS}_cells']} of them seen through by "
            f"{FEW_VIEWS} scans or more",
            f"{'added_drawn':<16}{share(scores['added_drawn']):>8}  "
            f"{scores['added_outline_cells']} seen outline cells of added boxes",
            f"{'  seen 3+ times':<16}{share(scores[f'added_drawn_{FEW_VIEWS}']):>8}  "
            f"{scores[f'added_outline_{FEW_VIEWS}_cells']} of them hit by {FEW_VIEWS} scans "
            "or more",
            f"{'false_occupied':<16}{scores['false_occupied']:>8}  cells",
            f"{'walls_freed':<16}{scores['walls_freed']:>8}  cells",
            f"{'ghosts':<16}{scores['ghosts']:>8}  cells ({scores['people_cells']} cells "
            "people covered)",
            f"{'grown_occupied':<16}{scores['grown_occupied']:>8}  cells drawn where the map "
            "knows nothing (not scored)"]


def write_scores(scores: dict, path) -> None:
    """The scores as JSON, written atomically."""
    write_atomically(path, json.dumps(scores, indent=2) + "\n")
