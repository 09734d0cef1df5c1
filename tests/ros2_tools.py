"""A private ROS 2 graph for the ROS 2 node's tests: processes of .venv-ros2 (where `make ros2`
installs ROS 2 Jazzy's wheels) on a domain id of their own, discovery limited to this
machine; everything started is stopped at the end."""

from __future__ import annotations

import functools
import json
import os
import random
import signal
import subprocess
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = ROOT / ".venv-ros2" / "bin" / "python"
PLAY = ROOT / "ros" / "tools" / "play.py"
# Cyclone DDS found the way Fast DDS's localhost discovery goes: unicast on the loopback, to
# the well-known ports of each participant index
CYCLONE = ('<CycloneDDS><Domain><General><Interfaces><NetworkInterface address="127.0.0.1"/>'
           '</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>'
           '<ParticipantIndex>auto</ParticipantIndex><Peers><Peer address="127.0.0.1"/>'
           '</Peers></Discovery></Domain></CycloneDDS>')


@functools.cache
def missing() -> str:
    """Why the ROS 2 tests cannot run here ('' when they can)."""
    if not PYTHON.exists():
        return "no .venv-ros2 (`make ros2` installs ROS 2 Jazzy's wheels there)"
    p = subprocess.run([PYTHON, "-c", "import rclpy, cyclonedds"], capture_output=True,
                       text=True, timeout=120)
    if p.returncode:
        return f".venv-ros2 cannot import rclpy and cyclonedds: {p.stderr.strip()[-300:]}"
    return ""


@functools.cache
def missing_tf() -> str:
    """Why the node's tf tests cannot run here ('' when they can): tf2_msgs and map_msgs have no
    wheel, `make ros2` builds them."""
    if missing():
        return missing()
    p = subprocess.run([PYTHON, "-c", "import tf2_msgs.msg, map_msgs.msg, bond.msg, "
                        "nav2_msgs.srv"], capture_output=True, text=True, timeout=120)
    if p.returncode:
        return ("tf2_msgs, map_msgs, bond and nav2_msgs were not built into .venv-ros2 (`make "
                f"ros2` builds them with cmake and a C compiler): {p.stderr.strip()[-200:]}")
    return ""


@functools.cache
def missing_colcon() -> str:
    """Why the package build test cannot run here ('' when it can)."""
    if missing():
        return missing()
    if not (PYTHON.parent / "colcon").exists():
        return "colcon is not in .venv-ros2 (`make ros2` installs colcon-core and colcon-ros)"
    return ""


class Graph:
    def __init__(self, folder: Path, other_than: "Graph | None" = None):
        self.folder = folder
        # domains 51-100: the README's journeys, which may run beside this in another test
        # process, take 1-50
        taken = {other_than.env["ROS_DOMAIN_ID"]} if other_than is not None else set()
        domain = random.choice([str(d) for d in range(51, 101) if str(d) not in taken])
        self.env = {**os.environ, "ROS_DOMAIN_ID": domain,
                    "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                    "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp", "PYTHONUNBUFFERED": "1",
                    "ROS_LOG_DIR": str(folder / "log"), "CYCLONEDDS_URI": CYCLONE}
        for var in ("_ROS_WHEELS_BOOTSTRAP_COMPLETE", "LD_LIBRARY_PATH", "VIRTUAL_ENV"):
            self.env.pop(var, None)
        self.procs: list[subprocess.Popen] = []

    def start(self, args, name: str, python: bool = True) -> subprocess.Popen:
        log = open(self.folder / f"{name}.log", "ab")
        p = subprocess.Popen([str(PYTHON)] * python + [*map(str, args)], env=self.env, stdout=log,
                             stderr=subprocess.STDOUT, cwd=self.folder, start_new_session=True)
        self.procs.append(p)
        return p

    def node(self, *args, name: str = "map_updater") -> subprocess.Popen:
        return self.start(["-m", "mapupdate", "ros2", *args], name)

    def log(self, name: str) -> str:
        return (self.folder / f"{name}.log").read_text(errors="replace")

    def script(self, code: str, *args, timeout: float = 120.0) -> str:
        """Run a Python snippet in the graph; its stdout."""
        p = subprocess.run([str(PYTHON), "-c", textwrap.dedent(code), *map(str, args)],
                           env=self.env, capture_output=True, text=True, timeout=timeout,
                           cwd=self.folder)
        assert p.returncode == 0, p.stderr[-3000:]
        return p.stdout

    def call(self, service: str, srv: str = "std_srvs.srv.Trigger", fields: dict | None = None,
             timeout: float = 30.0) -> dict:
        """Call a service once it is there; its response's fields."""
        out = self.script(CALL, service, srv, json.dumps(fields or {}), timeout, timeout=timeout + 30)
        return json.loads(out.strip().splitlines()[-1])

    def wait_for_service(self, service: str, timeout: float = 60.0) -> None:
        self.call(service, "lifecycle_msgs.srv.GetState", timeout=timeout)

    def replay(self, bag: Path, rate: float, poses: str = "tf", *more: str) -> str:
        p = subprocess.run([str(PYTHON), str(PLAY), str(bag), "--rate", str(rate), "--poses",
                            poses, *more], env=self.env, capture_output=True, text=True,
                           timeout=1200, cwd=self.folder)
        assert p.returncode == 0, p.stderr[-3000:]
        return p.stdout

    def stop(self, p: subprocess.Popen, timeout: float = 20.0) -> int:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGINT)
            try:
                p.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(10)
        return p.returncode

    def close(self) -> None:
        for p in reversed(self.procs):
            if p.poll() is None:
                self.stop(p)


CALL = """
import importlib, json, sys, time
import rclpy
service, srv, fields, timeout = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), float(sys.argv[4])
module, _, name = srv.rpartition(".")
Srv = getattr(importlib.import_module(module), name)
rclpy.init()
node = rclpy.create_node("test_client")
client = node.create_client(Srv, service)
if not client.wait_for_service(timeout_sec=timeout):
    raise SystemExit(f"no service {service}")
request = Srv.Request()
for k, v in fields.items():
    target, *path = k.split(".")
    obj = request
    for p in [target, *path][:-1]:
        obj = getattr(obj, p)
    setattr(obj, [target, *path][-1], v)
future = client.call_async(request)
rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
r = future.result()
out = {}
for f in r.get_fields_and_field_types():
    v = getattr(r, f)
    out[f] = v if isinstance(v, (bool, int, float, str)) else {
        g: getattr(v, g) for g in v.get_fields_and_field_types()}
print(json.dumps(out))
node.destroy_node()
rclpy.shutdown()
"""


def wait_until(ready, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if ready():
            return
        time.sleep(0.2)
    raise TimeoutError(f"{what} did not happen in {timeout} s")
