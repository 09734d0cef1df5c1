"""Bad input the other test files leave out: each is a clear error naming the file or value, or
a counted skip, and none changes a map. (Already covered elsewhere: malformed map_server keys,
PGM headers and truncated pixels in test_gridmap_map_io.py; NaN/inf/negative/zero ranges, bad
poses and a sensor off the map in test_updater_api.py; malformed CARMEN lines and undecodable
bag messages in test_logs_*.py; unknown keys and overlapping objects in test_sim_scenario.py.)"""

from __future__ import annotations

import copy
import math
import os

import numpy as np
import pytest
import yaml

import sim
from gridmap import GridError, MapFileError, OccupancyGrid, Pose2D, Scan, load_map, save_map
from gridmap import map_io
from gridmap.mapping import LogOddsMapper
from localization import MonteCarloLocalizer
from localization.confidence import PoseCheck
from robotlogs.carmen import parse_carmen
from robotlogs.records import LogError, OdomRecord, ReadStats, ScanRecord, TransformRecord
from mapupdate import main
from mapupdate.summaries import update_lines as summary_lines
from onboard.replay import LogSource, Outputs, update_from_log
from robotlogs.rosbag import BagWriter, read_bag, write_bag
from updater import MapUpdater, ScanStatus, UpdaterConfig, UpdaterError
from updater.gating import GATED_INTERVAL, GATED_TIME_BACK

import test_sim_scenario as scenario_tests
import synthetic_room as world

CENTRE = Pose2D(5.5, 5.5, 0.3)
BAD = {"nan": np.nan, "-inf": -np.inf, "negative": -1.0, "beyond range": 1e9}


def room():
    walls = world.room_walls()
    return walls, world.rasterise(walls)


def no_temporary_files(folder) -> bool:
    return not [p for p in os.listdir(folder) if p.endswith(".tmp") or ".tmp." in p]


# --- map files -----------------------------------------------------------------------------------
GOOD_YAML = ("image: m.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
             "occupied_thresh: 0.65\nfree_thresh: 0.196\n")


@pytest.mark.parametrize("yaml_text, image, image_bytes, words", [
    ("", "m.pgm", b"P5\n1 1\n255\n\x00", ("expected a mapping",)),
    (b"\xff\xfe\x00\x01", "m.pgm", b"P5\n1 1\n255\n\x00", ("map file is a binary file",)),
    ("!!python/object/apply:os.system ['true']\n", "m.pgm", b"", ("not valid YAML",)),
    (GOOD_YAML, "m.pgm", b"", ("bad PGM header", "magic")),
    (GOOD_YAML, "m.pgm", b"P2\n2 1\n255\n0 99999999999999999999999\n", ("outside 0..255",)),
    (GOOD_YAML, "m.pgm", b"P5\n99999 99999\n255\n\x00", ("99999 x 99999 pixels",
                                                           "more than the 64000000 cells")),
    (GOOD_YAML, "m.pgm", b"P5\n4000 4000\n255\n\x00", ("truncated pixel data",)),
    (GOOD_YAML.replace("m.pgm", "m.png"), "m.png", b"\x89PNG\r\n\x1a\n\x00\x00",
     ("m.png", "cannot read image")),
    (GOOD_YAML.replace("m.pgm", "folder"), "folder", None, ("folder", "image file is a folder")),
    (GOOD_YAML.replace("0.05", ".nan"), "m.pgm", b"P5\n1 1\n255\n\x00",
     ("resolution", "finite")),
])
def test_hostile_map_files_are_one_line_errors_naming_the_file(tmp_path, yaml_text, image,
                                                               image_bytes, words):
    path = tmp_path / "m.yaml"
    if isinstance(yaml_text, bytes):
        path.write_bytes(yaml_text)
    else:
        path.write_text(yaml_text)
    if image_bytes is None:
        (tmp_path / image).mkdir()
    else:
        (tmp_path / image).write_bytes(image_bytes)
    with pytest.raises(MapFileError) as e:
        load_map(path)
    msg = str(e.value)
    assert str(tmp_path) in msg and "\n" not in msg
    for w in words:
        assert w in msg, msg


def test_a_save_that_fails_or_is_interrupted_leaves_the_previous_map(tmp_path, monkeypatch):
    old = OccupancyGrid(np.zeros((30, 40), np.int8), 0.05, (1.0, -2.0))
    old.data[3:6, 4:9] = 100
    new = OccupancyGrid(np.full((60, 20), -1, np.int8), 0.1)
    save_map(old, tmp_path / "m.yaml")
    before = {p: p.read_bytes() for p in tmp_path.iterdir()}

    class Killed(BaseException):
        pass

    for failure, raised in ((OSError(28, "No space left on device"), MapFileError),
                            (Killed(), Killed)):
        def fail(fd, failure=failure):
            raise failure
        monkeypatch.setattr(map_io.os, "fsync", fail)
        with pytest.raises(raised):
            save_map(new, tmp_path / "m.yaml")
        monkeypatch.undo()
        assert {p: p.read_bytes() for p in tmp_path.iterdir()} == before
        back = load_map(tmp_path / "m.yaml")
        assert (back.data == old.data).all() and back.origin == old.origin
    # a map server running as another user must be able to read what we write
    assert all(p.stat().st_mode & 0o044 == 0o044 for p in tmp_path.iterdir())


def test_truncated_or_foreign_updater_state_is_an_updater_error(tmp_path):
    walls, ref = room()
    u = MapUpdater(ref, profile="paper")
    u.process(world.full_scan(walls, CENTRE, 0.0), CENTRE)
    u.save(tmp_path / "s.npz")
    raw = (tmp_path / "s.npz").read_bytes()
    for name, content in (("half", raw[:len(raw) // 2]), ("empty", b""),
                          ("zip", b"PK\x03\x04junk"), ("text", b"not a state")):
        (tmp_path / f"{name}.npz").write_bytes(content)
        with pytest.raises(UpdaterError, match=f"{name}.npz: not a readable updater state"):
            MapUpdater.load(tmp_path / f"{name}.npz")
    meta_only = tmp_path / "meta.npz"
    np.savez(meta_only, meta=np.array('{"format": 1}'), reference=ref.data, hist=u._hist)
    with pytest.raises(UpdaterError, match="meta.npz: state lacks config"):
        MapUpdater.load(meta_only)


def test_an_interrupted_state_save_leaves_the_previous_state(tmp_path, monkeypatch):
    walls, ref = room()
    u = MapUpdater(ref, UpdaterConfig(gating=False))
    u.save(tmp_path / "s.npz")
    before = (tmp_path / "s.npz").read_bytes()
    for k in range(3):
        u.process(world.full_scan(walls + [world.Rect(7.0, 5.0, 7.6, 5.8)], CENTRE, k), CENTRE)

    def killed(fd):
        raise KeyboardInterrupt
    monkeypatch.setattr(os, "fsync", killed)
    with pytest.raises(KeyboardInterrupt):
        u.save(tmp_path / "s.npz")
    assert (tmp_path / "s.npz").read_bytes() == before and no_temporary_files(tmp_path)
    assert not MapUpdater.load(tmp_path / "s.npz").change_counts().any()


# --- ranges ------------------------------------------------------------------------------------
def test_localiser_treats_bad_ranges_like_missing_returns():
    walls, ref = room()
    scan = world.full_scan(walls, CENTRE, 0.0)
    idx = np.arange(0, 720, 36)[:len(BAD) * 4]         # beams the 60-beam model does use
    weights = []
    for values in (np.full(idx.size, np.inf), np.resize(list(BAD.values()), idx.size)):
        ranges = scan.ranges.copy()
        ranges[idx] = values
        loc = MonteCarloLocalizer(ref, seed=3, profile="paper")
        loc.initialize(CENTRE, np.diag([0.02, 0.02, 0.01]))
        s = Scan(ranges, scan.angle_min, scan.angle_increment, 0.05, 20.0, 0.0)
        loc.update(Pose2D(0, 0, 0), s, Pose2D(0, 0, 0))
        assert loc.update(Pose2D(0.3, 0, 0), s, Pose2D(0, 0, 0))
        weights.append((loc.particles, loc.weights, loc.estimate().pose))
    (pa, wa, ea), (pb, wb, eb) = weights
    assert (pa == pb).all() and (wa == wb).all() and ea == eb and ea.is_finite()


def test_mapping_and_pose_check_ignore_bad_ranges():
    walls, ref = room()
    scan = world.full_scan(walls, CENTRE, 0.0)
    idx = np.arange(5, 720, 40)
    results = []
    for values in (np.full(idx.size, np.nan), np.resize(list(BAD.values())[1:3], idx.size)):
        ranges = scan.ranges.copy()
        ranges[idx] = values               # nan and anything below range_min say nothing
        s = Scan(ranges, scan.angle_min, scan.angle_increment, 0.05, 20.0, 0.0)
        mapper = LogOddsMapper(ref)
        mapper.add_scan(s, CENTRE)
        fit = PoseCheck(ref).fit(s, CENTRE, Pose2D(0, 0, 0))
        results.append((mapper.logodds.copy(), fit))
    (la, fa), (lb, fb) = results
    assert (la == lb).all() and np.isfinite(la).all()
    assert fa == fb and fa.gain < 0.005 and fa.fit < 0.05     # the true pose fits


# --- a beam count that does not fit the angles ----------------------------------------------------
ROBOTLASER = ("ROBOTLASER1 0 -1.5 {fov} 0.5 20.0 0.01 0 7 1 2 3 20 5 6 7 0 "
              "1.3 2.0 0.0 1.0 2.0 0.0 0.1 0.0 0.5 0.3 0.0 11.0 host 11.1")


@pytest.mark.parametrize("fov, fits", [(3.0, True), (3.5, True), (2.5, True), (6.0, False),
                                       (1.0, False)])
def test_carmen_robotlaser_beams_must_fit_the_field_of_view(fov, fits):
    line = ROBOTLASER.format(fov=fov)          # 7 beams 0.5 rad apart span 3.0 rad
    log = parse_carmen([line], source="r.log")
    assert len(log.records) == (1 if fits else 0)
    if not fits:
        assert log.stats.skipped == {"wrong beam count": 1}
        with pytest.raises(LogError, match=r"r.log, line 1: ROBOTLASER1 has 7 beams 0.5 rad "
                                           r"apart, which does not fit its field of view"):
            parse_carmen([line], source="r.log", strict=True)


def _laser_scan_bag(path, angle_maxes):
    """A ROS 2 bag of LaserScans with the given angle_max each (5 beams, 0.5 rad apart)."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    T = ts.types
    with Writer(path, version=8) as w:
        conn = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
        for k, angle_max in enumerate(angle_maxes):
            hdr = T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=k + 1, nanosec=0), frame_id="laser")
            msg = T["sensor_msgs/msg/LaserScan"](
                header=hdr, angle_min=-1.0, angle_max=angle_max, angle_increment=0.5,
                time_increment=0.0, scan_time=0.0, range_min=0.1, range_max=10.0,
                ranges=np.ones(5, np.float32), intensities=np.zeros(0, np.float32))
            w.write(conn, (k + 1) * 1_000_000_000, bytes(ts.serialize_cdr(msg, conn.msgtype)))


def test_ros_scan_whose_beams_do_not_reach_angle_max_is_named_or_counted(tmp_path):
    # 5 beams from -1.0 by 0.5 end at 1.0; drivers that count one beam more or less pass
    _laser_scan_bag(tmp_path / "b", [1.0, 1.5, 0.5, 3.0, -1.0])
    stats = ReadStats()
    times = [r.time for r in read_bag(tmp_path / "b", stats=stats)]
    assert times == [1.0, 2.0, 3.0] and stats.skipped == {"bad /scan": 2}
    assert "do not reach angle_max 3 (wrong beam count)" in stats.problems[0]
    with pytest.raises(LogError, match=r"topic /scan at 4.000000000 s: .*wrong beam count"):
        list(read_bag(tmp_path / "b", strict=True))


# --- poses off the map ------------------------------------------------------------------------
def test_poses_off_the_map_crash_nothing_and_change_nothing():
    walls, ref = room()
    scan = world.full_scan(walls, CENTRE, 0.0)
    far = Pose2D(-40.0, 60.0, 1.0)
    loc = MonteCarloLocalizer(ref, seed=1, profile="paper")
    loc.initialize(far, np.diag([0.01, 0.01, 0.01]))
    loc.update(Pose2D(0, 0, 0), scan, Pose2D(0, 0, 0))
    assert loc.update(Pose2D(0.5, 0, 0), scan, Pose2D(0, 0, 0))
    assert loc.estimate().pose.is_finite() and np.isfinite(loc.weights).all()
    mapper = LogOddsMapper(ref)
    mapper.add_scan(scan, far)                  # every beam misses the grid
    assert not mapper.logodds.any()
    assert PoseCheck(ref).check(scan, far, Pose2D(0, 0, 0)) == ""   # nothing to fit: no verdict
    u = MapUpdater(ref, profile="paper")
    assert u.process(scan, far).reason == "sensor off the map"
    assert u.stats["skipped"] == 1 and not u.change_counts().any()


def test_replay_with_every_pose_off_the_map_skips_and_keeps_the_map(tmp_path):
    walls, ref = room()
    save_map(ref, tmp_path / "m.yaml")
    lines = []
    for k in range(20):
        r = " ".join(["3.0"] * 180)
        lines.append(f"FLASER 180 {r} 90.0 90.0 0.0 90.0 90.0 0.0 {k * 0.5:.1f} h 0")
    (tmp_path / "far.log").write_text("\n".join(lines) + "\n")
    s = update_from_log(tmp_path / "m.yaml", LogSource(tmp_path / "far.log"),
                        Outputs(tmp_path / "out.yaml"))
    assert s["scans_used"] == 20 and s["scans_processed"] == 0
    assert s["cells_freed"] == s["cells_occupied"] == 0
    assert (load_map(tmp_path / "out.yaml").data == ref.data).all()


@pytest.mark.parametrize("increment", [1e-12, 1e-38, 1e-300, 5e-324])
def test_a_tiny_angle_increment_is_processed_in_bounded_time(increment):
    import time

    grid = OccupancyGrid.empty(100, 100, 0.05)
    updater = MapUpdater(grid, UpdaterConfig(gating=False))
    scan = Scan(np.full(100, 2.0, np.float32), 0.0, increment, 0.05, 20.0, 1.0)
    t0 = time.perf_counter()
    report = updater.process(scan, Pose2D(2.5, 2.5, 0.0))
    assert report.status is ScanStatus.PROCESSED       # the window clamped to the scan
    assert time.perf_counter() - t0 < 5.0              # (1e11 beams searched, unclamped)


def test_a_log_with_no_usable_scan_is_an_error_and_writes_nothing(tmp_path, capsys):
    _, ref = room()
    save_map(ref, tmp_path / "m.yaml")
    bad = [f"FLASER 180 {' '.join(['3.0'] * 90)} 90.0 90.0 0.0 90.0 90.0 0.0 {k:.1f} h 0"
           for k in range(10)]                  # 90 readings where 180 are announced
    (tmp_path / "bad.log").write_text("\n".join(bad) + "\n")
    assert main(["update", "--map", str(tmp_path / "m.yaml"), "--log",
                 str(tmp_path / "bad.log"), "--out", str(tmp_path / "out.yaml"),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mapupdate update: error:") and "\n" not in err
    assert "no usable" in err and "FLASER declares 180 ranges" in err
    assert not (tmp_path / "out.yaml").exists() and not (tmp_path / "out.pgm").exists()


def test_no_scan_in_the_time_window_is_an_error_not_an_unchanged_map(tmp_path):
    _, ref = room()
    save_map(ref, tmp_path / "m.yaml")
    lines = [f"FLASER 180 {' '.join(['3.0'] * 180)} 5.0 5.0 0.0 5.0 5.0 0.0 {k * 0.5:.1f} h 0"
             for k in range(10)]
    (tmp_path / "ok.log").write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError, match=r"no usable scan \(10 read, none in the time window"):
        update_from_log(tmp_path / "m.yaml", LogSource(tmp_path / "ok.log", start_time=100.0),
                        Outputs(tmp_path / "out.yaml"))
    assert not (tmp_path / "out.yaml").exists()


# --- time going backwards or repeating ------------------------------------------------------
def test_updater_gates_a_repeated_or_earlier_scan_and_it_changes_nothing():
    walls, ref = room()
    box = world.Rect(7.0125, 5.0125, 7.6125, 5.8125)
    u = MapUpdater(ref, profile="paper")
    odom = Pose2D(0, 0, 0)
    first = world.full_scan(walls + [box], CENTRE, 10.0)
    assert u.process(first, CENTRE, odometry=odom).processed
    counts = u.change_counts().copy()
    moved = Pose2D(1.0, 0, 0)                       # far enough to pass the motion gate
    again = world.full_scan(walls + [box], CENTRE, 10.0)
    assert u.process(again, CENTRE, odometry=moved).reason == GATED_INTERVAL
    earlier = world.full_scan(walls + [box], CENTRE, 4.0)
    assert u.process(earlier, CENTRE, odometry=moved).reason == GATED_TIME_BACK
    assert (u.change_counts() == counts).all()
    assert u.stats == {"scans": 3, "processed": 1, "gated": 2, "lost": 0, "skipped": 0}
    # the gate restarts from the earlier time: the clock may have been reset
    later = world.full_scan(walls + [box], CENTRE, 4.1)
    assert u.process(later, CENTRE, odometry=Pose2D(2.0, 0, 0)).processed


def test_localiser_ignores_a_repeated_odometry_pose():
    walls, ref = room()
    scan = world.full_scan(walls, CENTRE, 0.0)
    loc = MonteCarloLocalizer(ref, seed=5, profile="paper")
    loc.initialize(CENTRE, np.diag([0.01, 0.01, 0.005]))
    odom = Pose2D(1.0, 2.0, 0.1)
    assert not loc.update(odom, scan, Pose2D(0, 0, 0))      # first call: odometry only
    p, w = loc.particles, loc.weights
    for _ in range(3):                                      # the same message again
        assert not loc.update(odom, scan, Pose2D(0, 0, 0))
    assert (loc.particles == p).all() and (loc.weights == w).all()


def test_carmen_lines_out_of_time_order_replay_as_if_sorted(tmp_path):
    walls, ref = room()
    save_map(ref, tmp_path / "m.yaml")
    lines = []
    for k in range(30):
        pose = Pose2D(2.0 + 0.2 * k, 5.0, 0.0)
        scan = world.partial_scan(walls, pose, 0.0, fov_deg=180.0, beams=181)
        r = " ".join(f"{v:.3f}" for v in np.minimum(scan.ranges, 81.83))
        lines.append(f"ROBOTLASER1 0 {-math.pi / 2:.6f} {math.pi:.6f} {math.pi / 180:.8f} 81.83 "
                     f"0.01 0 181 {r} 0 {pose.x} {pose.y} 0.0 {pose.x} {pose.y} 0.0 "
                     f"0 0 0 0 0 {k * 0.5:.1f} h 0")
    shuffled = [lines[i] for i in np.random.default_rng(0).permutation(len(lines))]
    maps = []
    for name, content in (("sorted", lines), ("shuffled", shuffled + lines[:3])):
        (tmp_path / f"{name}.log").write_text("\n".join(content) + "\n")
        s = update_from_log(tmp_path / "m.yaml", LogSource(tmp_path / f"{name}.log"),
                            Outputs(tmp_path / f"{name}.yaml"))
        maps.append((load_map(tmp_path / f"{name}.yaml").data, s))
    (a, sa), (b, sb) = maps
    # the repeated lines are gated (same time), so the maps agree cell for cell
    assert (a == b).all() and sa["scans_processed"] == sb["scans_processed"] > 5


def test_bag_with_header_stamps_going_back_replays_and_says_so(tmp_path, monkeypatch):
    """A bag is stored in receive order; here the sender's clock jumps back mid-way, so the
    header stamps (what the replay uses) go backwards while the bag's own times go on. The
    replay times the scan after the jump from scan order (the median interval after the one
    before) and the scans after it keep their intervals, so the gate goes on as before. Poses
    are looked up at the stamps, which here stand for two moments 3 m apart: the summary warns
    of it. With the authors' gate and threshold the 12 scans change nothing; with `update`'s
    defaults (3 views may change a cell) such misplaced scans do, so this test gives the
    authors' rules."""
    walls, ref = room()
    save_map(ref, tmp_path / "m.yaml")
    received = {"t": 0.0}
    put = BagWriter._put

    def put_in_receive_order(self, topic, msgtype, time, msg, latched=False):
        received["t"] += 0.01
        return put(self, topic, msgtype, received["t"], msg, latched)
    monkeypatch.setattr(BagWriter, "_put", put_in_receive_order)
    recs = [TransformRecord(0.0, "base_link", "laser", Pose2D(0, 0, 0), static=True)]
    for k in range(12):
        t = 1.0 + 0.5 * k - (3.0 if k >= 6 else 0.0)     # 3.5 then 1.0: back 2.5 s
        pose = Pose2D(2.0 + 0.5 * k, 5.0, 0.0)
        recs.append(OdomRecord(t, pose))
        recs.append(TransformRecord(t, "map", "odom", Pose2D(0, 0, 0)))
        recs.append(ScanRecord(t, world.full_scan(walls, pose, t)))
    write_bag(tmp_path / "b.bag", recs, "ros1")
    monkeypatch.undo()
    scans = [r.time for r in read_bag(tmp_path / "b.bag", kinds=("scan",))]
    assert scans[5:7] == [3.5, 1.0]
    s = update_from_log(tmp_path / "m.yaml", LogSource(tmp_path / "b.bag"),
                        Outputs(tmp_path / "out.yaml"),
                        updater_config=UpdaterConfig(grow_into_unknown=True))
    assert s["scans"] == s["scans_used"] == s["scans_processed"] == 12
    assert s["cells_freed"] == s["cells_occupied"] == 0
    assert s["timestamps"] == {"scans": 12, "same_as_before": 0, "earlier_than_before": 1,
                               "period_s": 0.5, "period_measured": True}
    lines = "\n".join(summary_lines(s))
    assert "1 of 12 scans have an earlier timestamp than the scan before" in lines
    assert "the bag's clock went back" in lines


# --- scenario files ------------------------------------------------------------------------------
@pytest.mark.parametrize("edit, words", [
    (lambda d: d["sessions"][0]["route"].append([7.0, 1.0]),
     ("sessions[0].route[2]", "waypoint [7.0, 1.0]", "does not fit inside the walls")),
    (lambda d: d["sessions"][1]["route"].append([0.2, 2.0]),   # closer than its radius
     ("sessions[1].route[1]", "the robot (radius 0.35 m)")),
    (lambda d: d["sessions"][1]["people"][0].update(route=[[1.0, 1.5], [1.0, -2.0]]),
     ("sessions[1].people[0].route[1]", "a person", "walls")),
])
def test_routes_the_walker_cannot_reach_are_refused(edit, words):
    data = copy.deepcopy(scenario_tests.BASE)
    edit(data)
    with pytest.raises(sim.ScenarioError) as e:
        sim.scenario_from_dict(data, "test.yaml")
    for w in words:
        assert w in str(e.value), str(e.value)


def test_unknown_keys_name_the_file_and_the_nearest_key(tmp_path):
    data = copy.deepcopy(scenario_tests.BASE)
    data["sessions"][1]["people"][1]["wnader"] = data["sessions"][1]["people"][1].pop("wander")
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(sim.ScenarioError, match=r"s.yaml: sessions\[1\].people\[1\].wnader: "
                                                r"unknown key 'wnader' \(did you mean 'wander'"):
        sim.load_scenario(path)


def test_errors_are_grid_errors_where_documented():
    assert issubclass(MapFileError, GridError)
