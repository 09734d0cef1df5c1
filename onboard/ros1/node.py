"""The live ROS 1 node: the one robot pipeline fed by LaserScan messages and tf, publishing the
updated map. The only module of the project that imports rospy.

Subscribes: LaserScan on ``~scan_topics`` (default ``scan``), tf (``map -> odom -> base``, as
amcl or gmapping publish it, and ``base -> laser``), and the latched ``map`` when no ``--map``
is given. Publishes: ``map_updated`` (nav_msgs/OccupancyGrid, latched) every
``~publish_period`` seconds when it changed, ``map_updated_updates``
(map_msgs/OccupancyGridUpdate: the box of cells that changed since the last publication, what
costmap_2d's static layer reads with ``subscribe_to_updates``), and the node's health on
``/diagnostics`` (``pipeline_values``: the method, the scans by fate, the gate's refusals by
rule, the evidence of change left below the threshold). Services (std_srvs/Trigger):
``~save``, ``~commit``, ``~reset``. ``~method`` chooses what updates the map: the paper's
updater (the default), ``fuse`` or ``hybrid`` (``onboard.methods``).

Scans are queued by the subscriber and processed in order by one worker thread, so a slow
scan never blocks ROS's callbacks; past ``~queue_size`` waiting scans the oldest is dropped
and counted. Malformed traffic (an empty scan, bad angles, a frame without a transform, a scan
older than the tf buffer, a map of another resolution) is counted by kind and skipped.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

from gridmap import MapUpdatingError, OccupancyGrid, Pose2D, load_map, save_map
from localization.confidence import PoseCheck
from localization.smoothing import PoseSmoother
from robotlogs.rosbag import transform_pose

from ..methods import face_cells, make_method, next_session
from ..pipeline import RobotPipeline, warm_up
from ..robot_config import load_robot_config
from ..ros_common.gaps import Gaps
from ..ros_common.grids import changed_box, grid_from_message, message_fields
from ..ros_common.health import Health, pipeline_values
from ..ros_common.queue import ScanQueue, scan_bytes
from ..ros_common.scans import has_bad_ranges, usable_scan
from ..ros_common.settings import (NodeSettings, check_save_path, node_settings, profile_line,
                                   refuse_saving_over_the_map)
from ..ros_common.store_link import StoreLink
from ..ros_common.transforms import TransformError, ascending, mirrored, planar

ROS_PACKAGES = ("ros-core python3-rospy python3-tf2-ros python3-nav-msgs python3-sensor-msgs "
                "python3-geometry-msgs python3-std-srvs python3-diagnostic-msgs "
                "python3-map-msgs")


def _ros():
    try:
        import rospy
        import tf2_ros
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        from map_msgs.msg import OccupancyGridUpdate
        from nav_msgs.msg import OccupancyGrid as GridMsg
        from sensor_msgs.msg import LaserScan
        from std_srvs.srv import Trigger, TriggerResponse
    except ImportError as e:
        raise MapUpdatingError(f"mapupdate ros1 needs ROS 1's Python packages ({e}); on "
                               f"Debian 12: apt-get install {ROS_PACKAGES}") from None
    return {"rospy": rospy, "tf2_ros": tf2_ros, "DiagnosticArray": DiagnosticArray,
            "DiagnosticStatus": DiagnosticStatus, "KeyValue": KeyValue,
            "OccupancyGridUpdate": OccupancyGridUpdate, "GridMsg": GridMsg,
            "LaserScan": LaserScan, "Trigger": Trigger, "TriggerResponse": TriggerResponse}


class MapUpdaterNode:
    """The node: call ``start()`` after ``rospy.init_node``, then ``rospy.spin()``."""

    def __init__(self, settings: NodeSettings, updater_config, pose_check_config,
                 reference: OccupancyGrid | None = None, store: StoreLink | None = None):
        self.ros = _ros()
        self.store = store
        self.settings, self.updater_config = settings, updater_config
        self.pose_check_config = pose_check_config
        self.health = Health()
        self.pipeline = None
        self._lock = threading.Lock()            # the pipeline, the published map
        self._queue = ScanQueue(settings.queue_size)
        self._gaps = Gaps()                      # scans lost before the callback, by header.seq
        self._worker_stopped = ""                # why the scan worker ended, if it did
        self._wake = threading.Condition()
        self._published: np.ndarray | None = None
        if reference is not None:
            self._adopt(reference)

    # --- the map ------------------------------------------------------------------------------
    def _adopt(self, reference: OccupancyGrid, carry: bool = True) -> None:
        """The next session on ``reference``: new buffers, a new pose check, with what the
        last session carries (the faces rule's counts, halved) when ``carry`` and the map is
        in its frame (lock held or not needed)."""
        last = self.pipeline.updater if carry and self.pipeline is not None else None
        updater = next_session(self.settings.method, last, reference, self.updater_config)
        self.health.counts["face_cells_carried"] = face_cells(updater)
        self.pipeline = self._pipeline_on(reference, updater)
        self._published = None                   # publish the new map at the next period

    def _pipeline_on(self, reference: OccupancyGrid, updater=None) -> RobotPipeline:
        # the node's poses come from outside (tf, amcl_pose): refined as the profile says
        check = PoseCheck(reference, self.pose_check_config.for_poses(own_localizer=False)) \
            if self.settings.use_pose_check else None
        smoother = PoseSmoother(self.settings.smooth_poses) \
            if self.settings.smooth_poses > 0 else None
        updater = updater or make_method(self.settings.method, reference, self.updater_config)
        return RobotPipeline(updater, pose_check=check, smoother=smoother)

    def _on_map(self, msg) -> None:
        try:
            grid = grid_from_message(msg)
        except MapUpdatingError as e:
            self._skip("map message unusable", e)
            return
        with self._lock:
            if self.pipeline is not None:
                ref = self.pipeline.updater.reference_map
                if not ref.same_frame(grid):
                    self._skip("map of another size, resolution or origin",
                               f"{grid.shape} at {grid.resolution} m, origin {grid.origin}; "
                               f"the reference has {ref.shape} at {ref.resolution} m")
                    return
                if np.array_equal(ref.data, grid.data):
                    return                       # the same map again (a latched re-send)
            if self.store is not None and self.store.version is None:
                try:                             # an empty store: this map is its first version
                    grid = self.store.start(grid)
                except MapUpdatingError as e:
                    self._skip("map store unusable", e)
                    return
            self._adopt(grid)
            self.health.counts["maps_received"] += 1

    # --- scans --------------------------------------------------------------------------------
    def _on_scan(self, msg, topic: str) -> None:
        # rospy numbers each publisher's messages (header.seq): a jump is scans dropped on the
        # way, in the publisher's or this subscriber's queue, which the node never sees
        publisher = getattr(msg, "_connection_header", {}).get("callerid", "")
        lost = self._gaps.see((topic, publisher), msg.header.seq)
        with self._wake:
            self.health.counts["scans_received"] += 1
            self.health.counts["scans_lost_in_transport"] += lost
            dropped = self._queue.push((msg, topic), scan_bytes(msg.ranges, msg.intensities))
            self.health.counts["scans_dropped_behind"] += dropped
            self._wake.notify()

    def _work(self) -> None:
        """The scan worker; should it ever end before the node does, ``/diagnostics`` says
        so at level ERROR with the reason (``_worker_stopped``)."""
        try:
            self._work_loop()
        except BaseException as e:
            self._worker_stopped = f"{type(e).__name__}: {e}"
            raise
        if not self.ros["rospy"].is_shutdown():
            self._worker_stopped = "it returned"

    def _work_loop(self) -> None:
        rospy = self.ros["rospy"]
        while not rospy.is_shutdown():
            with self._wake:
                while not self._queue and not rospy.is_shutdown():
                    self._wake.wait(0.1)
                if not self._queue:
                    continue
                msg, topic = self._queue.pop()
            t0 = time.perf_counter()
            try:
                self._handle(msg, topic)
            except Exception as e:  # noqa: BLE001 - whatever one scan raises, the worker goes on
                self._skip(f"scan raised {type(e).__name__}", e)
            self.health.times.append(time.perf_counter() - t0)

    def _handle(self, msg, topic: str) -> None:
        rec, skip = usable_scan(msg, topic, self.settings.max_beams)
        if skip is not None:
            return self._skip(*skip)
        if has_bad_ranges(rec):
            self.health.counts["scans_with_bad_ranges"] += 1   # those beams are invalid
        if self.pipeline is None:
            return self._skip("no reference map yet", topic)
        poses = self._poses(msg.header.stamp, rec.frame_id or self.settings.base_frame)
        if poses is None:
            return
        robot, odom, (mount, flipped) = poses
        scan = rec.scan
        if flipped:                              # a lidar mounted upside down
            scan = mirrored(scan)
            self.health.counts["scans_upside_down"] += 1
        with self._lock:
            # a clockwise lidar's beams (a negative angle_increment) in counter-clockwise order
            self.pipeline.step(ascending(scan), mount, odometry=odom, pose=robot)
            self.health.counts["scans_used"] += 1

    def _poses(self, stamp, laser_frame: str):
        """(robot in map, robot in odom, laser on robot) at ``stamp``; None, counted, when tf
        cannot give them. map -> base is composed from map -> odom and odom -> base, as the
        log replay composes them."""
        tf2 = self.ros["tf2_ros"]
        s = self.settings
        try:
            map_odom = transform_pose(self._lookup(s.map_frame, s.odom_frame, stamp))
            odom = transform_pose(self._lookup(s.odom_frame, s.base_frame, stamp))
            mount = self._mount(laser_frame, stamp)
        except tf2.ExtrapolationException as e:
            past = "past" in str(e)
            return self._skip("scan older than the tf buffer" if past
                              else "no transform at the scan's time", e)
        except tf2.TransformException as e:
            return self._skip("no transform for the scan's frames", e)
        except TransformError as e:
            return self._skip("laser neither upright nor upside down", e)
        robot = map_odom.compose(odom)
        if not (robot.is_finite() and odom.is_finite() and mount[0].is_finite()):
            return self._skip("transform not finite", f"robot {robot}, laser mount {mount}")
        return robot, odom, mount

    def _lookup(self, parent: str, child: str, stamp):
        """The transform at ``stamp``, waited for ``tf_timeout`` only when it may still come:
        a scan no newer than what the buffer holds already (a stale one) costs no waiting."""
        tf2 = self.ros["tf2_ros"]
        try:
            return self.tf.lookup_transform(parent, child, stamp).transform
        except tf2.ExtrapolationException as e:
            if "past" in str(e) or not self._may_come(parent, child, stamp):
                raise
        except tf2.TransformException:
            pass
        return self.tf.lookup_transform(parent, child, stamp, self.ros["rospy"].Duration(
            self.settings.tf_timeout)).transform

    def _may_come(self, parent: str, child: str, stamp) -> bool:
        tf2 = self.ros["tf2_ros"]
        try:
            return stamp > self.tf.get_latest_common_time(parent, child)
        except tf2.TransformException:
            return True

    def _mount(self, laser_frame: str, stamp) -> tuple[Pose2D, bool]:
        """(the laser on the base, upside down); ``TransformError`` for one tilted more than
        ``max_mount_tilt`` from level."""
        if laser_frame == self.settings.base_frame:
            return Pose2D(0.0, 0.0, 0.0), False
        # at every scan's stamp: a corrected /tf_static counts from then on, and a mount that
        # moves (on /tf) is taken where it was. tf2 has composed it in 3D
        tr = self._lookup(self.settings.base_frame, laser_frame, stamp)
        r = tr.rotation
        pose, flipped, tilt = planar(tr.translation.x, tr.translation.y, (r.x, r.y, r.z, r.w))
        if tilt > self.settings.max_mount_tilt:
            raise TransformError(f"frame '{laser_frame}' is tilted {tilt:.3g} rad from level")
        return pose, flipped

    def _skip(self, why: str, detail) -> None:
        self.health.skipped[why] += 1
        if self.health.skipped[why] == 1:        # the first of each kind, then only counted
            self.ros["rospy"].logwarn(f"map_updater: {why} ({detail}); further ones counted "
                                      "on /diagnostics")
        return None

    # --- output -------------------------------------------------------------------------------
    def _publish(self, _event=None) -> None:
        with self._lock:
            self._take_newer_version()
            if self.pipeline is None:
                self._diagnostics({})
                return
            grid = self.pipeline.updater.updated_map()
            before, self._published = self._published, grid.data
            counts = pipeline_values(self.pipeline, self.settings.method)
        if before is None or not np.array_equal(before, grid.data):
            self.map_pub.publish(self._grid_msg(grid))
            box = None if before is None else changed_box(before, grid.data)
            if box is not None:
                self.update_pub.publish(self._update_msg(grid, box))
            self.health.counts["maps_published"] += 1
        self._diagnostics(counts)

    def _header(self):
        r = self.ros
        h = r["GridMsg"]().header
        h.stamp, h.frame_id = r["rospy"].Time.now(), self.settings.map_frame
        return h

    def _grid_msg(self, grid: OccupancyGrid):
        f = message_fields(grid)
        msg = self.ros["GridMsg"]()
        msg.header = self._header()
        info = msg.info
        info.map_load_time = msg.header.stamp
        info.resolution, info.width, info.height = f["resolution"], f["width"], f["height"]
        info.origin.position.x, info.origin.position.y = f["origin"]
        info.origin.orientation.w = 1.0
        msg.data = f["data"]
        return msg

    def _update_msg(self, grid: OccupancyGrid, box):
        x, y, w, h = box
        msg = self.ros["OccupancyGridUpdate"]()
        msg.header = self._header()
        msg.x, msg.y, msg.width, msg.height = x, y, w, h
        msg.data = grid.data[y:y + h, x:x + w].reshape(-1).tolist()
        return msg

    def _diagnostics(self, counts: dict) -> None:
        r = self.ros
        self.health.counts["scans_waiting"] = len(self._queue)
        status = r["DiagnosticStatus"]()
        status.name = f"{r['rospy'].get_name()}: health"
        status.hardware_id = self.settings.map_frame
        c = self.health.counts
        worrying = c["scans_dropped_behind"] or c["scans_lost_in_transport"] or \
            sum(self.health.skipped.values())
        status.level = status.WARN if worrying else status.OK
        status.message = "scans dropped, lost or skipped" if worrying else "ok"
        if self._worker_stopped:                 # nothing is processed any more: never "ok"
            status.level = status.ERROR
            status.message = f"the scan worker stopped ({self._worker_stopped})"
        status.values = [r["KeyValue"](k, v) for k, v in self.health.values(counts)]
        array = r["DiagnosticArray"]()
        array.header.stamp = r["rospy"].Time.now()
        array.status = [status]
        self.diag_pub.publish(array)

    # --- services -----------------------------------------------------------------------------
    def _save(self, _req):
        with self._lock:
            if self.pipeline is None:
                return self.ros["TriggerResponse"](False, "no reference map yet")
            grid = self.pipeline.updater.updated_map()
        try:
            save_map(grid, Path(self.settings.save_path))    # written to a temporary file
        except (MapUpdatingError, OSError) as e:
            return self.ros["TriggerResponse"](False, f"cannot save: {e}")
        return self.ros["TriggerResponse"](True, f"saved {self.settings.save_path}")

    def _commit(self, _req):
        with self._lock:
            if self.pipeline is None:
                return self.ros["TriggerResponse"](False, "no reference map yet")
            if self.store is None:
                self._adopt(self.pipeline.updater.updated_map())
                said = "the updated map is the reference now"
            else:
                ok, said, then = self.store.commit_session(self.pipeline, self.settings.method,
                                                           self.updater_config)
                if not ok:
                    return self.ros["TriggerResponse"](False, said)
                self._adopt(then)
        self._publish()
        return self.ros["TriggerResponse"](True, said)

    def _take_newer_version(self) -> None:
        """A newer approved version in the store becomes the reference (lock held)."""
        if self.store is None or self.pipeline is None:
            return
        try:
            updater = self.pipeline.updater
            newer = self.store.newer(session=(updater.reference_map, updater.updated_map()))
        except MapUpdatingError as e:
            self._skip("map store unusable", e)
            return
        if newer is not None:
            self._adopt(newer[1])
            self.health.counts["store_versions_taken"] += 1
        self.health.counts["store_version"] = self.store.version or 0

    def _reset(self, _req):
        with self._lock:
            if self.pipeline is None:
                return self.ros["TriggerResponse"](False, "no reference map yet")
            self._adopt(self.pipeline.updater.reference_map, carry=False)
        self._publish()
        return self.ros["TriggerResponse"](True, "buffers and the faces rule's counts cleared; "
                                           "the reference is unchanged")

    # --- wiring -------------------------------------------------------------------------------
    def start(self, subscribe_map: bool) -> None:
        r, s = self.ros, self.settings
        rospy, tf2 = r["rospy"], r["tf2_ros"]
        warm_up(self._pipeline_on)
        self.tf = tf2.Buffer(rospy.Duration(10.0))
        self._listener = tf2.TransformListener(self.tf)
        self.map_pub = rospy.Publisher("map_updated", r["GridMsg"], queue_size=1, latch=True)
        self.update_pub = rospy.Publisher("map_updated_updates", r["OccupancyGridUpdate"],
                                          queue_size=10)
        self.diag_pub = rospy.Publisher("/diagnostics", r["DiagnosticArray"], queue_size=10)
        for name, handler in (("~save", self._save), ("~commit", self._commit),
                              ("~reset", self._reset)):
            rospy.Service(name, r["Trigger"], handler)
        if subscribe_map:
            rospy.Subscriber(s.map_topic, r["GridMsg"], self._on_map, queue_size=1)
        for topic in s.scan_topics:
            rospy.Subscriber(topic, r["LaserScan"], self._on_scan, callback_args=topic,
                             queue_size=s.queue_size)
        threading.Thread(target=self._work, name="map_updater_worker", daemon=True).start()
        rospy.Timer(rospy.Duration(s.publish_period), self._publish)
        rospy.on_shutdown(self._log_summary)

    def _log_summary(self) -> None:
        counts = pipeline_values(self.pipeline, self.settings.method) \
            if self.pipeline is not None else {}
        text = ", ".join(f"{k} {v}" for k, v in self.health.values(counts))
        self.ros["rospy"].loginfo(f"map_updater: {text}")


def _require_master(wait: float = 3.0) -> None:
    """Refuse to start, in one line, when no ROS master answers (rospy would end in a bare
    "Connection refused", or wait for ever); a master starting at the same moment is given
    ``wait`` seconds."""
    import rosgraph

    end = time.monotonic() + wait
    while not rosgraph.is_master_online():
        if time.monotonic() > end:
            raise MapUpdatingError(f"no ROS master answers at {rosgraph.get_master_uri()}: "
                                   "start one (roscore) or set ROS_MASTER_URI")
        time.sleep(0.2)


def run_node(map_path=None, config_path=None, argv=None) -> int:
    """``mapupdate ros1``: init the node, read its parameters, run until shut down."""
    r = _ros()
    rospy = r["rospy"]

    base = load_robot_config(config_path)          # refused before anything starts
    reference = load_map(map_path) if map_path is not None else None
    _require_master()
    rospy.init_node("map_updater", argv=argv)
    settings, updater_config, pose_check_config = node_settings(rospy.get_param("~", {}), base)
    check_save_path(settings.save_path)
    refuse_saving_over_the_map(settings.save_path, map_path)
    store = StoreLink(settings.store, settings.robot_name, settings.store_poll_period) \
        if settings.store else None
    if store is not None:
        reference = store.start(reference)
    node = MapUpdaterNode(settings, updater_config, pose_check_config, reference, store)
    node.start(subscribe_map=reference is None)
    source = f"map {map_path}" if map_path else f"waiting for {settings.map_topic}"
    rospy.loginfo(f"map_updater: ready ({source}; scans on {', '.join(settings.scan_topics)})")
    rospy.loginfo(f"map_updater: {profile_line(settings, updater_config, pose_check_config)}")
    rospy.spin()
    return 0
