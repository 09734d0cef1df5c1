"""The Intel Research Lab log (real SICK scans in an office with people, poses corrected by
gmapping): a map of the first half of the scans, updated with the second half through
``update_from_log``, must move towards the map of the second half, over the cells both halves
observed, without freeing any cell both halves saw occupied.

Run with ``-s`` to print the figures.
"""

from pathlib import Path

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, load_map, save_map
from gridmap.mapping import build_map
from gridmap.metrics import cross_correlation, opdf
from robotlogs.carmen import read_carmen
from onboard.replay import LogSource, Outputs, update_from_log

INTEL = Path(__file__).resolve().parents[2] / "shared/data/intel.gfs.log"
RES = 0.05
MARGIN = 1.0  # [m] around every hit point

pytestmark = pytest.mark.skipif(not INTEL.exists(),
                                reason=f"the Intel lab log is not at {INTEL} (see data/README)")


def frame_around(scans, res: float) -> OccupancyGrid:
    """A grid that holds every hit point of the log, with a margin."""
    points = []
    for r in scans:
        hit = np.isfinite(r.scan.ranges)
        a = r.scan.angles()[hit] + r.laser_pose.theta
        d = r.scan.ranges[hit]
        points.append(np.c_[r.laser_pose.x + d * np.cos(a), r.laser_pose.y + d * np.sin(a)])
    p = np.concatenate(points)
    lo = np.floor(p.min(axis=0) - MARGIN)
    hi = np.ceil(p.max(axis=0) + MARGIN)
    width, height = (int(round(v)) for v in (hi - lo) / res)
    return OccupancyGrid.empty(width, height, res, origin=(float(lo[0]), float(lo[1])))


def figures(a: OccupancyGrid, b: OccupancyGrid, observed: np.ndarray) -> dict:
    """CC over the observed cells only; OPDF with every other cell unknown (not occupied)."""
    cc = cross_correlation(a.data[observed][None, :], b.data[observed][None, :])
    da, db = (np.where(observed, g.data, UNKNOWN) for g in (a, b))
    return {"cc": cc, "opdf": opdf(da, db)}


@pytest.fixture(scope="module")
def intel(tmp_path_factory):
    d = tmp_path_factory.mktemp("intel")
    scans = read_carmen(INTEL, strict=True).scans()
    half = len(scans) // 2
    frame = frame_around(scans, RES)
    first = build_map(frame, [(r.scan, r.laser_pose) for r in scans[:half]])
    second = build_map(frame, [(r.scan, r.laser_pose) for r in scans[half:]])
    save_map(first, d / "first.yaml")
    summary = update_from_log(d / "first.yaml", LogSource(INTEL, start_time=scans[half].time),
                              Outputs(d / "updated.yaml"))
    updated = load_map(d / "updated.yaml")
    observed = (first.data != UNKNOWN) & (second.data != UNKNOWN)
    result = {
        "scans": len(scans), "half": half, "summary": summary, "first": first,
        "second": second, "updated": updated, "observed": observed,
        "first_vs_second": figures(first, second, observed),
        "updated_vs_second": figures(updated, second, observed),
    }
    print(f"\nIntel lab: {len(scans)} scans, map {frame.width} x {frame.height} at {RES} m, "
          f"{int(observed.sum())} cells observed by both halves")
    for k in ("first_vs_second", "updated_vs_second"):
        print(f"  {k:<18} CC {result[k]['cc']:.3f} %  OPDF {result[k]['opdf']:.3f} %")
    print("  replay: " + ", ".join(f"{k} {summary[k]}" for k in (
        "scans_used", "scans_processed", "scans_dropped_as_lost", "cells_freed",
        "cells_occupied")))
    return result


def test_replay_used_the_corrected_poses_of_the_second_half(intel):
    s = intel["summary"]
    assert s["format"] == "carmen" and s["pose_source"] == "recorded"
    assert s["scans_used"] == intel["scans"] - intel["half"]
    assert s["scans_processed"] > 0 and s["read"]["skipped"] == {}


def test_updated_map_is_closer_to_the_second_half(intel):
    before, after = intel["first_vs_second"], intel["updated_vs_second"]
    assert after["cc"] > before["cc"]
    assert after["opdf"] > before["opdf"]


def test_no_cell_occupied_in_both_halves_is_freed(intel):
    both = (intel["first"].data == OCCUPIED) & (intel["second"].data == OCCUPIED)
    assert both.sum() > 1000
    assert not np.any(both & (intel["updated"].data == FREE))
