"""Benchmark: what a wrong pose does to the map, with and without the pose check.

The built-in warehouse: M1 is built by the runner's W1 mapping; session W2 (its changes and
people) is simulated once and its scans are fed to a fresh updater on M1 at the true robot pose
plus an injected error, with the simulator's odometry for gating, as the runner does. Errors:

- persistent offsets: 0.05 to 1.0 m of position (four directions: +x, +y, -x, -y) and 0.5 to 20
  deg of heading (both signs), and 0.15 m with 3 deg together (four directions, both signs);
- a kidnapping: correct poses until mid-session, then the robot is carried 2 m aside and turned
  by 30 deg while the pose keeps following odometry from where it was (est = E (+) true, E a
  fixed rigid motion of the map frame).

Per error level, summed over its variants: G-occupied cells freed (cells occupied in G2, a wall
or an object's outline, that the updater made free), how many of them belong to the building's
structure (walls and static objects: racks, shelves), holes (those of them with no occupied cell
of the output within one cell: the outline is broken there), incorrect changes (docs/evaluation.md,
one cell of slack), and scans dropped by the lost check or refused by the pose check. The
"guarded" columns use the safeguard, ``localization.confidence.PoseCheck`` with its defaults
(without a localiser here, only its scan-fit part, not its covariance part): it refuses a scan
when a pose of a small grid around the one given fits the scan to M1 clearly better.

    python benchmarks/bench_mislocalisation.py [--quick] [--session W2] [--json PATH]

``python benchmarks/run.py --baseline REV mislocalisation`` runs it on a git revision's packages
and on the working tree's, and says whether the two tables are the same (``--json``: the
wall time and the digest of the table's counts).

Bars (exit 1 when missed), with the pose check: no G-occupied cell freed from 0.1 m or 1 deg of
error on, nor after the kidnapping; no hole at any level. Below that (0.05 m, 0.5 deg: under a
cell, which the pose check cannot tell) the updater's seen-surface guard
(``UpdaterConfig.seen_surface_radius``, in the plain columns too) keeps all but 0-2 cells.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# the packages measured: this checkout's, or a revision's (run.py --baseline)
sys.path.insert(0, os.environ.get("BENCH_CODE_ROOT") or str(Path(__file__).resolve().parents[1]))

from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D  # noqa: E402

DIRECTIONS = (0, 90, 180, 270)          # [deg] of the position offsets, map frame
OFFSETS = (0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 1.0)          # [m]
TURNS = (0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 20.0)            # [deg]
KIDNAP = (2.0, 0.0, 30.0)               # [m, m, deg]: where the robot is carried at mid-session
PROTECTED = (0.15, 3.0)                 # [m, deg]: the combined error of the table


@dataclass
class Recording:
    """One simulated session: the map the updater starts from, the truth, and the scans with
    the true and odometry poses of the robot."""

    reference: OccupancyGrid           # M1
    truth: OccupancyGrid               # G of the session
    structure: np.ndarray              # (H, W) bool: cells of G occupied by walls and static
    #                                    objects (racks, shelves), which never move
    mount: Pose2D                      # the lidar on the robot
    scans: list = field(default_factory=list)     # Scan
    true: np.ndarray | None = None     # (N, 3) robot poses, map frame
    odom: np.ndarray | None = None     # (N, 3) robot poses, odometry frame


@dataclass(frozen=True)
class Error:
    """An injected pose error: est = (x + dx, y + dy, theta + dtheta) from ``start`` (a
    fraction of the session) on; ``rigid`` applies it as a rigid motion of the map frame
    about the robot's position at ``start`` instead (a kidnapping)."""

    level: str
    dx: float = 0.0
    dy: float = 0.0
    dtheta: float = 0.0                # [rad]
    start: float = 0.0
    rigid: bool = False


@dataclass
class Damage:
    freed: int = 0                     # G-occupied cells made free
    structure: int = 0                 # ... of walls and static objects
    holes: int = 0                     # ... with no occupied output cell within one cell
    incorrect: int = 0                 # incorrect changes (one cell of slack)
    changes: int = 0
    processed: int = 0
    lost: int = 0
    unsure: int = 0                    # refused by the pose check

    def add(self, other: Damage) -> None:
        for k in vars(self):
            setattr(self, k, getattr(self, k) + getattr(other, k))


def record(session: str = "W2", quick: bool = False, route_length: float | None = None
           ) -> Recording:
    """Simulate ``session`` of the built-in warehouse and build M1 as the runner does.
    ``quick`` cuts the update route after ``route_length`` m (default 30 m)."""
    import sim
    from scenarios import runner
    from scenarios.session import session_seeds
    from sim.geometry import obstacle_arrays
    from sim.groundtruth import covered_cells
    from scenarios.catalog import find_scenario

    scn = sim.load_scenario(find_scenario(None))
    if quick:
        scn = sim.quick_variant(scn, max_route_length=route_length or 30.0)
    seeds = session_seeds(scn.seed, len(scn.sessions))
    m1 = runner.build_initial_map(scn, 0, seeds[0]).updated
    i = scn.session_index(session)
    world = sim.World(scn, i, seeds[i]["world"])
    truth = world.ground_truth()
    boxes, circles = obstacle_arrays(scn.world.static, scn.world.bounds,
                                                  scn.world.wall_thickness)
    structure = covered_cells(truth, boxes, circles) & (truth.data == OCCUPIED)
    rec = Recording(m1, truth, structure, scn.robot.lidars[0].mount)
    true, odom = [], []
    for msg in world.run():
        if isinstance(msg, sim.ScanMsg) and msg.lidar == 0:
            rec.scans.append(msg.scan)
            true.append(msg.true_pose.as_array())
            odom.append(msg.odom_pose.as_array())
    rec.true, rec.odom = np.array(true), np.array(odom)
    return rec


def injected_poses(true: np.ndarray, error: Error) -> np.ndarray:
    """Robot poses (N, 3) with ``error`` applied from its start on."""
    est = true.copy()
    k0 = int(round(error.start * len(true)))
    if error.rigid:
        # est = E (+) true with E the motion that takes the robot's pose at k0 to that pose
        # shifted by (dx, dy) and turned by dtheta about its own position.
        c, s = math.cos(error.dtheta), math.sin(error.dtheta)
        px, py = true[k0, 0], true[k0, 1]
        rel = true[k0:, :2] - (px, py)
        est[k0:, 0] = px + error.dx + c * rel[:, 0] - s * rel[:, 1]
        est[k0:, 1] = py + error.dy + s * rel[:, 0] + c * rel[:, 1]
        est[k0:, 2] = true[k0:, 2] + error.dtheta
    else:
        est[k0:] += (error.dx, error.dy, error.dtheta)
    est[:, 2] = (est[:, 2] + math.pi) % (2 * math.pi) - math.pi
    return est


def replay(rec: Recording, poses: np.ndarray, guard=None, config=None) -> Damage:
    """Feed the recorded scans to a fresh updater on M1 at ``poses``; score the output.
    ``config``: the updater's configuration (None: the paper profile's)."""
    import evaluation as ev
    from onboard.pipeline import RobotPipeline
    from updater import MapUpdater

    upd = MapUpdater(rec.reference, config, profile="paper")
    pipeline = RobotPipeline(upd, pose_check=guard)
    for k, scan in enumerate(rec.scans):
        pipeline.step(scan, rec.mount, odometry=Pose2D(*rec.odom[k]), pose=Pose2D(*poses[k]))
    dmg = Damage(unsure=pipeline.counts.scans_refused_by_pose_check)
    out = upd.updated_map()
    freed = (rec.truth.data == OCCUPIED) & (out.data == FREE) & (rec.reference.data != FREE)
    cd = ev.change_detection(rec.reference, out, rec.truth, np.ones(out.shape, bool))
    dmg.freed = int(freed.sum())
    dmg.structure = int((freed & rec.structure).sum())
    dmg.holes = int((freed & ~ev.near(out.data == OCCUPIED)).sum())
    dmg.incorrect, dmg.changes = cd["incorrect_changes"], cd["changes"]
    dmg.processed, dmg.lost = upd.stats["processed"], upd.stats["lost"]
    return dmg


def error_levels() -> dict[str, list[Error]]:
    """Every error level of the table and its variants."""
    levels: dict[str, list[Error]] = {"none": [Error("none")]}
    for d in OFFSETS:
        levels[f"{d:g} m"] = [Error(f"{d:g} m", d * math.cos(math.radians(a)),
                                    d * math.sin(math.radians(a))) for a in DIRECTIONS]
    for deg in TURNS:
        levels[f"{deg:g} deg"] = [Error(f"{deg:g} deg", dtheta=s * math.radians(deg))
                                  for s in (1, -1)]
    d, deg = PROTECTED
    levels[f"{d:g} m + {deg:g} deg"] = [
        Error(f"{d:g} m + {deg:g} deg", d * math.cos(math.radians(a)),
              d * math.sin(math.radians(a)), s * math.radians(deg))
        for a in DIRECTIONS for s in (1, -1)]
    kx, ky, kdeg = KIDNAP
    levels["kidnapping"] = [Error("kidnapping", kx, ky, math.radians(kdeg), 0.5, rigid=True),
                            Error("kidnapping", -kx, -ky, -math.radians(kdeg), 0.5, rigid=True)]
    return levels


def detectable(level: str) -> bool:
    """True for the levels the pose check must stop: from 0.1 m or 1 deg on, and kidnapping."""
    if level == "none":
        return False
    if level == "kidnapping":
        return True
    metres, degrees = level_size(level)
    return metres >= 0.1 - 1e-9 or degrees >= 1.0 - 1e-9


def level_size(level: str) -> tuple[float, float]:
    """(metres, degrees) of a level name such as "0.15 m + 3 deg"."""
    metres = degrees = 0.0
    for part in level.split("+"):
        value, unit = part.split()
        if unit == "m":
            metres = float(value)
        else:
            degrees = float(value)
    return metres, degrees


def run_table(rec: Recording, levels: dict[str, list[Error]], guard_config=None,
              progress: bool = True, config=None) -> list[tuple[str, int, Damage, Damage]]:
    """(level, variants, damage without the pose check, damage with it) per level;
    ``config``: the updater's (None: the paper profile's)."""
    from localization.confidence import PoseCheck

    guard = PoseCheck(rec.reference, guard_config)
    rows = []
    for name, errors in levels.items():
        plain, guarded = Damage(), Damage()
        for e in errors:
            poses = injected_poses(rec.true, e)
            plain.add(replay(rec, poses, config=config))
            guarded.add(replay(rec, poses, guard, config))
        rows.append((name, len(errors), plain, guarded))
        if progress:
            print(f"  {name}: {plain.freed} / {guarded.freed}", file=sys.stderr, flush=True)
    return rows


def print_table(rows, processed_per_run: int) -> None:
    print("| error | runs | freed G-occ. | of structure | holes | incorrect changes | lost "
          "| guarded: freed G-occ. | of structure | holes | incorrect changes | lost | refused |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, n, p, g in rows:
        print(f"| {name} | {n} | {p.freed} | {p.structure} | {p.holes} | {p.incorrect} | "
              f"{p.lost} | {g.freed} | {g.structure} | {g.holes} | {g.incorrect} | {g.lost} | "
              f"{g.unsure} |")
    print(f"\nProcessed scans per run without errors: {processed_per_run}. Counts are summed "
          "over a level's runs; 'refused' are scans the pose check refused (after gating).")


def main(argv=None) -> int:
    from figures import Figures, add_option  # beside this script

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--session", default="W2")
    ap.add_argument("--quick", action="store_true", help="30 m of the route")
    ap.add_argument("--profile", default="paper", choices=("paper", "robot"),
                    help="the updater's and the pose check's configuration (default paper)")
    add_option(ap)
    args = ap.parse_args(argv)
    from localization.confidence import PoseCheckConfig
    from updater import UpdaterConfig
    t0 = time.perf_counter()
    rec = record(args.session, args.quick)
    print(f"{args.session}: {len(rec.scans)} scans recorded in "
          f"{time.perf_counter() - t0:.1f} s", file=sys.stderr)
    # the offsets are laid on poses given from outside, as a log's are
    rows = run_table(rec, error_levels(),
                     PoseCheckConfig.profile(args.profile).for_poses(own_localizer=False),
                     config=UpdaterConfig.profile(args.profile))
    print_table(rows, rows[0][2].processed)
    print(f"\nWall time {time.perf_counter() - t0:.0f} s.")
    out = Figures()
    out.add("wall time", time.perf_counter() - t0, "s")
    out.output("the table's counts", [(name, n, vars(p), vars(g)) for name, n, p, g in rows])
    out.write(args.json)
    freed = [name for name, _, _, g in rows if detectable(name) and g.freed]
    holes = [name for name, _, _, g in rows if g.holes]
    if freed:
        print(f"G-occupied cells freed with the pose check at: {', '.join(freed)}")
    if holes:
        print(f"holes with the pose check at: {', '.join(holes)}")
    return 1 if freed or holes else 0


if __name__ == "__main__":
    raise SystemExit(main())
