"""Calls a ``std_srvs/Trigger`` service (the node's ``~/save``, ``~/commit``, ``~/reset``) and
prints its answer, for a machine without the ``ros2`` command (a tool of the repository, not
of the installed package); exit 1 when it says no.

    python ros/tools/trigger.py /map_updater/save
"""

from __future__ import annotations

import sys

import rclpy
from std_srvs.srv import Trigger


def call(service: str, timeout: float = 30.0) -> tuple[bool, str]:
    rclpy.init()
    node = rclpy.create_node("trigger_client")
    try:
        try:
            client = node.create_client(Trigger, service)
        except Exception as e:  # noqa: BLE001 - rclpy's refusal of a name, in its own words
            return False, f"{service!r} is not a service name ({' '.join(str(e).split())[:120]})"
        if not client.wait_for_service(timeout_sec=timeout):
            return False, f"no service {service} within {timeout:g} s"
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
        answer = future.result()
        if answer is None:
            return False, f"{service} did not answer within {timeout:g} s"
        return answer.success, answer.message
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python ros/tools/trigger.py SERVICE")
    ok, message = call(sys.argv[1])
    print(f"{'success' if ok else 'failed'}: {message}")
    sys.exit(0 if ok else 1)
