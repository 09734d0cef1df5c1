"""`mapupdate sweep` against hostile input and faults: workers that outlive a killed sweep, two
specs (or two sweeps at once) in one study folder, spec files that are not what a spec is, and
hypothesis-made specs, which may only ever raise ``SweepError``."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mapupdate import main
from studies import study_report, sweep
from studies.sweep import SweepError, check_spec, load_spec, study_lock

ROOT = Path(__file__).resolve().parents[1]
MAPUPDATE = ROOT / ".venv" / "bin" / "mapupdate"
SPEC = "scenarios: [aws_small_warehouse]\nseeds: [1, 2]\nmethods: [none]\nquick: true\n"


def _spec(folder: Path, text: str, name: str = "spec.yaml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def _gone(proc) -> bool:
    import psutil

    try:
        return proc.status() == psutil.STATUS_ZOMBIE    # ended, not yet reaped by init
    except psutil.NoSuchProcess:
        return True


def _wait_until(condition, seconds: float, step: float = 0.05) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(step)
    return condition()


# --- 1. the pool's workers end with the sweep -----------------------------------------------------
def test_the_workers_of_a_sweep_killed_with_sigkill_end_by_themselves(tmp_path):
    psutil = pytest.importorskip("psutil")
    out = tmp_path / "study"
    proc = subprocess.Popen([sys.executable, "-m", "mapupdate", "sweep",
                             str(_spec(tmp_path, SPEC)), "--out", str(out), "--workers", "2",
                             "--no-progress"], cwd=ROOT, start_new_session=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)},
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    kids = []
    try:
        # both workers are past their start (their runs' folders exist), mid-run
        started = _wait_until(lambda: len(list(out.glob("runs/*"))) >= 2 or
                              proc.poll() is not None, 90)
        kids = psutil.Process(proc.pid).children(recursive=True)
        workers = [k for k in kids if "spawn_main" in " ".join(k.cmdline())]
        assert started and proc.poll() is None and len(workers) == 2
        proc.send_signal(signal.SIGKILL)               # the sweep alone, not its group
        proc.wait()
        # every process the sweep started (the workers, multiprocessing's resource tracker)
        assert _wait_until(lambda: all(_gone(k) for k in kids), 5), \
            [k.pid for k in kids if not _gone(k)]
    finally:
        for k in kids:
            if not _gone(k):
                k.kill()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    # the kernel dropped the dead sweep's lock: the folder is free for its resume
    with study_lock(out):
        pass


def test_without_the_kernels_help_a_worker_ends_within_a_second_of_its_parent(tmp_path):
    psutil = pytest.importorskip("psutil")
    # parent -> worker; the worker asks for the fallback (a thread watching its parent's pid)
    worker = ("import os, sys, time; from studies.sweep import _end_with_parent; "
              "_end_with_parent(os.getppid(), kernel=False); "
              "print(os.getpid(), flush=True); time.sleep(60)")
    parent = (f"import subprocess, sys, time; subprocess.Popen([sys.executable, '-c', "
              f"{worker!r}]); time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", parent], cwd=ROOT, stdout=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, text=True)
    child = None
    try:
        child = psutil.Process(int(proc.stdout.readline()))
        assert not _gone(child)
        proc.kill()
        proc.wait()
        assert _wait_until(lambda: _gone(child), 3 * sweep.PARENT_POLL + 1)
    finally:
        if child is not None and not _gone(child):
            child.kill()
        if proc.poll() is None:
            proc.kill()
            proc.wait()


# --- 2. a study folder holds one spec, written by one sweep at a time -----------------------------
@pytest.fixture()
def fake_runs(monkeypatch):
    """Runs that take no time: each writes a result of one row, as a played run would."""
    played = []

    def execute(run, runs_dir):
        folder = Path(runs_dir) / run.key
        folder.mkdir(parents=True, exist_ok=True)
        row = {"scenario": run.scenario, "seed": run.seed, "method": run.method,
               "session": "W2", "opdf": 90.0 + (run.seed or 0), "precision": 1.0}
        record = {"format": sweep.RESULT_FORMAT, "run": run.definition(), "wall_s": 0.0,
                  "rows": [row]}
        (folder / "result.json").write_text(json.dumps(record))
        played.append(run.key)
        return record

    monkeypatch.setattr(sweep, "execute", execute)
    # the box plots are the study report's (tested in test_sweep.py), not what this tests
    monkeypatch.setattr(study_report, "box_plot", lambda *args: None)
    return played


def _rows(out: Path) -> list[dict]:
    with open(out / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def _sweep(spec: Path, out: Path) -> int:
    return main(["sweep", str(spec), "--out", str(out), "--workers", "1", "--no-progress"])


def test_a_sweep_of_another_spec_into_a_study_folder_is_refused(tmp_path, capsys, fake_runs):
    out = tmp_path / "study"
    assert _sweep(_spec(tmp_path, SPEC), out) == 0 and len(fake_runs) == 2
    before = (out / "results.csv").read_bytes()
    other = _spec(tmp_path, SPEC.replace("seeds: [1, 2]", "seeds: [3]"), "other.yaml")
    capsys.readouterr()
    assert _sweep(other, out) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"mapupdate sweep: error: {out}: holds the study of another spec (its seeds "
                   "differ); a folder holds one study: use another --out"]
    assert (out / "results.csv").read_bytes() == before and len(fake_runs) == 2
    assert len(_rows(out)) == 2
    # the same spec, moved, reordered and commented, resumes: nothing is played again
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    same = _spec(moved, "# the study again\nquick: true\nmethods: [none]\nseeds: [1, 2]\n"
                        f"scenarios: [{ROOT / 'scenarios' / 'aws_small_warehouse.yaml'}]\n")
    assert _sweep(same, out) == 0 and len(fake_runs) == 2 and len(_rows(out)) == 2


def test_a_study_folder_holding_other_files_or_a_file_is_refused(tmp_path, capsys):
    spec = _spec(tmp_path, SPEC)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine\n")
    (tmp_path / "file").write_text("x\n")
    for out, message in ((mine, "holds files that are not a study's (['notes.txt'])"),
                         (tmp_path / "file", "exists and is not a folder")):
        assert _sweep(spec, out) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("mapupdate sweep: error: ")
        assert message in err[0]
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"]


def test_a_second_sweep_into_a_folder_being_written_is_refused(tmp_path, capsys, fake_runs):
    out = tmp_path / "study"
    spec = _spec(tmp_path, SPEC)
    with study_lock(out):                        # a sweep writing into the folder
        assert _sweep(spec, out) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"mapupdate sweep: error: {out}: another sweep is writing into this "
                       f"study folder (pid {os.getpid()}); wait for it or use another --out"]
        assert fake_runs == [] and not (out / "sweep.json").exists()
    assert _sweep(spec, out) == 0 and len(fake_runs) == 2


# --- 3. spec files that are not what a spec is ----------------------------------------------------
def _alias_bomb() -> str:
    lines = ['scenarios: [&a0 ["x", "x", "x", "x", "x", "x", "x", "x", "x"]']
    lines += [f"  , &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    return "\n".join(lines) + "]\n"


def _hostile_file(kind: str, folder: Path) -> tuple[Path, str]:
    """(a spec file of ``kind``, what its error line says)."""
    path = folder / f"{kind}.yaml"
    if kind == "fifo":
        os.mkfifo(path)
        return path, "the sweep spec is a FIFO"
    if kind == "dev_zero":
        return Path("/dev/zero"), "the sweep spec is not a regular file"
    if kind == "link_to_device":
        path.symlink_to("/dev/zero")
        return path, "the sweep spec is not a regular file"
    if kind == "alias_bomb":
        return _spec(folder, _alias_bomb(), path.name), "expands to more than 1000000 nodes"
    if kind == "million_seeds":
        text = "scenarios: [aws_small_warehouse]\nseeds: [" + \
            ", ".join(map(str, range(1_000_000))) + "]\n"
        return _spec(folder, text, path.name), "more than the 262144 a sweep spec can be"
    if kind == "grid_of_1e8":
        grid = ", ".join(f"updater.{k}: [{', '.join(map(str, range(1, 101)))}]"
                         for k in ("min_run", "n_skip", "last_check_max_area",
                                   "gate_min_interval"))
        text = f"scenarios: [aws_small_warehouse]\ngrid: {{{grid}}}\n"
        return _spec(folder, text, path.name), "the spec asks for 100000000 runs, more than 10000"
    if kind == "thousands_of_digits":
        return _spec(folder, "scenarios: [aws_small_warehouse]\nseeds: [" + "7" * 5000 + "]\n",
                     path.name), "not valid YAML (ValueError: Exceeds the limit"
    if kind == "impossible_date":
        return _spec(folder, "scenarios: [aws_small_warehouse]\nquick: 2001-13-45\n",
                     path.name), "not valid YAML (ValueError: month must be in 1..12)"
    if kind == "scenario_is_a_fifo":
        os.mkfifo(folder / "fifo_scenario.yaml")
        return _spec(folder, "scenarios: [fifo_scenario.yaml]\n", path.name), \
            "scenarios[0]: " + str(folder / "fifo_scenario.yaml") + ": the scenario file is a FIFO"
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["fifo", "dev_zero", "link_to_device", "alias_bomb",
                                  "million_seeds", "grid_of_1e8"])
def test_a_hostile_spec_file_is_refused_in_one_line_within_seconds(tmp_path, kind):
    spec, message = _hostile_file(kind, tmp_path)
    out = tmp_path / "study"

    def at_most_2_gb():                          # a blow-up fails the test, not the machine
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))
    t0 = time.monotonic()
    done = subprocess.run([str(MAPUPDATE), "sweep", str(spec), "--out", str(out)],
                          capture_output=True, text=True, timeout=60, preexec_fn=at_most_2_gb)
    assert time.monotonic() - t0 < 15
    err = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(err) == 1, done.stderr[-2000:]
    assert err[0].startswith("mapupdate sweep: error: ") and message in err[0]
    assert "Traceback" not in done.stderr and done.stdout == ""
    assert not out.exists()


@pytest.mark.parametrize("kind", ["thousands_of_digits", "impossible_date",
                                  "scenario_is_a_fifo"])
def test_values_yaml_cannot_make_and_a_fifo_scenario_are_refused_in_one_line(tmp_path, capsys,
                                                                             kind):
    spec, message = _hostile_file(kind, tmp_path)
    out = tmp_path / "study"
    assert main(["sweep", str(spec), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mapupdate sweep: error: ") and message in err[0]
    assert not out.exists()


# --- 4. hypothesis: any spec is a checked spec or one SweepError ----------------------------------
SETTINGS = dict(derandomize=True, database=None, deadline=5000,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
GOOD = {"scenarios": ["aws_small_warehouse", {"generate": {"seeds": [1], "size": [15, 10],
                                                           "sessions": 2, "fov": 270}}],
        "seeds": [1, 2], "methods": ["paper", "none"], "quick": True, "sessions": 2,
        "config": {"updater": {"fill_gaps": True}, "localizer": {"max_particles": 500}},
        "grid": {"updater.threshold": [5, 7], "pose_check.max_gain": [0.1]}}
texts = st.one_of(st.text(max_size=12), st.sampled_from(
    ["..", "../..", "../../etc/passwd", "a\x00b", "\x00", "/dev/zero", "/", "", ".", "~",
     "aws_small_warehouse/../aws_small_warehouse", "updater.", ".threshold", "updater..x",
     "x" * 5000, "paper\n", "é", "\ud800"]))
scalars = st.one_of(st.none(), st.booleans(), st.integers(), st.integers(-10**30, 10**30),
                    st.floats(allow_nan=True, allow_infinity=True), texts,
                    st.sampled_from([math.nan, math.inf, -math.inf, 2**63, 2**64, -1, 0, 1e308,
                                     10**400, 270.0, 1e-300]))
values = st.recursive(scalars, lambda c: st.one_of(
    st.lists(c, max_size=4), st.dictionaries(st.one_of(texts, st.integers()), c, max_size=3)),
    max_leaves=8)


def _deep(depth: int, leaf=1):
    node = leaf
    for _ in range(depth):
        node = [node]
    return node


# (made afresh for each example: a spec is mutated in place)
small = st.one_of(values, st.sampled_from([list, dict]).map(lambda f: f()))
big = st.sampled_from([lambda: list(range(20_000)), lambda: [7] * 20_000, lambda: _deep(3000),
                       lambda: {"a": _deep(3000)}, lambda: {str(i): i for i in range(5000)}])
hostile = st.one_of(small, big.map(lambda f: f()))


@st.composite
def hostile_specs(draw, hostile=hostile):
    """GOOD with one to three values anywhere replaced, deleted or joined by an unknown key."""
    doc = json.loads(json.dumps(GOOD))
    for _ in range(draw(st.integers(1, 3))):
        paths = []

        def walk(node, path):
            paths.append(path)
            if len(path) > 6 or not isinstance(node, (dict, list)) or len(node) > 50:
                return
            for k, v in (node.items() if isinstance(node, dict) else enumerate(node)):
                walk(v, path + (k,))
        walk(doc, ())
        path = draw(st.sampled_from(paths))
        if not path:
            return draw(hostile)
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        action = draw(st.sampled_from(["replace", "replace", "delete", "add"]))
        if action == "delete":
            del parent[path[-1]]
        elif action == "add" and isinstance(parent, dict):
            parent[draw(st.one_of(texts, st.integers()))] = draw(hostile)
        else:
            parent[path[-1]] = draw(hostile)
    return doc


def _within(seconds: int):
    """Fail an example that takes ``seconds`` (hypothesis' deadline cannot stop a hang)."""
    def expired(*_):
        raise TimeoutError(f"an example took more than {seconds} s")
    return expired


def _check_bounded(call, seconds: int = 20):
    previous = signal.signal(signal.SIGALRM, _within(seconds))
    signal.alarm(seconds)
    try:
        return call()
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _assert_checked(spec: dict) -> None:
    assert set(spec) == set(sweep.SPEC_KEYS)
    # what sweep.json keeps and compares: JSON without NaN, read back equal
    assert json.loads(json.dumps(spec, allow_nan=False)) == json.loads(json.dumps(spec))
    assert sweep._count_runs(spec, "h.yaml") <= sweep.MAX_RUNS


@settings(max_examples=150, **SETTINGS)
@given(hostile_specs())
def test_hostile_specs_raise_only_sweep_errors(tmp_path_factory, doc):
    base = tmp_path_factory.getbasetemp()
    try:
        spec = _check_bounded(lambda: check_spec(doc, "h.yaml", base))
    except SweepError as e:
        assert "\n" not in str(e) and str(e).startswith("h.yaml") and len(str(e)) < 1000
    else:
        _assert_checked(spec)


raw_texts = st.one_of(st.text(max_size=80), st.sampled_from([
    "[" * 5000, "{a: " * 3000, "scenarios: [aws_small_warehouse]\nseeds: [" + "9" * 5000 + "]",
    "scenarios: [aws_small_warehouse]\nquick: 2001-13-45\n", "quick: !!float x\n",
    "scenarios: !!python/object:os.system [ls]\n", "&a [*a]\n", "scenarios: [\t]\n",
    "? [a, b]\n: 1\n", "scenarios: !!binary xx\n", _alias_bomb(), "---\n...\n---\n"]))


@settings(max_examples=150, **SETTINGS)
@given(st.one_of(hostile_specs(small), raw_texts))   # (big files: the tests above)
def test_hostile_spec_files_raise_only_sweep_errors(tmp_path_factory, doc):
    folder = tmp_path_factory.mktemp("spec")
    path = folder / "h.yaml"
    try:
        text = doc if isinstance(doc, str) else yaml.safe_dump(doc, allow_unicode=True)
    except (RecursionError, yaml.YAMLError):
        text = "[" * 5000                        # a nest deeper than YAML can write
    try:
        path.write_text(text, errors="surrogatepass")
    except ValueError:
        path.write_bytes(text.encode("utf-8", "replace"))
    try:
        spec = _check_bounded(lambda: load_spec(path))
    except SweepError as e:
        assert "\n" not in str(e) and str(e).startswith(str(path)) and len(str(e)) < 1000
    else:
        _assert_checked(spec)
