"""Replays a recording into a ROS 2 graph, as a robot's drivers and amcl would send it, for a
machine without ``ros2 bag``: LaserScan on /scan (sensor-data QoS), Odometry on /odom,
PoseWithCovarianceStamped on /amcl_pose (transient local, as Nav2's amcl), in the recording's
time order, at ``--rate`` times real time, with the recording's stamps. It starts once every
topic has a subscriber (a scan sent before would be lost).

    python -m robot.ros2.play BAG [--rate 1]
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
from robotlogs.records import OdomRecord, PoseRecord, ScanRecord
from robotlogs.rosbag import read_bag


def stamp(header, t: float) -> None:
    ns = int(round(t * 1e9))
    header.stamp.sec, header.stamp.nanosec = ns // 1_000_000_000, ns % 1_000_000_000


def pose_msg(target, p) -> None:
    target.position.x, target.position.y = float(p.x), float(p.y)
    target.orientation.z, target.orientation.w = math.sin(p.theta / 2), math.cos(p.theta / 2)


def scan_msg(r: ScanRecord) -> LaserScan:
    m, s = LaserScan(), r.scan
    stamp(m.header, r.time)
    m.header.frame_id = r.frame_id
    m.angle_min, m.angle_increment = float(s.angle_min), float(s.angle_increment)
    m.angle_max = float(s.angle_min + (s.beams - 1) * s.angle_increment)
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


def main(bag: str, rate: float) -> int:
    if not (math.isfinite(rate) and 0 < rate <= 1000):
        raise MapUpdatingError(f"--rate must be a number in (0, 1000], got {rate:g}")
    kinds = (ScanRecord, OdomRecord, PoseRecord)
    records = [r for r in read_bag(bag, kinds=("scan", "odom", "pose")) if type(r) in kinds]
    if not records:
        raise MapUpdatingError(f"{bag}: no scans, odometry or poses to play")
    rclpy.init()
    node = rclpy.create_node("recording_player")
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         reliability=ReliabilityPolicy.RELIABLE)
    pubs = {ScanRecord: (node.create_publisher(LaserScan, "scan", qos_profile_sensor_data),
                         scan_msg),
            OdomRecord: (node.create_publisher(Odometry, "odom", 50), odom_msg),
            PoseRecord: (node.create_publisher(PoseWithCovarianceStamped, "amcl_pose",
                                               latched), amcl_msg)}
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


if __name__ == "__main__":
    ap = argparse.ArgumentParser(prog="python -m robot.ros2.play",
                                 description="replay a recording into a ROS 2 graph")
    ap.add_argument("bag", help="ROS 1 bag or ROS 2 bag folder")
    ap.add_argument("--rate", type=float, default=1.0, help="times real time (1)")
    a = ap.parse_args()
    try:
        sys.exit(main(a.bag, a.rate))
    except (MapUpdatingError, OSError) as e:
        print(f"robot.ros2.play: error: {' '.join(str(e).split())}", file=sys.stderr)
        sys.exit(2)
