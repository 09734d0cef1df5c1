"""The live ROS 2 node in a real ROS 2 graph (ROS 2 Jazzy's wheels in .venv-ros2, a domain of
its own): a W2 recording replayed into it by a separate rclpy process, its poses on /tf and
/tf_static or on /amcl_pose and /odom, gives the map `mapupdate update` makes of that
recording, cell for cell, and the costmap's updates rebuild it; a subscriber of another DDS
implementation (cyclonedds) that joins late receives the latched map; the lifecycle transitions
in and out of order; commit, reset and a misspelt parameter; bad traffic counted. Skipped, with
the reason, where the wheels cannot be had."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from gridmap import load_map, save_map
from mapupdate import main
from updater import MapUpdater

import ros2_tools

pytestmark = pytest.mark.skipif(bool(ros2_tools.missing()),
                                reason=ros2_tools.missing() or "-")
NODE = "/map_updater"
MOUNT = "laser_mount:=[0.25, 0.0, 0.0]"          # the simulated robot's lidar (its /tf_static)
AMCL = "pose_source:=amcl_pose"
needs_tf = pytest.mark.skipif(bool(ros2_tools.missing_tf()), reason=ros2_tools.missing_tf() or "-")
CONFIGURE, CLEANUP, ACTIVATE, DEACTIVATE = 1, 2, 3, 4   # lifecycle_msgs/msg/Transition


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    g = ros2_tools.Graph(tmp_path_factory.mktemp("ros2"))
    yield g
    g.close()


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """W2 of the warehouse (quick route) as `mapupdate run --bag` writes it, and the map
    `mapupdate update` makes of it."""
    root = tmp_path_factory.mktemp("run")
    assert main(["run", "--quick", "--sessions", "2", "--bag", str(root / "bags"), "--out",
                 str(root / "run"), "--no-progress"]) == 0
    assert main(["update", "--map", str(root / "run/maps/M_W1.yaml"), "--log",
                 str(root / "bags/W2.bag"), "--out", str(root / "update.yaml"),
                 "--no-progress"]) == 0
    return root


def transition(graph, node: str, transition_id: int) -> bool:
    answer = graph.call(f"{node}/change_state", "lifecycle_msgs.srv.ChangeState",
                        {"transition.id": transition_id})
    return answer["success"]


def state(graph, node: str) -> str:
    return graph.call(f"{node}/get_state", "lifecycle_msgs.srv.GetState")["current_state"][
        "label"]


UPDATES_LISTENER = """
import os, sys
import numpy as np
import rclpy
from map_msgs.msg import OccupancyGridUpdate
from nav_msgs.msg import OccupancyGrid
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

out = sys.argv[1]
rclpy.init()
node = rclpy.create_node("costmap_like")
state = {"grid": None, "updates": 0}

def keep():
    np.save(out + ".tmp.npy", state["grid"])
    os.replace(out + ".tmp.npy", out + f".{state['updates']}.npy")

def on_map(m):
    if state["grid"] is None:           # the first map only: the rest must come as updates
        state["grid"] = np.asarray(m.data, np.int8).reshape(m.info.height, m.info.width)
        keep()

def on_update(u):
    state["updates"] += 1
    state["grid"][u.y:u.y + u.height, u.x:u.x + u.width] = np.asarray(
        u.data, np.int8).reshape(u.height, u.width)
    keep()

latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
node.create_subscription(OccupancyGrid, "map_updated", on_map, latched)
node.create_subscription(OccupancyGridUpdate, "map_updated_updates", on_update, 10)
rclpy.spin(node)
"""


def _start(graph, recording, name: str, *params):
    node = graph.node("--map", recording / "run/maps/M_W1.yaml", "--autostart", "--ros-args",
                      "-r", f"__node:={name}", *params, name=name)
    graph.wait_for_service(f"/{name}/get_state", timeout=180)   # a cold numba cache compiles
    assert state(graph, f"/{name}") == "active"
    return node


def _replay_and_save(graph, recording, name: str, poses: str, *params, listen=False,
                     play=()) -> dict:
    save = graph.folder / f"{name}.yaml"
    # a scan waits up to tf_timeout for odometry that a loaded machine delivers late, then is
    # placed without it; a second rather than 0.2 s keeps the replay's map the offline one there
    node = _start(graph, recording, name, "-p", "tf_timeout:=1.0", *params, "-p",
                  f"save_path:={save}")
    listener = None
    if listen:
        listener = graph.start(["-c", UPDATES_LISTENER, graph.folder / f"{name}-costmap"],
                               f"{name}-costmap")
        ros2_tools.wait_until(lambda: list(graph.folder.glob(f"{name}-costmap.0.npy")), 60,
                              "the costmap-like listener's first map")
    graph.replay(recording / "bags/W2.bag", 4.0, poses, *play)
    assert graph.call(f"/{name}/save")["success"]
    if listener is not None:
        time.sleep(2.0)                                         # the last period's update
        graph.stop(listener)
    return {"node": node, "saved": load_map(save).data}


@pytest.fixture(scope="module")
def replayed(graph, recording):
    """The node on M1, W2 replayed into it at four times real time, its poses on /tf and
    /tf_static; the map it saved. The default name, as the other tests address it."""
    if ros2_tools.missing_tf():
        pytest.skip(ros2_tools.missing_tf())
    yield _replay_and_save(graph, recording, "map_updater", "tf", listen=True)


@needs_tf
def test_the_node_saves_the_map_mapupdate_update_makes_of_the_same_recording(replayed,
                                                                             recording):
    expected = load_map(recording / "update.yaml").data
    reference = load_map(recording / "run/maps/M_W1.yaml").data
    assert (expected != reference).sum() > 300                  # W2 changed the map
    assert np.array_equal(replayed["saved"], expected)          # cell for cell


@needs_tf
def test_the_costmaps_updates_rebuild_the_map_from_the_first_one(replayed, graph):
    kept = sorted(graph.folder.glob("map_updater-costmap.*.npy"),
                  key=lambda f: int(f.name.split(".")[1]))
    assert len(kept) > 2                                        # the first map, then updates
    rebuilt = np.load(kept[-1])
    assert np.array_equal(rebuilt, replayed["saved"])


DIAGNOSTICS = """
import json, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
name = sys.argv[1]
rclpy.init()
node = rclpy.create_node("diagnostics_reader")
seen = {}
node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: seen.update(
    {s.name: {v.key: v.value for v in s.values} | {"_message": s.message} for s in m.status}), 10)
end = time.monotonic() + 30
while f"/{name}: health" not in seen and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.2)
print(json.dumps(seen.get(f"/{name}: health", {})))
"""


def health(graph, name: str) -> dict:
    return json.loads(graph.script(DIAGNOSTICS, name).strip().splitlines()[-1])


@needs_tf
def test_an_upside_down_lidar_gives_the_upright_lidars_map_to_the_cell_and_a_restart_resumes(
        graph, recording, tmp_path):
    # the same recording, its lidar mounted rolled by pi (/tf_static's quaternion (1, 0, 0, 0)
    # at yaw 0) and each scan as that lidar sees the same beams; read upright it lost 318 of
    # 590 scans and missed the right map by 10 767 cells. In a graph of its own: the other
    # nodes would hear this replay too
    own = ros2_tools.Graph(tmp_path, other_than=graph)
    name, save = "flipped_probe", tmp_path / "flipped_probe.yaml"
    try:
        got = _replay_and_save(own, recording, name, "tf", play=["--flip-laser"])
        values = health(own, name)
        expected = load_map(recording / "update.yaml").data
        assert np.array_equal(got["saved"], expected)
        # killed, then started again on the same save_path: it resumes from its map and
        # buffers (before, its first save wrote the input map over the updated one)
        ros2_tools.os.killpg(got["node"].pid, ros2_tools.signal.SIGKILL)
        again = _start(own, recording, name, "-p", f"save_path:={save}")
        assert health(own, name)["resumed"] == "1"
        assert own.call(f"/{name}/save")["success"]
        assert np.array_equal(load_map(save).data, expected)
        assert own.stop(again) == 0
        # with another configuration its buffers cannot be resumed: the map is not written over
        third = _start(own, recording, name, "-p", f"save_path:={save}", "-p",
                       "updater.threshold:=9")
        answer = own.call(f"/{name}/save")
        assert not answer["success"] and "is not written over" in answer["message"]
        assert np.array_equal(load_map(save).data, expected)
        assert own.stop(third) == 0
    finally:
        own.close()
    assert values["scans_upside_down"] == values["scans_used"] == "590"
    assert values["scans_dropped_as_lost"] == "0"


CYCLONE_READER = """
import json, os, sys
from dataclasses import dataclass
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float32, float64, int8, int32, sequence, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32

@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_
    frame_id: str

@dataclass
class Point_(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64

@dataclass
class Quaternion_(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64

@dataclass
class Pose_(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point_
    orientation: Quaternion_

@dataclass
class MapMetaData_(IdlStruct, typename="nav_msgs::msg::dds_::MapMetaData_"):
    map_load_time: Time_
    resolution: float32
    width: uint32
    height: uint32
    origin: Pose_

@dataclass
class OccupancyGrid_(IdlStruct, typename="nav_msgs::msg::dds_::OccupancyGrid_"):
    header: Header_
    info: MapMetaData_
    data: sequence[int8]

participant = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
topic = Topic(participant, "rt/map_updated", OccupancyGrid_)
qos = Qos(Policy.Durability.TransientLocal, Policy.Reliability.Reliable(duration(seconds=1)),
          Policy.History.KeepLast(1))
reader = DataReader(participant, topic, qos=qos)
for grid in reader.take_iter(timeout=duration(seconds=30)):
    info = grid.info
    print(json.dumps({"frame": grid.header.frame_id, "width": info.width, "height": info.height,
                      "resolution": info.resolution, "origin": [info.origin.position.x,
                      info.origin.position.y], "data": list(grid.data)}))
    break
"""


def test_a_late_subscriber_of_another_dds_gets_the_latched_updated_map(replayed, graph,
                                                                      recording):
    got = json.loads(graph.script(CYCLONE_READER, timeout=90).strip().splitlines()[-1])
    reference = load_map(recording / "run/maps/M_W1.yaml")
    h, w = reference.shape
    assert (got["width"], got["height"], got["frame"]) == (w, h, "map")
    assert got["resolution"] == pytest.approx(reference.resolution)
    assert got["origin"] == pytest.approx(list(reference.origin))
    cells = np.asarray(got["data"], np.int8).reshape(h, w)
    assert np.array_equal(cells, replayed["saved"])             # the changed cells with it


def test_reset_and_commit_do_what_they_say(replayed, graph, recording):
    save = graph.folder / "map_updater.yaml"
    reference = load_map(recording / "run/maps/M_W1.yaml").data
    assert graph.call(f"{NODE}/reset")["success"]              # buffers cleared: M1 again
    assert graph.call(f"{NODE}/save")["success"]
    assert np.array_equal(load_map(save).data, reference)
    assert graph.call(f"{NODE}/commit")["success"]             # now the reference
    assert graph.call(f"{NODE}/save")["success"]
    assert np.array_equal(load_map(save).data, reference)


@needs_tf
def test_commit_carries_the_faces_counts_as_update_state_does_and_reset_clears_them(
        graph, recording, tmp_path):
    # the faces rule counts scans the pose check placed: with poses given on /tf, only with
    # pose_check.refine_given. In a graph of its own: the other nodes would hear this replay
    config = tmp_path / "refine.yaml"
    config.write_text("pose_check:\n  refine_given: true\n")
    state = tmp_path / "W2.state.npz"
    assert main(["update", "--map", str(recording / "run/maps/M_W1.yaml"), "--log",
                 str(recording / "bags/W2.bag"), "--out", str(tmp_path / "u.yaml"), "--state",
                 str(state), "--config", str(config), "--no-progress"]) == 0
    carried = MapUpdater.load(state).carried_faces().cells
    assert carried > 1000
    own = ros2_tools.Graph(tmp_path, other_than=graph)
    name = "carrier"
    try:
        got = _replay_and_save(own, recording, name, "tf", "-p",
                               "pose_check.refine_given:=true")
        assert np.array_equal(got["saved"], load_map(tmp_path / "u.yaml").data)
        assert own.call(f"/{name}/commit")["success"]          # the next session
        assert int(health(own, name)["face_cells_carried"]) == carried
        assert own.call(f"/{name}/reset")["success"]
        assert int(health(own, name)["face_cells_carried"]) == 0
        # killed, then started on the map it saved (a copy, as map_server would serve it):
        # the next session after the saved one, its counts carried, its saves written over
        ros2_tools.os.killpg(got["node"].pid, ros2_tools.signal.SIGKILL)
        today = tmp_path / "today.yaml"
        save_map(load_map(own.folder / f"{name}.yaml"), today)
        again = own.node("--map", today, "--autostart", "--ros-args", "-r", f"__node:={name}",
                         "-p", f"save_path:={own.folder / f'{name}.yaml'}", "-p",
                         "pose_check.refine_given:=true", name=name)
        own.wait_for_service(f"/{name}/get_state", timeout=180)
        values = health(own, name)
        assert int(values["face_cells_carried"]) == carried and "resumed" not in values
        assert own.call(f"/{name}/save")["success"]
        assert np.array_equal(load_map(own.folder / f"{name}.yaml").data, got["saved"])
        assert own.stop(again) == 0
    finally:
        own.close()


LIFECYCLE = """
import json, sys
import rclpy
from lifecycle_msgs.srv import ChangeState, GetState
node_name, steps = sys.argv[1], json.loads(sys.argv[2])
rclpy.init()
client = rclpy.create_node("lifecycle_client")
change = client.create_client(ChangeState, f"/{node_name}/change_state")
get = client.create_client(GetState, f"/{node_name}/get_state")
assert change.wait_for_service(timeout_sec=60) and get.wait_for_service(timeout_sec=60)

def call(c, request, tries=1):
    # a service found may not answer its first request yet (the reply's reader not yet
    # matched): the idempotent first get_state is asked again until it is answered
    for _ in range(tries):
        future = c.call_async(request)
        rclpy.spin_until_future_complete(client, future, timeout_sec=30 if tries == 1 else 10)
        if future.done():
            return future.result()
        c.remove_pending_request(future)
    raise SystemExit(f"no answer from {c.srv_name}")

out = [call(get, GetState.Request(), tries=9).current_state.label]
for transition_id in steps:
    request = ChangeState.Request()
    request.transition.id = transition_id
    ok = call(change, request).success
    out.append([ok, call(get, GetState.Request()).current_state.label])
print(json.dumps(out))
"""


def test_lifecycle_transitions_in_order_and_out_of_order(graph, recording):
    name = "lifecycle_probe"
    node = graph.node("--map", recording / "run/maps/M_W1.yaml", "--ros-args", "-r",
                      f"__node:={name}", "-p", MOUNT, name=name)
    steps = [ACTIVATE, CONFIGURE, ACTIVATE, CONFIGURE, DEACTIVATE, CLEANUP, CONFIGURE]
    seen = json.loads(graph.script(LIFECYCLE, name, json.dumps(steps)).strip().splitlines()[-1])
    assert seen == ["unconfigured",
                    [False, "unconfigured"],     # activate before configure: refused
                    [True, "inactive"], [True, "active"],
                    [False, "active"],           # configure while active: refused
                    [True, "inactive"], [True, "unconfigured"],
                    [True, "inactive"]]          # configured again after a cleanup
    assert graph.stop(node) == 0
    log = graph.log(name)
    assert "refused: not available in state 'unconfigured'" in log and "Traceback" not in log


def test_a_misspelt_parameter_fails_configure_with_the_nearest_name(graph, recording):
    name = "typo_probe"
    node = graph.node("--map", recording / "run/maps/M_W1.yaml", "--autostart", "--ros-args",
                      "-r", f"__node:={name}", "-p", "updater.treshold:=5", name=name)
    assert node.wait(90) == 2
    log = graph.log(name)
    assert "unknown key 'treshold'" in log and "did you mean 'threshold'" in log
    assert "mapupdate ros2: error: the node did not come up: configure failed: node " \
           "parameters: unknown key 'treshold'" in log
    assert "Traceback" not in log


BAD_TRAFFIC = """
import json, math, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

node_name = sys.argv[1]
rclpy.init()
node = rclpy.create_node("bad_traffic")
latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
scans = node.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
odom = node.create_publisher(Odometry, "odom", 50)
amcl = node.create_publisher(PoseWithCovarianceStamped, "amcl_pose", latched)
seen = {}
node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: seen.update(
    {s.name: {v.key: v.value for v in s.values} | {"_level": int.from_bytes(s.level, "little")
     if isinstance(s.level, bytes) else int(s.level)} for s in m.status}), 10)
end = time.monotonic() + 60
while min(p.get_subscription_count() for p in (scans, odom, amcl)) == 0:
    rclpy.spin_once(node, timeout_sec=0.1)
    assert time.monotonic() < end, "the node never subscribed"
for _ in range(10):                        # the node's side of the match too (best effort)
    rclpy.spin_once(node, timeout_sec=0.1)
t0 = node.get_clock().now().nanoseconds / 1e9

def stamped(msg, t):
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    return msg

def scan(t, ranges, increment=0.01):
    m = stamped(LaserScan(), t)
    m.header.frame_id = "laser"
    m.angle_min, m.angle_increment = -0.5, increment
    m.angle_max = -0.5 + (len(ranges) - 1) * increment
    m.range_min, m.range_max, m.ranges = 0.05, 20.0, ranges
    return m

def pose(msg, target, x):
    target.position.x, target.orientation.w = x, 1.0
    return msg

a = stamped(PoseWithCovarianceStamped(), t0)
amcl.publish(pose(a, a.pose.pose, 0.0))
for _ in range(5):                         # the localisation first, as a robot has it
    rclpy.spin_once(node, timeout_sec=0.1)
bad_a = stamped(PoseWithCovarianceStamped(), t0 + 0.05)
amcl.publish(pose(bad_a, bad_a.pose.pose, math.inf))             # a localisation of inf
for k, t in enumerate((t0, t0 + 0.1, t0 + 0.2)):
    o = stamped(Odometry(), t)
    odom.publish(pose(o, o.pose.pose, 0.01 * k))
bad_o = stamped(Odometry(), t0 + 0.15)
odom.publish(pose(bad_o, bad_o.pose.pose, math.nan))             # odometry of NaN
scans.publish(scan(t0 + 0.05, [1.0] * 101, increment=0.0))       # angles that go nowhere
scans.publish(scan(t0 + 0.06, []))                               # no beams
scans.publish(scan(t0 + 0.07, [math.nan] * 50 + [2.0] * 51))     # NaN beams: invalid, used
scans.publish(scan(t0 + 0.08, [2.0] * 101, increment=1e-12))     # 1e11 beams' window: clamped
scans.publish(scan(0.0, [2.0] * 101))                             # stamped 0: said, skipped
o = stamped(Odometry(), t0 + 0.3)
odom.publish(pose(o, o.pose.pose, 0.03))
end = time.monotonic() + 30
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.2)
    values = seen.get(f"/{node_name}: health", {})
    if values.get("scans_received") == "5" and values.get("scans_used") == "2":
        break
print(json.dumps(values))
"""


def test_malformed_traffic_is_counted_and_skipped_never_a_crash(graph, recording):
    name = "bad_probe"
    node = graph.node("--map", recording / "run/maps/M_W1.yaml", "--autostart", "--ros-args",
                      "-r", f"__node:={name}", "-p", MOUNT, "-p", AMCL, "-p",
                      "publish_period:=0.2", name=name)
    values = json.loads(graph.script(BAD_TRAFFIC, name, timeout=120).strip().splitlines()[-1])
    assert values["skipped: malformed scan"] == "1"
    assert values["skipped: empty scan"] == "1"
    assert values["skipped: scan stamped 0"] == "1"
    assert values["skipped: odometry not finite"] == "1"
    assert values["skipped: localisation not finite"] == "1"
    assert values["scans_with_bad_ranges"] == "1" and values["scans_used"] == "2"
    assert values["_level"] == 1                                  # WARN
    assert node.poll() is None and graph.stop(node) == 0
    assert "Traceback" not in graph.log(name)


def test_the_player_refuses_a_missing_bag_or_an_absurd_rate_in_one_line(graph, recording):
    import subprocess

    for args, words in (([graph.folder / "nope.bag"], "no such bag"),
                        ([recording / "bags/W2.bag", "--rate", "-1"], "--rate must be")):
        p = subprocess.run([str(ros2_tools.PYTHON), str(ros2_tools.PLAY), *map(str, args)],
                           env=graph.env, capture_output=True, text=True, timeout=120)
        assert p.returncode == 2 and p.stderr.strip().splitlines() == [
            next(line for line in p.stderr.splitlines() if words in line)]


TF_TRAFFIC = """
import json, math, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

node_name = sys.argv[1]
rclpy.init()
node = rclpy.create_node("tf_traffic")
latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
scans = node.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
tf = node.create_publisher(TFMessage, "/tf", 100)
tf_static = node.create_publisher(TFMessage, "/tf_static", latched)
seen = {}
node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: seen.update(
    {s.name: {v.key: v.value for v in s.values} for s in m.status}), 10)
end = time.monotonic() + 60
while min(p.get_subscription_count() for p in (scans, tf, tf_static)) == 0:
    rclpy.spin_once(node, timeout_sec=0.1)
    assert time.monotonic() < end, "the node never subscribed"
for _ in range(30):                        # the node's side of the match (best effort)
    rclpy.spin_once(node, timeout_sec=0.1)
t0 = node.get_clock().now().nanoseconds / 1e9

def stamped(msg, t):
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    return msg

def edge(t, parent, child, x):
    e = stamped(TransformStamped(), t)
    e.header.frame_id, e.child_frame_id = parent, child
    e.transform.translation.x, e.transform.rotation.w = x, 1.0
    return e

def send(pub, *edges):
    m = TFMessage()
    m.transforms = list(edges)
    pub.publish(m)
    for _ in range(3):
        rclpy.spin_once(node, timeout_sec=0.05)

def scan(t):
    m = stamped(LaserScan(), t)
    m.header.frame_id = "laser"
    m.angle_min, m.angle_increment, m.angle_max = -0.5, 0.01, 0.5
    m.range_min, m.range_max, m.ranges = 0.05, 20.0, [2.0] * 101
    scans.publish(m)

send(tf_static, edge(t0, "base_link", "camera", 0.1))      # no laser in the static tf yet
for k in range(3):
    send(tf, edge(t0 + 0.1 * k, "odom", "base_link", 0.01 * k),
         edge(t0 + 0.1 * k, "map", "odom", 0.0))
scan(t0 + 0.05)                                             # no base_link -> laser: skipped
send(tf, edge(t0 + 0.25, "odom", "base_link", math.inf))    # not finite: the message skipped
send(tf_static, edge(t0, "base_link", "laser", 0.25))       # the mount arrives: counts from now
for k in range(3, 6):
    send(tf, edge(t0 + 0.1 * k, "odom", "base_link", 0.01 * k),
         edge(t0 + 0.1 * k, "map", "odom", 0.0))
scan(t0 + 0.35)                                             # placed: used
send(tf, edge(t0 + 0.6, "odom", "base_link", 0.06), edge(t0 + 0.6, "map", "odom", 0.0))
end = time.monotonic() + 30
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.2)
    values = seen.get(f"/{node_name}: health", {})
    if values.get("scans_received") == "2" and values.get("scans_used") == "1":
        break
print(json.dumps(values))
"""


@needs_tf
def test_tf_traffic_a_late_mount_and_a_transform_of_inf_are_counted(graph, recording):
    name = "tf_probe"
    node = graph.node("--map", recording / "run/maps/M_W1.yaml", "--autostart", "--ros-args",
                      "-r", f"__node:={name}", "-p", "publish_period:=0.2", "-p",
                      "tf_timeout:=0.1", name=name)
    values = json.loads(graph.script(TF_TRAFFIC, name, timeout=120).strip().splitlines()[-1])
    assert values["scans_received"] == "2" and values["scans_used"] == "1"
    assert values["skipped: no transform from the base to the scan's frame"] == "1"
    assert values["skipped: transform not finite"] == "1"
    assert node.poll() is None and graph.stop(node) == 0
    assert "Traceback" not in graph.log(name)


def test_pose_source_tf_without_tf2_msgs_or_a_bad_source_fails_configure(graph, recording):
    name = "source_probe"
    node = graph.node("--map", recording / "run/maps/M_W1.yaml", "--autostart", "--ros-args",
                      "-r", f"__node:={name}", "-p", "pose_source:=gps", name=name)
    assert node.wait(90) == 2
    log = graph.log(name)
    assert "parameter 'pose_source' must be one of tf, amcl_pose, got 'gps'" in log
    assert "Traceback" not in log


# last: the other nodes of the graph hear this replay too, and the default node keeps the first
# replay's tf, which the same stamps would find again
@pytest.mark.slow          # a second whole replay: the same arithmetic as tf's, by other topics
def test_with_amcl_pose_and_odometry_the_same_map(graph, recording):
    got = _replay_and_save(graph, recording, "amcl_probe", "amcl_pose", "-p", AMCL, "-p", MOUNT)
    assert np.array_equal(got["saved"], load_map(recording / "update.yaml").data)
    assert graph.stop(got["node"]) == 0


def test_with_a_store_the_node_commits_versions_and_serves_the_latest_approved(graph,
                                                                              recording):
    from mapstore import open_store

    db, save = graph.folder / "maps.db", graph.folder / "store_probe.yaml"
    with open_store(db, create=True) as store:
        store.set_require_approval(True)
    name = "store_probe"
    node = graph.node("--map", recording / "run/maps/M_W1.yaml", "--autostart", "--ros-args",
                      "-r", f"__node:={name}", "-p", f"store:={db}", "-p", "robot_name:=amr-9",
                      "-p", "store_poll_period:=0.3", "-p", "publish_period:=0.2", "-p",
                      f"save_path:={save}", name=name)
    graph.wait_for_service(f"/{name}/get_state", timeout=180)
    with open_store(db) as store:                       # the empty store took the map as v1
        assert store.latest() == 1 and store.version(1).status == "approved"
    answer = graph.call(f"/{name}/commit")
    assert answer["success"] and "committed v2, pending review" in answer["message"]
    with open_store(db) as store:                       # another robot's version, approved
        assert store.version(2).status == "pending"
        assert store.version(2).meta["robot"] == "amr-9"
        first = store.get(1)
        data = first.data.copy()
        data[100:110, 100:110] = 100
        v3 = store.commit(first.with_data(data), 1, {"robot": "amr-2"})
        store.approve(v3)

    def serves_v3():
        return graph.call(f"/{name}/save")["success"] and np.array_equal(
            load_map(save).data, data)

    ros2_tools.wait_until(serves_v3, 60, "the node serving the approved v3")
    assert node.poll() is None and graph.stop(node) == 0
    assert "Traceback" not in graph.log(name)


@needs_tf
def test_a_parameter_at_its_profile_value_gives_the_map_the_profile_gives(graph, recording):
    """Parameters are laid over the profile key by key: one updater key at the robot
    profile's value gives the map of no parameter (`mapupdate update`'s), and with the paper profile the node saves the
    map `mapupdate update --profile paper` makes."""
    one_key = _replay_and_save(graph, recording, "one_key", "tf", "-p", "updater.threshold:=7")
    graph.stop(one_key["node"])
    # on a loaded machine a scan whose transform came late may be skipped: a few cells of the
    # hundreds the update changes may differ (none on a quiet one)
    expected = load_map(recording / "update.yaml").data
    changed = int((expected != load_map(recording / "run/maps/M_W1.yaml").data).sum())
    assert changed > 300 and (one_key["saved"] != expected).sum() <= 0.02 * changed
    paper = _replay_and_save(graph, recording, "paper_profile", "tf", "-p", "profile:=paper",
                             "-p", "updater.threshold:=7")
    graph.stop(paper["node"])
    expected = recording / "update_paper.yaml"
    assert main(["update", "--map", str(recording / "run/maps/M_W1.yaml"), "--log",
                 str(recording / "bags/W2.bag"), "--out", str(expected), "--profile", "paper",
                 "--no-progress"]) == 0
    # the profiles themselves differ by far more than a late transform makes
    off = int((paper["saved"] != load_map(expected).data).sum())
    between = int((paper["saved"] != one_key["saved"]).sum())
    assert between > 100 and off <= 0.05 * between, (off, between)
