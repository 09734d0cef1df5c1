"""A throwaway PostgreSQL server for the tests: Debian's binaries, a cluster in a temporary
folder, a private port, trust authentication on 127.0.0.1 only, stopped at the end.

PostgreSQL refuses to run as root, so as root the cluster belongs to the ``postgres`` user
(``runuser``); as anyone else it runs as that user. ``server()`` returns None with the
reason when it cannot be had (no binaries, no such user), so the tests skip and say why."""

from __future__ import annotations

import glob
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path


class Server:
    def __init__(self, bindir: Path, folder: Path, port: int, runas: list[str]):
        self.bindir, self.folder, self.port, self.runas = bindir, folder, port, runas
        self.count = 0
        self.options = ""           # the server's command-line options, kept for restart

    def url(self, database: str = "postgres") -> str:
        return f"postgresql://postgres@127.0.0.1:{self.port}/{database}"

    def new_database(self) -> str:
        """The URL of a new, empty database of its own."""
        import psycopg
        self.count += 1
        name = f"store_{os.getpid()}_{self.count}"
        with psycopg.connect(self.url(), autocommit=True) as conn:
            conn.execute(f"CREATE DATABASE {name}")
        return self.url(name)

    def _pg_ctl(self, *args: str) -> None:
        subprocess.run(self.runas + [str(self.bindir / "pg_ctl"), "-D", str(self.folder / "data"),
                                     *args], check=True, capture_output=True, timeout=90)

    def restart(self, down_for: float = 0.0) -> None:
        """Stop the server at once (every connection dropped), wait ``down_for`` seconds,
        start it again on the same port."""
        self._pg_ctl("-m", "immediate", "stop")
        time.sleep(down_for)
        self._pg_ctl("-o", self.options, "-l", str(self.folder / "log"), "-w", "-t", "60",
                     "start")

    def pids(self) -> list[int]:
        """The server's processes: the postmaster and its children."""
        head = (self.folder / "data" / "postmaster.pid").read_text().split()
        main = int(head[0])
        out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(main)], capture_output=True,
                             text=True).stdout.split()
        return [main] + [int(x) for x in out]

    def pause(self) -> None:
        """SIGSTOP every process of the server: connections stay open, nothing answers."""
        for pid in self.pids():
            os.kill(pid, signal.SIGSTOP)

    def resume(self) -> None:
        for pid in self.pids():
            os.kill(pid, signal.SIGCONT)

    def stop(self) -> None:
        """Stop the server at once (resumed first: a paused one would not hear pg_ctl) and
        remove its folder."""
        try:
            self.resume()
        except (OSError, ValueError, IndexError):  # not running: no postmaster.pid to read
            pass
        subprocess.run(self.runas + [str(self.bindir / "pg_ctl"), "-D", str(self.folder / "data"),
                                     "-m", "immediate", "stop"], capture_output=True, timeout=60)
        shutil.rmtree(self.folder, ignore_errors=True)


def binaries() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"),
                   key=lambda p: int(Path(p).parts[-3]) if Path(p).parts[-3].isdigit() else 0)
    if found:
        return Path(found[-1]).parent
    which = shutil.which("initdb")
    return Path(which).resolve().parent if which else None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def server(fsync: bool = False) -> tuple[Server | None, str]:
    """A running server and "", or None and why there is none. ``fsync``: flush commits to
    disk as a production server does (off for the tests: a throwaway cluster needs no
    durability, and the shared disk is slow)."""
    bindir = binaries()
    if bindir is None:
        return None, "no PostgreSQL binaries (Debian's postgresql package; make test installs it as root)"
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return None, "psycopg is not installed (pip install 'lidar-map-updating[store]')"
    runas: list[str] = []
    if os.geteuid() == 0:
        if shutil.which("runuser") is None or _no_user("postgres"):
            return None, "running as root with no postgres user to run the server as"
        runas = ["runuser", "-u", "postgres", "--"]
    folder = Path(tempfile.mkdtemp(prefix="mapstore-pg-"))
    os.chmod(folder, 0o777)
    srv = Server(bindir, folder, free_port(), runas)
    try:
        _start(srv, fsync)
    except (subprocess.SubprocessError, OSError, TimeoutError) as e:
        srv.stop()
        return None, f"the PostgreSQL server did not start: {' '.join(str(e).split())[:300]}"
    return srv, ""


def _no_user(name: str) -> bool:
    import pwd
    try:
        pwd.getpwnam(name)
        return False
    except KeyError:
        return True


def _start(srv: Server, fsync: bool) -> None:
    data, sock = srv.folder / "data", srv.folder / "sock"
    sock.mkdir()
    os.chmod(sock, 0o777)
    subprocess.run(srv.runas + [str(srv.bindir / "initdb"), "-D", str(data), "-U", "postgres",
                                "-A", "trust", "--no-sync", "-E", "UTF8"],
                   check=True, capture_output=True, timeout=120)
    options = (f"-p {srv.port} -k {sock} -c listen_addresses=127.0.0.1 "
               f"-c fsync={'on' if fsync else 'off'} -c max_connections=40 "
               "-c shared_buffers=128MB")
    srv.options = options
    subprocess.run(srv.runas + [str(srv.bindir / "pg_ctl"), "-D", str(data), "-o", options,
                                "-l", str(srv.folder / "log"), "-w", "-t", "60", "start"],
                   check=True, capture_output=True, timeout=90)
    import psycopg
    deadline = time.monotonic() + 30
    while True:
        try:
            psycopg.connect(srv.url(), connect_timeout=2).close()
            return
        except psycopg.OperationalError:
            if time.monotonic() > deadline:
                raise TimeoutError("no answer within 30 s") from None
            time.sleep(0.2)
