"""What the ROS 1 and ROS 2 nodes share (parameters, grid messages, health), without ROS."""

from types import SimpleNamespace as NS

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, GridError, MapUpdatingError, OccupancyGrid
from localization.confidence import PoseCheckConfig
from updater import UpdaterConfig
from onboard.ros_common.grids import changed_box, grid_from_message, message_fields
from onboard.ros_common.settings import (NodeSettings, NodeSettingsError, Ros2Settings,
                                       node_settings, refuse_saving_over_the_map)


def test_defaults_are_rosy_and_sections_reach_the_configs():
    settings, upd, check = node_settings({})
    assert (settings.map_frame, settings.odom_frame, settings.base_frame) == \
        ("map", "odom", "base_link")
    assert settings.scan_topics == ("scan",) and settings.publish_period == 1.0
    settings, upd, check = node_settings(
        {"updater": {"threshold": 9}, "pose_check": {"max_gain": 0.02},
         "scan_topics": ["front", "rear"], "publish_period": 2},
        base={"updater": {"threshold": 5, "min_run": 2}, "localizer": {"max_particles": 900}})
    assert upd.threshold == 9 and upd.min_run == 2          # parameters over the file
    assert check.max_gain == 0.02 and settings.scan_topics == ("front", "rear")
    assert settings.publish_period == 2.0


@pytest.mark.parametrize("params, words", [
    ({"updater": {"treshold": 5}}, ["unknown key 'treshold'", "did you mean 'threshold'"]),
    ({"pose_check": {"max_gian": 0.1}}, ["unknown key 'max_gian'", "'max_gain'"]),
    ({"map_frme": "world"}, ["unknown parameter '~map_frme'", "'map_frame'"]),
    ({"publish_period": -1.0}, ["'~publish_period'", "[0.01, 3600]"]),
    ({"publish_period": "fast"}, ["'~publish_period'"]),
    ({"queue_size": 0}, ["'~queue_size'"]),
    ({"scan_topics": []}, ["'~scan_topics'"]),
    ({"use_pose_check": "yes"}, ["'~use_pose_check'"]),
    ({"smooth_poses": 120.0}, ["'~smooth_poses'", "[0, 60]"]),
    ({"updater": 3}, ["'~updater' must be a mapping"]),
    ({"method": "fusse"}, ["parameter '~method': unknown method 'fusse'", "'fuse'",
                           "(methods: paper, fuse, hybrid)"]),
    ({"method": "remap"}, ["parameter '~method': unknown method 'remap'"]),
])
def test_bad_parameters_are_refused_with_a_line_that_names_them(params, words):
    with pytest.raises(MapUpdatingError) as e:
        node_settings(params)
    assert all(w in str(e.value) for w in words), str(e.value)
    assert "\n" not in str(e.value)


def test_node_settings_validate_on_their_own():
    with pytest.raises(NodeSettingsError, match="'~base_frame'"):
        NodeSettings(base_frame="")


def msg_of(grid: OccupancyGrid, yaw_w=1.0, yaw_z=0.0, data=None):
    f = message_fields(grid)
    origin = NS(position=NS(x=f["origin"][0], y=f["origin"][1]),
                orientation=NS(x=0.0, y=0.0, z=yaw_z, w=yaw_w))
    info = NS(width=f["width"], height=f["height"], resolution=f["resolution"], origin=origin)
    return NS(info=info, data=f["data"] if data is None else data)


def test_a_grid_survives_the_round_trip_through_message_fields():
    cells = np.array([[FREE, OCCUPIED, UNKNOWN], [UNKNOWN, FREE, FREE]], np.int8)
    grid = OccupancyGrid(cells, 0.05, (-1.0, 2.5))
    f = message_fields(grid)
    assert (f["width"], f["height"]) == (3, 2) and f["data"][:3] == [0, 100, -1]  # row 0 first
    back = grid_from_message(msg_of(grid))
    assert np.array_equal(back.data, cells) and back.origin == (-1.0, 2.5)


def test_probabilities_are_read_with_map_servers_thresholds_and_bad_maps_refused():
    grid = OccupancyGrid(np.zeros((1, 5), np.int8), 0.1, (0.0, 0.0))
    got = grid_from_message(msg_of(grid, data=[0, 19, 20, 65, -1])).data[0]
    assert list(got) == [FREE, FREE, UNKNOWN, OCCUPIED, UNKNOWN]
    with pytest.raises(GridError, match="rotated"):
        grid_from_message(msg_of(grid, yaw_w=0.7071, yaw_z=0.7071))
    with pytest.raises(GridError, match="4 cells, not width x height = 5 x 1"):
        grid_from_message(msg_of(grid, data=[0, 0, 0, 0]))


def test_changed_box_is_the_smallest_box_around_the_changes():
    a = np.zeros((6, 8), np.int8)
    b = a.copy()
    assert changed_box(a, b) is None
    b[1, 2] = 100
    b[4, 6] = -1
    assert changed_box(a, b) == (2, 1, 5, 4)       # x, y, width, height


def test_the_node_smooths_recorded_poses_as_mapupdate_update_does_by_default():
    from localization.smoothing import SMOOTH_WINDOW

    settings, _, _ = node_settings({})
    assert settings.smooth_poses == SMOOTH_WINDOW > 0
    assert node_settings({"smooth_poses": 0.0})[0].smooth_poses == 0.0


def test_the_node_lays_the_file_and_its_parameters_over_the_profile_key_by_key():
    """The robot profile (with the growth into the unknown), a ``--config`` file's keys over
    it, the node's parameters over those: a key left out keeps the profile's value, as for
    ``mapupdate update``; ``profile:=paper`` starts from the paper's."""
    from onboard.robot_config import POSE_CHECK_ON

    settings, updater, check = node_settings({})
    assert updater == UpdaterConfig.profile("robot") and updater.grow_into_unknown is True
    assert check == PoseCheckConfig.profile("robot")
    assert settings.profile == "robot" and settings.use_pose_check is POSE_CHECK_ON["robot"][0]
    assert node_settings({"updater": {"threshold": 6}})[1] == \
        UpdaterConfig.profile("robot", {"threshold": 6})
    from_file = node_settings({"updater": {"min_run": 4}}, {"updater": {"threshold": 6}})[1]
    assert from_file == UpdaterConfig.profile("robot", {"threshold": 6, "min_run": 4})
    settings, updater, check = node_settings({"profile": "paper"}, {"updater": {"threshold": 6}})
    assert updater == UpdaterConfig(threshold=6) and check == PoseCheckConfig()
    assert settings.use_pose_check is False
    assert node_settings({}, {"profile": "paper"})[0].profile == "paper"
    assert node_settings({"use_pose_check": False})[0].use_pose_check is False
    with pytest.raises(NodeSettingsError, match=r"parameter '~profile': unknown profile 'papr'"):
        node_settings({"profile": "papr"})


def test_the_method_is_the_papers_unless_the_parameter_names_another():
    assert node_settings({})[0].method == "paper"
    assert node_settings({"method": "hybrid"})[0].method == "hybrid"


def test_diagnostics_say_the_method_the_gates_refusals_by_rule_and_the_pending_cells():
    """What ``_publish`` hands to /diagnostics, built without ROS: a still robot's scans, the
    first processed, the rest refused by the robot's gate (no motion; the first of them confirms
    the map's surfaces it hits)."""
    from gridmap import Pose2D
    from onboard.methods import make_method
    from onboard.pipeline import RobotPipeline
    from onboard.ros_common.health import Health, pipeline_values
    from updater import UpdaterConfig

    import synthetic_room as world

    box = world.Rect(6.0, 5.0, 6.6, 5.6)
    ref = world.rasterise(world.room_walls() + [box])
    robot = Pose2D(3.0, 5.3, 0.0)
    values = {}
    for method in ("paper", "fuse", "paper's own"):
        config = UpdaterConfig() if method == "paper's own" else \
            UpdaterConfig.profile("robot")
        pipeline = RobotPipeline(make_method(method.split("'")[0], ref, config))
        for k in range(10):
            scan = world.full_scan(world.room_walls(), robot, 0.1 * k)
            pipeline.step(scan, Pose2D(0.0, 0.0, 0.0), odometry=robot, pose=robot)
        values[method] = dict(Health().values(pipeline_values(pipeline, method)))
    paper = values["paper"]
    assert paper["method"] == "paper" and paper["scans_processed"] == "1"
    assert paper["scans_gated"] == paper["gated_by: no motion"] == "9"
    # the first held-back scan confirms the surfaces it hits, the others nothing more until
    # a new view (gate_confirm_once)
    assert paper["scans_confirming"] == "1"
    # the box's face, seen once: a changed flag each, short of the threshold
    pending = int(paper["pending_cells"])
    assert pending == int(paper["pending_few_observations"]) > 5
    assert paper["pending_outvoted"] == "0"
    fuse = values["fuse"]
    assert fuse["method"] == "fuse" and fuse["gated_by: no motion"] == "9"
    assert "pending_cells" not in fuse          # log-odds mapping keeps no flag buffers
    own = values["paper's own"]                 # the authors' gate; flags not counted
    assert (own["gated_by: interval"], own["gated_by: no motion"]) == ("2", "7")
    assert int(own["pending_cells"]) == pending and "pending_few_observations" not in own
    assert "pose_check_lost" not in paper                # no pose check, nothing to hold


def test_diagnostics_say_when_the_pose_check_holds_every_scan_as_the_localiser_lost():
    """A second of poses a tenth of a metre off, then the right ones: /diagnostics shows the
    hold, and that it ends once the scans fit as before."""
    from gridmap import Pose2D
    from localization.confidence import PoseCheck, PoseCheckConfig
    from onboard.methods import make_method
    from onboard.pipeline import RobotPipeline
    from onboard.ros_common.health import Health, pipeline_values
    from updater import UpdaterConfig

    import synthetic_room as world

    ref = world.rasterise(world.room_walls())
    check = PoseCheck(ref, PoseCheckConfig.profile("robot"))
    pipeline = RobotPipeline(make_method("paper", ref, UpdaterConfig.profile("robot")),
                             pose_check=check)
    lost = []
    for k in range(60):
        truth = Pose2D(3.0 + 0.05 * k, 5.3, 0.0)
        told = Pose2D(truth.x + (0.3 if 10 <= k < 30 else 0.0), truth.y, truth.theta)
        pipeline.step(world.full_scan(world.room_walls(), truth, 0.1 * k), Pose2D(0, 0, 0),
                      odometry=truth, pose=told)
        lost.append(dict(Health().values(pipeline_values(pipeline, "paper")))
                    ["pose_check_lost"])
    assert lost[:10] == ["false"] * 10 and "true" in lost[10:30] and lost[-1] == "false"


def test_a_topic_named_twice_is_one_subscription_and_bad_names_are_refused():
    settings, _, _ = node_settings({"scan_topics": ["scan", "scan", "/front/scan"]})
    assert settings.scan_topics == ("scan", "/front/scan")
    for params, name in (({"scan_topics": ["sc an"]}, "scan_topics"),
                         ({"scan_topics": ["1scan"]}, "scan_topics"),
                         ({"scan_topics": ["a//b"]}, "scan_topics"),
                         ({"map_topic": "map/"}, "map_topic")):
        with pytest.raises(NodeSettingsError, match=f"'~{name}': .* is not a valid ROS topic"):
            node_settings(params)
    ros2, _, _ = node_settings({"pose_topic": "~/amcl_pose"}, None, Ros2Settings)
    assert ros2.pose_topic == "~/amcl_pose"
    with pytest.raises(NodeSettingsError, match="'~odom_topic'"):
        node_settings({"odom_topic": "odom topic"}, None, Ros2Settings)


@pytest.mark.parametrize("change, words", [
    ({"resolution": 1e-30}, "resolution must be in"),
    ({"resolution": 1e30}, "resolution must be in"),
    ({"resolution": float("nan")}, "resolution must be in"),
    ({"width": 8100, "height": 8100}, "more than the 64000000 cells"),
    ({"origin": (1e9, 0.0)}, "origin must lie within")])
def test_a_map_message_meets_the_limits_of_a_map_file(change, words):
    msg = msg_of(OccupancyGrid.empty(4, 3, 0.05))
    for key, value in change.items():
        if key == "origin":
            msg.info.origin.position.x, msg.info.origin.position.y = value
        else:
            setattr(msg.info, key, value)
    with pytest.raises(GridError, match=words):
        grid_from_message(msg)


def test_saving_over_the_input_map_is_refused_at_start(tmp_path):
    from gridmap import save_map

    save_map(OccupancyGrid.empty(4, 3, 0.05), tmp_path / "m.yaml")
    for clash in ("m.yaml", "m.pgm"):
        with pytest.raises(MapUpdatingError, match="input --map"):
            refuse_saving_over_the_map(str(tmp_path / clash), tmp_path / "m.yaml")
    refuse_saving_over_the_map(str(tmp_path / "other.yaml"), tmp_path / "m.yaml")
    refuse_saving_over_the_map(str(tmp_path / "m.yaml"), None)      # the map from its topic


def _edge(t, parent, child, x, y=0.0, th=0.0, static=False):
    from gridmap import Pose2D
    from robotlogs.records import TransformRecord
    return TransformRecord(t, parent, child, Pose2D(x, y, th), static=static)


def test_tf_poses_interpolate_compose_and_wait_for_the_localisers_correction():
    from onboard.ros_common.poses import TfPoses

    p = TfPoses("map", "odom", "base_link")
    p.add(_edge(0.0, "base_link", "laser", 0.25, static=True))
    for t, x in ((0.0, 0.0), (1.0, 1.0)):
        p.add(_edge(t, "odom", "base_link", x))
    assert p.ready(0.5)                          # no correction has come yet: odometry only
    p.add(_edge(0.0, "map", "odom", 10.0, 5.0, np.pi / 2))
    assert not p.ready(0.5)                      # amcl's correction of 0.5 or later not yet
    p.add(_edge(1.0, "map", "odom", 10.0, 5.0, np.pi / 2))
    assert p.ready(0.5) and not p.ready(1.0)     # odometry not past 1.0
    robot, odom = p.at(0.5)
    # by hand: odom x 0.5, turned a quarter and shifted by map -> odom
    assert (odom.x, odom.y) == pytest.approx((0.5, 0.0))
    assert (robot.x, robot.y, robot.theta) == pytest.approx((10.0, 5.5, np.pi / 2))
    assert p.mount("laser", 0.5)[0].x == pytest.approx(0.25)
    assert p.mount("elsewhere", 0.5) is None


def test_tf_poses_take_a_corrected_static_mount_and_stay_bounded():
    from onboard.ros_common.poses import TfPoses

    p = TfPoses("map", "odom", "base_link", keep=5.0)
    p.add(_edge(0.0, "base_link", "laser", 0.25, static=True))
    p.add(_edge(0.0, "base_link", "laser", 0.40, static=True))      # corrected
    assert p.mount("laser", 100.0)[0].x == pytest.approx(0.40)
    for k in range(2000):                        # 200 s of odometry at 10 Hz
        p.add(_edge(0.1 * k, "odom", "base_link", 0.01 * k))
    samples = p._edges["base_link"][1]
    assert len(samples) <= 2 * 5.0 / 0.1 + 2     # about the last 2 x keep seconds
    assert p.at(199.9)[1].x == pytest.approx(19.99)
    assert p.mount("laser", 199.9)[0].x == pytest.approx(0.40)      # static edges survive


def test_tf_poses_stay_bounded_when_the_odometry_never_comes():
    from onboard.ros_common.poses import TfPoses

    p = TfPoses("map", "odom", "base_misnamed", keep=5.0)
    for k in range(9000):                        # 30 s at 300 Hz, no odom -> base_misnamed
        p.add(_edge(k / 300, "odom", "base_link", 0.001 * k))
        p.add(_edge(k / 300, "map", "odom", 0.0))
    # about the last 2 x keep seconds of each edge, not all 18 000 transforms
    assert p.samples() <= 2 * (2 * 5.0 * 300 + 2)
    assert p.at(29.0) == (None, None)


def test_the_scan_queue_drops_the_oldest_past_its_count_or_its_memory():
    import array

    from onboard.ros_common.queue import ScanQueue, scan_bytes

    q = ScanQueue(max_items=3, max_bytes=10**9)
    assert [q.push(k, 10) for k in range(5)] == [0, 0, 0, 1, 1]
    assert [q.pop() for _ in range(len(q))] == [2, 3, 4] and q.bytes == 0
    big = scan_bytes(array.array("f", [1.0] * 250_000))          # rclpy: float32 array
    assert big == 256 + 4 * 250_000
    assert scan_bytes([1.0] * 1000, [0.5] * 1000) == 256 + 32 * 2000   # rospy: Python floats
    q = ScanQueue(max_items=5000, max_bytes=5 * big)
    dropped = sum(q.push(k, big) for k in range(100))
    assert len(q) == 5 and dropped == 95 and q.bytes <= 5 * big
    q = ScanQueue(max_items=10, max_bytes=1)                     # one scan past the bytes: kept
    assert q.push("huge", big) == 0 and len(q) == 1


def _quaternion(roll=0.0, pitch=0.0, yaw=0.0):
    """(x, y, z, w) of Rz(yaw) Ry(pitch) Rx(roll), the textbook formula."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def _rotation(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_quaternions_are_normalised_or_refused_as_tf2_does():
    from onboard.ros_common.transforms import TransformError, planar, unit_quaternion

    q = _quaternion(yaw=np.pi / 2)
    for scale in (2.0, 0.5):                     # the yaw 126.9 and 18.4 deg read before
        with pytest.raises(TransformError, match="not unit"):
            unit_quaternion(*(scale * v for v in q))
    with pytest.raises(TransformError, match="not unit"):
        unit_quaternion(0.0, 0.0, 0.0, 0.0)
    with pytest.raises(TransformError, match="not unit"):
        unit_quaternion(np.nan, 0.0, 0.0, 1.0)
    near = unit_quaternion(*(1.004 * v for v in q))   # |n^2 - 1| < 0.01: normalised
    assert np.linalg.norm(near) == pytest.approx(1.0)
    assert planar(0.0, 0.0, near)[0].theta == pytest.approx(np.pi / 2)


@pytest.mark.parametrize("roll, pitch, yaw, flipped, tilt", [
    (0.0, 0.0, 0.7, False, 0.0), (np.pi, 0.0, 0.0, True, 0.0), (np.pi, 0.0, -2.0, True, 0.0),
    (0.0, np.pi, 0.3, True, 0.0), (0.3, 0.0, 1.0, False, 0.3), (0.0, -0.2, 0.0, False, 0.2),
    (np.pi - 0.1, 0.0, 0.5, True, 0.1)])
def test_a_rotation_reduced_to_the_plane_says_upside_down_and_tilt(roll, pitch, yaw, flipped,
                                                                   tilt):
    from onboard.ros_common.transforms import planar

    q = _quaternion(roll, pitch, yaw)
    pose, upside_down, got_tilt = planar(1.0, 2.0, q)
    r = _rotation(q)
    # the yaw is where the frame's x axis points, seen from above
    assert pose.theta == pytest.approx(np.arctan2(r[1, 0], r[0, 0]))
    assert (pose.x, pose.y) == (1.0, 2.0)
    assert upside_down == flipped and got_tilt == pytest.approx(tilt, abs=1e-6)


def test_an_upside_down_mount_places_each_beam_where_the_3d_transform_does():
    from gridmap import Pose2D, Scan
    from onboard.ros_common.poses import TfPoses
    from onboard.ros_common.transforms import ascending, mirrored, planar

    # base -> plate (rolled by pi, 0.3 m up, turned 0.4) -> laser (0.1 forward, 0.05 left
    # of the plate, turned 0.2): the beams in 3D, against the node's planar reading
    plate_q, laser_q = _quaternion(np.pi, 0.0, 0.4), _quaternion(0.0, 0.0, 0.2)
    t = TfPoses("map", "odom", "base_link")
    for child, parent, xy, q in (("plate", "base_link", (0.2, -0.1), plate_q),
                                 ("laser", "plate", (0.1, 0.05), laser_q)):
        pose, flipped, tilt = planar(*xy, q)
        t.add(_edge(0.0, parent, child, pose.x, pose.y, pose.theta, static=True), flipped, tilt)
    mount, flipped = t.mount("laser", 1.0)
    assert flipped
    scan = Scan(np.array([1.0, 2.0, 3.0], np.float32), -0.5, 0.5, 0.1, 10.0, 1.0)
    seen = ascending(mirrored(scan))
    got = [(mount.x + r * np.cos(mount.theta + a), mount.y + r * np.sin(mount.theta + a))
           for r, a in zip(seen.ranges, seen.angles())]
    r_plate, r_laser = _rotation(plate_q), _rotation(laser_q)
    laser_in_base = np.array([0.2, -0.1, 0.0]) + r_plate @ np.array([0.1, 0.05, 0.0])
    truth = [laser_in_base + r_plate @ r_laser @ np.array([r * np.cos(a), r * np.sin(a), 0.0])
             for r, a in zip(scan.ranges, scan.angles())]
    assert np.allclose(sorted(got), sorted((p[0], p[1]) for p in truth))
    assert seen.angle_increment > 0 and mirrored(mirrored(scan)).angle_min == scan.angle_min


def test_a_tilted_mount_is_refused():
    from onboard.ros_common.poses import TfPoses
    from onboard.ros_common.transforms import TransformError, planar

    t = TfPoses("map", "odom", "base_link")
    pose, flipped, tilt = planar(0.2, 0.0, _quaternion(0.0, 0.3, 0.0))   # pitched 17 deg
    t.add(_edge(0.0, "base_link", "laser", pose.x, pose.y, pose.theta, static=True), flipped,
          tilt)
    with pytest.raises(TransformError, match="tilted 17.2 deg"):
        t.mount("laser", 0.0, max_tilt=0.05)


def test_a_clockwise_scan_is_the_same_beams_reversed():
    from gridmap import Scan
    from onboard.ros_common.transforms import ascending

    cw = Scan(np.array([1.0, 2.0, 3.0, 4.0], np.float32), 1.0, -0.25, 0.1, 10.0)
    ccw = ascending(cw)
    assert ccw.angle_increment == 0.25 and ccw.angle_min == pytest.approx(0.25)
    pairs = sorted(zip(cw.angles().round(9), cw.ranges))
    assert pairs == sorted(zip(ccw.angles().round(9), ccw.ranges))


def test_sequence_gaps_count_the_messages_lost_on_the_way():
    from onboard.ros_common.gaps import Gaps

    g = Gaps()
    seen = [g.see("a", n) for n in (1, 2, 5, 6, 10)] + [g.see("b", n) for n in (7, 9)]
    assert seen == [0, 0, 2, 0, 3, 0, 1] and g.lost == 6
    assert g.see("a", 1) == 0 and g.see("a", 3) == 1         # a publisher started again
    assert g.see("c", 2**64 - 1) == 0 and g.lost == 7         # not numbered: not counted


def test_oversize_scans_and_scans_of_more_than_a_turn_are_skipped():
    from onboard.ros_common.scans import usable_scan

    def scan(n, increment):
        return NS(header=NS(stamp=NS(sec=5, nanosec=0), frame_id="laser"), ranges=[1.0] * n,
                  angle_min=0.0, angle_increment=increment,
                  angle_max=(n - 1) * increment, range_min=0.1, range_max=10.0, intensities=[])

    assert usable_scan(scan(1000, 0.006), "/scan")[1] is None
    assert usable_scan(scan(1000, 0.006), "/scan", max_beams=999)[1][0] == \
        "scan with more beams than max_beams"
    assert usable_scan(scan(1000, -0.006), "/scan")[1] is None          # clockwise: fine
    assert usable_scan(scan(360, 2 * np.pi / 360), "/scan")[1] is None   # one whole turn
    assert usable_scan(scan(1000, 1.08), "/scan")[1][0] == "scan spanning more than one turn"


def test_the_save_path_is_checked_at_start(tmp_path):
    from onboard.ros_common.settings import check_save_path

    check_save_path(str(tmp_path / "map.yaml"))
    for path, words in (("/", "folder"), (str(tmp_path), "folder"),
                        (str(tmp_path / "none" / "map.yaml"), "does not exist")):
        with pytest.raises(NodeSettingsError, match=words):
            check_save_path(path)
