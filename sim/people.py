"""People walking through the warehouse: route walkers and wanderers, moved by social forces.

Each person heads for a goal at their preferred speed: the next waypoint of their route (looping,
or back and forth), or a random point of their rectangle that they can walk to in a straight
line. Helbing's social-force model turns that wish into an acceleration, with repulsion from the
other people, the robot and the objects; the physics engine then resolves contacts, and a last
exact push keeps everyone out of objects. A walker who makes no progress for a while moves on to
the next goal, so nobody stays stuck behind an obstacle or in front of the waiting robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import geometry as geo
from .scenario import ScenarioError

# tau [s]; people strength [m/s^2], range [m]; obstacles; robot; anisotropy; cutoff [m]
SOCIAL_PARAMS = np.array([0.5, 3.0, 0.3, 4.0, 0.12, 4.0, 0.4, 0.35, 2.0])
GOAL_REACHED = 0.3        # [m]
STUCK_AFTER = 6.0         # [s] without getting 0.5 m closer to the goal
SPEED_CAP = 1.3           # a person never goes faster than this times their preferred speed
_NO_BOXES = np.zeros((0, 5))


@dataclass
class Walker:
    """What one person is doing; ``route`` people follow points, wanderers draw goals."""

    route: np.ndarray | None        # (K, 2)
    loop: bool
    rect: tuple | None
    target: int = 0                 # index into route
    step: int = 1                   # +1 or -1 when walking back and forth
    goal: np.ndarray | None = None


def _kernels():
    from . import _kernels

    return _kernels


class People:
    """State arrays of everyone walking: positions (N, 2), velocities (N, 2), radii and
    preferred speeds (N,)."""

    def __init__(self, specs, boxes: np.ndarray, circles: np.ndarray, keep_clear: np.ndarray,
                 rng: np.random.Generator):
        """``keep_clear`` (x, y, radius): where nobody may start (the robot)."""
        self.boxes, self.circles, self.rng = boxes, circles, rng
        self.segments = geo.box_segments(boxes)
        self.walkers: list[Walker] = []
        pos, rad, spd = [], [], []
        for spec in specs:
            for k in range(spec.count):
                if spec.route is not None:
                    route = np.asarray(spec.route, np.float64)
                    p, target = self._spread(route, spec.loop, (k + rng.random()) / spec.count)
                    w = Walker(route, spec.loop, None, target=target)
                else:
                    w = Walker(None, False, spec.wander)
                    p = None
                pos.append(p)
                rad.append(spec.radius)
                spd.append(spec.speed)
                self.walkers.append(w)
        self.radius = np.array(rad, np.float64)
        self.speed = np.array(spd, np.float64)
        self.pos = np.zeros((len(pos), 2))
        self.vel = np.zeros((len(pos), 2))
        placed = []
        for i, p in enumerate(pos):
            # route walkers where their spread put them unless that spot is taken
            if p is None or not self._free_spot(p, self.radius[i], placed, keep_clear):
                rect = self.walkers[i].rect
                if rect is None:
                    r = self.walkers[i].route
                    rect = (*r.min(axis=0), *r.max(axis=0))
                p = self._sample_spot(rect, self.radius[i], placed, keep_clear)
            self.pos[i] = p
            placed.append((p[0], p[1], self.radius[i]))
        for i, w in enumerate(self.walkers):
            if w.rect is not None:
                w.goal = self._sample_goal(i)
        self.goals = np.array([self._goal(i) for i in range(len(self))]).reshape(-1, 2)
        # per person: closest approach to the goal so far [m], time since the last real
        # progress [s], distance to the goal now [m]
        self.progress = np.tile([math.inf, 0.0, math.inf], (len(self), 1))

    def __len__(self) -> int:
        return self.pos.shape[0]

    def discs(self) -> np.ndarray:
        """(N, 3) x, y, radius."""
        return np.column_stack([self.pos, self.radius])

    # --- goals ------------------------------------------------------------------------------------
    @staticmethod
    def _spread(route: np.ndarray, loop: bool, frac: float):
        """The point at fraction ``frac`` of the route's length, and the waypoint after it."""
        pts = np.vstack([route, route[:1]]) if loop else route
        seg = np.hypot(*np.diff(pts, axis=0).T)
        s = frac * seg.sum()
        j = int(np.searchsorted(np.cumsum(seg), s, side="right"))
        j = min(j, len(seg) - 1)
        u = (s - (np.cumsum(seg)[j] - seg[j])) / max(seg[j], 1e-12)
        return pts[j] + u * (pts[j + 1] - pts[j]), (j + 1) % len(route)

    def _free_spot(self, p, r, placed, keep_clear, margin=0.05) -> bool:
        p = np.asarray(p, np.float64)[None]
        if (geo.point_box_distance(p, self.boxes) < r + margin).any():
            return False
        if len(self.circles) and (geo.point_circle_distance(p, self.circles) < r + margin).any():
            return False
        others = np.array(list(placed) + [tuple(keep_clear)], np.float64).reshape(-1, 3)
        return not (geo.point_circle_distance(p, others) < r + margin).any()

    def _sample_spot(self, rect, r, placed, keep_clear) -> np.ndarray:
        for _ in range(2000):
            p = np.array([self.rng.uniform(rect[0], rect[2]), self.rng.uniform(rect[1], rect[3])])
            if self._free_spot(p, r, placed, keep_clear):
                return p
        raise ScenarioError(f"no free spot for a person of radius {r} m in {list(rect)}")

    def _sample_goal(self, i: int) -> np.ndarray:
        """A random point of the walker's rectangle, clear of objects and, if possible, reachable
        in a straight line from where they stand."""
        rect, r = self.walkers[i].rect, self.radius[i]
        fallback = None
        for _ in range(60):
            g = np.array([self.rng.uniform(rect[0], rect[2]), self.rng.uniform(rect[1], rect[3])])
            if not self._free_spot(g, r, [], (math.inf, math.inf, 0.0), margin=0.1):
                continue
            fallback = g if fallback is None else fallback
            clear = geo.segment_box_distance(self.pos[i], g, self.boxes)
            if (clear > r + 0.05).all() and (len(self.circles) == 0 or (
                    geo.segment_circle_distance(self.pos[i], g, self.circles) > r + 0.05).all()):
                return g
        return fallback if fallback is not None else self.pos[i].copy()

    def _goal(self, i: int) -> np.ndarray:
        w = self.walkers[i]
        return w.goal if w.route is None else w.route[w.target]

    def update_goals(self) -> None:
        """Move on to the next waypoint or goal where one is reached or where the walker makes
        no progress (someone or something is in the way)."""
        best, since, dist = self.progress.T
        due = (dist <= GOAL_REACHED) | (since > STUCK_AFTER)
        if not due.any():
            return
        for i in np.nonzero(due)[0]:
            w = self.walkers[i]
            if w.route is None:
                w.goal = self._sample_goal(i)
            elif w.loop:
                w.target = (w.target + 1) % len(w.route)
            else:
                if not 0 <= w.target + w.step < len(w.route):
                    w.step = -w.step
                w.target += w.step
            self.goals[i] = self._goal(i)
            self.progress[i] = (math.inf, 0.0, math.inf)

    # --- motion ---------------------------------------------------------------------------------
    def desired_velocities(self) -> np.ndarray:
        """Preferred velocities (N, 2) towards the current goals."""
        out = np.empty_like(self.pos)
        _kernels().desired_velocities(self.pos, self.goals, self.speed, out)
        return out

    def wished_velocities(self, robot_disc: np.ndarray, dt: float) -> np.ndarray:
        """The velocities (N, 2) people want after ``dt``: social forces integrated once and
        capped at their top speed. Goals reached now are replaced for the next step."""
        out = np.empty_like(self.pos)
        if len(self):
            _kernels().people_step(self.pos, self.vel, self.radius, self.speed, self.goals,
                                   boxes=self.boxes, segs=self.segments, circles=self.circles,
                                   robot=robot_disc, params=SOCIAL_PARAMS, dt=dt,
                                   speed_cap=SPEED_CAP, progress=self.progress, out=out)
            self.update_goals()
        return out

    def keep_out(self, robot_disc: np.ndarray) -> int:
        """Push everyone exactly clear of the robot (1, 3), then of the objects; returns how
        many pushes it took."""
        if not len(self):
            return 0
        k = _kernels()
        return int(k.keep_out(self.pos, self.radius, _NO_BOXES, robot_disc, 0.0)
                   + k.keep_out(self.pos, self.radius, self.boxes, self.circles, 0.0))
