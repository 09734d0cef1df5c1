"""The node's side of the bond Nav2's lifecycle manager makes with each node it brings up
(bondcpp's protocol): from activation to deactivation, ``bond/msg/Status`` heartbeats on the
``bond`` topic (in the node's namespace, as the manager's) every 0.1 s, with the node's name as
the bond's id and an instance id of its own, the timeouts Nav2's nodes announce
(``nav2_util::LifecycleNode::createBond``). The manager waits for the first one for half its
``bond_timeout`` after activating the node, and takes the node for dead when they stop for
``bond_timeout`` (a crash, a kill -9). Deactivation breaks the bond with ``active: false``; so
does the manager when it lets go, and the node then answers once and stops.

No wheel carries the ``bond`` messages: ``make ros2`` builds them from their definitions
(``ros/msgs/bond``). Without them the node has no bond, says so, and Nav2's manager needs
``bond_timeout: 0.0``."""

from __future__ import annotations

import uuid

from rclpy.qos import QoSProfile

try:
    from bond.msg import Status
except ImportError:
    Status = None

HEARTBEAT_PERIOD = 0.1      # [s] as Nav2's nodes
HEARTBEAT_TIMEOUT = 4.0     # [s] as Nav2's nodes (and the manager's default bond_timeout)


class Bond:
    def __init__(self, node, topic: str = "bond"):
        self.node, self.id = node, node.get_name()
        self.instance_id = str(uuid.uuid4())
        self.sister = ""                   # the manager's instance id, once heard
        self.alive = True
        self._pub = node.create_publisher(Status, topic, QoSProfile(depth=5))
        self._sub = node.create_subscription(Status, topic, self._on_status, 100)
        self._timer = node.create_timer(HEARTBEAT_PERIOD, self._beat)
        self._beat()

    def _beat(self) -> None:
        if self.alive:
            self._publish(True)

    def _publish(self, active: bool) -> None:
        msg = Status()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.id, msg.instance_id, msg.active = self.id, self.instance_id, active
        msg.heartbeat_timeout, msg.heartbeat_period = HEARTBEAT_TIMEOUT, HEARTBEAT_PERIOD
        self._pub.publish(msg)

    def _on_status(self, msg) -> None:
        if msg.id != self.id or msg.instance_id == self.instance_id:
            return                         # another bond's, or our own
        self.sister = msg.instance_id
        if not msg.active and self.alive:  # the manager let go: acknowledge, stop
            self.alive = False
            self._publish(False)

    def close(self) -> None:
        """Break the bond (``active: false``) and stop."""
        if self.alive:
            self.alive = False
            self._publish(False)
        self.node.destroy_timer(self._timer)
        self.node.destroy_subscription(self._sub)
        self.node.destroy_publisher(self._pub)
