"""The live ROS 2 node's speed: W2 of the warehouse (quick route) replayed into it by a separate
rclpy process at 1x and 5x real time, in a private ROS 2 graph (.venv-ros2, `make ros2`). For
each rate: the scans received, used and dropped, and the per-scan latency the node reports on
/diagnostics (from a scan's arrival to the end of its update, the wait for its transforms past its
stamp included), median and 99th percentile; and whether the saved map equals `mapupdate
update` on the same recording.

Bar (exit 1 when missed): no scan dropped at 5x real time.

    python benchmarks/bench_ros2.py [--rates 1 5]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[1.0, 5.0])
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
    fast = [r for r in rows if r["rate"] >= 5]
    return 1 if any(r["dropped"] or r["received"] < 590 for r in fast) else 0


if __name__ == "__main__":
    raise SystemExit(main())
