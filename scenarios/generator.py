"""Generated warehouses: a scenario in the format of ``sim.scenario`` from a seed.

    tree = generate(3, size=(30, 20), sessions=4)     # the YAML tree
    write_generated(3, "gen3.yaml")                   # the file, byte for byte the same each time

The building is a rectangle (15 x 10 m to 60 x 40 m) with a dock strip along its south wall, a
strip along its north wall, and between them rows of racks (static boxes, split into bays with
pass-throughs when long) separated by aisles of varied width; a cross-aisle at each end of the
rows joins the aisles. Pillars stand where no lane runs. Movable pallets, drums and boxes stand
beside the lanes. The robot drives only on lanes: the centre line of every aisle and strip
and of both cross-aisles. No object comes closer than ``LANE_CLEARANCE`` beyond the robot's
radius to any lane, so every route on them is clear in every session.

Sessions: W1 maps the warehouse along a serpentine through every aisle; each later session
drives a transport loop through a few aisles and back to the dock, and has 2-6 rearrangements
(moves, additions, removals), each placed validly and seen from that session's route and from
its ``quick_route`` (an out-and-back into the first aisle of its loop, what ``--quick``
drives): at least ``SEEN_CELLS`` cells of the object's outline (or of the place it left) take
lidar hits within ``SEEN_RANGE`` from ``SEEN_POSES`` poses along the route or more, so the
evaluation finds observable targets there. People walk along the lanes and wander in the dock.
Numbers are rounded to the millimetre, so the file is the same for the same arguments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

import sim
from gridmap import MapUpdatingError, Pose2D
from gridmap.atomic import write_atomically
from sim import geometry as geo, lidar as lid
from sim.validate import objects_overlap

SIZE_MIN, SIZE_MAX = (15.0, 10.0), (60.0, 40.0)
MAX_SESSIONS = 100         # sessions of one scenario (each a few minutes of simulated time)
ROBOT_RADIUS = 0.35
LANE_CLEARANCE = 0.3      # [m] beyond the robot's radius: lanes stay clear, as a warehouse keeps them
OBJECT_GAP = 0.1          # [m] between any two objects
SEEN_POSES = 9            # route poses (every ROUTE_STEP m) from which ...
SEEN_CELLS = 6            # ... at least this many cells of a change's outline are hit
SEEN_RANGE = 9.5          # [m] hits further than this do not count (the evaluation's 10 m)
ROUTE_STEP = 0.5          # [m]
QUICK_DEPTH = 12.0        # [m] how far the quick route goes into its aisle
TRIES = 200               # placements tried before a change is given up


class GenerateError(MapUpdatingError, ValueError):
    """Arguments for which no warehouse is generated."""


@dataclass(frozen=True)
class Layout:
    """The fixed part of a warehouse: the building, its racks and pillars, and its lanes."""

    bounds: tuple[float, float, float, float]
    static: tuple            # sim.Obstacle
    lanes_y: tuple[float, ...]    # horizontal lanes, south to north; the first is the dock's
    strips: tuple[tuple[float, float], ...]   # free band (y_lo, y_hi) around each lane
    x_west: float            # the two cross-aisle lanes
    x_east: float
    lidar: dict

    @property
    def start(self) -> tuple[float, float]:
        return (self.x_west, self.lanes_y[0])

    def lane_segments(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        y0, y1 = self.lanes_y[0], self.lanes_y[-1]
        segs = [((self.x_west, y), (self.x_east, y)) for y in self.lanes_y]
        return segs + [((self.x_west, y0), (self.x_west, y1)),
                       ((self.x_east, y0), (self.x_east, y1))]


def _r(v: float) -> float:
    return round(float(v), 3)


def check_arguments(size, sessions: int, fov: int) -> tuple[float, float]:
    try:
        w, h = (float(v) for v in size)
    except (TypeError, ValueError):
        raise GenerateError(f"size must be two numbers W H [m], got {size!r}") from None
    if not (SIZE_MIN[0] <= w <= SIZE_MAX[0] and SIZE_MIN[1] <= h <= SIZE_MAX[1]):
        raise GenerateError(f"size {w:g} x {h:g} m is outside {SIZE_MIN[0]:g} x "
                            f"{SIZE_MIN[1]:g} to {SIZE_MAX[0]:g} x {SIZE_MAX[1]:g} m")
    if isinstance(sessions, bool) or not isinstance(sessions, int) or \
            not 2 <= sessions <= MAX_SESSIONS:
        raise GenerateError(f"sessions must be an integer from 2 (the mapping session W1 and "
                            f"an update session) to {MAX_SESSIONS}, got {sessions!r}")
    if fov not in (270, 360):
        raise GenerateError(f"fov must be 270 or 360, got {fov!r}")
    return w, h


# --- the building ----------------------------------------------------------------------------
def _rack_rows(rng, y_lo: float, y_hi: float) -> list[tuple[float, float]]:
    """(y_bottom, y_top) of each rack row between the dock strip and the north strip: single
    racks or back to back, with aisles of 1.8-3.4 m between them."""
    rows, y = [], y_lo
    while True:
        depth = float(rng.choice([0.9, 1.1, 2.0]))
        if y + depth > y_hi:
            depth = 0.9
            if y + depth > y_hi:
                break
        rows.append((y, y + depth))
        y += depth
        room = y_hi - y - 0.9         # an aisle and one more single rack must fit
        if room < 1.8:
            break
        y += min(float(rng.uniform(1.8, 3.4)), room)
    return rows


def _racks(rows, x_lo: float, x_hi: float):
    length = x_hi - x_lo
    n_bays = max(1, math.ceil(length / 14.0))
    gap = 1.5 if n_bays > 1 else 0.0     # pass-throughs between bays, the same in every row
    bay = (length - gap * (n_bays - 1)) / n_bays
    out = []
    for j, (yb, yt) in enumerate(rows):
        for b in range(n_bays):
            xa = x_lo + b * (bay + gap)
            out.append(sim.Obstacle(f"rack_{j + 1}_{b + 1}", (_r(xa + bay / 2), _r((yb + yt) / 2)),
                                    size=(_r(bay), _r(yt - yb)), kind="rack"))
    return out


def _layout(rng, w: float, h: float, fov: int) -> Layout:
    x0, y0, x1, y1 = -w / 2, -h / 2, w / 2, h / 2
    dock = float(np.clip(0.2 * h, 3.0, 4.5))
    north = float(np.clip(0.15 * h, 2.2, 3.2))
    cross_w, cross_e = float(rng.uniform(3.0, 4.0)), float(rng.uniform(3.0, 4.0))
    rows = _rack_rows(rng, y0 + dock, y1 - north)
    racks = _racks(rows, x0 + cross_w, x1 - cross_e)
    # a lane down the middle of every band between racks (and walls)
    edges = [y0] + [v for row in rows for v in row] + [y1]
    strips = [(edges[k], edges[k + 1]) for k in range(0, len(edges), 2)]
    lanes = [_r(y0 + 1.2)] + [_r((a + b) / 2) for a, b in strips[1:]]
    lidar = ({"mount": [0.25, 0.0, 0.0], "fov_deg": 270, "beams": 1081} if fov == 270 else
             {"mount": [0.0, 0.0, 0.0], "fov_deg": 360, "beams": 1440})
    lidar.update(range_max=20.0, range_min=0.05, range_noise_std=0.01, rate_hz=10)
    layout = Layout((_r(x0), _r(y0), _r(x1), _r(y1)), tuple(racks), tuple(lanes),
                    tuple(strips), _r(x0 + cross_w / 2), _r(x1 - cross_e / 2), lidar)
    return replace(layout, static=layout.static + tuple(_pillars(rng, layout)))


def _pillars(rng, layout: Layout) -> list:
    x0, y0, x1, y1 = layout.bounds
    n = max(2, int((x1 - x0) * (y1 - y0) // 120))
    out: list = []
    for _ in range(TRIES):
        if len(out) == n:
            break
        c = (_r(rng.uniform(x0 + 0.3, x1 - 0.3)), _r(rng.uniform(y0 + 0.3, y1 - 0.3)))
        p = sim.Obstacle(f"pillar_{len(out) + 1}", c, size=(0.4, 0.4), kind="pillar")
        if _fits(p, layout, list(layout.static) + out):
            out.append(p)
    return out


# --- where an object may stand ---------------------------------------------------------------
def _fits(o, layout: Layout, others) -> bool:
    """Inside the walls, clear of every other object by OBJECT_GAP and of every lane by the
    robot's radius plus LANE_CLEARANCE."""
    grown = replace(o, radius=o.radius + OBJECT_GAP / 2) if o.is_circle else \
        replace(o, size=(o.size[0] + OBJECT_GAP, o.size[1] + OBJECT_GAP))
    inside = geo.circle_inside(grown.circle(), layout.bounds) if o.is_circle else \
        geo.box_inside(grown.box(), layout.bounds)
    if not inside:
        return False
    clear = ROBOT_RADIUS + LANE_CLEARANCE
    for a, b in layout.lane_segments():
        a, b = np.asarray(a, float), np.asarray(b, float)
        d = geo.segment_circle_distance(a, b, o.circle()[None]) if o.is_circle else \
            geo.segment_box_distance(a, b, o.box()[None])
        if float(d[0]) < clear:
            return False

    return not any(objects_overlap(grown, q) for q in others if q.id != o.id)


def _new_object(rng, oid_kind: tuple[str, str], area) -> sim.Obstacle:
    """An object of ``kind`` (pallet, drum, box) with its centre drawn in ``area``
    (x_lo, y_lo, x_hi, y_hi)."""
    oid, kind = oid_kind
    c = (_r(rng.uniform(area[0], area[2])), _r(rng.uniform(area[1], area[3])))
    if kind == "drum":
        return sim.Obstacle(oid, c, radius=0.3, kind=kind, movable=True)
    size = (1.2, 0.8) if kind == "pallet" else (_r(rng.uniform(0.5, 0.8)),) * 2
    yaw = float(rng.choice([0.0, 1.5708]))
    return sim.Obstacle(oid, c, size=size, yaw=yaw, kind=kind, movable=True)


def _place(rng, oid_kind, layout: Layout, others, area, accept=None):
    """A valid object drawn in ``area`` (and accepted by ``accept(o)``), or None."""
    for _ in range(TRIES):
        o = _new_object(rng, oid_kind, area)
        if _fits(o, layout, others) and (accept is None or accept(o)):
            return o
    return None


# --- routes ----------------------------------------------------------------------------------
def _serpentine(layout: Layout, lanes, from_west: bool = True) -> list[tuple[float, float]]:
    """Waypoints from the dock through each lane of ``lanes`` in turn, alternating sides, and
    back to the dock (the start is not repeated at the front)."""
    xw, xe, dock = layout.x_west, layout.x_east, layout.lanes_y[0]
    pts, west = [], from_west
    for y in lanes:
        here, other = (xw, xe) if west else (xe, xw)
        pts += [(here, y), (other, y)]
        west = not west
    pts.append((xw if west else xe, dock))
    if not west:
        pts.append((xw, dock))
    return pts


def mapping_route(layout: Layout) -> list[tuple[float, float]]:
    """W1: along the dock, then up the building through every lane."""
    return [(layout.x_east, layout.lanes_y[0])] + _serpentine(layout, layout.lanes_y[1:],
                                                              from_west=False)


def _transport(rng, layout: Layout):
    """(route, quick route) of an update session: a loop through 1-3 aisles, and an
    out-and-back into the first of them."""
    aisles = list(layout.lanes_y[1:])
    n = int(rng.integers(1, min(3, len(aisles)) + 1))
    chosen = sorted(float(y) for y in rng.choice(aisles, size=n, replace=False))
    y, xw = chosen[0], layout.x_west
    far = _r(min(xw + QUICK_DEPTH, layout.x_east))
    quick = [(xw, y), (far, y), (xw, y), layout.start]
    return _serpentine(layout, chosen), quick


def route_poses(start, route) -> np.ndarray:
    """Robot poses (N, 3) every ROUTE_STEP metres along the route, facing along each leg."""
    pts = np.vstack([start, np.asarray(route, float)])
    out = []
    for a, b in zip(pts[:-1], pts[1:]):
        length = float(np.hypot(*(b - a)))
        yaw = math.atan2(b[1] - a[1], b[0] - a[0])
        for s in np.arange(0.0, length, ROUTE_STEP):
            p = a + (b - a) * s / max(length, 1e-9)
            out.append((p[0], p[1], yaw))
    return np.array(out).reshape(-1, 3)


def lidar_hits(layout: Layout, objects, poses: np.ndarray) -> np.ndarray:
    """Hit points (N, beams, 2) of noise-free scans from robot ``poses`` (N, 3) among
    ``objects`` (the world as it stands, no people); far away where a beam has no hit within
    SEEN_RANGE."""
    spec = _lidar_spec(layout)
    boxes, circles = geo.obstacle_arrays(objects, layout.bounds, 0.13)
    sensors = lid.sensor_poses(poses, spec.mount)
    ranges = lid.cast_ranges(sensors, spec, geo.box_segments(boxes), circles)
    ranges[~(ranges <= SEEN_RANGE)] = 1e6
    a = sensors[:, 2:3] + spec.angle_min + spec.angle_increment * np.arange(spec.beams)
    return np.stack([sensors[:, 0:1] + ranges * np.cos(a),
                     sensors[:, 1:2] + ranges * np.sin(a)], axis=-1)


def seen_in(hits: np.ndarray, target) -> bool:
    """Whether the scans of ``hits`` (from ``lidar_hits``) see ``target`` as the evaluation
    needs: at least SEEN_CELLS cells of its outline (5 cm) hit from SEEN_POSES scans or more."""
    reach = target.radius if target.is_circle else math.hypot(*target.size) / 2
    cx, cy = target.center
    # only the hits near the object need the exact distance
    pose, beam = np.nonzero((np.abs(hits[..., 0] - cx) < reach + 0.05)
                            & (np.abs(hits[..., 1] - cy) < reach + 0.05))
    pts = hits[pose, beam]
    d = geo.point_circle_distance(pts, target.circle()[None]) if target.is_circle else \
        geo.point_box_distance(pts, target.box()[None])
    on = np.abs(d[:, 0]) < 0.03
    cells = np.floor(pts[on] / 0.05).astype(np.int64)
    seen = np.unique(np.column_stack([pose[on], cells]), axis=0)   # (scan, cell) once each
    _, per_cell = np.unique(seen[:, 1:], axis=0, return_counts=True)
    return int((per_cell >= SEEN_POSES).sum()) >= SEEN_CELLS


def _lidar_spec(layout: Layout):
    ld = layout.lidar
    return sim.LidarSpec(mount=Pose2D(*ld["mount"]), fov_deg=ld["fov_deg"], beams=ld["beams"],
                         range_min=ld["range_min"], range_max=ld["range_max"])


# --- sessions --------------------------------------------------------------------------------
@dataclass
class _Session:
    """What the rearrangements of one session are checked against."""

    layout: Layout
    movable: dict            # id -> sim.Obstacle, as the world stands now
    views: tuple             # pose arrays of the route and of the quick route
    area: tuple              # (x_lo, y_lo, x_hi, y_hi) where new places are drawn
    touched: set = field(default_factory=set)   # ids this session changed already
    places: list = field(default_factory=list)  # (object, stands there now) of each change

    def objects(self, without: str | None = None, extra=None) -> list:
        objs = [o for o in self.movable.values() if o.id != without]
        return list(self.layout.static) + objs + ([extra] if extra is not None else [])

    def keeps_in_view(self, objects, new_places) -> bool:
        """Whether, with ``objects`` standing, both routes see every place this session changed
        (``places`` and ``new_places``): an object standing there, or the place an object left
        (as if it stood there still: the beams reach it), so no change hides another."""
        places = self.places + new_places
        for view in self.views:
            view = _near(view, [o for o, _ in places])
            hits = lidar_hits(self.layout, objects, view)
            for o, present in places:
                h = hits if present else lidar_hits(self.layout, objects + [o], view)
                if not seen_in(h, o):
                    return False
        return True

    def vacated(self) -> list:
        """The places objects left this session: nothing new may stand there, or the session
        would not show them free."""
        return [o for o, present in self.places if not present]

    def commit(self, new_places) -> None:
        self.places += new_places
        self.touched.update(o.id for o, _ in new_places)

    def seen_now(self) -> list[str]:
        """The movable objects both routes see as the world stands."""
        x0, y0, x1, y1 = self.area
        # objects beyond where the quick route looks are not seen from it: skip the casts
        near = [o for o in self.movable.values()
                if x0 - 1 <= o.center[0] <= x1 + 1 and y0 - 1 <= o.center[1] <= y1 + 1]
        if not near:
            return []
        hits = [lidar_hits(self.layout, self.objects(), _near(p, near)) for p in self.views]
        return [o.id for o in near if o.id not in self.touched
                and all(seen_in(h, o) for h in hits)]


def _near(poses: np.ndarray, objects) -> np.ndarray:
    """The poses within SEEN_RANGE of any of ``objects``: the others cannot see them."""
    keep = np.zeros(len(poses), bool)
    for o in objects:
        keep |= np.hypot(poses[:, 0] - o.center[0], poses[:, 1] - o.center[1]) < SEEN_RANGE + 1
    return poses[keep]


def _view_area(layout: Layout, quick) -> tuple:
    """Where the quick route looks: from the west wall to past its far end, from the south
    wall to past its aisle."""
    x0, y0, x1, y1 = layout.bounds
    far, y = quick[1]
    return (x0, y0, min(x1, far + 3.0), min(y1, y + 2.5))


def _move(rng, s: _Session, oid: str) -> dict | None:
    old = s.movable[oid]
    for _ in range(TRIES):
        a = s.area
        x, y = _r(rng.uniform(a[0], a[2])), _r(rng.uniform(a[1], a[3]))
        yaw = 0.0 if old.is_circle else float(rng.choice([0.0, 1.5708]))
        new = old.moved(x, y, yaw)
        if math.dist(old.center, new.center) < 1.0 or not _fits(new, s.layout,
                                                                   s.objects(oid) + s.vacated()):
            continue
        if s.keeps_in_view(s.objects(oid, new), [(old, False), (new, True)]):
            s.movable[oid] = new
            s.commit([(old, False), (new, True)])
            return {"move": oid, "to": [x, y] if old.is_circle else [x, y, yaw]}
    return None


def _add(rng, s: _Session, counters: dict) -> dict | None:
    kind = str(rng.choice(["pallet", "pallet", "drum", "box"]))
    oid = f"{kind}_{counters[kind] + 1}"
    o = _place(rng, (oid, kind), s.layout, s.objects() + s.vacated(), s.area,
               accept=lambda o: s.keeps_in_view(s.objects(extra=o), [(o, True)]))
    if o is None:
        return None
    counters[kind] += 1
    s.movable[oid] = o
    s.commit([(o, True)])
    return {"add": _object_dict(o)}


def _changes(rng, s: _Session, counters: dict) -> list[dict]:
    """2-6 moves, additions and removals, each of an object (or place) the session sees."""
    out = []
    wanted = int(rng.integers(2, 7))
    for _ in range(3 * wanted):         # a change that finds no place is drawn again
        if len(out) == wanted:
            break
        kind = str(rng.choice(["move", "add", "remove"]))
        seen = s.seen_now()
        change = None
        if kind != "add" and seen:
            oid = str(rng.choice(seen))
            gone = s.movable[oid]
            if kind == "remove" and s.keeps_in_view(s.objects(oid), [(gone, False)]):
                del s.movable[oid]
                s.commit([(gone, False)])
                change = {"remove": oid}
            elif kind == "move":
                change = _move(rng, s, oid)
        if change is None:
            change = _add(rng, s, counters)
        if change is not None:
            out.append(change)
    return out


def _people(rng, layout: Layout) -> list[dict]:
    """Walkers along the lanes (a little off their centre line) and in the dock strip."""
    x0, y0, x1, y1 = layout.bounds
    n = int(rng.integers(1, min(6, 3 + int((x1 - x0) * (y1 - y0) // 400)) + 1))
    out = []
    for _ in range(n):
        speed = _r(rng.uniform(0.8, 1.3))
        if rng.random() < 0.6:
            y = _r(float(rng.choice(layout.lanes_y[1:])) + float(rng.choice([-0.3, 0.3])))
            xa = _r(rng.uniform(layout.x_west, layout.x_east - 5.0))
            xb = _r(rng.uniform(xa + 4.0, layout.x_east))
            out.append({"route": [[xa, y], [xb, y]], "loop": False, "speed": speed})
        else:
            top = layout.strips[0][1] - 0.3
            out.append({"wander": [_r(x0 + 0.5), _r(y0 + 0.5), _r(x1 - 0.5), _r(top)],
                        "count": 1, "speed": speed})
    return out


# --- the scenario ----------------------------------------------------------------------------
def _object_dict(o) -> dict:
    d = {"id": o.id, "center": [o.center[0], o.center[1]]}
    if o.is_circle:
        d["radius"] = o.radius
    else:
        d["size"] = [o.size[0], o.size[1]]
        d["yaw"] = o.yaw
    d["kind"] = o.kind
    return d


def _initial_objects(rng, layout: Layout, counters: dict) -> dict:
    """Movable objects beside the lanes, about one per 25 m^2 of floor."""
    x0, y0, x1, y1 = layout.bounds
    n = max(4, int((x1 - x0) * (y1 - y0) // 25))
    movable: dict = {}
    for _ in range(n):
        kind = str(rng.choice(["pallet", "pallet", "drum", "box"]))
        oid = f"{kind}_{counters[kind] + 1}"
        o = _place(rng, (oid, kind), layout, list(layout.static) + list(movable.values()),
                   layout.bounds)
        if o is not None:
            counters[kind] += 1
            movable[oid] = o
    return movable


def generate(seed: int, size=(30.0, 20.0), sessions: int = 4, fov: int = 270) -> dict:
    """The YAML tree of a generated warehouse scenario (see the module docstring); the same
    arguments give the same tree. Raises ``GenerateError`` for arguments out of range."""
    w, h = check_arguments(size, sessions, fov)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise GenerateError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(np.random.SeedSequence([seed, round(w * 1000), round(h * 1000),
                                                        sessions, fov]))
    layout = _layout(rng, w, h, fov)
    counters = {"pallet": 0, "drum": 0, "box": 0}
    movable = _initial_objects(rng, layout, counters)
    initial = [_object_dict(o) for o in movable.values()]
    tree_sessions = [{"name": "W1", "mapping": True, "route": _points(mapping_route(layout))}]
    for i in range(1, sessions):
        route, quick = _transport(rng, layout)
        # the quick route first: it is the shorter, so a place it misses is given up sooner
        views = tuple(route_poses(layout.start, r) for r in (quick, route))
        state = _Session(layout, movable, views, _view_area(layout, quick))
        entry = {"name": f"W{i + 1}", "changes": _changes(rng, state, counters),
                 "people": _people(rng, layout)}
        tree_sessions.append({**entry, "quick_route": _points(quick), "route": _points(route)})
    name = f"generated_{seed}_{w:g}x{h:g}" + ("_360" if fov == 360 else "")
    tree = {"name": name, "seed": int(seed), "resolution": 0.05, "physics_hz": 20,
            "world": {"bounds": list(layout.bounds), "wall_thickness": 0.13,
                      "static": [_object_dict(o) for o in layout.static], "movable": initial},
            "robot": {"start": [layout.start[0], layout.start[1], 0.0], "radius": ROBOT_RADIUS,
                      "max_speed": 0.6, "max_turn_rate": 1.0, "max_accel": 0.5,
                      "odometry_noise": [0.05, 0.01, 0.05, 0.01], "odometry_rate_hz": 20,
                      "lidars": [dict(layout.lidar)]},
            "sessions": tree_sessions}
    sim.scenario_from_dict(tree, name)      # the scenario checks, as for any file
    return tree


def _points(route) -> list[list[float]]:
    return [[_r(x), _r(y)] for x, y in route]


def scenario_yaml(tree: dict, header: str = "") -> str:
    """The scenario file's text: mappings as blocks, each object, change, person, lidar and
    route point on a line of its own (flow style)."""
    out = [f"# {header}"] if header else []
    for key, value in tree.items():
        if key != "sessions":
            _emit(key, value, 0, out)
    out.append("sessions:")
    for s in tree["sessions"]:
        first, *rest = s.items()
        out.append(f"  - {first[0]}: {_flow(first[1])}")
        for key, value in rest:
            _emit(key, value, 4, out)
    return "\n".join(out) + "\n"


def _emit(key: str, value, indent: int, out: list[str]) -> None:
    pad = " " * indent
    if isinstance(value, dict):
        out.append(f"{pad}{key}:")
        for k, v in value.items():
            _emit(k, v, indent + 2, out)
    elif isinstance(value, list) and value and isinstance(value[0], (dict, list)):
        out.append(f"{pad}{key}:")
        out += [f"{pad}  - {_flow(item)}" for item in value]
    else:
        out.append(f"{pad}{key}: {_flow(value)}")


def _flow(value) -> str:
    # a one-item list keeps yaml from adding its document end marker to a plain scalar
    return yaml.safe_dump([value], default_flow_style=True, sort_keys=False,
                          width=10**6).strip()[1:-1]


def write_generated(seed: int, out, size=(30.0, 20.0), sessions: int = 4,
                    fov: int = 270) -> Path:
    """Write ``generate(seed, ...)`` to ``out`` (atomically) and return the path."""
    tree = generate(seed, size, sessions, fov)
    w, h = check_arguments(size, sessions, fov)
    header = (f"generated by: mapupdate generate --seed {seed} --size {w:g} {h:g} "
              f"--sessions {sessions} --fov {fov}")
    out = Path(out)
    if out.parent != Path(""):
        out.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(out, scenario_yaml(tree, header))
    return out
