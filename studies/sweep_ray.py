"""A study's runs as Ray tasks: the only module of the project that imports Ray.

``--ray auto`` starts a Ray instance on this machine (as many CPUs as ``--workers``, default
all); ``--ray ADDRESS`` joins an existing cluster (``ray start --head`` on one machine,
``ray start --address ...`` on the others; every machine needs this package installed and the
study folder on a shared file system, since each task writes its run there). Each run is one
task of one CPU, so a study grows to many machines with no change to its spec.
"""

from __future__ import annotations

import importlib.util
import re
import socket
from pathlib import Path

from gridmap import MapUpdatingError

INSTALL_HINT = "pip install 'lidar-map-updating[ray]'"
ADDRESS = re.compile(r"(?P<client>ray://)?(?P<host>[A-Za-z0-9_.-]+):(?P<port>[0-9]{1,5})")
CONNECT_TIMEOUT = 5.0     # [s] a cluster that does not answer within this is not there


class RayMissing(MapUpdatingError, ImportError):
    """Ray was asked for and is not installed."""


class RayAddressError(MapUpdatingError, ValueError):
    """An address of a Ray cluster that is malformed or where nothing answers."""


def check_address(address: str) -> None:
    """Refuse, in one line and within seconds, an address Ray would hang on or fail at:
    "auto", HOST:PORT (a cluster's GCS) or ray://HOST:PORT (Ray's client, which needs
    ``ray[client]``), with something answering on that port."""
    if address == "auto":
        return
    m = ADDRESS.fullmatch(address or "")
    if m is None or not 0 < int(m["port"]) < 65536:
        raise RayAddressError(f"--ray {address!r}: not an address; give 'auto', HOST:PORT or "
                              "ray://HOST:PORT")
    if m["client"] and importlib.util.find_spec("grpc") is None:
        raise RayAddressError(f"--ray {address}: Ray's client needs its extra: pip install "
                              "'ray[client]'")
    try:
        socket.create_connection((m["host"], int(m["port"])), timeout=CONNECT_TIMEOUT).close()
    except OSError as e:
        raise RayAddressError(f"--ray {address}: no Ray cluster answers there within "
                              f"{CONNECT_TIMEOUT:g} s ({e.strerror or e})") from None


def require_ray():
    """The ``ray`` module, or ``RayMissing`` saying what to install."""
    try:
        import ray
    except ImportError:
        raise RayMissing(f"--ray needs Ray, which is not installed: {INSTALL_HINT}") from None
    return ray


def start(address: str, workers: int | None = None):
    """Join the cluster at ``address``, or start a local instance for "auto"; returns ray."""
    ray = require_ray()
    if not ray.is_initialized():
        quiet = {"log_to_driver": False, "include_dashboard": False}
        if address == "auto":
            ray.init(num_cpus=workers, **quiet)
        else:
            ray.init(address=address, **quiet)
    return ray


def ray_tasks(execute, runs, runs_dir, address: str, workers: int | None = None):
    """Yield (run, record) as the Ray tasks ``execute(run, runs_dir)`` of ``runs`` finish."""
    ray = start(address, workers)
    task = ray.remote(num_cpus=1, max_retries=0)(execute)
    pending = {task.remote(run, str(Path(runs_dir).resolve())): run for run in runs}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                run = pending.pop(ref)
                try:
                    record = ray.get(ref)
                except ray.exceptions.RayTaskError as e:
                    # the run's own error, as the pool would give it
                    raise e.as_instanceof_cause() from None
                yield run, record
    finally:
        for ref in pending:
            ray.cancel(ref)
