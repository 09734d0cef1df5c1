"""`mapupdate update`'s summary says what the update did and why, with numbers: the cells
changed by kind, counted apart (each checked against the two maps); the method that updated
the map; scans timed from scan order when the log's stamps do not increase; the gate's
refusals by rule and the evidence of change left below the threshold, above all when no cell
changed."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, Pose2D, load_map, save_map
from robotlogs.carmen import read_carmen
from mapupdate import main
from onboard.methods import make_method
from mapupdate.summaries import update_lines as summary_lines
from onboard.replay import LogSource, Outputs, ScanClock, update_from_log
from updater import ScanStatus, UpdaterConfig

import synthetic_room as world

BOX = world.Rect(5.2, 5.2, 5.8, 5.8)      # in the map, gone from the room
UNMAPPED = world.Rect(2.0, 2.0, 3.0, 3.0)  # floor the map leaves unknown
ROBOT = UpdaterConfig.profile("robot")


def reference():
    """The room with the box, and a patch of its floor unknown."""
    grid = world.rasterise(world.room_walls() + [BOX])
    data = grid.data.copy()
    data[world.cells_of(UNMAPPED)] = UNKNOWN
    return grid.with_data(data)


def circle(n=400):
    """The robot circling the box, 5 cm per scan."""
    return [true for true, _, _ in world.Drive(seconds=n / 10, rate=10.0).steps()]


def in_process(method, log, config=ROBOT):
    """The method fed the log's scans at their recorded poses, each at its stamp."""
    upd = make_method(method, reference(), config)
    reports = [upd.process(rec.scan, rec.laser_pose, odometry=rec.odom_pose)
               for rec in read_carmen(log).scans()]
    return upd, reports


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    d = tmp_path_factory.mktemp("summary")
    save_map(reference(), d / "map.yaml")
    return d


# --- the cells changed, by kind -------------------------------------------------------------------
def test_cells_changed_are_counted_by_kind_as_the_two_maps_differ(room, capsys):
    log = world.carmen_log(room / "circle.log", circle(), [0.1 * k for k in range(400)])
    out = room / "circle.yaml"
    assert main(["update", "--map", str(room / "map.yaml"), "--log", str(log), "--out",
                 str(out), "--no-progress"]) == 0
    lines = capsys.readouterr().out.splitlines()
    before, after = load_map(room / "map.yaml").data, load_map(out).data
    kinds = {"occupied_to_free": (OCCUPIED, FREE), "free_to_occupied": (FREE, OCCUPIED),
             "unknown_to_free": (UNKNOWN, FREE), "unknown_to_occupied": (UNKNOWN, OCCUPIED)}
    n = {k: int(((before == a) & (after == b)).sum()) for k, (a, b) in kinds.items()}
    box = world.cells_of(BOX)
    # the box is gone: its cells are freed, and they are the only occupied cells freed
    assert n["occupied_to_free"] == int((after[box] == FREE).sum()) > 0.9 * box.sum()
    assert n["unknown_to_free"] > 0.9 * world.cells_of(UNMAPPED).sum()   # the floor grown into
    assert int((before != after).sum()) == sum(n.values())               # nothing else changed
    assert lines[0] == (f"wrote {out}: {n['occupied_to_free']} occupied cells freed, "
                        f"{n['free_to_occupied']} free cells occupied, "
                        f"{n['unknown_to_free'] + n['unknown_to_occupied']} unknown cells now "
                        f"known ({n['unknown_to_free']} free, {n['unknown_to_occupied']} "
                        "occupied); method paper, poses recorded, profile robot")
    s = update_from_log(room / "map.yaml", LogSource(log), Outputs(room / "again.yaml"))
    assert {k: s[k] for k in kinds} == n and s["known_to_unknown"] == 0
    assert s["cells_freed"] == n["occupied_to_free"] + n["unknown_to_free"]
    assert s["cells_occupied"] == n["free_to_occupied"] + n["unknown_to_occupied"]
    # the gate's refusals, by rule, as the updater reports them scan by scan
    _, reports = in_process("paper", log)
    rules = Counter(r.reason for r in reports if r.status is ScanStatus.GATED)
    assert s["gated_by"] == dict(rules) and s["scans_gated"] == sum(rules.values()) > 300
    assert s["scans_processed"] + s["scans_gated"] == s["scans_used"] == 400
    listed = ", ".join(f"{rule} {k}" for rule, k in rules.most_common())
    confirming = sum(r.status is ScanStatus.GATED and r.unchanged_flags > 0 for r in reports)
    assert s["scans_confirming"] == confirming > 0
    assert f"  the gate refused {s['scans_gated']} of 400 scans: {listed}; {confirming} of " \
           "them, views already taken, confirmed the map's surfaces" in lines


# --- the method -----------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["fuse", "hybrid"])
def test_method_fuse_or_hybrid_through_the_command_line(room, capsys, method):
    log = room / "circle.log"
    if not log.exists():
        world.carmen_log(log, circle(), [0.1 * k for k in range(400)])
    out = room / f"{method}.yaml"
    assert main(["update", "--map", str(room / "map.yaml"), "--log", str(log), "--out",
                 str(out), "--method", method, "--no-progress"]) == 0
    text = capsys.readouterr().out
    upd, _ = in_process(method, log)
    expected = upd.updated_map().data
    np.testing.assert_array_equal(load_map(out).data, expected)     # the method's own map
    before = load_map(room / "map.yaml").data
    freed = int(((before == OCCUPIED) & (expected == FREE)).sum())
    assert freed > 100                                               # the box, mostly
    first = text.splitlines()[0]
    assert first.startswith(f"wrote {out}: {freed} occupied cells freed, ")
    assert first.endswith(f"; method {method}, poses recorded, profile robot")
    assert "evidence of change" not in text        # the method keeps no flag buffers


@pytest.mark.parametrize("argv, words", [
    (["--method", "hybird"], "--method: unknown method 'hybird' (did you mean 'hybrid'?) "
                             "(methods: paper, fuse, hybrid)"),
    (["--method", "remap"], "--method: unknown method 'remap' (methods: paper, fuse, hybrid)"),
    (["--method", "fuse", "--state", "s.npz"],
     "--state s.npz: only the paper's updater has a state to save and load, --method fuse has "
     "none; leave out --state or use --method paper"),
])
def test_a_misspelt_method_or_a_state_without_the_paper_is_one_line_before_any_read(
        tmp_path, capsys, monkeypatch, argv, words):
    monkeypatch.chdir(tmp_path)
    # neither the map nor the log exists: the arguments are refused before they are read
    assert main(["update", "--map", "none.yaml", "--log", "none.log", "--out", "o.yaml",
                 "--no-progress", *argv]) == 2
    err = capsys.readouterr().err
    assert err == f"mapupdate update: error: {words}\n"
    assert list(tmp_path.iterdir()) == []


# --- stamps that do not tell time -----------------------------------------------------------------
def test_the_clock_keeps_increasing_stamps_and_times_the_others_from_scan_order():
    clock = ScanClock()
    assert [clock(t) for t in (3.0, 3.5, 4.0)] == [3.0, 3.5, 4.0]
    assert clock.placed == 0 and clock.period is None
    # all equal, no interval known yet: 1 s apart
    clock = ScanClock()
    assert [clock(0.0) for _ in range(4)] == [0.0, 1.0, 2.0, 3.0]
    assert clock.summary() == {"scans": 4, "same_as_before": 3, "earlier_than_before": 0,
                               "period_s": 1.0, "period_measured": False}
    # a jump back: the median interval after the scan before, and the rest keeps its intervals
    clock = ScanClock()
    assert [clock(t) for t in (10.0, 10.2, 10.4, 10.8, 7.0, 7.2, 7.4)] == \
        pytest.approx([10.0, 10.2, 10.4, 10.8, 11.0, 11.2, 11.4])
    assert (clock.same, clock.earlier, clock.measured) == (0, 1, True)
    assert clock.period == pytest.approx(0.2)
    # stamps coarser than the scans: an interval counts over the scans that shared a stamp
    clock = ScanClock()
    got = [clock(t) for t in (5.0, 5.0, 5.0, 5.0, 6.0, 6.0)]
    assert got[:5] == [5.0, 6.0, 7.0, 8.0, 9.0] and got[5] == pytest.approx(9.25)
    # two lidars may share a stamp; each lidar's stamps are judged apart
    clock = ScanClock()
    assert [clock(t, lidar) for t, lidar in ((1.0, "front"), (1.0, "rear"), (1.1, "front"),
                                             (1.1, "rear"), (1.1, "rear"))] == \
        pytest.approx([1.0, 1.0, 1.1, 1.1, 1.2])
    assert (clock.same, clock.earlier) == (1, 0)
    # the intervals kept are bounded, whatever the log's length
    clock = ScanClock(keep=5)
    for k in range(100):
        clock(0.1 * k)
    assert max(len(own.intervals) for own in clock._lidars.values()) == 5


def test_a_log_whose_stamps_are_all_equal_is_replayed_from_scan_order_and_says_so(room):
    poses = circle()
    equal = world.carmen_log(room / "equal.log", poses, [0.0] * len(poses))
    # the scans at their stamps, as the replay gave them before, to the authors' gate: it
    # never sees time pass, so it lets the first scan through and no other
    _, reports = in_process("paper", equal, UpdaterConfig(grow_into_unknown=True))
    assert sum(r.processed for r in reports) == 1
    s = update_from_log(room / "map.yaml", LogSource(equal), Outputs(room / "equal.yaml"))
    assert s["timestamps"] == {"scans": 400, "same_as_before": 399, "earlier_than_before": 0,
                               "period_s": 1.0, "period_measured": False}
    # ... now timed 1 s apart: as the same log with stamps 1 s apart, scan for scan
    spaced = world.carmen_log(room / "spaced.log", poses, [float(k) for k in range(len(poses))])
    t = update_from_log(room / "map.yaml", LogSource(spaced), Outputs(room / "spaced.yaml"))
    assert t["timestamps"]["same_as_before"] == t["timestamps"]["earlier_than_before"] == 0
    assert s["scans_processed"] == t["scans_processed"] > 30
    np.testing.assert_array_equal(load_map(room / "equal.yaml").data,
                                  load_map(room / "spaced.yaml").data)
    assert s["occupied_to_free"] > 100
    assert "  warning: 399 of 400 scans have the same timestamp as the scan before; their " \
           "times were taken from scan order, 1 s after the scan before (the log gives no " \
           "interval between its scans), for the gate and the pose smoothing" \
           in summary_lines(s)
    assert not any("timestamp" in line for line in summary_lines(t))


# --- why nothing changed --------------------------------------------------------------------------
def test_when_no_cell_changed_the_summary_says_why(room, capsys):
    """The robot stands before the box's place for 1 s, then spins on the spot at 100 deg/s:
    the gate lets the first scan through, refuses the standing ones (no motion: they only
    confirm the map's surfaces) and the spinning ones (fast turn), and the box's cells keep one
    changed flag each, short of the threshold."""
    start = Pose2D(3.5, 5.5, 0.0)
    poses = [start] * 10 + [Pose2D(start.x, start.y, math.radians(10.0 * k)) for k in
                            range(1, 11)]
    log = world.carmen_log(room / "still.log", poses, [0.1 * k for k in range(len(poses))])
    out = room / "still.yaml"
    assert main(["update", "--map", str(room / "map.yaml"), "--log", str(log), "--out",
                 str(out), "--no-progress"]) == 0
    lines = capsys.readouterr().out.splitlines()
    np.testing.assert_array_equal(load_map(out).data, load_map(room / "map.yaml").data)
    upd, reports = in_process("paper", log)
    rules = Counter(r.reason for r in reports if r.status is ScanStatus.GATED)
    assert set(rules) == {"no motion", "fast turn"} and rules["fast turn"] == 10
    flagged = int((upd.change_counts() > 0).sum())           # cells with a changed flag
    assert flagged > 20
    s = update_from_log(room / "map.yaml", LogSource(log), Outputs(room / "again.yaml"))
    assert s["evidence"] == {"pending_cells": flagged, "pending_few_observations": flagged,
                             "pending_outvoted": 0, "threshold": 7}
    listed = ", ".join(f"{rule} {k}" for rule, k in sorted(rules.items(),
                                                           key=lambda kv: (-kv[1], kv[0])))
    assert lines[0] == f"wrote {out}: 0 cells changed; method paper, poses recorded, profile robot"
    confirming = sum(r.status is ScanStatus.GATED and r.unchanged_flags > 0 for r in reports)
    assert lines[2] == (f"  0 cells changed: {flagged} cells collected evidence of change "
                        f"below the threshold ({flagged} seen by fewer than 7 processed "
                        f"scans); the gate refused 19 of 20 scans ({listed}); {confirming} of "
                        "them, views already taken, confirmed the map's surfaces")


def test_with_nothing_pending_and_nothing_refused_the_summary_still_says_why():
    s = {"out": "o.yaml", "method": "paper", "pose_source": "recorded", "scans": 5,
         "scans_used": 5, "scans_processed": 5, "evidence": {"pending_cells": 0}}
    assert summary_lines(s)[2] == "  0 cells changed: the 5 scans processed found no " \
                                  "evidence of change"
    s.update(method="fuse", evidence=None)
    assert summary_lines(s)[2] == "  0 cells changed: the 5 scans processed gave no cell " \
                                  "evidence enough to change it"
    s.update(scans_processed=0, scans_off_map=5)
    assert summary_lines(s)[2] == "  0 cells changed: no scan was processed; 5 scans lay off " \
                                  "the map"


def test_without_the_unanimous_rule_the_pending_cells_are_counted_not_split(room):
    """The paper's own configuration keeps no flag counts (a byte per cell less): the summary
    gives the cells whose evidence stayed below the threshold without saying why."""
    start = Pose2D(3.5, 5.5, 0.0)
    log = world.carmen_log(room / "still2.log", [start] * 10, [0.1 * k for k in range(10)])
    s = update_from_log(room / "map.yaml", LogSource(log), Outputs(room / "still2.yaml"),
                        updater_config=UpdaterConfig(grow_into_unknown=True))
    e = s["evidence"]
    assert e["pending_cells"] > 20 and e["pending_few_observations"] is None
    line = next(x for x in summary_lines(s) if "cells collected evidence" in x)
    assert f"{e['pending_cells']} cells collected evidence of change below the threshold" in line
    assert "seen by fewer" not in line
