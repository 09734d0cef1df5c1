"""The command line, ``mapupdate``: parses arguments and calls the library; nothing else.

Heavy modules (numba kernels, pymunk, matplotlib) are imported inside the subcommands so that
``mapupdate --help`` answers at once.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


CONFIG_HELP = ("YAML file with the sections updater, localizer and pose_check, each optional, "
               "holding the fields of updater.UpdaterConfig, localization.LocalizerConfig and "
               "localization.confidence.PoseCheckConfig; keys a section leaves out keep that "
               "class's defaults. --pose-check/--no-pose-check still turn the check on or off")


def _cmd_compare(args) -> int:
    from gridmap import load_map
    from gridmap.metrics import compare_maps

    a, b = load_map(args.a), load_map(args.b)
    m = compare_maps(a, b)
    print(f"{'metric':<8}{'value':>10}")
    print(f"{'CC':<8}{m['cc']:>9.2f}%")
    print(f"{'MS':<8}{m['ms']:>9.2f}%")
    print(f"{'OPDF':<8}{m['opdf']:>9.2f}%")
    return 0


def _cmd_render(args) -> int:
    import sim

    from .catalog import find_scenario
    from .outputs import check_outputs

    path = find_scenario(args.scenario)
    check_outputs({"scenario": [path]}, {"--out": [args.out]})
    scenario = sim.load_scenario(path)
    out = sim.render_world(scenario, args.session, args.out, seed=args.seed, time=args.time)
    print(f"wrote {out}")
    return 0


def _cmd_run(args) -> int:
    from .checkpoint import ResumeError
    from .observers import Observers
    from .methods import check_method
    from .robot_config import load_robot_config
    from .runner import RunOptions, run_scenario

    config = load_robot_config(args.config)     # refused before anything is written
    check_method(args.method, "--method")
    if args.resume is not None and args.out is not None and args.out != args.resume:
        raise ResumeError(f"--resume {args.resume} and --out {args.out} name different folders")
    observers = []
    if args.bag is not None:
        from .session_bags import SessionBagRecorder

        observers.append(SessionBagRecorder(args.bag, args.bag_format))
    recorder = _rerun_recorder(args) if args.rerun or args.rerun_spawn else None
    if recorder is not None:
        observers.append(recorder)
    given = {} if args.pose_check is None else {"pose_check": args.pose_check}
    opts = RunOptions(out=args.resume or args.out, seed=args.seed, sessions=args.sessions,
                      quick=args.quick, progress=not args.no_progress,
                      updater_config=config.updater, localizer_config=config.localizer,
                      pose_check_config=config.pose_check,
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


def _rerun_recorder(args):
    from .rerun_log import RerunRecorder, has_display

    spawn = args.rerun_spawn and has_display()
    if args.rerun_spawn and not spawn:
        print("mapupdate run: no display here, the viewer is not opened", file=sys.stderr)
    return RerunRecorder(args.rerun, spawn=spawn) if args.rerun or spawn else None


def _cmd_update(args) -> int:
    from . import replay
    from .outputs import check_outputs, map_files, map_inputs
    from .robot_config import load_robot_config

    # the method and --state, then the configuration, are refused before anything is read
    replay.check_update_arguments(args.poses, args.smooth_poses, args.method, args.state)
    config = load_robot_config(args.config)
    check_outputs({"--map": map_inputs(args.map), "--log": [args.log],
                   "--config": [args.config] if args.config else [],
                   "--state": [args.state] if args.state and args.state.exists() else []},
                  {"--out": map_files(args.out), "--state": [args.state] if args.state else [],
                   "--trajectory": [args.trajectory] if args.trajectory else []},
                  both=("--state",))
    start = None if args.initial_pose is None else replay.parse_pose(args.initial_pose)
    summary = replay.update_from_log(
        args.map, args.log, args.out, args.state, pose_source=args.poses,
        updater_config=config.updater, localizer_config=config.localizer,
        pose_check_config=config.pose_check, progress=not args.no_progress,
        log_format=args.format, scan_topics=args.scan_topic or None,
        odom_topic=args.odom_topic, pose_topic=args.pose_topic, pose_check=args.pose_check,
        strict=args.strict, initial_pose=start, trajectory_path=args.trajectory,
        smooth_window=args.smooth_poses, method=args.method)
    summary.setdefault("out", str(args.out))
    print("\n".join(replay.summary_lines(summary)))
    return 0


def _cmd_map(args) -> int:
    from . import logmap
    from .outputs import check_outputs, map_files

    check_outputs({"--log": [args.log]}, {"--out": map_files(args.out)})
    summary = logmap.map_from_log(args.log, args.out, resolution=args.resolution,
                                  pose_source=args.poses, log_format=args.format,
                                  strict=args.strict, scan_topics=args.scan_topic or None,
                                  odom_topic=args.odom_topic, pose_topic=args.pose_topic,
                                  progress=not args.no_progress)
    print("\n".join(logmap.summary_lines(summary)))
    return 0


def _cmd_inject(args) -> int:
    from evaluation import case_folder, edited_world
    from gridmap import load_map
    from robotlogs import log_observations

    case_folder.check_case_dir(args.out, args.map, args.log)      # before anything is read
    grid = load_map(args.map)
    found = log_observations(args.log, log_format=args.format, strict=args.strict,
                             scan_topics=args.scan_topic or None, odom_topic=args.odom_topic,
                             pose_topic=args.pose_topic)
    case = edited_world.make_case(grid, found.observations, args.seed, removed=args.removed,
                                  added=args.added, moved=args.moved, people=args.people,
                                  min_views=args.min_views, progress=not args.no_progress)
    case_folder.write_case(case, args.out, map_path=args.map, log_path=args.log)
    print("\n".join(case_folder.case_lines(case, args.out)))
    return 0


def _cmd_score(args) -> int:
    from evaluation import case_folder
    from gridmap import load_map

    from .outputs import check_outputs, map_inputs

    if args.json is not None:
        check_outputs({"DIR": [args.case / f for f in case_folder.CASE_FILES],
                       "OUT.yaml": map_inputs(args.updated)}, {"--json": [args.json]})
    scores = case_folder.score_case(args.case, load_map(args.updated))
    print("\n".join(case_folder.score_lines(scores)))
    if args.json is not None:
        case_folder.write_scores(scores, args.json)
        print(f"wrote {args.json}")
    return 0


def _cmd_ros1(args) -> int:
    from .ros1.node import run_node

    # an empty --config (a launch file's unset argument) means none
    return run_node(args.map, args.config or None, args.ros_argv)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="mapupdate",
        description="Keep a 2D occupancy-grid map true while the world changes.")
    p.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    sub = p.add_subparsers(dest="command", required=True)
    _add_run(sub)
    _add_compare(sub)
    _add_update(sub)
    _add_map(sub)
    _add_render(sub)
    _add_ros1(sub)
    _add_generate(sub)
    _add_sweep(sub)
    _add_inject(sub)
    _add_score(sub)
    return p


def _add_run(sub) -> None:
    run = sub.add_parser("run", help="play a scenario's sessions end to end and report scores")
    run.add_argument("scenario", nargs="?", default=None,
                     help="built-in scenario name or YAML path (default: aws_small_warehouse)")
    run.add_argument("--out", type=Path, default=None,
                     help="output folder (default: runs/<scenario>-<timestamp>)")
    run.add_argument("--seed", type=int, default=None, help="override the scenario's seed")
    run.add_argument("--sessions", type=int, default=None,
                     help="run only the first K sessions")
    run.add_argument("--quick", action="store_true",
                     help="short routes that still keep every change in view (for CI)")
    run.add_argument("--bag", type=Path, default=None,
                     help="also write each update session as a ROS bag into this folder")
    run.add_argument("--bag-format", choices=["ros1", "ros2"], default="ros1",
                     help="bag format for --bag (default ros1)")
    run.add_argument("--no-progress", action="store_true", help="no progress bars")
    run.add_argument("--resume", type=Path, default=None, metavar="DIR",
                     help="continue the killed run in DIR after its last finished session")
    run.add_argument("--config", type=Path, default=None, metavar="FILE.yaml", help=CONFIG_HELP)
    run.add_argument("--pose-check", action=argparse.BooleanOptionalAction, default=None,
                     help="skip scans whose pose the scan's fit to the map or the localiser's "
                          "covariance calls unsure (default: on)")
    run.add_argument("--method", default="paper", metavar="NAME",
                     help="what updates the map: paper (the updater, default), none (keep "
                          "M(i-1)), remap (a fresh log-odds map of the session), fuse "
                          "(log-odds mapping on M(i-1) as the prior), hybrid (the paper's "
                          "detector decides where, fuse's evidence what)")
    run.add_argument("--rerun", type=Path, default=None, metavar="FILE.rrd",
                     help="record the run for the rerun viewer")
    run.add_argument("--rerun-spawn", action="store_true",
                     help="show the run live in a rerun viewer (when there is a display)")
    run.set_defaults(func=_cmd_run)


def _add_compare(sub) -> None:
    cmp_ = sub.add_parser("compare", help="CC, MS and OPDF of two map_server maps")
    cmp_.add_argument("a", type=Path)
    cmp_.add_argument("b", type=Path)
    cmp_.set_defaults(func=_cmd_compare)


def _add_update(sub) -> None:
    from localization.smoothing import SMOOTH_WINDOW

    upd = sub.add_parser("update", help="update a map from a recorded ROS bag or CARMEN log")
    upd.add_argument("--map", type=Path, required=True, help="map_server YAML of the map")
    upd.add_argument("--log", type=Path, required=True,
                     help="ROS 1 bag, ROS 2 bag folder or CARMEN log")
    upd.add_argument("--out", type=Path, required=True, help="YAML path of the updated map")
    upd.add_argument("--state", type=Path, default=None,
                     help="updater state file: loaded if present, saved at the end (method "
                          "paper only)")
    upd.add_argument("--method", default="paper", metavar="NAME",
                     help="what updates the map: paper (the updater, default), fuse (log-odds "
                          "mapping on the map as the prior), hybrid (the paper's detector "
                          "decides where, fuse's evidence what)")
    upd.add_argument("--poses", default="auto", choices=["auto", "recorded", "localizer", "truth"],
                     help="where scan poses come from (default: recorded when present)")
    upd.add_argument("--config", type=Path, default=None, metavar="FILE.yaml",
                     help=CONFIG_HELP + " (updater keys go under 'updater:', also when they "
                                        "are the only ones)")
    _add_log_options(upd)
    upd.add_argument("--pose-check", action=argparse.BooleanOptionalAction, default=False,
                     help="skip scans whose pose the scan's fit to the map (or the localiser's "
                          "covariance) calls unsure (default: off; README, 'Choices')")
    upd.add_argument("--initial-pose", nargs=3, type=float, default=None,
                     metavar=("X", "Y", "YAW"),
                     help="where the localiser starts, in the map frame [m, m, rad] (default: "
                          "the log's localisation if it has one, else over the whole map)")
    upd.add_argument("--trajectory", type=Path, default=None, metavar="OUT.tum",
                     help="write the robot pose of each scan the update used (TUM, for evo)")
    upd.add_argument("--smooth-poses", type=float, default=SMOOTH_WINDOW, metavar="SECONDS",
                     help="smooth a recorded localisation (map -> odom, corrected poses) that "
                          "jitters from scan to scan with the odometry over this window "
                          f"(default {SMOOTH_WINDOW:g}; 0: the poses as recorded)")
    upd.set_defaults(func=_cmd_update)


def _add_log_options(p) -> None:
    """What ``update`` and ``map`` both need to read a log."""
    p.add_argument("--format", default=None, choices=["carmen", "ros1", "ros2"],
                   help="log format (default: detected)")
    p.add_argument("--scan-topic", action="append", default=[], help="LaserScan topic(s)")
    p.add_argument("--odom-topic", default=None)
    p.add_argument("--pose-topic", default=None)
    p.add_argument("--strict", action="store_true",
                   help="refuse a log with a malformed line or message instead of skipping "
                        "and counting it")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_map(sub) -> None:
    mp = sub.add_parser("map", help="build a first map from a log with corrected poses",
                        description="Log-odds occupancy mapping, as M1 is built in the "
                        "simulator, from every scan of a log at the poses it records.")
    mp.add_argument("--log", type=Path, required=True,
                    help="ROS 1 bag, ROS 2 bag folder or CARMEN log (also .gz) with corrected "
                         "poses")
    mp.add_argument("--out", type=Path, required=True, help="YAML path of the map")
    mp.add_argument("--resolution", type=float, default=0.05, help="cell size [m] (0.05)")
    mp.add_argument("--poses", default="recorded", choices=["recorded", "truth"],
                    help="the log's recorded (corrected) poses, or a simulated log's true "
                         "ones (default: recorded)")
    _add_log_options(mp)
    mp.set_defaults(func=_cmd_map)


def _add_inject(sub) -> None:
    inj = sub.add_parser("inject", help="make an edited-world case from a log with corrected "
                                        "poses and its map (docs/edited_world.md)",
                         description="Draw removed boxes into the map and cut added boxes and "
                         "walking people into the log's scans, so that an update's result can "
                         "be scored against an exact truth with 'mapupdate score'.")
    inj.add_argument("--map", type=Path, required=True, help="map_server YAML of the log's map")
    inj.add_argument("--log", type=Path, required=True,
                     help="ROS 1 bag, ROS 2 bag folder or CARMEN log with corrected poses")
    inj.add_argument("--out", type=Path, required=True,
                     help="the case folder to write (new or empty)")
    inj.add_argument("--seed", type=int, required=True, help="seed of every random choice")
    inj.add_argument("--removed", type=int, default=4, metavar="K",
                     help="boxes drawn into the map where the scans see free floor (4)")
    inj.add_argument("--added", type=int, default=4, metavar="K",
                     help="boxes cut into the scans where the map is free (4)")
    inj.add_argument("--moved", type=int, default=0, metavar="K",
                     help="objects moved: a removed box and an added one of its size (0)")
    inj.add_argument("--people", type=int, default=0, metavar="K",
                     help="people walking through the scans, never part of the truth (0)")
    inj.add_argument("--min-views", type=int, default=5, metavar="N",
                     help="scans that must see each box with 3 beams or more (5)")
    _add_log_options(inj)
    inj.set_defaults(func=_cmd_inject)


def _add_score(sub) -> None:
    sc = sub.add_parser("score", help="score an updated map against an edited-world case")
    sc.add_argument("case", type=Path, metavar="DIR", help="the case folder of 'mapupdate inject'")
    sc.add_argument("updated", type=Path, metavar="OUT.yaml",
                    help="the map 'mapupdate update' wrote from DIR/stale.yaml and DIR/log.clf")
    sc.add_argument("--json", type=Path, default=None, metavar="FILE",
                    help="also write the scores as JSON")
    sc.set_defaults(func=_cmd_score)


def _add_ros1(sub) -> None:
    ros = sub.add_parser("ros1", help="run the live ROS 1 node (under a roscore)",
                         description="The map updater as a ROS 1 node: LaserScan and tf in, "
                         "map_updated out; ROS remappings (name:=value) are passed to ROS.")
    ros.add_argument("--map", type=Path, default=None,
                     help="map_server YAML of the reference map (default: the latched 'map' "
                          "topic)")
    ros.add_argument("--config", default=None,
                     help="YAML with 'updater' and 'pose_check' sections; private ROS "
                          "parameters (~updater/threshold, ...) override it")
    ros.set_defaults(func=_cmd_ros1)


def _add_render(sub) -> None:
    ren = sub.add_parser("render", help="draw a session's world to a PNG")
    ren.add_argument("scenario", nargs="?", default=None,
                     help="built-in scenario name or YAML path (default: aws_small_warehouse)")
    ren.add_argument("--session", default="W1", help="session name or index (default W1)")
    ren.add_argument("--out", type=Path, default=Path("world.png"),
                     help="output PNG (default: world.png)")
    ren.add_argument("--time", type=float, default=0.0,
                     help="draw the world at this time [s] of the session (default 0)")
    ren.add_argument("--seed", type=int, default=None,
                     help="seed of the world, which places the people (default: the scenario's)")
    ren.set_defaults(func=_cmd_render)


def _cmd_generate(args) -> int:
    from .catalog import HERE
    from .generator import write_generated
    from .outputs import OutputClash

    out = Path(args.out)
    if out.exists() and (out.is_dir() or out.resolve().parent == HERE):
        # a folder, or one of the built-in scenarios this package ships
        raise OutputClash(f"{out}: is {'a folder' if out.is_dir() else 'a built-in scenario'}; "
                          "choose another --out")
    path = write_generated(args.seed, args.out, size=tuple(args.size), sessions=args.sessions,
                           fov=args.fov)
    print(f"wrote {path}")
    return 0


def _cmd_sweep(args) -> int:
    from .study_report import summarise
    from .sweep import SweepError, run_sweep

    if args.summarise is not None:
        table = summarise(args.summarise)
        print(f"wrote {args.summarise}/results.csv, summary.md and figures ({table} runs)")
        return 0
    if args.spec is None or args.out is None:
        raise SweepError("mapupdate sweep needs SPEC.yaml and --out DIR "
                              "(or --summarise DIR)")
    done = run_sweep(args.spec, args.out, workers=args.workers, ray=args.ray,
                     progress=not args.no_progress)
    print(f"wrote {args.out}/results.csv and summary.md ({done} runs)")
    return 0


def _add_generate(sub) -> None:
    gen = sub.add_parser("generate", help="write a generated warehouse scenario")
    gen.add_argument("--seed", type=int, required=True, help="layout seed")
    gen.add_argument("--out", type=Path, required=True, help="scenario YAML to write")
    gen.add_argument("--size", type=float, nargs=2, default=[30.0, 20.0], metavar=("W", "H"),
                     help="inner size of the building [m], 15 x 10 to 60 x 40 (default 30 20)")
    gen.add_argument("--sessions", type=int, default=4,
                     help="sessions, the mapping session W1 included (default 4)")
    gen.add_argument("--fov", type=int, default=270, help="lidar field of view, 270 or 360")
    gen.set_defaults(func=_cmd_generate)


def _add_sweep(sub) -> None:
    sw = sub.add_parser("sweep", help="run a study: scenarios x seeds x methods x grid")
    sw.add_argument("spec", nargs="?", type=Path, default=None, help="the study's YAML spec")
    sw.add_argument("--out", type=Path, default=None, help="study folder")
    sw.add_argument("--workers", type=int, default=None,
                    help="processes of the local pool (default: the number of CPUs)")
    sw.add_argument("--ray", default=None, metavar="auto|ADDRESS",
                    help="run the runs as Ray tasks: 'auto' starts a local Ray, an address "
                         "joins a cluster (needs the extra: pip install "
                         "'lidar-map-updating[ray]')")
    sw.add_argument("--summarise", type=Path, default=None, metavar="DIR",
                    help="rebuild results.csv, summary.md and figures of DIR from its "
                         "finished runs")
    sw.add_argument("--no-progress", action="store_true", help="no progress bar")
    sw.set_defaults(func=_cmd_sweep)


def _user_errors() -> tuple[type[BaseException], ...]:
    """The errors a user's input or machine can cause: reported in one line, never a
    traceback. Every package's own error derives from ``MapUpdatingError``."""
    from gridmap import MapUpdatingError

    # OSError: the machine's answer to a write or read (a full disk, a read-only folder, no
    # permission), which names the file; the user can act on it
    return (MapUpdatingError, OSError)


def main(argv: list[str] | None = None) -> int:
    full = sys.argv if argv is None else ["mapupdate", *map(str, argv)]
    # ROS remappings and private parameters (``__name:=x``, ``_rate:=5``) are ROS's, not ours
    args = build_parser().parse_args([a for a in full[1:] if ":=" not in a])
    args.ros_argv = full
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("mapupdate: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - sorted into user errors and bugs just below
        if args.debug or not isinstance(exc, _user_errors()):
            raise
        print(f"mapupdate {args.command}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
