"""The command line, ``mapupdate``: its parser, and the one-line errors.

Each command lives in the module of its area (``robot_commands``, ``testbed_commands``,
``study_commands``), loaded only when that command runs: a robot's command never loads the
simulated testbed, and ``mapupdate --help`` answers at once.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from gridmap import MapUpdatingError
from localization.smoothing import SMOOTH_WINDOW

from .extras import missing_extra
from .version import __version__

CONFIG_HELP = ("YAML file with the sections updater, localizer and pose_check, each optional, "
               "holding the fields of updater.UpdaterConfig, localization.LocalizerConfig and "
               "localization.confidence.PoseCheckConfig, laid over the profile key by key "
               "(and an optional 'profile' key); --pose-check/--no-pose-check still turn the "
               "check on or off")
PROFILE_HELP = ("the defaults the configuration starts from: robot (what a robot should run, "
                "the default) or paper (the paper and its authors' code); "
                "docs/configuration.md lists where they differ")


def _add_profile(p) -> None:
    p.add_argument("--profile", default=None, metavar="NAME", help=PROFILE_HELP)


class OneLineParser(argparse.ArgumentParser):
    """A usage mistake is one line, as every other error of the command line, and names the
    help that says how (argparse would print the whole usage first)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog="mapupdate",
        description="Keep a 2D occupancy-grid map true while the world changes.")
    p.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    _add_run(sub)
    _add_compare(sub)
    _add_update(sub)
    _add_map(sub)
    _add_render(sub)
    _add_ros1(sub)
    _add_ros2(sub)
    _add_generate(sub)
    _add_sweep(sub)
    _add_inject(sub)
    _add_score(sub)
    _add_store(sub)
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
    _add_profile(run)
    run.add_argument("--pose-check", action=argparse.BooleanOptionalAction, default=None,
                     help="skip scans whose pose the scan's fit to the map or the localiser's "
                          "covariance calls unsure (default: as the profile has it, on for "
                          "robot)")
    run.add_argument("--method", default="paper", metavar="NAME",
                     help="what updates the map: paper (the updater, default), none (keep "
                          "M(i-1)), remap (a fresh log-odds map of the session), fuse "
                          "(log-odds mapping on M(i-1) as the prior), hybrid (the paper's "
                          "detector decides where, fuse's evidence what)")
    run.add_argument("--rerun", type=Path, default=None, metavar="FILE.rrd",
                     help="record the run for the rerun viewer")
    run.add_argument("--rerun-spawn", action="store_true",
                     help="show the run live in a rerun viewer (when there is a display)")
    run.add_argument("--store", default=None, metavar="maps.db|postgresql://...",
                     help="commit each session's map as a version of this map store (made if "
                          "absent; docs/map_store.md)")
    run.set_defaults(command_at=("testbed_commands", "run"))
    fleet = sub.add_parser("fleet", help="several robots update one map in the simulated "
                                         "warehouse (docs/fleet.md)")
    fleet.add_argument("--scenario", default=None, help="built-in name or scenario file")
    fleet.add_argument("--robots", type=int, default=2, help="1..8 (default 2)")
    fleet.add_argument("--mode", choices=("shared", "per-robot", "store"), default=None,
                       help="one updater fed every robot's scans in time order (default), "
                            "one per robot merged at the session's end, or one per robot "
                            "committing to --store (the default with --store)")
    fleet.add_argument("--store", default=None, metavar="maps.db|postgresql://...",
                       help="each robot commits its map to this map store every 30 s of the "
                            "session and takes up the others' merged versions (made if absent; "
                            "docs/fleet.md)")
    fleet.add_argument("--merge", choices=("vote", "union"), default="vote",
                       help="merge rule of the per-robot mode (default vote)")
    fleet.add_argument("--sessions", type=int, default=None, help="W1 and this many minus one")
    fleet.add_argument("--quick", action="store_true", help="the short routes")
    fleet.add_argument("--seed", type=int, default=None)
    fleet.add_argument("--out", type=Path, default=None, help="folder for fleet.json and maps")
    fleet.add_argument("--unmasked", action="store_true",
                       help="give the updater the other robots' returns too")
    fleet.add_argument("--no-progress", action="store_true", help="no progress line")
    _add_profile(fleet)
    fleet.set_defaults(command_at=("testbed_commands", "fleet"))


def _add_compare(sub) -> None:
    cmp_ = sub.add_parser("compare", help="CC, MS and OPDF of two map_server maps")
    cmp_.add_argument("a", type=Path)
    cmp_.add_argument("b", type=Path)
    cmp_.set_defaults(command_at=("robot_commands", "compare"))


def _add_update(sub) -> None:
    upd = sub.add_parser("update", help="update a map from a recorded ROS bag or CARMEN log")
    upd.add_argument("--map", type=Path, default=None,
                     help="map_server YAML of the map (with --store: default the store's latest "
                          "approved map)")
    upd.add_argument("--log", type=Path, default=None,
                     help="ROS 1 bag, ROS 2 bag folder or CARMEN log (required)")
    upd.add_argument("--out", type=Path, default=None,
                     help="YAML path of the updated map (optional with --store)")
    upd.add_argument("--state", type=Path, default=None,
                     help="updater state file: loaded if present, saved at the end (method "
                          "paper only). The log continues the state's session when --map is "
                          "the map that session started from, and is the next session when "
                          "--map is the map it made")
    upd.add_argument("--new-session", action="store_true",
                     help="with --state: the log is a new session on --map, carrying only "
                          "what the state keeps from session to session (the faces rule's "
                          "counts)")
    upd.add_argument("--method", default="paper", metavar="NAME",
                     help="what updates the map: paper (the updater, default), fuse (log-odds "
                          "mapping on the map as the prior), hybrid (the paper's detector "
                          "decides where, fuse's evidence what)")
    upd.add_argument("--poses", default="auto", choices=["auto", "recorded", "localizer", "truth"],
                     help="where scan poses come from (default: recorded when present)")
    upd.add_argument("--config", type=Path, default=None, metavar="FILE.yaml",
                     help=CONFIG_HELP + " (updater keys go under 'updater:', also when they "
                                        "are the only ones)")
    _add_profile(upd)
    _add_log_options(upd)
    upd.add_argument("--pose-check", action=argparse.BooleanOptionalAction, default=None,
                     help="skip scans whose pose the scan's fit to the map (or the localiser's "
                          "covariance) calls unsure (default: as the profile has it, on for "
                          "robot; docs/choices.md)")
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
    upd.add_argument("--store", default=None, metavar="maps.db|postgresql://...",
                     help="commit the updated map as a version of this map store, starting "
                          "from its latest approved map (made only when --map gives the map "
                          "it starts from; docs/map_store.md). A commit that fails keeps the "
                          "session in the spool (exit 3) for 'mapupdate store push'")
    upd.add_argument("--robot", default=None, metavar="NAME",
                     help="the robot's name recorded with the version (default: the host name)")
    _add_spool(upd)
    upd.set_defaults(command_at=("robot_commands", "update"))


def _add_log_options(p) -> None:
    """What ``update``, ``map`` and ``inject`` need to read a log."""
    p.add_argument("--format", default=None, choices=["carmen", "ros1", "ros2"],
                   help="log format (default: detected)")
    p.add_argument("--scan-topic", action="append", default=[], help="LaserScan topic(s)")
    p.add_argument("--odom-topic", default=None)
    p.add_argument("--pose-topic", default=None)
    p.add_argument("--strict", action="store_true",
                   help="refuse a log with a malformed line or message, or cut short, instead "
                        "of skipping and counting it")
    p.add_argument("--refuse-truncated", action="store_true",
                   help="refuse a gzip log cut short (a full disk, a power cut) instead of "
                        "reading it up to the cut")
    p.add_argument("--max-log-lines", type=_whole_number, default=None, metavar="N",
                   help="refuse a CARMEN log of more lines (default: none for a plain file, "
                        "for a gzip file a line per 4 bytes of it, at least 1000000)")
    p.add_argument("--max-log-bytes", type=_whole_number, default=None, metavar="N",
                   help="refuse a CARMEN log of more bytes of text (default: none for a plain "
                        "file, for a gzip file 100 times its size, at least 64 MiB)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _whole_number(text: str) -> int:
    """A count of 1 or more, for argparse."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    return value


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
    mp.set_defaults(command_at=("robot_commands", "map_command"))


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
    inj.set_defaults(command_at=("robot_commands", "inject"))


def _add_score(sub) -> None:
    sc = sub.add_parser("score", help="score an updated map against an edited-world case")
    sc.add_argument("case", type=Path, metavar="DIR", help="the case folder of 'mapupdate inject'")
    sc.add_argument("updated", type=Path, metavar="OUT.yaml",
                    help="the map 'mapupdate update' wrote from DIR/stale.yaml and DIR/log.clf")
    sc.add_argument("--json", type=Path, default=None, metavar="FILE",
                    help="also write the scores as JSON")
    sc.set_defaults(command_at=("robot_commands", "score"))


STORE_HELP = "the map store: an SQLite file (maps.db) or a postgresql:// URL"


def _add_spool(p) -> None:
    p.add_argument("--spool", type=Path, default=None, metavar="DIR",
                   help="where sessions whose commit failed wait for 'store push' (default: "
                        "$MAPUPDATE_SPOOL, else $XDG_DATA_HOME/mapupdate/spool, "
                        "~/.local/share/mapupdate/spool)")


def _add_store(sub) -> None:
    st = sub.add_parser("store", help="versions of a map: log, show, diff, export, rollback, "
                                      "tags, review, push (docs/map_store.md)")
    acts = st.add_subparsers(dest="action", required=True)

    def action(name, text, *positional):
        a = acts.add_parser(name, help=text)
        for arg, arg_help in positional:
            a.add_argument(arg, help=arg_help)
        a.add_argument("--store", required=True, metavar="maps.db|postgresql://...",
                       help=STORE_HELP)
        a.set_defaults(command_at=("robot_commands", "store"))
        return a
    version = ("version", "a version: N, vN, a tag, latest (approved) or head")
    init = action("init", "make a map store (or set the review rule of one)")
    init.add_argument("--require-approval", action=argparse.BooleanOptionalAction,
                      default=None, help="new versions wait for 'approve' before robots get them")
    action("log", "list the versions")
    action("show", "what made a version", version)
    diff = action("diff", "the cells changed from A to B", ("a", "version A"), ("b", "version B"))
    diff.add_argument("--png", type=Path, default=None, metavar="OUT.png",
                      help="also draw B with the cells freed (green) and drawn (magenta)")
    export = action("export", "write a version as a map_server map", version)
    export.add_argument("--out", type=Path, required=True, metavar="MAP.yaml")
    action("rollback", "a new approved version equal to an approved one", version)
    tag = acts.add_parser("tag", help="name a version, or list the names")
    tag.add_argument("version", nargs="?", default=None, help=version[1])
    tag.add_argument("name", nargs="?", default=None, help="the tag")
    tag.add_argument("--store", required=True, metavar="maps.db|postgresql://...",
                     help=STORE_HELP)
    tag.set_defaults(command_at=("robot_commands", "store"))
    push = action("push", "commit the sessions the spool keeps for the store (those whose "
                          "commit failed), oldest first; exit 3 when some stay")
    _add_spool(push)
    for name, text in (("approve", "serve a pending version to robots"),
                       ("reject", "refuse a pending version")):
        review = action(name, text, version)
        review.add_argument("--note", default=None, help="why, kept with the version")


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
    ros.set_defaults(command_at=("robot_commands", "ros1"))


def _add_ros2(sub) -> None:
    ros = sub.add_parser("ros2", help="run the live ROS 2 node (a lifecycle node, for Nav2)",
                         description="The map updater as a ROS 2 lifecycle node: LaserScan, "
                         "odometry and amcl's pose in, map_updated out. Everything after "
                         "--ros-args is ROS's (-p name:=value, --params-file FILE, -r remaps).")
    ros.add_argument("--map", type=Path, default=None,
                     help="map_server YAML of the reference map (default: the transient-local "
                          "'map' topic)")
    ros.add_argument("--config", default=None,
                     help="YAML with 'updater' and 'pose_check' sections; ROS parameters "
                          "(updater.threshold, ...) override it")
    ros.add_argument("--autostart", action="store_true",
                     help="configure and activate at once (without a lifecycle manager)")
    ros.set_defaults(command_at=("robot_commands", "ros2"))


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
    ren.set_defaults(command_at=("testbed_commands", "render"))


def _add_generate(sub) -> None:
    gen = sub.add_parser("generate", help="write a generated warehouse scenario")
    gen.add_argument("--seed", type=int, required=True, help="layout seed")
    gen.add_argument("--out", type=Path, required=True, help="scenario YAML to write")
    gen.add_argument("--size", type=float, nargs=2, default=[30.0, 20.0], metavar=("W", "H"),
                     help="inner size of the building [m], 15 x 10 to 60 x 40 (default 30 20)")
    gen.add_argument("--sessions", type=int, default=4,
                     help="sessions, the mapping session W1 included (default 4)")
    gen.add_argument("--fov", type=int, default=270, help="lidar field of view, 270 or 360")
    gen.set_defaults(command_at=("testbed_commands", "generate"))


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
    sw.set_defaults(command_at=("study_commands", "sweep"))


def _check_update_required(parser, args) -> None:
    """``update`` needs --map and --out unless the map comes from and goes to a store
    (--store), and --log always: said as argparse says a missing required option."""
    missing = [name for name, value, needed in (("--map", args.map, args.store is None),
                                                ("--log", args.log, True),
                                                ("--out", args.out, args.store is None))
               if needed and value is None]
    if missing:
        prog = f"{parser.prog} update"
        parser.exit(2, f"{prog}: error: the following arguments are required: "
                       f"{', '.join(missing)} (see {prog} --help)\n")


def _user_errors() -> tuple[type[BaseException], ...]:
    """The errors a user's input or machine can cause: reported in one line, never a
    traceback. Every package's own error derives from ``MapUpdatingError``."""
    # OSError: the machine's answer to a write or read (a full disk, a read-only folder, no
    # permission), which names the file; the user can act on it
    return (MapUpdatingError, OSError)


def main(argv: list[str] | None = None) -> int:
    full = sys.argv if argv is None else ["mapupdate", *map(str, argv)]
    # ROS 2's arguments (after --ros-args) and ROS 1's remappings and private parameters
    # (``__name:=x``, ``_rate:=5``) are ROS's, not ours
    ours = full[1:full.index("--ros-args")] if "--ros-args" in full else full[1:]
    parser = build_parser()
    args = parser.parse_args([a for a in ours if ":=" not in a])
    if args.command == "update":
        _check_update_required(parser, args)
    args.ros_argv = full
    try:
        # the command's module is loaded only now: a robot's command never loads the testbed
        module, name = args.command_at
        return getattr(importlib.import_module(f"{__package__}.{module}"), name)(args)
    except KeyboardInterrupt:
        print("mapupdate: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - sorted into user errors and bugs just below
        missing = missing_extra(exc)
        if args.debug or not (missing or isinstance(exc, _user_errors())):
            raise
        message = missing or " ".join(str(exc).split())
        print(f"mapupdate {args.command}: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
