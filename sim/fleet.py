"""Several robots in one world: each with its own start, route, drifting odometry and lidars,
and each a moving obstacle in the others' scans, as people are.

``FleetWorld(scenario, session, members, seed).run()`` steps the physics at a fixed rate and
yields ``(robot, msg)`` pairs in time order: ``msg`` an ``OdometryMsg`` or a ``ScanMsg`` of that
robot, exactly as ``World`` yields them for its one robot, until every robot has driven its
route. The walls, objects, people, ground truth and the scans without people are those of the
session's ``World``, which the fleet keeps as ``base``.

Robot 0 uses the single robot's random streams (odometry, lidars), so a fleet of one on the
scenario's own route is that robot; every other robot has streams of its own, derived from the
same seed. The robots' lidars need not fire together: ``FleetMember.lidar_phase`` delays a
robot's scan clock, as unsynchronised robots' clocks are. A robot yields to the robots ahead of
it as it yields to people, so routes that meet head on in an aisle narrower than two robots
hold both up until the session's time limit: the routes of a fleet are one-way.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from gridmap import OccupancyGrid, Pose2D, Scan

from . import geometry as geo
from . import lidar as lid
from .odometry import Odometry
from .robot import RouteFollower, integrate
from .scenario import Scenario
from .world import _LIDAR0, OdometryMsg, ScanMsg, World, _child, _Physics

# seed-tree key of robot k > 0 (robot 0 keeps the single robot's streams)
_ROBOT_KEY = 1000


@dataclass(frozen=True)
class FleetMember:
    """One robot of a fleet: where it starts and the waypoints (K, 2) it drives to in order."""

    start: Pose2D
    route: tuple
    lidar_phase: float = 0.0     # [s] its scans come this much after the fleet's first clock


class _Robot:
    """The moving state of one robot of the fleet."""

    def __init__(self, scenario: Scenario, member: FleetMember, odometry_rng, lidar_rngs):
        spec = scenario.robot
        start = member.start
        self.pose = np.array([start.x, start.y, start.theta])
        waypoints = np.vstack([[start.x, start.y], np.asarray(member.route, np.float64)])
        self.follower = RouteFollower(waypoints, spec.max_speed, spec.max_turn_rate,
                                      spec.max_accel, spec.radius)
        self.odometry = Odometry(start, spec.odometry_noise, odometry_rng)
        self.lidar_rngs = lidar_rngs
        self.phase = float(member.lidar_phase)
        self.true, self.odom = start, start
        self.v = self.w = 0.0

    @property
    def done(self) -> bool:
        return self.follower.done and self.follower.v == 0.0 and self.follower.w == 0.0


class FleetWorld:
    """One session's world with a fleet of robots (see the module's docstring)."""

    def __init__(self, scenario: Scenario, session: int | str, members,
                 seed: int | np.random.SeedSequence | None = None):
        members = list(members)
        if not members:
            raise ValueError("a fleet needs at least one robot")
        self.scenario = scenario
        self.base = World(scenario, session, seed)
        self.members = members
        self._check_starts()
        root = seed if isinstance(seed, np.random.SeedSequence) else \
            np.random.SeedSequence(scenario.seed if seed is None else int(seed))
        ss = _child(root, self.base.index)
        n_lidars = len(scenario.robot.lidars)
        self.robots = [_Robot(scenario, members[0], self.base.odometry.rng,
                              self.base._lidar_rngs)]
        for k, member in enumerate(members[1:], start=1):
            own = _child(ss, _ROBOT_KEY + k)
            rngs = [np.random.default_rng(_child(own, j)) for j in range(_LIDAR0 + n_lidars)]
            self.robots.append(_Robot(scenario, member, rngs[1], rngs[_LIDAR0:]))
        self._time = 0.0
        self._people_now = self.base.crowd.discs()
        self._started = False
        self.finished = False

    def _check_starts(self) -> None:
        """Refuse a robot that would start inside a wall, an object or another robot: the
        physics would never push it out (robots are kinematic)."""
        r = self.scenario.robot.radius - geo.TOUCH_TOL
        xy = np.array([[m.start.x, m.start.y] for m in self.members], np.float64)
        for k, p in enumerate(xy):
            blocked = (geo.point_box_distance(p[None], self.base.boxes) < r).any() or \
                (geo.point_circle_distance(p[None], self.base.circles) < r).any()
            close = np.hypot(*(xy[:k] - p).T) < 2 * r if k else np.zeros(0, bool)
            if blocked or close.any():
                what = "a wall or an object" if blocked else f"robot {int(np.argmax(close))}"
                raise ValueError(f"robot {k} starts at ({p[0]:.2f}, {p[1]:.2f}) inside {what}")

    # --- state ------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.robots)

    @property
    def time(self) -> float:
        """[s] time of the latest message."""
        return self._time

    def true_poses(self) -> list[Pose2D]:
        """Each robot's true pose at the latest message's time."""
        return [r.true for r in self.robots]

    def people(self) -> np.ndarray:
        """(N, 3) x, y, radius of every person at the latest message's time."""
        return self._people_now.copy()

    def robot_discs(self) -> np.ndarray:
        """(R, 3) x, y, radius of every robot at the latest message's time."""
        radius = self.scenario.robot.radius
        return np.array([[r.true.x, r.true.y, radius] for r in self.robots], np.float64)

    def ground_truth(self) -> OccupancyGrid:
        return self.base.ground_truth()

    def scan_without_people(self, robot_pose: Pose2D, lidar: int = 0) -> Scan:
        """The noise-free scan from ``robot_pose`` with neither people nor robots in the way."""
        return self.base.scan_without_people(robot_pose, lidar)

    @property
    def time_limit(self) -> float:
        """[s] the session's ``max_duration``, or three times the longest route at top speed
        plus time for turns and for waiting behind the others."""
        if self.base.session.max_duration:
            return self.base.session.max_duration
        longest = max(_length(r.follower.waypoints) for r in self.robots)
        turns = max(len(r.follower.waypoints) for r in self.robots)
        return 3.0 * longest / self.scenario.robot.max_speed + 10.0 * turns + 60.0

    # --- running ----------------------------------------------------------------------------------
    def run(self):
        """Step the world; yield ``(robot, msg)`` in time order until every robot is done (or
        the time limit has passed). At a shared time odometry comes before scans, and a lower
        robot number first."""
        if self._started:
            raise RuntimeError("FleetWorld.run() can be called once; make a new one to replay")
        self._started = True
        self._begin()
        limit, dt = self.time_limit, self.base.physics_dt
        step = 0
        while True:
            yield from self._advance(step, dt)
            step += 1
            if all(r.done for r in self.robots):
                self.finished = True
                return
            if step * dt >= limit:
                warnings.warn(f"{self.scenario.name}/{self.base.session.name}: the fleet did not "
                              f"finish its routes within {limit:.0f} s", RuntimeWarning,
                              stacklevel=2)
                return

    def _begin(self) -> None:
        robot = self.scenario.robot
        self.base._pose = self.robots[0].pose.copy()
        self._physics = _FleetPhysics(self.base, [r.pose for r in self.robots[1:]])
        rates = [robot.odometry_rate_hz] + [ld.rate_hz for ld in robot.lidars]
        # one clock per robot and stream: (rate, phase, ticks so far)
        self._clocks = [[rate, 0.0 if j == 0 else r.phase, 0]
                        for r in self.robots for j, rate in enumerate(rates)]
        self._streams = len(rates)

    def _commands(self, dt: float) -> list[tuple[float, float]]:
        """Each robot's route speeds; the other robots count as people in its way."""
        people = self.base.crowd.discs() if len(self.base.crowd) else np.zeros((0, 3))
        radius = self.scenario.robot.radius
        out = []
        for k, r in enumerate(self.robots):
            others = [[o.pose[0], o.pose[1], radius] for j, o in enumerate(self.robots) if j != k]
            in_way = np.vstack([people, np.asarray(others, np.float64).reshape(-1, 3)])
            out.append(r.follower.command(r.pose, in_way, dt))
        return out

    def _advance(self, step: int, dt: float):
        """One physics step; yields the messages due within it, earliest first."""
        base, crowd = self.base, self.base.crowd
        t0, t1 = step * dt, (step + 1) * dt
        commands = self._commands(dt)
        poses0 = [r.pose for r in self.robots]
        people0 = crowd.pos.copy()
        if len(crowd):
            self._physics.set_people_velocities(self._wished_velocities(poses0, dt))
        for r, (v, w) in zip(self.robots, commands):
            r.v, r.w = v, w
            r.pose = integrate(r.pose, v, w, dt)
        self._physics.step_all(dt, poses0, [r.pose for r in self.robots], commands)
        if len(crowd):
            self._physics.read_people(crowd.pos, crowd.vel)
            self._keep_people_out()
        while True:
            due = [(k * self._streams + j) for k in range(len(self.robots))
                   for j in range(self._streams)]
            c = min(due, key=self._due)
            t = self._due(c)
            if t > t1 + 1e-9:
                break
            self._clocks[c][2] += 1
            s = min(max((t - t0) / dt, 0.0), 1.0)
            poses = [integrate(p, r.v, r.w, s * dt) for p, r in zip(poses0, self.robots)]
            people = people0 + s * (crowd.pos - people0)
            k, j = divmod(c, self._streams)
            yield k, self._message(k, j, t, poses, people)
        base._step = step + 1

    def _due(self, clock: int) -> float:
        rate, phase, ticks = self._clocks[clock]
        return phase + ticks / rate

    def _wished_velocities(self, poses, dt: float) -> np.ndarray:
        """People's social forces with the nearest robot as the robot and the others as
        obstacles (the force model knows one robot)."""
        crowd, radius = self.base.crowd, self.scenario.robot.radius
        discs = np.array([[p[0], p[1], radius] for p in poses], np.float64)
        centre = crowd.pos.mean(axis=0)
        k = int(np.argmin(np.hypot(discs[:, 0] - centre[0], discs[:, 1] - centre[1])))
        static = crowd.circles
        crowd.circles = np.vstack([static, np.delete(discs, k, axis=0)])
        try:
            return crowd.wished_velocities(discs[k], dt)
        finally:
            crowd.circles = static

    def _keep_people_out(self) -> None:
        crowd, radius = self.base.crowd, self.scenario.robot.radius
        before = crowd.pos.copy()
        discs = np.array([[r.pose[0], r.pose[1], radius] for r in self.robots], np.float64)
        pushes = crowd.keep_out(discs)
        if pushes:
            self.base.pushes += pushes
            moved = np.nonzero((crowd.pos != before).any(axis=1))[0]
            self._physics.place_people(moved, crowd.pos[moved])

    def _message(self, k: int, j: int, t: float, poses, people_xy):
        """Robot ``k``'s message of stream ``j`` (0 odometry, then the lidars) at time ``t``."""
        robot = self.robots[k]
        self._time = t
        for r, p in zip(self.robots, poses):
            r.true = Pose2D(float(p[0]), float(p[1]), float(p[2]))
        crowd = self.base.crowd
        if len(crowd):
            self._people_now = np.column_stack([people_xy, crowd.radius])
        if j == 0:
            robot.odom = robot.odometry.tick(robot.true)
            return OdometryMsg(t, robot.odom, robot.true)
        spec = self.scenario.robot.lidars[j - 1]
        robot.odom = robot.odometry.pose_at(robot.true)
        radius = self.scenario.robot.radius
        others = np.array([[p[0], p[1], radius] for i, p in enumerate(poses) if i != k],
                          np.float64).reshape(-1, 3)
        circles = np.concatenate([self.base.circles, self._people_now, others])
        exact = lid.cast_ranges(lid.sensor_poses(poses[k][None], spec.mount), spec,
                                self.base.segments, circles)[0]
        scan = lid.make_scan(lid.measure(exact, spec, robot.lidar_rngs[j - 1]), spec, t)
        return ScanMsg(t, j - 1, scan, robot.true, robot.odom)


class _FleetPhysics(_Physics):
    """The world's pymunk space with a kinematic disc per robot (they push people, nothing
    pushes them)."""

    def __init__(self, world: World, other_poses):
        import pymunk

        super().__init__(world)
        self.robots = [self.robot]
        for pose in other_poses:
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            body.position = (float(pose[0]), float(pose[1]))
            body.angle = float(pose[2])
            shape = pymunk.Circle(body, world.scenario.robot.radius)
            shape.friction = 0.0
            self.space.add(body, shape)
            self.robots.append(body)

    def step_all(self, dt: float, poses0, poses1, commands) -> None:
        """Advance by ``dt`` with each robot moving from ``poses0`` to ``poses1``."""
        for body, p0, (v, w) in zip(self.robots, poses0, commands):
            body.velocity = (v * math.cos(p0[2]), v * math.sin(p0[2]))
            body.angular_velocity = w
        self.space.step(dt)
        for body, p1 in zip(self.robots, poses1):
            body.position = (float(p1[0]), float(p1[1]))
            body.angle = float(p1[2])


def _length(points) -> float:
    pts = np.asarray(points, np.float64)
    return float(np.hypot(*np.diff(pts, axis=0).T).sum()) if len(pts) > 1 else 0.0


__all__ = ["FleetMember", "FleetWorld"]
