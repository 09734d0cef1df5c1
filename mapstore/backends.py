"""The two databases a map store lives in, behind one small interface: an SQLite file (the
default, nothing to start) and PostgreSQL (for a fleet, through psycopg 3). The store writes
one SQL dialect, with ``?`` placeholders; this module turns it into each database's.

A PostgreSQL store is reached over a network that fails: every statement is bounded in time
on the server (``statement_timeout``) and on the client (a server stopped, or a network that
drops packets, never answers, and psycopg would wait for ever); a connection lost between
statements is made again with backoff, and one lost inside a write is ``ConnectionLost``, for
the caller to write again. No message ever holds the URL's password."""

from __future__ import annotations

import math
import os
import re
import socket
import sqlite3
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import unquote

from gridmap import MapUpdatingError

CONNECT_TIMEOUT = 5          # [s] to reach a PostgreSQL server before the store says it cannot
# [s] a writer waits for another's transaction: a commit of a 400 x 250 m map at 5 cm holds
# the lock well under a second, so a minute means something is stuck
LOCK_TIMEOUT = 60
# [s] the server's own bound on one statement (its statement_timeout), above LOCK_TIMEOUT so
# that a writer waiting for the lock ends with the lock's message; the environment variable
# MAPSTORE_STATEMENT_TIMEOUT sets another. The longest statement of a store writes or reads
# one packed map (4 MB for 40 M cells): well under a second
STATEMENT_TIMEOUT = 75.0
# [s] how much longer the client waits for an answer before it cuts the connection: a server
# that runs answers with its own timeout first; one that does not run never answers
ANSWER_MARGIN = 5.0
# [s] a connection lost between statements is made again for this long (a server restarted
# for an upgrade or a failover is back within seconds), after 0.2, 0.4, 0.8 ... s, at most 5
RECONNECT_WINDOW = 30.0
RECONNECT_DELAYS = (0.2, 5.0)
SQLITE_MAGIC = b"SQLite format 3\x00"
URL_SCHEMES = ("postgresql", "postgres")
SCHEME = re.compile(r"([A-Za-z][A-Za-z0-9+.-]*):(//)?")
# a libpq "key=value ..." string: told apart from a file name by a keyword at its start or
# after a space
LIBPQ_KEYWORDS = re.compile(r"(?:^|\s)(?:host|hostaddr|port|dbname|user|password|passfile|"
                            r"service|sslmode|connect_timeout|options|application_name)\s*=",
                            re.I)
# an authority that reads as host:port (a name or an IPv6 address in brackets)
HOST_PORT = re.compile(r"(?:[^:@\[\]]*|\[[0-9A-Fa-f:.]*\]):\d{1,5}")
# a URL's query parameter, or a key=value pair, that holds a secret (password, sslpassword,
# oauth_client_secret)
SECRET_PARAM = re.compile(r"(?i)([?&][^=&]*(?:password|secret)[^=&]*=)([^&]*)")
SECRET_PAIR = re.compile(r"(?i)((?:^|\s)\w*(?:password|secret)\w*\s*=\s*)"
                         r"('(?:[^'\\]|\\.)*'?|\S*)")


class StoreError(MapUpdatingError):
    """A store that cannot be used as asked: missing, not a store, unreachable, an unknown
    version or tag, a review out of turn. The message names the store and the problem."""


class ConnectionLost(StoreError):
    """The connection to a PostgreSQL server was lost inside a write. Nothing of the write is
    committed, unless ``at_commit``: lost while committing, it may or may not be; the caller
    may write it again (the store makes that safe with the commit's id)."""

    def __init__(self, message: str, at_commit: bool = False):
        super().__init__(message)
        self.at_commit = at_commit


def is_url(target) -> bool:
    """A PostgreSQL URL (the scheme in any case)."""
    if not isinstance(target, str):
        return False
    found = SCHEME.match(target.strip())
    return bool(found and found.group(2) and found.group(1).lower() in URL_SCHEMES)


# --- passwords ---------------------------------------------------------------------------------
def _userinfo_end(rest: str) -> tuple[int, bool]:
    """(where the user:password of a URL's text after ``scheme://`` ends, its ``@``, or -1;
    whether it ends beyond the authority a URL parser would read). The last ``@`` before the
    first ``/`` ends it, so an unencoded ``@`` in the password stays the password's; when
    there is none there but a later ``@`` has a ``:`` before it, the password may hold an
    unencoded ``/``: taken as one too, so that it is never printed. (An authority that reads
    as host:port leaves a later ``@`` to the path or the parameters, where it may stand.)"""
    slash = rest.find("/")
    authority = rest if slash < 0 else rest[:slash]
    at = authority.rfind("@")
    if at >= 0:
        return at, False
    at = rest.rfind("@")
    if at >= 0 and ":" in rest[:at]:
        return at, not HOST_PORT.fullmatch(authority)
    return -1, False


def redacted(target) -> str:
    """``target`` with every secret it holds as ``***``: a URL's password (up to the last
    ``@`` of its authority), its ``?password=`` and ``&password=`` parameters, a libpq
    key=value string's ``password=``. For messages and names."""
    text = str(target)
    found = SCHEME.match(text.strip())
    if found is None or not (found.group(2) or "@" in text):
        return SECRET_PAIR.sub(r"\1***", text)
    start = len(text) - len(text.lstrip()) + found.end()
    rest = text[start:]
    at, _ = _userinfo_end(rest)
    colon = rest.find(":", 0, max(at, 0))
    if at >= 0 and colon >= 0:
        rest = f"{rest[:colon + 1]}***{rest[at:]}"
    return SECRET_PAIR.sub(r"\1***", text[:start] + SECRET_PARAM.sub(r"\1***", rest))


def _secrets_of(url: str) -> list[str]:
    """The password of ``url`` and every secret parameter's value, as written and decoded,
    longest first: removed from any text a driver returns, whatever it echoes of the URL."""
    rest = url.strip().split("://", 1)[-1]
    at, _ = _userinfo_end(rest)
    found = [rest[:at].partition(":")[2]] if at >= 0 and ":" in rest[:at] else []
    found += [m.group(2) for m in SECRET_PARAM.finditer(rest)]
    found += [unquote(s) for s in found]
    return sorted({s for s in found if s}, key=len, reverse=True)


def _scrubbed(text: str, secrets: list[str]) -> str:
    text = redacted(" ".join(text.split()))
    for secret in secrets:
        text = text.replace(secret, "***")
    return text


def _for_libpq(url: str) -> str:
    """``url`` as libpq reads it: the scheme in lower case (libpq reads ``POSTGRESQL://`` as
    a key=value string, and echoes it whole in its error), an ``@`` of the password
    percent-encoded (libpq ends the password at the first ``@`` and reads the rest of it as
    the host's name)."""
    text = url.strip()
    rest = text.split("://", 1)[1]
    at, beyond = _userinfo_end(rest)
    if beyond:
        raise StoreError(f"{redacted(text)}: the URL has an '@' after a '/' with a ':' before "
                         "it; percent-encode a '/' of the password as %2F (and an '@' of the "
                         "database's name or a parameter as %40)")
    if at >= 0:
        rest = rest[:at].replace("@", "%40") + rest[at:]
    return "postgresql://" + rest


def _refuse_other_forms(text: str) -> None:
    """A target that is no PostgreSQL URL but no file name either: another or a misspelt
    scheme (``postgressql://``, ``pg://``), ``postgresql:`` without ``//``, a libpq key=value
    string. Refused rather than taken as an SQLite file's name (printed whole, password and
    all, in its 'no map store there')."""
    text = text.strip()
    found = SCHEME.match(text)
    if found and (found.group(2) or "@" in text):
        scheme = found.group(1)
        if scheme.lower() in URL_SCHEMES:
            raise StoreError(f"{redacted(text)}: not a URL; give postgresql://user:password@"
                             "host/database")
        raise StoreError(f"{redacted(text)}: unknown scheme {scheme!r} (a PostgreSQL store "
                         "is a postgresql:// URL, an SQLite store a file's path)")
    if LIBPQ_KEYWORDS.search(text):
        raise StoreError(f"{redacted(text)}: a libpq key=value string; give a postgresql:// "
                         "URL (postgresql://user:password@host:port/database)")


# --- timeouts ------------------------------------------------------------------------------
def statement_timeout() -> float:
    """[s] the server's bound on one statement: MAPSTORE_STATEMENT_TIMEOUT, else
    STATEMENT_TIMEOUT."""
    text = os.environ.get("MAPSTORE_STATEMENT_TIMEOUT")
    if text is None:
        return float(STATEMENT_TIMEOUT)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise StoreError(f"MAPSTORE_STATEMENT_TIMEOUT={text!r}: not a number of seconds above 0")
    return value


def answer_timeout() -> float:
    """[s] the client's bound on one statement's answer."""
    return statement_timeout() + ANSWER_MARGIN


class _Watchdog:
    """Cuts a connection whose statement outlives ``limit`` seconds: shuts its socket down, so
    that psycopg, waiting for an answer that does not come, returns with an error. A stopped
    server (or a network that drops packets) cannot enforce its own statement_timeout, and
    psycopg has no timeout of its own for a statement. Disarmed under a lock, it never cuts a
    connection whose statement has ended."""

    def __init__(self, fileno: int, limit: float):
        self.fired = False
        self._fileno, self._ended, self._lock = fileno, False, threading.Lock()
        self._timer = threading.Timer(limit, self._cut)
        self._timer.daemon = True
        self._timer.start()

    def _cut(self) -> None:
        with self._lock:
            if self._ended:
                return
            self.fired = True
            try:    # a duplicate of the descriptor: shutting it down shuts the socket down
                with socket.socket(fileno=os.dup(self._fileno)) as s:
                    s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def disarm(self) -> None:
        with self._lock:
            self._ended = True
        self._timer.cancel()


# --- connection errors ---------------------------------------------------------------------------
# (what psycopg's text says, the kind, what to say): libpq reports a failed connection as text
# only (no SQLSTATE), the server's FATAL message within it
CONNECT_PROBLEMS = (
    (r"password authentication failed for user \"([^\"]*)\"", "auth",
     "authentication failed for user \"{0}\": wrong password"),
    (r"authentication failed for user \"([^\"]*)\"", "auth",
     "authentication failed for user \"{0}\""),
    (r"no password supplied|password is required", "auth",
     "the server asks for a password and the URL gives none"),
    (r"role \"([^\"]*)\" does not exist", "role",
     "no user (role) \"{0}\" on the server; check the URL's user name"),
    (r"database \"([^\"]*)\" does not exist", "database",
     "no database \"{0}\" on the server; create it or check the URL"),
    (r"no pg_hba\.conf entry", "refused",
     "the server lets in no connection from this host as this user to this database "
     "(its pg_hba.conf)"),
    (r"the database system is (starting up|shutting down|in recovery mode|not yet accepting)",
     "starting", "the server is {0}; try again"),
    (r"too many (?:connections|clients)", "busy", "the server has too many connections"),
    (r"connection refused", "unreachable", "connection refused"),
    (r"timeout expired|timed out", "unreachable", "no answer"),
    (r"failed to resolve host|could not translate host name|name or service not known",
     "unreachable", "unknown host"),
    (r"no route to host|network is unreachable|host is down", "unreachable", "no route to host"),
    (r"server closed the connection unexpectedly|connection reset", "unreachable",
     "the server closed the connection"),
)


class _NoConnection(StoreError):
    """A connection that could not be made, and ``why``; ``lasting``: trying again would not
    help (a wrong password, no such user or database)."""

    def __init__(self, message: str, why: str, lasting: bool):
        super().__init__(message)
        self.why, self.lasting = why, lasting


def connect_problem(text: str) -> tuple[str, str]:
    """(kind, what to say) of psycopg's text for a connection that failed: kinds ``auth``,
    ``role``, ``database``, ``refused``, ``starting``, ``busy``, ``unreachable``, or ``other``
    (the text's first line)."""
    for pattern, kind, say in CONNECT_PROBLEMS:
        found = re.search(pattern, text, re.I)
        if found:
            return kind, say.format(*found.groups())
    lines = str(text).strip().splitlines()
    return "other", lines[0].strip() if lines else "no reason given"


def connect_error(name: str, text: str, secrets: list[str]) -> _NoConnection:
    """The one-line error of a connection to ``name`` that failed with psycopg's ``text``."""
    kind, say = connect_problem(text)
    say = _scrubbed(say, secrets)
    if kind == "unreachable":
        message = f"{name}: cannot reach the database within {CONNECT_TIMEOUT} s ({say})"
    elif kind == "other":
        message = f"{name}: cannot connect ({say})"
    else:
        message = f"{name}: {say}"
    return _NoConnection(message, say, lasting=kind in ("auth", "role", "database", "refused"))


# --- the two databases ---------------------------------------------------------------------
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
            _wal_mode(self.conn)
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


def _wal_mode(conn: sqlite3.Connection) -> None:
    """Turn on WAL, waiting for other connections as a write would. SQLite answers "database
    is locked" at once, without its busy wait, when robots open a new file together and
    another is switching it to WAL at that moment; so the switch is tried again until
    LOCK_TIMEOUT."""
    deadline, pause = time.monotonic() + LOCK_TIMEOUT, 0.005
    while True:
        try:
            conn.execute("PRAGMA journal_mode=WAL")
            return
        except sqlite3.OperationalError as e:
            if "locked" not in str(e) or time.monotonic() + pause > deadline:
                raise
        time.sleep(pause)
        pause = min(2 * pause, 0.2)


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
    the lock sees what the writer before committed, so version numbers never clash.

    Each statement is bounded: by the server's statement_timeout, and by the client's
    ``answer_timeout()`` (a server that does not run never answers). A connection found lost
    outside a write (a server restarted while a long session held its store open) is made
    again with backoff and the statement run once more: only reads and session settings run
    outside a write. One lost inside a write is ``ConnectionLost``."""

    kind = "postgresql"
    blob, real = "BYTEA", "DOUBLE PRECISION"

    def __init__(self, url: str):
        self.name = redacted(url.strip())
        self._secrets = _secrets_of(url)
        self._url = _for_libpq(url)
        try:
            import psycopg
        except ImportError:
            raise StoreError(f"{self.name}: a PostgreSQL store needs psycopg, which a robot "
                             "install leaves out: pip install 'lidar-map-updating[store]'"
                             ) from None
        self._psycopg = psycopg
        self._in_write = False
        statement_timeout()         # a wrong MAPSTORE_STATEMENT_TIMEOUT said before connecting
        self.conn = self._connect()

    def _connect(self):
        psycopg = self._psycopg
        try:
            conn = psycopg.connect(self._url, autocommit=True, connect_timeout=CONNECT_TIMEOUT)
        except psycopg.Error as e:
            raise connect_error(self.name, str(e), self._secrets) from None
        self.conn = conn
        try:    # the session's settings, made again with each new connection
            self._bounded(f"SET lock_timeout = '{LOCK_TIMEOUT}s'")
            self._bounded(f"SET statement_timeout = '{round(statement_timeout() * 1000)}ms'")
        except (psycopg.Error, StoreError) as e:
            conn.close()
            why = _scrubbed(str(e), self._secrets)
            raise _NoConnection(f"{self.name}: cannot connect ({why})", why, False) from None
        return conn

    def _reconnect(self) -> None:
        """A new connection for one found lost, tried with backoff for RECONNECT_WINDOW s."""
        try:
            self.conn.close()
        except self._psycopg.Error:
            pass
        deadline = time.monotonic() + RECONNECT_WINDOW
        delay, longest = RECONNECT_DELAYS
        while True:
            try:
                self.conn = self._connect()
                return
            except _NoConnection as e:
                left = deadline - time.monotonic()
                if e.lasting:
                    raise StoreError(str(e)) from None
                if left <= 0:
                    raise StoreError(f"{self.name}: lost the connection to the server and could "
                                     f"not connect again within {RECONNECT_WINDOW:g} s ({e.why})"
                                     ) from None
            time.sleep(min(delay, left))    # the last try at the window's end
            delay = min(2 * delay, longest)

    def _bounded(self, sql: str, params=()) -> list[tuple]:
        """One statement under the watchdog; its rows (none for a statement without)."""
        limit = answer_timeout()
        watchdog = _Watchdog(self.conn.fileno(), limit)
        try:
            cur = self.conn.execute(sql, params)
            return cur.fetchall() if cur.description else []
        except self._psycopg.Error:
            if watchdog.fired:
                raise self._lost(f"the server did not answer within {limit:g} s", sql) from None
            raise
        finally:
            watchdog.disarm()

    def _lost(self, what: str, sql: str) -> StoreError:
        """The error of a connection lost (or cut for want of an answer) during ``sql``."""
        if not self._in_write:
            return StoreError(f"{self.name}: {what}")
        if sql == "COMMIT":
            return ConnectionLost(f"{self.name}: {what} while committing a write; it may or may "
                                  "not have been committed", at_commit=True)
        return ConnectionLost(f"{self.name}: {what} during a write, which was not committed")

    def _statement(self, sql: str, params=()) -> list[tuple]:
        """One statement; outside a write, on a connection found lost, reconnected and run
        once more."""
        psycopg = self._psycopg
        for attempt in (1, 2):
            if self.conn.closed and not self._in_write:
                self._reconnect()
            try:
                return self._bounded(sql.replace("?", "%s"), params)
            except psycopg.Error as e:
                if not self.conn.closed:
                    raise       # the statement's own error; the connection stands
                first = _scrubbed(str(e).strip().splitlines()[0] if str(e).strip()
                                  else type(e).__name__, self._secrets)
                if self._in_write or attempt == 2:
                    raise self._lost(f"lost the connection to the server ({first})", sql
                                     ) from None
        raise AssertionError("unreachable")

    def rows(self, sql: str, params=()) -> list[tuple]:
        return self._statement(sql, params)

    def run(self, sql: str, params=()) -> None:
        self._statement(sql, params)

    @contextmanager
    def write(self):
        # BEGIN runs as a statement outside the transaction: a connection lost since the last
        # statement is made again here, before anything of the write is sent
        self._statement("BEGIN")
        self._in_write = True
        try:
            if self.has_table("mapstore_info"):
                self.run("SELECT value FROM mapstore_info WHERE key = 'schema' FOR UPDATE")
            else:   # the store is being made: an advisory lock keeps two inits apart
                self.run("SELECT pg_advisory_xact_lock(1835102323)")
            yield
        except BaseException:
            self._in_write = False
            self._rollback()
            raise
        try:
            self._statement("COMMIT")
        finally:
            self._in_write = False

    def _rollback(self) -> None:
        """Undo the write; on a lost connection there is nothing to undo (the server drops an
        unfinished transaction with its connection), and the write's own error is the one to
        tell."""
        if self.conn.closed:
            return
        try:
            self._bounded("ROLLBACK")
        except (self._psycopg.Error, StoreError):
            pass

    def has_table(self, name: str) -> bool:
        return bool(self.rows("SELECT to_regclass(?) IS NOT NULL", (name,))[0][0])

    def close(self) -> None:
        self.conn.close()


def connect(target, create: bool = False):
    """The database of ``target``: a ``postgresql://`` URL (the scheme in any case), else the
    path of an SQLite file (made when ``create``). A target that looks like neither (another
    scheme, a libpq key=value string) is refused, its password never printed."""
    if is_url(target):
        return PostgresDB(target)
    _refuse_other_forms(str(target))
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
