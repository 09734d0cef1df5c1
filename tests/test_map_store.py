"""The map store (mapstore, docs/map_store.md): versions whole or absent whatever is killed
when, writers that never interleave, the same results in an SQLite file and in a real
PostgreSQL server, review, rollback and tags, and the commands ``mapupdate store`` and
``mapupdate update --store``."""

from __future__ import annotations

import math
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, load_map, save_map
from mapstore import StoreError, cells, open_store
from mapstore.png import COLORS
from mapupdate import main

import synthetic_room as world

# ``target`` (an SQLite file, then a database on this file's PostgreSQL server) and
# ``postgres`` (the server) are tests/conftest.py's


def grid(seed: int, shape=(60, 90)) -> OccupancyGrid:
    rng = np.random.default_rng(seed)
    data = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], np.int8), size=shape, p=[.7, .1, .2])
    return OccupancyGrid(data, 0.05, (-1.5, 2.0))


def edited(g: OccupancyGrid, rows: slice, cols: slice, value: int) -> OccupancyGrid:
    d = g.data.copy()
    d[rows, cols] = value
    return g.with_data(d)


def whole(store) -> list[int]:
    """Every version's map read back (fingerprint checked) and equal to its parent's with its
    stored changes applied; returns the version numbers, which must run 1..n."""
    numbers = [v.number for v in store.log()]
    assert numbers == list(range(1, len(numbers) + 1))
    for v in store.log():
        g = store.get(v.number)
        if v.parent is not None:
            ch = store.diff(v.parent, v.number)
            assert np.array_equal(cells.apply_changes(store.get(v.parent).data, ch), g.data)
            assert ch.counts() == v.counts
    return numbers


# --- the encoding ------------------------------------------------------------------------------
def test_cells_and_changes_round_trip():
    a, b = grid(1), edited(grid(1), slice(5, 20), slice(30, 33), OCCUPIED)
    assert np.array_equal(cells.unpack_cells(cells.pack_cells(a.data), a.shape), a.data)
    ch = cells.changes_between(a.data, b.data)
    back = cells.unpack_changes(*cells.pack_changes(ch))
    assert np.array_equal(back.index, ch.index) and np.array_equal(back.after, ch.after)
    assert np.array_equal(cells.apply_changes(a.data, back), b.data)
    empty = cells.unpack_changes(*cells.pack_changes(cells.changes_between(a.data, a.data)))
    assert len(empty) == 0


# --- one sequence, both databases -----------------------------------------------------------------
def sequence_maps():
    base = grid(0)
    moved = edited(edited(base, slice(10, 14), slice(10, 30), FREE), slice(40, 44),
                   slice(50, 70), OCCUPIED)
    return base, moved, edited(moved, slice(20, 22), slice(0, 90), OCCUPIED)


def sequence(target) -> list:
    """Commits, a branch, review, a rollback, tags and diffs; what each step answered."""
    out = []
    base, moved, fourth = sequence_maps()
    with open_store(target, create=True) as s:
        out.append(s.commit(base, None, {"robot": "r1", "log": "W1.bag"}))
        out.append(s.commit(moved, 1, {"robot": "r1", "log": "W2.bag"}))
        s.set_require_approval(True)
        out.append(s.commit(edited(moved, slice(0, 5), slice(0, 5), UNKNOWN), 2, {"robot": "r2"}))
        out += [s.version(3).status, s.latest(), s.latest(approved_only=False)]
        out.append(s.reject(3, "ghost"))
        out.append(s.commit(fourth, 2, {}))
        out.append(s.approve("v4"))
        out += [s.latest(), s.tag(4, "shift-2"), s.resolve("shift-2"), s.rollback(1)]
        out += [s.diff(a, b).counts() for a, b in ((1, 2), (2, 1), (3, 4), (1, 5), (4, 5))]
        out += [(v.number, v.parent, v.status, v.tags, v.counts, v.meta.get("robot"))
                for v in s.log()]
        out += [cells.digest(s.get(v).data) for v in range(1, 6)]
        out.append(whole(s))
        with pytest.raises(StoreError, match="v3 is rejected, not pending"):
            s.approve(3)
        with pytest.raises(StoreError, match="a rollback goes back to an approved"):
            s.rollback(3)
        with pytest.raises(StoreError, match="no version 9 .versions 1 to 5"):
            s.get(9)
        with pytest.raises(StoreError, match="tag 'shift-2' already names v4"):
            s.tag(5, "shift-2")
    return out


def test_a_sequence_of_commits_reviews_and_rollbacks_on_sqlite(tmp_path):
    out = sequence(str(tmp_path / "maps.db"))
    # commits 1, 2, 3 (pending: review on), latest approved 2, head 3; reject 3; commit 4,
    # approve it; latest 4, tag and resolve it; the rollback to v1 is v5
    assert out[:14] == [1, 2, 3, "pending", 2, 3, 3, 4, 4, 4, 4, 4, 5, out[13]]
    c12, c21, c34, c15, c45 = out[13:18]
    base, moved, fourth = (m.data for m in sequence_maps())
    assert c12["cells_changed"] == int((base != moved).sum())
    assert c12["cells_changed"] == int((base[10:14, 10:30] != FREE).sum()
                                       + (base[40:44, 50:70] != OCCUPIED).sum())
    assert (c21["cells_changed"], c21["occupied_to_free"], c21["free_to_occupied"]) == \
        (c12["cells_changed"], c12["free_to_occupied"], c12["occupied_to_free"])
    assert c34["known_to_unknown"] + c34["cells_freed"] + c34["cells_drawn"] == \
        c34["cells_changed"] > 0
    assert c15["cells_changed"] == 0                          # the rollback is v1's map
    assert c45["cells_changed"] == int((fourth != base).sum())
    log = {row[0]: row for row in out if isinstance(row, tuple)}
    assert [log[v][2] for v in range(1, 6)] == ["approved", "approved", "rejected", "approved",
                                              "approved"]
    assert log[4][3] == ("shift-2",) and log[5][1] == 4      # the rollback's parent: v4
    digests = out[-6:-1]
    assert digests[4] == digests[0] and len(set(digests)) == 4     # v5 is v1's map again
    assert out[-1] == [1, 2, 3, 4, 5]


def test_the_same_sequence_gives_the_same_results_on_sqlite_and_postgresql(tmp_path, postgres):
    pg = postgres.new_database()
    assert sequence(pg) == sequence(str(tmp_path / "maps.db"))


# --- kills and concurrent writers ---------------------------------------------------------------
WRITER = """
import os, sys, time, numpy as np
from gridmap import OccupancyGrid
from mapstore import open_store
target, stop_at, count, tag, size = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
print("ready", flush=True)
while len(sys.argv) > 6 and not os.path.exists(sys.argv[6]):   # a start line for all writers
    time.sleep(0.01)
def hook(step):
    if step == stop_at:
        print(step, flush=True)
        time.sleep(600)
with open_store(target) as s:
    s.hook = hook
    for k in range(count):
        parent = s.latest()
        base = s.get(parent) if parent else OccupancyGrid(np.zeros((size, size), np.int8), 0.05)
        d = base.data.copy()
        n = d.shape[0]
        d[(k * 7) % n, :] = 100                         # a row of this writer's
        d[:, sum(map(ord, tag)) % n] = -1
        s.commit(base.with_data(d), parent, {"writer": tag, "k": k})
        print("done", k, flush=True)
        if len(sys.argv) > 6:       # as robots do, not back to back: the other gets its turn
            time.sleep(0.02)
"""


def writer(target, stop_at="", count=1, tag="w", size=300, start=None):
    p = subprocess.Popen([sys.executable, "-c", WRITER, target, stop_at, str(count), tag,
                          str(size)] + ([str(start)] if start else []),
                         stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    return p


def seeded(target, n=2):
    with open_store(target, create=True) as s:
        for k in range(n):
            s.commit(edited(grid(0, (300, 300)), slice(k, k + 1), slice(0, 300), OCCUPIED),
                     s.latest(), {"writer": "seed"})


@pytest.mark.parametrize("step", ["locked", "version row", "map row", "changes row", "written"])
def test_a_commit_killed_at_each_step_leaves_the_versions_before_it_whole(target, step):
    seeded(target)
    p = writer(target, stop_at=step)
    assert p.stdout.readline().strip() == step
    p.send_signal(signal.SIGKILL)
    p.wait()
    with open_store(target) as s:
        assert whole(s) == [1, 2]
        assert s.commit(grid(3, (300, 300)), 2, {}) == 3     # and the store goes on


def test_commits_killed_after_random_delays_leave_whole_versions(target):
    seeded(target, 1)
    rng = random.Random(7)
    for _ in range(4):
        p = writer(target, count=100_000)
        time.sleep(rng.uniform(0.05, 0.8))
        assert p.poll() is None                  # killed while committing, not after
        p.send_signal(signal.SIGKILL)
        p.wait()
        with open_store(target) as s:
            n = len(whole(s))
    assert n > 1


def test_a_commit_killed_after_its_transaction_is_kept(target):
    seeded(target)
    p = writer(target, stop_at="committed")
    assert p.stdout.readline().strip() == "committed"
    p.send_signal(signal.SIGKILL)
    p.wait()
    with open_store(target) as s:
        assert whole(s) == [1, 2, 3]


def test_two_writers_at_once_never_interleave_a_version(target, tmp_path):
    seeded(target, 1)
    writers = [writer(target, count=15, tag=t, start=tmp_path / "go") for t in ("a", "b")]
    (tmp_path / "go").touch()
    for w in writers:
        w.communicate(timeout=120)
        assert w.returncode == 0
    with open_store(target) as s:
        numbers = whole(s)
        own = [v for v in s.log()[1:] if v.merge_parent is None]
        done = [(v.meta["writer"], v.meta["k"]) for v in own]
        assert sorted(done) == sorted((t, k) for t in "ab" for k in range(15))
        # they did write at once: one's versions come between the other's, and a commit made
        # from a version that was no longer the latest was merged with what came since
        order = "".join(w for w, _ in done)
        assert "ab" in order and "ba" in order, order
        assert len(numbers) == 31 + sum(v.merge_parent is not None for v in s.log())
        cols = [sum(map(ord, w)) % 300 for w in "ab"]
        for v in own:              # each version holds its own writer's row and column, whole
            d, col = s.get(v.number).data, sum(map(ord, v.meta["writer"])) % 300
            assert (np.delete(d[(v.meta["k"] * 7) % 300], col) == OCCUPIED).all()
            assert (d[:, col] == UNKNOWN).all()
        # and the site's map lost no writer's row: every row both drew is there
        final = s.get(s.latest()).data
        for w, k in done:
            assert (np.delete(final[(k * 7) % 300], cols) == OCCUPIED).all(), (w, k)


# --- opening, errors ----------------------------------------------------------------------------
def test_robots_opening_a_new_sqlite_store_together_all_get_in(tmp_path):
    """Six robots opening the same new file at once, 40 files in turn: switching a new file
    to WAL while another does is answered "database is locked" at once (without SQLite's busy
    wait) about once in 18 opens; the store waits instead, so every open succeeds."""
    script = (
        "import os, sys, time\n"
        "from mapstore.backends import connect\n"
        "folder, n = sys.argv[1], int(sys.argv[2])\n"
        "for i in range(n):\n"
        "    while not os.path.exists(f'{folder}/go{i}'): time.sleep(0.001)\n"
        "    connect(f'{folder}/s{i}.db', True).close()\n"
        "print('ok', flush=True)\n")
    files = 40
    procs = [subprocess.Popen([sys.executable, "-c", script, str(tmp_path), str(files)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(6)]
    time.sleep(1.0)                           # the imports are done before the first go
    for i in range(files):
        (tmp_path / f"go{i}").touch()
        time.sleep(0.03)
    outs = [p.communicate(timeout=120) for p in procs]
    assert [o.strip() for o, _ in outs] == ["ok"] * 6, [e.strip()[-200:] for _, e in outs]


def test_what_is_not_a_store_is_refused_in_one_line(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("hello")
    cases = {str(tmp_path / "missing.db"): "no map store there",
             str(tmp_path / "notes.txt"): "not a map store .not an SQLite database",
             str(tmp_path): "not a map store .not a regular file"}
    import sqlite3
    other = tmp_path / "other.db"
    sqlite3.connect(other).execute("CREATE TABLE t (x)").connection.commit()
    cases[str(other)] = "not a map store"
    for path, message in cases.items():
        assert main(["store", "log", "--store", path]) == 2
        err = capsys.readouterr().err
        assert err.startswith("mapupdate store: error: ") and err.count("\n") == 1
        assert re.search(message, err), err
    assert main(["store", "init", "--store", str(other)]) == 2
    assert "other tables" in capsys.readouterr().err


def test_an_unreachable_server_is_refused_within_seconds(capsys):
    import socket
    with socket.socket() as s:          # a port with nothing behind it
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    assert main(["store", "log", "--store", f"postgresql://me:secret@127.0.0.1:{port}/maps"]) == 2
    err = capsys.readouterr().err
    assert time.monotonic() - t0 < 8
    assert "cannot reach the database within 5 s" in err and "secret" not in err


# --- the commands -------------------------------------------------------------------------------
def run(capsys, *argv) -> str:
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    assert code == 0, out.err
    return out.out


def test_store_commands(target, tmp_path, capsys):
    base = grid(0, (80, 120))
    with open_store(target, create=True) as s:
        s.commit(base, None, {"robot": "r1", "log_name": "W1.bag", "method": "paper"})
        s.commit(edited(edited(base, slice(10, 20), slice(10, 20), FREE), slice(50, 52),
                        slice(60, 80), OCCUPIED), 1, {"robot": "r1", "log_name": "W2.bag"})
    out = run(capsys, "store", "init", "--require-approval", "--store", target)
    assert "2 versions; new versions wait" in out
    out = run(capsys, "store", "log", "--store", target)
    assert "review on" in out and "r1 W2.bag" in out
    out = run(capsys, "store", "show", "v2", "--store", target)
    assert "parent           v1" in out and "robot            r1" in out
    png = tmp_path / "d.png"
    out = run(capsys, "store", "diff", "1", "2", "--png", png, "--store", target)
    assert "v1 -> v2" in out and "wrote" in out
    image = np.asarray(Image.open(png).convert("RGB"))
    colours = {tuple(c) for c in image.reshape(-1, 3)}
    assert COLORS["freed"] in colours and COLORS["drawn"] in colours
    run(capsys, "store", "tag", "2", "good", "--store", target)
    assert "good" in run(capsys, "store", "tag", "--store", target)
    run(capsys, "store", "export", "good", "--out", tmp_path / "good.yaml", "--store", target)
    with open_store(target) as s:
        assert np.array_equal(load_map(tmp_path / "good.yaml").data, s.get(2).data)
    assert "a copy of v1" in run(capsys, "store", "rollback", "1", "--store", target)
    assert main(["store", "show", "7", "--store", target]) == 2
    assert "no version 7" in capsys.readouterr().err


# --- update --store: sessions, review ----------------------------------------------------------
BOX = world.Rect(5.2, 5.2, 5.8, 5.8)


def room_log(path: Path, with_box: bool) -> Path:
    """ROBOTLASER1 lines (270 deg, 1 deg apart) of the robot circling the room's middle, the
    box there or gone."""
    shapes = world.room_walls() + ([BOX] if with_box else [])
    lines = []
    for k, (pose, _, _) in enumerate(world.Drive(seconds=30, rate=10.0).steps()):
        scan = world.partial_scan(shapes, pose, 0.0, fov_deg=270.0, beams=271)
        r = " ".join(f"{v:.3f}" for v in np.minimum(scan.ranges, 81.83))
        p = f"{pose.x:.6f} {pose.y:.6f} {pose.theta:.6f}"
        lines.append(f"ROBOTLASER1 0 {-math.radians(135):.6f} {math.radians(270):.6f} "
                     f"{math.radians(1):.8f} 81.83 0.01 0 271 {r} 0 {p} {p} 0 0 0 0 0 "
                     f"{0.1 * k:.3f} h 0")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_sessions_commit_versions_and_a_rejected_one_is_not_proposed_again(target, tmp_path,
                                                                            capsys):
    save_map(world.rasterise(world.room_walls() + [BOX]), tmp_path / "map.yaml")
    gone, there = room_log(tmp_path / "gone.log", False), room_log(tmp_path / "there.log", True)
    store = target
    run(capsys, "store", "init", "--require-approval", "--store", store)
    update = ["update", "--log", None, "--store", store, "--robot", "r7", "--no-progress"]
    out = run(capsys, *update[:2], gone, *update[3:], "--map", tmp_path / "map.yaml")
    assert "as v1, the first map" in out and "committed v2" in out and "pending" in out
    with open_store(store) as s:
        box = np.zeros(s.get(1).shape, bool)
        box[world.cells_of(BOX)] = True
        freed = s.diff(1, 2)
        assert s.latest() == 1 and freed.counts()["occupied_to_free"] > 0
        assert box.reshape(-1)[freed.index].any()
        meta = s.version(2).meta
        assert meta["robot"] == "r7" and meta["log_name"] == "gone.log"
        assert meta["scans"]["scans"] == 300 and meta["time_span"] == [0.0, 29.9]
        assert meta["config"]["updater"]["threshold"] > 0 and meta["started_from"] == 1
    run(capsys, "store", "reject", "2", "--store", store)
    # the next session starts from v1: its scans, which show the box, propose nothing
    run(capsys, *update[:2], there, *update[3:])
    with open_store(store) as s:
        assert s.version(3).parent == 1
        assert not box.reshape(-1)[s.diff(1, 3).index].any()
    run(capsys, "store", "reject", "3", "--store", store)
    # ... and a session whose scans show the box gone again proposes it again
    run(capsys, *update[:2], gone, *update[3:])
    with open_store(store) as s:
        assert s.version(4).parent == 1
        assert box.reshape(-1)[s.diff(1, 4).index].any()
    run(capsys, "store", "approve", "4", "--store", store)
    with open_store(store) as s:
        assert s.latest() == 4


def test_update_store_refusals(tmp_path, capsys):
    save_map(grid(0), tmp_path / "map.yaml")
    save_map(grid(1), tmp_path / "other.yaml")
    log = room_log(tmp_path / "gone.log", False)
    store = tmp_path / "maps.db"
    cases = [(["--map", tmp_path / "map.yaml", "--state", tmp_path / "s.npz"],
              "--state does not go with --store"),
             ([], "holds no approved map yet; give --map")]
    for extra, message in cases:
        assert main(["update", "--log", log, "--store", store, "--no-progress", *extra]) == 2
        assert message in capsys.readouterr().err
    # a session that fails leaves an empty store empty: the map given is not committed alone
    (tmp_path / "bad.log").write_text("not a log\n")
    assert main(["update", "--log", tmp_path / "bad.log", "--store", store, "--map",
                 tmp_path / "map.yaml", "--no-progress", "--strict"]) == 2
    capsys.readouterr()
    with open_store(store) as s:
        assert s.log() == []
    with open_store(store, create=True) as s:
        s.commit(grid(0), None, {})
    assert main(["update", "--log", log, "--store", store, "--map", tmp_path / "other.yaml",
                 "--no-progress"]) == 2
    assert "not the store's latest approved map v1" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        main(["update", "--log", log, "--map", tmp_path / "map.yaml"])
    assert stop.value.code == 2
    assert "arguments are required: --out (see" in capsys.readouterr().err


def test_no_output_of_a_store_command_is_the_store_itself(tmp_path, capsys):
    save_map(grid(0), tmp_path / "map.yaml")
    store = tmp_path / "maps.db"
    with open_store(store, create=True) as s:
        s.commit(grid(0), None, {})
        s.commit(grid(1), 1, {})
    before = store.read_bytes()
    log = room_log(tmp_path / "gone.log", False)
    for argv in (["store", "diff", "1", "2", "--png", store, "--store", store],
                 ["store", "export", "latest", "--out", store, "--store", store],
                 ["update", "--log", log, "--store", store, "--out", store, "--no-progress"],
                 ["update", "--log", log, "--store", store, "--trajectory", store,
                  "--no-progress"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"which is input --store ({store})" in err[0], err
    assert store.read_bytes() == before


def test_a_damaged_map_is_refused_never_served(tmp_path):
    import sqlite3
    import zlib
    path = tmp_path / "maps.db"
    with open_store(path, create=True) as s:
        s.commit(grid(0), None, {})
        s.commit(grid(1), 1, {})
    db = sqlite3.connect(path)
    db.execute("UPDATE mapstore_maps SET cells = ? WHERE version = 1",
               (zlib.compress(grid(2).data.tobytes()),))
    db.execute("UPDATE mapstore_maps SET cells = ? WHERE version = 2", (b"garbage",))
    db.commit()
    db.close()
    with open_store(path) as s:
        with pytest.raises(StoreError, match="cells of v1 are damaged .their fingerprint"):
            s.get(1)
        with pytest.raises(StoreError, match="cells of v2 are damaged"):
            s.get(2)


def test_a_postgresql_store_without_psycopg_says_what_to_install():
    code = ("import sys; sys.modules['psycopg'] = None\n"
            "from mapupdate import main\n"
            "sys.exit(main(['store', 'log', '--store', 'postgresql://127.0.0.1:9/x']))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2
    assert "needs psycopg" in p.stderr and "lidar-map-updating[store]" in p.stderr


def test_run_commits_each_session_as_a_version(tmp_path):
    from gridmap import load_map
    from mapstore import open_store
    from mapupdate import main

    db = tmp_path / "maps.db"
    assert main(["run", "--quick", "--sessions", "3", "--out", str(tmp_path / "run"),
                 "--store", str(db), "--no-progress"]) == 0
    with open_store(db) as store:
        versions = store.log()
        assert [v.number for v in versions] == [1, 2, 3]
        assert [v.parent for v in versions] == [None, 1, 2]
        assert [v.meta.get("session") for v in versions[1:]] == ["W2", "W3"]
        for number, name in ((1, "M_W1"), (2, "M_W2"), (3, "M_W3")):
            assert np.array_equal(store.get(number).data,
                                  load_map(tmp_path / f"run/maps/{name}.yaml").data)
