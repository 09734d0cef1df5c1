"""How a version's cells are kept: the whole map as zlib of its int8 cells, and the cells it
changed against its parent as two arrays (flat indices, new values), so that a diff between a
version and its parent, the diff asked for most, reads a few kilobytes instead of two maps."""

from __future__ import annotations

import hashlib
import zlib
from dataclasses import dataclass

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN

# zlib level 1: on a 400 x 250 m map at 5 cm it packs in 0.17 s where level 6 takes 0.74 s,
# for a third more bytes on a noisy map (3.8 MB against 2.5); packing is most of a commit's
# time (benchmarks/bench_map_store.py, docs/map_store.md)
LEVEL = 1


def pack_cells(data: np.ndarray) -> bytes:
    return zlib.compress(np.ascontiguousarray(data, dtype=np.int8).tobytes(), LEVEL)


def unpack_cells(blob: bytes, shape: tuple[int, int]) -> np.ndarray:
    raw = zlib.decompress(bytes(blob))
    if len(raw) != shape[0] * shape[1]:
        raise ValueError(f"{len(raw)} cells stored for a map of {shape[0]} x {shape[1]}")
    return np.frombuffer(raw, dtype=np.int8).reshape(shape).copy()


def digest(data: np.ndarray) -> str:
    """The cells' fingerprint alone: a store of schema 1's, checked once as it is upgraded."""
    return hashlib.sha256(np.ascontiguousarray(data, dtype=np.int8).tobytes()).hexdigest()


def fingerprint(data: np.ndarray, resolution: float, origin: tuple[float, float]) -> str:
    """A version's fingerprint, checked on every read: its frame (size, resolution, origin, to
    the last bit) and its cells, so that a version whose frame or cells changed is refused,
    never served shifted or rescaled."""
    h = hashlib.sha256()
    h.update(f"frame {data.shape[0]} {data.shape[1]} {float(resolution).hex()} "
             f"{float(origin[0]).hex()} {float(origin[1]).hex()}\n".encode())
    h.update(np.ascontiguousarray(data, dtype=np.int8).tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class CellChanges:
    """Cells that differ from one map to another of the same shape: flat indices (row-major,
    increasing) and each cell's value before and after."""

    index: np.ndarray        # int64
    before: np.ndarray       # int8
    after: np.ndarray        # int8

    def __len__(self) -> int:
        return int(self.index.size)

    def counts(self) -> dict[str, int]:
        """The changes by kind, as ``mapupdate update`` counts them (``cells_freed``: every
        cell now free that was not, an unknown one made known included)."""
        a, b = self.before, self.after

        def count(was, now) -> int:
            return int(np.count_nonzero(was & now))
        out = {"occupied_to_free": count(a == OCCUPIED, b == FREE),
               "free_to_occupied": count(a == FREE, b == OCCUPIED),
               "unknown_to_free": count(a == UNKNOWN, b == FREE),
               "unknown_to_occupied": count(a == UNKNOWN, b == OCCUPIED),
               "known_to_unknown": count(a != UNKNOWN, b == UNKNOWN)}
        out["cells_freed"] = out["occupied_to_free"] + out["unknown_to_free"]
        out["cells_drawn"] = out["free_to_occupied"] + out["unknown_to_occupied"]
        out["cells_changed"] = len(self)
        return out


def changes_between(before: np.ndarray, after: np.ndarray) -> CellChanges:
    a, b = before.reshape(-1), after.reshape(-1)
    index = np.flatnonzero(a != b)
    return CellChanges(index.astype(np.int64), a[index].copy(), b[index].copy())


def pack_cells_values(index: np.ndarray, values: list[np.ndarray]) -> tuple[bytes, bytes]:
    """(index, values) blobs of cells and a few int8 values each. The indices are stored as
    gaps from the one before (uint32, zlib): changes come in patches, so most gaps are 1 and
    compress to almost nothing."""
    gaps = np.diff(index, prepend=0).astype(np.uint32)
    stacked = np.stack(values).astype(np.int8)
    return zlib.compress(gaps.tobytes(), LEVEL), zlib.compress(stacked.tobytes(), LEVEL)


def unpack_cells_values(index_blob: bytes, values_blob: bytes, rows: int, what: str
                        ) -> tuple[np.ndarray, np.ndarray]:
    """(flat indices, ``rows`` x n values) from ``pack_cells_values``'s blobs."""
    gaps = np.frombuffer(zlib.decompress(bytes(index_blob)), dtype=np.uint32)
    values = np.frombuffer(zlib.decompress(bytes(values_blob)), dtype=np.int8)
    if values.size != rows * gaps.size:
        raise ValueError(f"{gaps.size} {what} cells stored with {values.size} values")
    return np.cumsum(gaps, dtype=np.int64), values.reshape(rows, -1).copy()


def pack_changes(changes: CellChanges) -> tuple[bytes, bytes]:
    return pack_cells_values(changes.index, [changes.before, changes.after])


def unpack_changes(index_blob: bytes, values_blob: bytes) -> CellChanges:
    index, (before, after) = unpack_cells_values(index_blob, values_blob, 2, "changed")
    return CellChanges(index, before, after)


def apply_changes(data: np.ndarray, changes: CellChanges) -> np.ndarray:
    out = data.copy().reshape(-1)
    out[changes.index] = changes.after
    return out.reshape(data.shape)
