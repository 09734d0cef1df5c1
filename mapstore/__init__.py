"""Versions of a site's map: each commit's map, the cells it changed against its parent and
what made it, in an SQLite file or a PostgreSQL database; review, rollback and tags. Imports
gridmap, numpy and the database drivers only."""

from .backends import StoreError
from .cells import CellChanges
from .store import STATUSES, Store, Version, open_store

__all__ = ["STATUSES", "CellChanges", "Store", "StoreError", "Version", "open_store"]
