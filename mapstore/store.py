"""The map store: one version per commit, each holding its map, the cells it changed against
its parent and what made it, in an SQLite file or a PostgreSQL database with the same schema.
A fleet shares one history: a commit whose parent is no longer the latest version is merged
with what came since (``merge``), and a merge is a version with two parents.

A version is written in one transaction (its row, its map and its changes), so it is whole or
absent whatever is killed when; writers take the store's write lock first (see
``backends``), so version numbers, assigned inside the transaction, never clash. A version's
map is never changed afterwards: a rollback is a new version equal to an old one. With review
on (``require_approval``) a version is ``pending`` until approved or rejected, and only
approved versions count as ``latest``, the map robots start from.
"""

from __future__ import annotations

import functools
import json
import re
import time
import uuid
import zlib
from dataclasses import dataclass, field


import numpy as np

from gridmap import OccupancyGrid

from . import cells, history, merge
from .backends import ConnectionLost, StoreError, connect, database_errors
from .text import NAME_LIMIT, NOTE_LIMIT, check_text

SCHEMA_VERSION = "2"
TABLES = ("mapstore_info", "mapstore_versions", "mapstore_maps", "mapstore_changes",
          "mapstore_tags", "mapstore_conflicts")
# {blob} and {real}: each database's names for bytes and doubles; nothing else differs
SCHEMA = (
    "CREATE TABLE IF NOT EXISTS mapstore_info (key TEXT PRIMARY KEY, value TEXT NOT NULL)",
    "CREATE TABLE IF NOT EXISTS mapstore_versions (version BIGINT PRIMARY KEY, "
    "parent BIGINT REFERENCES mapstore_versions (version), status TEXT NOT NULL, "
    "created {real} NOT NULL, reviewed {real}, note TEXT, width BIGINT NOT NULL, "
    "height BIGINT NOT NULL, resolution {real} NOT NULL, origin_x {real} NOT NULL, "
    "origin_y {real} NOT NULL, meta TEXT NOT NULL, counts TEXT NOT NULL, "
    "merge_parent BIGINT REFERENCES mapstore_versions (version), uid TEXT UNIQUE)",
    "CREATE TABLE IF NOT EXISTS mapstore_maps (version BIGINT PRIMARY KEY REFERENCES "
    "mapstore_versions (version), sha256 TEXT NOT NULL, cells {blob} NOT NULL)",
    "CREATE TABLE IF NOT EXISTS mapstore_changes (version BIGINT PRIMARY KEY REFERENCES "
    "mapstore_versions (version), against BIGINT NOT NULL, cells BIGINT NOT NULL, "
    "idx {blob} NOT NULL, vals {blob} NOT NULL)",
    "CREATE TABLE IF NOT EXISTS mapstore_tags (name TEXT PRIMARY KEY, version BIGINT NOT NULL "
    "REFERENCES mapstore_versions (version), created {real} NOT NULL)",
    "CREATE TABLE IF NOT EXISTS mapstore_conflicts (version BIGINT PRIMARY KEY REFERENCES "
    "mapstore_versions (version), base BIGINT, cells BIGINT NOT NULL, idx {blob} NOT NULL, "
    "vals {blob} NOT NULL)",
)
# schema 1 to 2: merges (a second parent and their conflicts), commit ids, the frame under the
# fingerprint
UPGRADE_1 = (
    "ALTER TABLE mapstore_versions ADD COLUMN merge_parent BIGINT",
    "ALTER TABLE mapstore_versions ADD COLUMN uid TEXT",
    "CREATE UNIQUE INDEX IF NOT EXISTS mapstore_versions_uid ON mapstore_versions (uid)",
    SCHEMA[-1],
)
STATUSES = ("approved", "pending", "rejected")
TAG_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9._-]{0,63}")
RESERVED = ("latest", "head")
VERSION_COLUMNS = ("version, parent, status, created, reviewed, note, width, height, "
                   "resolution, origin_x, origin_y, meta, counts, merge_parent, uid")
UID = re.compile(r"[A-Za-z0-9._:-]{1,128}")
# how many times a commit plans outside the write lock before it plans under it (each time
# another writer moved the latest version while it planned)
PLAN_TRIES = 3
# how many times a commit is written when its connection is lost inside the write (the
# database reconnects first; the commit's id finds a write that did land)
LOST_TRIES = 3


@dataclass(frozen=True)
class Version:
    """What the store knows of a version besides its cells."""

    number: int
    parent: int | None
    status: str
    created: float                 # [s] since the epoch, when it was committed
    reviewed: float | None         # when it was approved or rejected
    note: str | None               # the reviewer's note
    shape: tuple[int, int]         # (height, width) [cells]
    resolution: float
    origin: tuple[float, float]
    meta: dict                     # what made it (robot, log, scans, method, ...)
    counts: dict                   # its changes against its parent, by kind
    tags: tuple[str, ...] = field(default=())
    merge_parent: int | None = None  # a merge's second parent: the version merged in
    uid: str | None = None         # the committer's id of the commit (a retry finds it)


def _one_line_errors(method):
    """The databases' own errors (a full disk, a lock held too long, a lost connection) as
    one-line ``StoreError``s naming the store."""
    @functools.wraps(method)
    def wrapped(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except database_errors() as e:
            text = " ".join(str(e).split()) or type(e).__name__
            raise StoreError(f"{self.name}: {text}") from None
    return wrapped


class Store:
    """A map store opened by :func:`open_store`. ``hook``, when set, is called with the name of
    each step of a write (so the tests can kill a writer at each)."""

    def __init__(self, db):
        self.db = db
        self.name = db.name
        self.hook = None
        # (number, map) of the last version read or written: a session's commit compares its
        # map with the parent it has just read, and a map never changes once committed
        self._last: tuple[int, OccupancyGrid] | None = None
        # the merge the last commit or approval made (its number), None when it made none
        self.merged: int | None = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        self.db.close()

    def _at(self, step: str) -> None:
        if self.hook is not None:
            self.hook(step)

    # --- the schema ------------------------------------------------------------------------
    @_one_line_errors
    def _init(self) -> None:
        with self.db.write():
            if (self.db.kind == "sqlite" and not self.db.has_table("mapstore_info")
                    and self.db.rows("SELECT COUNT(*) FROM sqlite_master")[0][0]):
                # another program's database: its tables are not to be mixed with ours
                raise StoreError(f"{self.name}: not a map store (an SQLite database of "
                                 "other tables)")
            for sql in SCHEMA:
                self.db.run(sql.format(blob=self.db.blob, real=self.db.real))
            if not self.db.rows("SELECT value FROM mapstore_info WHERE key = 'schema'"):
                self.db.run("INSERT INTO mapstore_info VALUES ('schema', ?)", (SCHEMA_VERSION,))
                self.db.run("INSERT INTO mapstore_info VALUES ('require_approval', '0')")

    @_one_line_errors
    def _check(self) -> None:
        if not self.db.has_table("mapstore_info"):
            raise StoreError(f"{self.name}: not a map store (make one with 'mapupdate store "
                             f"init --store ...')")
        found = [r[0] for r in
                 self.db.rows("SELECT value FROM mapstore_info WHERE key = 'schema'")]
        if found == ["1"]:
            self._upgrade()
        elif found != [SCHEMA_VERSION]:
            raise StoreError(f"{self.name}: a map store of another schema "
                             f"({found[0] if found else 'none'}; this one reads "
                             f"{SCHEMA_VERSION})")

    def _upgrade(self) -> None:
        """Schema 1 to 2 in one transaction: the new columns and table, and each version's
        fingerprint taken again with its frame once its cells are checked against the old."""
        with self.db.write():
            if self.db.rows("SELECT value FROM mapstore_info WHERE key = 'schema'")[0][0] != "1":
                return                  # another process upgraded it while this one waited
            for sql in UPGRADE_1:
                self.db.run(sql.format(blob=self.db.blob, real=self.db.real))
            frames = self.db.rows("SELECT version, width, height, resolution, origin_x, "
                                  "origin_y FROM mapstore_versions")
            for number, width, height, res, ox, oy in frames:
                sha, blob = self.db.rows("SELECT sha256, cells FROM mapstore_maps WHERE "
                                         "version = ?", (number,))[0]
                try:
                    data = cells.unpack_cells(blob, (int(height), int(width)))
                except (ValueError, zlib.error):
                    data = None
                if data is None or cells.digest(data) != sha:
                    raise StoreError(f"{self.name}: the cells of v{number} are damaged (their "
                                     "fingerprint differs); the store is left at schema 1")
                self.db.run("UPDATE mapstore_maps SET sha256 = ? WHERE version = ?",
                            (cells.fingerprint(data, res, (ox, oy)), number))
            self.db.run("UPDATE mapstore_info SET value = ? WHERE key = 'schema'",
                        (SCHEMA_VERSION,))

    @property
    @_one_line_errors
    def require_approval(self) -> bool:
        rows = self.db.rows("SELECT value FROM mapstore_info WHERE key = 'require_approval'")
        return bool(rows) and rows[0][0] == "1"

    @_one_line_errors
    def set_require_approval(self, on: bool) -> None:
        with self.db.write():
            self.db.run("UPDATE mapstore_info SET value = ? WHERE key = 'require_approval'",
                        ("1" if on else "0",))

    # --- writing ---------------------------------------------------------------------------
    @_one_line_errors
    def commit(self, grid: OccupancyGrid, parent: int | None = None, meta: dict | None = None,
               status: str | None = None, uid: str | None = None) -> int:
        """Add ``grid`` as a new version whose parent is ``parent`` and return its number.

        ``parent`` None: a first map; into a store that has one already, the map is taken as
        a child of that first map (the same cells: that version itself, nothing written), so
        a site keeps one history however many robots start it at once. A parent that is no
        longer the latest approved version is merged with it (``self.merged``: the merge's
        number). ``meta``: what made it (JSON). ``status``: None for the store's rule
        (pending with review on, else approved). ``uid``: the committer's id for this
        commit; a commit whose uid the store holds already returns that version (a retry
        after a lost answer writes nothing twice)."""
        if not isinstance(grid, OccupancyGrid):
            raise StoreError(f"{self.name}: a version needs an OccupancyGrid, got "
                             f"{type(grid).__name__}")
        if status is not None and status not in STATUSES:
            raise StoreError(f"{self.name}: unknown status {status!r} ({', '.join(STATUSES)})")
        if uid is not None and not UID.fullmatch(str(uid)):
            raise StoreError(f"{self.name}: {uid!r} cannot be a commit id (1-128 letters, "
                             "digits, '.', '_', ':' or '-')")
        _check_meta(self.name, meta or {})
        meta_text = _json(self.name, meta or {})
        # every commit has an id, so that one whose connection was lost inside its write can
        # be written again without being written twice
        uid = uuid.uuid4().hex if uid is None else str(uid)
        for attempt in range(LOST_TRIES):
            try:
                return self._commit(grid, parent, meta_text, status, uid)
            except ConnectionLost:
                if attempt + 1 == LOST_TRIES:
                    raise
        raise AssertionError("unreachable: the last try raises")

    def _commit(self, grid, parent, meta_text, status, uid) -> int:
        self.merged = None
        if (done := self._by_uid(uid)) is not None:
            self.merged = self._merge_of(done)
            return done
        parent = None if parent is None else self.resolve(parent)
        # the slow part, reading, merging and packing maps, is done before the lock is taken;
        # when another writer moved the latest version meanwhile it is done again, outside
        # the lock while tries last, then under it (so a commit always ends)
        plan = self._plan(grid, parent)
        for attempt in range(PLAN_TRIES):
            with self.db.write():
                self._at("locked")
                if (done := self._by_uid(uid)) is not None:
                    self.merged = self._merge_of(done)
                    return done
                if (self._root(), self.latest()) != (plan.root, plan.latest):
                    if attempt + 1 < PLAN_TRIES:
                        moved = True
                    else:
                        plan, moved = self._plan(grid, parent), False
                else:
                    moved = False
                if not moved:
                    number = self._write_commit(plan, grid, meta_text, status, uid)
            if moved:
                plan = self._plan(grid, parent)
                continue
            self._at("committed")
            if plan.same_as is None:
                self._last = (number, grid.copy())
            return number
        raise AssertionError("unreachable: the last try plans under the lock")

    def _write_commit(self, plan: "_Plan", grid, meta_text, status, uid) -> int:
        if plan.same_as is not None:
            return plan.same_as
        number = self._next_number()
        if status is None:
            status = "pending" if self.require_approval else "approved"
        self._insert(number, plan.parent, status, grid, meta_text, plan.packed, uid=uid)
        if plan.merge is not None:
            self.merged = self._write_merge(plan.latest, number, plan.merge, status)
        self._at("written")
        return number

    def _plan(self, grid: OccupancyGrid, parent: int | None) -> "_Plan":
        root, latest = self._root(), self.latest()
        same_as = None
        if parent is None and root is not None:
            first = self.get(root)
            self._check_frame(grid, first, f"the store's first map v{root}")
            if np.array_equal(first.data, grid.data):
                same_as = root
            parent = root
        before = None if parent is None else self.get(parent)
        if before is not None:
            self._check_frame(grid, before, f"its parent v{parent}")
        graph = self._graph()
        holds_latest = (latest is None or parent is None
                        or history.holds(graph, parent, latest))
        if same_as is not None:
            return _Plan(root, latest, parent, same_as, None, None)
        # the committing session is the newest there is: conflicts go to it
        to_merge = None if holds_latest else self._merged(
            latest, grid, history.common_ancestor(graph, latest, parent), True)
        return _Plan(root, latest, parent, None, _packed(grid, before), to_merge)

    def _check_frame(self, grid: OccupancyGrid, other: OccupancyGrid, what: str) -> None:
        if not other.same_frame(grid):
            raise StoreError(f"{self.name}: the map ({grid.shape[0]} x {grid.shape[1]} at "
                             f"{grid.resolution} m, origin {grid.origin}) is not in the frame "
                             f"of {what} ({other.shape[0]} x {other.shape[1]} "
                             f"at {other.resolution} m, origin {other.origin})")

    def _merged(self, ours: int, theirs_grid: OccupancyGrid, base: int | None,
                theirs_wins: bool) -> "_Merged":
        """The merge of ``theirs_grid`` into version ``ours`` against version ``base``,
        packed, ready to write."""
        ours_grid = self.get(ours)
        base_data = None if base is None else self.get(base).data
        result = merge.three_way(base_data, ours_grid.data, theirs_grid.data, theirs_wins)
        grid = OccupancyGrid(result.data, ours_grid.resolution, ours_grid.origin)
        return _Merged(base, theirs_wins, result, grid, _packed(grid, ours_grid),
                       merge.pack_conflicts(result.conflicts))

    def _write_merge(self, ours: int, theirs: int, m: "_Merged", status: str) -> int:
        """Write a merge as a new version whose parents are ``ours`` and ``theirs`` and
        return its number. Under the write lock: ``theirs`` may be a row of this
        transaction."""
        number = self._next_number()
        meta = {"method": "merge", "merge_of": [ours, theirs], "base": m.base,
                "rule": merge.RULE, "conflicts_to": "theirs" if m.theirs_wins else "ours",
                "cells": m.result.counts, "robot": self._meta_of(theirs).get("robot")}
        self._insert(number, ours, status, m.grid, _json(self.name, meta), m.packed,
                     merge_parent=theirs)
        self.db.run("INSERT INTO mapstore_conflicts VALUES (?, ?, ?, ?, ?)",
                    (number, m.base, len(m.result.conflicts), *m.conflicts_packed))
        self._at("merge written")
        self._last = (number, m.grid.copy())
        return number

    def _next_number(self) -> int:
        return int(self.db.rows("SELECT COALESCE(MAX(version), 0) FROM mapstore_versions")
                   [0][0]) + 1

    def _root(self) -> int | None:
        found = self.db.rows("SELECT MIN(version) FROM mapstore_versions")[0][0]
        return None if found is None else int(found)

    def _merge_of(self, number: int) -> int | None:
        """The merge a commit made (its second parent is the commit), if it made one."""
        found = self.db.rows("SELECT MIN(version) FROM mapstore_versions WHERE merge_parent = ?",
                             (number,))[0][0]
        return None if found is None else int(found)

    def _by_uid(self, uid: str) -> int | None:
        found = self.db.rows("SELECT version FROM mapstore_versions WHERE uid = ?", (uid,))
        return int(found[0][0]) if found else None

    def _meta_of(self, number: int) -> dict:
        return json.loads(self.db.rows("SELECT meta FROM mapstore_versions WHERE version = ?",
                                       (number,))[0][0])

    def _graph(self) -> history.Graph:
        return {int(n): history.Node(None if p is None else int(p),
                                     None if m is None else int(m), float(c))
                for n, p, m, c in self.db.rows("SELECT version, parent, merge_parent, created "
                                               "FROM mapstore_versions")}

    def _insert(self, number, parent, status, grid, meta_text, packed, merge_parent=None,
                uid=None) -> None:
        sha, blob, changes = packed
        counts = changes.counts() if changes is not None else {}
        self.db.run(f"INSERT INTO mapstore_versions ({VERSION_COLUMNS}) VALUES "
                    "(?, ?, ?, ?, NULL, NULL, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (number, parent, status, time.time(), grid.width, grid.height,
                     grid.resolution, grid.origin[0], grid.origin[1], meta_text,
                     json.dumps(counts), merge_parent, uid))
        self._at("version row")
        self.db.run("INSERT INTO mapstore_maps VALUES (?, ?, ?)", (number, sha, blob))
        self._at("map row")
        if changes is not None:
            idx, vals = cells.pack_changes(changes)
            self.db.run("INSERT INTO mapstore_changes VALUES (?, ?, ?, ?, ?)",
                        (number, parent, len(changes), idx, vals))
            self._at("changes row")

    @_one_line_errors
    def rollback(self, v, meta: dict | None = None) -> int:
        """A new approved version equal to the approved version ``v``, its parent the latest
        approved one: history is kept, and robots start from ``v``'s map again."""
        number = self.resolve(v)
        info = self.version(number)
        if info.status != "approved":
            raise StoreError(f"{self.name}: v{number} is {info.status}; a rollback goes back "
                             "to an approved version")
        parent = self.latest()
        return self.commit(self.get(number), parent,
                           {**(meta or {}), "method": "rollback", "rollback_of": number},
                           status="approved")

    @_one_line_errors
    def approve(self, v, note: str | None = None) -> int:
        """Approve a pending version. One that does not hold the latest approved version's
        changes (a sibling of it) is merged with it, and the merge, approved, is the latest
        (``self.merged``: its number)."""
        return self._review(v, "approved", note)

    @_one_line_errors
    def reject(self, v, note: str | None = None) -> int:
        return self._review(v, "rejected", note)

    def _review(self, v, status: str, note: str | None) -> int:
        note = check_text(f"{self.name}: the note", note, NOTE_LIMIT)
        number = self.resolve(v)
        self.merged = None
        with self.db.write():
            now = self.db.rows("SELECT status FROM mapstore_versions WHERE version = ?",
                               (number,))[0][0]
            if now != "pending":
                raise StoreError(f"{self.name}: v{number} is {now}, not pending review")
            latest = self.latest()
            self.db.run("UPDATE mapstore_versions SET status = ?, reviewed = ?, note = ? "
                        "WHERE version = ?", (status, time.time(), note, number))
            graph = self._graph()
            if (status == "approved" and latest is not None
                    and not history.holds(graph, number, latest)
                    and not history.holds(graph, latest, number)):
                base = history.common_ancestor(graph, latest, number)
                theirs_wins = (history.newest_session(graph, number, base)
                               >= history.newest_session(graph, latest, base))
                m = self._merged(latest, self.get(number), base, theirs_wins)
                self.merged = self._write_merge(latest, number, m, "approved")
        return number

    @_one_line_errors
    def tag(self, v, name: str) -> int:
        number = self.resolve(v)
        if not TAG_NAME.fullmatch(name) or name in RESERVED:
            raise StoreError(f"{self.name}: {name!r} cannot be a tag (letters, digits, '.', "
                             f"'_' and '-', at most 64, starting with a letter or '_'; not "
                             f"{' or '.join(RESERVED)})")
        with self.db.write():
            held = self.db.rows("SELECT version FROM mapstore_tags WHERE name = ?", (name,))
            if held and held[0][0] != number:
                raise StoreError(f"{self.name}: tag {name!r} already names v{held[0][0]}")
            if not held:
                self.db.run("INSERT INTO mapstore_tags VALUES (?, ?, ?)",
                            (name, number, time.time()))
        return number

    # --- reading ---------------------------------------------------------------------------
    @_one_line_errors
    def resolve(self, spec) -> int:
        """The number of a version given as a number, ``vN``, a tag, ``latest`` (the latest
        approved) or ``head`` (the last committed, whatever its status)."""
        text = str(spec).strip()
        if text == "latest" or text == "head":
            found = self.latest(approved_only=text == "latest")
            if found is None:
                raise StoreError(f"{self.name}: no {'approved ' if text == 'latest' else ''}"
                                 "version yet")
            return found
        if re.fullmatch(r"v?\d{1,18}", text):
            number = int(text.lstrip("v"))
            if self.db.rows("SELECT 1 FROM mapstore_versions WHERE version = ?", (number,)):
                return number
            last = self.latest(approved_only=False)
            raise StoreError(f"{self.name}: no version {number} "
                             f"({f'versions 1 to {last}' if last else 'no versions yet'})")
        held = self.db.rows("SELECT version FROM mapstore_tags WHERE name = ?", (text,))
        if not held:
            raise StoreError(f"{self.name}: no version or tag {text!r}")
        return int(held[0][0])

    @_one_line_errors
    def latest(self, approved_only: bool = True) -> int | None:
        where = " WHERE status = 'approved'" if approved_only else ""
        found = self.db.rows(f"SELECT MAX(version) FROM mapstore_versions{where}")[0][0]
        return None if found is None else int(found)

    @_one_line_errors
    def log(self) -> list[Version]:
        rows = self.db.rows(f"SELECT {VERSION_COLUMNS} FROM mapstore_versions ORDER BY version")
        return [self._version(row, tags) for row, tags in zip(rows, self._tags_of(rows))]

    @_one_line_errors
    def version(self, v) -> Version:
        number = self.resolve(v)
        rows = self.db.rows(f"SELECT {VERSION_COLUMNS} FROM mapstore_versions WHERE version = ?",
                            (number,))
        return self._version(rows[0], self._tags_of(rows)[0])

    def _tags_of(self, rows) -> list[tuple[str, ...]]:
        tags: dict[int, list[str]] = {}
        for name, number in self.db.rows("SELECT name, version FROM mapstore_tags ORDER BY name"):
            tags.setdefault(int(number), []).append(name)
        return [tuple(tags.get(int(row[0]), ())) for row in rows]

    @staticmethod
    def _version(row, tags) -> Version:
        (number, parent, status, created, reviewed, note, width, height, res, ox, oy, meta,
         counts, merge_parent, uid) = row
        return Version(int(number), None if parent is None else int(parent), status,
                       float(created), reviewed, note, (int(height), int(width)), float(res),
                       (float(ox), float(oy)), json.loads(meta), json.loads(counts), tags,
                       None if merge_parent is None else int(merge_parent), uid)

    @_one_line_errors
    def get(self, v) -> OccupancyGrid:
        """The map of version ``v``, checked against its fingerprint."""
        info = self.version(v)
        if self._last is not None and self._last[0] == info.number:
            return self._last[1].copy()
        sha, blob = self.db.rows("SELECT sha256, cells FROM mapstore_maps WHERE version = ?",
                                 (info.number,))[0]
        try:
            data = cells.unpack_cells(blob, info.shape)
        except (ValueError, zlib.error) as e:
            raise StoreError(f"{self.name}: the cells of v{info.number} are damaged ({e})"
                             ) from None
        if cells.fingerprint(data, info.resolution, info.origin) != sha:
            raise StoreError(f"{self.name}: the cells of v{info.number} are damaged (their "
                             "fingerprint differs)")
        grid = OccupancyGrid(data, info.resolution, info.origin)
        self._last = (info.number, grid.copy())
        return grid

    @_one_line_errors
    def conflicts(self, v) -> merge.Conflicts | None:
        """The conflicts a merge settled (None: ``v`` is not a merge)."""
        number = self.resolve(v)
        found = self.db.rows("SELECT idx, vals FROM mapstore_conflicts WHERE version = ?",
                             (number,))
        return merge.unpack_conflicts(*found[0]) if found else None

    @_one_line_errors
    def diff(self, a, b) -> cells.CellChanges:
        """The cells that differ from version ``a`` to version ``b``: read from what ``b``
        stored against its parent when ``a`` is that parent (or the other way round), else
        from the two maps."""
        na, nb = self.resolve(a), self.resolve(b)
        for child, parent, forward in ((nb, na, True), (na, nb, False)):
            found = self.db.rows("SELECT idx, vals FROM mapstore_changes WHERE version = ? "
                                 "AND against = ?", (child, parent))
            if found and na != nb:
                ch = cells.unpack_changes(*found[0])
                return ch if forward else cells.CellChanges(ch.index, ch.after, ch.before)
        ga, gb = self.get(na), self.get(nb)
        if not ga.same_frame(gb):
            raise StoreError(f"{self.name}: v{na} and v{nb} are maps of different frames "
                             f"({ga.shape[0]} x {ga.shape[1]} and {gb.shape[0]} x "
                             f"{gb.shape[1]} cells)")
        return cells.changes_between(ga.data, gb.data)


@dataclass(frozen=True)
class _Plan:
    """What a commit writes, worked out before the write lock is taken."""

    root: int | None            # the store's first version when planned
    latest: int | None          # its latest approved version when planned
    parent: int | None
    same_as: int | None         # a first map equal to the store's: that version, no new one
    packed: tuple | None
    merge: "_Merged | None"     # the merge with the latest, when the parent does not hold it


@dataclass(frozen=True)
class _Merged:
    base: int | None
    theirs_wins: bool
    result: merge.Merge
    grid: OccupancyGrid
    packed: tuple
    conflicts_packed: tuple[bytes, bytes]


def _packed(grid: OccupancyGrid, before: OccupancyGrid | None):
    """(fingerprint, packed cells, changes against ``before`` or None)."""
    changes = None if before is None else cells.changes_between(before.data, grid.data)
    return (cells.fingerprint(grid.data, grid.resolution, grid.origin),
            cells.pack_cells(grid.data), changes)


# what ``store log`` shows of a version's description, checked as one line of text
SHOWN_KEYS = {"robot": NAME_LIMIT, "log": 4096, "log_name": 4096, "method": 256,
              "source": 4096}


def _check_meta(name: str, meta: dict) -> None:
    for key, limit in SHOWN_KEYS.items():
        if isinstance(meta.get(key), (str, bytes)):
            check_text(f"{name}: the version's {key.replace('_', ' ')}", meta[key], limit)


def _json(name: str, meta: dict) -> str:
    try:
        return json.dumps(meta, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise StoreError(f"{name}: the version's description is not JSON ({e})") from None


def open_store(target, create: bool = False) -> Store:
    """The store at ``target``: a ``postgresql://`` URL or the path of an SQLite file.
    ``create``: make the file (or the tables) when there is none yet; else a target that
    holds no store is a ``StoreError``."""
    store = Store(connect(target, create))
    try:
        if create:
            store._init()
        store._check()
    except BaseException:
        store.close()
        raise
    return store
