"""update_from_log on recordings of a small synthetic room: a bag (ROS 1 and ROS 2) or a CARMEN
log replayed with each pose source gives the map an in-process run gives; the state carries an
update across recordings; format detection and user errors."""

import math

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan, load_map, save_map
from gridmap.raycast import cast_rays
from robotlogs import detect_format
from robotlogs.records import LogError, OdomRecord, PoseRecord, ScanRecord, TransformRecord
from robotlogs.rosbag import write_bag
from onboard.replay import LogSource, Outputs, Placement, update_from_log
from updater import MapUpdater, UpdaterConfig

RES = 0.05
MOUNT = Pose2D(0.2, 0.0, 0.0)
REMOVED = (2.0, 2.0)   # a box in the map, gone in the recording
ADDED = (5.5, 3.6)     # a box not in the map, there in the recording
NO_GATING = UpdaterConfig(gating=False)
F32 = lambda v: float(np.float32(v))  # noqa: E731 - LaserScan keeps these as float32


def room(boxes) -> OccupancyGrid:
    """An 8 m x 6 m room (walls 0.1 m) with 0.6 m boxes; unknown outside the walls."""
    grid = OccupancyGrid.empty(180, 140, RES, origin=(-0.5, -0.5))
    rows, cols = np.mgrid[0:grid.height, 0:grid.width]
    x, y = grid.cell_to_world(rows, cols)
    inside = (x > -0.1) & (x < 8.1) & (y > -0.1) & (y < 6.1)
    cells = np.full(grid.shape, UNKNOWN, np.int8)
    cells[inside] = OCCUPIED
    cells[(x > 0) & (x < 8) & (y > 0) & (y < 6)] = FREE
    for cx, cy in boxes:
        cells[(abs(x - cx) < 0.3) & (abs(y - cy) < 0.3)] = OCCUPIED
    return grid.with_data(cells)


def route() -> list[Pose2D]:
    corners = [(1.0, 1.0), (7.0, 1.0), (7.0, 5.0), (1.0, 5.0), (1.0, 1.2)]
    poses = []
    for (x0, y0), (x1, y1) in zip(corners, corners[1:]):
        n = int(round(math.hypot(x1 - x0, y1 - y0) / 0.25))
        yaw = math.atan2(y1 - y0, x1 - x0)
        poses += [Pose2D(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n, yaw) for i in range(n)]
    return poses


def session(seed=11):
    """(time, true pose, odometry pose, scan) along the route, odometry drifting."""
    rng = np.random.default_rng(seed)
    world = room([ADDED])
    angles_min, inc, n = F32(-math.radians(135)), F32(math.radians(1.0)), 271
    out, odom = [], Pose2D(0.3, -0.2, 0.05)
    true = route()
    for k, pose in enumerate(true):
        if k:
            step = true[k - 1].inverse().compose(pose)
            odom = odom.compose(Pose2D(step.x * 1.01, step.y + rng.normal(0, 0.003),
                                       step.theta + rng.normal(0, 0.003)))
        sensor = pose.compose(MOUNT)
        ranges = cast_rays(world, sensor, angles_min + inc * np.arange(n), 9.0)
        ranges = ranges + rng.normal(0, 0.01, n)
        scan = Scan(ranges.astype(np.float32), angles_min, inc, F32(0.05), 10.0,
                    10.0 + 0.25 * k)
        out.append((scan.time, pose, odom, scan))
    return out


def bag_records(steps, *, map_odom_tf=True, amcl=True, mount_tf=True):
    recs = []
    if mount_tf:
        recs.append(TransformRecord(steps[0][0], "base_link", "laser", MOUNT, static=True))
    for t, true, odom, scan in steps:
        recs.append(OdomRecord(t, odom))
        recs.append(TransformRecord(t, "odom", "base_link", odom))
        if map_odom_tf:
            recs.append(TransformRecord(t, "map", "odom", true.compose(odom.inverse())))
        if amcl:
            recs.append(PoseRecord(t, true, covariance=np.diag([0.01, 0.01, 0.003])))
        recs.append(PoseRecord(t, true, topic="/ground_truth/pose"))
        recs.append(ScanRecord(t, scan))
    return recs


def in_process(reference, steps, config, sensor_of):
    upd = MapUpdater(reference, config)
    for t, true, odom, scan in steps:
        upd.process(scan, sensor_of(true, odom), odometry=odom)
    return upd.updated_map()


def recorded_sensor(true, odom):
    return true.compose(odom.inverse()).compose(odom).compose(MOUNT)


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    d = tmp_path_factory.mktemp("replay")
    steps = session()
    save_map(room([REMOVED]), d / "map.yaml")
    write_bag(d / "s.bag", bag_records(steps), "ros1")
    write_bag(d / "s2", bag_records(steps), "ros2")
    return d, steps


def changed_right(grid: OccupancyGrid) -> tuple[float, float]:
    """Share of the removed box's cells now free, of the added box's cells now occupied."""
    rows, cols = np.mgrid[0:grid.height, 0:grid.width]
    x, y = grid.cell_to_world(rows, cols)
    gone = (abs(x - REMOVED[0]) < 0.3) & (abs(y - REMOVED[1]) < 0.3)
    new = (abs(x - ADDED[0]) < 0.3) & (abs(y - ADDED[1]) < 0.3)
    faces = new & ~((abs(x - ADDED[0]) < 0.2) & (abs(y - ADDED[1]) < 0.2))
    return float((grid.data[gone] == FREE).mean()), float((grid.data[faces] == OCCUPIED).mean())


@pytest.mark.parametrize("bag", ["s.bag", "s2"])
def test_recorded_tf_replay_equals_in_process_run(world, bag):
    d, steps = world
    summary = update_from_log(d / "map.yaml", LogSource(d / bag), Outputs(d / f"out_{bag}.yaml"),
                              Placement(smooth_window=0.0), updater_config=NO_GATING)
    assert summary["pose_source"] == "recorded"
    assert summary["scans"] == summary["scans_used"] == summary["scans_processed"] == len(steps)
    out = load_map(d / f"out_{bag}.yaml")
    expected = in_process(room([REMOVED]), steps, NO_GATING, recorded_sensor)
    np.testing.assert_array_equal(out.data, expected.data)
    freed, added = changed_right(out)
    assert freed > 0.5 and added > 0.3
    assert summary["cells_freed"] > 0 and summary["cells_occupied"] > 0


def test_amcl_pose_without_map_odom_tf(world, tmp_path):
    d, steps = world
    write_bag(tmp_path / "a.bag", bag_records(steps, map_odom_tf=False), "ros1")
    summary = update_from_log(d / "map.yaml", LogSource(tmp_path / "a.bag"),
                              Outputs(tmp_path / "out.yaml"), Placement(smooth_window=0.0),
                              updater_config=NO_GATING)
    assert summary["pose_source"] == "recorded" and summary["scans_used"] == len(steps)
    expected = load_map(d / "out_s.bag.yaml") if (d / "out_s.bag.yaml").exists() else \
        in_process(room([REMOVED]), steps, NO_GATING, recorded_sensor)
    differ = int((load_map(tmp_path / "out.yaml").data != expected.data).sum())
    assert differ <= 2  # the same poses up to rounding in the composition


def test_amcl_pose_now_and_then_holds_until_the_next_as_amcl_s_tf_would(world, tmp_path):
    """/amcl_pose at every fourth scan, each off by up to 2 cm / 0.6 deg (a filter update),
    and no map -> odom tf: the map -> odom it gives holds until the next pose, as amcl's tf
    does, so the poses follow the odometry in between, are not taken for jitter (nothing
    smoothed) and place the scans where a bag with that tf at every scan places them."""
    d, steps = world
    rng = np.random.default_rng(8)
    held, with_tf, only_pose = None, [], []
    for k, (t, true, odom, scan) in enumerate(steps):
        common = [OdomRecord(t, odom), TransformRecord(t, "odom", "base_link", odom),
                  ScanRecord(t, scan)]
        if k % 4 == 0:
            estimate = true.compose(Pose2D(rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02),
                                           rng.uniform(-0.01, 0.01)))
            held = estimate.compose(odom.inverse())
            only_pose.append(PoseRecord(t, estimate, covariance=np.diag([0.01, 0.01, 0.003])))
        with_tf += common + [TransformRecord(t, "map", "odom", held)]
        only_pose += common
    mount = TransformRecord(steps[0][0], "base_link", "laser", MOUNT, static=True)
    write_bag(tmp_path / "tf.bag", [mount] + with_tf, "ros1")
    write_bag(tmp_path / "pose.bag", [mount] + only_pose, "ros1")
    out = {}
    for name in ("tf", "pose"):
        s = update_from_log(d / "map.yaml", LogSource(tmp_path / f"{name}.bag"),
                            Outputs(tmp_path / f"{name}.yaml"), updater_config=NO_GATING)
        assert s["pose_source"] == "recorded" and s["smoothing"]["scans_smoothed"] == 0
        out[name] = load_map(tmp_path / f"{name}.yaml").data
    assert int((out["tf"] != out["pose"]).sum()) <= 2     # rounding in the composition


def test_truth_and_localizer_sources(world, tmp_path):
    d, steps = world
    s = update_from_log(d / "map.yaml", LogSource(d / "s2"), Outputs(tmp_path / "t.yaml"),
                        Placement(source="truth"), updater_config=NO_GATING)
    assert s["pose_source"] == "truth"
    expected = in_process(room([REMOVED]), steps, NO_GATING, lambda t, o: t.compose(MOUNT))
    np.testing.assert_array_equal(load_map(tmp_path / "t.yaml").data, expected.data)

    s = update_from_log(d / "map.yaml", LogSource(d / "s.bag"), Outputs(tmp_path / "l.yaml"),
                        Placement(source="localizer", initial_pose=steps[0][1], seed=5),
                        updater_config=NO_GATING)
    assert s["pose_source"] == "localizer" and s["localizer_updates"] > 10
    # the route turns 90 deg within a scan at its corners: the filter's heading spread then
    # passes 10 deg for a moment, and those few scans are withheld (not tracking)
    assert s["scans_used"] + s["scans_not_tracking"] == len(steps)
    assert s["scans_not_tracking"] <= 5
    # Estimates a few cm and degrees off: the removed box is freed all the same, and the
    # walls stay (the added box's faces need sharper poses to collect 7 flags of 10).
    out = load_map(tmp_path / "l.yaml")
    freed, _ = changed_right(out)
    walls = room([]).data == OCCUPIED
    assert freed > 0.5 and (out.data[walls] == FREE).mean() < 0.01


def test_auto_falls_back_to_the_localizer(world, tmp_path):
    d, steps = world
    write_bag(tmp_path / "o.bag", bag_records(steps, map_odom_tf=False, amcl=False), "ros1")
    # a map the scans fit at one place only: the box the recording sees is in it (the stale
    # map's removed box would make the room nearly symmetric to them, and a global start
    # over it ambiguous, refused)
    save_map(room([ADDED]), tmp_path / "m.yaml")
    s = update_from_log(tmp_path / "m.yaml", LogSource(tmp_path / "o.bag"),
                        Outputs(tmp_path / "o.yaml"), Placement(seed=1), updater_config=NO_GATING)
    assert s["pose_source"] == "localizer"  # a global start over the map's free space
    with pytest.raises(LogError, match="no recorded localisation"):
        update_from_log(d / "map.yaml", LogSource(tmp_path / "o.bag"),
                        Outputs(tmp_path / "o2.yaml"), Placement(source="recorded"))


def test_state_continues_across_recordings(world, tmp_path):
    """(Poses as recorded: the smoothing's window starts afresh with each recording, so the
    first scans of the second would be placed a little differently from the whole run's.)"""
    d, steps = world
    cut = steps[len(steps) // 2][0]
    state = tmp_path / "state.npz"
    first = update_from_log(d / "map.yaml", LogSource(d / "s.bag", end_time=cut - 0.1),
                            Outputs(tmp_path / "a.yaml", state=state),
                            Placement(smooth_window=0.0))
    assert not first["state_loaded"] and state.exists()
    second = update_from_log(d / "map.yaml", LogSource(d / "s.bag", start_time=cut),
                             Outputs(tmp_path / "b.yaml", state=state),
                             Placement(smooth_window=0.0))
    assert second["state_loaded"]
    whole = update_from_log(d / "map.yaml", LogSource(d / "s.bag"), Outputs(tmp_path / "w.yaml"),
                            Placement(smooth_window=0.0))
    assert first["scans_used"] + second["scans_used"] == whole["scans_used"]
    np.testing.assert_array_equal(load_map(tmp_path / "b.yaml").data,
                                  load_map(tmp_path / "w.yaml").data)
    other = room([REMOVED])
    save_map(OccupancyGrid(other.data[:, :-4], RES, other.origin), tmp_path / "small.yaml")
    with pytest.raises(LogError, match="state belongs to a map of shape"):
        update_from_log(tmp_path / "small.yaml", LogSource(d / "s.bag"),
                        Outputs(tmp_path / "c.yaml", state=state))


def test_carmen_log_replay(world, tmp_path):
    """FLASER lines carry the laser pose: the replay places each scan exactly there."""
    _, steps = world
    lines = []
    for t, true, odom, scan in steps:
        sensor = true.compose(MOUNT)
        r = np.where(np.isfinite(scan.ranges), scan.ranges, 81.83)[45:225]  # 180 beams
        lines.append(f"ODOM {odom.x:.6f} {odom.y:.6f} {odom.theta:.6f} 0 0 0 {t - 0.01:.3f} h 0")
        lines.append("FLASER 180 " + " ".join(f"{v:.3f}" for v in r)
                     + f" {sensor.x:.6f} {sensor.y:.6f} {sensor.theta:.6f}"
                     f" {true.x:.6f} {true.y:.6f} {true.theta:.6f} {t:.3f} h {t:.3f}")
    log = tmp_path / "room.log"
    log.write_text("# a CARMEN log\n" + "\n".join(lines) + "\nNEFF 3\n")
    assert detect_format(log) == "carmen"
    s = update_from_log(world[0] / "map.yaml", LogSource(log), Outputs(tmp_path / "c.yaml"),
                        updater_config=NO_GATING)
    assert s["pose_source"] == "recorded" and s["scans_used"] == len(steps)
    from robotlogs.carmen import read_carmen

    upd = MapUpdater(room([REMOVED]), NO_GATING)
    for rec in read_carmen(log).scans():
        upd.process(rec.scan, rec.laser_pose, odometry=rec.odom_pose)
    np.testing.assert_array_equal(load_map(tmp_path / "c.yaml").data, upd.updated_map().data)


def test_carmen_corrected_poses_beside_raw_odometry_are_the_map_frame_poses(world, tmp_path):
    """Laser poses of a localisation (the map's frame, jittering by 1 cm / 0.5 deg) beside the
    raw odometry (its own frame, drifting): their difference is no mount, so the laser is taken
    at the robot's origin; the trajectory written is the map-frame poses, smoothed with the
    odometry, not the odometry."""
    _, steps = world
    rng = np.random.default_rng(5)
    lines, truth = [], {}
    for t, true, odom, scan in steps:
        sensor = true.compose(MOUNT)
        laser = Pose2D(sensor.x + rng.normal(0, 0.01), sensor.y + rng.normal(0, 0.01),
                       sensor.theta + rng.normal(0, math.radians(0.5)))
        r = np.where(np.isfinite(scan.ranges), scan.ranges, 81.83)[45:225]
        lines.append("FLASER 180 " + " ".join(f"{v:.3f}" for v in r)
                     + f" {laser.x:.6f} {laser.y:.6f} {laser.theta:.6f}"
                     f" {odom.x:.6f} {odom.y:.6f} {odom.theta:.6f} {t:.3f} h {t:.3f}")
        truth[round(t, 3)] = sensor
    log = tmp_path / "corrected.log"
    log.write_text("\n".join(lines) + "\n")
    s = update_from_log(world[0] / "map.yaml", LogSource(log),
                        Outputs(tmp_path / "c.yaml", trajectory=tmp_path / "c.tum"))
    assert s["pose_source"] == "recorded" and s["smoothing"]["scans_smoothed"] > 30
    rows = np.loadtxt(tmp_path / "c.tum")
    errors = [math.hypot(x - truth[round(t, 3)].x, y - truth[round(t, 3)].y)
              for t, x, y, *_ in rows]
    assert len(errors) > 40 and max(errors) < 0.05 and float(np.median(errors)) < 0.02


def test_detect_format(world, tmp_path):
    d, _ = world
    assert detect_format(d / "s.bag") == "ros1"
    assert detect_format(d / "s2") == "ros2"
    (db3,) = (d / "s2").glob("*.db3")
    assert detect_format(db3) == "ros2"
    (tmp_path / "junk.bin").write_bytes(b"\x00\x01\x02" * 100)
    with pytest.raises(LogError, match="neither a ROS bag nor a CARMEN"):
        detect_format(tmp_path / "junk.bin")
    (tmp_path / "empty_dir").mkdir()
    with pytest.raises(LogError, match="metadata.yaml"):
        detect_format(tmp_path / "empty_dir")
    with pytest.raises(FileNotFoundError):
        detect_format(tmp_path / "nothing.bag")


def test_user_errors_name_the_problem(world, tmp_path):
    d, steps = world
    with pytest.raises(LogError, match=r"no LaserScan topic '/front'.*the bag has .*/scan"):
        update_from_log(d / "map.yaml", LogSource(d / "s.bag", scan_topics=["/front"]),
                        Outputs(tmp_path / "x.yaml"))
    write_bag(tmp_path / "m.bag", bag_records(steps[:3], mount_tf=False), "ros1")
    with pytest.raises(LogError, match=r"no transform from 'base_link' to the scan frame "
                                       r"'laser'.*laser_mount"):
        update_from_log(d / "map.yaml", LogSource(tmp_path / "m.bag"),
                        Outputs(tmp_path / "x.yaml"))
    s = update_from_log(d / "map.yaml", LogSource(tmp_path / "m.bag", laser_mount=MOUNT),
                        Outputs(tmp_path / "x.yaml"))
    assert s["scans_used"] == 3
    with pytest.raises(LogError, match="pose_source must be one of"):
        update_from_log(d / "map.yaml", LogSource(d / "s.bag"), Outputs(tmp_path / "x.yaml"),
                        Placement(source="gps"))


def test_two_lidars_each_with_its_own_mount(world, tmp_path):
    """No /scan: every LaserScan topic is read, each scan placed with its own frame's mount
    (a rear lidar placed with the front mount would contradict the map everywhere)."""
    d, steps = world
    rear = Pose2D(-0.2, 0.0, math.pi)
    world_grid = room([ADDED])
    recs = [TransformRecord(steps[0][0], "base_link", "laser", MOUNT, static=True),
            TransformRecord(steps[0][0], "base_link", "rear_laser", rear, static=True)]
    for t, true, odom, scan in steps:
        ranges = cast_rays(world_grid, true.compose(rear), scan.angles(), 9.0)
        back = Scan(ranges.astype(np.float32), scan.angle_min, scan.angle_increment,
                    scan.range_min, scan.range_max, t)
        recs += [OdomRecord(t, odom), TransformRecord(t, "odom", "base_link", odom),
                 TransformRecord(t, "map", "odom", true.compose(odom.inverse())),
                 ScanRecord(t, scan, topic="/front/scan"),
                 ScanRecord(t, back, frame_id="rear_laser", topic="/rear/scan")]
    write_bag(tmp_path / "two", recs, "ros2")
    s = update_from_log(d / "map.yaml", LogSource(tmp_path / "two"),
                        Outputs(tmp_path / "two.yaml"), updater_config=NO_GATING)
    assert s["scans_used"] == 2 * len(steps) and s["scans_dropped_as_lost"] == 0
    out = load_map(tmp_path / "two.yaml")
    freed, added = changed_right(out)
    assert freed > 0.5 and added > 0.3
    assert not np.any(out.data[room([]).data == OCCUPIED] == FREE)


def test_pose_check_keeps_walls_when_the_recorded_poses_are_off(world, tmp_path):
    """A CARMEN log whose recorded laser poses are all 0.2 m and 2 deg off: without the pose
    check the replay frees wall cells; with it, the off scans are refused and no wall cell is
    freed, while the same log with right poses is replayed as before. The log's 180 deg scans
    leave the pose unconstrained along the room's long walls: there the check needs its cell
    of slack (without it, 42 of the 79 right scans are refused)."""
    from localization.confidence import PoseCheckConfig

    _, steps = world
    walls = room([]).data == OCCUPIED

    def log_with(offset: Pose2D, name: str):
        lines = []
        for t, true, odom, scan in steps:
            sensor = true.compose(offset).compose(MOUNT)
            r = np.where(np.isfinite(scan.ranges), scan.ranges, 81.83)[45:225]
            lines.append(f"ODOM {odom.x:.6f} {odom.y:.6f} {odom.theta:.6f} 0 0 0 {t:.3f} h 0")
            lines.append("FLASER 180 " + " ".join(f"{v:.3f}" for v in r)
                         + f" {sensor.x:.6f} {sensor.y:.6f} {sensor.theta:.6f}"
                         f" {true.x:.6f} {true.y:.6f} {true.theta:.6f} {t:.3f} h {t:.3f}")
        path = tmp_path / name
        path.write_text("\n".join(lines) + "\n")
        return path

    def freed_walls(log, check):
        out = tmp_path / f"{log.stem}-{check}.yaml"
        s = update_from_log(world[0] / "map.yaml", LogSource(log), Outputs(out),
                            Placement(pose_check=check,
                                      pose_check_config=PoseCheckConfig(slack_cells=1)),
                            updater_config=NO_GATING)
        return s, int((walls & (load_map(out).data == FREE)).sum())

    off = log_with(Pose2D(0.2, 0.0, math.radians(2.0)), "off.log")
    s_plain, freed_plain = freed_walls(off, False)
    s_checked, freed_checked = freed_walls(off, True)
    assert s_plain["scans_refused_by_pose_check"] == 0 and freed_plain > 20
    assert s_checked["scans_refused_by_pose_check"] > 0.9 * s_checked["scans_used"]
    assert freed_checked == 0
    right = log_with(Pose2D(0.0, 0.0, 0.0), "right.log")
    s_right, freed_right = freed_walls(right, True)
    assert s_right["scans_refused_by_pose_check"] < 0.1 * s_right["scans_used"]
    assert freed_right == 0 and s_right["cells_freed"] > 50


# --- hostile input: bad readings kept, skipped lines counted (hostile-input issue) ----------------
def _carmen_lines(steps, bad=None):
    """The session as FLASER lines (laser pose = true pose with the mount); ``bad(k, r)`` may
    spoil readings of line k (a list of words)."""
    lines = []
    for k, (t, true, odom, scan) in enumerate(steps):
        sensor = true.compose(MOUNT)
        r = [f"{v:.3f}" for v in np.where(np.isfinite(scan.ranges), scan.ranges, 81.83)[45:225]]
        if bad is not None:
            bad(k, r)
        lines.append("FLASER 180 " + " ".join(r) + f" {sensor.x:.6f} {sensor.y:.6f} "
                     f"{sensor.theta:.6f} {true.x:.6f} {true.y:.6f} {true.theta:.6f} {t:.3f} h 0")
    return lines


def test_carmen_scans_with_nan_negative_or_huge_readings_are_all_used(world, tmp_path):
    _, steps = world

    def spoil(k, r):                   # three bad readings among the 180 of every line
        r[10], r[90], r[170] = "nan", "-0.5", "1e9"

    def blank(k, r):                   # the same readings as plain invalid beams
        r[10], r[90], r[170] = "0.000", "0.000", "0.000"

    for name, change in (("bad", spoil), ("blank", blank)):
        (tmp_path / f"{name}.log").write_text("\n".join(_carmen_lines(steps, change)) + "\n")
    s = update_from_log(world[0] / "map.yaml", LogSource(tmp_path / "bad.log"),
                        Outputs(tmp_path / "bad.yaml"), updater_config=NO_GATING)
    update_from_log(world[0] / "map.yaml", LogSource(tmp_path / "blank.log"),
                    Outputs(tmp_path / "blank.yaml"), updater_config=NO_GATING)
    assert s["scans"] == s["scans_used"] == len(steps) and s["read"]["skipped"] == {}
    assert s["read_lines"] == [f"kept {len(steps)} scans with {2 * len(steps)} invalid ranges "
                               "(NaN or negative) as invalid beams"]
    np.testing.assert_array_equal(load_map(tmp_path / "bad.yaml").data,
                                  load_map(tmp_path / "blank.yaml").data)


def test_skipped_lines_are_reported_per_kind_and_strict_refuses_them(world, tmp_path, capfd):
    """112 scan lines, 56 of them cut short and 1 of an unknown kind: the summary says so, one
    line per kind, and --strict refuses the log before writing anything."""
    from mapupdate import main

    _, steps = world
    lines = _carmen_lines((steps * 2)[:112])
    for k in range(1, 112, 2):
        lines[k] = " ".join(lines[k].split()[:50])
    lines.insert(3, "FOO 1 2 3")
    log = tmp_path / "cut.log"
    log.write_text("\n".join(lines) + "\n")
    argv = ["update", "--map", str(world[0] / "map.yaml"), "--log", str(log), "--out",
            str(tmp_path / "cut.yaml"), "--no-progress"]
    assert main(argv) == 0
    out = capfd.readouterr().out.splitlines()
    assert "56 scans read (57 lines or messages of the log skipped, below)" in out[1]
    assert out[2].startswith(f"  skipped 56 (truncated); first: {log}, line 2: FLASER")
    assert out[3] == f"  skipped 1 (unknown message); first: {log}, line 4: unknown message " \
                     "type 'FOO'"
    (tmp_path / "cut.yaml").unlink()
    assert main(argv + ["--strict"]) == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and f"{log}, line 2: FLASER" in err and "truncated" in err
    assert not (tmp_path / "cut.yaml").exists()
