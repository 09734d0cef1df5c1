"""The gate for recordings of any density (``UpdaterConfig.gate_velocity_max_dt``,
``gate_turn_views``, ``gate_confirm``) and the robot profile's gate: a sparse recording
is not taken for a fast turn, a robot spinning in place gives a bounded number of views, and a
robot standing still confirms the map without putting its one view of a change into the
buffers again and again."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, Pose2D
from updater import MapUpdater, UpdaterConfig
from updater.gating import (GATED_FAST_TURN, GATED_INTERVAL, GATED_NO_MOTION, GATED_TURN_VIEWS,
                            Gate, bins_seen, directions_seen)

import synthetic_room as world

ROBOT = UpdaterConfig.profile("robot")
BOX = world.Rect(6.4125, 5.1125, 7.0125, 5.9125)      # 0.6 x 0.8 m, 1.2 m ahead of the robot


def sparse_track(n=40):
    """A recording that keeps a scan every 1.5 s: 1 m on and 20 deg of turn between scans
    (13 deg/s, a fast turn for the paper's gate)."""
    return [(1.5 * k, Pose2D(float(k), 0.0, math.radians(20.0 * k))) for k in range(n)]


def run_gate(config, track):
    g, reasons = Gate(config), []
    for t, pose in track:
        reason = g.check(t, pose, True)
        if reason == "":
            g.mark_processed(t, pose)
        reasons.append(reason)
    return reasons


def test_sparse_recording_is_not_read_as_a_fast_turn():
    paper = run_gate(UpdaterConfig(), sparse_track())
    robot = run_gate(ROBOT, sparse_track())
    assert paper.count(GATED_FAST_TURN) > 20           # the paper's gate idles most of it
    assert robot.count("") == len(robot)               # every scan is a new view


def test_a_dense_fast_turn_still_holds_scans_back_briefly():
    # 10 Hz, 90 deg/s for 1 s while driving 0.5 m/s, then straight on
    track = [(0.1 * k, Pose2D(0.05 * k, 0.0, math.radians(9.0 * min(k, 10)))) for k in range(40)]
    reasons = run_gate(ROBOT, track)
    assert GATED_FAST_TURN in reasons[1:11]
    resumed = [k for k, r in enumerate(reasons) if r == "" and k > 10]
    assert resumed and resumed[0] * 0.1 <= 1.0 + ROBOT.gate_recovery_time + 0.5


def turn_in_place(config, fov_deg):
    """20 deg/s in place at 10 Hz for two full turns, then 1 m straight on: the reasons."""
    track = [(0.1 * k, Pose2D(0.0, 0.0, math.radians(2.0 * k))) for k in range(360)]
    track += [(36.0 + 0.1 * k, Pose2D(0.05 * k, 0.0, 0.0)) for k in range(1, 21)]
    g, reasons = Gate(config), []
    for t, pose in track:
        reason = g.check(t, pose, True, fov_deg)
        if reason == "":
            g.mark_processed(t, pose)
        reasons.append(reason)
    return reasons


def views_until_seen(views, fov_deg, step_deg=20.0, turn_deg=720.0):
    """Reference: the views a robot turning in place in steps of ``step_deg`` takes while a
    direction (to the degree) in its field was seen fewer than ``views`` times."""
    seen = np.zeros(360, int)
    taken = 0
    for heading in np.arange(0.0, turn_deg, step_deg):
        off = (np.arange(360) + 0.5 - heading + 180.0) % 360.0 - 180.0
        field = np.abs(off) <= fov_deg / 2 if fov_deg < 360 else np.ones(360, bool)
        if heading > 0 and seen[field].min() >= views:
            continue
        seen[field] += 1
        taken += heading > 0
    return taken


@pytest.mark.parametrize("views", [1, 2, 3])
def test_turning_in_place_is_processed_until_each_direction_was_seen_so_often(views):
    config = replace(ROBOT, gate_turn_views=views)
    reasons = turn_in_place(config, 180.0)           # a lidar of 180 deg
    # a view each time the heading moved gate_min_rotation_deg (in steps of 2 deg, so 20 to
    # 22 deg apart); the gate counts directions in bins of 10 deg, the reference to the degree
    turns = reasons[:360].count("") - 1
    slow = views_until_seen(views, 180.0, ROBOT.gate_min_rotation_deg + 2.0)
    fast = views_until_seen(views, 180.0, ROBOT.gate_min_rotation_deg)
    assert slow - 1 <= turns <= fast + 1
    assert reasons.count(GATED_TURN_VIEWS) > 0
    assert reasons[360:].count("") >= 2              # moving again starts afresh
    # a lidar of 360 deg sees every direction in each view: views - 1 views from turning
    full = turn_in_place(config, 360.0)
    assert full[:360].count("") - 1 == views - 1 == views_until_seen(views, 360.0)
    assert full[:360].count(GATED_TURN_VIEWS) > 300


def test_a_narrow_scan_counts_the_direction_it_faces():
    assert directions_seen(math.radians(-3.0), 4.0).nonzero()[0].tolist() == [35]
    reasons = turn_in_place(ROBOT, 4.0)              # a 4 deg beam fan turning in place
    # 720 deg in views of at least 20 deg, each bin of 10 deg seen twice at most
    assert 2 <= reasons[:360].count("") - 1 <= 720 // 20


def test_the_bins_from_the_arc_ends_are_the_bins_every_bin_is_tested_for():
    # headings round the circle and past it, on the bins' edges and centres, and fields from
    # none to nearly a turn (the arc's ends then meet behind the scan)
    rng = np.random.default_rng(5)
    headings = np.concatenate([rng.uniform(-8.0, 8.0, 400),
                               np.radians(np.arange(-725.0, 725.0, 2.5))])
    fields = [0.0, 0.5, 4.0, 9.99, 10.0, 20.0, 90.0, 180.0, 270.0, 340.0, 350.0, 355.0, 359.9]
    for heading in headings:
        for fov in fields + [float(rng.uniform(0.0, 360.0))]:
            got = bins_seen(float(heading), fov)
            want = directions_seen(float(heading), fov).nonzero()[0].tolist()
            assert sorted(got) == want and len(set(got)) == len(got), (heading, fov)
    assert sorted(bins_seen(math.radians(-3.0), 4.0)) == [35]
    # 17.2 deg: the centres at 195 and 205 deg lie 177.8 and 172.2 deg from it
    assert len(bins_seen(0.3, 359.9)) == 36 and len(bins_seen(0.3, 340.0)) == 34


def test_turning_in_place_is_unbounded_without_the_rule():
    unlimited = turn_in_place(UpdaterConfig(gate_fast_turn_deg_s=3600.0), 180.0)
    assert unlimited[:360].count("") == 1 + 2 * 360 // 45 - 1     # every 45 deg, twice round


def test_a_saved_gate_keeps_its_views_of_each_direction(tmp_path):
    g = Gate(ROBOT)
    for k in range(4):                               # a place, then three turning views
        pose = Pose2D(0.0, 0.0, math.radians(30.0 * k))
        assert g.check(float(k), pose, True, 180.0) == ""
        g.mark_processed(float(k), pose)
    h = Gate(ROBOT)
    h.restore(json.loads(json.dumps(g.state())))
    assert np.array_equal(h.turn_views, g.turn_views) and h.turn_views.max() == 4
    nxt = (4.0, Pose2D(0.0, 0.0, math.radians(120.0)), True, 180.0)
    assert h.check(*nxt) == g.check(*nxt)


def _stand_still(config, scans=60):
    """The robot stands still 1.2 m from where M has a box the world no longer has."""
    walls = world.room_walls()
    ref = world.rasterise(walls + [BOX])
    updater = MapUpdater(ref, config)
    pose = Pose2D(5.2, 5.5, 0.0)
    reports = [updater.process(world.full_scan(walls, pose, 0.1 * k), pose, odometry=pose)
               for k in range(scans)]
    return ref, updater, reports


def test_standing_still_confirms_the_map_but_adds_no_change():
    box = world.cells_of(BOX)
    ref, updater, reports = _stand_still(ROBOT)
    held = [r for r in reports[1:]]
    assert all(r.reason in (GATED_NO_MOTION, GATED_INTERVAL) for r in held)
    assert all(r.changed_flags == 0 for r in held)
    # the first held-back scan confirms what it hits, the others nothing more: a cell is
    # confirmed once between two views
    walls_hit = held[0].unchanged_flags
    assert walls_hit > 100 and all(r.unchanged_flags == 0 for r in held[1:])
    out = updater.updated_map().data
    walls = (ref.data == OCCUPIED) & ~box
    assert (out[walls] == OCCUPIED).all()
    # one view of the removed box is one flag per cell: below any threshold, so the box stays
    assert updater.change_counts()[box].max() == 1
    assert (out[box & (ref.data == OCCUPIED)] == OCCUPIED).all()
    # ungated, the same 60 scans are 60 views of one place, and free the box
    ref, ungated, _ = _stand_still(UpdaterConfig.profile("robot", {"gating": False}))
    assert (ungated.updated_map().data[box & (ref.data == OCCUPIED)] == FREE).mean() > 0.5


def test_paper_gate_without_confirm_flags_nothing_while_standing():
    _, updater, reports = _stand_still(UpdaterConfig())
    assert all(r.unchanged_flags == 0 for r in reports[1:])
    assert np.count_nonzero(updater.change_counts()) > 0     # the first scan's flags only
