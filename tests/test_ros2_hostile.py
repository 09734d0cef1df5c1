"""The ROS 2 node against traffic that once fooled it, in a real ROS 2 graph: transforms
whose quaternions are not unit (tf2 ignores them, and so does the node, counted), a lidar
tilted from level, a scan of a million beams, one stamped in 2037, one of 172 turns, a
clockwise lidar; a flood of scans, every one of which is either received or counted as lost
on the way. Skipped, with the reason, where the wheels cannot be had."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gridmap import OccupancyGrid, save_map

import ros2_tools

pytestmark = pytest.mark.skipif(bool(ros2_tools.missing_tf()),
                                reason=ros2_tools.missing_tf() or "-")


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    g = ros2_tools.Graph(tmp_path_factory.mktemp("hostile"))
    yield g
    g.close()


@pytest.fixture(scope="module")
def room_map(tmp_path_factory):
    cells = np.zeros((120, 120), np.int8)
    cells[[0, -1], :] = 100
    cells[:, [0, -1]] = 100
    path = tmp_path_factory.mktemp("maps") / "room.yaml"
    save_map(OccupancyGrid(cells, 0.05, (-3.0, -3.0)), path)
    return path


COMMON = """
import array, json, math, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

node_name = sys.argv[1]
rclpy.init()
node = rclpy.create_node("hostile")
latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
scans = node.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
second = node.create_publisher(LaserScan, "scan", qos_profile_sensor_data)   # another lidar
tf = node.create_publisher(TFMessage, "/tf", 100)
tf_static = node.create_publisher(TFMessage, "/tf_static", latched)
seen = {}
node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: seen.update(
    {s.name: {v.key: v.value for v in s.values} for s in m.status}), 10)
end = time.monotonic() + 60
while min(p.get_subscription_count() for p in (scans, second, tf, tf_static)) == 0:
    rclpy.spin_once(node, timeout_sec=0.1)
    assert time.monotonic() < end, "the node never subscribed"
for _ in range(10):
    rclpy.spin_once(node, timeout_sec=0.1)
t0 = node.get_clock().now().nanoseconds / 1e9

def stamped(msg, t):
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    return msg

def edge(t, parent, child, x, q=(0.0, 0.0, 0.0, 1.0)):
    e = stamped(TransformStamped(), t)
    e.header.frame_id, e.child_frame_id = parent, child
    e.transform.translation.x = x
    r = e.transform.rotation
    r.x, r.y, r.z, r.w = q
    return e

def send(pub, *edges):
    m = TFMessage()
    m.transforms = list(edges)
    pub.publish(m)
    for _ in range(3):
        rclpy.spin_once(node, timeout_sec=0.02)

def odometry(k):
    send(tf, edge(t0 + 0.1 * k, "odom", "base_link", 0.01 * k),
         edge(t0 + 0.1 * k, "map", "odom", 0.0))

def scan(t, n=101, increment=0.01, frame="laser", ranges=None, pub=scans):
    m = stamped(LaserScan(), t)
    m.header.frame_id = frame
    m.angle_min, m.angle_increment = -0.5, increment
    m.angle_max = -0.5 + (n - 1) * increment
    m.range_min, m.range_max = 0.05, 20.0
    m.ranges = ranges if ranges is not None else array.array("f", [2.0]) * n
    pub.publish(m)

def health():
    return seen.get(f"/{node_name}: health", {})

def wait_for(ok, timeout=30):
    end = time.monotonic() + timeout
    while time.monotonic() < end and not ok(health()):
        rclpy.spin_once(node, timeout_sec=0.1)
    return health()
"""

HOSTILE = COMMON + """
yaw90 = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
pitched = (0.0, math.sin(0.15), 0.0, math.cos(0.15))          # 0.3 rad from level
send(tf_static, edge(t0, "base_link", "laser", 0.25), edge(t0, "base_link", "tilted", 0.2,
                                                             pitched))
for k in range(3):
    odometry(k)
for k, scale in enumerate((2.0, 0.5, 0.0)):      # read as 126.9, 18.4 and 0 deg before
    send(tf, edge(t0 + 0.25 + 0.01 * k, "odom", "base_link", 0.0,
                  tuple(scale * v for v in yaw90)))
for k in range(3, 6):
    odometry(k)
scan(t0 + 0.35)                                              # used
scan(t0 + 0.36, frame="tilted", pub=second)                  # not level: skipped
sent = time.monotonic()
scan(t0 + 0.37, n=1_000_000, increment=1e-6)                 # a million beams: skipped
scan(2_145_916_800.0)                                        # 2038-01-01: skipped
scan(t0 + 0.38, n=1001, increment=1.08)                      # 1080 rad: skipped
scan(t0 + 0.39, increment=-0.01)                             # clockwise: used
for k in range(6, 9):
    odometry(k)
scan(t0 + 0.45)                                              # used, not held back
done = wait_for(lambda v: v.get("scans_used") == "3")
print(json.dumps({**done, "_seconds": time.monotonic() - sent}))
"""


def test_transforms_mounts_and_scans_that_fooled_the_node_are_counted_and_skipped(graph,
                                                                                  room_map):
    name = "hostile_probe"
    node = graph.node("--map", room_map, "--autostart", "--ros-args", "-r", f"__node:={name}",
                      "-p", "publish_period:=0.2", name=name)
    values = json.loads(graph.script(HOSTILE, name, timeout=120).strip().splitlines()[-1])
    assert values["scans_used"] == "3"
    assert values["skipped: transform with a non-unit quaternion"] == "3"
    assert values["skipped: laser neither upright nor upside down"] == "1"
    # the million-beam scan (4 MB) is refused unread, or, lost on the way, counted so
    assert int(values.get("skipped: scan with more beams than max_beams", 0)) + \
        int(values["scans_lost_in_transport"]) == 1
    assert values["skipped: scan stamped ahead of the odometry"] == "1"
    assert values["skipped: scan spanning more than one turn"] == "1"
    # the scans after them went through at once (one of 166 s held the node before)
    assert values["_seconds"] < 5.0
    assert node.poll() is None and graph.stop(node) == 0
    assert "Traceback" not in graph.log(name)


FLOOD = COMMON + """
n = int(sys.argv[2])
scan(t0)
wait_for(lambda v: v.get("scans_received") == "1")
start = time.monotonic()
for k in range(n):                      # as fast as Python publishes
    scan(t0 + 0.001 * (k + 1))
rate = n / (time.monotonic() - start)
time.sleep(1.0)
scan(t0 + 0.001 * (n + 1))              # a last one, after the flood: every gap closed
done = wait_for(lambda v: int(v.get("scans_received", 0)) + int(
    v.get("scans_lost_in_transport", 0)) >= n + 2 and v.get("scans_waiting") == "0")
print(json.dumps({**done, "_rate": rate}))
"""


def test_every_scan_of_a_flood_is_received_or_counted_lost(graph, room_map):
    name = "flood_probe"
    sent = 4000
    node = graph.node("--map", room_map, "--autostart", "--ros-args", "-r", f"__node:={name}",
                      "-p", "publish_period:=0.2", "-p", "queue_size:=10", "-p",
                      "tf_timeout:=0.05", name=name)
    values = json.loads(graph.script(FLOOD, name, sent, timeout=180).strip().splitlines()[-1])
    got = {k: int(v) for k, v in values.items() if k.startswith(("scans_", "skipped"))}
    assert values["_rate"] > 1000                         # a flood indeed
    assert got["scans_lost_in_transport"] > 0             # some did not make it ...
    assert got["scans_received"] + got["scans_lost_in_transport"] == sent + 2   # ... counted
    # and what was received is accounted for: used, skipped, dropped in the node's queue
    skipped = sum(v for k, v in got.items() if k.startswith("skipped"))
    assert got["scans_received"] == got.get("scans_used", 0) + skipped + \
        got["scans_dropped_behind"] + got["scans_waiting"]
    print(got, f"{values['_rate']:.0f} scans/s")
    assert node.poll() is None and graph.stop(node) == 0
