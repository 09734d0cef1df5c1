"""Hostile files, round three: gzip bombs and endless lines in CARMEN logs, outputs that are
links into another file system, a bag folder that holds another run's bags, a log whose
scans share one stamp, a state file whose gate can never open, invalid beams against beams
that did not return, and LaserScan messages with absurd fields on their way to the updater."""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import time
import types
import zlib
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gridmap import MapUpdatingError, Pose2D, load_map, save_map
from gridmap.atomic import write_atomically
from localization.smoothing import MAX_POSES, PoseSmoother
from mapupdate import main
from mapupdate.summaries import update_lines
from onboard.pipeline import RobotPipeline
from onboard.replay import LogSource, Outputs, Placement, update_from_log
from onboard.ros_common.scans import usable_scan
from robotlogs.carmen import read_carmen
from robotlogs.records import LogError
from robotlogs.text_lines import GZIP_MIN_BYTES, MAX_LINE_BYTES, LogLimits, bounds
from updater import MapUpdater, UpdaterConfig

import synthetic_room as world
from test_reliability_hostile import refused, time_limit

ROBOT = UpdaterConfig.profile("robot")
BOX = world.Rect(5.2, 5.2, 5.8, 5.8)      # in the map, gone from the room


def flaser_lines(poses, stamps, odom=None, beams=181):
    """FLASER lines (180 deg) cast in the room without the box at ``poses`` (the laser poses),
    with ``odom`` poses (default: the laser poses, so no localisation apart) and ``stamps``."""
    walls = world.room_walls()
    odom = poses if odom is None else odom
    lines = []
    for pose, o, t in zip(poses, odom, stamps):
        scan = world.partial_scan(walls, pose, 0.0, fov_deg=180.0, beams=beams)
        r = [f"{v:.3f}" for v in np.minimum(scan.ranges, 81.83)]
        lines.append(f"FLASER {beams} {' '.join(r)} {pose.x:.6f} {pose.y:.6f} {pose.theta:.6f} "
                     f"{o.x:.6f} {o.y:.6f} {o.theta:.6f} {t:.3f} h {t:.3f}")
    return lines


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """The room's map with the box, and a short log of the robot circling it."""
    d = tmp_path_factory.mktemp("files")
    save_map(world.rasterise(world.room_walls() + [BOX]), d / "map.yaml")
    poses = [true for true, _, _ in world.Drive(seconds=10, rate=10.0).steps()]
    (d / "run.log").write_text("\n".join(flaser_lines(poses, [0.1 * k for k in range(100)]))
                               + "\n")
    return d


# --- 1. gzip bombs and endless lines -------------------------------------------------------------
def gzip_bomb(path: Path, block: bytes, copies: int) -> int:
    """``copies`` gzip members each holding ``block``: compressed once, written many times (a
    reader takes the members as one stream), so a gigabyte costs a millisecond to make.
    Returns the bytes it expands to."""
    c = zlib.compressobj(9, zlib.DEFLATED, 31)
    member = c.compress(block) + c.flush()
    with open(path, "wb") as f:
        for _ in range(copies):
            f.write(member)
    return len(block) * copies


def test_a_gzip_log_of_endless_comments_is_refused_at_the_bound_not_read_through(room,
                                                                                   tmp_path,
                                                                                   capsys):
    line = b"# " + b"x" * 4093 + b"\n"
    bomb = tmp_path / "bomb.clf.gz"
    expands = gzip_bomb(bomb, line * 256, 1024)              # 1 GB of comments in 1.4 MB
    limit = bounds(bomb, LogLimits())[1]
    assert expands == 1 << 30 and GZIP_MIN_BYTES <= limit < expands / 5
    t0 = time.perf_counter()
    with pytest.raises(LogError, match=r"bomb.clf.gz: the gzip file expands to more than "
                                       rf"{limit} bytes.*gzip bomb"):
        read_carmen(bomb)
    assert time.perf_counter() - t0 < 5         # 140 MB read, not 1 GB
    refused(["update", "--map", room / "map.yaml", "--log", bomb, "--out", tmp_path / "o.yaml",
             "--no-progress"], "mapupdate update: error:", "bomb.clf.gz", "gzip bomb",
            inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "o.yaml"])


def test_a_gzip_log_of_one_endless_line_is_refused_before_it_fills_the_memory(room, tmp_path,
                                                                               capsys):
    bomb = tmp_path / "line.clf.gz"
    assert gzip_bomb(bomb, b"0" * (1 << 20), 2048) == 2 << 30      # one 2 GB line of digits
    t0 = time.perf_counter()
    with pytest.raises(LogError, match=rf"line.clf.gz, line 1: longer than {MAX_LINE_BYTES}"):
        read_carmen(bomb)
    assert time.perf_counter() - t0 < 5
    refused(["update", "--map", room / "map.yaml", "--log", bomb, "--out", tmp_path / "o.yaml",
             "--no-progress"], "line.clf.gz, line 1: longer than", inputs=tmp_path,
            capsys=capsys, outputs=[tmp_path / "o.yaml"])


def test_a_plain_log_line_past_the_bound_is_refused_and_lines_below_it_are_read(room, tmp_path):
    lines = (room / "run.log").read_text().splitlines()
    long = tmp_path / "long.log"
    long.write_text("\n".join(lines[:3] + ["#" + " " * MAX_LINE_BYTES] + lines[3:]) + "\n")
    with pytest.raises(LogError, match=rf"long.log, line 4: longer than {MAX_LINE_BYTES}"):
        read_carmen(long)
    ok = tmp_path / "ok.log"                    # a comment just under the bound is only skipped
    ok.write_text("\n".join(lines[:3] + ["#" + " " * (MAX_LINE_BYTES - 2)] + lines[3:]) + "\n")
    assert len(read_carmen(ok, strict=True).scans()) == len(lines)


# --- 2. outputs that are links into another file system ------------------------------------------
@pytest.fixture
def shm(tmp_path):
    """A folder in /dev/shm (a tmpfs), removed afterwards; skipped where /dev/shm is missing
    or on the same file system as the test's folder."""
    if not os.path.isdir("/dev/shm") or not os.access("/dev/shm", os.W_OK):
        pytest.skip("no writable /dev/shm here")
    if os.stat("/dev/shm").st_dev == os.stat(tmp_path).st_dev:
        pytest.skip("/dev/shm is on the same file system as the test's folder")
    folder = Path(tempfile.mkdtemp(dir="/dev/shm", prefix="mapupdate-test-"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def leftovers(*folders) -> list:
    return [p for f in folders for p in Path(f).iterdir() if ".tmp" in p.name]


def test_update_writes_through_links_into_another_file_system(room, tmp_path, shm):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("o.yaml", "o.pgm", "s.npz", "t.tum"):
        os.symlink(shm / name, out / name)       # the targets do not exist yet
    assert main(["update", "--map", room / "map.yaml", "--log", room / "run.log", "--out",
                 out / "o.yaml", "--state", out / "s.npz", "--trajectory", out / "t.tum",
                 "--no-progress"]) == 0
    for name in ("o.yaml", "o.pgm", "s.npz", "t.tum"):
        assert (out / name).is_symlink() and (shm / name).is_file(), name
    assert load_map(out / "o.yaml").shape == load_map(shm / "o.yaml").shape == \
        load_map(room / "map.yaml").shape
    assert MapUpdater.load(shm / "s.npz").reference_map.shape == load_map(room / "map.yaml").shape
    assert len((shm / "t.tum").read_text().splitlines()) > 5
    assert not leftovers(out, shm)
    # and again over the files now there: replaced whole, the links kept
    assert main(["update", "--map", room / "map.yaml", "--log", room / "run.log", "--out",
                 out / "o.yaml", "--state", out / "s.npz", "--no-progress"]) == 0
    assert (out / "s.npz").is_symlink() and not leftovers(out, shm)


def test_the_atomic_writer_replaces_the_file_a_link_points_to_and_keeps_the_link(tmp_path):
    real = tmp_path / "real" / "f.txt"
    real.parent.mkdir()
    real.write_text("old")
    link = tmp_path / "link.txt"
    os.symlink(os.path.relpath(real, tmp_path), link)       # a relative link, too
    chain = tmp_path / "chain.txt"
    os.symlink(link, chain)
    write_atomically(chain, "new")
    assert link.is_symlink() and chain.is_symlink() and real.read_text() == "new"
    os.symlink(tmp_path / "real" / "g.txt", tmp_path / "dangling.txt")
    write_atomically(tmp_path / "dangling.txt", b"made")
    assert (tmp_path / "real" / "g.txt").read_bytes() == b"made"
    os.symlink("loop.txt", tmp_path / "loop.txt")
    with pytest.raises(OSError):
        write_atomically(tmp_path / "loop.txt", "x")
    assert not leftovers(tmp_path, tmp_path / "real")


def test_the_atomic_writer_through_a_link_into_another_file_system(tmp_path, shm):
    os.symlink(shm / "f.bin", tmp_path / "f.bin")
    payload = os.urandom(1 << 20)
    write_atomically(tmp_path / "f.bin", payload)
    assert (shm / "f.bin").read_bytes() == payload and (tmp_path / "f.bin").is_symlink()
    assert not leftovers(tmp_path, shm)


# --- 3. run --bag into a folder holding bags -----------------------------------------------------
def test_run_refuses_a_bag_folder_that_holds_files_before_any_work(tmp_path, capsys):
    pytest.importorskip("pymunk")
    bags = tmp_path / "bags"
    bags.mkdir()
    (bags / "W2.bag").write_bytes(b"#ROSBAG V2.0\nanother run's bag")
    refused(["run", "--quick", "--sessions", "2", "--bag", bags, "--out", tmp_path / "sim",
             "--no-progress"], "--bag", "bags", "W2.bag", "new or empty folder",
            inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "sim"])
    (tmp_path / "file").write_text("not a folder")
    refused(["run", "--quick", "--sessions", "2", "--bag", tmp_path / "file", "--out",
             tmp_path / "sim", "--no-progress"], "--bag", "is a file, not a folder",
            inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "sim"])


def test_a_resumed_run_keeps_its_bag_folder_and_a_new_folder_is_made(tmp_path):
    pytest.importorskip("pymunk")
    from scenarios.session_bags import check_bag_folder
    (tmp_path / "W2.bag").write_bytes(b"#ROSBAG V2.0\nthis run's finished bag")
    check_bag_folder(tmp_path, resume=True)
    check_bag_folder(tmp_path / "new")
    (tmp_path / "empty").mkdir()
    check_bag_folder(tmp_path / "empty")


# --- 4. a log whose scans share one stamp --------------------------------------------------------
def test_a_log_of_3000_scans_at_one_stamp_updates_in_bounded_time(room, tmp_path):
    drive = list(world.Drive(seconds=300, rate=10.0).steps())
    odom0 = Pose2D(1.0, -2.0, 0.4)        # the odometry's frame apart from the map's: smoothed
    lines = flaser_lines([noisy for _, noisy, _ in drive], [5.0] * len(drive),
                         odom=[odom0.compose(true) for true, _, _ in drive], beams=61)
    (tmp_path / "equal.log").write_text("\n".join(lines) + "\n")
    t0 = time.perf_counter()
    with time_limit(120):
        s = update_from_log(room / "map.yaml", LogSource(tmp_path / "equal.log"),
                            Outputs(tmp_path / "o.yaml"))
    took = time.perf_counter() - t0
    assert took < 60, took
    assert s["timestamps"]["same_as_before"] == 2999 and s["scans"] == 3000
    assert any(line.startswith("  warning: 2999 of 3000 scans have the same timestamp as the "
                               "scan before") for line in update_lines(s))
    assert s["smoothing"]["window_s"] > 0 and s["scans_processed"] > 100


def test_the_pose_smoother_keeps_a_bounded_window_when_the_stamps_do_not_advance():
    smoother = PoseSmoother(2.0)
    odom0 = Pose2D(1.0, -2.0, 0.4)
    times = []
    for true, noisy, _ in world.Drive(seconds=40, rate=10.0).steps():
        t0 = time.perf_counter()
        pose = smoother(5.0, noisy, odom0.compose(true))
        times.append(time.perf_counter() - t0)
        assert pose.is_finite() and len(smoother._past) <= MAX_POSES
    assert len(smoother._past) == MAX_POSES and smoother.smoothed > 0
    # once full, each scan costs what a full window costs: no growth with the log's length
    assert np.median(times[-50:]) < 3 * np.median(times[MAX_POSES - 50:MAX_POSES]) + 1e-3


# --- 5. a state whose gate can never open --------------------------------------------------------
@pytest.fixture(scope="module")
def state(room, tmp_path_factory):
    d = tmp_path_factory.mktemp("state")
    assert main(["update", "--map", room / "map.yaml", "--log", room / "run.log", "--out",
                 d / "o.yaml", "--state", d / "s.npz", "--no-progress"]) == 0
    return d / "s.npz"


def edited_state(state: Path, path: Path, edit) -> Path:
    with np.load(state) as z:
        arrays = dict(z)
    meta = json.loads(str(arrays["meta"]))
    edit(meta)
    arrays["meta"] = np.array(json.dumps(meta))      # JSON writes Infinity and NaN as such
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


@pytest.mark.parametrize("key, value, words", [
    ("proc_t", math.inf, ("proc_t must be a finite number", "inf")),
    ("last_t", -math.inf, ("last_t must be a finite number", "-inf")),
    ("proc_t", math.nan, ("processed scan is part NaN", "proc_t=nan")),
    ("idle_t", math.inf, ("idle_t must be a finite number",)),
    ("travel", math.nan, ("travel must be a finite number",)),
    ("turn_views", [1] * 35 + [-1], ("turn_views must be 36 whole numbers >= 0",)),
    ("turn_views", [1.5] * 36, ("turn_views must be 36 whole numbers >= 0",)),
    ("idle", "yes", ("idle 'yes'",)),
])
def test_a_state_whose_gate_is_not_finite_is_refused_in_one_line(room, state, tmp_path, capsys,
                                                                 key, value, words):
    bad = edited_state(state, tmp_path / "bad.npz", lambda m: m["gate"].update({key: value}))
    refused(["update", "--map", room / "map.yaml", "--log", room / "run.log", "--out",
             tmp_path / "o.yaml", "--state", bad, "--no-progress"], "mapupdate update: error:",
            "bad.npz", *words, inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "o.yaml"])


def test_a_state_with_counts_that_are_not_whole_numbers_is_refused(state, tmp_path):
    for value in (math.inf, math.nan, -1, 2.5):
        bad = edited_state(state, tmp_path / "c.npz", lambda m: m["counts"].update(scans=value))
        with pytest.raises(MapUpdatingError, match=r"c.npz: the saved scan count scans must be "
                                                   r"a whole number >= 0"):
            MapUpdater.load(bad)
    # a gate that saw no scan yet saves NaN times, and a state saved so loads and processes
    fresh = MapUpdater(load_map(Path(state).parent / "o.yaml"))
    fresh.save(tmp_path / "fresh.npz")
    scan, pose = step_scan()
    assert MapUpdater.load(tmp_path / "fresh.npz").process(scan, pose).processed


def step_scan():
    pose = Pose2D(5.5, 2.5, 0.0)
    return world.full_scan(world.room_walls(), pose, 1e6), pose


# --- 6. an invalid beam is a beam that did not return --------------------------------------------
def spoilt(lines, every, word):
    """``lines`` with beams 10, 60, 100 and 150 of every ``every``-th line set to ``word``."""
    out = []
    for k, line in enumerate(lines):
        w = line.split()
        if k % every == 1:
            for b in (10, 60, 100, 150):
                w[2 + b] = word
        out.append(" ".join(w))
    return out


@pytest.mark.parametrize("pose_check", [False, True])
def test_nan_or_negative_readings_give_the_map_of_readings_that_did_not_return(room, tmp_path,
                                                                               pose_check):
    clean = (room / "run.log").read_text().splitlines()
    maps = {}
    for name, word in (("clean", None), ("nan", "nan"), ("negative", "-2.5"),
                       ("no return", "81.83")):
        lines = clean if word is None else spoilt(clean, 2, word)
        log = tmp_path / f"{name}.log"
        log.write_text("\n".join(lines) + "\n")
        update_from_log(room / "map.yaml", LogSource(log), Outputs(tmp_path / f"{name}.yaml"),
                        Placement(pose_check=pose_check))
        maps[name] = load_map(tmp_path / f"{name}.yaml").data
    np.testing.assert_array_equal(maps["nan"], maps["no return"])
    np.testing.assert_array_equal(maps["negative"], maps["no return"])


# --- 7. LaserScan messages with absurd fields ----------------------------------------------------
HOSTILE_FLOATS = st.sampled_from([0.0, 1e-300, -1e-300, 1e-38, 1e-12, -1e-12, 1e-3, 0.01,
                                  math.pi / 180, 1.0, -1.0, math.pi, 7.0, 1e300, -1e300,
                                  math.nan, math.inf, -math.inf])
HOSTILE_RANGES = st.sampled_from([0.0, 0.3, 2.0, 9.5, 30.0, 1e300, -1.0, -math.inf, math.inf,
                                  math.nan, 1e-38])


def sometimes(draw, hostile, sane):
    """A hostile value one time in three, else a sane one: most messages reach the updater."""
    return draw(hostile) if draw(st.integers(0, 2)) == 0 else draw(sane)


@st.composite
def laser_scans(draw):
    n = draw(st.integers(0, 2000))
    angle_min = sometimes(draw, HOSTILE_FLOATS, st.floats(-4.0, 4.0))
    increment = draw(st.one_of(HOSTILE_FLOATS, st.floats(-0.1, 0.1)))
    with np.errstate(all="ignore"):
        as_driver = angle_min + (n - 1) * increment      # what a driver writes
    angle_max = sometimes(draw, st.one_of(HOSTILE_FLOATS, st.floats(-7.0, 7.0)),
                          st.just(as_driver))
    fill = draw(st.sampled_from(["room", "one value", "mixed"]))
    if fill == "one value":
        ranges = np.full(n, draw(HOSTILE_RANGES))
    else:
        ranges = np.linspace(0.5, 6.0, n)
        if fill == "mixed" and n:
            idx = draw(st.lists(st.integers(0, n - 1), max_size=20))
            ranges[idx] = [draw(HOSTILE_RANGES) for _ in idx]
    header = types.SimpleNamespace(stamp=types.SimpleNamespace(sec=draw(st.integers(0, 2**31)),
                                                               nanosec=0), frame_id="laser")
    return types.SimpleNamespace(header=header, angle_min=angle_min, angle_max=angle_max,
                                 angle_increment=increment, time_increment=0.0, scan_time=0.0,
                                 range_min=sometimes(draw, HOSTILE_FLOATS, st.just(0.05)),
                                 range_max=sometimes(draw, HOSTILE_FLOATS, st.just(10.0)),
                                 ranges=ranges.tolist(), intensities=[])


@pytest.fixture(scope="module")
def node_updaters():
    """What a node holds (the paper's updater with the robot's defaults on the room, behind
    the pose check), and the same updater without its gate, which processes every scan it is
    given; warmed up so that no example pays for compiling the kernels."""
    from localization.confidence import PoseCheck
    grid = world.rasterise(world.room_walls() + [BOX])
    pipeline = RobotPipeline(MapUpdater(grid, ROBOT), pose_check=PoseCheck(grid))
    ungated = MapUpdater(grid, UpdaterConfig.profile("robot", {"gating": False}))
    scan, pose = step_scan()
    pipeline.step(scan, Pose2D(0.0, 0.0, 0.0), odometry=pose, pose=pose)
    ungated.process(scan, pose)
    return pipeline, ungated


@settings(max_examples=120, derandomize=True, database=None, deadline=timedelta(seconds=3),
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                 HealthCheck.data_too_large])
@given(laser_scans(), st.floats(-0.5, 0.5))
def test_hostile_laser_scans_are_skipped_or_processed_never_crash(node_updaters, msg, turn):
    rec, skip = usable_scan(msg, "/scan")
    if skip is not None:
        why, detail = skip
        assert rec is None and why in ("malformed scan", "empty scan", "scan stamped 0",
                                       "scan spanning more than one turn"), skip
        assert why != "scan stamped 0" or msg.header.stamp.sec == 0, skip
        return
    assert rec.scan.beams == len(msg.ranges) > 0
    pipeline, ungated = node_updaters
    pose = Pose2D(5.5, 3.0, turn)
    try:                        # the project's own errors only: a node counts them, goes on
        pipeline.step(rec.scan, Pose2D(0.0, 0.0, 0.0), odometry=pose, pose=pose)
    except MapUpdatingError:
        pass
    try:
        report = ungated.process(rec.scan, pose)
    except MapUpdatingError:
        return
    assert report.processed or report.reason, report


def test_an_angle_increment_a_laserscan_cannot_hold_is_refused_by_the_readers(room, tmp_path,
                                                                               capsys):
    # below float32's smallest the updater's angular window came out infinite (OverflowError)
    line = ("ROBOTLASER1 0 0.0 0.0 {inc} 20.0 0.01 0 1 2.0 0 5.0 5.0 0.0 5.0 5.0 0.0 "
            "0 0 0 0 0 {t}.0 h 0")
    log = tmp_path / "tiny.log"
    log.write_text("\n".join(line.format(inc="5e-324", t=k) for k in range(5)) + "\n")
    refused(["update", "--map", room / "map.yaml", "--log", log, "--out", tmp_path / "o.yaml",
             "--no-progress"], "tiny.log, line 1: ROBOTLASER1: angle_increment 4.94066e-324 "
            "rad is below", inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "o.yaml"])
    msg = types.SimpleNamespace(
        header=types.SimpleNamespace(stamp=types.SimpleNamespace(sec=1, nanosec=0),
                                     frame_id="laser"),
        angle_min=0.0, angle_max=0.0, angle_increment=5e-324, range_min=0.0, range_max=10.0,
        ranges=[0.5], intensities=[])
    rec, (why, detail) = usable_scan(msg, "/scan")
    assert rec is None and why == "malformed scan" and "float32" in str(detail)
    msg.angle_increment = 1e-12           # tiny, but a float32 holds it: processed
    rec, skip = usable_scan(msg, "/scan")
    assert skip is None and rec.scan.angle_increment == 1e-12
