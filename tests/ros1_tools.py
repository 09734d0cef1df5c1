"""A real ROS 1 master for the tests: roscore on a port of its own, with its own ROS_HOME and
log folder, torn down with everything it started; plus the little clients the tests need (a
subscriber that stores one message, a service call, a bag player)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
import time
import xmlrpc.client
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def missing() -> str:
    """Why the ROS tests cannot run here ("" when they can)."""
    for tool in ("roscore", "rosbag", "rosservice", "roslaunch"):
        if shutil.which(tool) is None:
            return f"{tool} not found (Debian: ros-core python3-rosbag ...; `make test` " \
                   "installs them when run as root)"
    probe = subprocess.run([sys.executable, "-c", "import rospy, tf2_ros, map_msgs.msg"],
                           capture_output=True, text=True)
    if probe.returncode:
        return "rospy is not importable from this Python (`make setup` links the Debian " \
               "packages into the virtual environment)"
    return ""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Ros:
    """One roscore; ``env`` points clients at it."""

    def __init__(self, folder: Path):
        self.port = free_port()
        self.uri = f"http://127.0.0.1:{self.port}"
        home = folder / "ros_home"
        home.mkdir(parents=True, exist_ok=True)
        self.env = {**os.environ, "ROS_MASTER_URI": self.uri, "ROS_HOME": str(home),
                    "ROS_LOG_DIR": str(home / "log"), "ROS_IP": "127.0.0.1",
                    "PYTHONUNBUFFERED": "1",
                    "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
                    "ROS_PACKAGE_PATH": str(ROOT / "ros")}
        self.env.pop("ROS_HOSTNAME", None)
        self.folder = folder
        self.procs: list[subprocess.Popen] = []
        self.start(["roscore", "-p", str(self.port)], "roscore")
        self.wait(lambda: self.master().getSystemState("/test")[0] == 1, 30, "roscore")

    def master(self):
        return xmlrpc.client.ServerProxy(self.uri)

    def start(self, cmd, name: str) -> subprocess.Popen:
        log = open(self.folder / f"{name}.log", "ab")
        p = subprocess.Popen(cmd, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                             start_new_session=True, cwd=self.folder)
        self.procs.append(p)
        return p

    @staticmethod
    def wait(ready, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                if ready():
                    return
            except (OSError, xmlrpc.client.Error):
                pass
            time.sleep(0.2)
        raise TimeoutError(f"{what} did not come up in {timeout} s")

    def has_service(self, name: str) -> bool:
        code, _, _ = self.master().lookupService("/test", name)
        return code == 1

    def node(self, *args, name="map_updater") -> subprocess.Popen:
        p = self.start([sys.executable, "-m", "mapupdate", "ros1", *args], name)
        self.wait(lambda: self.has_service(f"/{name}/save") or p.poll() is not None, 60,
                  "the map_updater node")
        return p

    def call(self, service: str) -> str:
        out = subprocess.run(["rosservice", "call", service], env=self.env, text=True,
                             capture_output=True, timeout=60)
        return out.stdout + out.stderr

    def play(self, bag, rate: float = 1.0) -> None:
        subprocess.run(["rosbag", "play", "-q", "-r", str(rate), str(bag)], env=self.env,
                       check=True, capture_output=True, timeout=600)

    def grid(self, topic: str, out: Path, timeout: float = 20.0) -> dict:
        """The next (or latched) ``nav_msgs/OccupancyGrid`` of ``topic``, as JSON fields."""
        return self._probe("grid", topic, out, timeout)

    def health(self, node: str, out: Path, timeout: float = 20.0) -> dict:
        """The values of the next ``/diagnostics`` status that ``node`` publishes."""
        return self._probe("diagnostics", f"/{node}: health", out, timeout)

    def _probe(self, kind, what, out, timeout):
        subprocess.run([sys.executable, "-c", PROBE, kind, what, str(out), str(timeout)],
                       env=self.env, check=True, capture_output=True, timeout=timeout + 30)
        return json.loads(out.read_text())

    def stop(self, p: subprocess.Popen) -> None:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGINT)
            p.wait(20)

    def run_script(self, code: str, timeout: float = 60.0) -> str:
        out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=self.env,
                             text=True, capture_output=True, timeout=timeout)
        assert out.returncode == 0, out.stderr
        return out.stdout

    def close(self) -> None:
        for p in reversed(self.procs):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
        for p in reversed(self.procs):
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(10)


PROBE = r"""
import json, sys, time
import rospy
kind, what, out, timeout = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
rospy.init_node("probe", anonymous=True, disable_signals=True)
if kind == "grid":
    from nav_msgs.msg import OccupancyGrid
    m = rospy.wait_for_message(what, OccupancyGrid, timeout=timeout)
    i = m.info
    doc = {"frame_id": m.header.frame_id, "width": i.width, "height": i.height,
           "resolution": i.resolution, "origin": [i.origin.position.x, i.origin.position.y,
           i.origin.orientation.w], "data": list(m.data)}
else:
    from diagnostic_msgs.msg import DiagnosticArray
    end, doc = time.monotonic() + timeout, None
    while doc is None:
        m = rospy.wait_for_message("/diagnostics", DiagnosticArray,
                                   timeout=max(end - time.monotonic(), 0.1))
        for s in m.status:
            if s.name == what:
                doc = {v.key: v.value for v in s.values}
                doc["_level"] = s.level if isinstance(s.level, int) else ord(s.level)
open(out, "w").write(json.dumps(doc))
"""
