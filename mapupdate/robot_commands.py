"""The commands of the robot software: ``update``, ``map``, ``inject``, ``score``, ``compare``,
``store`` and ``ros1``. They need none of the optional extras (a PostgreSQL store needs
psycopg, the ``store`` extra)."""

from __future__ import annotations

import socket
import tempfile
from pathlib import Path

import numpy as np

from evaluation import case_folder, edited_world
from gridmap import load_map, save_map
from gridmap.metrics import compare_maps
from mapstore import StoreError, open_store, report
from mapstore.png import write_diff_png
from robot import logmap, replay
from robot.outputs import check_outputs, map_files, map_inputs
from robot.replay import LogSource, Outputs, Placement
from robot.robot_config import load_robot_config
from robot.ros1.node import run_node
from robotlogs import LogLimits, log_observations

from . import summaries
from .version import __version__


def compare(args) -> int:
    a, b = load_map(args.a), load_map(args.b)
    m = compare_maps(a, b)
    print(f"{'metric':<8}{'value':>10}")
    print(f"{'CC':<8}{m['cc']:>9.2f}%")
    print(f"{'MS':<8}{m['ms']:>9.2f}%")
    print(f"{'OPDF':<8}{m['opdf']:>9.2f}%")
    return 0


def update(args) -> int:
    if args.store is not None:
        return _update_into_store(args)
    summary, _ = _update(args, args.map, args.out, args.trajectory)
    print("\n".join(summaries.update_lines(summary)))
    return 0


def _update(args, map_path, out, trajectory):
    """Run the update of ``map_path`` from the log into ``out``; (summary, configuration)."""
    # the method and --state, then the configuration, are refused before anything is read
    replay.check_update_arguments(args.poses, args.smooth_poses, args.method, args.state)
    config = load_robot_config(args.config, profile=args.profile)
    check_outputs({"--map": map_inputs(map_path), "--log": [args.log],
                   "--config": [args.config] if args.config else [],
                   "--state": [args.state] if args.state and args.state.exists() else [],
                   "--store": store_files(args)},
                  {"--out": map_files(out), "--state": [args.state] if args.state else [],
                   "--trajectory": [trajectory] if trajectory else []},
                  both=("--state",))
    start = None if args.initial_pose is None else replay.parse_pose(args.initial_pose)
    log = LogSource(args.log, format=args.format, strict=args.strict,
                    scan_topics=tuple(args.scan_topic) or None, odom_topic=args.odom_topic,
                    pose_topic=args.pose_topic, limits=log_limits(args))
    placement = Placement(source=args.poses, initial_pose=start,
                          smooth_window=args.smooth_poses, pose_check=args.pose_check,
                          profile=config.profile, localizer_config=config.localizer,
                          pose_check_config=config.pose_check)
    outputs = Outputs(out, state=args.state, trajectory=trajectory)
    # with a saved state and no configuration asked for, the state's own
    asked = args.config is not None or args.profile is not None
    summary = replay.update_from_log(map_path, log, outputs, placement, method=args.method,
                                     updater_config=config.updater if asked else None,
                                     progress=not args.no_progress)
    summary.setdefault("out", str(out))
    summary["profile"], summary["differences"] = config.profile, config.differences()
    return summary, config


# --- update --store: each session a version of the store -----------------------------------

def _update_into_store(args) -> int:
    """Update the store's latest approved map (or ``--map``, which must be it, or which
    starts an empty store) from the log and commit the result as a version whose parent is
    that map. A rejected version is never the start of a session, and no updater state
    (``--state``) carries its evidence over: a session proposes what its own scans show."""
    if args.state is not None:
        raise StoreError("--state does not go with --store: a session committed to a store "
                         "starts from the store's latest approved map with fresh evidence")
    with open_store(args.store, create=True) as store, \
            tempfile.TemporaryDirectory(prefix="mapupdate-") as tmp:
        parent, map_path = _session_start(store, args.map, Path(tmp))
        out = args.out or Path(tmp) / "updated.yaml"
        trajectory = args.trajectory or Path(tmp) / "trajectory.tum"
        summary, config = _update(args, map_path, out, trajectory)
        if parent is None:
            parent = _first_version(store, args.map)
        meta = _session_meta(args, summary, config, trajectory, parent)
        number = store.commit(load_map(out), parent, meta)
        status = store.version(number).status
        if args.out is None:
            summary["out"] = f"{store.name} v{number}"
        if args.trajectory is None:         # the temporary one is not the user's
            summary["trajectory"] = None
        lines = summaries.update_lines(summary)
        lines.append(f"committed v{number} to {store.name} (parent v{parent}; {status}"
                     + (": 'mapupdate store approve' serves it to robots" if status == "pending"
                        else "") + ")")
    print("\n".join(lines))
    return 0


def _session_start(store, map_arg, tmp: Path) -> tuple[int | None, Path]:
    """(the parent version, None for the map given to an empty store; the map file the update
    starts from)."""
    parent = store.latest()
    if map_arg is None:
        if parent is None:
            raise StoreError(f"{store.name}: holds no approved map yet; give --map to start it")
        map_path = tmp / "start.yaml"
        save_map(store.get(parent), map_path)
        return parent, map_path
    if parent is None:
        return None, Path(map_arg)
    grid, latest = load_map(map_arg), store.get(parent)
    if not latest.same_frame(grid) or not np.array_equal(latest.data, grid.data):
        differ = (f"{int(np.count_nonzero(latest.data != grid.data))} cells differ"
                  if latest.same_frame(grid) else "another frame")
        raise StoreError(f"{map_arg} is not the store's latest approved map v{parent} "
                         f"({differ}); leave --map out to start from it")
    return parent, Path(map_arg)


def _first_version(store, map_arg) -> int:
    """The map given to an empty store, committed as its first version once the session that
    starts from it has run (a failed session leaves the store as it was)."""
    first = store.commit(load_map(map_arg), None, {"method": "import", "source": str(map_arg),
                                                   "project_version": __version__},
                         status="approved")
    print(f"committed {map_arg} to {store.name} as v{first}, the first map")
    return first


def _session_meta(args, summary: dict, config, trajectory: Path, parent: int) -> dict:
    """What made the version: robot, log, time span, scans, method and configuration."""
    times = _tum_times(trajectory)
    keys = ("scans", "scans_used", "scans_processed", "scans_refused_by_pose_check",
            "scans_dropped_as_lost", "scans_gated", "scans_off_map", "scans_not_tracking",
            "scans_without_pose")
    return {"robot": args.robot or socket.gethostname(), "log": str(Path(args.log).resolve()),
            "log_name": Path(args.log).name, "format": summary.get("format"),
            "time_span": [times[0], times[-1]] if times else None,
            "scans": {k: int(summary.get(k) or 0) for k in keys},
            "method": args.method, "pose_source": summary.get("pose_source"),
            "pose_check": config.use_pose_check if args.pose_check is None else args.pose_check,
            "profile": config.profile,
            "config": {"profile": config.profile, "updater": config.updater.to_dict(),
                       "localizer": config.localizer.to_dict(),
                       "pose_check": config.pose_check.to_dict()},
            "started_from": parent, "project_version": __version__}


def _tum_times(path: Path) -> list[float]:
    if not path.exists():
        return []
    return [float(line.split()[0]) for line in path.read_text().splitlines()
            if line.strip() and not line.startswith("#")]


def log_limits(args) -> LogLimits:
    """What a CARMEN log may hold, and whether one cut short is read: the log options."""
    return LogLimits(args.max_log_lines, args.max_log_bytes, args.refuse_truncated)


def map_command(args) -> int:
    check_outputs({"--log": [args.log]}, {"--out": map_files(args.out)})
    summary = logmap.map_from_log(args.log, args.out, resolution=args.resolution,
                                  pose_source=args.poses, log_format=args.format,
                                  strict=args.strict, scan_topics=args.scan_topic or None,
                                  odom_topic=args.odom_topic, pose_topic=args.pose_topic,
                                  limits=log_limits(args), progress=not args.no_progress)
    print("\n".join(summaries.map_lines(summary)))
    return 0


def inject(args) -> int:
    case_folder.check_case_dir(args.out, args.map, args.log)      # before anything is read
    grid = load_map(args.map)
    found = log_observations(args.log, log_format=args.format, strict=args.strict,
                             scan_topics=args.scan_topic or None, odom_topic=args.odom_topic,
                             pose_topic=args.pose_topic, limits=log_limits(args))
    case = edited_world.make_case(grid, found.observations, args.seed, removed=args.removed,
                                  added=args.added, moved=args.moved, people=args.people,
                                  min_views=args.min_views, progress=not args.no_progress)
    case_folder.write_case(case, args.out, map_path=args.map, log_path=args.log)
    lines = case_folder.case_lines(case, args.out)
    if found.stats.cut:
        lines.append(f"  warning: {found.stats.cut}")
    print("\n".join(lines))
    return 0


def score(args) -> int:
    if args.json is not None:
        check_outputs({"DIR": [args.case / f for f in case_folder.CASE_FILES],
                       "OUT.yaml": map_inputs(args.updated)}, {"--json": [args.json]})
    scores = case_folder.score_case(args.case, load_map(args.updated))
    print("\n".join(case_folder.score_lines(scores)))
    if args.json is not None:
        case_folder.write_scores(scores, args.json)
        print(f"wrote {args.json}")
    return 0


# --- store ---------------------------------------------------------------------------------

def store(args) -> int:
    create = args.action == "init"
    with open_store(args.store, create=create) as st:
        lines = STORE_ACTIONS[args.action](st, args)
    print("\n".join(lines))
    return 0


def _store_init(st, args) -> list[str]:
    if args.require_approval is not None:
        st.set_require_approval(args.require_approval)
    rule = ("new versions wait for 'mapupdate store approve'" if st.require_approval
            else "new versions are served at once")
    return [f"{st.name}: a map store of {len(st.log())} versions; {rule}"]


def store_files(args) -> list[Path]:
    """The files of ``--store`` that no output may be: an SQLite store and its journal files
    (a PostgreSQL URL has none here)."""
    target = getattr(args, "store", None)
    if target is None or str(target).startswith(("postgresql://", "postgres://")):
        return []
    return [Path(f"{target}{suffix}") for suffix in ("", "-wal", "-shm", "-journal")]


def _store_diff(st, args) -> list[str]:
    a, b = st.resolve(args.a), st.resolve(args.b)
    changes = st.diff(a, b)
    after = st.get(b)
    lines = report.diff_lines(a, b, changes, after.shape)
    if args.png is not None:
        check_outputs({"--store": store_files(args)}, {"--png": [args.png]})
        before = after.data.copy().reshape(-1)
        before[changes.index] = changes.before
        w, h = write_diff_png(args.png, before.reshape(after.shape), after.data)
        lines.append(f"wrote {args.png} ({w} x {h} px)")
    return lines


def _store_export(st, args) -> list[str]:
    number = st.resolve(args.version)
    check_outputs({"--store": store_files(args)}, {"--out": map_files(args.out)})
    grid = st.get(number)
    save_map(grid, args.out)
    return [f"wrote {args.out}: v{number} ({st.version(number).status}), {grid.width} x "
            f"{grid.height} cells at {grid.resolution:g} m"]


def _store_tag(st, args) -> list[str]:
    if args.version is None:
        tags = [(t, v.number) for v in st.log() for t in v.tags]
        return [f"{t:<24}v{n}" for t, n in sorted(tags)] or [f"{st.name}: no tags"]
    if args.name is None:
        raise StoreError("tag needs a version and a name (or neither, to list the tags)")
    return [f"{args.name} -> v{st.tag(args.version, args.name)}"]


def _store_review(st, args) -> list[str]:
    number = (st.approve if args.action == "approve" else st.reject)(args.version, args.note)
    done = {"approve": "approved", "reject": "rejected"}[args.action]
    return [f"v{number} {done}" + ("; robots now start from it"
                                           if number == st.latest() else "")]


STORE_ACTIONS = {
    "init": _store_init,
    "log": lambda st, args: report.log_lines(st.log(), st.name, st.require_approval),
    "show": lambda st, args: report.show_lines(st.version(args.version)),
    "diff": _store_diff,
    "export": _store_export,
    "rollback": lambda st, args: [f"v{st.rollback(args.version)}: a copy of "
                                  f"v{st.resolve(args.version)}, approved; robots now start "
                                  "from it"],
    "tag": _store_tag,
    "approve": _store_review,
    "reject": _store_review,
}


def ros1(args) -> int:
    # an empty --config (a launch file's unset argument) means none
    return run_node(args.map, args.config or None, args.ros_argv)


def ros2(args) -> int:
    from robot.ros2.node import run_node as run_ros2_node    # rclpy: the [ros2] extra

    return run_ros2_node(args.map, args.config or None, args.autostart, args.ros_argv)
