"""The robot's pose at a scan's stamp from what arrives live: odometry, and a localiser's pose
(amcl's ``/amcl_pose``), by the rules a recording is read with
(``robotlogs.observations.bag_poses``): odometry interpolated between its samples and held a
little outside them; amcl's pose turned into ``map -> odom`` with the odometry at its stamp,
each correction held until the next, as amcl's own tf is. The same arithmetic as the log
replay, so a node fed a recording places its scans where ``mapupdate update`` does.

Old samples are dropped (``keep`` seconds behind the newest), so a node running for days holds
a bounded history."""

from __future__ import annotations

import math

from gridmap import Pose2D
from robotlogs.frames import TransformTree
from robotlogs.records import TransformRecord

MAP, ODOM, BASE = "map", "odom", "base"


class LivePoses:
    def __init__(self, keep: float = 60.0):
        self.keep = keep
        self._odom: list[tuple[float, Pose2D]] = []
        self._amcl: list[tuple[float, Pose2D]] = []     # waiting for odometry past their stamp
        self._corrections: list[tuple[float, Pose2D]] = []
        self._tree = TransformTree()
        self.newest_odom = -math.inf
        self.newest_amcl = -math.inf

    def add_odometry(self, t: float, pose: Pose2D) -> None:
        self._odom.append((t, pose))
        self._tree.add(TransformRecord(t, ODOM, BASE, pose))
        self.newest_odom = max(self.newest_odom, t)
        self._settle()
        if self._odom[0][0] < self.newest_odom - 2 * self.keep:
            self._prune()

    def add_localisation(self, t: float, pose: Pose2D) -> None:
        """A localiser's robot pose in the map frame at ``t``; used once odometry is known
        on both sides of ``t`` (interpolated, as the replay does)."""
        self._amcl.append((t, pose))
        self.newest_amcl = max(self.newest_amcl, t)
        self._settle()

    def ready(self, t: float) -> bool:
        """Whether odometry past ``t`` has arrived, and the localiser's pose of ``t`` or later
        (once one came): a scan at ``t`` can be placed exactly, whatever order the topics'
        messages arrived in (the node stops waiting after ``tf_timeout``)."""
        return self.newest_odom > t and (self.newest_amcl == -math.inf or self.newest_amcl >= t)

    def at(self, t: float) -> tuple[Pose2D | None, Pose2D | None]:
        """(robot in map, robot in odom) at ``t``; None where not known."""
        self._settle(force_before=t)
        odom = self._tree.lookup(ODOM, BASE, t)
        robot = self._tree.lookup(MAP, BASE, t) if odom is not None else None
        return robot, odom

    def _settle(self, force_before: float = -math.inf) -> None:
        """Turn the localiser's poses whose stamps the odometry has passed into map -> odom."""
        still = []
        for t, pose in self._amcl:
            if t > self.newest_odom and t > force_before:
                still.append((t, pose))
                continue
            o = self._tree.lookup(ODOM, BASE, t)
            if o is not None:
                correction = pose.compose(o.inverse())
                self._corrections.append((t, correction))
                self._tree.add(TransformRecord(t, MAP, ODOM, correction), hold_after=math.inf,
                               steps=True)
        self._amcl = still

    def _prune(self) -> None:
        horizon = self.newest_odom - self.keep
        self._odom = [(t, p) for t, p in self._odom if t >= horizon]
        last = [c for c in self._corrections if c[0] < horizon][-1:]
        self._corrections = last + [c for c in self._corrections if c[0] >= horizon]
        self._tree = TransformTree()
        for t, p in self._odom:
            self._tree.add(TransformRecord(t, ODOM, BASE, p))
        for t, p in self._corrections:
            self._tree.add(TransformRecord(t, MAP, ODOM, p), hold_after=math.inf, steps=True)


class TfPoses:
    """The robot's pose at a scan's stamp from /tf and /tf_static, by the rules a recording's
    tf is read with (``robotlogs.observations.bag_poses``): each edge interpolated between its
    samples and held a little outside them, static edges held for ever. A static edge sent
    again replaces the old one (a corrected mount counts from then on). Samples older than
    ``keep`` seconds behind the newest odometry are dropped."""

    def __init__(self, map_frame: str, odom_frame: str, base_frame: str, keep: float = 60.0):
        self.map_frame, self.odom_frame, self.base_frame = map_frame, odom_frame, base_frame
        self.keep = keep
        self._edges: dict[str, tuple[str, list]] = {}     # child -> (parent, [(t, pose)])
        self._static: dict[str, tuple[str, Pose2D]] = {}  # child -> (parent, pose)
        self._tree = TransformTree()
        self.newest_odom = -math.inf
        self.newest_map = -math.inf

    def add(self, rec: TransformRecord) -> None:
        if rec.static:
            self._static[rec.child] = (rec.parent, rec.pose)
            self._rebuild()
            return
        parent, samples = self._edges.setdefault(rec.child, (rec.parent, []))
        if parent != rec.parent:             # tf's rule: a frame has one parent
            return
        samples.append((rec.time, rec.pose))
        self._tree.add(rec)
        if (rec.parent, rec.child) == (self.odom_frame, self.base_frame):
            self.newest_odom = max(self.newest_odom, rec.time)
            if samples[0][0] < self.newest_odom - 2 * self.keep:
                self._prune()
        elif (rec.parent, rec.child) == (self.map_frame, self.odom_frame):
            self.newest_map = max(self.newest_map, rec.time)

    def ready(self, t: float) -> bool:
        """Whether the odometry (and the localiser's correction, once one came) has passed
        ``t``, so a scan at ``t`` is placed as a replay of the recording places it."""
        return self.newest_odom > t and (self.newest_map == -math.inf or self.newest_map >= t)

    def at(self, t: float) -> tuple[Pose2D | None, Pose2D | None]:
        """(robot in map, robot in odom) at ``t``; None where not known."""
        odom = self._tree.lookup(self.odom_frame, self.base_frame, t)
        robot = self._tree.lookup(self.map_frame, self.base_frame, t) if odom is not None \
            else None
        return robot, odom

    def mount(self, laser_frame: str, t: float) -> Pose2D | None:
        """The laser's pose on the base at ``t`` (static edges hold for ever)."""
        return self._tree.lookup(self.base_frame, laser_frame, t, hold=math.inf)

    def _prune(self) -> None:
        horizon = self.newest_odom - self.keep
        for child, (parent, samples) in self._edges.items():
            older = [s for s in samples if s[0] < horizon][-1:]
            samples[:] = older + [s for s in samples if s[0] >= horizon]
        self._rebuild()

    def _rebuild(self) -> None:
        self._tree = TransformTree()
        for child, (parent, pose) in self._static.items():
            self._tree.add(TransformRecord(0.0, parent, child, pose, static=True))
        for child, (parent, samples) in self._edges.items():
            for t, pose in samples:
                self._tree.add(TransformRecord(t, parent, child, pose))
