"""The live ROS 2 node's speed: W2 of the warehouse (quick route) replayed into it by a separate
rclpy process at 1x and 5x real time, in a private ROS 2 graph (.venv-ros2, `make ros2`). For
each rate: the scans received, used and dropped, and the per-scan latency the node reports on
/diagnostics (from a scan's arrival to the end of its update, the wait for its transforms past its
stamp included), median and 99th percentile; and whether the saved map equals `mapupdate
update` on the same recording. Then two hostile rows: a flood (1081-beam scans at up to
5 000 per second for ``--flood`` seconds, into the default ``queue_size``) and a scan of a
million beams followed by one stamped in 2038: the scans counted (received + lost on the way)
against those sent, and the time from the end of the burst until the next ordinary scan has
been used.

Bars (exit 1 when missed): no scan dropped at 5x real time; every flooded scan counted;
the node back within 2 s of either burst.

    python benchmarks/bench_ros2.py [--rates 1 5] [--flood 10]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(ROOT))

import numpy as np  # noqa: E402

import ros2_tools  # noqa: E402
from gridmap import load_map  # noqa: E402
from mapupdate import main as mapupdate  # noqa: E402

DIAGNOSTICS = """
import json, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
rclpy.init()
node = rclpy.create_node("diagnostics_reader")
seen = {}
node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: seen.update(
    {s.name: {v.key: v.value for v in s.values} for s in m.status}), 10)
end = time.monotonic() + 30
while "/map_updater: health" not in seen and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.2)
print(json.dumps(seen.get("/map_updater: health", {})))
"""


def one_rate(graph, folder: Path, rate: float) -> dict:
    save = folder / f"saved_{rate:g}.yaml"
    node = graph.node("--map", folder / "run/maps/M_W1.yaml", "--autostart", "--ros-args",
                      "-p", f"save_path:={save}", name=f"node_{rate:g}")
    try:
        graph.wait_for_service("/map_updater/get_state", timeout=180)   # cold kernels compile
        graph.replay(folder / "bags/W2.bag", rate)
        assert graph.call("/map_updater/save")["success"]
        health = json.loads(graph.script(DIAGNOSTICS).strip().splitlines()[-1])
    finally:
        graph.stop(node)
    same = np.array_equal(load_map(save).data, load_map(folder / "update.yaml").data)
    return {"rate": rate, "received": int(health.get("scans_received", 0)),
            "used": int(health.get("scans_used", 0)),
            "dropped": int(health.get("scans_dropped_behind", 0)),
            "p50": float(health.get("scan_latency_ms_p50", "nan")),
            "p99": float(health.get("scan_latency_ms_p99", "nan")),
            "update_ms": float(health.get("scan_time_ms_mean", "nan")), "same_map": same}


HOSTILE = """
import array, json, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TransformStamped
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

kind, seconds = sys.argv[1], float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("hostile_lidar")
scans = node.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
tf = node.create_publisher(TFMessage, "/tf", 100)
seen = {}
node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: seen.update(
    {s.name: {v.key: v.value for v in s.values} for s in m.status}), 10)
while min(scans.get_subscription_count(), tf.get_subscription_count()) == 0:
    rclpy.spin_once(node, timeout_sec=0.1)
for _ in range(20):
    rclpy.spin_once(node, timeout_sec=0.1)
t0 = node.get_clock().now().nanoseconds / 1e9
RANGES = array.array("f", [2.0]) * 1081

def stamp(msg, t):
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    return msg

def odometry(t):
    m = TFMessage()
    for parent, child in (("odom", "base_link"), ("map", "odom")):
        e = stamp(TransformStamped(), t)
        e.header.frame_id, e.child_frame_id = parent, child
        e.transform.translation.x, e.transform.rotation.w = 1.0, 1.0
        m.transforms.append(e)
    tf.publish(m)

def scan(t, n=1081, ranges=RANGES):
    m = stamp(LaserScan(), t)
    m.header.frame_id = "base_link"
    m.angle_min, m.angle_increment = -2.35, 4.7 / max(n - 1, 1)
    m.angle_max, m.range_min, m.range_max = 2.35, 0.05, 20.0
    m.ranges = ranges
    scans.publish(m)

def health():
    return seen.get("/map_updater: health", {})

def wait(ok, timeout=120.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end and not ok(health()):
        rclpy.spin_once(node, timeout_sec=0.02)
    return health()

odometry(t0)
odometry(t0 + 1000.0)                         # odometry past every stamp sent below
scan(t0 + 0.001)
wait(lambda v: v.get("scans_used") == "1")
sent, start = 1, time.monotonic()
if kind == "flood":
    while time.monotonic() - start < seconds:
        if sent - 1 < 5000 * (time.monotonic() - start):
            scan(t0 + 0.001 * (sent + 1))
            sent += 1
else:
    scan(t0 + 0.002, 1_000_000, array.array("f", [2.0]) * 1_000_000)
    scan(2_145_916_800.0)
    sent += 2
burst = time.monotonic() - start
ended = time.monotonic()
for _ in range(5):
    rclpy.spin_once(node, timeout_sec=0.01)
used = int(health().get("scans_used", 0))
scan(t0 + 500.0)                              # an ordinary scan after the burst
sent += 1
done = wait(lambda v: int(v.get("scans_received", 0)) + int(
    v.get("scans_lost_in_transport", 0)) >= sent and v.get("scans_waiting") == "0"
    and int(v.get("scans_used", 0)) > used)
print(json.dumps({"sent": sent, "burst_s": burst, "recover_s": time.monotonic() - ended,
                  **done}))
"""


def hostile(graph, folder: Path, kind: str, seconds: float) -> dict:
    node = graph.node("--map", folder / "run/maps/M_W1.yaml", "--autostart", "--ros-args",
                      "-p", f"save_path:={folder / 'hostile.yaml'}", "-p",
                      "publish_period:=0.1", name=f"node_{kind}")
    try:
        graph.wait_for_service("/map_updater/get_state", timeout=180)
        out = json.loads(graph.script(HOSTILE, kind, seconds, timeout=600)
                         .strip().splitlines()[-1])
    finally:
        graph.stop(node)
    count = {k: int(v) for k, v in out.items() if k.startswith(("scans_", "skipped"))}
    return {"kind": kind, "sent": out["sent"], "rate": out["sent"] / max(out["burst_s"], 1e-9),
            "received": count.get("scans_received", 0),
            "lost": count.get("scans_lost_in_transport", 0),
            "dropped": count.get("scans_dropped_behind", 0),
            "skipped": sum(v for k, v in count.items() if k.startswith("skipped")),
            "used": count.get("scans_used", 0), "recover_s": out["recover_s"]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[1.0, 5.0])
    ap.add_argument("--flood", type=float, default=10.0, help="seconds of flood (10)")
    args = ap.parse_args()
    if ros2_tools.missing():
        print(f"cannot run: {ros2_tools.missing()}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        assert mapupdate(["run", "--quick", "--sessions", "2", "--bag", str(folder / "bags"),
                          "--out", str(folder / "run"), "--no-progress"]) == 0
        assert mapupdate(["update", "--map", str(folder / "run/maps/M_W1.yaml"), "--log",
                          str(folder / "bags/W2.bag"), "--out", str(folder / "update.yaml"),
                          "--no-progress"]) == 0
        graph = ros2_tools.Graph(folder)
        try:
            rows = [one_rate(graph, folder, rate) for rate in args.rates]
            bursts = [hostile(graph, folder, "flood", args.flood),
                      hostile(graph, folder, "huge", 0.0)]
        finally:
            graph.close()
    print(f"ROS 2 node, W2 quick route (590 scans), {platform.machine()}, "
          f"{platform.python_version()}")
    print("| rate | scans received | used | dropped | latency p50 ms | p99 ms | "
          "update mean ms | map = mapupdate update |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['rate']:g}x | {r['received']} | {r['used']} | {r['dropped']} | "
              f"{r['p50']:.2f} | {r['p99']:.2f} | {r['update_ms']:.2f} | "
              f"{'yes' if r['same_map'] else 'no'} |")
    print()
    print("| burst | sent | at scans/s | received | lost on the way | counted = sent | "
          "dropped in the node | skipped | used | back in s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for b in bursts:
        what = f"flood, {args.flood:g} s" if b["kind"] == "flood" else \
            "10^6 beams, then stamped 2038"
        print(f"| {what} | {b['sent']} | {b['rate']:.0f} | {b['received']} | {b['lost']} | "
              f"{'yes' if b['received'] + b['lost'] == b['sent'] else 'no'} | "
              f"{b['dropped']} | {b['skipped']} | {b['used']} | {b['recover_s']:.2f} |")
    fast = [r for r in rows if r["rate"] >= 5]
    missed = any(r["dropped"] or r["received"] < 590 for r in fast) or any(
        b["received"] + b["lost"] != b["sent"] or b["recover_s"] > 2.0 for b in bursts)
    return 1 if missed else 0


if __name__ == "__main__":
    raise SystemExit(main())
