"""The simulated world of one session: objects, walls, people, the robot, its odometry and lidars.

``World(scenario, session, seed).run()`` steps the physics at a fixed rate and yields, in time
order, an ``OdometryMsg`` at each odometry tick and a ``ScanMsg`` per lidar at each of its ticks,
until the robot has driven its route. ``step(v, w)`` (or ``drive``) instead holds commanded
speeds for a physics step and returns that step's messages: a caller drives the robot. Messages that fall inside a physics step see the state at
their own time: the robot's arc is exact and people move in straight lines within a step. At a
shared time the odometry message comes first, then the lidars in order.

Randomness: one ``numpy.random.Generator`` per component (people, odometry, each lidar, and the
on-demand noisy scans), all derived from the seed and the session index through
``numpy.random.SeedSequence``; the same seed gives the same messages, bit for bit.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from gridmap import OccupancyGrid, Pose2D, Scan

from . import geometry as geo
from . import lidar as lid
from .groundtruth import grid_frame, rasterise
from .odometry import Odometry
from .people import People
from .robot import RouteFollower, integrate
from .scenario import Scenario

PERSON_MASS = 70.0        # [kg]
COLLISION_SLOP = 0.002    # [m] overlap the physics engine tolerates between bodies
CONTACT_GAP = 0.01        # [m] a person this close to the robot's disc touches it
_PEOPLE, _ODOMETRY, _EXTRA, _LIDAR0 = 0, 1, 2, 3   # component numbers in the seed tree
_NOBODY = np.zeros((0, 3))


@dataclass(frozen=True)
class OdometryMsg:
    time: float          # [s]
    pose: Pose2D         # robot in the odom frame: noisy, drifting
    true_pose: Pose2D    # robot in the map frame


@dataclass(frozen=True)
class ScanMsg:
    time: float
    lidar: int           # index into scenario.robot.lidars
    scan: Scan
    true_pose: Pose2D    # robot (not sensor) in the map frame at the scan time
    odom_pose: Pose2D    # robot in the odom frame at the scan time


def _child(ss: np.random.SeedSequence, key: int) -> np.random.SeedSequence:
    # Built from the spawn key rather than by spawn(), which counts children on the parent
    # object: a caller handing us the same SeedSequence twice must get the same streams.
    return np.random.SeedSequence(ss.entropy, spawn_key=tuple(ss.spawn_key) + (key,),
                                  pool_size=ss.pool_size)


class World:
    """One session's world. ``session`` is an index (0 = first) or a name; its world has the
    changes of every session up to and including it applied in order."""

    def __init__(self, scenario: Scenario, session: int | str = 0,
                 seed: int | np.random.SeedSequence | None = None):
        self.scenario = scenario
        self.index = scenario.session_index(session)
        self.session = scenario.sessions[self.index]
        bounds, thick = scenario.world.bounds, scenario.world.wall_thickness
        self.obstacles = scenario.obstacles(self.index)
        self.boxes, self.circles = geo.obstacle_arrays(self.obstacles, bounds, thick)
        self.segments = geo.box_segments(self.boxes)
        root = seed if isinstance(seed, np.random.SeedSequence) else \
            np.random.SeedSequence(scenario.seed if seed is None else int(seed))
        ss = _child(root, self.index)
        rng = [np.random.default_rng(_child(ss, k))
               for k in range(_LIDAR0 + len(scenario.robot.lidars))]
        self._lidar_rngs = rng[_LIDAR0:]
        self._extra_rng = rng[_EXTRA]
        robot = scenario.robot
        start = robot.start
        self._pose = np.array([start.x, start.y, start.theta])
        self.crowd = People(self.session.people, self.boxes, self.circles,
                            np.array([start.x, start.y, robot.radius + 0.5]), rng[_PEOPLE])
        self.follower = RouteFollower(
            np.vstack([[start.x, start.y], np.asarray(self.session.route, np.float64)]),
            robot.max_speed, robot.max_turn_rate, robot.max_accel, robot.radius)
        self.odometry = Odometry(start, robot.odometry_noise, rng[_ODOMETRY])
        self._time = 0.0
        self._true = start
        self._odom = start
        self._people_now = self.crowd.discs()
        self.finished = False       # the route was driven to its end
        self.pushes = 0             # exact pushes of people out of the robot or objects
        self.collisions = 0         # step(): moves refused because of a wall or object
        self.people_contacts = 0    # step(): physics steps ending with a person at the robot
        self._started = False
        self._stepping = False
        self._step = 0

    # --- state ------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """[s] time of the latest message (0 before the first)."""
        return self._time

    @property
    def true_pose(self) -> Pose2D:
        return self._true

    @property
    def odom_pose(self) -> Pose2D:
        return self._odom

    @property
    def robot_pose(self) -> Pose2D:
        """The robot's true pose at the end of the latest physics step (``true_pose`` is the one
        at the latest message, which may fall inside a step)."""
        return Pose2D(float(self._pose[0]), float(self._pose[1]), float(self._pose[2]))

    @property
    def elapsed(self) -> float:
        """[s] simulated time at the end of the latest physics step."""
        return self._step * self.physics_dt

    def people(self) -> np.ndarray:
        """(N, 3) x, y, radius of every person at the latest message's time."""
        return self._people_now.copy()

    # --- truth --------------------------------------------------------------------------------------
    def ground_truth(self) -> OccupancyGrid:
        """G of this session's world in ``grid_frame(scenario)``; people are never part of it."""
        st = self.scenario.robot.start
        return rasterise(grid_frame(self.scenario), self.boxes, self.circles,
                         self.scenario.world.bounds, (st.x, st.y))

    def scan_without_people(self, robot_pose: Pose2D, lidar: int = 0, noise: bool = False) -> Scan:
        """The scan lidar ``lidar`` would take from ``robot_pose`` (map frame) in this world
        without people; noise-free unless ``noise`` (drawn from a stream of its own)."""
        ranges = self.scans_without_people(robot_pose.as_array()[None], lidar, noise)[0]
        return lid.make_scan(ranges, self.scenario.robot.lidars[lidar], self._time)

    def exact_scan(self, lidar: int = 0) -> Scan:
        """The noise-free scan lidar ``lidar`` would take now from the robot's pose, people
        included. Draws no random numbers, so looking does not change what comes next."""
        spec = self.scenario.robot.lidars[lidar]
        sensors = lid.sensor_poses(self._pose[None], spec.mount)
        circles = np.concatenate([self.circles, self._people_now]) if len(self.crowd) \
            else self.circles
        exact = lid.cast_ranges(sensors, spec, self.segments, circles)[0]
        return lid.make_scan(lid.measure(exact, spec, None), spec, self._time)

    def scans_without_people(self, robot_poses: np.ndarray, lidar: int = 0,
                             noise: bool = False) -> np.ndarray:
        """Ranges (N, beams) float32 of lidar ``lidar`` from robot poses (N, 3) in this world
        without people; inf for no return."""
        spec = self.scenario.robot.lidars[lidar]
        sensors = lid.sensor_poses(robot_poses, spec.mount)
        exact = lid.cast_ranges(sensors, spec, self.segments, self.circles)
        return lid.measure(exact, spec, self._extra_rng if noise else None)

    # --- running ------------------------------------------------------------------------------------
    @property
    def physics_dt(self) -> float:
        """[s] one physics step."""
        return 1.0 / self.scenario.physics_hz

    @property
    def time_limit(self) -> float:
        """[s] when the session gives up: its ``max_duration``, or time enough to drive the
        route three times over."""
        return self.session.max_duration or self._default_duration()

    def route_command(self) -> tuple[float, float]:
        """The route follower's speeds (v [m/s], w [rad/s]) for the next physics step, given the
        robot's pose and the people now. Advances the follower's state: call once per step."""
        return self.follower.command(self._pose, self.crowd.discs() if len(self.crowd)
                                     else _NOBODY, self.physics_dt)

    def run(self):
        """Step the world and yield ``OdometryMsg`` and ``ScanMsg`` in time order until the robot
        has finished its route (or the session's ``max_duration`` has passed)."""
        if self._started:
            raise RuntimeError("World.run() can be called once; make a new World to replay")
        self._begin()
        limit = self.time_limit
        while True:
            v, w = self.route_command()
            yield from self._advance(v, w, blocking=False)
            done = self.follower.done and self.follower.v == 0.0 and self.follower.w == 0.0
            if done or self._step * self._dt >= limit:
                self.finished = done
                if not done:
                    warnings.warn(f"{self.scenario.name}/{self.session.name}: the robot did not "
                                  f"finish its route within {limit:.0f} s", RuntimeWarning,
                                  stacklevel=2)
                return

    def step(self, v: float, w: float, n_steps: int = 1) -> list:
        """Drive the robot by command instead of along its route: hold speed ``v`` [m/s] and turn
        rate ``w`` [rad/s], clipped to the robot's limits, for ``n_steps`` physics steps and
        return the messages of that interval in time order. A move that would put the robot
        into a wall or an object is not made (it stands still for that step) and counts in
        ``collisions``; steps that end with a person touching the robot count in
        ``people_contacts``. Cannot be mixed with ``run()``."""
        return list(self.drive(v, w, n_steps))

    def drive(self, v: float, w: float, n_steps: int = 1):
        """``step`` as a generator: the world's state (``people()``, ``true_pose``) is that of
        each message's time while it is handled. Iterate it to the end before the next call."""
        if self._started and not self._stepping:
            raise RuntimeError("World.step() cannot follow World.run(); make a new World")
        robot = self.scenario.robot
        v = min(max(float(v), -robot.max_speed), robot.max_speed)
        w = min(max(float(w), -robot.max_turn_rate), robot.max_turn_rate)
        if not (math.isfinite(v) and math.isfinite(w)):
            raise ValueError(f"speeds must be finite, got v={v}, w={w}")
        if not self._started:
            self._begin()
            self._stepping = True
        for _ in range(int(n_steps)):
            yield from self._advance(v, w, blocking=True)

    def _begin(self) -> None:
        self._started = True
        self._physics = _Physics(self)
        robot = self.scenario.robot
        self._dt = 1.0 / self.scenario.physics_hz
        self._rates = [robot.odometry_rate_hz] + [ld.rate_hz for ld in robot.lidars]
        self._ticks = [0] * len(self._rates)
        self._due = [0.0] * len(self._rates)
        self._step = 0

    def _advance(self, v: float, w: float, blocking: bool):
        """One physics step with the robot at (v, w); yields the messages due within it. With
        ``blocking`` a move into a wall or object is refused (the route follower never makes
        one, and run() must stay exactly as it was, so it does not check)."""
        physics, dt, robot = self._physics, self._dt, self.scenario.robot
        rates, ticks, due = self._rates, self._ticks, self._due
        t0, t1 = self._step * dt, (self._step + 1) * dt
        pose0, people0 = self._pose, self.crowd.pos.copy()
        if len(self.crowd):
            robot_disc = np.array([pose0[0], pose0[1], robot.radius])
            physics.set_people_velocities(self.crowd.wished_velocities(robot_disc, dt))
        pose1 = integrate(pose0, v, w, dt)
        if blocking and v != 0.0 and self._hits_object(pose1):
            self.collisions += 1
            v = 0.0               # it may still turn on the spot: a disc turning hits nothing
            pose1 = integrate(pose0, v, w, dt)
        self._pose = pose1
        physics.step(dt, pose0, self._pose, v, w)
        if len(self.crowd):
            physics.read_people(self.crowd.pos, self.crowd.vel)
            self._keep_people_out(physics, self._pose)
            if blocking and self._touches_people(self._pose):
                self.people_contacts += 1
        while True:   # every message due by the end of this step, earliest first
            j = min(range(len(rates)), key=due.__getitem__)
            if due[j] > t1 + 1e-9:
                break
            t = due[j]
            ticks[j] += 1
            due[j] = ticks[j] / rates[j]
            s = min(max((t - t0) / dt, 0.0), 1.0)
            yield self._message(j, t, integrate(pose0, v, w, s * dt),
                                people0 + s * (self.crowd.pos - people0))
        self._step += 1

    def _hits_object(self, pose) -> bool:
        """Whether the robot's disc at ``pose`` overlaps a wall or an object (touching is fine)."""
        r = self.scenario.robot.radius - geo.TOUCH_TOL
        xy = np.asarray(pose[:2])[None]
        return bool((geo.point_box_distance(xy, self.boxes) < r).any()
                    or (geo.point_circle_distance(xy, self.circles) < r).any())

    def _touches_people(self, pose) -> bool:
        d = np.hypot(self.crowd.pos[:, 0] - pose[0], self.crowd.pos[:, 1] - pose[1])
        return bool((d < self.crowd.radius + self.scenario.robot.radius + CONTACT_GAP).any())

    def _default_duration(self) -> float:
        pts = self.follower.waypoints
        length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
        return 3.0 * length / self.scenario.robot.max_speed + 10.0 * len(pts) + 60.0

    def _message(self, j: int, t: float, pose: np.ndarray, people_xy: np.ndarray):
        true = Pose2D(float(pose[0]), float(pose[1]), float(pose[2]))
        self._time = t
        self._true = true
        if len(self.crowd):
            self._people_now = np.column_stack([people_xy, self.crowd.radius])
        if j == 0:
            self._odom = self.odometry.tick(true)
            return OdometryMsg(t, self._odom, true)
        k = j - 1
        spec = self.scenario.robot.lidars[k]
        self._odom = self.odometry.pose_at(true)
        sensors = lid.sensor_poses(pose[None], spec.mount)
        circles = np.concatenate([self.circles, self._people_now]) if len(self.crowd) \
            else self.circles
        exact = lid.cast_ranges(sensors, spec, self.segments, circles)[0]
        scan = lid.make_scan(lid.measure(exact, spec, self._lidar_rngs[k]), spec, t)
        return ScanMsg(t, k, scan, true, self._odom)

    def _keep_people_out(self, physics, pose) -> None:
        """The physics engine allows a little overlap; push anyone inside the robot or an object
        exactly clear of it (objects last: they win) and tell the engine."""
        before = self.crowd.pos.copy()
        pushes = self.crowd.keep_out(np.array([[pose[0], pose[1], self.scenario.robot.radius]]))
        if pushes:
            self.pushes += pushes
            moved = np.nonzero((self.crowd.pos != before).any(axis=1))[0]
            physics.place_people(moved, self.crowd.pos[moved])


class _Physics:
    """The pymunk space of a world: static walls and objects, the robot as a kinematic disc
    (it pushes, nothing pushes it), and a dynamic disc per person."""

    def __init__(self, world: World):
        import pymunk
        import pymunk.batch

        self.space = space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.collision_slop = COLLISION_SLOP
        for corners in geo.box_corners(world.boxes):
            self._add_static(pymunk.Poly(space.static_body, [tuple(map(float, c))
                                                             for c in corners]))
        for x, y, r in world.circles:
            self._add_static(pymunk.Circle(space.static_body, float(r), (float(x), float(y))))
        self.robot = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self.robot.position = (float(world._pose[0]), float(world._pose[1]))
        self.robot.angle = float(world._pose[2])
        shape = pymunk.Circle(self.robot, world.scenario.robot.radius)
        shape.friction = 0.0
        space.add(self.robot, shape)
        self.people = []
        for (x, y), r in zip(world.crowd.pos, world.crowd.radius):
            body = pymunk.Body(PERSON_MASS, math.inf)
            body.position = (float(x), float(y))
            shape = pymunk.Circle(body, float(r))
            shape.friction = 0.0
            space.add(body, shape)
            self.people.append(body)
        # people's state is read back in one batched call rather than attribute by attribute
        self._batch = pymunk.batch
        self._fields = pymunk.batch.BodyFields.BODY_ID | pymunk.batch.BodyFields.POSITION \
            | pymunk.batch.BodyFields.VELOCITY
        self._buffer = pymunk.batch.Buffer()
        self._ids = np.array([b.id for b in self.people], np.uintp)
        self._order = None
        self._order_key = b""

    def _add_static(self, shape) -> None:
        shape.friction = 0.0
        self.space.add(shape)

    def set_people_velocities(self, v: np.ndarray) -> None:
        for body, (vx, vy) in zip(self.people, v.tolist()):
            body.velocity = (vx, vy)

    def step(self, dt: float, pose0, pose1, v: float, w: float) -> None:
        """Advance by ``dt`` with the robot moving from ``pose0`` to ``pose1`` (its exact arc;
        the engine only needs its velocity to push people out of its way)."""
        self.robot.velocity = (v * math.cos(pose0[2]), v * math.sin(pose0[2]))
        self.robot.angular_velocity = w
        self.space.step(dt)
        self.robot.position = (float(pose1[0]), float(pose1[1]))
        self.robot.angle = float(pose1[2])

    def read_people(self, pos: np.ndarray, vel: np.ndarray) -> None:
        buf = self._buffer
        buf.clear()
        self._batch.get_space_bodies(self.space, self._fields, buf)
        ids = np.frombuffer(buf.int_buf(), dtype=np.uintp)
        state = np.frombuffer(buf.float_buf(), dtype=np.float64).reshape(-1, 4)
        key = ids.tobytes()
        if key != self._order_key:    # the engine's body order changes only on add or remove
            row = {int(b): k for k, b in enumerate(ids)}
            self._order = np.array([row[int(b)] for b in self._ids], np.int64)
            self._order_key = key
        pos[:] = state[self._order, :2]
        vel[:] = state[self._order, 2:]

    def place_people(self, idx, xy: np.ndarray) -> None:
        for i, (x, y) in zip(idx, xy.tolist()):
            self.people[i].position = (x, y)


__all__ = ["OdometryMsg", "ScanMsg", "World"]
