"""MIT Killian Court (../shared/data/killian.clf.gz: CARMEN ROBOTLASER1 lines, gzip, corrected
poses, 3 873 scans over 128 minutes): a map of the first third of the scans, updated with the
last third through ``update_from_log``, must free no cell that both thirds' maps have
occupied, and move no further from the last third's map (CC and OPDF over the cells both
observed). Also the time it takes, per 1000 scans.

Of the 2 323 cells occupied in both thirds' maps, 1 905 have two or more occupied neighbours in
both (walls, pillars). The hardest of the rest are specks at the corners of recesses along a
corridor that the first third saw only from 18-24 m, one hit each and nothing else around them:
in the first map they are occupied cells in unknown space. The last third drives up that
corridor, looks past them (the beams end 0.1-1.5 m behind), and later drives back and hits
them at 1.3-9 m. Around them M is unknown, so every beam there is a detected change, and
before ``UpdaterConfig.confirm_hit_surfaces`` the hits gave no unchanged flag: the walks of
the way up and the unknown cells around them seen through (neighbour support) freed 3 of
them, although the same session hit them last (its log-odds map has them occupied because the
hits came last).

Run with ``-s`` to print the figures.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, save_map
from gridmap import load_map
from gridmap.mapping import build_map
from robotlogs import log_observations
from onboard.logmap import _placed_scans, map_frame
from onboard.replay import LogSource, Outputs, update_from_log

from test_intel import figures

KILLIAN = Path(__file__).resolve().parents[2] / "shared/data/killian.clf.gz"

pytestmark = pytest.mark.skipif(not KILLIAN.exists(),
                                reason=f"the Killian Court log is not at {KILLIAN} "
                                       "(see data/README)")


@pytest.fixture(scope="module")
def killian(tmp_path_factory):
    d = tmp_path_factory.mktemp("killian")
    found = log_observations(KILLIAN)
    placed = _placed_scans(found, "recorded", (None, None))
    times = [o.time for o in found.observations]
    third = len(placed) // 3
    frame = map_frame(placed, 0.05)            # one frame for both thirds' maps
    first, last = build_map(frame, placed[:third]), build_map(frame, placed[-third:])
    save_map(first, d / "first.yaml")
    t0 = time.perf_counter()
    summary = update_from_log(d / "first.yaml", LogSource(KILLIAN, start_time=times[-third]),
                              Outputs(d / "updated.yaml"))
    seconds = time.perf_counter() - t0
    updated = load_map(d / "updated.yaml")
    observed = (first.data != UNKNOWN) & (last.data != UNKNOWN)
    out = {"summary": summary, "first": first, "last": last, "updated": updated,
           "before": figures(first, last, observed), "after": figures(updated, last, observed),
           "per_1000": 1000 * seconds / summary["scans_used"], "third": third}
    print(f"\nKillian Court: {len(placed)} scans, map {frame.width} x {frame.height} at 0.05 m, "
          f"{int(observed.sum())} cells observed by both thirds")
    print(f"  first vs last third: CC {out['before']['cc']:.3f} %  OPDF "
          f"{out['before']['opdf']:.3f} %")
    print(f"  updated vs last third: CC {out['after']['cc']:.3f} %  OPDF "
          f"{out['after']['opdf']:.3f} %")
    print("  replay: " + ", ".join(f"{k} {summary[k]}" for k in (
        "scans_used", "scans_processed", "scans_dropped_as_lost", "cells_freed",
        "cells_occupied")) + f"; {out['per_1000']:.2f} s per 1000 scans")
    return out


def test_the_last_third_is_replayed_at_its_corrected_poses(killian):
    s = killian["summary"]
    assert s["format"] == "carmen" and s["pose_source"] == "recorded"
    assert s["scans_used"] == killian["third"] and s["read"]["skipped"] == {}


def occupied_neighbours(grid) -> np.ndarray:
    occupied = (grid.data == OCCUPIED).astype(np.int32)
    p = np.pad(occupied, 1)
    return sum(p[1 + dr:p.shape[0] - 1 + dr, 1 + dc:p.shape[1] - 1 + dc]
               for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc)


def test_no_cell_occupied_in_both_thirds_is_freed(killian):
    first, last, updated = killian["first"], killian["last"], killian["updated"]
    both = (first.data == OCCUPIED) & (last.data == OCCUPIED)
    surfaces = both & (occupied_neighbours(first) >= 2) & (occupied_neighbours(last) >= 2)
    freed = both & (updated.data == FREE)
    print(f"\nKillian: {int(both.sum())} cells occupied in both thirds, {int(freed.sum())} "
          f"freed; {int(surfaces.sum())} of them on surfaces, "
          f"{int((surfaces & freed).sum())} freed")
    assert both.sum() > 2000 and surfaces.sum() > 1000
    assert not np.any(freed)


def test_the_update_moves_no_further_from_the_last_third(killian):
    before, after = killian["before"], killian["after"]
    assert after["cc"] >= before["cc"] and after["opdf"] >= before["opdf"]


def test_it_takes_seconds_per_thousand_scans(killian):
    assert killian["per_1000"] < 30.0
