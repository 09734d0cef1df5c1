"""The live ROS 2 node (``mapupdate ros2``): the one robot pipeline as a lifecycle node, as
Nav2's map_server and amcl are, so that Nav2's lifecycle manager brings it up and down.

- configure: the parameters (validated as the YAML configs are; a misspelt name fails the
  transition with the nearest valid one) and the reference map (``--map``, or the
  transient-local ``map`` topic as Nav2's map_server publishes it); the services.
- activate: the subscriptions (scans best effort, as lidars publish, with a history of
  ``queue_size``; the poses) and the publications (``map_updated``, transient local, each
  ``publish_period`` when it changed; ``map_updated_updates``, the box of cells changed
  since the last publication, as the costmap's static layer reads with
  ``subscribe_to_updates``; ``/diagnostics``).
- deactivate, cleanup: stop those, then drop the map and the buffers.

Poses (``pose_source``): "tf", each scan's ``map -> odom -> base_frame -> laser`` from /tf
and /tf_static at its stamp, as Nav2's nodes look them up; or "amcl_pose", ``/amcl_pose`` with
``/odom`` (the ``map -> odom`` amcl would publish, composed as the log replay composes it) and
the laser's mount from the ``laser_mount`` parameter. No wheel carries ``tf2_msgs`` or
``map_msgs``: ``make ros2`` builds them from their definitions (``ros/build-ros2-msgs.sh``);
without them the node needs ``pose_source:=amcl_pose`` and publishes no updates. Each scan
waits for the odometry (and the localiser's correction) past its stamp, so it is placed
exactly where ``mapupdate update`` places it in the recording.

"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from gridmap import MapUpdatingError, OccupancyGrid, Pose2D, load_map, save_map
from localization.confidence import PoseCheck
from localization.smoothing import PoseSmoother
from robotlogs.records import TransformRecord
from robotlogs.rosbag import pose_pose, stamp_seconds, transform_pose

from ..methods import make_method
from ..pipeline import RobotPipeline, warm_up
from ..robot_config import load_robot_config
from ..ros_common.grids import changed_box, grid_from_message, message_fields
from ..ros_common.health import Health, pipeline_values
from ..ros_common.poses import LivePoses, TfPoses
from ..ros_common.queue import ScanQueue, scan_bytes
from ..ros_common.scans import has_bad_ranges, usable_scan
from ..ros_common.settings import Ros2Settings, node_settings, refuse_saving_over_the_map
from ..ros_common.store_link import StoreLink
from .parameters import declare_all, overrides_as_dict

WHEELS = ("ros-jazzy-rclpy ros-jazzy-rmw-fastrtps-cpp ros-jazzy-nav-msgs "
          "ros-jazzy-sensor-msgs ros-jazzy-geometry-msgs ros-jazzy-std-srvs "
          "ros-jazzy-diagnostic-msgs ros-jazzy-lifecycle-msgs")

try:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from nav_msgs.msg import OccupancyGrid as GridMsg
    from nav_msgs.msg import Odometry
    from rclpy.executors import ExternalShutdownException
    from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import LaserScan
    from std_srvs.srv import Trigger
except ImportError as e:  # a robot without the ROS 2 wheels: said in one line by the command
    raise MapUpdatingError(f"mapupdate ros2 needs ROS 2 Jazzy's Python packages ({e}): pip "
                           f"install 'lidar-map-updating[ros2]' (or {WHEELS})") from None
try:                 # built from their definitions by `make ros2` (no wheel carries them)
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None
try:
    from map_msgs.msg import OccupancyGridUpdate
except ImportError:
    OccupancyGridUpdate = None
NO_TF2_MSGS = ("pose_source 'tf' needs the tf2_msgs package, which has no wheel: `make ros2` "
               "builds it (ros/build-ros2-msgs.sh), or set pose_source:=amcl_pose")

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)   # as tf2's listener
SUCCESS, FAILURE = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE


class MapUpdaterNode(LifecycleNode):
    def __init__(self, map_path=None, config_path=None, name: str = "map_updater"):
        super().__init__(name)
        self.map_path, self.config_path = map_path, config_path
        self.health = Health()
        self.pipeline: RobotPipeline | None = None
        self.settings: Ros2Settings | None = None
        self.failure = ""                       # why the last configure failed
        # logged for a lifecycle manager; with --autostart the command line says it instead
        self.log_failure = True
        self.store: StoreLink | None = None     # the map store, with the ``store`` parameter
        self._active = []                       # what activate made and deactivate destroys
        self._configured = []                   # what configure made and cleanup destroys
        self._reset_state()

    def _reset_state(self) -> None:
        s = self.settings
        self.poses = TfPoses(s.map_frame, s.odom_frame, s.base_frame) \
            if s is not None and s.pose_source == "tf" else LivePoses()
        # (record, arrival) waiting for their poses
        self._scans = ScanQueue(self.settings.queue_size if self.settings else 1)
        self._published: np.ndarray | None = None

    # --- lifecycle ----------------------------------------------------------------------------
    def _LifecycleNodeMixin__change_state(self, transition_id: int):
        # rclpy raises inside its change_state service for a transition the current state does
        # not have (activate before configure), which ends the node: refuse it as a failed
        # transition instead, as a lifecycle manager expects
        if transition_id not in {t[0] for t in self._state_machine.available_transitions}:
            label = self._state_machine.current_state[1]
            self.get_logger().warn(f"transition {transition_id} refused: not available in "
                                   f"state '{label}'")
            return FAILURE
        return super()._LifecycleNodeMixin__change_state(transition_id)

    def on_configure(self, state) -> TransitionCallbackReturn:
        try:
            base = load_robot_config(self.config_path)
            params = overrides_as_dict(self)
            self.settings, self.updater_config, self.pose_check_config = node_settings(
                params, base, Ros2Settings)
            refuse_saving_over_the_map(self.settings.save_path, self.map_path)
            if self.settings.pose_source == "tf" and TFMessage is None:
                raise MapUpdatingError(NO_TF2_MSGS)
            declare_all(self, self.settings, self.updater_config, self.pose_check_config)
            reference = load_map(self.map_path) if self.map_path is not None else None
            s = self.settings
            self.store = StoreLink(s.store, s.robot_name, s.store_poll_period) if s.store \
                else None
            if self.store is not None:
                reference = self.store.start(reference)
        except (MapUpdatingError, OSError) as e:
            self.failure = " ".join(str(e).split())
            if self.log_failure:
                self.get_logger().error(f"configure: {self.failure}")
            return FAILURE
        s = self.settings
        self._reset_state()
        warm_up(self._pipeline_on)
        self._configured = [self.create_service(Trigger, f"~/{name}", handler)
                            for name, handler in (("save", self._save),
                                                  ("commit", self._commit),
                                                  ("reset", self._reset))]
        if reference is not None:
            self._adopt(reference)
        else:
            self._configured.append(self.create_subscription(GridMsg, s.map_topic,
                                                             self._on_map, LATCHED))
        self.map_pub = self.create_lifecycle_publisher(GridMsg, "map_updated", LATCHED)
        self.update_pub = None if OccupancyGridUpdate is None else \
            self.create_lifecycle_publisher(OccupancyGridUpdate, "map_updated_updates", 10)
        self.diag_pub = self.create_lifecycle_publisher(DiagnosticArray, "/diagnostics", 10)
        self.get_logger().info(f"configured ({self.map_path or 'waiting for ' + s.map_topic}; "
                               f"scans on {', '.join(s.scan_topics)})")
        return SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        s = self.settings
        # best effort, as lidar drivers publish; the history as long as the node's own queue,
        # so that a busy moment drops scans there, counted, and not unseen in the middleware
        scan_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=s.queue_size,
                              reliability=ReliabilityPolicy.BEST_EFFORT,
                              durability=DurabilityPolicy.VOLATILE)
        subs = [self.create_subscription(LaserScan, topic, self._scan_handler(topic), scan_qos)
                for topic in dict.fromkeys(s.scan_topics)]
        if s.pose_source == "tf":
            subs.append(self.create_subscription(TFMessage, "/tf",
                                                 lambda m: self._on_tf(m, False), TF_QOS))
            subs.append(self.create_subscription(TFMessage, "/tf_static",
                                                 lambda m: self._on_tf(m, True), LATCHED))
        else:
            subs.append(self.create_subscription(Odometry, s.odom_topic, self._on_odom, 50))
            subs.append(self.create_subscription(PoseWithCovarianceStamped, s.pose_topic,
                                                 self._on_pose, LATCHED))
        self._active = subs
        self._timer = self.create_timer(s.publish_period, self._publish)
        self._published = None                  # the map goes out at once on activation
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        for sub in self._active:
            self.destroy_subscription(sub)
        self._active = []
        self.destroy_timer(self._timer)
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        for entity in self._configured:
            if hasattr(entity, "srv_type"):
                self.destroy_service(entity)
            else:
                self.destroy_subscription(entity)
        self._configured = []
        self.destroy_lifecycle_publisher(self.map_pub)
        self.destroy_lifecycle_publisher(self.diag_pub)
        if self.update_pub is not None:
            self.destroy_lifecycle_publisher(self.update_pub)
        self.pipeline = None
        self._reset_state()
        return SUCCESS

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        return SUCCESS

    # --- the map ------------------------------------------------------------------------------
    def _adopt(self, reference: OccupancyGrid) -> None:
        self.pipeline = self._pipeline_on(reference)
        self._published = None

    def _pipeline_on(self, reference: OccupancyGrid) -> RobotPipeline:
        s = self.settings
        check = PoseCheck(reference, self.pose_check_config) if s.use_pose_check else None
        smoother = PoseSmoother(s.smooth_poses) if s.smooth_poses > 0 else None
        return RobotPipeline(make_method(s.method, reference, self.updater_config),
                             pose_check=check, smoother=smoother)

    def _on_map(self, msg) -> None:
        try:
            grid = grid_from_message(msg)
        except MapUpdatingError as e:
            return self._skip("map message unusable", e)
        if self.pipeline is not None:
            ref = self.pipeline.updater.reference_map
            if not ref.same_frame(grid):
                return self._skip("map of another size, resolution or origin",
                                  f"{grid.shape} at {grid.resolution} m")
            if np.array_equal(ref.data, grid.data):
                return
        if self.store is not None and self.store.version is None:
            try:                                # an empty store: this map is its first version
                grid = self.store.start(grid)
            except MapUpdatingError as e:
                return self._skip("map store unusable", e)
        self._adopt(grid)
        self.health.counts["maps_received"] += 1

    # --- poses and scans ----------------------------------------------------------------------
    def _on_odom(self, msg) -> None:
        pose = pose_pose(msg.pose.pose)
        if not pose.is_finite():
            return self._skip("odometry not finite", pose)
        self.poses.add_odometry(stamp_seconds(msg.header), pose)
        self._drain()

    def _on_pose(self, msg) -> None:
        pose = pose_pose(msg.pose.pose)
        if not pose.is_finite():
            return self._skip("localisation not finite", pose)
        self.poses.add_localisation(stamp_seconds(msg.header), pose)
        self._drain()

    def _on_tf(self, msg, static: bool) -> None:
        """One /tf or /tf_static message: all of its transforms or, one not finite, none."""
        records = []
        for tr in msg.transforms:
            pose = transform_pose(tr.transform)
            if not pose.is_finite():
                return self._skip("transform not finite", f"{tr.child_frame_id}: {pose}")
            records.append(TransformRecord(stamp_seconds(tr.header),
                                           tr.header.frame_id.lstrip("/"),
                                           tr.child_frame_id.lstrip("/"), pose, static=static))
        for rec in records:
            self.poses.add(rec)
        self._drain()

    def _scan_handler(self, topic: str):
        return lambda msg: self._on_scan(msg, topic)

    def _on_scan(self, msg, topic: str) -> None:
        self.health.counts["scans_received"] += 1
        rec, skip = usable_scan(msg, topic)
        if skip is not None:
            return self._skip(*skip)
        self.health.counts["scans_dropped_behind"] += self._scans.push(
            (rec, time.perf_counter()), scan_bytes(rec.scan.ranges))
        self._drain()

    def _drain(self, force: bool = False) -> None:
        """Place and use every waiting scan the odometry has passed (all of them, ``force``,
        when the odometry has stopped for longer than ``tf_timeout``)."""
        while self._scans and (force or self.poses.ready(self._scans.first()[0].time)):
            rec, arrival = self._scans.pop()
            t0 = time.perf_counter()
            try:
                self._use(rec)
            except Exception as e:  # noqa: BLE001 - whatever one scan raises, the node goes on
                self._skip(f"scan raised {type(e).__name__}", e)
            done = time.perf_counter()
            self.health.times.append(done - t0)
            self.health.latencies.append(done - arrival)

    def _use(self, rec) -> None:
        if self.pipeline is None:
            return self._skip("no reference map yet", rec.topic)
        if has_bad_ranges(rec):
            self.health.counts["scans_with_bad_ranges"] += 1
        robot, odom = self.poses.at(rec.time)
        if robot is None:
            return self._skip("no localisation or odometry at the scan's time", rec.time)
        if self.settings.pose_source == "tf":
            # looked up at every scan: a corrected /tf_static counts from then on
            mount = self.poses.mount(rec.frame_id.lstrip("/"), rec.time)
            if mount is None:
                return self._skip("no transform from the base to the scan's frame",
                                  rec.frame_id)
        else:
            mount = Pose2D(*self.settings.laser_mount)
        self.pipeline.step(rec.scan, mount, odometry=odom, pose=robot)
        self.health.counts["scans_used"] += 1

    def _skip(self, why: str, detail) -> None:
        self.health.skipped[why] += 1
        if self.health.skipped[why] == 1:
            self.get_logger().warn(f"{why} ({detail}); further ones counted on /diagnostics")
        return None

    # --- output -------------------------------------------------------------------------------
    def _publish(self) -> None:
        if self._scans and time.perf_counter() - self._scans.first()[1] > self.settings.tf_timeout:
            self._drain(force=True)             # the odometry stopped: use what waits
        counts = {}
        self._take_newer_version()
        if self.pipeline is not None:
            grid = self.pipeline.updater.updated_map()
            counts = pipeline_values(self.pipeline, self.settings.method)
            before = self._published
            if before is None or not np.array_equal(before, grid.data):
                self.map_pub.publish(self._grid_msg(grid))
                box = None if before is None else changed_box(before, grid.data)
                if box is not None and self.update_pub is not None:
                    self.update_pub.publish(self._update_msg(box, grid))
                self._published = grid.data
                self.health.counts["maps_published"] += 1
        self._diagnostics(counts)

    def _grid_msg(self, grid: OccupancyGrid) -> GridMsg:
        f = message_fields(grid)
        msg = GridMsg()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.settings.map_frame
        msg.info.map_load_time = msg.header.stamp
        msg.info.resolution = f["resolution"]
        msg.info.width, msg.info.height = f["width"], f["height"]
        msg.info.origin.position.x, msg.info.origin.position.y = f["origin"]
        msg.info.origin.orientation.w = 1.0
        msg.data = f["data"]
        return msg

    def _update_msg(self, box, grid: OccupancyGrid):
        x, y, w, h = box
        msg = OccupancyGridUpdate()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.settings.map_frame
        msg.x, msg.y, msg.width, msg.height = x, y, w, h
        msg.data = grid.data[y:y + h, x:x + w].reshape(-1).tolist()
        return msg

    def _diagnostics(self, counts: dict) -> None:
        status = DiagnosticStatus()
        status.name = f"{self.get_fully_qualified_name()}: health"
        status.hardware_id = self.settings.map_frame
        worrying = self.health.counts["scans_dropped_behind"] or sum(self.health.skipped.values())
        status.level = DiagnosticStatus.WARN if worrying else DiagnosticStatus.OK
        status.message = "scans dropped or skipped" if worrying else "ok"
        status.values = [KeyValue(key=k, value=v) for k, v in self.health.values(counts)]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        self.diag_pub.publish(array)

    # --- services -----------------------------------------------------------------------------
    def _save(self, _request, response):
        if self.pipeline is None:
            return _answer(response, False, "no reference map yet")
        self._drain(force=True)
        try:
            save_map(self.pipeline.updater.updated_map(), Path(self.settings.save_path))
        except (MapUpdatingError, OSError) as e:
            return _answer(response, False, f"cannot save: {e}")
        return _answer(response, True, f"saved {self.settings.save_path}")

    def _commit(self, _request, response):
        if self.pipeline is None:
            return _answer(response, False, "no reference map yet")
        self._drain(force=True)
        if self.store is None:
            self._adopt(self.pipeline.updater.updated_map())
            return _answer(response, True, "the updated map is the reference now")
        ok, said, then = self.store.commit_session(self.pipeline, self.settings.method,
                                                   self.updater_config)
        if ok:
            self._adopt(then)
        return _answer(response, ok, said)

    def _take_newer_version(self) -> None:
        """A newer approved version in the store (another robot's, or this one's reviewed)
        becomes the reference, buffers afresh."""
        if self.store is None or self.pipeline is None:
            return
        try:
            newer = self.store.newer()
        except MapUpdatingError as e:
            return self._skip("map store unusable", e)
        if newer is not None:
            self._adopt(newer[1])
            self.health.counts["store_versions_taken"] += 1
        self.health.counts["store_version"] = self.store.version or 0

    def _reset(self, _request, response):
        if self.pipeline is None:
            return _answer(response, False, "no reference map yet")
        self._adopt(self.pipeline.updater.reference_map)
        return _answer(response, True, "buffers cleared; the reference is unchanged")

    def summary(self) -> str:
        counts = pipeline_values(self.pipeline, self.settings.method) \
            if self.pipeline is not None and self.settings is not None else {}
        return ", ".join(f"{k} {v}" for k, v in self.health.values(counts))


def _answer(response, success: bool, message: str):
    response.success, response.message = success, message
    return response


def run_node(map_path=None, config_path=None, autostart: bool = False, argv=None) -> int:
    """``mapupdate ros2``: spin the lifecycle node until shut down; with ``autostart``,
    configure and activate it at once (a failed transition ends the command, said in one
    line)."""
    rclpy.init(args=argv if argv is not None else sys.argv)
    node = MapUpdaterNode(map_path, config_path)
    node.log_failure = not autostart        # one line, the command's, for a failed start
    try:
        if autostart:
            for step in (node.trigger_configure, node.trigger_activate):
                if step() != SUCCESS:
                    raise MapUpdatingError(f"the node did not come up: {step.__name__[8:]} "
                                           f"failed: {node.failure or 'see its log'}")
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # on SIGINT rclpy's context is already shut down, and its logger with it
        summary = node.summary() if node.settings is not None else ""
        if summary:
            print(f"{node.get_name()}: {summary}", flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
