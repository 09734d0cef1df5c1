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

import numpy as np

from gridmap import Pose2D
from robotlogs.frames import TransformTree
from robotlogs.records import TransformRecord

from .transforms import TransformError, from_matrix, matrix

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
    ``keep`` seconds behind the newest transform of any edge are dropped, so that edges pile
    up no history even while the odometry never comes (a misnamed ``base_frame``). Each edge
    keeps whether its child frame is upside down and how far it is tilted (``transforms``), so
    that the laser's mount is composed as its 3D transforms compose."""

    def __init__(self, map_frame: str, odom_frame: str, base_frame: str, keep: float = 60.0):
        self.map_frame, self.odom_frame, self.base_frame = map_frame, odom_frame, base_frame
        self.keep = keep
        self._edges: dict[str, tuple[str, list]] = {}     # child -> (parent, [(t, pose)])
        self._static: dict[str, tuple[str, Pose2D]] = {}  # child -> (parent, pose)
        self._attitude: dict[str, tuple[bool, float]] = {}  # child -> (upside down, tilt)
        self._tree = TransformTree()
        self.newest_odom = -math.inf
        self.newest_map = -math.inf
        self.newest = -math.inf

    def add(self, rec: TransformRecord, flipped: bool = False, tilt: float = 0.0) -> None:
        if rec.static:
            self._static[rec.child] = (rec.parent, rec.pose)
            self._attitude[rec.child] = (flipped, tilt)
            self._rebuild()
            return
        parent, samples = self._edges.setdefault(rec.child, (rec.parent, []))
        if parent != rec.parent:             # tf's rule: a frame has one parent
            return
        samples.append((rec.time, rec.pose))
        self._attitude[rec.child] = (flipped, tilt)
        self._tree.add(rec)
        self.newest = max(self.newest, rec.time)
        if (rec.parent, rec.child) == (self.odom_frame, self.base_frame):
            self.newest_odom = max(self.newest_odom, rec.time)
        elif (rec.parent, rec.child) == (self.map_frame, self.odom_frame):
            self.newest_map = max(self.newest_map, rec.time)
        if samples[0][0] < self.newest - 2 * self.keep:
            self._prune()

    def samples(self) -> int:
        """How many transforms are held (bounded by ``keep``)."""
        return sum(len(s) for _, s in self._edges.values()) + len(self._static)

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

    def mount(self, laser_frame: str, t: float, max_tilt: float = math.inf
              ) -> tuple[Pose2D, bool] | None:
        """(the laser's pose on the base, upside down) at ``t`` (static edges hold for ever);
        None when the frames are not connected. ``TransformError`` when a frame on the way is
        tilted by more than ``max_tilt`` [rad] (a 2D scan that is not level)."""
        up_laser, up_base = self._chain(laser_frame), self._chain(self.base_frame)
        common = next((f for f in up_laser if f in up_base), None)
        if common is None:
            return None
        a = self._in_ancestor(up_laser, common, t, max_tilt)
        b = self._in_ancestor(up_base, common, t, max_tilt)
        if a is None or b is None:
            return None
        return from_matrix(np.linalg.solve(b, a))

    def _chain(self, frame: str) -> list[str]:
        chain, parent = [frame], self._tree.parent
        while chain[-1] in parent and len(chain) <= len(parent):
            chain.append(parent[chain[-1]])
        return chain

    def _in_ancestor(self, chain: list[str], ancestor: str, t: float, max_tilt: float):
        m = np.eye(3)
        for frame in chain[:chain.index(ancestor)]:
            flipped, tilt = self._attitude.get(frame, (False, 0.0))
            if tilt > max_tilt:
                raise TransformError(f"frame '{frame}' is tilted {math.degrees(tilt):.1f} deg "
                                     f"from level (upright and upside down are used; at most "
                                     f"{math.degrees(max_tilt):.1f} deg, max_mount_tilt)")
            edge = self._tree.static.get(frame)
            if edge is None:
                edge = self._tree.dynamic[frame].at(t, math.inf)
                if edge is None:
                    return None
            m = matrix(edge, flipped) @ m
        return m

    def _prune(self) -> None:
        horizon = self.newest - self.keep
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
