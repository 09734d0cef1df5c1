"""A lifecycle manager that brings nodes up and watches them as Nav2's
(nav2_lifecycle_manager, Jazzy) does, for the tests: no wheel carries Nav2.

For each name of ``--node-names`` in turn: ``change_state`` configure, then activate, each
checked with ``get_state``; then a bond (bondcpp's protocol on ``bond``, ``bond/msg/Status``)
with the node's name as its id, heartbeats every 0.1 s and ``--bond-timeout`` as their
timeout, which must form (a heartbeat from the node) within half the timeout, or the bringup is
aborted ("Server X was unable to be reached after T s by bond"). Then every 0.2 s whether a
bond is broken: no heartbeat for the timeout. Prints one JSON line per event, with the
time since start [s]; exits once every bond is broken, or after ``--watch`` seconds.

    python tests/nav2_like_manager.py --node-names map_updater [--bond-timeout 4] [--watch 60]
"""

from __future__ import annotations

import argparse
import json
import time
import uuid

import rclpy
from bond.msg import Status
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.qos import QoSProfile

GOAL = {Transition.TRANSITION_CONFIGURE: "inactive", Transition.TRANSITION_ACTIVATE: "active"}
T0 = time.monotonic()


def say(event: str, **more) -> None:
    print(json.dumps({"event": event, "t": round(time.monotonic() - T0, 3), **more}),
          flush=True)


class BondWatch:
    """The manager's side of one bond."""

    def __init__(self, node, name: str, timeout: float):
        self.node, self.id, self.timeout = node, name, timeout
        self.instance_id = str(uuid.uuid4())
        self.state = "waiting"                 # waiting -> alive -> dead
        self.heard = None
        self.pub = node.create_publisher(Status, "bond", QoSProfile(depth=5))
        self.sub = node.create_subscription(Status, "bond", self.on_status, 100)
        self.timer = node.create_timer(0.1, self.beat)

    def beat(self) -> None:
        msg = Status(id=self.id, instance_id=self.instance_id, active=self.state != "dead",
                     heartbeat_timeout=float(self.timeout), heartbeat_period=0.1)
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.pub.publish(msg)
        if self.state == "alive" and time.monotonic() - self.heard > self.timeout:
            self.state = "dead"

    def on_status(self, msg) -> None:
        if msg.id != self.id or msg.instance_id == self.instance_id or self.state == "dead":
            return
        if msg.active:
            self.state, self.heard = "alive", time.monotonic()
        else:
            self.state = "dead"


def call(node, client, request, timeout: float = 10.0):
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
    return future.result()


def bring_up(node, name: str) -> bool:
    change = node.create_client(ChangeState, f"{name}/change_state")
    get = node.create_client(GetState, f"{name}/get_state")
    if not (change.wait_for_service(timeout_sec=60) and get.wait_for_service(timeout_sec=60)):
        say("unreachable", node=name)
        return False
    for transition, goal in GOAL.items():
        request = ChangeState.Request()
        request.transition.id = transition
        answer = call(node, change, request, timeout=120)
        label = call(node, get, GetState.Request()).current_state.label
        if answer is None or not answer.success or label != goal:
            say("failed to change state", node=name, transition=transition, state=label)
            return False
        say(goal, node=name)
    return True


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--node-names", nargs="+", required=True)
    ap.add_argument("--bond-timeout", type=float, default=4.0)
    ap.add_argument("--watch", type=float, default=60.0)
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("lifecycle_manager_test")
    bonds = []
    for name in a.node_names:
        if not bring_up(node, name):
            say("aborting bringup", node=name)
            return 1
        bond = BondWatch(node, name.rsplit("/", 1)[-1], a.bond_timeout)
        end = time.monotonic() + a.bond_timeout / 2
        while bond.state == "waiting" and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        if bond.state != "alive":
            say("unable to be reached by bond", node=name, after=a.bond_timeout)
            say("aborting bringup", node=name)
            return 1
        say("bond formed", node=name)
        bonds.append(bond)
    say("active")
    end = time.monotonic() + a.watch
    while time.monotonic() < end and any(b.state != "dead" for b in bonds):
        rclpy.spin_once(node, timeout_sec=0.2)
        for b in bonds:
            if b.state == "dead" and not getattr(b, "said", False):
                b.said = True
                say("bond broken", node=b.id, silent_for=round(time.monotonic() - b.heard, 3))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
