"""CARMEN log reading: hand-written lines of every kind read, malformed ones named by line."""

import math
from pathlib import Path

import numpy as np
import pytest

from gridmap import Pose2D
from robotlogs.carmen import parse_carmen, read_carmen
from robotlogs.records import LogError, OdomRecord, PoseRecord, ScanRecord

INTEL = Path(__file__).resolve().parents[2] / "shared/data/intel.gfs.log"

FLASER = "FLASER 4 1.0 2.5 81.83 3.25 0.5 -0.25 0.1 0.4 -0.2 0.05 12.5 host 12.6"
RLASER = "RLASER 3 1.0 2.0 3.0 1.0 2.0 3.1 1.0 2.0 0.0 13.0 host 13.1"
ROBOTLASER = ("ROBOTLASER1 0 -1.5 3.0 0.5 20.0 0.01 0 7 1 2 3 20 5 6 7 2 100 200 "
              "1.3 2.0 0.0 1.0 2.0 0.0 0.1 0.0 0.5 0.3 0.0 11.0 host 11.1")
ODOM = "ODOM 0.5 -0.5 0.1 0.3 0.05 0 10.0 host 10.0"
TRUEPOS = "TRUEPOS 1 2 0.3 1.1 2.1 0.31 10.5 host 10.5"


def test_flaser_fields_angles_and_no_return():
    log = parse_carmen([FLASER])
    (r,) = log.records
    assert isinstance(r, ScanRecord) and r.topic == "FLASER" and r.frame_id == "front_laser"
    assert r.time == 12.5 and r.scan.time == 12.5
    np.testing.assert_array_equal(r.scan.ranges, np.array([1.0, 2.5, np.inf, 3.25], np.float32))
    assert r.scan.angle_min == pytest.approx(-math.pi / 2)
    assert r.scan.angle_increment == pytest.approx(math.pi / 4)  # 4 beams over 180 deg
    assert r.laser_pose == Pose2D(0.5, -0.25, 0.1)
    assert r.odom_pose == Pose2D(0.4, -0.2, 0.05)


def test_odd_beam_count_spans_both_ends():
    (r,) = parse_carmen([RLASER]).records
    assert r.frame_id == "rear_laser"
    assert r.scan.angle_increment == pytest.approx(math.pi / 2)  # 3 beams: -90, 0, +90 deg


def test_robotlaser_has_its_own_angles_range_limit_and_poses():
    (r,) = parse_carmen([ROBOTLASER]).records
    assert r.topic == "ROBOTLASER1"
    assert r.scan.angle_min == -1.5 and r.scan.angle_increment == 0.5
    assert r.scan.range_max == 20.0
    np.testing.assert_array_equal(r.scan.ranges, np.array([1, 2, 3, np.inf, 5, 6, 7], np.float32))
    assert r.laser_pose == Pose2D(1.3, 2.0, 0.0)
    assert r.odom_pose == Pose2D(1.0, 2.0, 0.0)
    mount = r.laser_pose.relative_to(r.odom_pose)
    assert mount.x == pytest.approx(0.3) and mount.y == pytest.approx(0.0, abs=1e-12)
    assert r.time == 11.0


def test_odometry_truth_and_time_order():
    log = parse_carmen([FLASER, ROBOTLASER, ODOM, TRUEPOS, "NEFF 12.3", "PARAM x 1",
                        "# a comment", ""])
    assert [type(r) for r in log.records] == [OdomRecord, PoseRecord, ScanRecord, ScanRecord]
    assert [r.time for r in log.records] == [10.0, 10.5, 11.0, 12.5]
    odom = log.records[0]
    assert odom.pose == Pose2D(0.5, -0.5, 0.1) and odom.velocity == (0.3, 0.0, 0.05)
    assert log.records[1].pose == Pose2D(1.0, 2.0, 0.3)
    assert log.stats.ignored == {"NEFF": 1, "PARAM": 1}
    assert log.stats.total_skipped == 0


def test_line_without_host_fields_reads():
    (r,) = parse_carmen(["ODOM 1 2 0 0 0 0 5.0"]).records
    assert r.time == 5.0 and r.pose == Pose2D(1.0, 2.0, 0.0)


MALFORMED = [
    ("FLASER 4 1.0 2.0 3.0", "truncated", "needs at least 13 fields, found 5"),
    ("FLASER 3 1.0 2.5 81.83 3.25 0.5 -0.25 0.1 0.4 -0.2 0.05 12.5 host 12.6",
     "wrong beam count", "after its timestamp"),
    ("FLASER 4 1.0 abc 81.83 3.25 0.5 -0.25 0.1 0.4 -0.2 0.05 12.5 host 12.6",
     "not a number", "field 4"),
    ("FLASER four 1.0", "not a number", "field 2"),
    ("FLASER 4 1.0 2.5 81.83 3.25 0.5 -0.25 nan 0.4 -0.2 0.05 12.5 host 12.6",
     "not a number", "not finite"),
    ("ODOM 1 2 3", "truncated", "ODOM"),
    ("ROBOTLASER1 0 -1.5 3.0 0.5 20.0 0.01 0 7 1 2 3", "truncated", "7 ranges"),
    ("FOO 1 2 3", "unknown message", "'FOO'"),
]


@pytest.mark.parametrize("line, kind, words", MALFORMED)
def test_malformed_line_is_named_when_strict(line, kind, words):
    with pytest.raises(LogError) as e:
        parse_carmen([ODOM, line, FLASER], source="run.log", strict=True)
    assert "run.log, line 2:" in str(e.value) and words in str(e.value)


@pytest.mark.parametrize("line, kind, words", MALFORMED)
def test_malformed_line_is_skipped_and_counted_by_default(line, kind, words):
    log = parse_carmen([ODOM, line, FLASER], source="run.log")
    assert len(log.records) == 2
    assert log.stats.skipped == {kind: 1}
    assert log.stats.problems[0].startswith("run.log, line 2:")
    assert "skipped 1" in log.stats.summary()


def test_file_without_usable_lines_is_an_error(tmp_path):
    p = tmp_path / "bad.log"
    p.write_text("FOO 1\nBAR 2\n")
    with pytest.raises(LogError, match="no usable CARMEN line"):
        read_carmen(p)
    with pytest.raises(LogError, match=r"bad.log, line 1: unknown message type 'FOO'"):
        read_carmen(p, strict=True)


@pytest.mark.skipif(not INTEL.exists(), reason=f"the Intel lab log is not at {INTEL}")
def test_intel_log_reads_completely():
    log = read_carmen(INTEL, strict=True)
    scans = log.scans()
    assert len(scans) == 910 and len(log.odometry()) == 14541
    assert log.stats.ignored == {"NEFF": 910}
    assert all(s.scan.beams == 180 for s in scans)
    assert sum(int(np.isinf(s.scan.ranges).sum()) for s in scans) == 4172
    assert scans[0].scan.angle_increment == pytest.approx(math.radians(1.0))
    times = [r.time for r in log.records]
    assert times == sorted(times)
