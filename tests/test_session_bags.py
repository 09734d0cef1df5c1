"""A simulated session written as ROS 1 and ROS 2 bags replays through `mapupdate update`
to the same map as the in-process run."""

import numpy as np
import pytest

from gridmap import load_map
from mapupdate import main
from onboard.replay import LogSource, Outputs, Placement, update_from_log
from robotlogs.rosbag import bag_topics
from scenarios.session_bags import SessionBagRecorder
from scenarios.observers import Observers
from scenarios.runner import RunOptions, run_scenario
from localization.confidence import PoseCheckConfig


@pytest.fixture(scope="module")
def bag_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("bags")
    ros1, ros2 = SessionBagRecorder(root / "ros1", "ros1"), SessionBagRecorder(root / "ros2", "ros2")
    run_scenario(None, RunOptions(out=root / "run", quick=True, sessions=2, progress=False,
                                  observer=Observers(ros1, ros2)))
    return root, ros1, ros2


def test_bags_hold_the_ros_topics(bag_run):
    _, ros1, ros2 = bag_run
    for rec in (ros1, ros2):
        topics = bag_topics(rec.paths["W2"])
        assert topics["/scan"] == "sensor_msgs/msg/LaserScan"
        assert topics["/odom"] == "nav_msgs/msg/Odometry"
        assert topics["/amcl_pose"] == "geometry_msgs/msg/PoseWithCovarianceStamped"
        assert {"/tf", "/tf_static", "/ground_truth/pose"} <= set(topics)


@pytest.mark.parametrize("fmt", ["ros1", "ros2"])
def test_replay_of_recorded_localisation_gives_the_in_process_map(bag_run, fmt, tmp_path):
    root, ros1, ros2 = bag_run
    bag = (ros1 if fmt == "ros1" else ros2).paths["W2"]
    out = tmp_path / "replayed.yaml"
    # the run is the robot profile's: its pose check placed the localiser's poses where they
    # fit, so the replay of those poses asks the check to do the same with a log's poses
    # (which the profile takes as given), and to hold them as it did after a run of refusals;
    # the localiser's map -> odom moves only at its filter updates, so update smooths nothing
    check = PoseCheckConfig.profile("robot", {"refine_given": True, "lost_given": True})
    summary = update_from_log(root / "run" / "maps" / "M_W1.yaml", LogSource(bag), Outputs(out),
                              Placement(pose_check_config=check))
    assert summary["pose_source"] == "recorded" and summary["scans_corrected_by_pose_check"] > 0
    assert summary["smoothing"] == {"window_s": 2.0, "scans_smoothed": 0, "restarts": 0}
    in_process = load_map(root / "run" / "maps" / "M_W2.yaml")
    replayed = load_map(out)
    assert summary["cells_freed"] + summary["cells_occupied"] > 200
    assert np.array_equal(in_process.data, replayed.data)


def test_replay_with_this_projects_localiser_stays_close(bag_run, tmp_path):
    root, ros1, _ = bag_run
    out = tmp_path / "localised.yaml"
    assert main(["update", "--map", str(root / "run" / "maps" / "M_W1.yaml"), "--log",
                 str(ros1.paths["W2"]), "--out", str(out), "--poses", "localizer",
                 "--no-progress"]) == 0
    in_process = load_map(root / "run" / "maps" / "M_W2.yaml").data
    replayed = load_map(out).data
    # Another localiser run (its own seed) gives other poses: the maps agree on almost all
    # the cells the session changed.
    changed = in_process != load_map(root / "run" / "maps" / "M_W1.yaml").data
    assert (replayed[changed] == in_process[changed]).mean() > 0.9


def test_bag_clock_starts_at_a_realistic_epoch_not_at_zero(bag_run):
    # ROS 1 reads a stamp of 0 as "the latest" in tf lookups
    from robotlogs.rosbag import read_bag
    from scenarios.session_bags import BAG_EPOCH, DAY

    _, ros1, _ = bag_run
    times = [r.time for r in read_bag(ros1.paths["W2"], kinds=("scan", "tf"))]
    start = BAG_EPOCH + DAY          # W2 is session 1: a day after the epoch
    assert BAG_EPOCH == 1.7e9 and start <= min(times) < start + 1.0
    assert max(times) - min(times) > 10.0


def test_ros2_bag_names_its_data_file_after_the_bag_not_the_partial_folder(bag_run):
    import yaml

    from robotlogs.rosbag import read_bag

    _, _, ros2 = bag_run
    bag = ros2.paths["W2"]
    names = sorted(p.name for p in bag.iterdir())
    assert not [n for n in names if n.startswith(".")], names
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["relative_file_paths"] == ["W2.db3"] and "W2.db3" in names
    # no partial bag left beside the finished ones
    assert not [p.name for p in ros2.out_dir.iterdir() if p.name.startswith(".")]
    # the latched /tf_static is recorded as transient local, as ROS 2's broadcaster offers it
    tf_static = next(t for t in info["topics_with_message_count"]
                     if t["topic_metadata"]["name"] == "/tf_static")
    assert "durability: 1" in str(tf_static["topic_metadata"]["offered_qos_profiles"])
    assert len([r for r in read_bag(bag, kinds=("scan",))]) > 10


def test_bags_carry_the_sessions_map_latched_as_a_map_server_offers_it(bag_run):
    import yaml
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    root, ros1, ros2 = bag_run
    previous = load_map(root / "run" / "maps" / "M_W1.yaml")      # W2 starts from M1
    for rec in (ros1, ros2):
        assert bag_topics(rec.paths["W2"])["/map"] == "nav_msgs/msg/OccupancyGrid"
        with AnyReader([rec.paths["W2"]],
                       default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            (conn,) = [c for c in reader.connections if c.topic == "/map"]
            (_, _, raw), *rest = list(reader.messages(connections=[conn]))
            grid = reader.deserialize(raw, conn.msgtype)
        assert rest == [] and (grid.info.width, grid.info.height) == previous.shape[::-1]
        assert grid.info.resolution == pytest.approx(previous.resolution)
        assert np.array_equal(np.asarray(grid.data).reshape(previous.shape), previous.data)
    info = yaml.safe_load((ros2.paths["W2"] / "metadata.yaml").read_text())
    (topic,) = [t["topic_metadata"] for t in
                info["rosbag2_bagfile_information"]["topics_with_message_count"]
                if t["topic_metadata"]["name"] == "/map"]
    assert "durability: 1" in str(topic["offered_qos_profiles"])     # transient local


def test_sessions_replayed_one_recording_each_with_the_state_carried_give_the_chained_maps(
        tmp_path):
    """Three update sessions recorded as bags, then replayed one recording a session through
    `mapupdate update --state FILE --new-session` (the map of each the last one's output; the
    last without the flag, which that map implies):
    each map equals the chained run's, cell for cell, and the state file stays within a
    bound set by the map's size."""
    from updater import UpdaterConfig

    config = UpdaterConfig.profile("robot", {"move_faces": True})
    rec = SessionBagRecorder(tmp_path / "bags", "ros1")
    run_scenario(None, RunOptions(out=tmp_path / "run", quick=True, sessions=4, progress=False,
                                  observer=rec, updater_config=config))
    maps = tmp_path / "run" / "maps"
    (tmp_path / "cfg.yaml").write_text("pose_check:\n  refine_given: true\n  lost_given: true\n"
                                       "updater:\n  move_faces: true\n")
    state, previous, sizes = tmp_path / "life.npz", maps / "M_W1.yaml", []
    for name in ("W2", "W3", "W4"):
        out = tmp_path / f"{name}.yaml"
        # the last one without --new-session: the map the state's session made says it
        flag = ["--new-session"] if name != "W4" else []
        assert main(["update", "--map", str(previous), "--log", str(rec.paths[name]), "--out",
                     str(out), "--state", str(state), *flag, "--config",
                     str(tmp_path / "cfg.yaml"), "--smooth-poses", "0", "--no-progress"]) == 0
        assert np.array_equal(load_map(out).data, load_map(maps / f"M_{name}.yaml").data), name
        sizes.append(state.stat().st_size)
        previous = out
    # bounded: what it holds is a fixed number of bytes per cell (reference 1, buffers 2, hit
    # buffers 2, face counts 3), compressed; it grows with the cells seen, never past that
    cells = load_map(previous).data.size
    assert all(size <= 8 * cells for size in sizes), (sizes, cells)
    # the state carried something: the faces rule's counts of three sessions
    from updater import MapUpdater

    assert MapUpdater.load(state).carried_faces().hits.max() > 0


@pytest.mark.parametrize("fmt", ["ros1", "ros2"])
def test_a_recorded_scan_has_the_angles_and_limits_the_run_gave_the_updater(bag_run, fmt):
    """A LaserScan's angles and range limits are float32: the simulated scans carry them so,
    and a recording read back has the very beams the run's updater and localiser saw."""
    from robotlogs.records import ScanRecord
    from robotlogs.rosbag import read_bag
    from scenarios.catalog import find_scenario
    from sim import lidar
    from sim.scenario import load_scenario

    _, ros1, ros2 = bag_run
    spec = load_scenario(find_scenario()).robot.lidars[0]
    run = lidar.make_scan(np.zeros(spec.beams, np.float32), spec, 0.0)
    fields = ("angle_min", "angle_increment", "range_min", "range_max")
    assert all(getattr(run, f) == float(np.float32(getattr(run, f))) for f in fields)
    assert run.angle_min != -spec.fov / 2        # a float64 angle rounded, not the same
    bag = (ros1 if fmt == "ros1" else ros2).paths["W2"]
    scan = next(r.scan for r in read_bag(bag) if isinstance(r, ScanRecord))
    assert [getattr(scan, f) for f in fields] == [getattr(run, f) for f in fields]
