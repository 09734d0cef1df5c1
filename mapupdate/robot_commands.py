"""The commands of the robot software: ``update``, ``map``, ``inject``, ``score``, ``compare``,
``store`` and ``ros1``. They need none of the optional extras (a PostgreSQL store needs
psycopg, the ``store`` extra)."""

from __future__ import annotations

import inspect
import os
import shlex
import socket
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from evaluation import case_folder, edited_world
from gridmap import MapUpdatingError, load_map, save_map
from gridmap.metrics import compare_maps
from mapstore import StoreError, open_store, report, spool
from mapstore.backends import is_url, redacted
from mapstore.png import write_diff_png
from onboard import logmap, replay
from onboard.outputs import check_outputs, map_files, map_inputs
from onboard.replay import LogSource, Outputs, Placement
from onboard.robot_config import load_robot_config
from onboard.ros1.node import run_node
from robotlogs import LogError, LogLimits, log_observations

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
    if getattr(args, "new_session", False) and args.state is None:
        raise LogError("--new-session starts the next session from a state: give --state FILE "
                       "too (without a state every update is a new session)")
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
                                     progress=not args.no_progress,
                                     new_session=getattr(args, "new_session", False))
    summary.setdefault("out", str(out))
    summary["profile"], summary["differences"] = config.profile, config.differences()
    return summary, config


# --- update --store: each session a version of the store -----------------------------------

def _update_into_store(args) -> int:
    """Update the store's latest approved map (or ``--map``, which must be it, or which
    starts an empty store) from the log and commit the result as a version whose parent is
    that map. A rejected version is never the start of a session, and no updater state
    (``--state``) carries its evidence over: a session proposes what its own scans show.

    The store is open only to read the parent (after pushing what the spool holds for it)
    and, once the session has run, to commit; when that commit fails, the session is kept in
    the spool (exit 3) for ``mapupdate store push``: no session's map is lost."""
    if args.state is not None:
        raise StoreError("--state does not go with --store: a session committed to a store "
                         "starts from the store's latest approved map with fresh evidence")
    folder = spool.folder(args.spool)
    uid = spool.new_uid()
    spool.remove_stale_work()
    why = spool.writable(folder)
    if why is not None:
        print(f"mapupdate update: warning: the spool cannot be written ({why}): a failed "
              "commit would lose this session's map (--spool DIR or $MAPUPDATE_SPOOL)",
              file=sys.stderr)
    with spool.working_folder() as tmp:
        with _open_to_start(args) as store:
            _push_spool(store, spool.entries(folder, args.store)[0], at_start=True)
            parent, map_path = _session_start(store, args.map, tmp)
        first = load_map(args.map) if parent is None else None
        out = args.out or tmp / "updated.yaml"
        trajectory = args.trajectory or tmp / "trajectory.tum"
        summary, config = _update(args, map_path, out, trajectory)
        meta = {**_session_meta(args, summary, config, trajectory, parent), "uid": uid}
        session = spool.Session(uid, load_map(out), parent, meta, first,
                                _first_meta(args.map) if first is not None else None)
        if args.trajectory is None:         # the temporary one is not the user's
            summary["trajectory"] = None
        try:
            with open_store(args.store) as store:
                done = _commit_session(store, session)
                line = _committed_line(store, done)
        except (StoreError, KeyboardInterrupt) as e:
            return _spooled(args, folder, session, summary, e)
    if args.out is None:
        summary["out"] = f"{store.name} v{done.number}"
    if done.first is not None:
        print(f"committed {args.map} to {store.name} as v{done.first}, the first map")
    print("\n".join(summaries.update_lines(summary) + [line]))
    return 0


def _open_to_start(args):
    """The store a session starts from. A missing or empty one is made only when --map gives
    the map it starts from: a mistyped --store names itself and leaves nothing behind."""
    target = args.store
    if args.map is not None:
        return open_store(target, create=True)
    try:
        return open_store(target)
    except StoreError as e:       # the store's own refusals (a misspelt URL, ...) stand
        if is_url(target) or Path(target).exists() or "no map store there" not in str(e):
            raise
    raise StoreError(f"{redacted(target)}: no map store there, so it holds no approved map "
                     "yet; give --map to start it (nothing was made)")


# the exit code of update and store push when a session's map waits in the spool
SPOOLED = 3


def _spooled(args, folder: Path, session, summary: dict, error: BaseException) -> int:
    """Keep the session whose commit failed in the spool and say where, in one line."""
    text = " ".join(str(error).split()) or "interrupted"
    try:
        entry = spool.write(folder, args.store, session, text)
    except OSError as e:
        raise StoreError(f"not committed ({text}), and the spool cannot keep the session's map "
                         f"({e})") from None
    if args.out is None:
        summary["out"] = entry.path / "map.yaml"
    print("\n".join(summaries.update_lines(summary)))
    print(f"mapupdate update: not committed ({text}); the session's map is kept in "
          f"{entry.path}; commit it later with: {_push_command(args.store, args.spool)}",
          file=sys.stderr)
    return 130 if isinstance(error, KeyboardInterrupt) else SPOOLED


def _push_command(target, spool_arg) -> str:
    """The command that pushes the spool: the store without a password, --spool when the
    spool is not the default one."""
    folder = spool_arg if spool_arg is not None else os.environ.get(spool.ENV) or None
    return f"mapupdate store push --store {shlex.quote(spool.target_name(target))}" + (
        f" --spool {shlex.quote(str(Path(folder).expanduser().resolve()))}" if folder else "")


@dataclass
class _Done:
    number: int                     # the session's version
    parent: int
    already: bool                   # it was in the store already (an earlier push's)
    first: int | None = None        # the first map's version, when this commit made it


def _commit_session(store, session) -> _Done:
    """Commit a session (its first map first, when it started an empty store), each at most
    once whatever is retried: a commit carries its uid."""
    parent, first = session.parent, None
    if parent is None:
        parent, already = _commit_once(store, session.first, None, session.first_meta,
                                       f"{session.uid}-first", status="approved")
        first = None if already else parent
    meta = {**session.meta, "started_from": parent}
    number, already = _commit_once(store, session.grid, parent, meta, session.uid)
    return _Done(number, parent, already, first)


def _commit_once(store, grid, parent, meta, uid, status=None) -> tuple[int, bool]:
    """(the version's number, whether it was in the store already). The store finds a uid
    it holds and writes nothing; a store that takes no uid yet is searched for it."""
    meta = {**meta, "uid": uid}
    head = store.latest(approved_only=False)
    if "uid" in inspect.signature(store.commit).parameters:
        number = store.commit(grid, parent, meta, status=status, uid=uid)
    else:
        held = [v.number for v in store.log() if v.meta.get("uid") == uid]
        if held:
            return held[0], True
        number = store.commit(grid, parent, meta, status=status)
    return number, head is not None and number <= head


def _committed_line(store, done: _Done) -> str:
    if done.already:
        return f"v{done.number} was in {store.name} already {_outcome(store, done)}"
    return f"committed v{done.number} to {store.name} {_outcome(store, done)}"


def _outcome(store, done: _Done) -> str:
    """"(parent v9; approved), merged with v10 as v11 (2 conflicts)"."""
    status = store.version(done.number).status
    if done.already:
        return f"(parent v{done.parent}; {status})"
    return (f"(parent v{done.parent}; {status}"
            + (": 'mapupdate store approve' serves it to robots" if status == "pending" else "")
            + ")" + _merged_text(store, done.number))


def _merged_text(store, number: int) -> str:
    """", merged with v6 as v8 (3 conflicts)" when the store merged the commit with what came
    since its parent, else ""."""
    merged = getattr(store, "merged", None)
    if not merged or merged == number:
        return ""
    info = store.version(merged)
    other = info.parent if info.parent != number else getattr(info, "merge_parent", None)
    n = int(info.counts.get("conflicts", (info.meta.get("cells") or {}).get("conflicts", 0)))
    return (f", merged with v{other}" if other is not None else ", merged") + \
        f" as v{merged} ({n} conflict{'' if n == 1 else 's'})"


def _push_spool(store, found: list, at_start: bool = False) -> list[str]:
    """Commit the spooled sessions ``found`` for this store, oldest first, each with its own
    parent and uid; an entry is removed once its commit succeeded. Stops at the first that
    fails (the rest keep their order: the store settles a merge's conflicts by commit order).
    Prints a line per entry; returns the names of those kept."""
    if at_start and found:
        print(f"pushing {len(found)} spooled session{'' if len(found) == 1 else 's'} for "
              f"{store.name} first")
    kept, failed = [], None
    for entry in found:
        if failed is not None:
            print(f"kept {entry.name}: not tried, as {failed} before it was kept")
            kept.append(entry.name)
            continue
        try:
            done = _commit_session(store, entry.session())
            text = _outcome(store, done)
        except (MapUpdatingError, OSError, KeyError, ValueError) as e:   # a store's, a file's
            print(f"kept {entry.name}: {' '.join(str(e).split()) or type(e).__name__}")
            kept.append(failed := entry.name)
            continue
        spool.remove(entry)
        first = f", its first map as v{done.first}" if done.first is not None else ""
        print(f"pushed {entry.name}: " + (f"already in the store as v{done.number} {text}"
                                          if done.already else f"v{done.number} {text}{first}"))
    return kept


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


def _first_meta(map_arg) -> dict:
    """What made the first version of a store: the map given to start it, committed (approved:
    a store starts from a map someone chose) once the session that starts from it has run (a
    failed session leaves the store as it was)."""
    return {"method": "import", "source": str(map_arg), "project_version": __version__}


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
    source = logmap.LogSource(Path(args.log), format=args.format, strict=args.strict,
                              scan_topics=tuple(args.scan_topic) if args.scan_topic else None,
                              odom_topic=args.odom_topic, pose_topic=args.pose_topic,
                              limits=log_limits(args))
    summary = logmap.map_from_log(source, args.out, resolution=args.resolution,
                                  pose_source=args.poses, progress=not args.no_progress)
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
    if args.action == "push":
        return push(args)
    create = args.action == "init"
    with open_store(args.store, create=create) as st:
        lines = STORE_ACTIONS[args.action](st, args)
    print("\n".join(lines))
    return 0


def push(args) -> int:
    """``store push``: commit the spool's sessions for the store; 0 when none is left, 3
    when some stay."""
    folder = spool.folder(args.spool)
    found, others, bad = spool.entries(folder, args.store)
    for name, why in bad:
        print(f"skipped {folder / name}: not a spool entry ({why})")
    if not found:
        print(f"{spool.target_name(args.store)}: no spooled sessions in {folder}"
              + (f" ({others} for other stores)" if others else ""))
        return 0
    try:
        st = open_store(args.store)
    except StoreError as e:
        for entry in found:
            print(f"kept {entry.name}: {' '.join(str(e).split())}")
        return SPOOLED
    with st:
        kept = _push_spool(st, found)
    return SPOOLED if kept else 0


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
    if target is None or is_url(str(target)):
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
    if st.merged is not None:           # a sibling of the latest: merged with it
        n = len(st.conflicts(st.merged))
        return [f"v{number} {done}, merged with the latest as v{st.merged} ({n} conflict"
                f"{'s' * (n != 1)}); robots now start from v{st.merged}"]
    return [f"v{number} {done}" + ("; robots now start from it"
                                           if number == st.latest() else "")]


def _store_show(st, args) -> list[str]:
    v = st.version(args.version)
    lines = report.show_lines(v)
    conflicts = st.conflicts(v.number)
    if conflicts is not None:
        lines += report.conflict_lines(conflicts, v.shape)
    return lines


STORE_ACTIONS = {
    "init": _store_init,
    "log": lambda st, args: report.log_lines(st.log(), st.name, st.require_approval),
    "show": _store_show,
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
    from onboard.ros2.node import run_node as run_ros2_node    # rclpy: the [ros2] extra

    return run_ros2_node(args.map, args.config or None, args.autostart, args.ros_argv)
