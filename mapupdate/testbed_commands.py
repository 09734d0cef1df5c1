"""The commands of the simulated testbed: ``run``, ``render`` and ``generate``. Each first
checks that the simulator extra is installed, before anything is read or written."""

from __future__ import annotations

import sys
from pathlib import Path

import sim
from gridmap.config import DEFAULT_PROFILE
from mapstore import open_store
from onboard.methods import check_method
from onboard.outputs import OutputClash, check_outputs
from onboard.robot_config import load_robot_config
from scenarios.catalog import HERE, find_scenario
from scenarios.checkpoint import ResumeError
from scenarios.generator import write_generated
from scenarios.observers import Observers
from scenarios.runner import RunOptions, run_scenario
from scenarios.session_bags import SessionBagRecorder, check_bag_folder

from .extras import require
from .version import __version__


def render(args) -> int:
    require("pymunk", "matplotlib")
    path = find_scenario(args.scenario)
    check_outputs({"scenario": [path]}, {"--out": [args.out]})
    if not Path(args.out).parent.is_dir():
        raise OutputClash(f"--out {args.out}: the folder {Path(args.out).parent} does not "
                          "exist; make it first")
    scenario = sim.load_scenario(path)
    out = sim.render_world(scenario, args.session, args.out, seed=args.seed, time=args.time)
    print(f"wrote {out}")
    return 0


def run(args) -> int:
    require("pymunk", "matplotlib", *(["rerun"] if args.rerun or args.rerun_spawn else []))
    # refused before anything is written
    config = load_robot_config(args.config, profile=args.profile)
    check_method(args.method, "--method")
    if args.resume is not None and args.out is not None and args.out != args.resume:
        raise ResumeError(f"--resume {args.resume} and --out {args.out} name different folders")
    _check_run_outputs(args)
    observers = []
    if args.bag is not None:
        observers.append(SessionBagRecorder(args.bag, args.bag_format))
    recorder = rerun_recorder(args) if args.rerun or args.rerun_spawn else None
    if recorder is not None:
        observers.append(recorder)
    if args.store is not None:
        observers.append(StoreRecorder(args.store, args.method, args.seed))
    given = {} if args.pose_check is None else {"pose_check": args.pose_check}
    # only what was asked for: a resumed run keeps its own (scenarios.checkpoint)
    keys = config.given
    asked = args.profile is not None or args.config is not None
    opts = RunOptions(out=args.resume or args.out, seed=args.seed, sessions=args.sessions,
                      quick=args.quick, progress=not args.no_progress,
                      profile=config.profile if asked else None,
                      updater_config=config.updater if "updater" in keys else None,
                      localizer_config=keys.get("localizer"),
                      pose_check_config=config.pose_check if "pose_check" in keys else None,
                      observer=Observers(*observers) if observers else None,
                      resume=args.resume is not None, method=args.method, **given)
    try:
        result = run_scenario(args.scenario, opts)
    finally:
        if recorder is not None:
            recorder.close()
    print(f"wrote {result.out_dir}/report.md and metrics.json")
    if args.rerun:
        print(f"wrote {args.rerun}: open it with `rerun {args.rerun}`")
    return 0


def _check_run_outputs(args) -> None:
    """Before anything is written: a new run's folder, and its bag folder, are new or empty
    (never a folder holding other files), and the recording goes over none of the run's inputs
    (the scenario, the configuration, a resumed run's state)."""
    if args.resume is None and args.out is not None and Path(args.out).is_dir():
        others = sorted(p.name for p in Path(args.out).iterdir())
        if others and not (Path(args.out) / "state").is_dir():    # a run's: the run decides
            raise OutputClash(f"--out {args.out}: holds other files ({', '.join(others[:3])}"
                              f"{', ...' if len(others) > 3 else ''}); a run goes into a new "
                              "or empty folder")
    if args.bag is not None:
        check_bag_folder(args.bag, resume=args.resume is not None)
    if args.rerun is not None:
        inputs = {"scenario": [find_scenario(args.scenario)],
                  "--config": [args.config] if args.config else []}
        if args.resume is not None and (Path(args.resume) / "state").is_dir():
            inputs["--resume"] = [p for p in (Path(args.resume) / "state").iterdir()]
        check_outputs(inputs, {"--rerun": [args.rerun]})


class StoreRecorder:
    """A session observer that commits each session's updated map M_i to a map store, its
    parent the version committed before it (the store's first version: the map the first
    update session starts from). The simulated sessions go on from their own maps: review
    decides what robots are served, not what the testbed's next session starts from."""

    def __init__(self, target, method: str, seed):
        self.target, self.method, self.seed = target, method, seed
        with open_store(target, create=True):
            pass                                 # refused (one line) before the run starts

    def session_start(self, scenario, session, world, previous, *rest) -> None:
        self.scenario = scenario.name
        with open_store(self.target) as store:
            if store.latest(approved_only=False) is None:
                store.commit(previous, None, {"method": "import", "robot": "simulated",
                                              "source": f"{scenario.name} before session "
                                                        f"{session}",
                                              "project_version": __version__},
                             status="approved")

    def scan(self, *args) -> None:
        pass

    def session_end(self, result) -> None:
        metrics = {k: float(v) for k, v in (result.metrics or {}).items()
                   if isinstance(v, (int, float)) and not isinstance(v, bool)}
        with open_store(self.target) as store:
            parent = store.latest(approved_only=False)
            number = store.commit(result.updated, parent, {
                "robot": "simulated", "source": f"{self.scenario} {result.name}",
                "session": result.name, "method": self.method, "seed": self.seed,
                "metrics": metrics, "project_version": __version__})
            print(f"committed {result.name} to {store.name} as v{number} "
                  f"({store.version(number).status})")


def rerun_recorder(args):
    from scenarios.rerun_log import RerunRecorder, has_display  # rerun: an optional extra

    spawn = args.rerun_spawn and has_display()
    if args.rerun_spawn and not spawn:
        print("mapupdate run: no display here, the viewer is not opened", file=sys.stderr)
    return RerunRecorder(args.rerun, spawn=spawn) if args.rerun or spawn else None


def fleet(args) -> int:
    require("pymunk")
    from scenarios.fleet import FleetOptions, format_table, run_fleet
    from scenarios.options import RunError

    mode = args.mode or ("store" if args.store else "shared")
    options = FleetOptions(robots=args.robots, mode=mode, merge_rule=args.merge,
                           quick=args.quick, sessions=args.sessions, seed=args.seed,
                           mask_robots=not args.unmasked, progress=not args.no_progress,
                           profile=args.profile or DEFAULT_PROFILE, store=args.store)
    try:
        record = run_fleet(args.scenario, options, args.out)
    except ValueError as e:             # the fleet's own checks name the option
        raise RunError(str(e)) from None
    print(format_table(record["sessions"]))
    if args.out is not None:
        print(f"wrote {args.out}/fleet.json")
    return 0


def generate(args) -> int:
    require("pymunk")
    out = Path(args.out)
    if out.exists() and (out.is_dir() or out.resolve().parent == HERE):
        # a folder, or one of the built-in scenarios this package ships
        raise OutputClash(f"{out}: is {'a folder' if out.is_dir() else 'a built-in scenario'}; "
                          "choose another --out")
    path = write_generated(args.seed, args.out, size=tuple(args.size), sessions=args.sessions,
                           fov=args.fov)
    print(f"wrote {path}")
    return 0
