"""ROS 1 and ROS 2 bags: records written with the bag writer read back record for record;
topic choice and its errors; undecodable messages named or counted."""

import math

import numpy as np
import pytest

from gridmap import Pose2D, Scan
from robotlogs.records import (LogError, OdomRecord, PoseRecord, ReadStats, ScanRecord,
                                    TransformRecord)
from robotlogs.rosbag import BagWriter, bag_topics, read_bag, resolve_topics, scan_count, \
    write_bag


def session_records(seed=3, n=12):
    """A short simulated drive: static mount, odometry, tf, amcl and true poses, scans."""
    rng = np.random.default_rng(seed)
    out = [TransformRecord(0.5, "base_link", "laser", Pose2D(0.25, 0.0, 0.0), static=True)]
    for k in range(n):
        t = 1.0 + 0.1 * k
        odom = Pose2D(0.05 * k, 0.01 * k, -3.1 + 0.2 * k)  # yaw crosses +-pi
        corr = Pose2D(0.3, -0.2, 0.05)
        truth = corr.compose(odom).compose(Pose2D(*rng.normal(0, 0.01, 3)))
        ranges = rng.uniform(0.1, 9.0, 90).astype(np.float32)
        ranges[rng.random(90) < 0.2] = np.inf
        scan = Scan(ranges, -math.radians(135), math.radians(3), 0.05, 10.0, t)
        out += [
            OdomRecord(t, odom, (0.5, 0.0, 0.2)),
            TransformRecord(t, "odom", "base_link", odom),
            TransformRecord(t, "map", "odom", corr),
            ScanRecord(t, scan),
            PoseRecord(t, corr.compose(odom), covariance=np.diag(rng.uniform(0.01, 0.1, 3))),
            PoseRecord(t, truth, topic="/ground_truth/pose"),
        ]
    return out


def key(r):
    return (round(r.time, 6), type(r).__name__, getattr(r, "topic", ""), getattr(r, "child", ""))


def assert_pose_equal(a, b):
    assert a.x == pytest.approx(b.x, abs=1e-12) and a.y == pytest.approx(b.y, abs=1e-12)
    assert math.remainder(a.theta - b.theta, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)


def assert_same_record(a, b):
    assert type(a) is type(b)
    assert a.time == pytest.approx(b.time, abs=1e-9)
    if isinstance(a, ScanRecord):
        np.testing.assert_array_equal(a.scan.ranges, b.scan.ranges)
        for f in ("angle_min", "angle_increment", "range_min", "range_max"):
            # LaserScan holds these as float32.
            assert getattr(a.scan, f) == pytest.approx(getattr(b.scan, f), rel=1e-6)
        assert (a.frame_id, a.topic) == (b.frame_id, b.topic)
    elif isinstance(a, OdomRecord):
        assert_pose_equal(a.pose, b.pose)
        assert a.velocity == pytest.approx(b.velocity)
        assert (a.frame_id, a.child_frame_id, a.topic) == (b.frame_id, b.child_frame_id, b.topic)
    elif isinstance(a, TransformRecord):
        assert_pose_equal(a.pose, b.pose)
        assert (a.parent, a.child, a.static) == (b.parent, b.child, b.static)
    else:
        assert_pose_equal(a.pose, b.pose)
        assert (a.topic, a.frame_id) == (b.topic, b.frame_id)
        expected = np.zeros((3, 3)) if a.covariance is None else a.covariance
        np.testing.assert_allclose(b.covariance, expected)


@pytest.mark.parametrize("fmt, name, storage", [("ros1", "s.bag", "sqlite3"),
                                                ("ros2", "s2", "sqlite3"),
                                                ("ros2", "s2m", "mcap")])
def test_written_bag_reads_back_record_for_record(tmp_path, fmt, name, storage):
    records = session_records()
    path = write_bag(tmp_path / name, records, fmt, storage=storage)
    back = list(read_bag(path))
    assert len(back) == len(records)
    for a, b in zip(sorted(records, key=key), sorted(back, key=key)):
        assert_same_record(a, b)
    times = [r.time for r in back]
    assert times == sorted(times)
    assert scan_count(path) == 12


def test_bag_topics_and_types(tmp_path):
    path = write_bag(tmp_path / "s.bag", session_records(), "ros1")
    assert bag_topics(path) == {
        "/amcl_pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
        "/ground_truth/pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
        "/odom": "nav_msgs/msg/Odometry", "/scan": "sensor_msgs/msg/LaserScan",
        "/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage"}


def test_transforms_of_one_time_share_a_message(tmp_path):
    path = tmp_path / "tf2"
    with BagWriter(path, "ros2") as w:
        w.write_transforms([TransformRecord(1.0, "map", "odom", Pose2D(1, 2, 0.1)),
                            TransformRecord(1.0, "odom", "base_link", Pose2D(3, 4, 0.2)),
                            TransformRecord(1.0, "base_link", "laser", Pose2D(0.2, 0, 0), True)])
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as r:
        assert {t: i.msgcount for t, i in r.topics.items()} == {"/tf": 1, "/tf_static": 1}
    assert [(r.parent, r.child) for r in read_bag(path, scan_topics=None, kinds=("tf",))
            ] in ([("map", "odom"), ("odom", "base_link"), ("base_link", "laser")],
                  [("base_link", "laser"), ("map", "odom"), ("odom", "base_link")])


def test_missing_topic_error_lists_the_bag_topics(tmp_path):
    path = write_bag(tmp_path / "s.bag", session_records(), "ros1")
    with pytest.raises(LogError) as e:
        list(read_bag(path, scan_topics=["/front_scan"]))
    msg = str(e.value)
    assert "'/front_scan'" in msg
    for topic in ("/scan (sensor_msgs/msg/LaserScan)", "/odom (nav_msgs/msg/Odometry)",
                  "/tf (tf2_msgs/msg/TFMessage)", "/amcl_pose"):
        assert topic in msg
    with pytest.raises(LogError, match="no odometry topic '/wheel_odom'.*the bag has"):
        list(read_bag(path, odom_topic="/wheel_odom"))
    with pytest.raises(LogError, match="carries sensor_msgs/msg/LaserScan"):
        list(read_bag(path, odom_topic="/scan"))


def test_topic_defaults():
    available = {"/front/scan": "sensor_msgs/msg/LaserScan",
                 "/rear/scan": "sensor_msgs/msg/LaserScan", "/odom": "nav_msgs/msg/Odometry"}
    t = resolve_topics(available)
    assert t.scans == ("/front/scan", "/rear/scan")  # no /scan: every LaserScan topic
    assert t.odom == "/odom" and t.pose is None and t.truth is None and t.tf is None
    assert resolve_topics(available, odom_topic="").odom is None
    with pytest.raises(LogError, match=r"no sensor_msgs/LaserScan topic; the bag has /odom"):
        resolve_topics({"/odom": "nav_msgs/msg/Odometry"})


def test_undecodable_message_is_named_or_counted(tmp_path):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    good = write_bag(tmp_path / "good", session_records(n=2), "ros2")
    path = tmp_path / "bad"
    ts = get_typestore(Stores.ROS2_JAZZY)
    with Writer(path, version=8) as w:
        conn = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
        for rec in read_bag(good, kinds=("scan",)):
            w.write(conn, int(rec.time * 1e9), bytes(ts.serialize_cdr(_msg(ts, rec),
                                                                        conn.msgtype)))
        w.write(conn, 5_000_000_000, b"\x00\x01\x00\x00garbage")
    stats = ReadStats()
    assert len(list(read_bag(path, stats=stats))) == 2
    assert stats.skipped == {"bad /scan": 1}
    with pytest.raises(LogError, match=r"topic /scan at 5.000000000 s: cannot decode"):
        list(read_bag(path, strict=True))


def _msg(ts, rec):
    T = ts.types
    hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
        sec=int(rec.time), nanosec=int(round((rec.time % 1) * 1e9))), frame_id="laser")
    s = rec.scan
    return T["sensor_msgs/msg/LaserScan"](
        header=hdr, angle_min=s.angle_min,
        angle_max=s.angle_min + (s.beams - 1) * s.angle_increment,
        angle_increment=s.angle_increment,
        time_increment=0.0, scan_time=0.0, range_min=s.range_min, range_max=s.range_max,
        ranges=s.ranges, intensities=np.zeros(0, np.float32))


def test_writer_refuses_an_existing_path_and_bad_format(tmp_path):
    (tmp_path / "x.bag").write_bytes(b"")
    with pytest.raises(LogError, match="exists already"):
        BagWriter(tmp_path / "x.bag", "ros1")
    with pytest.raises(LogError, match="'ros1' or 'ros2'"):
        BagWriter(tmp_path / "y", "ros3")
    with pytest.raises(LogError, match="ends in .bag"):
        BagWriter(tmp_path / "y", "ros1")
    with pytest.raises(LogError, match="ends in .bag"):
        BagWriter(tmp_path / "y.bag", "ros2")


def test_not_a_bag_is_a_log_error(tmp_path):
    p = tmp_path / "x.bag"
    p.write_bytes(b"hello")
    with pytest.raises(LogError, match="not a readable ROS bag"):
        bag_topics(p)


@pytest.mark.parametrize("fmt", ["ros1", "ros2"])
def test_whole_nanosecond_times_read_back_bit_for_bit(tmp_path, fmt):
    rng = np.random.default_rng(5)
    times = sorted(round(float(x) * 1e9) / 1e9 for x in rng.uniform(0, 5000, 50))
    records = [OdomRecord(t, Pose2D(0.0, 0.0, 0.0)) for t in times]
    path = tmp_path / ("t.bag" if fmt == "ros1" else "t")
    back = list(read_bag(write_bag(path, records, fmt), kinds=("odom",)))
    assert [r.time for r in back] == times


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_odometry_message_that_is_not_finite_is_skipped_and_counted(tmp_path, bad):
    """One NaN or inf odometry message (a faulty driver) is dropped like an undecodable one;
    the bag's other messages read as before. tf and pose messages likewise."""
    records = session_records(n=6)
    records.append(OdomRecord(1.25, Pose2D(bad, 0.0, 0.0)))
    records.append(TransformRecord(1.25, "odom", "base_link", Pose2D(0.0, bad, 0.0)))
    records.append(PoseRecord(1.25, Pose2D(bad, 1.0, 0.0)))
    path = write_bag(tmp_path / "nan", records, "ros2")
    stats = ReadStats()
    got = list(read_bag(path, stats=stats))
    assert len(got) == len(records) - 3
    assert all(r.pose.is_finite() for r in got if hasattr(r, "pose"))
    assert stats.skipped == {"not finite /odom": 1, "not finite /tf": 1,
                             "not finite /amcl_pose": 1}
    assert "pose is not finite" in stats.first["not finite /odom"]
    with pytest.raises(LogError, match=r"topic /odom at 1.250000000 s: not finite"):
        list(read_bag(path, strict=True))
