"""Scenario files: the warehouse and the sessions that rearrange it, as frozen dataclasses.

The YAML format is the contract of the design document; ``load_scenario`` reads a file into a
``Scenario`` and refuses, with a message naming the file and key (or object), an unknown key
(with the nearest valid name), a missing field, a value of the wrong kind, an object outside the
walls, overlapping objects, and a route that runs into an object. Checks on the geometry of each
session live in ``sim.validate``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from gridmap import MapUpdatingError, Pose2D
from gridmap.files import FileInputError, load_yaml
from gridmap.suggest import did_you_mean

from .validate import MAX_SESSION_S, check_scenario


class ScenarioError(MapUpdatingError, ValueError):
    """A scenario file that cannot be used; the message names the file and the key or object."""


# --- the dataclasses -------------------------------------------------------------------------------

@dataclass(frozen=True)
class Obstacle:
    """A box (``size`` = width along its own x, depth along its own y) or a circle (``radius``)."""

    id: str
    center: tuple[float, float]
    size: tuple[float, float] | None = None
    yaw: float = 0.0
    radius: float | None = None
    kind: str = ""           # free text for pictures: "shelf", "pallet", ...
    movable: bool = False

    @property
    def is_circle(self) -> bool:
        return self.radius is not None

    def box(self) -> np.ndarray:
        """(5,) centre x, y, half width, half depth, yaw."""
        return np.array([self.center[0], self.center[1], self.size[0] / 2, self.size[1] / 2,
                         self.yaw])

    def circle(self) -> np.ndarray:
        return np.array([self.center[0], self.center[1], self.radius])

    def moved(self, x: float, y: float, yaw: float) -> Obstacle:
        return replace(self, center=(x, y), yaw=yaw)


@dataclass(frozen=True)
class LidarSpec:
    mount: Pose2D = Pose2D(0.0, 0.0, 0.0)   # sensor pose in the robot frame
    fov_deg: float = 270.0
    beams: int = 1081
    range_min: float = 0.05                  # [m]
    range_max: float = 20.0                  # [m]
    range_noise_std: float = 0.01            # [m]
    rate_hz: float = 10.0

    @property
    def fov(self) -> float:
        return math.radians(self.fov_deg)

    @property
    def full_circle(self) -> bool:
        return self.fov_deg >= 360.0 - 1e-9

    @property
    def angle_increment(self) -> float:
        # A full circle has no beam at both ends; a partial fan has one at each edge.
        if self.beams == 1:
            return 0.0
        return self.fov / (self.beams if self.full_circle else self.beams - 1)

    @property
    def angle_min(self) -> float:
        return -math.pi if self.full_circle else -self.fov / 2


@dataclass(frozen=True)
class RobotSpec:
    start: Pose2D
    lidars: tuple[LidarSpec, ...]
    radius: float = 0.35                      # [m]
    max_speed: float = 0.6                    # [m/s]
    max_turn_rate: float = 1.0                # [rad/s]
    max_accel: float = 0.5                    # [m/s^2]
    odometry_noise: tuple[float, float, float, float] = (0.05, 0.01, 0.05, 0.01)
    odometry_rate_hz: float = 20.0


@dataclass(frozen=True)
class Change:
    """One rearrangement: ``kind`` is "move", "add" or "remove"."""

    kind: str
    id: str
    to: tuple[float, float, float] | None = None   # move: x, y, yaw
    obstacle: Obstacle | None = None               # add


@dataclass(frozen=True)
class PersonSpec:
    """Walkers: along ``route`` (``count`` of them, spread along it) or wandering in ``wander``."""

    speed: float = 1.1                                  # preferred walking speed [m/s]
    radius: float = 0.25                                # [m]
    route: tuple[tuple[float, float], ...] | None = None
    loop: bool = True                                   # else back and forth
    wander: tuple[float, float, float, float] | None = None   # x0, y0, x1, y1
    count: int = 1


@dataclass(frozen=True)
class SessionSpec:
    name: str
    route: tuple[tuple[float, float], ...]
    mapping: bool = False
    changes: tuple[Change, ...] = ()
    people: tuple[PersonSpec, ...] = ()
    max_duration: float | None = None        # [s] give up if the route is not done by then
    quick_route: tuple[tuple[float, float], ...] | None = None   # the route of quick runs


@dataclass(frozen=True)
class WorldSpec:
    bounds: tuple[float, float, float, float]
    wall_thickness: float = 0.13
    static: tuple[Obstacle, ...] = ()
    movable: tuple[Obstacle, ...] = ()


@dataclass(frozen=True)
class Scenario:
    name: str
    world: WorldSpec
    robot: RobotSpec
    sessions: tuple[SessionSpec, ...]
    seed: int = 0
    resolution: float = 0.05
    physics_hz: float = 20.0
    source: str = ""

    def session_index(self, session: int | str) -> int:
        """The index (0 = first session) of a session given by index or name."""
        names = [s.name for s in self.sessions]
        if isinstance(session, str) and session not in names and session.strip().isdigit():
            session = int(session)                      # "2" from a command line
        if isinstance(session, str):
            if session in names:
                return names.index(session)
            raise ScenarioError(f"{self.name}: no session named {session!r}"
                                f"{did_you_mean(session, names)}; sessions: {', '.join(names)}")
        i = int(session)
        if not 0 <= i < len(self.sessions):
            raise ScenarioError(f"{self.name}: session index {i} out of range 0..{len(names) - 1}")
        return i

    def obstacles(self, session: int | str) -> tuple[Obstacle, ...]:
        """Every object of the world of a session: the static ones, then the movable ones with
        the changes of all sessions up to and including this one applied in order."""
        i = self.session_index(session)
        movable = {o.id: o for o in self.world.movable}
        for s in self.sessions[: i + 1]:
            for ch in s.changes:
                if ch.kind == "move":
                    movable[ch.id] = movable[ch.id].moved(*ch.to)
                elif ch.kind == "remove":
                    del movable[ch.id]
                else:
                    movable[ch.id] = ch.obstacle
        return self.world.static + tuple(movable.values())


# --- reading YAML ----------------------------------------------------------------------------------

# What a scenario can hold: coordinates within 5 km of the origin, lists of at most 10 000
# entries, names fit for file names. The ranges of the single values are given where each is
# read; the size of the grid and the length of a session are checked in ``validate``.
MAX_COORD = 5000.0
MAX_ITEMS = 10_000
MAX_SEED = 2**63 - 1
NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]{0,63}")

class _Reader:
    """Walks the YAML tree keeping the path of keys, so every error names where it is."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, message: str):
        where = f"{self.source}: " if self.source else ""
        raise ScenarioError(f"{where}{key}: {message}" if key else f"{where}{message}")

    def mapping(self, node, key: str, required: set[str], optional: set[str]) -> dict:
        if not isinstance(node, dict):
            self.fail(key, f"expected a mapping, got {type(node).__name__}")
        allowed = sorted(required | optional)
        for k in node:
            if k not in allowed:
                more = did_you_mean(k, allowed, cutoff=0.5) or \
                    f" (valid keys: {', '.join(allowed)})"
                self.fail(_join(key, k), f"unknown key {k!r}{more}")
        for k in sorted(required):
            if k not in node:
                self.fail(_join(key, k), "missing required key")
        return node

    def number(self, node, key: str, positive: bool = False, nonneg: bool = False,
               within: tuple[float, float] | None = None) -> float:
        """A finite number; ``within``: the (low, high) it must lie in, named in the error
        (``positive`` makes low exclusive)."""
        if isinstance(node, bool) or not isinstance(node, (int, float)) or not math.isfinite(node):
            self.fail(key, f"expected a number, got {_short(node)}")
        if positive and not node > 0:
            self.fail(key, f"must be positive, got {node!r}")
        if nonneg and node < 0:
            self.fail(key, f"must not be negative, got {node!r}")
        if within is not None and not within[0] <= node <= within[1]:
            self.fail(key, f"must be in [{within[0]:g}, {within[1]:g}], got {node!r}")
        return float(node)

    def integer(self, node, key: str, minimum: int = 0, maximum: int | None = None) -> int:
        if isinstance(node, bool) or not isinstance(node, int):
            self.fail(key, f"expected an integer, got {_short(node)}")
        if node < minimum or (maximum is not None and node > maximum):
            span = f"in [{minimum}, {maximum}]" if maximum is not None else f"at least {minimum}"
            self.fail(key, f"must be {span}, got {node}")
        return int(node)

    def numbers(self, node, key: str, lengths: tuple[int, ...],
                within: tuple[float, float] = (-MAX_COORD, MAX_COORD)) -> tuple[float, ...]:
        if not isinstance(node, (list, tuple)) or len(node) not in lengths:
            want = " or ".join(str(n) for n in lengths)
            self.fail(key, f"expected a list of {want} numbers, got {_short(node)}")
        return tuple(self.number(v, f"{key}[{j}]", within=within) for j, v in enumerate(node))

    def points(self, node, key: str, minimum: int = 1) -> tuple[tuple[float, float], ...]:
        if not isinstance(node, (list, tuple)) or len(node) < minimum:
            self.fail(key, f"expected a list of at least {minimum} [x, y] points, "
                           f"got {_short(node)}")
        if len(node) > MAX_ITEMS:
            self.fail(key, f"more than {MAX_ITEMS} points")
        return tuple(self.numbers(p, f"{key}[{j}]", (2,)) for j, p in enumerate(node))

    def items(self, node, key: str) -> list:
        if node is None:
            return []
        if not isinstance(node, (list, tuple)):
            self.fail(key, f"expected a list, got {type(node).__name__}")
        if len(node) > MAX_ITEMS:
            self.fail(key, f"more than {MAX_ITEMS} entries")
        return list(node)

    def string(self, node, key: str) -> str:
        if not isinstance(node, (str, int)) or isinstance(node, bool):
            self.fail(key, f"expected a name, got {_short(node)}")
        return str(node)

    def file_name(self, node, key: str) -> str:
        """A name that becomes part of file and folder names (run folders, M_W2.yaml)."""
        name = self.string(node, key)
        if not NAME.fullmatch(name):
            self.fail(key, f"{name[:40]!r} cannot name files: use letters, digits, '.', '_' "
                           "and '-' (at most 64, not starting with '.' or '-')")
        return name

    def boolean(self, node, key: str) -> bool:
        if not isinstance(node, bool):
            self.fail(key, f"expected true or false, got {node!r}")
        return node


def _short(node) -> str:
    """A value for an error message: never a page of it."""
    text = repr(node)
    return text if len(text) <= 80 else text[:77] + "..."


def _join(key: str, k) -> str:
    return f"{key}.{k}" if key else str(k)


def _obstacle(r: _Reader, node, key: str, movable: bool) -> Obstacle:
    node = r.mapping(node, key, {"id", "center"}, {"size", "yaw", "radius", "kind"})
    has_size, has_radius = "size" in node, "radius" in node
    if has_size == has_radius:
        r.fail(key, "an object needs exactly one of 'size' (a box) or 'radius' (a circle)")
    oid = r.string(node["id"], _join(key, "id"))
    center = r.numbers(node["center"], _join(key, "center"), (2,))
    kind = r.string(node.get("kind", ""), _join(key, "kind"))
    if has_radius:
        if "yaw" in node:
            r.fail(_join(key, "yaw"), f"object {oid!r} is a circle and has no yaw")
        rad = r.number(node["radius"], _join(key, "radius"), positive=True, within=(0, 500))
        return Obstacle(oid, center, radius=rad, kind=kind, movable=movable)
    size = r.numbers(node["size"], _join(key, "size"), (2,), within=(-1000, 1000))
    if min(size) <= 0:
        r.fail(_join(key, "size"), f"object {oid!r} needs a positive size, got {list(size)}")
    yaw = r.number(node.get("yaw", 0.0), _join(key, "yaw"))
    return Obstacle(oid, center, size=size, yaw=yaw, kind=kind, movable=movable)


def _lidar(r: _Reader, node, key: str) -> LidarSpec:
    node = r.mapping(node, key, {"fov_deg", "beams", "range_max"},
                     {"mount", "range_min", "range_noise_std", "rate_hz"})
    d = LidarSpec()
    mount = r.numbers(node.get("mount", [0.0, 0.0, 0.0]), _join(key, "mount"), (3,),
                      within=(-10.0, 10.0))
    fov = r.number(node["fov_deg"], _join(key, "fov_deg"), positive=True)
    if fov > 360:
        r.fail(_join(key, "fov_deg"), f"must be at most 360, got {fov}")
    spec = LidarSpec(
        mount=Pose2D(*mount), fov_deg=fov,
        beams=r.integer(node["beams"], _join(key, "beams"), minimum=2, maximum=16384),
        range_min=r.number(node.get("range_min", d.range_min), _join(key, "range_min"),
                           nonneg=True, within=(0.0, 100.0)),
        range_max=r.number(node["range_max"], _join(key, "range_max"), positive=True,
                           within=(0.0, 100.0)),
        range_noise_std=r.number(node.get("range_noise_std", d.range_noise_std),
                                 _join(key, "range_noise_std"), nonneg=True, within=(0.0, 1.0)),
        rate_hz=r.number(node.get("rate_hz", d.rate_hz), _join(key, "rate_hz"), positive=True,
                         within=(0.1, 100.0)))
    if spec.range_min >= spec.range_max:
        r.fail(_join(key, "range_min"), f"must be below range_max ({spec.range_max})")
    return spec


def _robot(r: _Reader, node, key: str) -> RobotSpec:
    node = r.mapping(node, key, {"start", "lidars"},
                     {"radius", "max_speed", "max_turn_rate", "max_accel", "odometry_noise",
                      "odometry_rate_hz"})
    d = RobotSpec(Pose2D(0, 0, 0), ())
    lidars = r.items(node["lidars"], _join(key, "lidars"))
    if not lidars:
        r.fail(_join(key, "lidars"), "the robot needs at least one lidar")
    alphas = r.numbers(node.get("odometry_noise", list(d.odometry_noise)),
                       _join(key, "odometry_noise"), (4,), within=(0.0, 2.0))
    if min(alphas) < 0:
        r.fail(_join(key, "odometry_noise"), f"alphas must not be negative, got {list(alphas)}")
    return RobotSpec(
        start=Pose2D(*r.numbers(node["start"], _join(key, "start"), (3,))),
        lidars=tuple(_lidar(r, n, f"{key}.lidars[{j}]") for j, n in enumerate(lidars)),
        radius=r.number(node.get("radius", d.radius), _join(key, "radius"), positive=True,
                        within=(0.05, 5.0)),
        max_speed=r.number(node.get("max_speed", d.max_speed), _join(key, "max_speed"),
                           positive=True, within=(0.01, 5.0)),
        max_turn_rate=r.number(node.get("max_turn_rate", d.max_turn_rate),
                               _join(key, "max_turn_rate"), positive=True, within=(0.01, 10.0)),
        max_accel=r.number(node.get("max_accel", d.max_accel), _join(key, "max_accel"),
                           positive=True, within=(0.01, 20.0)),
        odometry_noise=alphas,
        odometry_rate_hz=r.number(node.get("odometry_rate_hz", d.odometry_rate_hz),
                                  _join(key, "odometry_rate_hz"), positive=True,
                                  within=(1.0, 1000.0)))


def _change(r: _Reader, node, key: str) -> Change:
    node = r.mapping(node, key, set(), {"move", "to", "remove", "add"})
    kinds = [k for k in ("move", "remove", "add") if k in node]
    if len(kinds) != 1:
        r.fail(key, "a change needs exactly one of 'move', 'remove' or 'add'")
    kind = kinds[0]
    if kind != "move" and "to" in node:
        r.fail(_join(key, "to"), "'to' belongs to a 'move'")
    if kind == "add":
        obs = _obstacle(r, node["add"], _join(key, "add"), movable=True)
        return Change("add", obs.id, obstacle=obs)
    oid = r.string(node[kind], _join(key, kind))
    if kind == "remove":
        return Change("remove", oid)
    if "to" not in node:
        r.fail(_join(key, "to"), f"missing required key (where {oid!r} goes: [x, y, yaw])")
    to = r.numbers(node["to"], _join(key, "to"), (2, 3))
    return Change("move", oid, to=to if len(to) == 3 else (to[0], to[1], math.nan))


def _person(r: _Reader, node, key: str) -> PersonSpec:
    node = r.mapping(node, key, set(), {"route", "loop", "wander", "count", "speed", "radius"})
    if ("route" in node) == ("wander" in node):
        r.fail(key, "a people entry needs exactly one of 'route' or 'wander'")
    d = PersonSpec()
    speed = r.number(node.get("speed", d.speed), _join(key, "speed"), positive=True)
    if speed > 2.5:
        r.fail(_join(key, "speed"), f"{speed} m/s is not a walking speed")
    radius = r.number(node.get("radius", d.radius), _join(key, "radius"), positive=True,
                      within=(0.0, 1.0))
    count = r.integer(node.get("count", 1), _join(key, "count"), minimum=1, maximum=500)
    if "route" in node:
        if "loop" in node:
            r.boolean(node["loop"], _join(key, "loop"))
        route = r.points(node["route"], _join(key, "route"), minimum=2)
        return PersonSpec(speed, radius, route=route, loop=node.get("loop", True), count=count)
    if "loop" in node:
        r.fail(_join(key, "loop"), "'loop' belongs to a 'route'")
    rect = r.numbers(node["wander"], _join(key, "wander"), (4,))
    if rect[2] <= rect[0] or rect[3] <= rect[1]:
        r.fail(_join(key, "wander"), f"expected [x_min, y_min, x_max, y_max], got {list(rect)}")
    return PersonSpec(speed, radius, wander=rect, count=count)


def _session(r: _Reader, node, key: str) -> SessionSpec:
    node = r.mapping(node, key, {"name", "route"},
                     {"mapping", "changes", "people", "max_duration", "quick_route"})
    name = r.file_name(node["name"], _join(key, "name"))
    dur = node.get("max_duration")
    return SessionSpec(
        name=name,
        route=r.points(node["route"], _join(key, "route")),
        mapping=r.boolean(node.get("mapping", False), _join(key, "mapping")),
        changes=tuple(_change(r, n, f"{key}.changes[{j}]")
                      for j, n in enumerate(r.items(node.get("changes"), _join(key, "changes")))),
        people=tuple(_person(r, n, f"{key}.people[{j}]")
                     for j, n in enumerate(r.items(node.get("people"), _join(key, "people")))),
        max_duration=None if dur is None else r.number(dur, _join(key, "max_duration"),
                                                       positive=True, within=(0.0, MAX_SESSION_S)),
        quick_route=(None if node.get("quick_route") is None
                     else r.points(node["quick_route"], _join(key, "quick_route"))))


def _world(r: _Reader, node, key: str) -> WorldSpec:
    node = r.mapping(node, key, {"bounds"}, {"wall_thickness", "static", "movable"})
    bounds = r.numbers(node["bounds"], _join(key, "bounds"), (4,))
    if bounds[2] <= bounds[0] or bounds[3] <= bounds[1]:
        r.fail(_join(key, "bounds"), f"expected [x_min, y_min, x_max, y_max], got {list(bounds)}")
    return WorldSpec(
        bounds=bounds,
        wall_thickness=r.number(node.get("wall_thickness", 0.13), _join(key, "wall_thickness"),
                                positive=True, within=(0.0, 2.0)),
        static=tuple(_obstacle(r, n, f"{key}.static[{j}]", False)
                     for j, n in enumerate(r.items(node.get("static"), _join(key, "static")))),
        movable=tuple(_obstacle(r, n, f"{key}.movable[{j}]", True)
                      for j, n in enumerate(r.items(node.get("movable"), _join(key, "movable")))))


def scenario_from_dict(data, source: str = "") -> Scenario:
    """Build and validate a scenario from the parsed YAML tree; ``source`` names it in errors."""
    r = _Reader(source)
    data = r.mapping(data, "", {"name", "world", "robot", "sessions"},
                     {"seed", "resolution", "physics_hz"})
    sessions = r.items(data["sessions"], "sessions")
    if not sessions:
        r.fail("sessions", "a scenario needs at least one session")
    scn = Scenario(
        name=r.file_name(data["name"], "name"),
        world=_world(r, data["world"], "world"),
        robot=_robot(r, data["robot"], "robot"),
        sessions=tuple(_session(r, n, f"sessions[{j}]") for j, n in enumerate(sessions)),
        seed=r.integer(data.get("seed", 0), "seed", minimum=0, maximum=MAX_SEED),
        resolution=r.number(data.get("resolution", 0.05), "resolution", positive=True,
                            within=(0.01, 1.0)),
        physics_hz=r.number(data.get("physics_hz", 20.0), "physics_hz", positive=True,
                            within=(5.0, 1000.0)),
        source=source)
    check_scenario(scn, r.fail)
    return _resolve_moves(scn)


def _resolve_moves(scn: Scenario) -> Scenario:
    """A move written as [x, y] keeps the object's yaw: fill it in once, here."""
    yaw = {o.id: o.yaw for o in scn.world.movable}
    sessions = []
    for s in scn.sessions:
        changes = []
        for ch in s.changes:
            if ch.kind == "move":
                if math.isnan(ch.to[2]):
                    ch = replace(ch, to=(ch.to[0], ch.to[1], yaw[ch.id]))
                yaw[ch.id] = ch.to[2]
            elif ch.kind == "add":
                yaw[ch.id] = ch.obstacle.yaw
            changes.append(ch)
        sessions.append(replace(s, changes=tuple(changes)))
    return replace(scn, sessions=tuple(sessions))


def load_scenario(path) -> Scenario:
    """Read and validate a scenario file (YAML, the format of the design document)."""
    path = Path(path)
    try:
        data = load_yaml(path, "scenario file", ScenarioError)
    except FileNotFoundError:
        raise ScenarioError(f"{path}: scenario file not found") from None
    except FileInputError as e:
        raise ScenarioError(str(e)) from None
    return scenario_from_dict(data, str(path))


def quick_variant(scn: Scenario, max_route_length: float | None = None,
                  beam_step: int = 1) -> Scenario:
    """A cheaper copy for smoke runs: each update session drives its ``quick_route`` when the
    scenario gives one (chosen to keep every change in view) and no ``max_route_length`` is
    asked for, else its route cut after ``max_route_length`` metres (default 30, at a waypoint); with ``beam_step`` > 1, every lidar keeps one
    beam in ``beam_step`` over the same field of view. Mapping routes stay whole, since the
    initial map decides what any later session can be scored against."""
    lidars = tuple(replace(ld, beams=max(2, (ld.beams - 1) // beam_step + 1))
                   for ld in scn.robot.lidars)
    sessions = []
    start = (scn.robot.start.x, scn.robot.start.y)
    for s in scn.sessions:
        if s.mapping:
            sessions.append(s)
            continue
        if s.quick_route is not None and max_route_length is None:
            sessions.append(replace(s, route=s.quick_route))
            continue
        pts, length, prev = [], 0.0, start
        for p in s.route:
            length += math.dist(prev, p)
            pts.append(p)
            prev = p
            if length >= (30.0 if max_route_length is None else max_route_length):
                break
        sessions.append(replace(s, route=tuple(pts)))
    return replace(scn, robot=replace(scn.robot, lidars=lidars), sessions=tuple(sessions))


__all__ = ["Change", "LidarSpec", "Obstacle", "PersonSpec", "RobotSpec", "Scenario",
           "ScenarioError", "SessionSpec", "WorldSpec", "load_scenario", "quick_variant",
           "scenario_from_dict"]
