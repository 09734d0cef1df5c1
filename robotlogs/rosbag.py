"""ROS 1 and ROS 2 bags, read and written through ``rosbags`` (no ROS installation needed).

Read: ``sensor_msgs/LaserScan`` (one or more topics), ``nav_msgs/Odometry``, ``/tf`` and
``/tf_static`` (``tf2_msgs/TFMessage``, or ``tf/tfMessage`` in old ROS 1 bags), and pose topics
(``geometry_msgs/PoseWithCovarianceStamped`` as amcl publishes on ``/amcl_pose``, or
``PoseStamped`` / ``Odometry``). Every message becomes a plain record of :mod:`.records`
stamped with its header time. Written: the same records, so simulated sessions can be played
in ROS tools and replayed here.

A ROS 1 bag is a ``.bag`` file; a ROS 2 bag a directory with ``metadata.yaml``, or a bare
``.mcap`` / ``.db3`` storage file.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gridmap import Pose2D, Scan
from gridmap.types import GridError

from .records import (LogError, MapRecord, OdomRecord, PoseRecord, ReadStats, Record,
                      ScanRecord, TransformRecord)

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
GRID = "nav_msgs/msg/OccupancyGrid"
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
POSE_TYPES = (POSE_COV, POSE_STAMPED, ODOMETRY)
# The (x, y, yaw) entries of a row-major 6 x 6 ROS covariance (x y z roll pitch yaw).
COV_INDEX = np.array([0, 1, 5])
# [rad] A LaserScan's angle_increment is a float32, which holds nothing smaller: a message built
# with less (5e-324 from Python, a CARMEN line's resolution) would arrive as 0, and the
# updater's angular window over it comes out infinite.
MIN_ANGLE_INCREMENT = float(np.finfo(np.float32).smallest_subnormal)


@dataclass(frozen=True)
class BagTopics:
    """Topic names. Reading resolves them against the bag (:func:`resolve_topics`); writing
    uses them as they are (records carry their own scan, odometry and pose topics)."""

    scans: tuple[str, ...] = ("/scan",)
    odom: str | None = "/odom"
    pose: str | None = "/amcl_pose"
    truth: str | None = "/ground_truth/pose"
    tf: str | None = "/tf"
    tf_static: str | None = "/tf_static"

    def all(self) -> list[str]:
        return [t for t in (*self.scans, self.odom, self.pose, self.truth, self.tf,
                            self.tf_static) if t]


# --- reading -----------------------------------------------------------------------------------

def _open(path: Path):
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    if not path.exists():
        raise FileNotFoundError(f"{path}: no such bag")
    try:
        # Bags written without message definitions (early ROS 2) decode with the stock types.
        return AnyReader([path], default_typestore=get_typestore(Stores.LATEST)).__enter__()
    except (AnyReaderError, OSError, ValueError, KeyError) as e:
        raise LogError(f"{path}: not a readable ROS bag: {_one_line(e)}") from None


def bag_topics(path) -> dict[str, str]:
    """Every topic of a bag and its message type: ``{"/scan": "sensor_msgs/msg/LaserScan"}``."""
    reader = _open(Path(path))
    try:
        return {name: info.msgtype or "?" for name, info in reader.topics.items()}
    finally:
        reader.close()


def scan_count(path, scan_topics=None) -> int:
    """How many scans :func:`read_bag` will yield with these scan topics (for progress bars)."""
    reader = _open(Path(path))
    try:
        info = reader.topics
        available = {n: i.msgtype or "?" for n, i in info.items()}
        topics = resolve_topics(available, scan_topics=scan_topics, source=str(path))
        return int(sum(info[t].msgcount for t in topics.scans))
    finally:
        reader.close()


def resolve_topics(available: dict[str, str], *, scan_topics=None, odom_topic=None,
                   pose_topic=None, truth_topic=None, source: str = "bag",
                   need_scans: bool = True) -> BagTopics:
    """Choose the topics to read from those a bag has.

    A topic given by name must exist with a fitting type, else :class:`LogError` lists the
    bag's topics. Left as None: scans are ``/scan`` if present, else every LaserScan topic
    (at least one is needed, unless ``need_scans`` is False); odometry ``/odom``, pose
    ``/amcl_pose``, truth ``/ground_truth/pose``, ``/tf`` and ``/tf_static`` are read when
    present.
    """
    default = BagTopics()

    def check(topic: str, types: tuple[str, ...], what: str) -> str:
        if topic not in available:
            raise LogError(f"{source}: no {what} topic {topic!r}; the bag has "
                           f"{_listing(available)}")
        if available[topic] not in types:
            raise LogError(f"{source}: topic {topic!r} carries {available[topic]}, not "
                           f"{' or '.join(types)} ({what})")
        return topic

    def optional(given, fallback, types, what):
        if given is not None:
            return check(given, types, what) if given else None  # "" switches a topic off
        return fallback if available.get(fallback) in types else None

    if scan_topics:
        names = (scan_topics,) if isinstance(scan_topics, str) else tuple(scan_topics)
        scans = tuple(check(t, (LASER_SCAN,), "LaserScan") for t in names)
    elif available.get("/scan") == LASER_SCAN:
        scans = ("/scan",)
    else:
        scans = tuple(sorted(t for t, ty in available.items() if ty == LASER_SCAN))
        if not scans and need_scans:
            raise LogError(f"{source}: no sensor_msgs/LaserScan topic; the bag has "
                           f"{_listing(available)}")
    return BagTopics(
        scans=scans,
        odom=optional(odom_topic, default.odom, (ODOMETRY,), "odometry"),
        pose=optional(pose_topic, default.pose, POSE_TYPES, "pose"),
        truth=optional(truth_topic, default.truth, POSE_TYPES, "true pose"),
        tf=default.tf if available.get(default.tf) in TF_TYPES else None,
        tf_static=default.tf_static if available.get(default.tf_static) in TF_TYPES else None,
    )


def read_bag(path, *, scan_topics=None, odom_topic=None, pose_topic=None, truth_topic=None,
             kinds=("scan", "odom", "tf", "pose", "truth"), strict: bool = False,
             stats: ReadStats | None = None) -> Iterator[Record]:
    """Records of a ROS 1 or ROS 2 bag in the bag's time order.

    Topics are chosen by :func:`resolve_topics`; ``kinds`` limits what is decoded (a replay
    reads the small topics first and the scans after). A message that cannot be decoded
    raises :class:`LogError` naming topic and time with ``strict``; otherwise it is skipped and
    counted in ``stats``.
    """
    path = Path(path)
    stats = stats if stats is not None else ReadStats()
    reader = _open(path)
    try:
        available = {n: i.msgtype or "?" for n, i in reader.topics.items()}
        topics = resolve_topics(available, scan_topics=scan_topics, odom_topic=odom_topic,
                                pose_topic=pose_topic, truth_topic=truth_topic, source=str(path),
                                need_scans="scan" in kinds)
        wanted = _wanted(topics, kinds)
        connections = [c for c in reader.connections if c.topic in wanted]
        for conn, stamp_ns, raw in reader.messages(connections=connections):
            try:
                msg = reader.deserialize(raw, conn.msgtype)
                records = list(_records(msg, conn.msgtype, conn.topic, wanted[conn.topic]))
            except Exception as e:  # noqa: BLE001 - any decoding failure is the message's fault
                where = f"{path}: topic {conn.topic} at {stamp_ns * 1e-9:.9f} s"
                bad = "not finite" if isinstance(e, NotFinite) else "cannot decode"
                if strict:
                    raise LogError(f"{where}: {bad} {conn.msgtype}: {_one_line(e)}") from None
                stats.skip(f"{'not finite' if bad == 'not finite' else 'bad'} {conn.topic}",
                           f"{where}: {_one_line(e)}")
                continue
            for r in records:
                if isinstance(r, ScanRecord):
                    stats.count_invalid_ranges(r.scan.ranges)
            yield from records
    finally:
        reader.close()


def _wanted(topics: BagTopics, kinds) -> dict[str, str]:
    """topic -> kind, for the kinds asked for."""
    pairs = [(t, "scan") for t in topics.scans]
    pairs += [(topics.odom, "odom"), (topics.pose, "pose"), (topics.truth, "truth"),
              (topics.tf, "tf"), (topics.tf_static, "tf_static")]
    return {t: k for t, k in pairs if t and (k in kinds or (k == "tf_static" and "tf" in kinds))}


def _records(msg, msgtype: str, topic: str, kind: str) -> Iterator[Record]:
    """The records of one message; a pose that is not finite (a faulty odometry driver's NaN)
    spoils its message, which the caller then skips and counts like any undecodable one."""
    if kind == "scan":
        yield scan_record(msg, topic)
    elif kind == "odom":
        yield OdomRecord(stamp_seconds(msg.header), _finite(pose_pose(msg.pose.pose), "pose"),
                         _twist(msg.twist.twist), msg.header.frame_id, msg.child_frame_id, topic)
    elif kind in ("pose", "truth"):
        record = _pose_record(msg, msgtype, topic)
        _finite(record.pose, "pose")
        yield record
    else:
        # all of a tf message or none: a transform of it that is not finite spoils the message
        records = [TransformRecord(stamp_seconds(tr.header), tr.header.frame_id.lstrip("/"),
                                   tr.child_frame_id.lstrip("/"),
                                   _finite(transform_pose(tr.transform),
                                           f"transform {tr.child_frame_id}"),
                                   static=kind == "tf_static")
                   for tr in msg.transforms]
        yield from records


class NotFinite(LogError):
    """A message whose pose is NaN or infinite."""


def _finite(pose: Pose2D, what: str) -> Pose2D:
    if not pose.is_finite():
        raise NotFinite(f"{what} is not finite ({pose.x}, {pose.y}, {pose.theta})")
    return pose


def scan_record(msg, topic: str) -> ScanRecord:
    """A ``sensor_msgs/LaserScan`` as a record: the same conversion for a bag's messages
    (rosbags) and a live node's (rospy). Raises ``LogError`` for a message that cannot be a
    scan (bad angles or range limits, a beam count that does not reach angle_max)."""
    # A reading or range_max past float32 (1e300, from a rospy message built in Python) is
    # inf, as a driver's float32 field would hold it: no warning for each such message.
    with np.errstate(invalid="ignore", over="ignore"):
        ranges = np.array(msg.ranges, dtype=np.float32)
        # ROS: readings beyond range_max (and +inf) mean nothing was hit within range.
        ranges[ranges >= msg.range_max] = np.inf
    t = stamp_seconds(msg.header)
    check_angle_increment(float(msg.angle_increment))
    try:
        scan = Scan(ranges, float(msg.angle_min), float(msg.angle_increment),
                    float(msg.range_min), float(msg.range_max), t)
    except GridError as e:
        raise LogError(str(e)) from None
    # angle_max is redundant, so it tells a corrupt message: more than a beam and a half away
    # from the last beam's angle (drivers differ by one beam) and the beams would be misplaced.
    last = float(msg.angle_min) + (scan.beams - 1) * float(msg.angle_increment)
    if scan.beams > 1 and not abs(float(msg.angle_max) - last) <= \
            1.5 * abs(float(msg.angle_increment)) + 1e-6:
        raise LogError(f"{scan.beams} ranges {float(msg.angle_increment):g} rad apart from "
                       f"angle_min {float(msg.angle_min):g} do not reach angle_max "
                       f"{float(msg.angle_max):g} (wrong beam count)")
    return ScanRecord(t, scan, frame_id=msg.header.frame_id.lstrip("/"), topic=topic)


def check_angle_increment(increment: float) -> None:
    """Raise ``LogError`` for a nonzero angle increment [rad] below ``MIN_ANGLE_INCREMENT``
    (0, NaN and inf are left to ``Scan``, which names them)."""
    if 0 < abs(increment) < MIN_ANGLE_INCREMENT:
        raise LogError(f"angle_increment {increment:g} rad is below the {MIN_ANGLE_INCREMENT:g} "
                       "a LaserScan's float32 can hold")


def _pose_record(msg, msgtype: str, topic: str) -> PoseRecord:
    if msgtype == POSE_COV:
        cov = np.asarray(msg.pose.covariance, np.float64).reshape(6, 6)[np.ix_(COV_INDEX,
                                                                                COV_INDEX)]
        return PoseRecord(stamp_seconds(msg.header), pose_pose(msg.pose.pose), topic,
                          msg.header.frame_id, cov)
    if msgtype == ODOMETRY:
        return PoseRecord(stamp_seconds(msg.header), pose_pose(msg.pose.pose), topic,
                          msg.header.frame_id)
    return PoseRecord(stamp_seconds(msg.header), pose_pose(msg.pose), topic, msg.header.frame_id)


def stamp_seconds(header) -> float:
    """A header's stamp [s]: ROS 2's ``sec``/``nanosec`` (rosbags reads ROS 1 bags so too) or
    rospy's ``secs``/``nsecs``. Integer nanoseconds divided once: a time written by ``_ns``
    reads back bit for bit, whoever reads it."""
    st = header.stamp
    sec, nsec = (st.sec, st.nanosec) if hasattr(st, "nanosec") else (st.secs, st.nsecs)
    return (int(sec) * 1_000_000_000 + int(nsec)) / 1e9


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def pose_pose(p) -> Pose2D:
    """A ``geometry_msgs/Pose`` as a 2D pose (x, y and the yaw of its orientation)."""
    return Pose2D(float(p.position.x), float(p.position.y), _yaw(p.orientation))


def transform_pose(tr) -> Pose2D:
    """A ``geometry_msgs/Transform`` as a 2D pose (x, y and the yaw of its rotation)."""
    return Pose2D(float(tr.translation.x), float(tr.translation.y), _yaw(tr.rotation))


def _twist(tw) -> tuple[float, float, float]:
    return float(tw.linear.x), float(tw.linear.y), float(tw.angular.z)


def _listing(available: dict[str, str]) -> str:
    if not available:
        return "no topics"
    return ", ".join(f"{t} ({ty})" for t, ty in sorted(available.items()))


def _one_line(e: Exception) -> str:
    return " ".join(str(e).split()) or type(e).__name__


# --- writing -----------------------------------------------------------------------------------

class BagWriter:
    """Writes records as a ROS 1 bag (``fmt="ros1"``, a ``.bag`` file) or a ROS 2 bag
    (``fmt="ros2"``, a directory; ``storage`` ``"sqlite3"`` or ``"mcap"``).

    ``ScanRecord`` -> LaserScan on its topic; ``OdomRecord`` -> Odometry on its topic;
    ``TransformRecord`` -> ``/tf`` or, static, the latched ``/tf_static``; ``PoseRecord`` ->
    PoseWithCovarianceStamped on its topic (/amcl_pose; a true pose on /ground_truth/pose with
    zero covariance). Message and bag times are the records' times. Use as a context manager;
    an existing path is refused rather than overwritten.
    """

    def __init__(self, path, fmt: str = "ros2", topics: BagTopics | None = None, *,
                 storage: str = "sqlite3"):
        if fmt not in ("ros1", "ros2"):
            raise LogError(f"bag format must be 'ros1' or 'ros2', got {fmt!r}")
        if storage not in ("sqlite3", "mcap"):
            raise LogError(f"ROS 2 storage must be 'sqlite3' or 'mcap', got {storage!r}")
        self.path = Path(path)
        if (fmt == "ros1") != (self.path.suffix == ".bag"):
            # Readers (rosbags', ROS's own) tell ROS 1 from ROS 2 by this suffix.
            raise LogError(f"{self.path}: a ROS 1 bag's name ends in .bag and a ROS 2 bag's "
                           f"does not (format {fmt!r})")
        if self.path.exists():
            raise LogError(f"{self.path} exists already; a bag is never overwritten")
        self.fmt = fmt
        self.topics = topics or BagTopics()
        self.storage = storage
        self._writer = None
        self._connections: dict[str, object] = {}
        self._seq: dict[str, int] = {}
        self._ts = None

    # context manager ------------------------------------------------------------------------
    def __enter__(self) -> BagWriter:
        from rosbags.typesys import Stores, get_typestore, get_types_from_msg

        if self.fmt == "ros1":
            from rosbags.rosbag1 import Writer

            self._ts = get_typestore(Stores.ROS1_NOETIC)
            # Noetic's store lacks tf2_msgs; this definition has ROS's md5 94810edd...
            self._ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                 TF_TYPES[0]))
            self._writer = Writer(self.path)
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            self._ts = get_typestore(Stores.ROS2_JAZZY)
            plugin = StoragePlugin.MCAP if self.storage == "mcap" else StoragePlugin.SQLITE3
            self._writer = Writer(self.path, version=8, storage_plugin=plugin)
        self._writer.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    # writing --------------------------------------------------------------------------------
    def write(self, record: Record) -> None:
        """Write one record (a transform as a one-transform tf message)."""
        if isinstance(record, TransformRecord):
            self.write_transforms([record])
        elif isinstance(record, ScanRecord):
            self._put(record.topic, LASER_SCAN, record.time, self._scan_msg(record))
        elif isinstance(record, OdomRecord):
            self._put(record.topic, ODOMETRY, record.time, self._odom_msg(record))
        elif isinstance(record, PoseRecord):
            self._put(record.topic, POSE_COV, record.time, self._pose_msg(record))
        elif isinstance(record, MapRecord):
            # latched (ROS 1) / transient local (ROS 2), as a map server offers it
            self._put(record.topic, GRID, record.time, self._grid_msg(record), latched=True)
        else:
            raise LogError(f"cannot write a {type(record).__name__} to a bag")

    def write_transforms(self, records: list[TransformRecord]) -> None:
        """Several transforms of one time as one tf message (as a tf broadcaster sends them);
        static and dynamic ones go to their own topics."""
        for static in (False, True):
            group = [r for r in records if r.static == static]
            if not group:
                continue
            topic = self.topics.tf_static if static else self.topics.tf
            T = self._ts.types
            msg = T[TF_TYPES[0]](transforms=[self._transform_msg(r) for r in group])
            self._put(topic, TF_TYPES[0], max(r.time for r in group), msg, latched=static)

    def _put(self, topic: str, msgtype: str, time: float, msg, latched: bool = False) -> None:
        if self._writer is None:
            raise LogError("the bag writer is not open (use it in a 'with' block)")
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._connect(topic, msgtype, latched)
        if self.fmt == "ros1":
            data = self._ts.serialize_ros1(msg, msgtype)
        else:
            data = self._ts.serialize_cdr(msg, msgtype)
        self._writer.write(conn, _ns(time), data)

    def _connect(self, topic: str, msgtype: str, latched: bool):
        if self.fmt == "ros1":
            conn = self._writer.add_connection(topic, msgtype, typestore=self._ts,
                                               latching=1 if latched else None)
        else:
            qos = (_latched_qos(),) if latched else ()
            conn = self._writer.add_connection(topic, msgtype, typestore=self._ts,
                                               offered_qos_profiles=qos)
        self._connections[topic] = conn
        return conn

    # messages -------------------------------------------------------------------------------
    def _header(self, key: str, time: float, frame_id: str):
        T = self._ts.types
        sec, nsec = divmod(_ns(time), 1_000_000_000)
        stamp = T["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nsec))
        if self.fmt == "ros1":
            seq = self._seq.get(key, 0)
            self._seq[key] = seq + 1
            return T["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=frame_id)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def _scan_msg(self, r: ScanRecord):
        s = r.scan
        n = s.beams
        return self._ts.types[LASER_SCAN](
            header=self._header(r.topic, r.time, r.frame_id),
            angle_min=float(s.angle_min),
            angle_max=float(s.angle_min + (n - 1) * s.angle_increment),
            angle_increment=float(s.angle_increment), time_increment=0.0, scan_time=0.0,
            range_min=float(s.range_min), range_max=float(s.range_max),
            ranges=np.asarray(s.ranges, np.float32), intensities=np.zeros(0, np.float32))

    def _odom_msg(self, r: OdomRecord):
        T = self._ts.types
        vx, vy, wz = r.velocity
        twist = T["geometry_msgs/msg/Twist"](linear=self._vector(vx, vy),
                                             angular=self._vector(0.0, 0.0, wz))
        return T[ODOMETRY](
            header=self._header(r.topic, r.time, r.frame_id), child_frame_id=r.child_frame_id,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=self._pose(r.pose),
                                                           covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist,
                                                             covariance=np.zeros(36)))

    def _pose_msg(self, r: PoseRecord):
        T = self._ts.types
        cov = np.zeros((6, 6))
        if r.covariance is not None:
            cov[np.ix_(COV_INDEX, COV_INDEX)] = np.asarray(r.covariance, np.float64).reshape(3, 3)
        return T[POSE_COV](
            header=self._header(r.topic, r.time, r.frame_id),
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=self._pose(r.pose),
                                                           covariance=cov.reshape(36)))

    def _grid_msg(self, r: MapRecord):
        T, grid = self._ts.types, r.grid
        h, w = grid.shape
        header = self._header(r.topic, r.time, r.frame_id)
        origin = self._pose(Pose2D(float(grid.origin[0]), float(grid.origin[1]), 0.0))
        info = T["nav_msgs/msg/MapMetaData"](map_load_time=header.stamp,
                                             resolution=float(grid.resolution), width=int(w),
                                             height=int(h), origin=origin)
        return T[GRID](header=header, info=info, data=grid.data.reshape(-1).astype(np.int8))

    def _transform_msg(self, r: TransformRecord):
        T = self._ts.types
        tr = T["geometry_msgs/msg/Transform"](translation=self._vector(r.pose.x, r.pose.y),
                                              rotation=self._quaternion(r.pose.theta))
        # ROS 1 tf messages share one header counter per topic, as a broadcaster's would.
        key = "/tf_static" if r.static else "/tf"
        return T["geometry_msgs/msg/TransformStamped"](
            header=self._header(key, r.time, r.parent), child_frame_id=r.child, transform=tr)

    def _pose(self, p: Pose2D):
        T = self._ts.types
        return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](
            x=float(p.x), y=float(p.y), z=0.0), orientation=self._quaternion(p.theta))

    def _vector(self, x: float, y: float, z: float = 0.0):
        return self._ts.types["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    def _quaternion(self, yaw: float):
        return self._ts.types["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))


def write_bag(path, records: Iterable[Record], fmt: str = "ros2",
              topics: BagTopics | None = None, *, storage: str = "sqlite3") -> Path:
    """Write records to a new bag (see :class:`BagWriter`); returns the bag's path."""
    with BagWriter(path, fmt, topics, storage=storage) as w:
        for r in records:
            w.write(r)
    return Path(path)


def _ns(time: float) -> int:
    """Seconds -> integer nanoseconds, rounded, so a stamp reads back to the nearest ns."""
    return int(round(float(time) * 1e9))


def _latched_qos():
    """What ROS 2's static transform broadcaster offers: reliable, transient local, depth 1."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)

    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
               zero, zero, QosLiveliness.AUTOMATIC, zero, False)
