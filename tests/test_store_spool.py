"""No session lost (docs/map_store.md): ``mapupdate update --store`` keeps a session whose
commit fails (a store's write lock held too long, a PostgreSQL server stopped) in the spool
and exits 3; ``mapupdate store push`` commits it once the store is back, once however often it
is pushed; the next update pushes the spool first; a mistyped store is not made; a killed
update's working folder is removed by the next. The failures are real: an SQLite lock held by
another connection, a PostgreSQL server stopped or paused (SIGSTOP) while the session runs."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from gridmap import load_map, save_map
from mapstore import backends, open_store, spool
from mapupdate import main, robot_commands

import synthetic_room as world

BOX = world.Rect(5.2, 5.2, 5.8, 5.8)
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def room(tmp_path, monkeypatch):
    """A map with the box, a log of the robot circling the room with the box gone, a spool
    and a temporary folder of the test's own."""
    save_map(world.rasterise(world.room_walls() + [BOX]), tmp_path / "map.yaml")
    poses = [p for p, _, _ in world.Drive(seconds=30, rate=10.0).steps()]
    world.carmen_log(tmp_path / "gone.log", poses, [0.1 * k for k in range(len(poses))])
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    monkeypatch.delenv(spool.ENV, raising=False)
    return tmp_path


def started(target, room) -> str:
    """``target`` holding the room's map as v1."""
    with open_store(target, create=True) as s:
        s.commit(load_map(room / "map.yaml"), None, {"robot": "setup"})
    return target


def update(capsys, room, target, *extra) -> tuple[int, str, str]:
    code = main(["update", "--log", room / "gone.log", "--store", target, "--robot", "r7",
                 "--spool", room / "spool", "--no-progress", *map(str, extra)])
    out = capsys.readouterr()
    return code, out.out, out.err


def push(capsys, room, target) -> tuple[int, str]:
    code = main(["store", "push", "--store", str(target), "--spool", str(room / "spool")])
    out = capsys.readouterr()
    assert out.err == ""
    return code, out.out


def spooled(room) -> list[Path]:
    folder = room / "spool"
    return sorted(p for p in folder.iterdir() if not p.name.startswith(".")) \
        if folder.exists() else []


def versions(target) -> list[int]:
    with open_store(target) as s:
        return [v.number for v in s.log()]


def session_then(monkeypatch, action):
    """Run ``action`` once the session's parent is read and the store closed, just before the
    update itself: a failure at the commit, not before."""
    real = robot_commands._update

    def then(*a, **k):
        action()
        return real(*a, **k)
    monkeypatch.setattr(robot_commands, "_update", then)


def hold_sqlite_lock(monkeypatch, path) -> sqlite3.Connection:
    """Another connection holding the SQLite store's write lock; the store gives up after
    0.5 s instead of a minute."""
    monkeypatch.setattr(backends, "LOCK_TIMEOUT", 0.5)
    holder = sqlite3.connect(str(path), isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    return holder


def failed_on_sqlite(capsys, monkeypatch, room, target, *extra):
    """An update whose commit meets the store's write lock held by another connection:
    (exit code, stdout, stderr, the holder)."""
    held = []
    session_then(monkeypatch, lambda: held.append(hold_sqlite_lock(monkeypatch, target)))
    code, out, err = update(capsys, room, target, *extra)
    monkeypatch.undo()
    return code, out, err, held[0]


def test_a_commit_that_meets_a_held_lock_is_spooled_and_pushed_once(room, capsys,
                                                                      monkeypatch):
    target = started(str(room / "a.db"), room)
    code, out, err, holder = failed_on_sqlite(capsys, monkeypatch, room, target)
    assert code == 3
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "not committed" in lines[0] and "locked" in lines[0], err
    [entry] = spooled(room)
    assert str(entry) in lines[0]
    hint = lines[0].split("commit it later with: ", 1)[1]
    assert hint == f"mapupdate store push --store {Path(target).resolve()} " \
                   f"--spool {(room / 'spool').resolve()}"
    assert f"wrote {entry / 'map.yaml'}: 144 occupied cells freed" in out
    assert versions(target) == [1]                    # nothing was committed
    record = json.loads((entry / "entry.json").read_text())
    assert record["parent"] == 1 and re.fullmatch(r"[0-9a-f]{32}", record["uid"])
    assert record["meta"]["robot"] == "r7" and record["meta"]["log_name"] == "gone.log"
    assert record["meta"]["uid"] == record["uid"] and record["store"] == str(Path(target))
    assert sorted(p.name for p in entry.iterdir()) == ["entry.json", "map.pgm", "map.yaml"]

    # the spooled map is what a successful run commits from the same parent
    other = started(str(room / "b.db"), room)
    assert update(capsys, room, other)[0] == 0
    with open_store(other) as s:
        assert np.array_equal(load_map(entry / "map.yaml").data, s.get(2).data)

    # pushed while the lock is still held: kept, with why
    monkeypatch.setattr(backends, "LOCK_TIMEOUT", 0.5)
    code, out = push(capsys, room, target)
    assert code == 3 and out.startswith(f"kept {entry.name}: ") and "locked" in out
    holder.rollback()
    holder.close()
    copy = shutil.copytree(entry, room / "copy")
    code, out = push(capsys, room, target)
    assert (code, out) == (0, f"pushed {entry.name}: v2 (parent v1; approved)\n")
    assert spooled(room) == [] and versions(target) == [1, 2]
    with open_store(target) as s:
        assert np.array_equal(s.get(2).data, load_map(copy / "map.yaml").data)
        assert s.version(2).meta["uid"] == record["uid"]
    # a push killed after its commit, before the entry was removed, pushed again: no twin
    shutil.copytree(copy, entry)
    code, out = push(capsys, room, target)
    assert (code, out) == (0, f"pushed {entry.name}: already in the store as v2 (parent v1; "
                              "approved)\n")
    assert spooled(room) == [] and versions(target) == [1, 2]
    assert push(capsys, room, target) == (0, f"{Path(target).resolve()}: no spooled sessions "
                                             f"in {room / 'spool'}\n")


def test_an_update_after_a_failed_one_pushes_the_spool_first(room, capsys, monkeypatch):
    target = started(str(room / "maps.db"), room)
    code, _, _, holder = failed_on_sqlite(capsys, monkeypatch, room, target)
    assert code == 3
    holder.rollback()
    holder.close()
    [entry] = spooled(room)
    code, out, err = update(capsys, room, target)
    assert code == 0, err
    lines = out.splitlines()
    assert lines[:2] == [f"pushing 1 spooled session for {target} first",
                         f"pushed {entry.name}: v2 (parent v1; approved)"]
    # this session started from what was pushed
    assert lines[-1] == f"committed v3 to {target} (parent v2; approved)"
    assert spooled(room) == [] and versions(target) == [1, 2, 3]


def test_the_first_map_of_an_empty_store_waits_in_the_spool_too(room, capsys, monkeypatch):
    target = str(room / "new.db")
    code, _, err, holder = failed_on_sqlite(capsys, monkeypatch, room, target,
                                            "--map", room / "map.yaml")
    assert code == 3, err
    holder.rollback()
    holder.close()
    [entry] = spooled(room)
    assert (entry / "start.yaml").exists() and versions(target) == []
    code, out = push(capsys, room, target)
    assert (code, out) == (0, f"pushed {entry.name}: v2 (parent v1; approved), its first map "
                              "as v1\n")
    with open_store(target) as s:
        assert np.array_equal(s.get(1).data, load_map(room / "map.yaml").data)
        assert s.version(1).meta["method"] == "import" and s.version(2).meta["started_from"] == 1


def pg_stop(srv):
    srv._pg_ctl("-m", "immediate", "stop")


def pg_start(srv):
    srv._pg_ctl("-o", srv.options, "-l", str(srv.folder / "log"), "-w", "-t", "60", "start")


def connections_to(srv, url) -> int:
    import psycopg
    with psycopg.connect(srv.url(), autocommit=True) as conn:
        return conn.execute("SELECT count(*) FROM pg_stat_activity WHERE datname = %s",
                            (url.rsplit("/", 1)[1],)).fetchone()[0]


def test_a_postgresql_server_stopped_during_the_session(room, capsys, monkeypatch, postgres):
    srv = postgres                      # this file's own server (conftest.py)
    # trust authentication: the password is sent for nothing, and must never be written
    target = started(srv.new_database().replace("postgres@", "postgres:s3cret@"), room)
    open_during_session = []

    def stop():
        open_during_session.append(connections_to(srv, target))
        pg_stop(srv)
    session_then(monkeypatch, stop)
    try:
        code, out, err = update(capsys, room, target)
        monkeypatch.undo()
        assert open_during_session == [0]          # the store was closed while it ran
        assert code == 3, err
        [entry] = spooled(room)
        assert str(entry) in err and err.count("\n") == 1
        assert f"push --store {shlex.quote(backends.redacted(target))} --spool" in err
        record = json.loads((entry / "entry.json").read_text())
        assert record["store"] == backends.redacted(target) and record["parent"] == 1
        for text in [out, err] + [f.read_bytes().decode("latin-1") for f in entry.iterdir()]:
            assert "s3cret" not in text
        # the server still down: kept, and said why
        code, out = push(capsys, room, target)
        assert code == 3 and out.startswith(f"kept {entry.name}: ") and out.count("\n") == 1
        assert "s3cret" not in out
    finally:
        pg_start(srv)
    # another robot committed meanwhile: the store merges the pushed session with it
    with open_store(target) as s:
        s.commit(s.get(1), 1, {"robot": "other"})
    code, out = push(capsys, room, target)
    assert code == 0 and out.startswith(f"pushed {entry.name}: v3 (parent v1; approved)")
    with open_store(target) as s:
        assert s.version(3).parent == 1 and s.version(3).meta["uid"] == record["uid"]
        if getattr(s, "merged", "absent") != "absent":      # the store merges
            assert out == f"pushed {entry.name}: v3 (parent v1; approved), merged with v2 " \
                          f"as v4 (0 conflicts)\n"
        n = len(s.log())
    assert push(capsys, room, target)[0] == 0 and versions(target)[-1] == n


def test_a_paused_postgresql_server_keeps_the_session_within_seconds(room, capsys, monkeypatch,
                                                                     postgres):
    srv = postgres
    target = started(srv.new_database(), room)
    real = robot_commands._update

    def then_pause(*a, **k):           # the session runs, then the server stops answering
        done = real(*a, **k)
        srv.pause()
        return done
    monkeypatch.setattr(robot_commands, "_update", then_pause)
    try:
        code, out, err = update(capsys, room, target)
    finally:
        srv.resume()
    monkeypatch.undo()
    assert code == 3 and "no answer" in err, err
    [entry] = spooled(room)
    assert push(capsys, room, target) == (0, f"pushed {entry.name}: v2 (parent v1; approved)\n")


def test_update_with_a_missing_store_and_no_map_makes_nothing(room, capsys):
    target = room / "typo.db"
    code, out, err = update(capsys, room, target)
    assert code == 2 and out == ""
    assert err == f"mapupdate update: error: {target}: no map store there, so it holds no " \
                  "approved map yet; give --map to start it (nothing was made)\n"
    assert sorted(p.name for p in room.iterdir()) == ["gone.log", "map.pgm", "map.yaml", "tmp"]
    # a target that is no store's URL is the store's to refuse, its password never shown
    code, out, err = update(capsys, room, "postgresq://me:s3cret@127.0.0.1/maps")
    assert code == 2 and "unknown scheme" in err and "s3cret" not in err


STUCK = """
import sys, time
from mapupdate import main, robot_commands
def stuck(*a, **k):
    print("session", flush=True)
    time.sleep(600)
robot_commands._update = stuck
sys.exit(main(sys.argv[1:]))
"""


def test_a_killed_update_leaves_its_working_folder_to_the_next(room, capsys):
    target = started(str(room / "maps.db"), room)
    env = {**os.environ, "TMPDIR": str(room / "tmp"), "PYTHONPATH": str(ROOT)}
    p = subprocess.Popen([sys.executable, "-c", STUCK, "update", "--log", str(room / "gone.log"),
                          "--store", target, "--spool", str(room / "spool"), "--no-progress"],
                         stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert p.stdout.readline().strip() == "session"
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait()
    [left] = list((room / "tmp").iterdir())
    assert left.name.startswith(f"mapupdate-{p.pid}-") and (left / "start.yaml").exists()
    # and a spool entry it was writing when killed (hidden until renamed into place)
    half = room / "spool" / f".tmp-{p.pid}@{socket.gethostname()}-0123abcd"
    half.mkdir(parents=True)
    # a live process's folder stays, whatever its age
    with spool.working_folder() as live:
        os.utime(live, (0, 0))
        assert update(capsys, room, target)[0] == 0
        assert list((room / "tmp").iterdir()) == [live]
    assert list((room / "tmp").iterdir()) == [] and list((room / "spool").iterdir()) == []


def test_the_spool_folder_is_chosen_as_documented(monkeypatch, tmp_path):
    monkeypatch.delenv(spool.ENV, raising=False)
    monkeypatch.delenv("XDG_DATA_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert spool.folder() == tmp_path / "home/.local/share/mapupdate/spool"
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    assert spool.folder() == tmp_path / "data/mapupdate/spool"
    monkeypatch.setenv(spool.ENV, str(tmp_path / "env"))
    assert spool.folder() == tmp_path / "env"
    assert spool.folder(tmp_path / "given") == tmp_path / "given"
