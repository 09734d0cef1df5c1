"""What a run keeps so that a killed run can be resumed: ``mapupdate run --resume DIR``.

A run's folder holds, besides its outputs, ``state/``:

- ``run.json``: what defines the run (scenario file and a hash of its text, seed, sessions asked
  for, quick routes, the pose check, the configurations), written once at the start;
- ``session_<name>.json`` and ``session_<name>.npz``: a finished session's metrics and
  trajectories, and ``faces_<name>.npz`` what its updater carries to the next session (the
  faces rule's counts, ``updater.FaceCounts``); its maps (M_i, G_i, the oracle, the evaluation masks) are in ``maps/``, its
  TUM trajectories in ``trajectories/`` and its figures in the run's folder;
- ``progress.json``: the finished sessions in order. It is written last, after everything of
  the session is on disk, so it is the commit point: a session not listed there is run again.

Every file is written with ``gridmap.atomic`` (a temporary name, flushed, renamed), so a run
killed at any instant leaves each file either as it was or complete. What the next session
needs is M_{i-1} and M1 (and the seeds, which are derived per session from the scenario's
seed): maps are saved as trinary images, which load back cell for cell, so a resumed run ends
with the same maps as a run that was never interrupted. A resumed run reads back only what the next sessions need (M1, the
last finished session whole, the metrics of the others), so its memory does not grow with the
number of sessions finished.
"""

from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np

from gridmap import MapUpdatingError, load_map
from gridmap.atomic import write_atomically, write_with
from gridmap.files import read_text
from onboard.robot_config import section_config
from updater import FaceCounts

from .catalog import find_scenario
from .options import RunOptions
from .report import json_default, session_output_paths, write_session_outputs
from .session import SessionResult, Trajectory

FORMAT = 1


class ResumeError(MapUpdatingError, ValueError):
    """A run folder that cannot be resumed, or options that contradict it; names the file."""


def state_dir(out_dir) -> Path:
    return Path(out_dir) / "state"


class RunFolderLock:
    """Holds ``DIR/state/lock`` for the life of a run, so that no second run writes into the
    same folder at once (their maps and reports would mix). An advisory ``flock``: the kernel
    drops it when the process dies, so a killed run leaves no stale lock behind."""

    def __init__(self, out_dir):
        self.path = state_dir(out_dir) / "lock"
        self._file = None

    def __enter__(self) -> RunFolderLock:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        f = open(self.path, "a+")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "another process"
            f.close()
            raise ResumeError(f"{self.path.parent.parent}: another run is writing into this "
                              f"folder ({holder}); wait for it or choose another --out") from None
        f.seek(0)
        f.truncate()
        f.write(f"pid {os.getpid()}\n")
        f.flush()
        self._file = f
        return self

    def __exit__(self, *exc) -> None:
        if self._file is not None:
            self._file.close()        # closing releases the lock
            self._file = None


def remove_partial_files(out_dir) -> list[Path]:
    """Remove the temporary files a killed run left half-written (``gridmap.atomic`` names
    them ``.<name>.<pid>.<thread>.tmp``; they never got their real name). Returns them."""
    pattern = re.compile(r"\..+\.\d+(\.\d+)?\.tmp")
    gone = [p for p in Path(out_dir).rglob(".*.tmp") if p.is_file() and pattern.fullmatch(p.name)]
    for p in gone:
        p.unlink(missing_ok=True)
    return gone


def check_new_run_folder(out_dir) -> None:
    """A new run (not --resume) may go into a missing or empty folder, or one without a run;
    never over another run's outputs, whose files would then describe two runs."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ResumeError(f"{out}: exists and is not a folder; --out names the run's folder")
    if (state_dir(out) / "run.json").exists():
        raise ResumeError(f"{out}: holds a run already; continue it with --resume {out} or "
                          "choose another --out")


def _write_json(path: Path, data: dict) -> None:
    write_atomically(path, json.dumps(data, indent=1, default=json_default) + "\n")


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(read_text(path, "run state file"))
    except FileNotFoundError:
        raise ResumeError(f"{path}: missing") from None
    except (MapUpdatingError, OSError, ValueError, RecursionError) as e:
        raise ResumeError(f"{path}: unreadable ({e})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ResumeError(f"{path}: not a run state file of format {FORMAT}")
    return data


# The configurations a run records in run.json, each under its key, and their sections of
# robot_config, through which they are read back (validated like a --config file).
CONFIG_KEYS = {"updater_config": "updater", "localizer_config": "localizer",
               "pose_check_config": "pose_check"}


def _config_dict(config) -> dict | None:
    return None if config is None else config.to_dict()


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# --- the manifest ----------------------------------------------------------------------------
def write_manifest(out_dir, scenario_path: Path, seed: int, options) -> None:
    """Start a fresh run in ``out_dir``: record what defines it, forget any earlier progress."""
    folder = state_dir(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "progress.json").unlink(missing_ok=True)
    _write_json(folder / "run.json", {
        "format": FORMAT,
        "scenario_file": str(Path(scenario_path).resolve()),
        "scenario_sha256": _sha256(scenario_path),
        "seed": seed,
        "sessions": options.sessions,
        "quick": bool(options.quick),
        "pose_check": bool(options.pose_check),
        "profile": options.profile,
        "method": options.method,
        "updater_config": _config_dict(options.updater_config),
        "localizer_config": _config_dict(options.localizer_config),
        "pose_check_config": _config_dict(options.pose_check_config),
    })


def resume_options(scenario, options):
    """(scenario path, options) of the run recorded in ``options.out``. The recording wins;
    an option or scenario given that contradicts it is refused, since the resumed run would
    then not be the same run. ``sessions`` may be given (a run can be continued further);
    without it the run goes as far as it was asked to."""
    if options.out is None:
        raise ResumeError("resuming needs the folder of the run to resume")
    path = state_dir(options.out) / "run.json"
    if not path.exists():
        raise ResumeError(f"{options.out}: no run to resume here (no {path.name} in "
                          f"{path.parent})")
    m = _read_json(path)
    missing = [k for k in ("scenario_file", "scenario_sha256", "seed", "sessions", "quick",
                           "pose_check", *CONFIG_KEYS) if k not in m]
    if missing:
        raise ResumeError(f"{path}: lacks {', '.join(missing)}; it cannot be resumed")
    scenario_file = Path(str(m["scenario_file"]))
    if scenario is not None and find_scenario(scenario).resolve() != scenario_file:
        raise ResumeError(f"{path}: the run played {scenario_file}, not {scenario}")
    if not scenario_file.exists() or _sha256(scenario_file) != m["scenario_sha256"]:
        raise ResumeError(f"{path}: the scenario file {scenario_file} changed or vanished since "
                          "the run started; start a new run")
    default = RunOptions()
    # runs recorded before methods: paper; before profiles: the classes' defaults, paper's
    recorded = {"seed": m["seed"], "quick": m["quick"], "pose_check": m["pose_check"],
                "method": m.get("method", "paper"), "profile": m.get("profile", "paper")}
    for key, value in recorded.items():
        given = getattr(options, key)
        if given is not None and given != getattr(default, key) and given != value:
            raise ResumeError(f"{path}: the run has {key} = {value}, not {given}")
    rebuilt = {}
    for key, section in CONFIG_KEYS.items():
        given = getattr(options, key)
        # keys given over the profile (a --config file's section): each as the run has it
        differs = any((m[key] or {}).get(k, object()) != v for k, v in given.items()) \
            if isinstance(given, dict) else _config_dict(given) != m[key]
        if given is not None and differs:
            raise ResumeError(f"{path}: {key} differs from the one the run started with")
        if isinstance(given, dict):
            given = None
        rebuilt[key] = given if given is not None or m[key] is None else \
            _recorded_config(section, m[key], path, key)
    sessions = m["sessions"] if options.sessions is None else options.sessions
    return scenario_file, dataclasses.replace(options, **recorded, **rebuilt, sessions=sessions)


def _recorded_config(section: str, values, path: Path, key: str):
    """A configuration run.json recorded under ``key``, read as a --config file's section."""
    try:
        return section_config(section, values, str(path), where=f"'{key}'")
    except MapUpdatingError as e:
        raise ResumeError(str(e)) from None


# --- sessions ----------------------------------------------------------------------------------
def save_session(out_dir, results: list, wall_time_s: float) -> None:
    """After the last of ``results`` has its maps on disk: its metrics and trajectories, then
    the progress file naming every finished session (the commit point)."""
    folder = state_dir(out_dir)
    res = results[-1]
    _write_json(folder / f"session_{res.name}.json", {"format": FORMAT, "metrics": res.metrics})
    if res.trajectory is not None:
        arrays = res.trajectory.arrays()
        write_with(folder / f"session_{res.name}.npz", lambda f: np.savez(f, **arrays))
    if res.faces is not None:
        counts = {"hits": res.faces.hits, "passes": res.faces.passes,
                  "behind": res.faces.behind, "confirmed": res.faces.confirmed}
        write_with(folder / f"faces_{res.name}.npz",
                   lambda f: np.savez_compressed(f, **counts))
    _write_json(folder / "progress.json", {"format": FORMAT,
                                           "finished": [r.name for r in results],
                                           "wall_time_s": wall_time_s})


def finished_sessions(out_dir, scenario, n: int) -> tuple[list, float]:
    """The results of the sessions a run in ``out_dir`` finished (at most ``n``), read back as
    a run keeps them (see ``runner.RunResult``): the last one whole, the first with M1, the
    others their name and metrics only; and the wall time they took."""
    path = state_dir(out_dir) / "progress.json"
    if not path.exists():
        return [], 0.0
    progress = _read_json(path)
    names = [s.name for s in scenario.sessions]
    done = progress["finished"][:n]
    if done != names[:len(done)]:
        raise ResumeError(f"{path}: finished sessions {done} are not the scenario's first "
                          f"sessions {names[:len(done)]}")
    results = []
    for k, name in enumerate(done):
        if k == len(done) - 1:
            res = load_session(out_dir, name, done[k - 1] if k else None)
        else:
            res = SessionResult(name, None, None, metrics=_metrics(out_dir, name))
            if k == 0:
                res.updated = load_map(Path(out_dir) / "maps" / f"M_{name}.yaml")
        results.append(res)
    return results, float(progress.get("wall_time_s", 0.0))


def _metrics(out_dir, name: str) -> dict:
    return _read_json(state_dir(out_dir) / f"session_{name}.json")["metrics"]


def load_session(out_dir, name: str, previous: str | None = None):
    """The full result of the finished session ``name``, read back from ``out_dir``;
    ``previous``: the name of the session before it (None for the mapping session)."""
    maps = Path(out_dir) / "maps"
    res = SessionResult(name, load_map(maps / f"M_{name}.yaml"),
                        load_map(maps / f"G_{name}.yaml"), metrics=_metrics(out_dir, name))
    if previous is not None:
        res.previous = load_map(maps / f"M_{previous}.yaml")
        res.oracle = load_map(maps / f"oracle_{name}.yaml")
        res.trajectory = _trajectory(state_dir(out_dir) / f"session_{name}.npz", Trajectory)
        res.masks = _arrays(maps / f"masks_{name}.npz")
        faces = state_dir(out_dir) / f"faces_{name}.npz"
        if faces.exists():
            z = _arrays(faces, ("hits", "passes", "behind", "confirmed"))
            res.faces = FaceCounts(z["hits"], z["passes"], z["behind"], None, z["confirmed"])
    return res


def restore_session_outputs(out_dir, names: list[str]) -> list[str]:
    """Write the TUM trajectories and figures of the finished update sessions ``names[1:]``
    that lack them (a run folder of an earlier version wrote them only at the end of the
    run), with one session in memory at a time. Returns the names of the sessions written."""
    written = []
    for k in range(1, len(names)):
        if all(p.exists() for p in session_output_paths(out_dir, names[k])):
            continue
        write_session_outputs(out_dir, load_session(out_dir, names[k], names[k - 1]))
        written.append(names[k])
    return written


def _arrays(path: Path, keys: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """The arrays of a run's ``.npz`` file, never its pickled objects; a file that is not what
    the run wrote (truncated, overwritten, pickled, lacking ``keys``) is a ``ResumeError``
    naming it."""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    # zipfile, zlib and numpy's header parser raise many kinds of error for damaged bytes
    except Exception as e:  # noqa: BLE001
        raise ResumeError(f"{path}: not a file this run wrote ({type(e).__name__}: "
                          f"{' '.join(str(e).split())[:200]}); the run cannot be resumed "
                          "from it") from None
    missing = [k for k in keys if k not in arrays]
    if missing:
        raise ResumeError(f"{path}: lacks {', '.join(missing)}; the run cannot be resumed "
                          "from it")
    return arrays


def _trajectory(path: Path, cls):
    z = _arrays(path, ("time", "true", "previous_map", "initial_map"))
    traj = cls()
    traj.time = list(z["time"])
    traj.true = list(z["true"])
    traj.previous_map = list(z["previous_map"])
    traj.initial_map = list(z["initial_map"])
    return traj
