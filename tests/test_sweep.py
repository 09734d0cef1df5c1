"""Studies (`mapupdate sweep`): bad specs refused before any run, the same metrics on a process
pool, on Ray and one by one with `mapupdate run`, a killed sweep resumed, the results files."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mapupdate import main

ROOT = Path(__file__).resolve().parents[1]
TIMING = ("wall_s", "updater_cpu_s")       # the only columns that differ between two runs
LAYOUTS = "{generate: {seeds: [1, 2], size: [15, 10], sessions: 2}}"


def _spec(tmp_path: Path, text: str, name: str = "spec.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _csv(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return [{k: v for k, v in row.items() if k not in TIMING} for row in csv.DictReader(f)]


def _sessions(metrics_path: Path) -> list[dict]:
    """A run's per-session metrics without what depends on the machine's timing, and
    without the paper profile's comparison (a lone run adds it, a sweep's runs do not)."""
    m = json.loads(metrics_path.read_text())
    for s in m["sessions"]:
        s.pop("comparison", None)
        r = s.get("resources", {})
        for k in [k for k in r if k.endswith("_s") or "rss" in k]:
            r.pop(k)
    return m["sessions"]


@pytest.mark.parametrize("text, message", [
    ("scenarios: [aws_small_warehouse]\nmethod: [paper]\n",
     "unknown key 'method' (did you mean 'methods'?)"),
    ("scenarios: [aws_small_warehouse]\nmethods: [paper, papr]\n",
     "methods[1]: unknown method 'papr' (did you mean 'paper'?)"),
    ("scenarios: [aws_small_warehouse]\nseeds: []\n", "seeds: the list is empty"),
    ("scenarios: []\n", "scenarios: the list is empty"),
    ("scenarios: [aws_small_warehouse]\ngrid: {updater.treshold: [5, 7]}\n",
     "'treshold' is not a key of section 'updater' (did you mean 'threshold'?)"),
    ("scenarios: [aws_small_warehouse]\ngrid: {updatr.threshold: [5]}\n",
     "(did you mean 'updater'?)"),
    ("scenarios: [aws_small_warehouse]\ngrid: {updater.threshold: []}\n",
     "grid.updater.threshold: the list is empty"),
    ("scenarios: [aws_small_warehouse]\ngrid: {updater.threshold: [7, -1]}\n", "threshold"),
    ("scenarios: [{generate: {seed: [1]}}]\n", "unknown key 'seed' (did you mean 'seeds'?)"),
    ("scenarios: [aws_smal_warehouse]\n", "(did you mean 'aws_small_warehouse'?)"),
    ("scenarios: [{generate: {seeds: [1], size: [10, 10]}}]\n", "outside 15 x 10"),
    ("scenarios: [aws_small_warehouse]\ngrid: {updater.threshold: [5, 7, 5]}\n",
     "grid.updater.threshold: a value is listed twice: [5, 7, 5]"),
    ("scenarios: [aws_small_warehouse]\nseeds: [" + ", ".join(map(str, range(200))) + "]\n"
     "grid: {updater.threshold: [3, 4, 5, 6, 7], updater.buffer_size: [10, 11, 12, 13, 14, 15, "
     "16], updater.n_skip: [0, 1]}\n",
     "the spec asks for 14000 runs, more than 10000"),
    ("scenarios: [{generate: {seeds: [1], sessions: 1000000000}}]\n", "to 100, got 1000000000"),
])
def test_a_bad_spec_is_refused_with_one_line_before_any_run(tmp_path, capsys, text, message):
    out = tmp_path / "study"
    assert main(["sweep", str(_spec(tmp_path, text)), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mapupdate sweep: error: ")
    assert message in err[0]
    assert not out.exists()                      # nothing written, no run started


def test_a_missing_ray_is_one_line_saying_what_to_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)           # import ray fails
    out = tmp_path / "study"
    spec = _spec(tmp_path, "scenarios: [aws_small_warehouse]\nquick: true\n")
    assert main(["sweep", str(spec), "--out", str(out), "--ray", "auto"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["mapupdate sweep: error: --ray needs Ray, which is not installed: "
                   "pip install 'lidar-map-updating[ray]'"]
    assert not out.exists()


@pytest.fixture()
def local_ray():
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def test_pool_and_ray_give_the_metrics_of_the_same_runs_one_by_one(tmp_path, local_ray):
    spec = _spec(tmp_path, f"scenarios: [{LAYOUTS}]\nseeds: [7]\n"
                           "methods: [paper, fuse, none]\nquick: true\n")
    pool, on_ray = tmp_path / "pool", tmp_path / "ray"
    assert main(["sweep", str(spec), "--out", str(pool), "--workers", "2",
                 "--no-progress"]) == 0
    assert main(["sweep", str(spec), "--out", str(on_ray), "--ray", "auto",
                 "--no-progress"]) == 0
    keys = json.loads((pool / "sweep.json").read_text())["runs"]
    assert len(keys) == 6 and _csv(pool / "results.csv") == _csv(on_ray / "results.csv")
    for key in keys:
        definition = json.loads((pool / "runs" / key / "result.json").read_text())["run"]
        alone = tmp_path / "alone" / key
        assert main(["run", definition["scenario_file"], "--seed", str(definition["seed"]),
                     "--method", definition["method"], "--quick", "--out", str(alone),
                     "--no-progress"]) == 0
        expected = _sessions(alone / "metrics.json")
        assert _sessions(pool / "runs" / key / "metrics.json") == expected, key
        assert _sessions(on_ray / "runs" / key / "metrics.json") == expected, key
    rows = _csv(pool / "results.csv")
    assert len(rows) == 6 and {r["method"] for r in rows} == {"paper", "fuse", "none"}
    for name in ("summary.md", "fig_opdf.png", "fig_precision.png", "fig_recall.png",
                 "fig_ghosts.png"):
        assert (pool / name).stat().st_size > 0


def _finished(out: Path) -> dict[str, int]:
    """result.json of each finished run -> the time it was written [ns]."""
    return {p.parent.name: p.stat().st_mtime_ns for p in out.glob("runs/*/result.json")}


def test_a_sweep_killed_part_way_resumes_without_redoing_a_finished_run(tmp_path, capsys):
    spec = _spec(tmp_path, "scenarios: [{generate: {seeds: [3], size: [15, 10], sessions: 2}}]"
                           "\nseeds: [1, 2, 3, 4, 5]\nmethods: [none]\nquick: true\n")
    out = tmp_path / "killed"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "mapupdate", "sweep", str(spec), "--out",
                             str(out), "--workers", "2", "--no-progress"], cwd=ROOT, env=env,
                            start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(_finished(out)) < 2 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)           # the sweep and its workers, at once
    proc.wait()
    before = _finished(out)
    assert 2 <= len(before) < 5, "the sweep was not killed part-way"
    # what is finished can be summarised at any time
    assert main(["sweep", "--summarise", str(out)]) == 0
    assert len(_csv(out / "results.csv")) == len(before)
    assert main(["sweep", str(spec), "--out", str(out), "--workers", "2",
                 "--no-progress"]) == 0
    after = _finished(out)
    assert len(after) == 5 and all(after[k] == t for k, t in before.items())
    reference = tmp_path / "whole"
    assert main(["sweep", str(spec), "--out", str(reference), "--workers", "1",
                 "--no-progress"]) == 0
    assert _csv(out / "results.csv") == _csv(reference / "results.csv")


def test_grid_points_become_columns_and_rows_of_the_summary(tmp_path):
    spec = _spec(tmp_path, "scenarios: [{generate: {seeds: [4], size: [15, 10], sessions: 2}}]"
                           "\nseeds: [1]\nquick: true\nconfig: {updater: {fill_gaps: true}}\n"
                           "grid: {updater.threshold: [6, 8]}\n")
    out = tmp_path / "grid"
    assert main(["sweep", str(spec), "--out", str(out), "--no-progress"]) == 0
    rows = _csv(out / "results.csv")
    assert [r["updater.threshold"] for r in rows] == ["6", "8"]
    for key, threshold in zip(json.loads((out / "sweep.json").read_text())["runs"], (6, 8)):
        manifest = json.loads((out / "runs" / key / "state" / "run.json").read_text())
        assert manifest["updater_config"]["threshold"] == threshold
        assert manifest["updater_config"]["fill_gaps"] is True
    summary = (out / "summary.md").read_text()
    assert "| method | updater.threshold | runs |" in summary
    assert "| paper | 6 | 1 |" in summary and "| paper | 8 | 1 |" in summary
