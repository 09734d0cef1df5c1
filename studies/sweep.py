"""Studies: the cross product of scenarios, seeds, methods and configuration values, run on a
local process pool or as Ray tasks, with resumable per-run results.

    mapupdate sweep study.yaml --out DIR [--workers N] [--ray auto|ADDRESS]

The spec (YAML)::

    scenarios: [aws_small_warehouse, {generate: {seeds: [1, 2, 3], size: [30, 20], sessions: 3}}]
    seeds: [7, 8]                        # run seeds (default: each scenario's own)
    methods: [paper, hybrid, fuse, remap, none]  # onboard.methods.METHODS (default: paper)
    quick: true                          # the quick routes of `mapupdate run --quick`
    sessions: 3                          # the first K sessions only (default: all)
    profile: robot                       # robot (default) or paper, or a list of both to compare
    config: {updater: {fill_gaps: true}} # keys over the profile, as --config reads them
    grid: {updater.threshold: [5, 7, 9]} # dotted keys into the configuration's sections

Every spec error (an unknown key, an unknown method, an empty list, a grid key that is not a
configuration key, a value the configuration refuses) is refused, with the nearest valid name,
before any run starts. Each run is ``runner.run_scenario`` with the options ``mapupdate run``
would give it, in its own folder ``DIR/runs/<key>/``; when it ends, its rows go atomically to
``DIR/runs/<key>/result.json``, which marks it finished: the same command run again skips it,
so a killed sweep resumes. Generated scenarios are written once to ``DIR/scenarios/``. At the
end ``studies.study_report`` writes ``DIR/results.csv``, ``DIR/summary.md`` and the box
plots.

A study folder belongs to one spec, as a run folder belongs to one run: a sweep of another
spec into it is refused (``sweep.json`` keeps the checked spec), and a second sweep into it at
the same moment is refused by ``DIR/state/lock``. The pool's workers die with the sweep, even
a sweep killed with SIGKILL. A spec file that is not a small text file (a FIFO, a device, over
256 KB) or whose YAML aliases expand without bound is refused before it is parsed or expanded.
"""

from __future__ import annotations

import ctypes
import json
import multiprocessing
import os
import re
import shutil
import signal
import sys
import threading
import time
from contextlib import contextmanager
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

from tqdm import tqdm

import sim
from gridmap import MapUpdatingError
from gridmap.atomic import write_atomically
from gridmap.config import check_profile
from gridmap.files import (MAX_TEXT_BYTES, FileInputError, check_regular_file, load_yaml,
                           parse_yaml, read_text)
from gridmap.suggest import did_you_mean
from onboard.methods import check_method
from onboard.robot_config import CLASSES, SECTIONS, load_robot_config, section_config
from scenarios.catalog import find_scenario
from scenarios.checkpoint import ResumeError, RunFolderLock, _sha256
from scenarios.generator import check_arguments, write_generated
from scenarios.runner import MAX_SEED, RunOptions, run_scenario

from .study_report import RUN_KEY_CHARS, StudyFolderError, _json, session_rows, summarise
from .sweep_ray import check_address, ray_tasks, require_ray

SPEC_KEYS = ("scenarios", "seeds", "methods", "profile", "quick", "sessions", "config", "grid")
# The most runs one spec may ask for (the study of 20 warehouses x 3 seeds x 5 methods is 300;
# what a run costs is in benchmarks/RESULTS.md).
MAX_RUNS = 10_000
# A spec is a few hundred bytes and 10 000 seeds take 60 KB; YAML is parsed at about 100 KB/s,
# so a bigger file is refused before it is parsed, within a second.
MAX_SPEC_BYTES = 256 * 1024
MAX_SESSIONS = 10_000              # as many as a scenario file may list
MAX_PATH_CHARS = 4096              # PATH_MAX of Linux
PR_SET_PDEATHSIG = 1               # <linux/prctl.h>
PARENT_POLL = 0.5                  # [s] how often a worker without it checks on its parent
# What a study folder holds before its sweep.json is written (a sweep killed while planning).
STUDY_ENTRIES = ("runs", "scenarios", "state")
GENERATE_KEYS = ("seeds", "size", "sessions", "fov")
RESULT_FORMAT = 1


class SweepError(MapUpdatingError, ValueError):
    """A sweep spec or study folder that cannot be used; the message names the file and key."""


@dataclass(frozen=True)
class RunSpec:
    """One run of a study: what ``mapupdate run`` is asked, and where its outputs go."""

    key: str                   # its folder under DIR/runs
    scenario: str              # the scenario's name
    scenario_file: str
    seed: int | None           # None: the scenario's own
    method: str
    quick: bool
    sessions: int | None
    config: dict               # robot configuration sections (base and grid point)
    point: dict = field(default_factory=dict)   # the grid point: dotted key -> value

    def definition(self) -> dict:
        """What makes the run this run (its result is reused only for the same)."""
        d = asdict(self)
        d["scenario_sha256"] = _sha256(Path(self.scenario_file))
        return d


# --- the spec --------------------------------------------------------------------------------
def _show(value, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters: a message stays one short line whatever
    the spec holds (a list of 80 000 seeds, an integer of 5000 digits)."""
    try:
        text = repr(value)
    except (ValueError, RecursionError):     # more digits than Python prints; a nest too deep
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _one_line(text: str, limit: int = 400) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _fail(source: str, key: str, message: str):
    raise SweepError(_one_line(f"{source}: {key}: {message}" if key else f"{source}: {message}"))


def _nonempty_list(value, source: str, key: str) -> list:
    if not isinstance(value, list):
        _fail(source, key, f"expected a list, got {type(value).__name__}")
    if not value:
        _fail(source, key, "the list is empty")
    return value


def _integers(value, source: str, key: str, minimum: int = 0,
              maximum: int = MAX_SEED) -> list[int]:
    for j, v in enumerate(_nonempty_list(value, source, key)):
        if isinstance(v, bool) or not isinstance(v, int) or not minimum <= v <= maximum:
            _fail(source, f"{key}[{j}]", f"expected an integer in [{minimum}, {maximum}], got "
                                         f"{_show(v)}")
    if len(set(value)) != len(value):
        _fail(source, key, f"a value is listed twice: {_show(value)}")
    return list(value)


def _check_keys(node, known, source: str, key: str) -> dict:
    if not isinstance(node, dict):
        _fail(source, key, f"expected a mapping, got {type(node).__name__}")
    for k in node:
        if k not in known:
            name = k if isinstance(k, str) and len(k) <= 60 and k.isprintable() else _show(k)
            hint = did_you_mean(k, known) if isinstance(k, str) else ""
            _fail(source, f"{key}.{name}" if key else name,
                  f"unknown key {_show(k)}{hint} (keys: {', '.join(known)})")
    return node


def load_spec(path) -> dict:
    """The spec of ``path``, checked; raises ``SweepError`` at the first problem, within
    seconds whatever the file is (a FIFO, a device, an alias bomb, megabytes of seeds)."""
    path = Path(path)
    try:
        spec = parse_yaml(read_text(path, "sweep spec", MAX_SPEC_BYTES), str(path), SweepError)
    except SweepError:
        raise
    except (FileNotFoundError, FileInputError) as e:
        raise SweepError(str(e)) from None
    except (ValueError, TypeError, OverflowError) as e:
        # a value YAML's own constructors refuse (2001-13-45, !!float x, an int of 5000 digits)
        raise SweepError(f"{path}: not valid YAML ({type(e).__name__}: "
                         f"{_one_line(e, 160)})") from None
    return check_spec(spec, str(path), path.parent)


def check_spec(spec, source: str, base: Path) -> dict:
    """The spec with defaults filled in and every entry checked (see the module docstring);
    ``SweepError`` naming ``source`` and the key for anything else."""
    try:
        return _checked_spec(spec, source, Path(base))
    except SweepError:
        raise
    except MapUpdatingError as e:
        raise SweepError(_one_line(e)) from None
    except (TypeError, ValueError, OverflowError, RecursionError, OSError) as e:
        # a value of a kind no check above foresaw still ends in one line, never a traceback
        raise SweepError(f"{source}: a value cannot be used ({type(e).__name__}: "
                         f"{_one_line(e, 160)})") from None


def _checked_spec(spec, source: str, base: Path) -> dict:
    spec = _check_keys(spec, SPEC_KEYS, source, "")
    if "scenarios" not in spec:
        _fail(source, "scenarios", "missing required key")
    _count_runs(spec, source)       # before any entry is checked: that costs per entry
    out = {"scenarios": _scenarios(spec["scenarios"], source, base)}
    out["seeds"] = _integers(spec["seeds"], source, "seeds") if "seeds" in spec else [None]
    out["methods"] = _methods(spec.get("methods", ["paper"]), source)
    out["quick"] = spec.get("quick", False)
    if not isinstance(out["quick"], bool):
        _fail(source, "quick", f"expected true or false, got {_show(out['quick'])}")
    out["sessions"] = n = spec.get("sessions")
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or
                          not 1 <= n <= MAX_SESSIONS):
        _fail(source, "sessions", f"expected an integer in [1, {MAX_SESSIONS}], got {_show(n)}")
    out["config"] = _base_config(spec.get("config"), source)
    named = out["config"].pop("profile")      # the spec's own key says which, else config's
    given = spec.get("profile")
    if given is None and isinstance(spec.get("config"), dict) and "profile" in spec["config"]:
        given = named
    out["profile"] = _profiles(given, source)
    out["grid"] = _grid(spec.get("grid"), out["config"], source)
    return out


def _profiles(node, source: str) -> list[str | None]:
    """The profiles of ``profile``: one name or a list; [None] (the default, unnamed in the
    runs' keys) when the spec has none."""
    if node is None:
        return [None]
    names = [node] if isinstance(node, str) else _nonempty_list(node, source, "profile")
    for j, name in enumerate(names):
        check_profile(name, SweepError, f"{source}: profile" + (
            "" if isinstance(node, str) else f"[{j}]"))
    if len(set(names)) != len(names):
        _fail(source, "profile", f"a profile is listed twice: {_show(node)}")
    return list(names)


def _scenarios(entries, source: str, base: Path) -> list[dict]:
    out, seen = [], set()
    for j, entry in enumerate(_nonempty_list(entries, source, "scenarios")):
        checked = _scenario_entry(entry, source, f"scenarios[{j}]", base)
        text = json.dumps(checked, sort_keys=True)
        if text in seen:
            _fail(source, f"scenarios[{j}]", f"{_show(entry)} is listed twice")
        seen.add(text)
        out.append(checked)
    return out


def _methods(methods, source: str) -> list[str]:
    seen = []
    for j, m in enumerate(_nonempty_list(methods, source, "methods")):
        if not isinstance(m, str) or len(m) > 60:
            _fail(source, f"methods[{j}]", f"expected a method name, got {_show(m)}")
        check_method(m, f"{source}: methods[{j}]")
        if m in seen:
            _fail(source, "methods", f"a method is listed twice: {_show(methods)}")
        seen.append(m)
    return seen


def _scenario_entry(entry, source: str, key: str, base: Path) -> dict:
    if isinstance(entry, str):
        return {"file": _scenario_file(entry, source, key, base)}
    node = _check_keys(entry, ("generate",), source, key)
    if "generate" not in node:
        _fail(source, key, "expected a scenario name or path, or {generate: {...}}")
    return {"generate": _generate_entry(node["generate"], source, f"{key}.generate")}


def _scenario_file(entry: str, source: str, key: str, base: Path) -> str:
    """The resolved path of a scenario named or given by path (beside the spec first), a
    regular file of YAML: a folder, a FIFO, a device, or a file that is not YAML or is an alias
    bomb is refused now, not once the sweep has made its folder. (Its scenario is checked when
    it is loaded: that takes seconds, reading it milliseconds.)"""
    if not entry or "\x00" in entry or len(entry) > MAX_PATH_CHARS:
        _fail(source, key, f"not a scenario name or path: {_show(entry)}")
    try:
        local = base / entry
        # any file beside the spec (a FIFO too, refused just below), never a folder there
        path = find_scenario(local if local.exists() and not local.is_dir() else entry)
        check_regular_file(path, "scenario file", MAX_TEXT_BYTES)
        load_yaml(path, "scenario file")
        return str(path.resolve())
    except (MapUpdatingError, OSError) as e:   # FileNotFoundError, a name too long for the OS
        _fail(source, key, str(e))


def _generate_entry(node, source: str, key: str) -> dict:
    node = _check_keys(node, GENERATE_KEYS, source, key)
    if "seeds" not in node:
        _fail(source, f"{key}.seeds", "missing required key (the layouts' seeds)")
    seeds = _integers(node["seeds"], source, f"{key}.seeds")
    size, sessions, fov = node.get("size", [30, 20]), node.get("sessions", 4), node.get("fov",
                                                                                         270)
    try:
        w, h = check_arguments(size, sessions, fov)
    except MapUpdatingError as e:
        _fail(source, key, str(e))
    return {"seeds": seeds, "size": [w, h], "sessions": sessions, "fov": fov}


def _base_config(node, source: str) -> dict:
    if node is None:
        return {"profile": None}
    if not isinstance(node, dict):
        _fail(source, "config", f"expected a mapping of sections, got {type(node).__name__}")
    try:
        return load_robot_config(node, source=f"{source}: config").to_dict()
    except MapUpdatingError as e:
        raise SweepError(_one_line(e)) from None


def _grid(node, config: dict, source: str) -> dict:
    """Dotted key -> values; every value is tried on its section now, so that a bad one stops
    the sweep before its first run."""
    if node is None:
        return {}
    if not isinstance(node, dict):
        _fail(source, "grid", f"expected a mapping of dotted keys to lists, got "
                              f"{type(node).__name__}")
    if not node:
        _fail(source, "grid", "the mapping is empty (leave 'grid' out for no grid)")
    for key, values in node.items():
        if not isinstance(key, str) or len(key) > 60 or not key.isprintable():
            _fail(source, "grid", f"a grid key is <section>.<key>, got {_show(key)}")
        section, _, name = key.partition(".")
        where = f"grid.{key}"
        if section not in SECTIONS or not name:
            _fail(source, where, f"a grid key is <section>.<key> with a section of "
                                 f"{', '.join(SECTIONS)}{did_you_mean(section, SECTIONS)}")
        known = [f.name for f in fields(CLASSES[section])]
        if name not in known:
            _fail(source, where, f"{name!r} is not a key of section '{section}'"
                                 f"{did_you_mean(name, known)}")
        for v in _nonempty_list(values, source, where):
            try:
                section_config(section, {**config.get(section, {}), name: v}, source, where)
            except MapUpdatingError as e:
                raise SweepError(_one_line(e)) from None
        if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
            _fail(source, where, f"a value is listed twice: {_show(values)}")
    return dict(node)


def _count_runs(spec: dict, source: str) -> int:
    """The runs a spec asks for, counted from its lists' lengths before any entry is checked
    (each check costs, and YAML aliases make long lists of a few bytes); more than
    ``MAX_RUNS`` is refused (a slip of a digit in a seed range or a grid)."""
    def length(value) -> int:
        return max(len(value), 1) if isinstance(value, list) else 1

    scenarios = 0
    for entry in spec["scenarios"] if isinstance(spec["scenarios"], list) else [None]:
        generate = entry.get("generate") if isinstance(entry, dict) else None
        scenarios += length(generate.get("seeds")) if isinstance(generate, dict) else 1
    n = scenarios * length(spec.get("seeds")) * length(spec.get("methods")) \
        * length(spec.get("profile"))
    grid = spec.get("grid")
    for values in grid.values() if isinstance(grid, dict) else ():
        n *= length(values)
    if n > MAX_RUNS:
        _fail(source, "", f"the spec asks for {n} runs, more than {MAX_RUNS} (scenarios x seeds "
                          f"x methods x grid points); split it into several studies")
    return n


# --- the runs --------------------------------------------------------------------------------
def _slug(text: str) -> str:
    return re.sub(f"[^{RUN_KEY_CHARS}]+", "-", text).strip("-")


def scenario_files(spec: dict, out_dir: Path, progress: bool = False) -> list[tuple[str, Path]]:
    """(name, file) of every scenario of the spec; generated ones are written to
    ``DIR/scenarios/`` unless already there (generation is deterministic)."""
    out = []
    layouts = sum(len(e["generate"]["seeds"]) for e in spec["scenarios"] if "generate" in e)
    with _progress(progress and layouts > 0, total=layouts, desc="layouts", unit="layout",
                   leave=False) as bar:
        for entry in spec["scenarios"]:
            if "file" in entry:
                out.append((sim.load_scenario(entry["file"]).name, Path(entry["file"])))
                continue
            g = entry["generate"]
            for seed in g["seeds"]:
                w, h = g["size"]
                name = f"generated_{seed}_{w:g}x{h:g}" + ("_360" if g["fov"] == 360 else "")
                path = out_dir / "scenarios" / f"{name}_k{g['sessions']}.yaml"
                if not path.exists():
                    write_generated(seed, path, (w, h), g["sessions"], g["fov"])
                out.append((name, path))
                bar.update(1)
    names = [n for n, _ in out]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise SweepError(f"scenario {twice[0]!r} is listed twice")
    return out


def _points(grid: dict) -> list[dict]:
    """The cross product of the grid's values, the first key varying slowest."""
    points = [{}]
    for key, values in grid.items():
        points = [{**p, key: v} for p in points for v in values]
    return points


def _with_point(config: dict, point: dict) -> dict:
    out = {section: dict(values) for section, values in config.items()}
    for key, value in point.items():
        section, _, name = key.partition(".")
        out.setdefault(section, {})[name] = value
    return out


def plan(spec: dict, out_dir: Path, progress: bool = False) -> list[RunSpec]:
    """Every run of the spec, in the order of the results: scenario, seed, method, grid point."""
    runs = []
    for name, path in scenario_files(spec, out_dir, progress):
        for seed in spec["seeds"]:
            for method in spec["methods"]:
                for profile in spec.get("profile", [None]):
                    for point in _points(spec["grid"]):
                        parts = [name, "seed-default" if seed is None else f"seed{seed}",
                                 method] + ([f"profile-{profile}"] if profile else [])
                        parts += [f"{k}={v}" for k, v in point.items()]
                        config = _with_point(spec["config"], point)
                        if profile:
                            config["profile"] = profile
                        runs.append(RunSpec(_slug("__".join(parts)), name,
                                            str(path.resolve()), seed, method, spec["quick"],
                                            spec["sessions"], config, point))
    return runs


# --- one run ---------------------------------------------------------------------------------
class SessionClock:
    """Times each update session from its start to its scores (an observer: told outside the
    timed parts of the session, so it changes nothing of the run)."""

    def __init__(self):
        self.wall: dict[str, float] = {}
        self._t0 = 0.0

    def session_start(self, *args) -> None:
        self._t0 = time.perf_counter()

    def scan(self, *args) -> None:
        pass

    def session_end(self, result) -> None:
        self.wall[result.name] = time.perf_counter() - self._t0


def execute(run: RunSpec, runs_dir) -> dict:
    """Play ``run`` as ``mapupdate run`` would, in ``runs_dir/<key>/``, and write its rows to
    ``result.json`` there (atomically, last: the mark that the run is finished)."""
    folder = Path(runs_dir) / run.key
    if folder.exists():
        # a run a killed sweep left unfinished (no result.json): the sweep's own output,
        # played again from the start, since a new run never goes into a folder holding one

        shutil.rmtree(folder)
    config = load_robot_config(run.config or None, source=run.key)
    clock = SessionClock()
    t0 = time.perf_counter()
    keys = config.given
    result = run_scenario(run.scenario_file, RunOptions(
        out=folder, seed=run.seed, sessions=run.sessions, quick=run.quick, progress=False,
        profile=config.profile,
        updater_config=config.updater if "updater" in keys else None,
        localizer_config=keys.get("localizer"),
        pose_check_config=config.pose_check if "pose_check" in keys else None,
        observer=clock, method=run.method, compare_paper=False))
    record = {"format": RESULT_FORMAT, "run": run.definition(),
              "wall_s": time.perf_counter() - t0,
              "rows": session_rows(folder, result.metrics, clock.wall)}
    write_atomically(folder / "result.json", json.dumps(record, indent=1) + "\n")
    return record


def finished(run: RunSpec, runs_dir) -> dict | None:
    """The record of ``run`` if it finished before, else None. A record of another definition
    under the same key (a spec changed between two sweeps into one folder) is refused."""
    path = Path(runs_dir) / run.key / "result.json"
    if not path.exists():
        return None
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise SweepError(f"{path}: unreadable ({e}); delete it to run the run again") from None
    if not isinstance(record, dict) or record.get("format") != RESULT_FORMAT:
        raise SweepError(f"{path}: not a sweep result of format {RESULT_FORMAT}")
    # compared as JSON reads it back (tuples of a configuration come back as lists)
    if record.get("run") != json.loads(json.dumps(run.definition())):
        raise SweepError(f"{path}: a result of another definition of run {run.key} (the spec "
                         f"or the scenario file changed); use another --out")
    return record


# --- all runs --------------------------------------------------------------------------------
def _sequential(runs, runs_dir):
    for run in runs:
        yield run, execute(run, runs_dir)


def _pool(runs, runs_dir, workers: int):
    """Yield (run, record) as the runs finish on a pool of ``workers`` processes."""
    # spawn: a fresh interpreter per worker, whatever threads the parent runs
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context,
                             initializer=_end_with_parent, initargs=(os.getpid(),)) as pool:
        pending = {pool.submit(execute, run, str(runs_dir)): run for run in runs}
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    run = pending.pop(future)
                    yield run, future.result()
        finally:
            for future in pending:
                future.cancel()


def _end_with_parent(parent: int, kernel: bool = True) -> None:
    """A pool worker's first call: the worker ends soon after the sweep ``parent`` that started
    it, even a sweep killed with SIGKILL, which leaves its pool no chance to stop the workers
    (they would play their runs to the end for nobody, holding CPUs and run folders). On Linux
    the kernel kills the worker with its parent; elsewhere (or with ``kernel`` False) a thread
    ends it within ``PARENT_POLL`` seconds of the parent's death."""
    if not (kernel and _kill_with_parent()):
        threading.Thread(target=_watch_parent, args=(parent,), name="watch-parent",
                         daemon=True).start()
    if os.getppid() != parent:          # the parent died before the worker got here
        os._exit(1)


def _kill_with_parent() -> bool:
    """Ask Linux to SIGKILL this process when its parent dies; False where it cannot."""
    # (the parent's thread that started the worker, in fact: the pool starts its workers
    # from the sweep's main thread, which lives as long as the sweep)
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent: int) -> None:
    # an orphan is adopted by init (or a subreaper): its parent's pid changes
    while os.getppid() == parent:
        time.sleep(PARENT_POLL)
    os._exit(1)


def _progress(enabled: bool, **kw):
    return tqdm(disable=not enabled, dynamic_ncols=True, **{"unit": "run", **kw})


def default_workers() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:      # not on Linux
        return os.cpu_count() or 1


def run_sweep(spec_path, out, workers: int | None = None, ray: str | None = None,
              progress: bool = True) -> int:
    """Run every unfinished run of the spec into ``out``, then write the study's results;
    returns the number of runs of the spec. ``workers``: processes of the local pool (default
    the CPUs; 1 runs in this process); ``ray``: "auto" (a local Ray) or a cluster's address."""
    spec = load_spec(spec_path)
    if workers is not None and (isinstance(workers, bool) or workers < 1):
        raise SweepError(f"--workers must be at least 1, got {workers}")
    if ray is not None:
        require_ray()
        check_address(ray)              # before anything is written
    out = Path(out)
    check_study_folder(out, spec)       # before anything is written
    with study_lock(out):
        check_study_folder(out, spec)   # again: another sweep may have claimed it meanwhile
        runs_dir = out / "runs"
        runs_dir.mkdir(parents=True, exist_ok=True)
        runs = plan(spec, out, progress)
        done = {run.key for run in runs if finished(run, runs_dir) is not None}
        write_atomically(out / "sweep.json", json.dumps(
            {"format": RESULT_FORMAT, "spec": spec, "runs": [r.key for r in runs]},
            indent=1) + "\n")
        todo = [run for run in runs if run.key not in done]
        workers = default_workers() if workers is None else workers
        with _progress(progress, total=len(runs), initial=len(done), desc="runs") as bar:
            for run, _record in _dispatch(todo, runs_dir, workers, ray):
                bar.set_postfix_str(run.key[-40:], refresh=False)
                bar.update(1)
        summarise(out)
    return len(runs)


# --- the study folder ------------------------------------------------------------------------
def check_study_folder(out: Path, spec: dict) -> None:
    """A study folder holds one study: a new folder, or one whose ``sweep.json`` has this very
    spec (as checked, so a spec file moved, reformatted or commented resumes its study). Any
    other is refused: its results.csv would be replaced by this spec's, its rows gone."""
    if not out.exists():
        return
    if not out.is_dir():
        _fail(str(out), "", "exists and is not a folder; --out names the study's folder")
    record = out / "sweep.json"
    if not record.exists():
        others = sorted(p.name for p in out.iterdir()
                        if p.name not in STUDY_ENTRIES and not p.name.startswith("."))
        if others:
            _fail(str(out), "", f"holds files that are not a study's ({_show(others)}); use a "
                                "new or empty folder for --out")
        return
    try:
        old = _json(record, "study file").get("spec")
    except StudyFolderError as e:
        raise SweepError(f"{e}; use another --out") from None
    new = json.loads(json.dumps(spec))      # as sweep.json reads back
    if old != new:
        differ = [k for k in SPEC_KEYS if not isinstance(old, dict) or old.get(k) != new.get(k)]
        _fail(str(out), "", f"holds the study of another spec (its {', '.join(differ) or 'keys'}"
                            " differ); a folder holds one study: use another --out")


@contextmanager
def study_lock(out: Path):
    """Hold ``out/state/lock`` while the sweep writes into ``out``: a second sweep into the
    same folder at the same moment is refused. The lock of a run folder: an advisory flock
    the kernel drops when the sweep dies, so a killed sweep leaves no stale lock."""
    lock = RunFolderLock(out)
    try:
        lock.__enter__()
    except ResumeError:
        holder = _one_line(lock.path.read_text(errors="replace"), 60) or "another process"
        raise SweepError(f"{out}: another sweep is writing into this study folder ({holder}); "
                         "wait for it or use another --out") from None
    try:
        yield lock
    finally:
        lock.__exit__(None, None, None)


def _dispatch(todo, runs_dir, workers: int, ray: str | None):
    try:
        if ray is not None:
            yield from ray_tasks(execute, todo, runs_dir, ray, workers)
        elif workers == 1 or len(todo) <= 1:
            yield from _sequential(todo, runs_dir)
        else:
            yield from _pool(todo, runs_dir, min(workers, len(todo)))
    except MapUpdatingError as e:
        raise SweepError(f"a run failed: {e}") from None
