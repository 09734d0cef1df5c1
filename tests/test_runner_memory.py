"""A run's memory does not grow with its sessions: each session's outputs go to disk when it
ends, and the run keeps whole only M1 and the last session (``RunResult``). The outputs and the
scores are those of playing every session and keeping every result, and a resumed run reads
back no more than a run that was never interrupted keeps."""

from __future__ import annotations

import copy
import filecmp
import json
import shutil

import numpy as np
import pytest

from gridmap import load_map
from scenarios.checkpoint import finished_sessions
from scenarios.report import session_output_paths, write_session_outputs
from scenarios.runner import RunOptions, build_initial_map, run_scenario, run_update_session
from scenarios.session import session_seeds
from tiny_room import tiny_room_dict

import sim

NAMES = ["W1", "W2", "W3", "W4"]
SCORES = ("map_metrics", "change_detection", "ghost_cells", "localization")


def four_sessions(path):
    """The tiny room with two more short sessions: the pallet goes back, then only a walker."""
    import yaml

    data = tiny_room_dict()
    w2 = data["sessions"][1]
    w3 = dict(copy.deepcopy(w2), name="W3",
              changes=[{"move": "pallet", "to": [2.0, 2.5, 0.0]}])
    w4 = dict(copy.deepcopy(w2), name="W4", changes=[])
    data["sessions"] += [w3, w4]
    path.write_text(yaml.safe_dump(data))
    return path


class Keeper:
    """An observer that holds on to every result it is given."""

    def __init__(self):
        self.results = []

    def session_start(self, *args) -> None: ...

    def scan(self, *args) -> None: ...

    def session_end(self, result) -> None:
        self.results.append(result)


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    """The run, and the same sessions played with every result kept whole."""
    tmp = tmp_path_factory.mktemp("memory")
    yaml = four_sessions(tmp / "four.yaml")
    keeper = Keeper()
    run = run_scenario(yaml, RunOptions(out=tmp / "run", progress=False, observer=keeper))

    scn = sim.load_scenario(yaml)
    seeds = session_seeds(scn.seed, len(scn.sessions))
    full = [build_initial_map(scn, 0, seeds[0])]
    for i in range(1, len(scn.sessions)):
        full.append(run_update_session(scn, i, full[-1].updated, full[0].updated, seeds[i],
                                       RunOptions(progress=False), full[-1].faces))
    for res in full:
        write_session_outputs(tmp / "full", res)
    return tmp, yaml, run, full, keeper


def scores(metrics: dict) -> dict:
    return {k: metrics.get(k) for k in SCORES}


def assert_kept_as_documented(sessions, out_dir) -> None:
    """M1 and the last session whole, name and metrics of the others."""
    assert [s.name for s in sessions] == NAMES
    first, middle, last = sessions[0], sessions[1:-1], sessions[-1]
    assert np.array_equal(first.updated.data, load_map(out_dir / "maps" / "M_W1.yaml").data)
    assert first.truth is None and first.previous is None
    for s in middle:
        assert s.updated is None and s.truth is None and s.previous is None
        assert s.oracle is None and s.trajectory is None and s.masks == {}
        assert s.metrics["name"] == s.name and "change_detection" in s.metrics
    assert all(x is not None for x in (last.updated, last.truth, last.previous, last.oracle,
                                       last.trajectory))
    assert set(last.masks) == {"observable", "people", "observations"}
    assert np.array_equal(last.previous.data, load_map(out_dir / "maps" / "M_W3.yaml").data)


def test_the_run_keeps_only_m1_and_the_last_session(played):
    tmp, _, run, _, keeper = played
    assert_kept_as_documented(run.sessions, tmp / "run")
    # what observers were given is theirs: thinning the run's list took nothing from it
    assert [r.name for r in keeper.results] == NAMES[1:]
    assert all(r.masks and r.trajectory is not None for r in keeper.results)


def test_every_output_is_written_with_its_old_name(played):
    tmp, _, run, _, _ = played
    out = tmp / "run"
    updates = NAMES[1:]
    top = {p.name for p in out.iterdir() if p.is_file()}
    assert top == {"metrics.json", "report.md", "fig_metrics.png", "fig_sessions.png",
                   *(f"fig_{kind}_{n}.png" for n in updates for kind in ("maps",
                                                                          "trajectories"))}
    maps = {p.name for p in (out / "maps").iterdir()}
    assert maps == {f"{kind}_{n}.{ext}" for n in NAMES for kind in ("M", "G")
                    for ext in ("yaml", "pgm")} | \
        {f"oracle_{n}.{ext}" for n in updates for ext in ("yaml", "pgm")} | \
        {f"masks_{n}.npz" for n in updates}
    assert {p.name for p in (out / "trajectories").iterdir()} == \
        {f"{n}_{which}.tum" for n in updates
         for which in ("true", "on_previous_map", "on_initial_map")}
    assert not [p for p in out.rglob(".*")]            # no temporary file left behind
    metrics = json.loads((out / "metrics.json").read_text())
    assert [s["name"] for s in metrics["sessions"]] == NAMES
    assert "W4" in (out / "report.md").read_text()


def test_outputs_and_scores_are_those_of_keeping_every_session(played):
    tmp, _, run, full, _ = played
    out = tmp / "run"
    for res, m in zip(full, run.metrics["sessions"], strict=True):
        assert m["name"] == res.name
        assert scores(m) == scores(res.metrics), res.name
        assert np.array_equal(load_map(out / "maps" / f"M_{res.name}.yaml").data,
                              res.updated.data)
    for name in NAMES[1:]:
        for path in session_output_paths(out, name):
            twin = tmp / "full" / path.relative_to(out)
            assert filecmp.cmp(path, twin, shallow=False), path.name


def test_a_resumed_run_reads_back_only_what_is_kept(played, tmp_path):
    tmp, yaml, run, _, _ = played
    scn = sim.load_scenario(yaml)
    back, _ = finished_sessions(tmp / "run", scn, len(NAMES))
    assert_kept_as_documented(back, tmp / "run")

    # W4 is played again; W2's trajectories and figures, lost, are drawn again from disk
    out = tmp_path / "run"
    shutil.copytree(tmp / "run", out)
    progress = out / "state" / "progress.json"
    state = json.loads(progress.read_text())
    progress.write_text(json.dumps(dict(state, finished=NAMES[:3])))
    lost = session_output_paths(out, "W2")
    for path in lost:
        path.unlink()
    resumed = run_scenario(None, RunOptions(out=out, resume=True, progress=False))
    assert_kept_as_documented(resumed.sessions, out)
    for a, b in zip(resumed.metrics["sessions"], run.metrics["sessions"], strict=True):
        assert scores(a) == scores(b), a["name"]
    for path in lost:
        assert filecmp.cmp(path, tmp / "run" / path.relative_to(out), shallow=False), path.name
    for name in NAMES:
        assert filecmp.cmp(out / "maps" / f"M_{name}.pgm", tmp / "run" / "maps" /
                           f"M_{name}.pgm", shallow=False)
