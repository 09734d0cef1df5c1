"""The ROS 2 node as a Nav2 user meets it, in a real ROS 2 graph (ROS 2 Jazzy's wheels in
.venv-ros2, a domain of its own): the package built by colcon and its installed executable
brought up by a lifecycle manager that does what Nav2's does, bond included, which sees the
node killed; the lifecycle interface without rclpy's private API; parameters declared from
the start with their ranges, given as Nav2 users give them, and each bad one refused in one
line; the state the node keeps (a switched map followed, services refused while inactive, the
shutdown transition ending the process). Skipped, with the reason, where the wheels cannot be
had."""

from __future__ import annotations

import ast
import json
import signal
import subprocess
import time

import numpy as np
import pytest

from gridmap import OccupancyGrid, load_map, save_map

import ros2_tools

pytestmark = pytest.mark.skipif(bool(ros2_tools.missing_tf()),
                                reason=ros2_tools.missing_tf() or "-")
PACKAGE = ros2_tools.ROOT / "ros" / "ros2" / "lidar_map_updating"
MANAGER = ros2_tools.ROOT / "tests" / "nav2_like_manager.py"
CONFIGURE, ACTIVATE, INACTIVE_SHUTDOWN = 1, 3, 6


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    g = ros2_tools.Graph(tmp_path_factory.mktemp("nav2"))
    yield g
    g.close()


def room(size: int = 120, resolution: float = 0.05) -> OccupancyGrid:
    """A square room: walls round a free floor."""
    cells = np.zeros((size, size), np.int8)
    cells[[0, -1], :] = 100
    cells[:, [0, -1]] = 100
    return OccupancyGrid(cells, resolution, (-size * resolution / 2, -size * resolution / 2))


@pytest.fixture(scope="module")
def room_map(tmp_path_factory):
    path = tmp_path_factory.mktemp("maps") / "room.yaml"
    save_map(room(), path)
    return path


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """The package built by colcon, as in a ROS 2 workspace: (install folder, colcon's log)."""
    if ros2_tools.missing_colcon():
        pytest.skip(ros2_tools.missing_colcon())
    ws = tmp_path_factory.mktemp("ws")
    env = {**ros2_tools.Graph(ws).env,
           "PATH": f"{ros2_tools.PYTHON.parent}:{ros2_tools.os.environ['PATH']}"}
    p = subprocess.run([str(ros2_tools.PYTHON.parent / "colcon"), "build", "--base-paths",
                        str(PACKAGE.parent), "--build-base", str(ws / "build"),
                        "--install-base", str(ws / "install")], cwd=ws, env=env,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return ws / "install" / "lidar_map_updating", p.stdout


def test_colcon_builds_an_ament_python_package_by_the_book(workspace):
    install, log = workspace
    assert "Finished <<< lidar_map_updating" in log
    share = install / "share" / "lidar_map_updating"
    assert (install / "lib" / "lidar_map_updating" / "map_updater").exists()   # ros2 run
    assert (install / "share/ament_index/resource_index/packages/lidar_map_updating").exists()
    assert (share / "launch" / "map_updater.launch.py").exists()
    assert (share / "params" / "map_updater.yaml").exists()
    manifest = (share / "package.xml").read_text()
    assert '<package format="3">' in manifest and "<build_type>ament_python</build_type>" in \
        manifest


def _calls(tree, name: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(
        n.func, "id", getattr(n.func, "attr", None)) == name]


def _keywords(call: ast.Call) -> dict:
    return {k.arg: k.value for k in call.keywords}


def test_the_launch_file_starts_a_lifecycle_node_and_a_nav2_manager_that_names_it(workspace):
    # no wheel carries launch_ros, so the launch file is read, not run: it must start the
    # installed executable as launch_ros's LifecycleNode, and Nav2's lifecycle manager with
    # that node in its node_names, as Nav2's bringup does
    install, _ = workspace
    tree = ast.parse((install / "share/lidar_map_updating/launch/map_updater.launch.py")
                     .read_text())
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                and n.module == "launch_ros.actions" for a in n.names}
    assert {"LifecycleNode", "Node"} <= imported
    (node,) = _calls(tree, "LifecycleNode")
    k = _keywords(node)
    assert (k["package"].value, k["executable"].value, k["name"].value) == (
        "lidar_map_updating", "map_updater", "map_updater")
    assert (install / "lib" / k["package"].value / k["executable"].value).exists()
    (manager,) = [c for c in _calls(tree, "Node")
                  if _keywords(c)["package"].value == "nav2_lifecycle_manager"]
    params = _keywords(manager)["parameters"].elts[0]
    given = {key.value: value for key, value in zip(params.keys, params.values)}
    assert [e.value for e in given["node_names"].elts] == ["map_updater"]
    assert {"autostart", "bond_timeout"} <= set(given)
    assert not list(_calls(tree, "ExecuteProcess"))


def _manager(graph, *names, timeout=4.0, watch=30.0, log="manager"):
    return graph.start([MANAGER, "--node-names", *names, "--bond-timeout", timeout, "--watch",
                        watch], log)


def _events(graph, log: str) -> list[dict]:
    text = graph.log(log)
    return [json.loads(line) for line in text.splitlines() if line.startswith("{")]


def test_nav2s_manager_brings_the_installed_node_up_bonds_and_sees_it_killed(graph, workspace,
                                                                             room_map):
    install, _ = workspace
    # as `ros2 run lidar_map_updating map_updater` runs it in a sourced workspace
    run = (f'. "{install.parent}/setup.sh" && exec "{install}/lib/lidar_map_updating/'
           f'map_updater" --map "{room_map}" --ros-args -r __node:=bonded -p '
           f'save_path:={graph.folder / "bonded.yaml"}')
    node = graph.start(["sh", "-c", run], "bonded", python=False)
    manager = _manager(graph, "bonded", watch=60.0)
    ros2_tools.wait_until(lambda: any(e["event"] == "active" and "node" not in e
                                      for e in _events(graph, "manager")), 120, "the bringup")
    time.sleep(5.0)                 # heartbeats go on past the manager's 4 s
    assert node.poll() is None and manager.poll() is None
    ros2_tools.os.killpg(node.pid, signal.SIGKILL)
    killed = time.monotonic()
    assert manager.wait(30) == 0
    events = _events(graph, "manager")
    assert [e["event"] for e in events] == ["inactive", "active", "bond formed", "active",
                                            "bond broken"]
    broken = events[-1]
    # the manager's bond_timeout after the last heartbeat, as Nav2's manager would see it
    assert 4.0 <= broken["silent_for"] <= 5.0
    assert time.monotonic() - killed < 10.0


NO_BOND_NODE = """
import rclpy
from rclpy.lifecycle import LifecycleNode
rclpy.init()
rclpy.spin(LifecycleNode("bondless"))
"""


def test_a_lifecycle_node_without_a_bond_makes_that_manager_abort(graph):
    # the control: what the node did before it had a bond
    node = graph.start(["-c", NO_BOND_NODE], "bondless")
    manager = _manager(graph, "bondless", timeout=2.0, log="manager_control")
    assert manager.wait(90) == 1
    events = [e["event"] for e in _events(graph, "manager_control")]
    assert events == ["inactive", "active", "unable to be reached by bond", "aborting bringup"]
    graph.stop(node)


DESCRIBE = """
import json, sys
import rclpy
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters
from lifecycle_msgs.srv import GetState
name, wanted = sys.argv[1], sys.argv[2].split(",")
rclpy.init()
node = rclpy.create_node("describer")

def call(srv, service, **fields):
    client = node.create_client(srv, f"/{name}/{service}")
    assert client.wait_for_service(timeout_sec=60), service
    request = srv.Request(**fields)
    for _ in range(9):      # idempotent: asked again while the reply's path is not matched
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=10)
        if future.done():
            return future.result()
        client.remove_pending_request(future)
    raise SystemExit(f"no answer from {service}")

listed = call(ListParameters, "list_parameters").result.names
described = call(DescribeParameters, "describe_parameters", names=wanted).descriptors
values = call(GetParameters, "get_parameters", names=wanted).values
out = {"listed": list(listed), "state": call(GetState, "get_state").current_state.label}
for d, v in zip(described, values):
    ranges = [[r.from_value, r.to_value] for r in (*d.floating_point_range, *d.integer_range)]
    value = {1: v.bool_value, 2: v.integer_value, 3: v.double_value, 4: v.string_value,
             9: list(v.string_array_value)}.get(v.type)
    out[d.name] = {"type": v.type, "value": value, "range": ranges, "read_only": d.read_only}
print(json.dumps(out))
"""


def test_parameters_are_declared_from_the_start_with_ranges_and_autostart_works(graph,
                                                                                room_map):
    # as a Nav2 user writes them: an integer for a number, one topic for a list, another
    # node's key from a shared file, and autostart as a parameter rather than a flag
    params = graph.folder / "shared.yaml"
    params.write_text("/**:\n  ros__parameters:\n    global_frame: map\n    robot_base_frame: "
                      "base_link\nprobe_params:\n  ros__parameters:\n    scan_topics: scan\n")
    name = "probe_params"
    node = graph.node("--map", room_map, "--ros-args", "-r", f"__node:={name}", "--params-file",
                      params, "-p", "publish_period:=2", "-p", "autostart:=true", "-p",
                      f"save_path:={graph.folder / 'p.yaml'}", name=name)
    wanted = ["publish_period", "queue_size", "tf_timeout", "max_beams", "scan_topics",
              "updater.threshold"]
    got = json.loads(graph.script(DESCRIBE, name, ",".join(wanted)).strip().splitlines()[-1])
    assert got["state"] == "active"                                # autostart:=true did it
    assert got["publish_period"] == {"type": 3, "value": 2.0, "range": [[0.01, 3600.0]],
                                     "read_only": True}
    assert got["queue_size"]["range"] == [[1, 100000]]
    assert got["tf_timeout"]["range"] == [[0.0, 10.0]]
    assert got["max_beams"]["value"] == 20000 and got["max_beams"]["range"] == [[1, 1000000]]
    assert got["scan_topics"]["value"] == ["scan"]
    assert got["updater.threshold"]["range"]                      # the config's bounds
    assert "global_frame" not in got["listed"] and "updater.threshold" in got["listed"]
    log = graph.log(name)
    assert "left alone: global_frame" in log and "robot_base_frame" in log
    assert graph.stop(node) == 0 and "Traceback" not in graph.log(name)


@pytest.mark.parametrize("given, words", [
    (["-p", "publish_period:=abc"], "parameter '~publish_period' must be a number"),
    (["-p", "queue_size:=0"], "parameter '~queue_size' must be a whole number in [1, 100000]"),
    (["-p", "save_path:=/nowhere/at/all/map.yaml"], "the folder '/nowhere/at/all' does not "
                                                    "exist"),
    (["-p", "save_path:=/"], "must name a map file"),
    ("scan_topics: []", "parameters given no value (an empty list or none): scan_topics"),
    (["-p", "updater.treshold:=5"], "did you mean 'threshold'"),
])
def test_each_bad_parameter_fails_configure_in_one_line(graph, room_map, given, words):
    name = "bad_params"
    args = given
    if isinstance(given, str):
        params = graph.folder / "bad.yaml"
        params.write_text(f"{name}:\n  ros__parameters:\n    {given}\n")
        args = ["--params-file", params]
    node = graph.node("--map", room_map, "--autostart", "--ros-args", "-r", f"__node:={name}",
                      *args, name=name)
    assert node.wait(90) == 2
    lines = graph.log(name).splitlines()
    error = [line for line in lines if "mapupdate ros2: error:" in line]
    assert len(error) == 1 and words in error[0], lines[-5:]
    assert ("configure failed" in error[0]) != isinstance(given, str)
    assert "Traceback" not in graph.log(name)
    (graph.folder / f"{name}.log").unlink()


QOS_PROBE = """
import json, sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
rclpy.init()
node = rclpy.create_node("qos_probe")
best_effort = node.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
reliable = node.create_publisher(LaserScan, "scan", QoSProfile(
    depth=10, reliability=ReliabilityPolicy.RELIABLE))
end = time.monotonic() + 30
while reliable.get_subscription_count() == 0 and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
time.sleep(2.0)
print(json.dumps([best_effort.get_subscription_count(), reliable.get_subscription_count()]))
"""


def test_a_qos_override_is_taken(graph, room_map):
    # a reliable scan subscription no longer matches a best-effort lidar driver
    name = "qos_node"
    node = graph.node("--map", room_map, "--autostart", "--ros-args", "-r", f"__node:={name}",
                      "-p", "qos_overrides./scan.subscription.reliability:=reliable", "-p",
                      "pose_source:=amcl_pose", name=name)
    matched = json.loads(graph.script(QOS_PROBE).strip().splitlines()[-1])
    assert matched == [0, 1]
    assert graph.stop(node) == 0


def _transition(graph, name: str, transition: int) -> bool:
    return graph.call(f"/{name}/change_state", "lifecycle_msgs.srv.ChangeState",
                      {"transition.id": transition})["success"]


def test_services_answer_only_while_active_and_shutdown_ends_the_process(graph, room_map):
    name = "states"
    save = graph.folder / "states.yaml"
    node = graph.node("--map", room_map, "--ros-args", "-r", f"__node:={name}", "-p",
                      f"save_path:={save}", name=name)
    graph.wait_for_service(f"/{name}/get_state", timeout=120)
    # declared from the start, before any transition, as Nav2's nodes declare theirs
    before = json.loads(graph.script(DESCRIBE, name, "publish_period").strip().splitlines()[-1])
    assert before["state"] == "unconfigured" and "updater.threshold" in before["listed"]
    assert before["publish_period"]["range"] == [[0.01, 3600.0]]
    assert _transition(graph, name, CONFIGURE)
    for service in ("save", "commit", "reset"):
        answer = graph.call(f"/{name}/{service}")
        assert answer == {"success": False, "message": "the node is not active (state "
                                                       "'inactive')"}
    assert not save.exists()
    assert _transition(graph, name, ACTIVATE)
    assert graph.call(f"/{name}/save")["success"] and save.exists()
    saved_map = graph.call(f"/{name}/save_map", "nav2_msgs.srv.SaveMap",
                           {"map_url": f"file://{graph.folder / 'by_nav2'}"})
    assert saved_map == {"result": True}
    assert np.array_equal(load_map(graph.folder / "by_nav2.yaml").data, room().data)
    assert graph.call(f"/{name}/save_map", "nav2_msgs.srv.SaveMap",
                      {"map_url": str(graph.folder / "x"), "image_format": "png"}) == \
        {"result": False}
    assert _transition(graph, name, 4)                      # deactivate
    assert _transition(graph, name, INACTIVE_SHUTDOWN)
    assert node.wait(30) == 0                               # finalized: the process ends
    assert "Traceback" not in graph.log(name)


MAPS = """
import json, sys, time
import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import MapMetaData, OccupancyGrid
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
name = sys.argv[1]
rclpy.init()
node = rclpy.create_node("map_server_like")
latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
maps = node.create_publisher(OccupancyGrid, "map", latched)
seen, meta = {}, []
node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: seen.update(
    {s.name: {v.key: v.value for v in s.values} | {"_message": s.message} for s in m.status}), 10)
node.create_subscription(MapMetaData, "map_updated_metadata",
                         lambda m: meta.append([m.width, m.height]), latched)

def grid(w, h):
    m = OccupancyGrid()
    m.header.frame_id = "map"
    m.info.resolution, m.info.width, m.info.height = 0.05, w, h
    m.info.origin.orientation.w = 1.0
    m.data = [0] * (w * h)
    return m

def wait(ok):
    end = time.monotonic() + 30
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
        if ok():
            return
    raise SystemExit(f"timed out: {seen}, {meta}")

while maps.get_subscription_count() == 0:
    rclpy.spin_once(node, timeout_sec=0.1)
maps.publish(grid(60, 40))                        # the first floor
wait(lambda: meta and meta[-1] == [60, 40])
maps.publish(grid(80, 50))                        # map_server switched floors
wait(lambda: meta and meta[-1] == [80, 50])
wait(lambda: seen.get(f"/{name}: health", {}).get("maps_switched") == "1")
print(json.dumps(seen[f"/{name}: health"]))
"""


def test_a_new_map_of_another_size_on_map_is_followed_and_said(graph):
    name = "floors"
    save = graph.folder / "floors.yaml"
    node = graph.node("--autostart", "--ros-args", "-r", f"__node:={name}", "-p",
                      f"save_path:={save}", "-p", "publish_period:=0.2", "-p",
                      "pose_source:=amcl_pose", name=name)
    values = json.loads(graph.script(MAPS, name).strip().splitlines()[-1])
    assert values["maps_received"] == "2" and values["maps_switched"] == "1"
    assert values["last_map_switch"] == "60x40 -> 80x50 cells, buffers re-seeded"
    assert values["_message"].startswith("ok; map switched")
    assert graph.call(f"/{name}/save")["success"]
    assert load_map(save).shape == (50, 80)
    assert graph.stop(node) == 0
