"""A global localisation that cannot tell two places apart says so (hostile-input issue): the
particle-set check on hand-made particles, and ``mapupdate update`` without a start in the bare
8 x 6 m room of test_logs_replay, which looks the same turned by 180 deg (exit 2, one line,
nothing written), with ``--initial-pose`` (exit 0), and with one box in a corner, which the
scans tell apart from its mirror image (exit 0, no false alarm)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gridmap import Pose2D, Scan, save_map
from gridmap.raycast import cast_rays
from localization.modes import AmbiguousStart, ambiguous_modes, far_apart, pose_modes
from mapupdate import main
from onboard.replay import LogSource, Outputs, Placement, update_from_log
from robotlogs.rosbag import write_bag

import test_logs_replay as room

CORNER_BOX = (7.5, 5.5)


def cloud(rng, centre, n, spread=0.05, turn=0.02):
    x, y, th = centre
    return np.column_stack((rng.normal(x, spread, n), rng.normal(y, spread, n),
                            np.angle(np.exp(1j * rng.normal(th, turn, n)))))


# --- the particle-set check ------------------------------------------------------------------
def test_two_equal_clusters_far_apart_are_ambiguous():
    rng = np.random.default_rng(0)
    p = np.vstack([cloud(rng, (1.0, 1.0, 0.0), 300), cloud(rng, (7.0, 5.0, math.pi), 300)])
    modes = ambiguous_modes(p, np.ones(len(p)))
    assert len(modes) == 2 and all(abs(m.weight - 0.5) < 1e-9 for m in modes)
    assert sorted(round(m.pose.x) for m in modes) == [1, 7]
    # the same place turned by more than 30 deg is another answer too
    turned = np.vstack([cloud(rng, (1.0, 1.0, 0.0), 300), cloud(rng, (1.0, 1.0, 1.0), 300)])
    assert len(ambiguous_modes(turned, np.ones(600))) == 2


def test_one_cluster_or_a_faint_second_is_not_ambiguous():
    rng = np.random.default_rng(1)
    one = cloud(rng, (1.0, 1.0, 0.0), 500)
    assert ambiguous_modes(one, np.ones(500)) == []
    two = np.vstack([one, cloud(rng, (7.0, 5.0, math.pi), 500)])
    w = np.r_[np.full(500, 0.95 / 500), np.full(500, 0.05 / 500)]
    assert ambiguous_modes(two, w) == []
    assert [round(m.weight, 2) for m in pose_modes(two, w)] == [0.95, 0.05]
    # a cloud split by the bins, or across +-pi, is one place
    near = np.vstack([one, cloud(rng, (1.6, 1.0, 0.0), 500)])
    assert ambiguous_modes(near, np.ones(1000)) == []
    assert len(pose_modes(cloud(rng, (3.0, 3.0, math.pi), 500, turn=0.05), np.ones(500))) == 1
    assert not far_apart(Pose2D(0, 0, 3.1), Pose2D(0.5, 0, -3.1))
    with pytest.raises(ValueError, match="finite"):
        pose_modes(one, np.full(500, np.nan))


# --- mapupdate update without a start ------------------------------------------------------------
def drive(world, seed=11):
    """(time, true pose, odometry pose, scan) along test_logs_replay's route in ``world``."""
    rng = np.random.default_rng(seed)
    start, inc, n = room.F32(-math.radians(135)), room.F32(math.radians(1.0)), 271
    out, odom, true = [], Pose2D(0.3, -0.2, 0.05), room.route()
    for k, pose in enumerate(true):
        if k:
            step = true[k - 1].inverse().compose(pose)
            odom = odom.compose(Pose2D(step.x * 1.01, step.y + rng.normal(0, 0.003),
                                       step.theta + rng.normal(0, 0.003)))
        ranges = cast_rays(world, pose.compose(room.MOUNT), start + inc * np.arange(n), 9.0)
        ranges = ranges + rng.normal(0, 0.01, n)
        t = 10.0 + 0.25 * k
        out.append((t, pose, odom, Scan(ranges.astype(np.float32), start, inc,
                                        room.F32(0.05), 10.0, t)))
    return out


@pytest.fixture(scope="module")
def rooms(tmp_path_factory):
    """Maps and odometry-only bags of the bare room and of the room with a box in a corner."""
    d = tmp_path_factory.mktemp("modes")
    for name, boxes in (("bare", []), ("box", [CORNER_BOX])):
        world = room.room(boxes)
        save_map(world, d / f"{name}.yaml")
        steps = drive(world)
        write_bag(d / f"{name}.bag", room.bag_records(steps, map_odom_tf=False, amcl=False),
                  "ros1")
    return d, steps


def update(d, name, out, *extra):
    return main(["update", "--map", str(d / f"{name}.yaml"), "--log", str(d / f"{name}.bag"),
                 "--out", str(d / f"{out}.yaml"), "--poses", "localizer", "--trajectory",
                 str(d / f"{out}.tum"), "--no-progress", *map(str, extra)])


def test_a_symmetric_room_refuses_to_guess_in_one_line_and_writes_nothing(rooms, capfd):
    d, steps = rooms
    start = steps[0][1]
    assert update(d, "bare", "bare_out") == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and err.startswith(
        "mapupdate update: error: global localisation is ambiguous: 2 poses of similar weight "
        "(x,y,th at the start of the log: ") and err.endswith("; give --initial-pose X Y TH\n")
    for suffix in (".yaml", ".pgm", ".tum"):
        assert not (d / f"bare_out{suffix}").exists()
    # the poses it names are the true start and its mirror image, at the log's start
    with pytest.raises(AmbiguousStart) as caught:
        update_from_log(d / "bare.yaml", LogSource(d / "bare.bag"), Outputs(d / "lib.yaml"),
                        Placement(source="localizer"))
    mirror = Pose2D(8.0 - start.x, 6.0 - start.y, start.theta + math.pi)
    for truth in (start, mirror):
        assert min(math.dist((p.x, p.y), (truth.x, truth.y)) for p in caught.value.poses) < 0.3
    assert not (d / "lib.yaml").exists()


def test_the_same_log_with_a_start_pose_updates_the_map(rooms, capfd):
    d, steps = rooms
    start = steps[0][1]
    assert update(d, "bare", "given", "--initial-pose", start.x, start.y, start.theta) == 0
    assert "localiser: started at the given pose" in capfd.readouterr().out
    assert (d / "given.yaml").exists()


def test_a_room_with_one_box_in_a_corner_still_localises_over_the_whole_map(rooms, capfd):
    d, steps = rooms
    assert update(d, "box", "box_out") == 0
    out = capfd.readouterr().out
    assert "started over the whole map" in out and "localiser tracking" in out
    truth = {round(t, 6): p for t, p, _, _ in steps}
    rows = np.loadtxt(d / "box_out.tum", ndmin=2)
    errors = [math.dist(r[1:3], (truth[round(r[0], 6)].x, truth[round(r[0], 6)].y))
              for r in rows]
    assert len(rows) > 0.8 * len(steps) and max(errors) < 0.3
