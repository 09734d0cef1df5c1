"""Replays a recording into a ROS 2 graph, as a robot's drivers and amcl would send it, for a
machine without ``ros2 bag`` (a tool of the repository, not of the installed package): LaserScan on /scan (sensor-data QoS) and the poses, by
``--poses``: "tf", the recording's /tf and, first and latched, its /tf_static (what the node's
default ``pose_source`` reads; needs the tf2_msgs package ``make ros2`` builds); or
"amcl_pose", Odometry on /odom and PoseWithCovarianceStamped on /amcl_pose (transient local, as
Nav2's amcl). In the recording's time order, at ``--rate`` times real time, with the
recording's stamps. It starts once every topic has a subscriber (a scan sent before would be
lost). ``--flip-laser``: as if the lidar were mounted upside down (rolled by pi) at the same
place and yaw: its /tf_static mount says so, and each scan is sent as that lidar sees the same
beams (each angle negated). ``--namespace robot1``: into a robot's namespace
(``/robot1/scan``, ``/robot1/tf``, ...), as a fleet's node there reads them (docs/ros2.md).

    python ros/tools/play.py BAG [--rate 1] [--poses tf|amcl_pose] [--flip-laser]
                             [--namespace NS]
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np
import rclpy
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

from gridmap import MapUpdatingError
from robotlogs.records import OdomRecord, PoseRecord, ScanRecord, TransformRecord
from robotlogs.rosbag import read_bag


def stamp(header, t: float) -> None:
    ns = int(round(t * 1e9))
    header.stamp.sec, header.stamp.nanosec = ns // 1_000_000_000, ns % 1_000_000_000


def pose_msg(target, p) -> None:
    target.position.x, target.position.y = float(p.x), float(p.y)
    target.orientation.z, target.orientation.w = math.sin(p.theta / 2), math.cos(p.theta / 2)


def scan_msg(r: ScanRecord, flip: bool = False) -> LaserScan:
    m, s = LaserScan(), r.scan
    stamp(m.header, r.time)
    m.header.frame_id = r.frame_id
    sign = -1.0 if flip else 1.0
    m.angle_min, m.angle_increment = sign * float(s.angle_min), sign * float(s.angle_increment)
    m.angle_max = sign * float(s.angle_min + (s.beams - 1) * s.angle_increment)
    m.range_min, m.range_max = float(s.range_min), float(s.range_max)
    m.ranges = np.asarray(s.ranges, np.float32).tolist()
    return m


def odom_msg(r: OdomRecord) -> Odometry:
    m = Odometry()
    stamp(m.header, r.time)
    m.header.frame_id, m.child_frame_id = r.frame_id, r.child_frame_id
    pose_msg(m.pose.pose, r.pose)
    return m


def amcl_msg(r: PoseRecord) -> PoseWithCovarianceStamped:
    m = PoseWithCovarianceStamped()
    stamp(m.header, r.time)
    m.header.frame_id = r.frame_id
    pose_msg(m.pose.pose, r.pose)
    return m


def tf_msg(records, flip_frames=()):
    """``flip_frames``: the child frames rolled by pi (q = qz(yaw) qx(pi))."""
    from tf2_msgs.msg import TFMessage
    from geometry_msgs.msg import TransformStamped
    m = TFMessage()
    for r in records:
        t = TransformStamped()
        stamp(t.header, r.time)
        t.header.frame_id, t.child_frame_id = r.parent, r.child
        t.transform.translation.x, t.transform.translation.y = float(r.pose.x), float(r.pose.y)
        c, s = math.cos(r.pose.theta / 2), math.sin(r.pose.theta / 2)
        q = t.transform.rotation
        if r.child in flip_frames:
            q.x, q.y, q.z, q.w = c, s, 0.0, 0.0
        else:
            q.z, q.w = s, c
        m.transforms.append(t)
    return m


def _publishers(node, poses: str, flip_frames=()) -> dict:
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         reliability=ReliabilityPolicy.RELIABLE)
    pubs = {ScanRecord: (node.create_publisher(LaserScan, "scan", qos_profile_sensor_data),
                         lambda r: scan_msg(r, bool(flip_frames)))}
    if poses == "tf":
        from tf2_msgs.msg import TFMessage
        pubs[TransformRecord] = (node.create_publisher(TFMessage, "/tf", 100),
                                 lambda r: tf_msg([r]))
        pubs["static"] = (node.create_publisher(TFMessage, "/tf_static", latched),
                          lambda rs: tf_msg(rs, flip_frames))
    else:
        pubs[OdomRecord] = (node.create_publisher(Odometry, "odom", 50), odom_msg)
        pubs[PoseRecord] = (node.create_publisher(PoseWithCovarianceStamped, "amcl_pose",
                                                  latched), amcl_msg)
    return pubs


def _records(bag: str, poses: str) -> tuple[list, list]:
    """(the records to play in order, the static transforms)"""
    if poses not in ("tf", "amcl_pose"):
        raise MapUpdatingError(f"--poses must be tf or amcl_pose, got {poses!r}")
    if poses == "tf":
        try:
            import tf2_msgs.msg  # noqa: F401
        except ImportError:
            raise MapUpdatingError("--poses tf needs the tf2_msgs package, which has no "
                                   "wheel: `make ros2` builds it") from None
    kinds = ("scan", "tf") if poses == "tf" else ("scan", "odom", "pose")
    types = (ScanRecord, TransformRecord) if poses == "tf" else \
        (ScanRecord, OdomRecord, PoseRecord)
    records = [r for r in read_bag(bag, kinds=kinds) if type(r) in types]
    static = [r for r in records if isinstance(r, TransformRecord) and r.static]
    records = [r for r in records if not (isinstance(r, TransformRecord) and r.static)]
    if not any(isinstance(r, ScanRecord) for r in records) or len(records) < 2:
        raise MapUpdatingError(f"{bag}: no scans and poses to play (--poses {poses})")
    return records, static


def main(bag: str, rate: float, poses: str = "tf", flip: bool = False,
         namespace: str | None = None) -> int:
    if not (math.isfinite(rate) and 0 < rate <= 1000):
        raise MapUpdatingError(f"--rate must be a number in (0, 1000], got {rate:g}")
    records, static = _records(bag, poses)
    if flip and poses != "tf":
        raise MapUpdatingError("--flip-laser needs --poses tf (the mount is on /tf_static)")
    lasers = {r.frame_id for r in records if isinstance(r, ScanRecord)} if flip else set()
    rclpy.init(args=None if namespace is None else remapped_into(namespace))
    node = rclpy.create_node("recording_player")
    pubs = _publishers(node, poses, lasers)
    if static:
        pub, convert = pubs.pop("static")
        pub.publish(convert(static))
    # discovery: a scan sent before the node's subscription matched would be lost
    end = time.monotonic() + 60
    while any(pub.get_subscription_count() == 0 for pub, _ in pubs.values()):
        if time.monotonic() > end:
            raise SystemExit("nobody subscribed to the recording's topics within 60 s")
        time.sleep(0.1)
    time.sleep(1.0)                  # and the subscribers' side of the match (best effort)
    t0, wall0 = records[0].time, time.monotonic()
    for r in records:
        wait = (r.time - t0) / rate - (time.monotonic() - wall0)
        if wait > 0:
            time.sleep(wait)
        pub, convert = pubs[type(r)]
        pub.publish(convert(r))
    time.sleep(1.0)
    node.destroy_node()
    rclpy.shutdown()
    print(f"played {len(records)} messages in {time.monotonic() - wall0:.1f} s")
    return 0


def remapped_into(namespace: str) -> list[str]:
    """ROS arguments that put the player in ``namespace``, /tf and /tf_static included (they
    are absolute names, as in Nav2)."""
    name = namespace.strip("/")
    if not name or not all(part.isidentifier() for part in name.split("/")):
        raise MapUpdatingError(f"--namespace must be a ROS name such as robot1, got "
                               f"{namespace!r}")
    return ["play", "--ros-args", "-r", f"__ns:=/{name}", "-r", "/tf:=tf", "-r",
            "/tf_static:=tf_static"]


if __name__ == "__main__":
    ap = argparse.ArgumentParser(prog="ros/tools/play.py",
                                 description="replay a recording into a ROS 2 graph")
    ap.add_argument("bag", help="ROS 1 bag or ROS 2 bag folder")
    ap.add_argument("--rate", type=float, default=1.0, help="times real time (1)")
    ap.add_argument("--poses", default="tf", choices=("tf", "amcl_pose"),
                    help="/tf and /tf_static (tf), or /odom and /amcl_pose")
    ap.add_argument("--flip-laser", action="store_true",
                    help="as if the lidar were mounted upside down at the same place")
    ap.add_argument("--namespace", default=None,
                    help="a robot's namespace to play into (its /tf and /tf_static too)")
    a = ap.parse_args()
    try:
        sys.exit(main(a.bag, a.rate, a.poses, a.flip_laser, a.namespace))
    except (MapUpdatingError, OSError) as e:
        print(f"play.py: error: {' '.join(str(e).split())}", file=sys.stderr)
        sys.exit(2)
