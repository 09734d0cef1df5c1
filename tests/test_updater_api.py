"""The updater's public surface: configuration, gating, bad input, scan geometry (270 degrees),
reports, saving and resuming."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from gridmap import OccupancyGrid, Pose2D, Scan
from updater import (BEAM_CHANGE, BEAM_INVALID, BEAM_SKIPPED, BEAM_UNCHANGED, MapUpdater,
                     UpdaterConfig, UpdaterError)
from updater.gating import GATED_FAST_TURN, GATED_INTERVAL, GATED_NO_MOTION, GATED_TIME_BACK, Gate

import synthetic_room as world

CENTRE = Pose2D(5.5, 5.5, 0.3)


def room():
    walls = world.room_walls()
    return walls, world.rasterise(walls)


# --- configuration ----------------------------------------------------------------------------
def test_defaults_are_those_of_the_algorithm():
    c = UpdaterConfig()
    assert c.gating and c.buffer_size == 10 and c.threshold == 7 and c.n_skip == 2
    assert c.min_run == 3 and c.lost_fraction == 0.8 and c.window_deg == 4.0
    assert c.max_range == 18.0 and c.cast_margin == 0.8 and c.free_fraction == 0.98
    assert c.last_check_max_area == 25.0 and c.virtual_to_measured_ratio == 1
    assert (c.gate_min_interval, c.gate_min_distance, c.gate_min_rotation_deg) == (0.3, 0.4, 45)
    assert (c.gate_fast_turn_deg_s, c.gate_recovery_time, c.gate_recovery_distance) == \
        (12.0, 1.2, 1.6)
    assert c.pairing_distance(0.2) == pytest.approx(0.15)
    assert c.pairing_distance(10.0) == pytest.approx(0.28, abs=1e-4)
    assert c.pairing_distance(30.0) == 0.30
    assert c.new_obstacle_radius(0.0) == 0.10 and c.new_obstacle_radius(5.0) == pytest.approx(0.15)
    assert c.new_obstacle_radius(10.0) == pytest.approx(0.20) and c.new_obstacle_radius(17) == 0.2
    assert c.removed_skip(1.0) == 0.15 and c.removed_skip(10.0) == pytest.approx(0.20)


def test_config_refuses_unknown_keys_with_a_suggestion(tmp_path):
    with pytest.raises(UpdaterError, match="unknown key 'treshold'.*did you mean 'threshold'"):
        UpdaterConfig.from_dict({"treshold": 5})
    with pytest.raises(UpdaterError, match="'threshold' .* exceeds 'buffer_size'"):
        UpdaterConfig.from_dict({"threshold": 11})
    with pytest.raises(UpdaterError, match="'gating' must be true or false"):
        UpdaterConfig.from_dict({"gating": "yes"})
    with pytest.raises(UpdaterError, match=r"'window_deg' must be a number in \[0, 45\]"):
        UpdaterConfig(window_deg=float("nan"))
    path = tmp_path / "u.yaml"
    path.write_text("updater:\n  gating: false\n  threshold: 6\n  max_range: 12\n")
    c = UpdaterConfig.from_yaml(path)
    assert not c.gating and c.threshold == 6 and c.max_range == 12.0
    path.write_text("lost_fractoin: 0.5\n")
    with pytest.raises(UpdaterError, match=r"u\.yaml: unknown key 'lost_fractoin'.*'lost_fr"):
        UpdaterConfig.from_yaml(path)
    with pytest.raises(Exception):
        c.threshold = 3          # frozen
    assert UpdaterConfig.from_dict(c.to_dict()) == c


# --- gating -----------------------------------------------------------------------------------
def test_gate_interval_motion_and_turns():
    g = Gate(UpdaterConfig())
    assert g.check(0.0, Pose2D(0, 0, 0), True) == ""
    g.mark_processed(0.0, Pose2D(0, 0, 0))
    assert g.check(0.1, Pose2D(0.5, 0, 0), True) == GATED_INTERVAL
    assert g.check(0.35, Pose2D(0.3, 0, 0), True) == GATED_NO_MOTION
    assert g.check(0.45, Pose2D(0.41, 0, 0), True) == ""
    g.mark_processed(0.45, Pose2D(0.41, 0, 0))
    # a slow turn of 46 deg counts as motion
    t, yaw = 0.45, 0.0
    while yaw < math.radians(46):
        t, yaw = t + 0.1, yaw + math.radians(1.0)      # 10 deg/s < 12 deg/s
        reason = g.check(t, Pose2D(0.41, 0, yaw), True)
    assert reason == ""


def test_gate_idles_after_a_fast_turn_until_time_and_distance():
    g = Gate(UpdaterConfig())
    g.check(0.0, Pose2D(0, 0, 0), True)
    g.mark_processed(0.0, Pose2D(0, 0, 0))
    assert g.check(0.1, Pose2D(0, 0, math.radians(1.5)), True) == GATED_FAST_TURN  # 15 deg/s
    x, t = 0.0, 0.1
    reasons = []
    while t < 6.0:
        t, x = t + 0.1, x + 0.1                          # 1 m/s straight on
        reasons.append((t, x, g.check(t, Pose2D(x, 0, math.radians(1.5)), True)))
    first = next((t, x) for t, x, r in reasons if r == "")
    assert first[0] >= 0.1 + 1.2 - 1e-9 and first[1] >= 1.6 - 1e-9
    assert all(r == GATED_FAST_TURN for t, x, r in reasons if t < first[0] - 1e-9)


def test_gate_without_odometry_ignores_yaw_noise_of_localised_poses():
    rng = np.random.default_rng(0)
    g = Gate(UpdaterConfig())
    processed = 0
    for k in range(200):                                 # 0.5 m/s, 10 Hz, 0.5-1 deg noise
        t = k * 0.1
        p = Pose2D(0.05 * k + rng.normal(0, 0.02), rng.normal(0, 0.02),
                   rng.normal(0, math.radians(1.0)))
        if g.check(t, p, False) == "":
            g.mark_processed(t, p)
            processed += 1
    assert not g.idle and 20 <= processed <= 26          # about every 0.4 m


def test_gate_restarts_when_time_goes_backwards():
    g = Gate(UpdaterConfig())
    g.check(5.0, Pose2D(0, 0, 0), True)
    g.mark_processed(5.0, Pose2D(0, 0, 0))
    assert g.check(1.0, Pose2D(3, 0, 0), True) == GATED_TIME_BACK
    assert g.check(1.1, Pose2D(3, 0, 0), True) == ""


# --- bad input --------------------------------------------------------------------------------
def test_bad_ranges_are_invalid_beams_and_zero_is_not_a_hit():
    walls, ref = room()
    scan = world.full_scan(walls, CENTRE, 0.0)
    bad = scan.ranges.copy()
    idx = np.array([3, 50, 51, 52, 200, 400, 401, 600])
    bad[idx] = [np.nan, np.inf, -np.inf, -1.0, 0.0, 0.0, 1e9, np.nan]
    clean = scan.ranges.copy()
    clean[idx] = np.inf
    results = []
    for ranges in (bad, clean):
        u = MapUpdater(ref, UpdaterConfig(gating=False))
        s = Scan(ranges, scan.angle_min, scan.angle_increment, 0.0, scan.range_max, 0.0)
        report = u.process(s, CENTRE)
        results.append((report, u.change_counts(), u._hist.copy()))
    (rb, _, hb), (rc, _, hc) = results
    assert (rb.verdicts[idx] == BEAM_INVALID).all() and rb.valid_beams == 720 - idx.size
    assert rb.summary() == rc.summary() and (rb.verdicts == rc.verdicts).all()
    assert (hb == hc).all()
    assert rb.detected_changes == 0 and rb.unchanged_flags > 0


def test_bad_poses_raise_or_skip_and_never_touch_the_state():
    walls, ref = room()
    u = MapUpdater(ref, UpdaterConfig(gating=False))
    scan = world.full_scan(walls, CENTRE, 0.0)
    for pose in (Pose2D(np.nan, 5, 0), Pose2D(5, np.inf, 0), Pose2D(5, 5, np.nan)):
        with pytest.raises(UpdaterError, match="sensor pose must be finite"):
            u.process(scan, pose)
    with pytest.raises(UpdaterError, match="odometry"):
        u.process(scan, CENTRE, odometry=Pose2D(0, 0, np.nan))
    with pytest.raises(UpdaterError, match="scan must be a gridmap.Scan"):
        u.process(scan.ranges, CENTRE)
    report = u.process(scan, Pose2D(-3.0, 5.0, 0.0))
    assert not report.processed and report.reason == "sensor off the map"
    assert u.stats == {"scans": 1, "processed": 0, "gated": 0, "lost": 0, "skipped": 1}
    assert not u.change_counts().any()
    assert u.process(scan, CENTRE).processed


# --- scan geometry ----------------------------------------------------------------------------
def _scan_with_phantoms(walls, fov_deg, beams, phantom):
    inc = math.radians(fov_deg) / beams
    angle_min = -math.radians(fov_deg) / 2
    angles = angle_min + inc * np.arange(beams)
    ranges = world.cast(walls, CENTRE, angles, 20.0)
    ranges[phantom] = 1.0                        # something new, 1 m away in open space
    return Scan(ranges, angle_min, inc, 0.05, 20.0, 0.0)


def test_a_270_degree_scan_does_not_wrap_its_window_or_runs():
    walls, ref = room()
    # beams 0, 1 and the last one see something new: one run of 3 only if the ends were joined
    for fov, beams, joined in ((270.0, 540, False), (360.0, 720, True)):
        u = MapUpdater(ref, UpdaterConfig(gating=False))
        report = u.process(_scan_with_phantoms(walls, fov, beams, [0, 1, beams - 1]), CENTRE)
        assert report.raw_detected_changes == 3
        assert report.detected_changes == (3 if joined else 0)
        v = report.verdicts
        if joined:
            assert v[0] == v[1] == v[-1] == BEAM_CHANGE and v[2] == v[-3] == BEAM_SKIPPED
        else:
            assert v[0] == v[1] == v[-1] == BEAM_UNCHANGED      # dropped by the run filter


def test_wrapped_window_matches_across_the_ends_of_a_full_circle():
    # The sensor is turned by 3 deg that the updater does not know of; with a box edge right at
    # the scan's start, beams 0.. need expected points from the end of the scan to match.
    walls = world.room_walls()
    box = world.Rect(7.0125, 3.5125, 7.8125, 5.5125)
    ref = world.rasterise(walls + [box])
    true = Pose2D(5.5, 5.5, math.radians(179.0))
    scan = world.full_scan(walls + [box], true, 0.0)
    told = Pose2D(5.5, 5.5, true.theta + math.radians(3.0))
    u = MapUpdater(ref, UpdaterConfig(gating=False))
    report = u.process(scan, told)
    assert (report.verdicts[:3] != BEAM_CHANGE).all()
    # the same scan one beam short of 360 deg must not wrap: its first beams disagree
    short = Scan(scan.ranges[:-1], scan.angle_min, scan.angle_increment, 0.05, 20.0, 0.0)
    report = u.process(short, told)
    assert (report.verdicts[:3] == BEAM_CHANGE).all()


def test_clockwise_scan_gives_the_same_result_as_counter_clockwise():
    walls, ref = room()
    box = world.Rect(7.0125, 5.0125, 7.6125, 5.8125)
    scan = world.full_scan(walls + [box], CENTRE, 0.0)
    n = scan.beams
    reverse = Scan(scan.ranges[::-1], scan.angle_min + (n - 1) * scan.angle_increment,
                   -scan.angle_increment, scan.range_min, scan.range_max, 0.0)
    results = []
    for s in (scan, reverse):
        u = MapUpdater(ref, UpdaterConfig(gating=False))
        for _ in range(3):
            report = u.process(s, CENTRE)
        results.append((report, u.change_counts()))
    (a, ca), (b, cb) = results
    assert a.detected_changes > 10 and (a.verdicts == b.verdicts[::-1]).all()
    assert a.summary() == b.summary() and (ca == cb).all()


def test_empty_and_single_beam_scans():
    walls, ref = room()
    u = MapUpdater(ref, UpdaterConfig(gating=False))
    empty = u.process(Scan(np.zeros(0, np.float32), 0.0, 0.01, 0.05, 20.0, 0.0), CENTRE)
    assert empty.processed and empty.valid_beams == 0 and empty.verdicts.size == 0
    one = u.process(Scan(np.array([2.0], np.float32), 0.0, 0.01, 0.05, 20.0, 0.1), CENTRE)
    assert one.valid_beams == 1 and one.dropped_as_lost      # 1 of 1 beams disagrees
    assert not u.change_counts().any()


# --- reports and inspection -------------------------------------------------------------------
def test_report_verdicts_and_counts():
    walls, ref = room()
    box = world.Rect(7.0125, 5.0125, 7.6125, 5.8125)
    u = MapUpdater(ref, UpdaterConfig(gating=False))
    for k in range(T_SCANS := 8):
        r = u.process(world.full_scan(walls + [box], CENTRE, 0.1 * k), CENTRE)
    v = r.verdicts
    assert r.processed and not r.dropped_as_lost and v.dtype == np.int8 and v.size == 720
    assert (v == BEAM_CHANGE).sum() == r.detected_changes > 10
    assert (v == BEAM_SKIPPED).sum() == 4 * len(_runs(v == BEAM_CHANGE))
    assert (v == BEAM_UNCHANGED).sum() == 720 - r.detected_changes - (v == BEAM_SKIPPED).sum()
    assert r.new_obstacle_flags > 0 and r.unchanged_flags > 1000
    counts = u.change_counts()
    assert counts.dtype == np.uint8 and counts.shape == ref.shape and counts.max() == T_SCANS
    rows, cols = u.changed_cells()
    assert r.changed_cells == rows.size == u.n_changed > 0
    assert (u.updated_map().data[rows, cols] == 100).all()
    fixed = 3 * ref.data.size + 4 * ((ref.data.size + 7) // 8)   # M, buffers, 4 bit planes
    assert fixed < u.state_bytes() < fixed + 1_000_000             # + scan-sized workspace


def _runs(mask):
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return list(zip(edges[::2], edges[1::2]))


# --- saving and resuming ----------------------------------------------------------------------
@pytest.mark.parametrize("config", [UpdaterConfig(), UpdaterConfig(
    grow_into_unknown=True, gate_min_distance=0.2, gate_min_rotation_deg=20.0,
    gate_min_interval=0.0, gate_turn_cover=True, gate_confirm=True, unanimous_min=3)],
    ids=["paper", "robot"])
def test_save_then_load_gives_identical_results(tmp_path, config):
    walls = world.room_walls()
    box = world.Rect(4.9125, 5.1125, 6.1125, 5.9125)
    ref = world.rasterise(walls, hollow=[box])
    steps = list(world.Drive(seconds=30, seed=3).steps())
    a = MapUpdater(ref, config)
    for true, noisy, t in steps[:150]:
        a.process(world.full_scan(walls, true, t), noisy, odometry=true)
    path = tmp_path / "state.npz"
    a.save(path)
    assert path.exists() and [p.name for p in tmp_path.iterdir()] == ["state.npz"]
    b = MapUpdater.load(path)
    assert b.stats == a.stats and b.n_changed == a.n_changed and b.config == a.config
    for true, noisy, t in steps[150:]:
        scan = world.full_scan(walls, true, t)
        ra, rb = a.process(scan, noisy, odometry=true), b.process(scan, noisy, odometry=true)
        assert ra.summary() == rb.summary()
        assert (ra.verdicts is None) == (rb.verdicts is None)
        if ra.verdicts is not None:
            assert (ra.verdicts == rb.verdicts).all()
    assert (a.updated_map().data == b.updated_map().data).all()
    assert (a.change_counts() == b.change_counts()).all() and a.n_changed > 0
    bad = tmp_path / "bad.npz"
    np.savez(bad, x=np.zeros(3))
    with pytest.raises(UpdaterError, match="bad.npz"):
        MapUpdater.load(bad)


def test_a_failed_save_is_an_updater_error_naming_the_file(tmp_path):
    u = MapUpdater(room()[1])
    path = tmp_path / "missing" / "state.npz"
    with pytest.raises(UpdaterError, match=r"missing/state\.npz: cannot save the updater state"):
        u.save(path)
    assert list(tmp_path.iterdir()) == []


def test_updater_imports_only_gridmap_and_numba_lazily():
    code = ("import sys, updater; assert 'numba' not in sys.modules; "
            "bad = [m for m in sys.modules if m.split('.')[0] in "
            "('sim', 'scenarios', 'localization', 'pymunk', 'rerun', 'gymnasium')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_reference_map_is_copied():
    data = np.zeros((20, 20), np.int8)
    grid = OccupancyGrid(data, 0.05)
    u = MapUpdater(grid, profile="paper")
    grid.data[3, 3] = 100
    assert u.reference_map.data[3, 3] == 0 and u.updated_map().data[3, 3] == 0
