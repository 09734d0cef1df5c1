"""A live node's link to the map store (the ``store`` parameter: an SQLite file or a
``postgresql://`` URL): the node serves the store's latest approved version as its reference,
commits its updated map as a version on ``commit``, and takes up a newer approved version
(another robot's, or its own once reviewed) when one appears. No ROS import."""

from __future__ import annotations

import socket
import time
import uuid
from importlib import metadata

import numpy as np

from gridmap import OccupancyGrid
from mapstore import StoreError, merge, open_store


def _project_version() -> str:
    try:
        return metadata.version("lidar-map-updating")
    except metadata.PackageNotFoundError:
        return "unknown"


class StoreLink:
    def __init__(self, target: str, robot: str = "", poll_period: float = 10.0):
        self.target, self.poll_period = target, poll_period
        self.robot = robot or socket.gethostname()
        self.version: int | None = None          # the version the node's reference is
        self._checked = time.monotonic()
        with open_store(target, create=True):     # a missing file becomes an empty store
            pass

    def start(self, given: OccupancyGrid | None) -> OccupancyGrid | None:
        """The reference the node starts from: the latest approved version; in an empty store,
        ``given`` (the map file or the first map message), committed as its first version."""
        with open_store(self.target) as store:
            latest = store.latest()
            if latest is not None:
                self.version = latest
                return store.get(latest)
            if given is None:
                return None
            self.version = store.commit(given, None, {
                "method": "import", "robot": self.robot, "source": "live node",
                "project_version": _project_version()}, status="approved")
            return given

    def commit(self, grid: OccupancyGrid, meta: dict
               ) -> tuple[int, str, tuple[int, OccupancyGrid] | None]:
        """Commit ``grid`` as a child of the node's version: (its number, its status, and
        (number, map) of the merge the store made when the node's version was no longer the
        latest, else None). Approved, the version (or its merge) is the node's from now."""
        with open_store(self.target) as store:
            number = store.commit(grid, self.version, {
                "robot": self.robot, "source": "live node", "started_from": self.version,
                "project_version": _project_version(), **meta}, uid=uuid.uuid4().hex)
            status = store.version(number).status
            merged = None if store.merged is None else (store.merged, store.get(store.merged))
        if status == "approved":
            self.version = number if merged is None else merged[0]
        return number, status, merged

    def commit_session(self, pipeline, method: str, updater_config) -> tuple[bool, str, object]:
        """A node's ``commit`` with a store: (done, what to answer, the map the node goes on
        from: the updated one when approved at once, or the merge of it with what other
        robots committed meanwhile; else its reference, buffers afresh)."""
        updated = pipeline.updater.updated_map()
        meta = {"method": method, "scans": pipeline.counts.as_dict(),
                "config": {"updater": updater_config.to_dict()}}
        try:
            number, status, merged = self.commit(updated, meta)
        except StoreError as e:
            return False, f"cannot commit: {e}", None
        if status == "approved" and merged is not None:
            return True, (f"committed v{number}, merged with the site's map as v{merged[0]}, "
                          "the reference now"), merged[1]
        if status == "approved":
            return True, f"committed v{number}, the reference now", updated
        return True, (f"committed v{number}, pending review; the node keeps v{self.version} "
                      "until a newer one is approved"), pipeline.updater.reference_map

    def newer(self, force: bool = False,
              session: tuple[OccupancyGrid, OccupancyGrid] | None = None
              ) -> tuple[int, OccupancyGrid] | None:
        """A newer approved version than the node's, looked for at most every
        ``poll_period`` seconds (``force``: now): (its number, the map the node goes on from).

        ``session``: (the node's reference, its updated map). When the session has changed
        cells it has not committed, they are not thrown away: the map the node goes on from is
        the newer version with the session's changes laid on it (the store's three-way merge,
        the session winning a conflict as the commit would), and the node's version becomes
        the newer one, so that its next commit is counted and merged against it."""
        now = time.monotonic()
        if not force and now - self._checked < self.poll_period:
            return None
        self._checked = now
        with open_store(self.target) as store:
            latest = store.latest()
            if latest is None or (self.version is not None and latest <= self.version):
                return None
            grid = store.get(latest)
            if session is not None and self.version is not None:
                reference, updated = session
                if not np.array_equal(reference.data, updated.data):
                    grid = grid.with_data(rebased(store.get(self.version).data, grid.data,
                                                  updated.data))
            self.version = latest
            return latest, grid


def rebased(base, newer, session):
    """``session``'s changes against ``base`` laid on ``newer`` (three-way, the session
    winning a conflict)."""
    return merge.three_way(base, newer, session, theirs_wins=True).data


__all__ = ["StoreError", "StoreLink"]
