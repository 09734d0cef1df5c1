"""The map store: one version per commit, each holding its map, the cells it changed against
its parent and what made it, in an SQLite file or a PostgreSQL database with the same schema.

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
import zlib
from dataclasses import dataclass, field


from gridmap import OccupancyGrid

from . import cells
from .backends import StoreError, connect, database_errors

SCHEMA_VERSION = "1"
TABLES = ("mapstore_info", "mapstore_versions", "mapstore_maps", "mapstore_changes",
          "mapstore_tags")
# {blob} and {real}: each database's names for bytes and doubles; nothing else differs
SCHEMA = (
    "CREATE TABLE IF NOT EXISTS mapstore_info (key TEXT PRIMARY KEY, value TEXT NOT NULL)",
    "CREATE TABLE IF NOT EXISTS mapstore_versions (version BIGINT PRIMARY KEY, "
    "parent BIGINT REFERENCES mapstore_versions (version), status TEXT NOT NULL, "
    "created {real} NOT NULL, reviewed {real}, note TEXT, width BIGINT NOT NULL, "
    "height BIGINT NOT NULL, resolution {real} NOT NULL, origin_x {real} NOT NULL, "
    "origin_y {real} NOT NULL, meta TEXT NOT NULL, counts TEXT NOT NULL)",
    "CREATE TABLE IF NOT EXISTS mapstore_maps (version BIGINT PRIMARY KEY REFERENCES "
    "mapstore_versions (version), sha256 TEXT NOT NULL, cells {blob} NOT NULL)",
    "CREATE TABLE IF NOT EXISTS mapstore_changes (version BIGINT PRIMARY KEY REFERENCES "
    "mapstore_versions (version), against BIGINT NOT NULL, cells BIGINT NOT NULL, "
    "idx {blob} NOT NULL, vals {blob} NOT NULL)",
    "CREATE TABLE IF NOT EXISTS mapstore_tags (name TEXT PRIMARY KEY, version BIGINT NOT NULL "
    "REFERENCES mapstore_versions (version), created {real} NOT NULL)",
)
STATUSES = ("approved", "pending", "rejected")
TAG_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9._-]{0,63}")
RESERVED = ("latest", "head")
VERSION_COLUMNS = ("version, parent, status, created, reviewed, note, width, height, "
                   "resolution, origin_x, origin_y, meta, counts")


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
        found = self.db.rows("SELECT value FROM mapstore_info WHERE key = 'schema'")
        if [r[0] for r in found] != [SCHEMA_VERSION]:
            raise StoreError(f"{self.name}: a map store of another schema "
                             f"({found[0][0] if found else 'none'}; this one reads "
                             f"{SCHEMA_VERSION})")

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
               status: str | None = None) -> int:
        """Add ``grid`` as a new version whose parent is ``parent`` (None: a first map) and
        return its number. ``meta``: what made it (JSON). ``status``: None for the store's
        rule (pending with review on, else approved)."""
        if not isinstance(grid, OccupancyGrid):
            raise StoreError(f"{self.name}: a version needs an OccupancyGrid, got "
                             f"{type(grid).__name__}")
        if status is not None and status not in STATUSES:
            raise StoreError(f"{self.name}: unknown status {status!r} ({', '.join(STATUSES)})")
        meta_text = _json(self.name, meta or {})
        parent = None if parent is None else self.resolve(parent)
        # the slow part, packing the cells, is done before the lock is taken
        before = None if parent is None else self.get(parent)
        if before is not None and not before.same_frame(grid):
            raise StoreError(f"{self.name}: the map ({grid.shape[0]} x {grid.shape[1]} at "
                             f"{grid.resolution} m, origin {grid.origin}) is not in the frame "
                             f"of its parent v{parent} ({before.shape[0]} x {before.shape[1]} "
                             f"at {before.resolution} m, origin {before.origin})")
        packed = _packed(grid, before)
        with self.db.write():
            self._at("locked")
            number = self._next_number()
            if status is None:
                status = "pending" if self.require_approval else "approved"
            self._insert(number, parent, status, grid, meta_text, packed)
            self._at("written")
        self._at("committed")
        self._last = (number, grid.copy())
        return number

    def _next_number(self) -> int:
        return int(self.db.rows("SELECT COALESCE(MAX(version), 0) FROM mapstore_versions")
                   [0][0]) + 1

    def _insert(self, number, parent, status, grid, meta_text, packed) -> None:
        sha, blob, changes = packed
        counts = changes.counts() if changes is not None else {}
        self.db.run(f"INSERT INTO mapstore_versions ({VERSION_COLUMNS}) VALUES "
                    "(?, ?, ?, ?, NULL, NULL, ?, ?, ?, ?, ?, ?, ?)",
                    (number, parent, status, time.time(), grid.width, grid.height,
                     grid.resolution, grid.origin[0], grid.origin[1], meta_text,
                     json.dumps(counts)))
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
        return self._review(v, "approved", note)

    @_one_line_errors
    def reject(self, v, note: str | None = None) -> int:
        return self._review(v, "rejected", note)

    def _review(self, v, status: str, note: str | None) -> int:
        number = self.resolve(v)
        with self.db.write():
            now = self.db.rows("SELECT status FROM mapstore_versions WHERE version = ?",
                               (number,))[0][0]
            if now != "pending":
                raise StoreError(f"{self.name}: v{number} is {now}, not pending review")
            self.db.run("UPDATE mapstore_versions SET status = ?, reviewed = ?, note = ? "
                        "WHERE version = ?", (status, time.time(), note, number))
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
         counts) = row
        return Version(int(number), None if parent is None else int(parent), status,
                       float(created), reviewed, note, (int(height), int(width)), float(res),
                       (float(ox), float(oy)), json.loads(meta), json.loads(counts), tags)

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
        if cells.digest(data) != sha:
            raise StoreError(f"{self.name}: the cells of v{info.number} are damaged (their "
                             "fingerprint differs)")
        grid = OccupancyGrid(data, info.resolution, info.origin)
        self._last = (info.number, grid.copy())
        return grid

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


def _packed(grid: OccupancyGrid, before: OccupancyGrid | None):
    """(fingerprint, packed cells, changes against ``before`` or None)."""
    changes = None if before is None else cells.changes_between(before.data, grid.data)
    return cells.digest(grid.data), cells.pack_cells(grid.data), changes


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
