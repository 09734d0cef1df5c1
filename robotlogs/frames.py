"""Poses over time and a small 2D tf tree, for looking poses up at scan time.

A recording holds poses at their own stamps (odometry at 50 Hz, map -> odom whenever the
localiser updated, the laser mount once); a scan needs them all at its stamp. Between two stamps
a pose is interpolated linearly (x, y and the unwrapped yaw), as tf2 does; a little past either
end it is held, further out it is unknown (None), so a scan is never placed with a made-up pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gridmap import Pose2D, wrap_angle

from .records import TransformRecord

# How far past its first or last stamp a pose is held [s]: a few odometry periods, and amcl's
# default transform tolerance (0.1 s) with room to spare.
HOLD_S = 0.5


@dataclass
class PoseTimeline:
    """Poses of one frame in another at increasing times; built by ``add``, read by ``at``."""

    hold_after: float | None = None  # [s] past the last stamp; None: the ``hold`` asked for
    steps: bool = False              # each pose holds until the next (no interpolation)
    _t: list = field(default_factory=list)
    _p: list = field(default_factory=list)
    _arrays: tuple | None = None

    def add(self, time: float, pose: Pose2D) -> None:
        self._t.append(float(time))
        self._p.append((pose.x, pose.y, pose.theta))
        self._arrays = None

    def __len__(self) -> int:
        return len(self._t)

    def _frozen(self) -> tuple[np.ndarray, np.ndarray]:
        if self._arrays is None:
            t = np.asarray(self._t, np.float64)
            p = np.asarray(self._p, np.float64).reshape(-1, 3)
            order = np.argsort(t, kind="stable")
            t, p = t[order], p[order]
            p[:, 2] = np.unwrap(p[:, 2])  # so yaw interpolates the short way round
            self._arrays = (t, p)
        return self._arrays

    def at(self, time: float, hold: float = HOLD_S) -> Pose2D | None:
        """The pose at ``time``: interpolated inside (with ``steps``, the last one at or
        before ``time``), held up to ``hold`` [s] outside."""
        if not self._t:
            return None
        t, p = self._frozen()
        after = hold if self.hold_after is None else self.hold_after
        if time < t[0] - hold or time > t[-1] + after:
            return None
        if self.steps:
            k = max(int(np.searchsorted(t, time, side="right")) - 1, 0)
            return Pose2D(float(p[k, 0]), float(p[k, 1]), float(wrap_angle(float(p[k, 2]))))
        x = np.interp(time, t, p[:, 0])
        y = np.interp(time, t, p[:, 1])
        th = np.interp(time, t, p[:, 2])
        return Pose2D(float(x), float(y), float(wrap_angle(float(th))))

    def span(self) -> tuple[float, float] | None:
        if not self._t:
            return None
        t, _ = self._frozen()
        return float(t[0]), float(t[-1])


@dataclass
class TransformTree:
    """The tf tree of a recording in 2D: each frame has one parent; static edges hold forever."""

    parent: dict = field(default_factory=dict)   # child -> parent
    static: dict = field(default_factory=dict)   # child -> Pose2D
    dynamic: dict = field(default_factory=dict)  # child -> PoseTimeline

    def add(self, rec: TransformRecord, hold_after: float | None = None,
            steps: bool = False) -> None:
        """Add one edge; an edge that would give a frame a second parent is ignored (tf's
        own rule: the first parent wins). ``hold_after`` [s]: how long the edge's last pose
        holds; ``steps``: each of its poses holds until the next, not interpolated (a
        localiser's correction holds until the next one)."""
        known = self.parent.get(rec.child)
        if known is not None and known != rec.parent:
            return
        self.parent[rec.child] = rec.parent
        if rec.static:
            self.static[rec.child] = rec.pose
        else:
            self.dynamic.setdefault(rec.child, PoseTimeline(hold_after, steps)).add(rec.time,
                                                                                   rec.pose)

    def frames(self) -> set[str]:
        return set(self.parent) | set(self.parent.values())

    def lookup(self, target: str, source: str, time: float,
               hold: float = HOLD_S) -> Pose2D | None:
        """The pose of frame ``source`` in frame ``target`` at ``time``; None when the frames
        are not connected or an edge on the way has no pose near ``time``."""
        if target == source:
            return Pose2D(0.0, 0.0, 0.0)
        up_source = self._to_root(source)
        up_target = self._to_root(target)
        common = next((f for f in up_source if f in up_target), None)
        if common is None:
            return None
        a = self._pose_in_ancestor(source, common, time, hold)
        b = self._pose_in_ancestor(target, common, time, hold)
        if a is None or b is None:
            return None
        return a.relative_to(b)

    def _to_root(self, frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in self.parent and len(chain) <= len(self.parent):
            chain.append(self.parent[chain[-1]])
        return chain

    def _pose_in_ancestor(self, frame: str, ancestor: str, time: float,
                          hold: float) -> Pose2D | None:
        pose = Pose2D(0.0, 0.0, 0.0)
        while frame != ancestor:
            if frame in self.static:
                edge = self.static[frame]
            else:
                edge = self.dynamic[frame].at(time, hold)
                if edge is None:
                    return None
            pose = edge.compose(pose)
            frame = self.parent[frame]
        return pose
