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


# --- bad readings are invalid beams, not bad lines (hostile-input issue) --------------------------
BAD_RANGES = "FLASER 6 1.0 nan -0.5 1e9 2.0 -inf 0.5 -0.25 0.1 0.4 -0.2 0.05 12.5 host 12.6"


@pytest.mark.parametrize("strict", [False, True])
def test_nan_negative_and_huge_ranges_keep_their_line(strict):
    (r,) = parse_carmen([BAD_RANGES], source="run.log", strict=strict).records
    np.testing.assert_array_equal(r.scan.ranges, np.array([1.0, np.nan, np.nan, np.inf, 2.0,
                                                           np.nan], np.float32))
    assert r.laser_pose == Pose2D(0.5, -0.25, 0.1)      # the rest of the line as it was
    log = parse_carmen([BAD_RANGES, FLASER], source="run.log")
    assert log.stats.skipped == {} and log.stats.invalid_ranges == 3
    assert log.stats.scans_with_invalid_ranges == 1
    assert log.stats.lines() == ["kept 1 scans with 3 invalid ranges (NaN or negative) as "
                                 "invalid beams"]


def test_log_of_lines_with_a_few_bad_ranges_each_is_read_whole(tmp_path):
    """400 lines of 360 readings, each with a NaN, a negative and a 1e9 reading: every line is
    kept (it was "no usable CARMEN line", 398 of 400 skipped)."""
    rng = np.random.default_rng(0)
    lines = []
    for k in range(400):
        r = rng.uniform(0.5, 20.0, 360).round(3).astype(str)
        r[rng.choice(360, 3, replace=False)] = ["nan", "-1.0", "1e9"]
        lines.append(f"FLASER 360 {' '.join(r)} 1 2 0.1 1 2 0.1 {k * 0.2:.1f} host 0")
    path = tmp_path / "bad_ranges.log"
    path.write_text("\n".join(lines) + "\n")
    log = read_carmen(path)
    assert len(log.scans()) == 400 and log.stats.total_skipped == 0
    assert log.stats.invalid_ranges == 800                   # NaN and negative; 1e9 is "no return"
    assert all(int(np.isinf(s.scan.ranges).sum()) == 1 for s in log.scans())


@pytest.mark.parametrize("line, words", [
    ("FLASER 2 1.0 2.0 nan 0 0 0 0 0 5.0 host 5.0", "not finite"),          # the pose
    ("FLASER 2 1.0 2.0 0 0 0 0 0 0 inf host 5.0", "not finite"),            # the time
    ("FLASER 2 1.0 x 0 0 0 0 0 0 5.0 host 5.0", "is not a number: 'x'"),    # not a reading
    ("FLASER 1 1.0 2.0 0 0 0 0 0 0 5.0 host 5.0", "wrong beam count"),
])
def test_a_bad_pose_time_count_or_word_still_spoils_the_line(line, words):
    log = parse_carmen([line, FLASER], source="run.log")
    assert len(log.records) == 1 and log.stats.total_skipped == 1
    assert words in log.stats.lines()[0]
    with pytest.raises(LogError, match="run.log, line 1"):
        parse_carmen([line], source="run.log", strict=True)


def test_skipped_lines_are_reported_one_line_per_kind():
    lines = [FLASER, "FLASER 4 1.0", "FLASER 4 1.0", "FOO 1", BAD_RANGES]
    stats = parse_carmen(lines, source="run.log").stats
    assert stats.lines() == [
        "skipped 2 (truncated); first: run.log, line 2: FLASER declares 4 ranges and needs at "
        "least 13 fields, found 3 (truncated line or wrong beam count)",
        "skipped 1 (unknown message); first: run.log, line 4: unknown message type 'FOO'",
        "kept 1 scans with 3 invalid ranges (NaN or negative) as invalid beams"]


# --- gzip ---------------------------------------------------------------------------------------
def test_gzip_compressed_log_is_read_directly(tmp_path):
    import gzip

    from robotlogs import detect_format

    path = tmp_path / "run.clf.gz"
    with gzip.open(path, "wt") as f:
        f.write("\n".join([ODOM, FLASER, ROBOTLASER]) + "\n")
    assert detect_format(path) == "carmen"
    log = read_carmen(path, strict=True)
    assert [r.time for r in log.records] == [10.0, 11.0, 12.5]
    damaged = tmp_path / "damaged.gz"          # cut inside its first line
    damaged.write_bytes(path.read_bytes()[:30])
    with pytest.raises(LogError, match="damaged.gz: no usable CARMEN line .*; cut short: its "
                                       "gzip stream ends without its end marker after 0 "
                                       "complete lines"):
        read_carmen(damaged)


# --- the real logs of ../shared/data --------------------------------------------------------------
DATA = INTEL.parent


def _data(name):
    path = DATA / name
    if not path.exists():
        pytest.skip(f"{name} is not at {path} (see data/README)")
    return path


@pytest.mark.parametrize("name, scans", [("sena.odom.log", 225), ("sena.keyframes.log", 99)])
def test_sena_logs_read_as_they_are(name, scans):
    """Comment lines, 361 beams 0.5 deg apart over 180 deg, 0.0 = no return (invalid beam)."""
    from robotlogs.observations import laser_poses_are_odometry

    log = read_carmen(_data(name), strict=True)
    assert len(log.scans()) == scans and log.stats.total_skipped == 0
    s = log.scans()[0].scan
    assert s.beams == 361 and s.angle_min == pytest.approx(-math.pi / 2)
    assert s.angle_increment == pytest.approx(math.radians(0.5))
    assert s.angle_min + 360 * s.angle_increment == pytest.approx(math.pi / 2)
    zeros = sum(int((r.scan.ranges == 0).sum()) for r in log.scans())
    assert zeros > 0 and s.range_min > 0        # 0.0 lies below range_min: an invalid beam
    mount = log.scans()[0].laser_pose.relative_to(log.scans()[0].odom_pose)
    assert mount.x == pytest.approx(0.78) and laser_poses_are_odometry(log)


def test_killian_robotlaser_gzip_log_reads_completely():
    log = read_carmen(_data("killian.clf.gz"), strict=True)
    scans = log.scans()
    assert len(scans) == 3873 and log.stats.total_skipped == 0
    assert all(r.topic == "ROBOTLASER1" and r.scan.beams == 180 for r in scans)
    assert scans[0].scan.range_max == 50.0
    assert scans[0].scan.angle_increment == pytest.approx(math.radians(1.0), rel=1e-4)
