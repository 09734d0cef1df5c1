"""The robot: a differential drive that follows its route and yields to people.

The controller drives leg by leg: it turns on the spot towards the next waypoint, drives
straight with a small heading correction, and slows down to stop where the route turns. Nearby
people ahead of it cap its speed, down to waiting, so it never runs into them; accelerations are
limited. The pose is integrated exactly (arcs) with the commanded speeds held over each step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gridmap import wrap_angle

TURN_DONE = 0.03          # [rad] heading error at which a turn on the spot ends
TURN_START = 0.5          # [rad] heading error that stops the robot for a turn on the spot
REACHED = 0.05            # [m] distance at which a waypoint where the route turns is reached
PASS_THROUGH = 0.2        # [rad] a route bend this small is driven through without stopping
HEADING_GAIN = 2.0        # [1/s] turn rate per radian of heading error
TURN_ACCEL = 2.0          # [rad/s^2]
PEOPLE_MARGIN = 0.1       # [m] clearance the robot keeps from people beyond the two radii
PEOPLE_STOP = 0.3         # [m] travel left before that clearance at which it stands still
PEOPLE_SLOW = 1.5         # [m] travel left at which it starts to slow down
CREEP_AFTER = 5.0         # [s] of waiting after which it creeps on where there is room
CREEP_SPEED = 0.05        # [m/s]


def integrate(pose, v: float, w: float, dt: float) -> np.ndarray:
    """The pose (x, y, yaw) after moving at speed ``v`` [m/s] and turn rate ``w`` [rad/s] for
    ``dt`` [s]: an exact arc, so poses between steps are exact too."""
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    if abs(w) < 1e-9:
        return np.array([x + v * dt * math.cos(th), y + v * dt * math.sin(th), th])
    th1 = th + w * dt
    r = v / w
    return np.array([x + r * (math.sin(th1) - math.sin(th)),
                     y - r * (math.cos(th1) - math.cos(th)),
                     (th1 + math.pi) % (2 * math.pi) - math.pi])


@dataclass
class RouteFollower:
    """State of the route following: the waypoints ahead and the current speeds."""

    waypoints: np.ndarray            # (K, 2) the start position, then the route's waypoints
    max_speed: float
    max_turn_rate: float
    max_accel: float
    radius: float
    index: int = 1                   # the waypoint being driven to
    turning: bool = True
    v: float = 0.0
    w: float = 0.0
    waiting: float = 0.0             # [s] spent held up by people

    @property
    def done(self) -> bool:
        return self.index >= len(self.waypoints)

    def command(self, pose: np.ndarray, people: np.ndarray, dt: float) -> tuple[float, float]:
        """Speeds (v, w) to hold over the next ``dt``, given the people (N, 3: x, y, radius)."""
        self._advance(pose)
        if self.done:
            v_cmd, w_cmd = 0.0, 0.0
        else:
            v_cmd, w_cmd = self._track(pose)
            v_free = v_cmd
            v_cmd = min(v_cmd, self._people_limit(pose, people))
            self.waiting = self.waiting + dt if v_cmd < v_free - 1e-9 else 0.0
        dv = self.max_accel * dt
        dw = TURN_ACCEL * dt
        self.v = min(max(v_cmd, self.v - dv), self.v + dv)
        self.w = min(max(w_cmd, self.w - dw), self.w + dw)
        return self.v, self.w

    def _advance(self, pose) -> None:
        while not self.done:
            tx, ty = self.waypoints[self.index]
            dist = math.hypot(tx - pose[0], ty - pose[1])
            if dist < REACHED or (dist < 0.3 and self._bend(self.index) < PASS_THROUGH
                                  and not self.turning):
                self.index += 1
                continue
            break

    def _bend(self, k: int) -> float:
        """Turn angle of the route at waypoint k (pi at the last one: the robot stops there)."""
        if k + 1 >= len(self.waypoints):
            return math.pi
        a, b, c = self.waypoints[k - 1], self.waypoints[k], self.waypoints[k + 1]
        return abs(wrap_angle(math.atan2(c[1] - b[1], c[0] - b[0])
                              - math.atan2(b[1] - a[1], b[0] - a[0])))

    def _track(self, pose) -> tuple[float, float]:
        tx, ty = self.waypoints[self.index]
        dist = math.hypot(tx - pose[0], ty - pose[1])
        err = wrap_angle(math.atan2(ty - pose[1], tx - pose[0]) - pose[2])
        if self.turning and abs(err) < TURN_DONE:
            self.turning = False
        elif not self.turning and abs(err) > TURN_START:
            self.turning = True
        w_lim = min(self.max_turn_rate, math.sqrt(2 * TURN_ACCEL * abs(err)))
        w = min(max(HEADING_GAIN * err, -w_lim), w_lim)
        if self.turning:
            return 0.0, w
        # brake to stop at a waypoint where the route bends
        stop = dist if self._bend(self.index) >= PASS_THROUGH else math.inf
        v = min(self.max_speed, math.sqrt(2 * self.max_accel * max(stop - REACHED / 2, 0.0)))
        return v * max(math.cos(err), 0.0), w

    def _people_limit(self, pose, people: np.ndarray) -> float:
        """Speed cap from the people the robot would run into if it drove straight on: it slows
        with the distance left before contact and stands still short of it. After a long wait
        it creeps on while there is room, so that people who stand near its path (they step
        away from an approaching robot) cannot hold it up forever."""
        if not len(people):
            return math.inf
        c, s = math.cos(pose[2]), math.sin(pose[2])
        room = math.inf
        for x, y, r in people.tolist():      # a handful of people: plain floats are fastest
            dx, dy = x - pose[0], y - pose[1]
            ahead = c * dx + s * dy
            side = -s * dx + c * dy
            reach = self.radius + r + PEOPLE_MARGIN
            if ahead > 0 and abs(side) < reach:
                room = min(room, ahead - math.sqrt(reach * reach - side * side))
        if room == math.inf:
            return math.inf
        cap = self.max_speed * min(max((room - PEOPLE_STOP) / (PEOPLE_SLOW - PEOPLE_STOP), 0.0),
                                   1.0)
        if self.waiting > CREEP_AFTER and room > 0.02:
            cap = max(cap, CREEP_SPEED)
        return cap
