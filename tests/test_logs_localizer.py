"""``mapupdate update --poses localizer`` on recordings: where the localiser starts (a given pose,
the log's localisation, or over the whole map), the tracking verdict that stops a lost
localiser feeding the update (a 100 m odometry jump in a simulated warehouse session), the
trajectory the update used, and bad odometry messages skipped and counted."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, Pose2D, load_map, save_map
from localization import MonteCarloLocalizer
from localization.tracking import TrackingConfig, TrackingMonitor, TrackState
from robotlogs import LogError, log_observations, read_bag
from robotlogs.records import OdomRecord, TransformRecord
from robotlogs.rosbag import write_bag
from mapupdate import main
from onboard.pipeline import RobotPipeline
from onboard.replay import LogSource, Outputs, Placement, update_from_log
from updater import MapUpdater

import test_logs_replay as room


def read_tum(path):
    return np.loadtxt(path, ndmin=2)


@pytest.fixture(scope="module")
def room_bags(tmp_path_factory):
    """The synthetic room of test_logs_replay: its map, and bags of the drive with odometry
    only (no localisation), and with one NaN odometry message."""
    d = tmp_path_factory.mktemp("room")
    steps = room.session()
    save_map(room.room([room.REMOVED]), d / "map.yaml")
    plain = room.bag_records(steps, map_odom_tf=False, amcl=False)
    write_bag(d / "odom.bag", plain, "ros1")
    nan = list(plain) + [OdomRecord(steps[10][0] + 0.01, Pose2D(math.nan, 0.0, 0.0))]
    write_bag(d / "nan.bag", nan, "ros1")
    return d, steps


# --- where the localiser starts -------------------------------------------------------------------
def test_initial_pose_starts_the_localiser_there_and_the_trajectory_follows_the_truth(
        room_bags, capfd):
    d, steps = room_bags
    start = steps[0][1]
    assert main(["update", "--map", str(d / "map.yaml"), "--log", str(d / "odom.bag"),
                 "--out", str(d / "given.yaml"), "--poses", "localizer", "--initial-pose",
                 str(start.x), str(start.y), str(start.theta), "--trajectory",
                 str(d / "given.tum"), "--no-progress"]) == 0
    out = capfd.readouterr().out
    assert "localiser: started at the given pose" in out and "(TUM)" in out
    rows = read_tum(d / "given.tum")
    truth = {round(t, 6): p for t, p, _, _ in steps}
    assert rows.shape[1] == 8 and len(rows) >= 0.9 * len(steps)
    assert np.allclose(rows[:, 3:6], 0.0) and np.allclose(np.hypot(rows[:, 6], rows[:, 7]), 1)
    errors = [math.dist(r[1:3], (truth[round(r[0], 6)].x, truth[round(r[0], 6)].y))
              for r in rows]
    assert np.sqrt(np.mean(np.square(errors))) < 0.1


def test_without_a_start_or_a_localisation_it_localises_over_the_whole_map(room_bags):
    """On a map of the room as it is (with the map of test_logs_replay, whose one box is gone
    from the world, the bare room is symmetric and half the global starts settle on its
    mirror image: a global start cannot tell what the place does not)."""
    d, steps = room_bags
    save_map(room.room([room.ADDED]), d / "as_it_is.yaml")
    s = update_from_log(d / "as_it_is.yaml", LogSource(d / "odom.bag"),
                        Outputs(d / "global.yaml", trajectory=d / "g.tum"),
                        Placement(source="localizer", seed=3), updater_config=room.NO_GATING)
    assert s["tracking"]["start"].startswith("started over the whole map")
    assert [e["state"] for e in s["tracking"]["events"]][-1] == "tracking"
    rows = read_tum(d / "g.tum")
    truth = {round(t, 6): p for t, p, _, _ in steps}
    errors = [math.dist(r[1:3], (truth[round(r[0], 6)].x, truth[round(r[0], 6)].y))
              for r in rows]
    assert max(errors) < 0.3 and s["scans_not_tracking"] > 0     # nothing used before it settled
    assert s["scans_used"] == len(rows)


def test_a_global_start_that_never_settles_is_one_clear_line_and_writes_nothing(room_bags,
                                                                                 capfd):
    d, steps = room_bags
    write_bag(d / "still.bag", [r for r in room.bag_records(steps[:4], map_odom_tf=False,
                                                            amcl=False)], "ros1")
    with pytest.raises(LogError, match=r"never settled on a pose .* give the start with "
                                       r"--initial-pose X Y YAW"):
        update_from_log(d / "map.yaml", LogSource(d / "still.bag"), Outputs(d / "still.yaml"),
                        Placement(source="localizer"))
    assert main(["update", "--map", str(d / "map.yaml"), "--log", str(d / "still.bag"),
                 "--out", str(d / "still.yaml"), "--poses", "localizer", "--no-progress"]) == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "never settled" in err
    assert not (d / "still.yaml").exists() and not (d / "still.pgm").exists()


@pytest.mark.parametrize("bad, says", [(["1", "2"], "expected 3 arguments"),
                                       (["1", "2", "nan"], "three finite numbers"),
                                       (["1", "x", "0"], "invalid float value: 'x'")])
def test_a_bad_initial_pose_is_refused_in_one_line(room_bags, capfd, bad, says):
    d, _ = room_bags
    argv = ["update", "--map", str(d / "map.yaml"), "--log", str(d / "odom.bag"), "--out",
            str(d / "bad.yaml"), "--poses", "localizer", "--no-progress", "--initial-pose", *bad]
    try:
        code = main(argv)
    except SystemExit as e:          # argparse's own refusal
        code = e.code
    err = capfd.readouterr().err
    assert code == 2 and says in err.splitlines()[-1] and not (d / "bad.yaml").exists()


def test_the_trajectory_may_not_overwrite_an_input(room_bags):
    d, _ = room_bags
    for clash in (d / "odom.bag", d / "map.yaml", d / "o.yaml", d / "o.pgm"):
        with pytest.raises(LogError, match="the trajectory would overwrite"):
            update_from_log(d / "map.yaml", LogSource(d / "odom.bag"),
                            Outputs(d / "o.yaml", trajectory=clash), Placement(source="localizer"))


# --- bad odometry messages (hostile-input issue) ---------------------------------------------------
@pytest.mark.parametrize("source", ["localizer", "truth"])
def test_one_nan_odometry_message_is_skipped_counted_and_the_update_goes_on(room_bags, capfd,
                                                                          source):
    d, steps = room_bags
    start = steps[0][1]
    given = ["--initial-pose", str(start.x), str(start.y), str(start.theta)] \
        if source == "localizer" else []
    assert main(["update", "--map", str(d / "map.yaml"), "--log", str(d / "nan.bag"),
                 "--out", str(d / f"nan_{source}.yaml"), "--poses", source, "--no-progress",
                 *given]) == 0
    out = capfd.readouterr().out
    assert "skipped 1 (not finite /odom); first: " in out and "pose is not finite" in out
    assert load_map(d / f"nan_{source}.yaml").data.shape == room.room([]).data.shape
    with pytest.raises(LogError, match="not finite"):
        update_from_log(d / "map.yaml", LogSource(d / "nan.bag", strict=True),
                        Outputs(d / "strict.yaml"), Placement(source=source))
    with pytest.raises(LogError, match="a start pose is for the localiser"):
        update_from_log(d / "map.yaml", LogSource(d / "nan.bag"), Outputs(d / "x.yaml"),
                        Placement(source="truth", initial_pose=start))


# --- the tracking verdict -------------------------------------------------------------------------
def test_tracking_verdict_from_the_spreads_and_the_scan(room_bags):
    d, steps = room_bags
    grid = load_map(d / "map.yaml")
    loc = MonteCarloLocalizer(grid, seed=0, profile="paper")
    loc.initialize(steps[0][1], np.diag([0.01, 0.01, 0.001]))
    monitor = TrackingMonitor(grid)
    assert monitor.tracking and monitor.doubt(loc.estimate()) == ""
    # a scattered filter (an odometry jump): lost at once, trusted again only when it has
    # settled and its scans fit the map, settle_updates times running
    loc.initialize_global(4000)
    scattered = loc.estimate()
    for k, (t, true, odom, scan) in enumerate(steps[:40]):
        if loc.update(odom, scan, room.MOUNT):
            monitor.observe(loc, scan, loc.estimate().pose_at(odom), room.MOUNT)
    assert "heaviest particle cluster" in monitor.doubt(scattered, lost=True) or \
        "std" in monitor.doubt(scattered, lost=True)
    states = [e.state for e in monitor.events]
    assert states[0] is TrackState.LOST and states[-1] is TrackState.TRACKING
    with pytest.raises(Exception, match="tracking key"):
        TrackingConfig(max_fit=2.0)
    with pytest.raises(Exception, match="tracking keys"):
        TrackingConfig(lost_position_std=0.1)


def test_the_updater_dropping_scans_as_lost_makes_the_localiser_lost(room_bags):
    d, _ = room_bags
    monitor = TrackingMonitor(load_map(d / "map.yaml"), TrackingConfig(lost_scans=3))
    for k, dropped in enumerate([True, True, False, True, True]):
        monitor.observe_lost(dropped, float(k))
    assert monitor.tracking
    monitor.observe_lost(True, 5.0)
    assert monitor.state is TrackState.LOST and "dropped 3 scans in a row" in \
        monitor.events[-1].reason


# --- a 100 m odometry jump in a simulated warehouse session -------------------------------------
@pytest.fixture(scope="module")
def jump(tmp_path_factory):
    """A W2 session bag of the quick warehouse whose odometry jumps 100 m halfway (the odom
    frame's tf and /odom alike, as a driver's reset would), with M1 and G2."""
    from scenarios.observers import Observers
    from scenarios.runner import RunOptions, run_scenario
    from scenarios.session_bags import SessionBagRecorder

    root = tmp_path_factory.mktemp("jump")
    bags = SessionBagRecorder(root / "bags", "ros1")
    run_scenario(None, RunOptions(out=root / "run", quick=True, sessions=2, progress=False,
                                  observer=Observers(bags)))
    records = list(read_bag(bags.paths["W2"]))
    times = [r.time for r in records]
    halfway = 0.5 * (min(times) + max(times))
    shift = Pose2D(100.0, 0.0, 0.0)
    jumped = [_shifted(r, shift) if r.time >= halfway else r for r in records]
    write_bag(root / "jump.bag", jumped, "ros1")
    return root


def _shifted(r, shift: Pose2D):
    if isinstance(r, OdomRecord):
        return OdomRecord(r.time, shift.compose(r.pose), r.velocity, r.frame_id,
                          r.child_frame_id, r.topic)
    if isinstance(r, TransformRecord) and r.parent == "odom":
        return TransformRecord(r.time, r.parent, r.child, shift.compose(r.pose), r.static)
    if isinstance(r, TransformRecord) and r.child == "odom":
        return TransformRecord(r.time, r.parent, r.child, r.pose.compose(shift.inverse()),
                               r.static)
    return r


def _walls_freed(root, out) -> int:
    g = load_map(root / "run/maps/G_W2.yaml").data
    m = load_map(root / "run/maps/M_W1.yaml").data
    return int(((g == OCCUPIED) & (m == OCCUPIED) & (out == FREE)).sum())


def test_without_a_tracking_verdict_the_jump_frees_walls(jump):
    """The failure the verdict exists for: the localiser, fed the jump as motion, diverges and
    the update it feeds frees cells of walls and racks."""
    grid = load_map(jump / "run/maps/M_W1.yaml")
    updater = MapUpdater(grid, profile="paper")
    pipeline = RobotPipeline(updater)
    for obs in log_observations(jump / "jump.bag").observations:
        if pipeline.localizer is None:
            pipeline.localizer = MonteCarloLocalizer(grid, seed=0, profile="paper")
            pipeline.localizer.initialize(obs.recorded, np.diag([0.0625, 0.0625, 0.01]))
        pipeline.step(obs.scan, obs.mount, odometry=obs.odom)
    assert _walls_freed(jump, updater.updated_map().data) > 10


def test_a_100_m_odometry_jump_stops_the_localiser_feeding_the_update_and_says_so(jump, capfd):
    assert main(["update", "--map", str(jump / "run/maps/M_W1.yaml"), "--log",
                 str(jump / "jump.bag"), "--out", str(jump / "out.yaml"), "--poses",
                 "localizer", "--trajectory", str(jump / "out.tum"), "--no-progress"]) == 0
    out = capfd.readouterr().out
    print(out)
    assert "localiser lost" in out and "scans were not used: the localiser was not tracking" in \
        out
    assert _walls_freed(jump, load_map(jump / "out.yaml").data) == 0
    # the poses it did use, before the jump and after it found the robot again, are right
    truth = {round(o.time, 6): o.truth for o in log_observations(jump / "jump.bag").observations}
    rows = read_tum(jump / "out.tum")
    errors = [math.dist(r[1:3], (truth[round(r[0], 6)].x, truth[round(r[0], 6)].y))
              for r in rows]
    assert max(errors) < 0.3
