"""State that survives a crash: a run killed while it writes keeps its previous maps and state
intact, and ``mapupdate run --resume DIR`` ends with the same maps as a run never interrupted
(quick routes, three sessions)."""

from __future__ import annotations

import filecmp
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gridmap import load_map, map_io
import mapupdate as cli
from scenarios.checkpoint import ResumeError
from scenarios.runner import RunOptions, run_scenario

SESSIONS = 3
SCORES = ("map_metrics", "change_detection", "ghost_cells", "localization")


def run(out: Path, **kw):
    return run_scenario(None, RunOptions(out=out, quick=True, sessions=SESSIONS, progress=False,
                                         **kw))


def finished(out: Path) -> list[str]:
    path = out / "state" / "progress.json"
    return json.loads(path.read_text())["finished"] if path.exists() else []


def assert_same_run(a: Path, b: Path) -> None:
    """Every map, mask and trajectory file identical, and the same scores."""
    maps = sorted(p.name for p in (a / "maps").iterdir())
    assert maps == sorted(p.name for p in (b / "maps").iterdir())
    assert len([m for m in maps if m.startswith("M_")]) == 2 * SESSIONS
    for name in maps:
        assert filecmp.cmp(a / "maps" / name, b / "maps" / name, shallow=False), name
    for name in os.listdir(a / "trajectories"):
        assert filecmp.cmp(a / "trajectories" / name, b / "trajectories" / name,
                           shallow=False), name
    ma, mb = (json.loads((d / "metrics.json").read_text()) for d in (a, b))
    for sa, sb in zip(ma["sessions"], mb["sessions"], strict=True):
        assert {k: sa.get(k) for k in SCORES} == {k: sb.get(k) for k in SCORES}


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("whole")
    run(out)
    return out


class Killed(BaseException):
    """Stands for SIGKILL: nothing after it runs, no except clause of the program catches it."""


def test_killed_while_writing_a_map_keeps_the_last_session_and_resumes_exactly(
        tmp_path, uninterrupted, monkeypatch):
    write = map_io._write_atomically

    def dies_half_way(path, content):
        if path.name == "M_W3.pgm":                   # the third session's output map
            tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
            tmp.write_bytes(content[:len(content) // 2])
            raise Killed
        write(path, content)
    monkeypatch.setattr(map_io, "_write_atomically", dies_half_way)
    with pytest.raises(Killed):
        run(tmp_path)
    monkeypatch.undo()

    # The previous session's map and state are whole; the half-written one never got a name.
    assert finished(tmp_path) == ["W1", "W2"]
    for name in ("M_W1", "M_W2", "G_W2", "oracle_W2"):
        for ext in (".yaml", ".pgm"):
            assert filecmp.cmp(tmp_path / "maps" / f"{name}{ext}",
                               uninterrupted / "maps" / f"{name}{ext}", shallow=False)
    assert not (tmp_path / "maps" / "M_W3.pgm").exists()
    assert load_map(tmp_path / "maps" / "M_W2.yaml").same_frame(
        load_map(uninterrupted / "maps" / "M_W2.yaml"))

    result = run(tmp_path, resume=True)
    assert [s.name for s in result.sessions] == ["W1", "W2", "W3"]
    assert finished(tmp_path) == ["W1", "W2", "W3"]
    assert_same_run(tmp_path, uninterrupted)


def test_killed_by_a_signal_mid_session_resumes_from_the_command_line(tmp_path, uninterrupted):
    cmd = [sys.executable, "-m", "mapupdate", "run", "--quick", "--sessions", str(SESSIONS),
           "--out", str(tmp_path), "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while finished(tmp_path) != ["W1", "W2"] and proc.poll() is None:
        assert time.monotonic() < deadline, "the run never finished W2"
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)                  # in W3, or writing its maps
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()
    done = finished(tmp_path)
    assert done in (["W1", "W2"], ["W1", "W2", "W3"])

    resumed = subprocess.run([sys.executable, "-m", "mapupdate", "run", "--resume",
                              str(tmp_path), "--no-progress"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert finished(tmp_path) == ["W1", "W2", "W3"]     # the run's own --sessions 3
    assert_same_run(tmp_path, uninterrupted)


def test_resume_refuses_a_different_run_with_one_line(tmp_path, uninterrupted, capsys):
    with pytest.raises(ResumeError, match="no run to resume"):
        run_scenario(None, RunOptions(out=tmp_path, resume=True, progress=False))
    with pytest.raises(ResumeError, match="the run has seed = 7, not 8"):
        run_scenario(None, RunOptions(out=uninterrupted, resume=True, seed=8, progress=False))
    with pytest.raises(ResumeError, match="the run played .*aws_small_warehouse.yaml, not "
                                          "warehouse_people_only"):
        run_scenario("warehouse_people_only", RunOptions(out=uninterrupted, resume=True,
                                                         progress=False))
    assert cli.main(["run", "--resume", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mapupdate run: error:") and "no run to resume" in err
    assert "\n" not in err


def test_a_finished_run_resumed_only_rewrites_its_reports(tmp_path, uninterrupted):
    import shutil

    shutil.copytree(uninterrupted, tmp_path / "run")
    (tmp_path / "run" / "report.md").unlink()
    t0 = time.perf_counter()
    result = run_scenario(None, RunOptions(out=tmp_path / "run", resume=True, progress=False))
    assert time.perf_counter() - t0 < 15            # no session is played again
    assert (tmp_path / "run" / "report.md").exists() and len(result.sessions) == SESSIONS
    assert_same_run(tmp_path / "run", uninterrupted)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "pickled"])
@pytest.mark.parametrize("victim", ["maps/masks_W2.npz", "state/session_W2.npz"])
def test_a_damaged_array_file_is_one_line_and_nothing_is_overwritten(tmp_path, uninterrupted,
                                                                    capsys, victim, damage):
    import hashlib
    import shutil

    run_dir = tmp_path / "run"
    shutil.copytree(uninterrupted, run_dir)
    # W2's figures gone, as an earlier version left them: the resume reads W2 back to draw them
    (run_dir / "fig_maps_W2.png").unlink()
    path = run_dir / victim
    if damage == "garbage":
        path.write_bytes(b"PK\x03\x04 not a zip at all" * 10)
    elif damage == "truncated":
        path.write_bytes(path.read_bytes()[:300])
    else:
        np.savez(path.with_suffix(""), time=np.array([{"a": 1}], dtype=object))
    before = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in run_dir.rglob("*")
              if p.is_file() and p.name != "lock"}
    assert cli.main(["run", "--resume", str(run_dir), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mapupdate run: error:") and "\n" not in err
    assert victim.split("/")[1] in err and "cannot be resumed" in err
    after = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in run_dir.rglob("*")
             if p.is_file() and p.name != "lock"}
    assert {p: h for p, h in after.items() if p in before} == before
