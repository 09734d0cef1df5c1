"""The spool: update sessions whose commit to a store failed (a server down or paused, a lock
held too long, a full disk), kept on the robot's disk until ``mapupdate store push`` (or the
next ``mapupdate update --store``) commits them, so that no session's map is ever lost.

An entry is a folder ``<spool>/<UTC time>-<uid>/`` holding the session's map (``map.yaml`` and
``map.pgm``), the map an empty store was to start from when there was one (``start.yaml``,
``start.pgm``) and ``entry.json``: the commit id (uid), the parent version, what made the map
(the version's meta) and the store it is for. An entry is written in a hidden temporary
folder and renamed into place, so it is whole or absent; it is removed (renamed away, then
deleted) only once its commit succeeded. The store is kept as its name without a password
(``backends.redacted``) and a PBKDF2-HMAC-SHA256 of the whole target, which matches the
target given to ``push`` and cannot be turned back into a password.

Also here: the update's working folders (``/tmp/mapupdate-<pid>-*``), each holding a lock
while its process lives, and the removal of those a killed process left behind.

Imports gridmap only (its map files)."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import socket
import tempfile
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

from gridmap import OccupancyGrid, load_map, save_map

from .backends import is_url, redacted

try:
    import fcntl
except ImportError:          # not POSIX: a working folder is told stale by its pid alone
    fcntl = None

ENV = "MAPUPDATE_SPOOL"
FORMAT = 1
ENTRY_FILE = "entry.json"
# the key of a target: slow to compute on purpose, so that a spool read by someone else does
# not let them try passwords fast; once per listing
KEY_SALT, KEY_ROUNDS = b"mapupdate-spool", 200_000
WORK_PREFIX = "mapupdate-"
WORK_NAME = re.compile(r"mapupdate-(\d+)-[A-Za-z0-9_]+")
HIDDEN_NAME = re.compile(r"\.(?:tmp|gone)-(\d+)@(.*)-[0-9a-f]{8}")
STALE_AFTER = 60.0           # [s] a folder of a dead process without a lock file is left alone
#                              this long (its process may have been about to take the lock)


def folder(given: Path | None = None) -> Path:
    """The spool folder: ``given`` (``--spool``), else ``$MAPUPDATE_SPOOL``, else
    ``$XDG_DATA_HOME/mapupdate/spool`` (``~/.local/share/mapupdate/spool``)."""
    if given is not None:
        return Path(given).expanduser()
    if os.environ.get(ENV):
        return Path(os.environ[ENV]).expanduser()
    data = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(data).expanduser() / "mapupdate" / "spool"


def _full_target(target) -> str:
    """The target as it is matched: a URL as given, an SQLite file by its absolute path."""
    return str(target) if is_url(target) else str(Path(target).expanduser().resolve())


def target_name(target) -> str:
    """The target as an entry keeps it and messages show it: never a password."""
    return redacted(_full_target(target))


def target_key(target) -> str:
    return hashlib.pbkdf2_hmac("sha256", _full_target(target).encode(), KEY_SALT,
                               KEY_ROUNDS).hex()


@dataclass
class Session:
    """What a commit of an update session needs: its map, its parent (None: the store was
    empty, ``first`` is the map it starts from), what made it, and its commit id."""

    uid: str
    grid: OccupancyGrid
    parent: int | None
    meta: dict
    first: OccupancyGrid | None = None
    first_meta: dict | None = None


@dataclass
class Entry:
    path: Path
    created: float
    store: str
    key: str
    error: str
    session_meta: dict        # entry.json as read

    @property
    def name(self) -> str:
        return self.path.name

    def session(self) -> Session:
        """The spooled session, its maps read back."""
        d = self.session_meta
        first = load_map(self.path / "start.yaml") if d.get("first_map") else None
        return Session(d["uid"], load_map(self.path / "map.yaml"), d["parent"], d["meta"],
                       first, d.get("first_meta"))


def new_uid() -> str:
    return uuid.uuid4().hex


def writable(spool: Path) -> str | None:
    """None when entries could be written in ``spool``, else why not; nothing is made (the
    folder, or the nearest one that exists above it, is asked)."""
    path = spool.absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    if not path.is_dir():
        return f"{path} is not a folder"
    if not os.access(path, os.W_OK | os.X_OK):
        return f"{path} is not writable"
    return None


def write(spool: Path, target, session: Session, error: str) -> Entry:
    """Keep ``session`` in ``spool`` for ``target``: written in a hidden folder, flushed to
    disk, renamed into place. Returns the entry."""
    created = time.time()
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(created))
    final = spool / f"{stamp}-{session.uid[:12]}"
    spool.mkdir(mode=0o700, parents=True, exist_ok=True)
    tmp = spool / f".tmp-{os.getpid()}@{socket.gethostname()}-{uuid.uuid4().hex[:8]}"
    tmp.mkdir(mode=0o700)
    try:
        files = list(save_map(session.grid, tmp / "map.yaml"))
        if session.first is not None:
            files += save_map(session.first, tmp / "start.yaml")
        record = {"spool_format": FORMAT, "uid": session.uid, "created": created,
                  "created_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(created)),
                  "store": target_name(target), "store_key": target_key(target),
                  "parent": session.parent, "map": "map.yaml",
                  "first_map": "start.yaml" if session.first is not None else None,
                  "first_meta": session.first_meta, "meta": session.meta, "error": error}
        (tmp / ENTRY_FILE).write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
        for f in files + [tmp / ENTRY_FILE, tmp]:
            _fsync(f)
        os.rename(tmp, final)
        _fsync(spool)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return _read(final)


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _read(path: Path) -> Entry:
    d = json.loads((path / ENTRY_FILE).read_text())
    if d.get("spool_format") != FORMAT:
        raise ValueError(f"spool format {d.get('spool_format')!r}, this one reads {FORMAT}")
    return Entry(path, float(d["created"]), str(d["store"]), str(d["store_key"]),
                 str(d.get("error") or ""), d)


def entries(spool: Path, target) -> tuple[list[Entry], int, list[tuple[str, str]]]:
    """(the entries for ``target``, oldest first; how many are for other stores; the folders
    that are not readable entries, with why). Hidden folders a killed process left are
    removed on the way."""
    if not spool.is_dir():
        return [], 0, []
    remove_stale(spool, HIDDEN_NAME)
    key = target_key(target)
    mine, others, bad = [], 0, []
    for path in sorted(spool.iterdir()):
        if path.name.startswith(".") or not path.is_dir() or path.name == "work":
            continue
        try:
            entry = _read(path)
        except (OSError, ValueError, KeyError, TypeError) as e:
            bad.append((path.name, " ".join(str(e).split()) or type(e).__name__))
            continue
        if entry.key == key:
            mine.append(entry)
        else:
            others += 1
    return sorted(mine, key=lambda e: (e.created, e.name)), others, bad


def remove(entry: Entry) -> None:
    """Remove a pushed entry: renamed away first (so another push running at once does not
    see it half-deleted), then deleted."""
    gone = entry.path.parent / f".gone-{os.getpid()}@{socket.gethostname()}-" \
                               f"{uuid.uuid4().hex[:8]}"
    try:
        os.rename(entry.path, gone)
    except FileNotFoundError:          # another push removed it
        return
    shutil.rmtree(gone, ignore_errors=True)


# --- working folders ---------------------------------------------------------------------------

@contextlib.contextmanager
def working_folder():
    """A temporary folder ``mapupdate-<pid>-*`` in the system's temporary folder, locked
    while this process uses it, removed at the end; one a killed process left behind is
    removed by :func:`remove_stale_work`."""
    path = Path(tempfile.mkdtemp(prefix=f"{WORK_PREFIX}{os.getpid()}-"))
    lock = open(path / ".lock", "w")
    try:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)
        yield path
    finally:
        lock.close()
        shutil.rmtree(path, ignore_errors=True)


def remove_stale_work(where: Path | None = None) -> list[Path]:
    """Remove the working folders whose process is gone; the folders removed."""
    return remove_stale(Path(where or tempfile.gettempdir()), WORK_NAME)


def remove_stale(where: Path, pattern: re.Pattern) -> list[Path]:
    """Remove the folders of ``where`` named by ``pattern`` (its first group a process id, a
    second one the host) whose process is gone: not running here, its lock (if it has one) not
    held, and, without a lock file, older than ``STALE_AFTER``."""
    removed = []
    try:
        found = list(where.iterdir())
    except OSError:
        return removed
    host = socket.gethostname()
    for path in found:
        m = pattern.fullmatch(path.name)
        if not m or (m.lastindex or 0) >= 2 and m.group(2) != host:
            continue
        try:
            st = path.lstat()
        except OSError:
            continue
        if not path.is_dir() or path.is_symlink() or st.st_uid != os.geteuid():
            continue
        if _alive(int(m.group(1))) or _locked(path, st.st_mtime):
            continue
        shutil.rmtree(path, ignore_errors=True)
        removed.append(path)
    return removed


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:          # another user's process
        return True
    except OSError:
        return False
    return True


def _locked(path: Path, mtime: float) -> bool:
    """Whether a process (maybe of another process namespace) still holds a working folder's
    lock; one without a lock file counts as held while it is young (its process may have been
    about to take it). The spool's hidden folders have no lock: their pid and host say."""
    if HIDDEN_NAME.fullmatch(path.name):
        return False
    lock_path = path / ".lock"
    if fcntl is None or not lock_path.exists():
        return time.time() - mtime < STALE_AFTER
    try:
        with open(lock_path) as f:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
    except OSError:
        return True
    return False


__all__ = ["ENV", "Entry", "Session", "entries", "folder", "new_uid", "remove",
           "remove_stale_work", "target_key", "target_name", "working_folder", "writable",
           "write"]
