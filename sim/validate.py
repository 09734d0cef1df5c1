"""Checks on a scenario's geometry, session by session, with errors that name the object.

Every session's world must have: unique object ids, changes that refer to movable objects that
exist at that point, every object inside the walls, no two objects sharing area, a robot start
clear of objects, and robot and people routes whose waypoints keep the walker's disc inside the
walls and whose legs keep it clear of every object (a waypoint inside an object is reported as
such).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from gridmap.map_io import MAX_CELLS
from gridmap.suggest import did_you_mean

from . import geometry as geo

MAX_SESSION_S = 86400.0       # [s] no session may take longer to simulate (a day)

Fail = Callable[[str, str], None]


def check_scenario(scn, fail: Fail) -> None:
    """Raise through ``fail(key, message)`` at the first problem found."""
    keys: dict[str, str] = {}
    for group, objs in (("static", scn.world.static), ("movable", scn.world.movable)):
        for j, o in enumerate(objs):
            key = f"world.{group}[{j}]"
            if o.id in keys:
                fail(key, f"object id {o.id!r} is already used by {keys[o.id]}")
            keys[o.id] = key
    static_ids = {o.id for o in scn.world.static}
    movable = {o.id: o for o in scn.world.movable}
    _check_objects(scn, list(scn.world.static) + list(movable.values()), keys, fail, "world")
    _check_start(scn, list(scn.world.static) + list(movable.values()), keys, fail)
    _check_size(scn, fail)
    names = set()
    for i, s in enumerate(scn.sessions):
        skey = f"sessions[{i}]"
        _check_duration(scn, s, skey, fail)
        if s.name in names:
            fail(f"{skey}.name", f"session name {s.name!r} is used twice")
        names.add(s.name)
        for k, ch in enumerate(s.changes):
            ckey = f"{skey}.changes[{k}]"
            _apply_change(ch, ckey, movable, static_ids, keys, fail)
        objs = list(scn.world.static) + list(movable.values())
        if s.changes:
            _check_objects(scn, objs, keys, fail, f"session {s.name!r}")
            _check_start(scn, objs, keys, fail, s.name)
        for rkey, route in (("route", s.route), ("quick_route", s.quick_route)):
            if route is not None:
                _check_path(scn.robot.radius, _robot_path(scn, route), objs, f"{skey}.{rkey}",
                            f"the robot (radius {scn.robot.radius} m)", fail, skip_first=True,
                            bounds=scn.world.bounds)
        for p, person in enumerate(s.people):
            pkey = f"{skey}.people[{p}]"
            if person.route is not None:
                _check_path(person.radius, list(person.route), objs, f"{pkey}.route",
                            f"a person (radius {person.radius} m)", fail, closed=person.loop,
                            bounds=scn.world.bounds)
            else:
                x0, y0, x1, y1 = person.wander
                b = scn.world.bounds
                if x0 < b[0] or y0 < b[1] or x1 > b[2] or y1 > b[3]:
                    fail(f"{pkey}.wander", f"rectangle {list(person.wander)} reaches outside the "
                                           f"walls {list(b)}")


def _check_size(scn, fail: Fail) -> None:
    """The session grids (maps, truth, buffers) must fit: at most ``MAX_CELLS`` cells."""
    x0, y0, x1, y1 = scn.world.bounds
    pad = 2 * (scn.world.wall_thickness + 0.1)
    cells = math.ceil((x1 - x0 + pad) / scn.resolution) * \
        math.ceil((y1 - y0 + pad) / scn.resolution)
    if cells > MAX_CELLS:
        fail("world.bounds", f"{x1 - x0:g} x {y1 - y0:g} m at {scn.resolution:g} m cells make "
                             f"{cells} cells, more than the {MAX_CELLS} a map can have")


def _check_duration(scn, session, key: str, fail: Fail) -> None:
    """A session must end within ``MAX_SESSION_S`` of simulated time: its ``max_duration``, or
    the time the world gives it to drive its route (``World._default_duration``)."""
    if session.max_duration is not None:
        return                                  # bounded where it was read
    start = (scn.robot.start.x, scn.robot.start.y)
    pts = [start, *session.route]
    length = sum(math.dist(a, b) for a, b in zip(pts, pts[1:]))
    seconds = 3.0 * length / scn.robot.max_speed + 10.0 * len(pts) + 60.0
    if seconds > MAX_SESSION_S:
        fail(f"{key}.route", f"{length:.0f} m at {scn.robot.max_speed:g} m/s would take "
                             f"{seconds / 86400:.1f} simulated days; at most one is allowed")


def _apply_change(ch, key, movable, static_ids, keys, fail: Fail) -> None:
    if ch.kind == "add":
        if ch.id in movable or ch.id in static_ids:
            fail(f"{key}.add.id", f"object {ch.id!r} already exists ({keys.get(ch.id, '')})")
        movable[ch.id] = ch.obstacle
        keys[ch.id] = f"{key}.add"
        return
    if ch.id in static_ids:
        fail(f"{key}.{ch.kind}", f"object {ch.id!r} is static and never moves")
    if ch.id not in movable:
        fail(f"{key}.{ch.kind}", f"no movable object {ch.id!r} in the world at this point"
                                 f"{did_you_mean(ch.id, movable)}")
    if ch.kind == "remove":
        del movable[ch.id]
    else:
        x, y, yaw = ch.to
        o = movable[ch.id]
        movable[ch.id] = o.moved(x, y, o.yaw if math.isnan(yaw) else yaw)
        keys[ch.id] = f"{key} (move of {ch.id!r})"


def _check_objects(scn, objs, keys, fail: Fail, where: str) -> None:
    bounds = scn.world.bounds
    for o in objs:
        inside = geo.circle_inside(o.circle(), bounds) if o.is_circle else \
            geo.box_inside(o.box(), bounds)
        if not inside:
            fail(keys[o.id], f"object {o.id!r} is outside the walls {list(bounds)} in {where}")
    ext = np.array([_extent(o) for o in objs]).reshape(-1, 4)
    for a in range(len(objs)):
        # only pairs whose axis-aligned bounds meet need the exact test
        near = np.nonzero((ext[a + 1:, 0] < ext[a, 2]) & (ext[a + 1:, 2] > ext[a, 0])
                          & (ext[a + 1:, 1] < ext[a, 3]) & (ext[a + 1:, 3] > ext[a, 1]))[0]
        for b in near + a + 1:
            if objects_overlap(objs[a], objs[b]):
                fail(keys[objs[b].id], f"object {objs[b].id!r} overlaps object {objs[a].id!r} "
                                       f"in {where}")


def _check_start(scn, objs, keys, fail: Fail, session: str | None = None) -> None:
    st = scn.robot.start
    b = scn.world.bounds
    r = scn.robot.radius
    if not (b[0] + r <= st.x <= b[2] - r and b[1] + r <= st.y <= b[3] - r):
        fail("robot.start", f"the robot at {st.x, st.y} does not fit inside the walls {list(b)}")
    for o in objs:
        if _distance_to(o, (st.x, st.y)) < r - geo.TOUCH_TOL:
            where = f" in session {session!r}" if session else ""
            fail("robot.start", f"the robot (radius {r} m) at its start {st.x, st.y} overlaps "
                                f"object {o.id!r}{where}")


def _robot_path(scn, route) -> list[tuple[float, float]]:
    return [(scn.robot.start.x, scn.robot.start.y)] + list(route)


def _check_path(radius, pts, objs, key, who, fail: Fail, skip_first: bool = False,
                closed: bool = False, bounds=None) -> None:
    """Each waypoint outside every object and each leg at least ``radius`` from every object.
    With ``bounds`` each waypoint also keeps ``radius`` from the walls (the building is a
    rectangle, so its legs then do too): a route the walker cannot reach is refused.
    With ``skip_first`` the first point is the robot's start (checked apart) and waypoint
    numbers count from the next one; ``closed`` adds the leg from the last point to the first."""
    first = 1 if skip_first else 0
    for j in range(first, len(pts)):
        wkey = f"{key}[{j - first}]"
        if bounds is not None:
            x, y = pts[j]
            if not (bounds[0] + radius - geo.TOUCH_TOL <= x <= bounds[2] - radius + geo.TOUCH_TOL
                    and bounds[1] + radius - geo.TOUCH_TOL <= y
                    <= bounds[3] - radius + geo.TOUCH_TOL):
                fail(wkey, f"waypoint {list(pts[j])}: {who} does not fit inside the walls "
                           f"{list(bounds)} there")
        for o in objs:
            d = _distance_to(o, pts[j])
            if d < 0:
                fail(wkey, f"waypoint {list(pts[j])} is inside object {o.id!r}")
            if d < radius - geo.TOUCH_TOL:
                fail(wkey, f"at waypoint {list(pts[j])} {who} would overlap object {o.id!r}")
    legs = [(j - 1, j) for j in range(1, len(pts))] + ([(len(pts) - 1, 0)] if closed else [])
    for i, j in legs:
        a, b = np.asarray(pts[i], float), np.asarray(pts[j], float)
        for o in objs:
            d = geo.segment_circle_distance(a, b, o.circle())[0] if o.is_circle else \
                geo.segment_box_distance(a, b, o.box())[0]
            if d < radius - geo.TOUCH_TOL:
                fail(f"{key}[{max(i, j) - first}]",
                     f"the leg {list(pts[i])} -> {list(pts[j])}: {who} would run into "
                     f"object {o.id!r}")


def _distance_to(o, p) -> float:
    if o.is_circle:
        return float(geo.point_circle_distance(np.asarray(p)[None], o.circle()[None])[0, 0])
    return float(geo.point_box_distance(np.asarray(p)[None], o.box()[None])[0, 0])


def _extent(o) -> np.ndarray:
    if o.is_circle:
        x, y, r = o.circle()
        return np.array([x - r, y - r, x + r, y + r])
    return geo.box_extent(o.box()[None])[0]


def objects_overlap(a, b) -> bool:
    """Whether two scenario objects (boxes or circles) share area."""
    if a.is_circle and b.is_circle:
        return geo.circles_overlap(a.circle(), b.circle())
    if a.is_circle or b.is_circle:
        c, box = (a, b) if a.is_circle else (b, a)
        return geo.box_circle_overlap(box.box(), c.circle())
    return geo.boxes_overlap(a.box(), b.box())
