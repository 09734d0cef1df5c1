"""The live ROS 2 node (``mapupdate ros2``, ``ros2 run lidar_map_updating map_updater``): the
one robot pipeline as a lifecycle node, as Nav2's map_server and amcl are, so that Nav2's
lifecycle manager brings it up and down and watches it through a bond (``bond``).

- construction: the parameters, declared with their types and ranges (``parameters``); the
  lifecycle services (``lifecycle``).
- configure: the parameters checked (a bad one fails the transition, said in one line) and
  the reference map (``--map``, or the transient-local ``map`` topic as Nav2's map_server
  publishes it); a map and buffers this node saved before, at ``save_path``, resumed; the
  services.
- activate: the subscriptions (scans best effort, as lidars publish, with a history of
  ``queue_size``; the poses), the publications (``map_updated`` and
  ``map_updated_metadata``, transient local, each ``publish_period`` when it changed;
  ``map_updated_updates``, the box of cells changed since the last publication, as the
  costmap's static layer reads with ``subscribe_to_updates``; ``/diagnostics``), the bond.
- deactivate, cleanup: stop those, then drop the map and the buffers; shutdown ends the
  process.

Poses (``pose_source``): "tf", each scan's ``map -> odom -> base_frame -> laser`` from /tf
and /tf_static at its stamp, as Nav2's nodes look them up, quaternions checked as tf2 checks
them and a lidar mounted upside down read as such; or "amcl_pose", ``/amcl_pose`` with
``/odom`` and the laser's mount from the ``laser_mount`` parameter. Each scan waits for the
odometry (and the localiser's correction) past its stamp, so it is placed exactly where
``mapupdate update`` places it in the recording.
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
from robotlogs.rosbag import stamp_seconds

from ..methods import face_cells, make_method, next_session
from ..pipeline import RobotPipeline, warm_up
from ..robot_config import load_robot_config
from ..ros_common.gaps import Gaps
from ..ros_common.grids import grid_from_message
from ..ros_common.health import Health, pipeline_values
from ..ros_common.poses import LivePoses, TfPoses
from ..ros_common.queue import ScanQueue, scan_bytes
from ..ros_common.scans import has_bad_ranges, usable_scan
from ..ros_common.settings import Ros2Settings, node_settings, profile_line
from ..ros_common.transforms import TransformError, ascending, mirrored, planar, unit_quaternion

WHEELS = ("ros-jazzy-rclpy ros-jazzy-rmw-fastrtps-cpp ros-jazzy-nav-msgs "
          "ros-jazzy-sensor-msgs ros-jazzy-geometry-msgs ros-jazzy-std-srvs "
          "ros-jazzy-diagnostic-msgs ros-jazzy-lifecycle-msgs")

try:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from lifecycle_msgs.msg import Transition
    from nav_msgs.msg import MapMetaData
    from nav_msgs.msg import OccupancyGrid as GridMsg
    from nav_msgs.msg import Odometry
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.qos_overriding_options import QoSOverridingOptions
    from sensor_msgs.msg import LaserScan
except ImportError as e:  # a robot without the ROS 2 wheels: said in one line by the command
    raise MapUpdatingError(f"mapupdate ros2 needs ROS 2 Jazzy's Python packages ({e}): pip "
                           f"install 'lidar-map-updating[ros2]' (or {WHEELS})") from None
from . import services
from .bond import Bond
from .bond import Status as BondStatus
from .lifecycle import Lifecycle
from .parameters import declare_all, given_parameters, valueless

try:                 # built from their definitions by `make ros2` (no wheel carries them)
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None
NO_TF2_MSGS = ("pose_source 'tf' needs the tf2_msgs package, which has no wheel: `make ros2` "
               "builds it (ros/build-ros2-msgs.sh), or set pose_source:=amcl_pose")

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)   # as tf2's listener
SUCCESS, FAILURE = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE
# [s] a scan stamped this far past the newest odometry will find no pose: skipped at once
# rather than holding every later scan back for tf_timeout
AHEAD_S = 2.0


class MapUpdaterNode(LifecycleNode):
    def __init__(self, map_path=None, config_path=None, name: str = "map_updater"):
        super().__init__(name, enable_communication_interface=False,
                         automatically_declare_parameters_from_overrides=True)
        self.map_path, self.config_path = map_path, config_path
        self.lifecycle = Lifecycle(self)
        self.health = Health()
        self.pipeline: RobotPipeline | None = None
        self.failure = ""                       # why the last configure failed
        # logged for a lifecycle manager; with --autostart the command line says it instead
        self.log_failure = True
        self.store = None                       # the map store, with the ``store`` parameter
        self.bond: Bond | None = None
        self._gaps = Gaps()
        self._active = []                       # what activate made and deactivate destroys
        self._configured = []                   # what configure made and cleanup destroys
        self._outputs = {}                      # the lifecycle publishers configure made
        self.parameter_error = ""
        self._save_refusal = ""                 # why ``save`` may not write save_path
        given, foreign = given_parameters(self)
        if foreign:
            self.get_logger().info(f"parameters that are not this node's, left alone: "
                                   f"{', '.join(foreign)}")
        try:
            base = load_robot_config(config_path)
            self.settings, self.updater_config, self.pose_check_config = node_settings(
                given, base, Ros2Settings)
        except MapUpdatingError as e:
            self.parameter_error = " ".join(str(e).split())
            self.settings, self.updater_config, self.pose_check_config = node_settings(
                {}, None, Ros2Settings)
        declare_all(self, self.settings, self.updater_config, self.pose_check_config)
        self._reset_state()

    def _reset_state(self) -> None:
        s = self.settings
        self.poses = TfPoses(s.map_frame, s.odom_frame, s.base_frame) \
            if s.pose_source == "tf" else LivePoses()
        self._scans = ScanQueue(s.queue_size)   # (record, arrival) waiting for their poses
        self._published: np.ndarray | None = None

    # --- lifecycle ----------------------------------------------------------------------------
    def on_configure(self, state) -> TransitionCallbackReturn:
        try:
            self._configure()
        except Exception as e:  # noqa: BLE001 - whatever it is, one line and a failed transition
            self.failure = " ".join(str(e).split()) or type(e).__name__
            if not isinstance(e, (MapUpdatingError, OSError)):
                self.failure = f"{type(e).__name__}: {self.failure}"
            if self.log_failure:
                self.get_logger().error(f"configure: {self.failure}")
            self.on_cleanup(state)
            return FAILURE
        s = self.settings
        self.get_logger().info(f"configured ({self.map_path or 'waiting for ' + s.map_topic}; "
                               f"scans on {', '.join(s.scan_topics)})")
        self.get_logger().info(profile_line(s, self.updater_config, self.pose_check_config))
        return SUCCESS

    def _configure(self) -> None:
        """The checks, the reference map, the services and publishers of ``configure``;
        raises with the reason."""
        if self.parameter_error:
            raise MapUpdatingError(self.parameter_error)
        s = self.settings
        services.check_paths(s.save_path, self.map_path)
        if s.pose_source == "tf" and TFMessage is None:
            raise MapUpdatingError(NO_TF2_MSGS)
        reference = load_map(self.map_path) if self.map_path is not None else None
        self.store = services.store_link(s)
        if self.store is not None:
            reference = self.store.start(reference)
        self._reset_state()
        warm_up(self._pipeline_on)
        self._configured = services.create(self)
        self._outputs = {
            "map": self.create_lifecycle_publisher(GridMsg, "map_updated", LATCHED),
            "metadata": self.create_lifecycle_publisher(MapMetaData, "map_updated_metadata",
                                                        LATCHED),
            "diagnostics": self.create_lifecycle_publisher(DiagnosticArray, "/diagnostics", 10)}
        if services.OccupancyGridUpdate is not None:
            self._outputs["updates"] = self.create_lifecycle_publisher(
                services.OccupancyGridUpdate, "map_updated_updates", 10)
        if reference is not None:
            self._start_on(reference)
        else:
            self._configured.append(self.create_subscription(GridMsg, s.map_topic,
                                                             self._on_map, LATCHED))

    def on_activate(self, state) -> TransitionCallbackReturn:
        s = self.settings
        try:
            self._active = self._subscribe()
        except Exception as e:  # noqa: BLE001 - a bad QoS override, said in one line
            self.get_logger().error(f"activate: {' '.join(str(e).split())}")
            for sub in self._active:
                self.destroy_subscription(sub)
            self._active = []
            return FAILURE
        self._timer = self.create_timer(s.publish_period, self._publish)
        self._published = None                  # the map goes out at once on activation
        if BondStatus is not None:
            self.bond = Bond(self)
        else:
            self.get_logger().warn("no bond messages (the 'bond' package): Nav2's lifecycle "
                                   "manager needs bond_timeout: 0.0 for this node")
        return super().on_activate(state)

    def _subscribe(self) -> list:
        s = self.settings
        # best effort, as lidar drivers publish; the history as long as the node's own queue.
        # A scan the middleware drops is counted by its publisher's sequence number
        scan_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=s.queue_size,
                              reliability=ReliabilityPolicy.BEST_EFFORT,
                              durability=DurabilityPolicy.VOLATILE)
        subs = [self.create_subscription(
            LaserScan, topic, self._scan_handler(topic), scan_qos,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
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
        return subs

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self._stop()
        return super().on_deactivate(state)

    def _stop(self) -> None:
        for sub in self._active:
            self.destroy_subscription(sub)
        self._active = []
        if getattr(self, "_timer", None) is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        if self.bond is not None:
            self.bond.close()
            self.bond = None

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        for entity in self._configured:
            if hasattr(entity, "srv_type"):
                self.destroy_service(entity)
            else:
                self.destroy_subscription(entity)
        self._configured = []
        for pub in self._outputs.values():
            self.destroy_lifecycle_publisher(pub)
        self._outputs = {}
        self.pipeline = None
        self._reset_state()
        return SUCCESS

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        self._stop()                            # the process ends once this returns
        return SUCCESS

    # --- the map ------------------------------------------------------------------------------
    def _start_on(self, reference: OccupancyGrid) -> None:
        """The first reference: the updater this node saved before at ``save_path`` when it
        belongs to this map and configuration (resumed), or the session after it when this is
        the map it made, else a fresh one."""
        resumed, self._save_refusal, how = services.resume(self, reference)
        if resumed is not None:
            self.pipeline = self._pipeline_on(reference, resumed)
            if how == "next session":
                self.health.counts["face_cells_carried"] = resumed.face_cells()
            else:
                self.health.counts["resumed"] = 1
        else:
            self._adopt(reference)

    def _adopt(self, reference: OccupancyGrid, carry: bool = True) -> None:
        """The next session on ``reference``: buffers afresh, with what the last session
        carries (the faces rule's counts, halved) when ``carry`` and the map is in its frame."""
        last = self.pipeline.updater if carry and self.pipeline is not None else None
        updater = next_session(self.settings.method, last, reference, self.updater_config)
        self.health.counts["face_cells_carried"] = face_cells(updater)
        self.pipeline = self._pipeline_on(reference, updater)
        self._published = None

    def _pipeline_on(self, reference: OccupancyGrid, updater=None) -> RobotPipeline:
        s = self.settings
        # the node's poses come from outside (tf, amcl_pose): refined as the profile says
        check = PoseCheck(reference, self.pose_check_config.for_poses(own_localizer=False)) \
            if s.use_pose_check else None
        smoother = PoseSmoother(s.smooth_poses) if s.smooth_poses > 0 else None
        updater = updater or make_method(s.method, reference, self.updater_config)
        return RobotPipeline(updater, pose_check=check, smoother=smoother)

    def _on_map(self, msg) -> None:
        try:
            grid = grid_from_message(msg)
        except MapUpdatingError as e:
            return self._skip("map message unusable", e)
        if self.pipeline is not None:
            ref = self.pipeline.updater.reference_map
            if ref.same_frame(grid) and np.array_equal(ref.data, grid.data):
                return                          # the same map again
            if not ref.same_frame(grid) and self.store is not None:
                return self._skip("map of another size, resolution or origin (the store's "
                                  "version is the reference)", f"{grid.shape}")
            if not ref.same_frame(grid):        # map_server switched floors: follow it
                self.health.counts["maps_switched"] += 1
                self.health.notes["last_map_switch"] = (f"{ref.shape[1]}x{ref.shape[0]} -> "
                                                        f"{grid.shape[1]}x{grid.shape[0]} "
                                                        f"cells, buffers re-seeded")
                self.get_logger().info(f"a map of another frame on {self.settings.map_topic}: "
                                       f"{self.health.notes['last_map_switch']}")
        elif self.store is not None and self.store.version is None:
            try:                                # an empty store: this map is its first version
                grid = self.store.start(grid)
            except MapUpdatingError as e:
                return self._skip("map store unusable", e)
        self.health.counts["maps_received"] += 1
        if self.pipeline is None:
            return self._start_on(grid)
        self._adopt(grid)

    # --- poses and scans ----------------------------------------------------------------------
    def _planar_pose(self, p, what: str) -> Pose2D | None:
        try:
            q = unit_quaternion(p.orientation.x, p.orientation.y, p.orientation.z,
                                p.orientation.w)
        except TransformError as e:
            return self._skip(f"{what} with a non-unit quaternion", e)
        pose = planar(p.position.x, p.position.y, q)[0]
        return pose if pose.is_finite() else self._skip(f"{what} not finite", pose)

    def _on_odom(self, msg) -> None:
        pose = self._planar_pose(msg.pose.pose, "odometry")
        if pose is not None:
            self.poses.add_odometry(stamp_seconds(msg.header), pose)
            self._drain()

    def _on_pose(self, msg) -> None:
        pose = self._planar_pose(msg.pose.pose, "localisation")
        if pose is not None:
            self.poses.add_localisation(stamp_seconds(msg.header), pose)
            self._drain()

    def _on_tf(self, msg, static: bool) -> None:
        """One /tf or /tf_static message: its transforms, each with a unit quaternion (tf2
        ignores one that is not, and so does the node, counted); one not finite, none."""
        records = []
        for tr in msg.transforms:
            r, t = tr.transform.rotation, tr.transform.translation
            try:
                q = unit_quaternion(r.x, r.y, r.z, r.w)
            except TransformError as e:
                self._skip("transform with a non-unit quaternion", f"{tr.child_frame_id}: {e}")
                continue
            pose, flipped, tilt = planar(t.x, t.y, q)
            if not pose.is_finite():
                return self._skip("transform not finite", f"{tr.child_frame_id}: {pose}")
            records.append((TransformRecord(stamp_seconds(tr.header),
                                            tr.header.frame_id.lstrip("/"),
                                            tr.child_frame_id.lstrip("/"), pose, static=static),
                            flipped, tilt))
        for rec, flipped, tilt in records:
            self.poses.add(rec, flipped, tilt)
        self._drain()

    def _scan_handler(self, topic: str):
        return lambda msg, info: self._on_scan(msg, info, topic)

    def _on_scan(self, msg, info, topic: str) -> None:
        self.health.counts["scans_received"] += 1
        self.health.counts["scans_lost_in_transport"] += self._gaps.see(
            (topic, msg.header.frame_id), info.get("publication_sequence_number"))
        rec, skip = usable_scan(msg, topic, self.settings.max_beams)
        if skip is not None:
            return self._skip(*skip)
        if rec.time > self.poses.newest_odom + AHEAD_S > -np.inf:
            return self._skip("scan stamped ahead of the odometry",
                              f"{rec.time - self.poses.newest_odom:.3g} s")
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
        scan = rec.scan
        if self.settings.pose_source == "tf":
            # looked up at every scan: a corrected /tf_static counts from then on
            try:
                found = self.poses.mount(rec.frame_id.lstrip("/"), rec.time,
                                         self.settings.max_mount_tilt)
            except TransformError as e:
                return self._skip("laser neither upright nor upside down", e)
            if found is None:
                return self._skip("no transform from the base to the scan's frame",
                                  rec.frame_id)
            mount, flipped = found
            if flipped:
                scan = mirrored(scan)
                self.health.counts["scans_upside_down"] += 1
        else:
            mount = Pose2D(*self.settings.laser_mount)
        self.pipeline.step(ascending(scan), mount, odometry=odom, pose=robot)
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
        services.take_newer_version(self)
        if self.pipeline is not None:
            grid = self.pipeline.updater.updated_map()
            counts = pipeline_values(self.pipeline, self.settings.method)
            before = self._published
            if before is None or not np.array_equal(before, grid.data):
                services.publish_map(self, grid, before)
                self._published = grid.data
                self.health.counts["maps_published"] += 1
        self._diagnostics(counts)

    def _diagnostics(self, counts: dict) -> None:
        self.health.counts["scans_waiting"] = len(self._scans)
        if self.health.counts["scans_received"] and not self._gaps.numbered:
            self.health.notes["scans_lost_in_transport"] = "unknown: not numbered by the rmw"
        else:
            self.health.notes.pop("scans_lost_in_transport", None)
        status = DiagnosticStatus()
        status.name = f"{self.get_fully_qualified_name()}: health"
        status.hardware_id = self.settings.map_frame
        c = self.health.counts
        worrying = c["scans_dropped_behind"] or c["scans_lost_in_transport"] or \
            sum(self.health.skipped.values())
        status.level = DiagnosticStatus.WARN if worrying else DiagnosticStatus.OK
        status.message = "scans dropped, lost or skipped" if worrying else "ok"
        if "last_map_switch" in self.health.notes and not worrying:
            status.message = f"ok; map switched ({self.health.notes['last_map_switch']})"
        status.values = [KeyValue(key=k, value=v) for k, v in self.health.values(counts)]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        self._outputs["diagnostics"].publish(array)

    def summary(self) -> str:
        counts = pipeline_values(self.pipeline, self.settings.method) \
            if self.pipeline is not None else {}
        return ", ".join(f"{k} {v}" for k, v in self.health.values(counts))


def _spin_once(executor, timeout: float) -> None:
    """One turn of the executor. A callback that SIGINT overtook (the context shut down
    between the executor taking a timer and its publishing: "publisher's context is
    invalid") ends the spinning as the shutdown does; with the context up, its error stands."""
    try:
        executor.spin_once(timeout_sec=timeout)
    except Exception:  # noqa: BLE001 - rclpy's RCLError is not public
        if rclpy.ok():
            raise


def run_node(map_path=None, config_path=None, autostart: bool = False, argv=None) -> int:
    """``mapupdate ros2``: spin the lifecycle node until shut down (SIGINT, or its shutdown
    transition); with ``autostart`` (or the ``autostart`` parameter), configure and activate
    it at once (a failed transition ends the command, said in one line)."""
    argv = argv if argv is not None else sys.argv
    rclpy.init(args=argv)
    try:
        node = MapUpdaterNode(map_path, config_path)
    except ValueError as e:                     # rclpy's: a parameter given no value
        rclpy.try_shutdown()
        names = ", ".join(valueless(argv)) or "one of them"
        raise MapUpdatingError(f"the node was not made: parameters given no value (an empty "
                               f"list or none): {names} ({' '.join(str(e).split())})") from None
    # one line, the command's, for a failed start
    node.log_failure = not (autostart or node.settings.autostart)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        if autostart or node.settings.autostart:
            for step in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
                if not node.lifecycle.change(step):
                    name = "configure" if step == Transition.TRANSITION_CONFIGURE else "activate"
                    raise MapUpdatingError(f"the node did not come up: {name} failed: "
                                           f"{node.failure or 'see its log'}")
        while rclpy.ok() and node.lifecycle.state != "finalized":
            _spin_once(executor, 0.5)
        end = time.monotonic() + 0.5            # the shutdown's answer on its way
        while rclpy.ok() and time.monotonic() < end:
            _spin_once(executor, 0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # on SIGINT rclpy's context is already shut down, and its logger with it
        summary = node.summary()
        if summary:
            print(f"{node.get_name()}: {summary}", flush=True)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
