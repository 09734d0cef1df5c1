"""A study's runs as Ray tasks: the only module of the project that imports Ray.

``--ray auto`` starts a Ray instance on this machine (as many CPUs as ``--workers``, default
all); ``--ray ADDRESS`` joins an existing cluster (``ray start --head`` on one machine,
``ray start --address ...`` on the others; every machine needs this package installed and the
study folder on a shared file system, since each task writes its run there). Each run is one
task of one CPU, so a study grows to many machines with no change to its spec.
"""

from __future__ import annotations

from pathlib import Path

from gridmap import MapUpdatingError

INSTALL_HINT = "pip install 'lidar-map-updating[ray]'"


class RayMissing(MapUpdatingError, ImportError):
    """Ray was asked for and is not installed."""


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
