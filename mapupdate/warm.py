"""Compile the main job's kernels ahead of its first run: ``python -m mapupdate.warm``
(``make setup`` runs it after installing).

numba compiles a kernel the first time it meets new argument types and, with ``cache=True``,
keeps the machine code beside the source for every later process. Unwarmed, the first
``mapupdate run`` compiles every kernel as it first meets it, most of them before its first
update session moves. This plays the main job's own code (the default scenario with the
options ``mapupdate run`` passes) over the first metres of the mapping session and of one
update session, into a temporary folder, so that every kernel is compiled for exactly the
argument types the main job gives it: a hand-written call with a float where the job passes an
int would fill the cache with a specialisation the job never uses.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

# metres of each route played: enough for the localiser to update and for the updater, the
# pose check and the scoring to see scans (everything they compile runs at the first few)
ROUTE_METRES = 4.0


def cut_route(route, metres: float) -> tuple:
    """The route's waypoints up to the first one ``metres`` along it (at least two)."""
    pts, length = [route[0]], 0.0
    for p in route[1:]:
        length += math.dist(pts[-1], p)
        pts.append(p)
        if length >= metres:
            break
    return tuple(pts)


def short_scenario(scenario, metres: float = ROUTE_METRES):
    """The mapping session and the first update session of ``scenario``, each cut short."""
    mapping = next(i for i, s in enumerate(scenario.sessions) if s.mapping)
    update = next(i for i, s in enumerate(scenario.sessions) if not s.mapping)
    sessions = tuple(replace(scenario.sessions[i], route=cut_route(scenario.sessions[i].route,
                                                                   metres), quick_route=None)
                     for i in (mapping, update))
    return replace(scenario, sessions=sessions)


def warm(metres: float = ROUTE_METRES) -> float:
    """Play the short run (see the module's docstring); returns its wall time [s]."""
    import sim
    from scenarios.catalog import find_scenario
    from scenarios.report import write_session_maps, write_session_outputs
    from scenarios.runner import RunOptions, build_initial_map, run_update_session
    from scenarios.session import session_seeds

    t0 = time.perf_counter()
    scn = short_scenario(sim.load_scenario(find_scenario(None)), metres)
    options = RunOptions(progress=False)            # the robot profile, as `mapupdate run`
    seeds = session_seeds(scn.seed, len(scn.sessions))
    with tempfile.TemporaryDirectory(prefix="mapupdate-warm-") as tmp:
        out = Path(tmp)
        initial = build_initial_map(scn, 0, seeds[0])
        result = run_update_session(scn, 1, initial.updated, initial.updated, seeds[1], options)
        for res in (initial, result):
            write_session_maps(out, res)
            write_session_outputs(out, res)
    rare_paths()
    return time.perf_counter() - t0


def rare_paths() -> None:
    """Kernels a short run need not reach but a long one can: the estimate of a particle cloud
    split in two clusters, with the localiser's argument types; and the updater of the paper
    profile, whose rules leave kernels of the robot's unused (and the other way round)."""
    import numpy as np

    from localization.estimate import estimate
    from localization.resample import KldParameters
    from onboard.methods import make_method
    from onboard.pipeline import RobotPipeline, warm_up
    from onboard.robot_config import CLASSES

    poses = np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 1.0]])
    estimate(poses, np.full(2, 0.5), KldParameters(1, 2, 0.05, 0.99, np.array([0.5, 0.5, 0.2])))
    config = CLASSES["updater"].profile("paper")
    warm_up(lambda grid: RobotPipeline(make_method("paper", grid, config)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m mapupdate.warm",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--metres", type=float, default=ROUTE_METRES,
                        help=f"metres of each route to play (default {ROUTE_METRES})")
    args = parser.parse_args(argv)
    print("compiling the kernels of mapupdate run (once, into numba's cache) ...", flush=True)
    seconds = warm(args.metres)
    print(f"kernels compiled and cached in {seconds:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
