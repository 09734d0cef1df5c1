"""A picture of a session's world: walls, objects, people, robot and route, to a PNG.

What the session changed is marked: moved objects are drawn where they went with their old place
dashed, added objects in green, removed ones as a dashed red outline. The command line entry is
``mapupdate render``. (A picture of the map a robot holds, drawn every step of the gym
environment, is ``scenarios.topview``: another job, the map's cells rather than the world's
geometry.)
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gridmap.atomic import write_with

from . import geometry as geo
from .world import World

COLORS = {"wall": "#555555", "static": "#7f7f7f", "movable": "#c8a165", "pallet": "#d9b44a",
          "added": "#4caf50", "removed": "#d62728", "person": "#e4572e", "robot": "#1f77b4"}


def _outline(ob) -> np.ndarray:
    if ob.is_circle:
        a = np.linspace(0, 2 * math.pi, 33)
        return np.column_stack([ob.center[0] + ob.radius * np.cos(a),
                                ob.center[1] + ob.radius * np.sin(a)])
    return geo.box_corners(ob.box()[None])[0]


def _area(ob) -> float:
    return math.pi * ob.radius ** 2 if ob.is_circle else ob.size[0] * ob.size[1]


def _changes(scenario, index: int):
    """Objects added, moved (new, old) and removed by the session ``index``."""
    now = {o.id: o for o in scenario.obstacles(index)}
    before = {o.id: o for o in scenario.obstacles(index - 1)} if index > 0 else \
        {o.id: o for o in scenario.world.static + scenario.world.movable}
    added = [o for k, o in now.items() if k not in before]
    removed = [o for k, o in before.items() if k not in now]
    moved = [(now[k], before[k]) for k in now if k in before and now[k] != before[k]]
    return added, moved, removed


def render_world(scenario, session, path_png, *, seed=None, time: float = 0.0,
                 show_ids: bool = True, dpi: int = 110) -> Path:
    """Draw the world of ``session`` (index or name) at ``time`` [s] of its run to ``path_png``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    world = _world_at(scenario, session, seed, time)
    changes = _changes(scenario, world.index)
    x0, y0, x1, y1 = scenario.world.bounds
    w = (x1 - x0) + 2
    h = (y1 - y0) + 2
    fig = Figure(figsize=(min(14, 0.5 * w + 2), min(18, 0.5 * h + 1)), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    _draw_objects(ax, scenario, world, changes, show_ids)
    _draw_people(ax, world)
    length = _draw_robot(ax, scenario, world)
    added, moved, removed = changes
    ax.set_title(f"{scenario.name} / {world.session.name}: {len(world.obstacles)} objects, "
                 f"{len(world.people())} people, route {length:.0f} m "
                 f"(+{len(added)} added, {len(moved)} moved, -{len(removed)} removed)",
                 fontsize=8)
    _set_axes(ax, scenario.world.bounds)
    fig.tight_layout()
    path = Path(path_png)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_with(path, lambda f: fig.savefig(f, format=path.suffix.lstrip(".") or "png"))
    return path


def _world_at(scenario, session, seed, time: float):
    """The session's world, run up to ``time`` [s]."""
    world = World(scenario, session, seed)
    if time > 0:
        for msg in world.run():
            if msg.time >= time:
                break
    return world


def _draw_objects(ax, scenario, world, changes, show_ids: bool) -> None:
    """Walls and objects; changed objects with a heavy edge, moved ones' old places dashed,
    removed ones as a dashed red outline."""
    from matplotlib.patches import Polygon

    added, moved, removed = changes
    changed = {o.id for o in added} | {o.id for o, _ in moved}
    for b in geo.wall_boxes(scenario.world.bounds, scenario.world.wall_thickness):
        ax.add_patch(Polygon(geo.box_corners(b[None])[0], color=COLORS["wall"]))
    for ob in world.obstacles:
        if ob in added:
            color = COLORS["added"]
        else:
            color = COLORS["pallet"] if ob.kind == "pallet" else \
                COLORS["movable"] if ob.movable else COLORS["static"]
        lw = 2.0 if ob.id in changed else 0.5
        ax.add_patch(Polygon(_outline(ob), facecolor=color, edgecolor="black", lw=lw, alpha=0.9))
        if show_ids and _area(ob) > 0.1:     # no labels on legs and posts
            ax.text(ob.center[0], ob.center[1], ob.id, fontsize=5, ha="center", va="center")
    for _, old in moved:
        ax.add_patch(Polygon(_outline(old), fill=False, edgecolor="black", ls="--", lw=1.0))
    for ob in removed:
        ax.add_patch(Polygon(_outline(ob), fill=False, edgecolor=COLORS["removed"], ls="--",
                             lw=1.2))


def _draw_people(ax, world) -> None:
    """The people's routes (dotted) or wander rectangles, and where they are."""
    from matplotlib.patches import Circle, Rectangle

    for spec in world.session.people:
        if spec.route is not None:
            r = np.asarray(spec.route + ((spec.route[0],) if spec.loop else ()))
            ax.plot(r[:, 0], r[:, 1], ":", color=COLORS["person"], lw=1)
        else:
            a, b, c, d = spec.wander
            ax.add_patch(Rectangle((a, b), c - a, d - b, fill=False, ls=":",
                                   edgecolor=COLORS["person"], lw=1))
    for x, y, r in world.people():
        ax.add_patch(Circle((x, y), r, color=COLORS["person"]))


def _draw_robot(ax, scenario, world) -> float:
    """The robot's route with arrows along it and the robot where it is; returns the route's
    length [m]."""
    from matplotlib.patches import Circle

    route = world.follower.waypoints
    ax.plot(route[:, 0], route[:, 1], "-", color=COLORS["robot"], lw=1.2, alpha=0.7)
    for a, b in zip(route[:-1], route[1:]):
        m = (a + b) / 2
        d = (b - a) / max(np.linalg.norm(b - a), 1e-9) * 0.3
        ax.annotate("", xy=m + d, xytext=m, arrowprops={"arrowstyle": "->",
                                                           "color": COLORS["robot"]})
    p = world.true_pose
    ax.add_patch(Circle((p.x, p.y), scenario.robot.radius, fill=False, edgecolor=COLORS["robot"],
                        lw=2))
    ax.plot([p.x, p.x + 0.5 * math.cos(p.theta)], [p.y, p.y + 0.5 * math.sin(p.theta)],
            color=COLORS["robot"], lw=2)
    return float(np.hypot(*np.diff(route, axis=0).T).sum())


def _set_axes(ax, bounds) -> None:
    """The walls with a metre around them, a grid every metre, labels in metres."""
    x0, y0, x1, y1 = bounds
    ax.set_xlim(x0 - 1, x1 + 1)
    ax.set_ylim(y0 - 1, y1 + 1)
    ax.set_aspect("equal")
    ax.set_xticks(np.arange(math.floor(x0), math.ceil(x1) + 1))
    ax.set_yticks(np.arange(math.floor(y0), math.ceil(y1) + 1))
    ax.tick_params(labelsize=6)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_xlabel("x [m]", fontsize=7)
    ax.set_ylabel("y [m]", fontsize=7)
