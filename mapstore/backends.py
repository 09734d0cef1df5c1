"""The two databases a map store lives in, behind one small interface: an SQLite file (the
default, nothing to start) and PostgreSQL (for a fleet, through psycopg 3). The store writes
one SQL dialect, with ``?`` placeholders; this module turns it into each database's."""

from __future__ import annotations

import re
import sqlite3
from contextlib import contextmanager
from pathlib import Path

from gridmap import MapUpdatingError

CONNECT_TIMEOUT = 5          # [s] to reach a PostgreSQL server before the store says it cannot
# [s] a writer waits for another's transaction: a commit of a 400 x 250 m map at 5 cm holds
# the lock well under a second, so a minute means something is stuck
LOCK_TIMEOUT = 60
SQLITE_MAGIC = b"SQLite format 3\x00"
URL_SCHEMES = ("postgresql://", "postgres://")


class StoreError(MapUpdatingError):
    """A store that cannot be used as asked: missing, not a store, unreachable, an unknown
    version or tag, a review out of turn. The message names the store and the problem."""


def is_url(target) -> bool:
    return isinstance(target, str) and target.startswith(URL_SCHEMES)


def redacted(url: str) -> str:
    """The URL without its password, for messages."""
    return re.sub(r"(://[^:/@]*):[^@]*@", r"\1:***@", url)


class SQLiteDB:
    """One SQLite file. Writes hold the file's write lock from their first statement
    (BEGIN IMMEDIATE), so two writers serialise instead of failing at their commit; WAL lets
    readers go on meanwhile, and synchronous=FULL makes a finished commit survive a power cut."""

    kind = "sqlite"
    blob, real = "BLOB", "REAL"

    def __init__(self, path: Path, create: bool):
        self.name = str(path)
        _check_sqlite_file(path, create)
        try:
            self.conn = sqlite3.connect(str(path), timeout=LOCK_TIMEOUT, isolation_level=None)
            self.conn.execute("PRAGMA journal_mode=WAL")
            self.conn.execute("PRAGMA synchronous=FULL")
        except sqlite3.DatabaseError as e:
            raise StoreError(f"{path}: not a map store ({e})") from None

    def rows(self, sql: str, params=()) -> list[tuple]:
        return self.conn.execute(sql, params).fetchall()

    def run(self, sql: str, params=()) -> None:
        self.conn.execute(sql, params)

    @contextmanager
    def write(self):
        self.conn.execute("BEGIN IMMEDIATE")
        try:
            yield
        except BaseException:
            self.conn.execute("ROLLBACK")
            raise
        self.conn.execute("COMMIT")

    def has_table(self, name: str) -> bool:
        return bool(self.rows("SELECT 1 FROM sqlite_master WHERE type='table' AND name=?",
                              (name,)))

    def close(self) -> None:
        self.conn.close()


def _check_sqlite_file(path: Path, create: bool) -> None:
    if not path.exists():
        if not create:
            raise StoreError(f"{path}: no map store there (make one with 'mapupdate store "
                             f"init --store {path}')")
        if not path.parent.is_dir():
            raise StoreError(f"{path}: the folder {path.parent} does not exist")
        return
    if not path.is_file():
        raise StoreError(f"{path}: not a map store (not a regular file)")
    with open(path, "rb") as f:
        head = f.read(len(SQLITE_MAGIC))
    if head != SQLITE_MAGIC and not (create and head == b""):
        raise StoreError(f"{path}: not a map store (not an SQLite database)")


class PostgresDB:
    """One PostgreSQL database. A write is a transaction that first locks the store's row in
    ``mapstore_info``: writers serialise on it, and under READ COMMITTED each statement after
    the lock sees what the writer before committed, so version numbers never clash."""

    kind = "postgresql"
    blob, real = "BYTEA", "DOUBLE PRECISION"

    def __init__(self, url: str):
        self.name = redacted(url)
        try:
            import psycopg
        except ImportError:
            raise StoreError(f"{self.name}: a PostgreSQL store needs psycopg, which a robot "
                             "install leaves out: pip install 'lidar-map-updating[store]'"
                             ) from None
        try:
            self.conn = psycopg.connect(url, autocommit=True, connect_timeout=CONNECT_TIMEOUT)
        except psycopg.Error as e:
            first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise StoreError(f"{self.name}: cannot reach the database within "
                             f"{CONNECT_TIMEOUT} s ({first})") from None
        self.conn.execute(f"SET lock_timeout = '{LOCK_TIMEOUT}s'")

    def rows(self, sql: str, params=()) -> list[tuple]:
        cur = self.conn.execute(sql.replace("?", "%s"), params)
        return cur.fetchall() if cur.description else []

    def run(self, sql: str, params=()) -> None:
        self.conn.execute(sql.replace("?", "%s"), params)

    @contextmanager
    def write(self):
        with self.conn.transaction():
            if self.has_table("mapstore_info"):
                self.run("SELECT value FROM mapstore_info WHERE key = 'schema' FOR UPDATE")
            else:   # the store is being made: an advisory lock keeps two inits apart
                self.run("SELECT pg_advisory_xact_lock(1835102323)")
            yield

    def has_table(self, name: str) -> bool:
        return bool(self.rows("SELECT to_regclass(?) IS NOT NULL", (name,))[0][0])

    def close(self) -> None:
        self.conn.close()


def connect(target, create: bool = False):
    """The database of ``target``: a ``postgresql://`` URL, else the path of an SQLite file
    (made when ``create``)."""
    if is_url(target):
        return PostgresDB(target)
    return SQLiteDB(Path(target), create)


def database_errors() -> tuple[type[BaseException], ...]:
    """The drivers' own errors, which the store turns into one-line ``StoreError``s."""
    errors: list[type[BaseException]] = [sqlite3.Error]
    try:
        import psycopg
        errors.append(psycopg.Error)
    except ImportError:
        pass
    return tuple(errors)
