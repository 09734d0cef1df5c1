"""A fleet that shares one map (mapstore.merge, docs/map_store.md "Merges"): a commit whose
parent is no longer the latest is merged three-way with what came since; approving a sibling
merges it the same way; the first map of a site is taken once; a map in another frame is
refused; the frame is under the fingerprint; a store of schema 1 is upgraded. Expectations are
built cell by cell, independently of the merge code."""

from __future__ import annotations

import itertools
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from mapstore import StoreError, cells, merge, open_store
from mapupdate import main

DATA = Path(__file__).parent / "data"
VALUES = (FREE, OCCUPIED, UNKNOWN)
# ``target``: an SQLite file, then a database on this file's PostgreSQL server (conftest.py)


def room() -> OccupancyGrid:
    """40 x 60 cells: walls, two boxes, an unknown corner."""
    d = np.full((40, 60), FREE, np.int8)
    d[[0, -1], :] = OCCUPIED
    d[:, [0, -1]] = OCCUPIED
    d[10:14, 10:16] = OCCUPIED          # box 1
    d[25:29, 30:36] = OCCUPIED          # box 2
    d[30:39, 45:59] = UNKNOWN           # a corner no scan reached
    return OccupancyGrid(d, 0.05, (-1.0, 0.5))


def with_cells(g: OccupancyGrid, rows: slice, cols: slice, value: int) -> OccupancyGrid:
    d = g.data.copy()
    d[rows, cols] = value
    return g.with_data(d)


# --- the rule, against a cell-by-cell reference ------------------------------------------------
def reference(base, ours, theirs, theirs_wins):
    out = np.empty_like(ours)
    for k, (b, o, t) in enumerate(zip(base.flat, ours.flat, theirs.flat)):
        if o == t or t == b:
            out.flat[k] = o
        elif o == b:
            out.flat[k] = t
        else:
            out.flat[k] = t if theirs_wins else o
    return out


def test_three_way_follows_the_rule_cell_by_cell():
    # every combination of the three values in base, ours and theirs, in both settings
    combos = np.array(list(itertools.product(VALUES, repeat=3)), np.int8)
    base, ours, theirs = (combos[:, k].reshape(3, 9) for k in range(3))
    for wins in (False, True):
        m = merge.three_way(base, ours, theirs, wins)
        assert np.array_equal(m.data, reference(base, ours, theirs, wins))
        conflicting = (ours != base) & (theirs != base) & (ours != theirs)
        assert len(m.conflicts) == int(conflicting.sum()) == 6
        assert np.array_equal(m.conflicts.index, np.flatnonzero(conflicting))
        assert np.array_equal(m.conflicts.chosen, (theirs if wins else ours)[conflicting])
        back = merge.unpack_conflicts(*merge.pack_conflicts(m.conflicts))
        assert np.array_equal(back.theirs, m.conflicts.theirs)
    rng = np.random.default_rng(3)
    base, ours, theirs = (rng.choice(np.array(VALUES, np.int8), (30, 30)) for _ in range(3))
    assert np.array_equal(merge.three_way(base, ours, theirs, True).data,
                          reference(base, ours, theirs, True))
    # no common ancestor: every cell where the two differ is a conflict
    assert len(merge.three_way(None, ours, theirs, True).conflicts) == int((ours != theirs).sum())


# --- merges in a store --------------------------------------------------------------------------
def test_two_robots_from_the_same_version_both_land(target):
    """The case that lost 15 262 cells: two sessions from v1, the second committed after the
    first; the site map keeps both."""
    base = room()
    a = with_cells(base, slice(10, 14), slice(10, 16), FREE)            # box 1 gone
    b = with_cells(base, slice(5, 8), slice(40, 44), OCCUPIED)          # a new pallet
    with open_store(target, create=True) as s:
        s.commit(base, None, {"method": "import"})
        assert s.commit(a, 1, {"robot": "r1"}) == 2 and s.merged is None
        assert s.commit(b, 1, {"robot": "r2"}) == 3 and s.merged == 4
        assert s.latest() == 4
        expected = with_cells(a, slice(5, 8), slice(40, 44), OCCUPIED).data
        assert np.array_equal(s.get(4).data, expected)
        v4 = s.version(4)
        assert (v4.parent, v4.merge_parent, v4.status) == (2, 3, "approved")
        assert v4.meta["base"] == 1 and v4.meta["cells"]["conflicts"] == 0
        assert v4.meta["cells"]["from_theirs"] == 12
        assert v4.counts["cells_drawn"] == 12 and v4.counts["cells_changed"] == 12
        assert len(s.conflicts(4)) == 0 and s.conflicts(3) is None


def test_a_conflict_goes_to_the_side_committed_last_and_is_listed(target):
    base = room()
    corner = (slice(30, 33), slice(45, 50))                   # unknown in the base
    a = with_cells(base, *corner, FREE)
    b = with_cells(with_cells(base, *corner, OCCUPIED), slice(31, 32), slice(45, 50), FREE)
    same = with_cells(a, slice(10, 14), slice(10, 16), FREE)  # both freed box 1 too
    b = with_cells(b, slice(10, 14), slice(10, 16), FREE)
    with open_store(target, create=True) as s:
        s.commit(base, None)
        s.commit(same, 1, {"robot": "r1"})
        s.commit(b, 1, {"robot": "r2"})
        m = s.merged
        got = s.get(m).data
        assert np.array_equal(got, b.data)          # r2 committed last: its cells where both
        c = s.conflicts(m)                          # changed the corner differently
        assert len(c) == 10 and s.version(m).meta["conflicts_to"] == "theirs"
        assert set(c.base.tolist()) == {UNKNOWN} and set(c.ours.tolist()) == {FREE}
        assert set(c.theirs.tolist()) == {OCCUPIED} and np.array_equal(c.chosen, c.theirs)
        rows = c.index // base.width
        assert set(rows.tolist()) == {30, 32}
        assert s.version(m).meta["cells"]["same_on_both"] == 24 + 5   # box 1 and row 31


def test_approving_siblings_in_turn_merges_the_second(target):
    """Review on: two pending siblings of v1; approving the second no longer reverts the
    first's changes."""
    base = room()
    a = with_cells(base, slice(10, 14), slice(10, 16), FREE)
    b = with_cells(base, slice(25, 29), slice(30, 36), FREE)
    with open_store(target, create=True) as s:
        s.commit(base, None)
        s.set_require_approval(True)
        s.commit(a, 1, {"robot": "r1"})
        s.commit(b, 1, {"robot": "r2"})
        assert s.merged is None and s.latest() == 1        # both pending, nothing merged
        s.approve(2)
        assert s.merged is None and s.latest() == 2
        s.approve(3)
        assert s.merged == 4 and s.latest() == 4 and s.version(4).status == "approved"
        expected = with_cells(a, slice(25, 29), slice(30, 36), FREE).data
        assert np.array_equal(s.get(4).data, expected)
        assert (s.version(4).parent, s.version(4).merge_parent) == (2, 3)


def test_with_review_on_a_merge_made_at_commit_waits_for_approval(target):
    base = room()
    a = with_cells(base, slice(10, 14), slice(10, 16), FREE)
    b = with_cells(base, slice(5, 8), slice(40, 44), OCCUPIED)
    c = with_cells(a, slice(25, 29), slice(30, 36), FREE)
    with open_store(target, create=True) as s:
        s.commit(base, None)
        s.commit(a, 1)                                  # approved: review is still off
        s.set_require_approval(True)
        s.commit(b, 1)                                  # v3, and its merge with v2: v4
        assert s.merged == 4 and s.version(4).status == "pending" and s.latest() == 2
        s.commit(c, 2)                                  # v5: a child of the latest, no merge
        assert s.merged is None
        s.approve(5)
        assert s.latest() == 5
        s.approve(4)                                    # v4 no longer holds the latest: merged
        assert s.merged == 6 and s.latest() == 6
        want = with_cells(with_cells(a, slice(5, 8), slice(40, 44), OCCUPIED),
                          slice(25, 29), slice(30, 36), FREE).data
        assert np.array_equal(s.get(6).data, want)
        s.approve(3)                                    # held by v6 already: nothing to merge
        assert s.merged is None and s.latest() == 6


def test_a_random_fleet_ends_with_every_change_the_last_commit_made(target):
    """Six robots commit 30 sessions in a shuffled order, each from whatever version it last
    saw (often not the latest). The reference replays every session's own changes (against
    the map it started from) in commit order, the last change of a cell winning: the rule the
    merges promise with review off."""
    rng = np.random.default_rng(11)
    base = room()
    site = base.data.copy()
    with open_store(target, create=True) as s:
        s.commit(base, None)
        seen = {r: 1 for r in range(6)}
        for k in range(30):
            robot = int(rng.integers(6))
            start = s.get(seen[robot])
            d = start.data.copy()
            for _ in range(int(rng.integers(1, 4))):       # 1-3 objects moved or appeared
                r, c = int(rng.integers(1, 36)), int(rng.integers(1, 56))
                d[r:r + 3, c:c + 4] = rng.choice(np.array(VALUES, np.int8))
            changed = d != start.data
            site[changed] = d[changed]
            s.commit(start.with_data(d), seen[robot], {"robot": f"r{robot}", "k": k})
            if rng.random() < 0.5:                        # picks up the site map now and then
                seen[robot] = s.latest()
        final = s.get(s.latest()).data
        merges = [v for v in s.log() if v.merge_parent is not None]
    assert len(merges) >= 10
    assert np.array_equal(final, site), int((final != site).sum())


def test_the_first_map_of_a_site_is_taken_once(target, tmp_path):
    """Four robots starting an empty store at once with the same map make one history."""
    np.save(tmp_path / "room.npy", room().data)
    script = (
        "import sys, os, time, numpy as np\n"
        "from gridmap import OccupancyGrid\n"
        "from mapstore import open_store\n"
        "target, folder, k = sys.argv[1], sys.argv[2], int(sys.argv[3])\n"
        "g = OccupancyGrid(np.load(folder + '/room.npy'), 0.05, (-1.0, 0.5))\n"
        "d = g.data.copy(); d[3:5, 4 + 12 * k:8 + 12 * k] = 100\n"
        "while not os.path.exists(folder + '/go'): time.sleep(0.005)\n"
        "with open_store(target, create=True) as s:\n"
        "    first = s.commit(g, None, {'method': 'import', 'robot': f'r{k}'})\n"
        "    print(first, s.commit(g.with_data(d), first, {'robot': f'r{k}'}), flush=True)\n")
    procs = [subprocess.Popen([sys.executable, "-c", script, target, str(tmp_path), str(k)],
                              stdout=subprocess.PIPE, text=True) for k in range(4)]
    (tmp_path / "go").touch()
    outs = [p.communicate(timeout=120)[0].split() for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert {o[0] for o in outs} == {"1"}                 # every robot found the same v1
    with open_store(target) as s:
        assert [v.parent for v in s.log()][0] is None
        assert sum(v.parent is None for v in s.log()) == 1
        final = s.get(s.latest()).data
    want = room().data.copy()
    for k in range(4):
        want[3:5, 4 + 12 * k:8 + 12 * k] = OCCUPIED
    assert np.array_equal(final, want)


def test_a_map_in_another_frame_is_refused_and_one_in_the_same_joins_the_history(target):
    base = room()
    with open_store(target, create=True) as s:
        s.commit(base, None)
        for other in (OccupancyGrid(base.data, 0.1, base.origin),
                      OccupancyGrid(base.data, 0.05, (0.0, 0.0)),
                      OccupancyGrid(np.zeros((40, 61), np.int8), 0.05, base.origin)):
            with pytest.raises(StoreError, match="is not in the frame of the store's first "
                                                 "map v1") as e:
                s.commit(other, None, {"source": "intel.yaml"})
            assert "\n" not in str(e.value)
        assert s.commit(base, None) == 1 and len(s.log()) == 1        # the same map: v1
        edited = with_cells(base, slice(10, 14), slice(10, 16), FREE)
        assert s.commit(edited, None) == 2 and s.version(2).parent == 1


def test_a_commit_id_makes_a_retry_write_nothing_twice(target):
    base = room()
    with open_store(target, create=True) as s:
        s.commit(base, None)
        a = with_cells(base, slice(10, 14), slice(10, 16), FREE)
        assert s.commit(a, 1, uid="amr-07:2026-12-06:1") == 2
        assert s.commit(a, 1, uid="amr-07:2026-12-06:1") == 2
        assert len(s.log()) == 2 and s.version(2).uid == "amr-07:2026-12-06:1"
        with pytest.raises(StoreError, match="cannot be a commit id"):
            s.commit(a, 1, uid="a b\n")


# --- the frame under the fingerprint, and the schema upgrade --------------------------------------
def test_a_flipped_bit_of_the_frame_is_refused(tmp_path, capsys):
    path = tmp_path / "maps.db"
    with open_store(str(path), create=True) as s:
        s.commit(room(), None)
    for column in ("origin_x", "resolution"):
        shutil.copy(path, tmp_path / "damaged.db")
        db = sqlite3.connect(tmp_path / "damaged.db")
        value = db.execute(f"SELECT {column} FROM mapstore_versions").fetchone()[0]
        bits = np.array([value], np.float64).view(np.int64)
        bits ^= 1                                         # the last bit of the mantissa
        db.execute(f"UPDATE mapstore_versions SET {column} = ?", (float(bits.view(np.float64)[0]),))
        db.commit()
        db.close()
        with open_store(str(tmp_path / "damaged.db")) as s, \
                pytest.raises(StoreError, match="v1 are damaged .their fingerprint differs"):
            s.get(1)
        out = tmp_path / f"{column}.yaml"
        assert main(["store", "export", "1", "--out", str(out), "--store",
                     str(tmp_path / "damaged.db")]) == 2
        assert not out.exists()
        assert "fingerprint differs" in capsys.readouterr().err


def test_a_store_of_schema_1_is_upgraded_and_keeps_its_versions(tmp_path):
    path = tmp_path / "old.db"
    shutil.copy(DATA / "store_schema1.db", path)
    with open_store(str(path)) as s:
        assert [v.number for v in s.log()] == [1, 2] and s.resolve("box-gone") == 2
        g1, g2 = s.get(1), s.get(2)
        assert int((g1.data != g2.data).sum()) == 24 and g1.origin == (-1.0, 0.5)
        assert s.diff(1, 2).counts()["occupied_to_free"] == 24
        # and it takes merges at once
        s.commit(with_cells(g1, slice(5, 7), slice(40, 44), OCCUPIED), 1)
        assert s.merged == 4
        assert int((s.get(4).data != g1.data).sum()) == 24 + 8
    db = sqlite3.connect(path)
    assert db.execute("SELECT value FROM mapstore_info WHERE key = 'schema'").fetchone() == ("2",)
    db.close()
    # a damaged schema-1 store is not upgraded
    shutil.copy(DATA / "store_schema1.db", tmp_path / "bad.db")
    db = sqlite3.connect(tmp_path / "bad.db")
    db.execute("UPDATE mapstore_maps SET sha256 = 'x' WHERE version = 2")
    db.commit()
    db.close()
    with pytest.raises(StoreError, match="v2 are damaged"):
        open_store(str(tmp_path / "bad.db"))
    db = sqlite3.connect(tmp_path / "bad.db")
    assert db.execute("SELECT value FROM mapstore_info WHERE key = 'schema'").fetchone() == ("1",)
    db.close()


def test_store_log_shows_the_merge_and_its_conflicts(tmp_path, capsys):
    base = room()
    path = str(tmp_path / "maps.db")
    with open_store(path, create=True) as s:
        s.commit(base, None, {"method": "import", "source": "room.yaml"})
        s.commit(with_cells(base, slice(30, 32), slice(45, 48), FREE), 1, {"robot": "r1"})
        s.commit(with_cells(base, slice(30, 32), slice(45, 48), OCCUPIED), 1, {"robot": "r2"})
    assert main(["store", "log", "--store", path]) == 0
    out = capsys.readouterr().out
    assert "v2+v3" in out
    assert "merge of v3 into v2 (base v1; 6 conflicts to theirs)" in out
    assert main(["store", "show", "4", "--store", path]) == 0
    out = capsys.readouterr().out
    assert "6 cells changed in different ways on the two sides" in out
    rows = [line.split() for line in out.splitlines() if line.strip().startswith(("30 ", "31 "))]
    assert len(rows) == 6 and all(r[2:] == ["unk", "free", "occ", "occ"] for r in rows)
    # review on: approving a sibling says it was merged
    with open_store(path) as s:
        s.set_require_approval(True)
        s.commit(with_cells(s.get(4), slice(5, 7), slice(5, 9), OCCUPIED), 4, {"robot": "r1"})
        s.commit(with_cells(s.get(4), slice(20, 22), slice(5, 9), OCCUPIED), 4, {"robot": "r2"})
    assert main(["store", "approve", "5", "--store", path]) == 0
    assert main(["store", "approve", "6", "--store", path]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == \
        "v6 approved, merged with the latest as v7 (0 conflicts); robots now start from v7"
    assert cells.changes_between(base.data, base.data).counts()["cells_changed"] == 0


# --- a live node's link: a newer version does not throw away a session ------------------------
def test_a_node_taking_up_a_newer_version_keeps_its_uncommitted_changes(target):
    """A node has freed box 1 and not committed; another robot's version (box 2 freed)
    appears. The node goes on from that version with its own change laid on it, and its
    commit, made on the newer version, keeps both."""
    from onboard.ros_common.store_link import StoreLink

    base = room()
    with open_store(target, create=True) as s:
        s.commit(base, None, {"method": "import"})
    link = StoreLink(target, robot="r1", poll_period=10.0)
    assert np.array_equal(link.start(None).data, base.data) and link.version == 1
    mine = with_cells(base, slice(10, 14), slice(10, 16), FREE)
    with open_store(target) as s:
        s.commit(with_cells(base, slice(25, 29), slice(30, 36), FREE), 1, {"robot": "r2"})
    number, grid = link.newer(force=True, session=(base, mine))
    both = with_cells(mine, slice(25, 29), slice(30, 36), FREE)
    assert number == 2 and link.version == 2 and np.array_equal(grid.data, both.data)
    assert link.newer(force=True, session=(grid, grid)) is None       # nothing newer now
    # the node commits what it has: a child of v2 with its own box, no merge needed
    number, status, merged = link.commit(both, {"method": "robot"})
    assert (number, status, merged) == (3, "approved", None)
    with open_store(target) as s:
        assert s.version(3).parent == 2 and s.version(3).counts["cells_freed"] == 24
        assert np.array_equal(s.get(s.latest()).data, both.data)
    # without a session (or one with no changes) the newer version is taken as it is
    with open_store(target) as s:
        s.commit(with_cells(both, slice(5, 8), slice(40, 44), OCCUPIED), 3, {"robot": "r2"})
    number, grid = link.newer(force=True, session=(both, both))
    assert number == 4 and np.array_equal(grid.data, with_cells(both, slice(5, 8),
                                                                slice(40, 44), OCCUPIED).data)
