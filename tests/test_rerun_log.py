"""Rerun recordings of a run: every entity is in the file with the rows its logging rule gives,
on both timelines, and the command line writes one headless (no viewer is ever spawned here)."""

import math
from collections import Counter

import pytest
from rerun.chunk import RrdReader

from mapupdate import main
from scenarios.rerun_log import ENTITIES, RerunRecorder
from scenarios.runner import RunOptions, run_scenario
from tiny_room import write_tiny_room


def rows_by_entity(path):
    """Rows of the recording's temporal chunks per entity path, and each one's timelines."""
    rows, timelines = Counter(), {}
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.is_static:
            continue
        name = chunk.entity_path.lstrip("/")
        rows[name] += chunk.num_rows
        timelines.setdefault(name, set()).update(chunk.timeline_names)
    return rows, timelines


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rerun")
    yaml = write_tiny_room(tmp / "tiny_room.yaml")
    recorder = RerunRecorder(tmp / "run.rrd")
    try:
        run = run_scenario(yaml, RunOptions(out=tmp / "out", progress=False, observer=recorder))
    finally:
        recorder.close()
    return tmp / "run.rrd", run


def test_every_entity_is_recorded_with_its_rows(recorded):
    path, run = recorded
    rows, timelines = rows_by_entity(path)
    assert set(ENTITIES) <= set(rows), set(ENTITIES) - set(rows)
    updates = run.metrics["sessions"][1:]
    n = len(updates)
    scans = sum(s["resources"]["scans"] for s in updates)
    seconds = sum(s["resources"]["simulated_s"] for s in updates)
    for entity in ("world/scan", "world/people", "world/robot/true", "world/robot/estimate",
                   "scores/localization_error", "scores/cells_changed"):
        assert rows[entity] == scans, entity
    # the filter's estimate changes at its first odometry and at every update
    assert rows["world/particles"] == sum(s["resources"]["localizer_updates"] + 1
                                          for s in updates)
    for entity in ("world/truth/objects", "world/truth/G", "world/maps/reference"):
        assert rows[entity] == n, entity
    assert rows["log/sessions"] == 2 * n
    # maps when they change, at most once per simulated second
    for entity in ("world/maps/updated", "world/maps/change_counts"):
        assert 2 * n <= rows[entity] <= math.ceil(seconds) + n, entity
    assert rows["world/maps/changed"] == rows["world/maps/updated"]
    assert rows["scores/correct_changes"] == rows["world/maps/updated"]
    assert 2 * n <= rows["world/robot/true_path"] <= math.ceil(seconds / 5) + 2 * n
    assert rows["scores/session/f1"] == n
    for entity in ENTITIES:
        assert {"sim_time", "scan"} <= timelines[entity], entity


def test_the_recording_holds_a_blueprint(recorded):
    path, _ = recorded
    assert len(RrdReader(path).blueprints()) == 1


def test_command_line_writes_a_recording_and_never_spawns_without_a_display(
        tmp_path, monkeypatch, capsys):
    yaml = write_tiny_room(tmp_path / "tiny_room.yaml")
    rrd = tmp_path / "rec" / "run.rrd"
    assert main(["run", str(yaml), "--out", str(tmp_path / "out"), "--no-progress",
                 "--rerun", str(rrd)]) == 0
    rows, _ = rows_by_entity(rrd)
    assert rows["world/scan"] > 100
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr("sys.platform", "linux")
    assert main(["run", str(yaml), "--out", str(tmp_path / "out2"), "--no-progress",
                 "--rerun-spawn"]) == 0
    assert "no display" in capsys.readouterr().err


def test_a_recorder_needs_somewhere_to_write():
    with pytest.raises(ValueError):
        RerunRecorder(None, spawn=False)
