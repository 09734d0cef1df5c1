"""Three-way merge of two versions of a site's map against their common ancestor, cell by
cell, as a fleet needs it when robots commit sessions that started from the same version.

A cell changed on one side only takes that side; changed the same way on both, that value;
changed in different ways on the two sides (the base occupied, one side freed it and the other
made it unknown; unknown floor seen free by one robot and occupied by the other) is a
**conflict**. A conflict goes to the side that saw the world last: the side whose newest
session was committed later (``newer``). The store keeps every conflict's cell with the base's,
both sides' and the chosen value, so an operator can see what was settled and how.

Only ``numpy`` and the store's cell packing: the store calls this with its maps' cells."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import cells

RULE = "newer"
RULE_TEXT = "a conflict goes to the side committed last"


@dataclass(frozen=True)
class Conflicts:
    """The cells changed in different ways on the two sides: flat indices (row-major,
    increasing) and each cell's value in the base, on each side and in the merge."""

    index: np.ndarray        # int64
    base: np.ndarray         # int8
    ours: np.ndarray         # int8: the site's latest version's value
    theirs: np.ndarray       # int8: the version merged into it
    chosen: np.ndarray       # int8

    def __len__(self) -> int:
        return int(self.index.size)


@dataclass(frozen=True)
class Merge:
    data: np.ndarray             # the merged cells
    conflicts: Conflicts
    counts: dict                 # cells taken from each side, the same on both, conflicts


def three_way(base: np.ndarray | None, ours: np.ndarray, theirs: np.ndarray,
              theirs_wins: bool) -> Merge:
    """Merge ``theirs`` into ``ours`` against ``base`` (None: no common ancestor, so every
    cell where the two differ is a conflict). ``theirs_wins``: conflicts go to ``theirs``."""
    if ours.shape != theirs.shape or (base is not None and base.shape != ours.shape):
        raise ValueError(f"maps of different shapes: {ours.shape}, {theirs.shape}"
                         + ("" if base is None else f", base {base.shape}"))
    o, t = ours.reshape(-1), theirs.reshape(-1)
    differ = o != t
    if base is None:
        b = np.where(differ, np.int8(-2), o)      # a value no cell holds: both sides "changed"
    else:
        b = base.reshape(-1)
    ours_changed, theirs_changed = o != b, t != b
    take_theirs = theirs_changed & ~ours_changed
    conflict = ours_changed & theirs_changed & differ
    merged = o.copy()
    merged[take_theirs] = t[take_theirs]
    if theirs_wins:
        merged[conflict] = t[conflict]
    index = np.flatnonzero(conflict).astype(np.int64)
    conflicts = Conflicts(index, b[index].astype(np.int8), o[index].copy(), t[index].copy(),
                          merged[index].copy())
    counts = {"from_ours": int(np.count_nonzero(ours_changed & ~theirs_changed)),
              "from_theirs": int(np.count_nonzero(take_theirs)),
              "same_on_both": int(np.count_nonzero(ours_changed & theirs_changed & ~differ)),
              "conflicts": len(conflicts),
              "conflicts_to_theirs": len(conflicts) if theirs_wins else 0}
    return Merge(merged.reshape(ours.shape), conflicts, counts)


def pack_conflicts(c: Conflicts) -> tuple[bytes, bytes]:
    """(index, values) blobs, as the store keeps changes: each cell's four values."""
    return cells.pack_cells_values(c.index, [c.base, c.ours, c.theirs, c.chosen])


def unpack_conflicts(index_blob: bytes, values_blob: bytes) -> Conflicts:
    index, (base, ours, theirs, chosen) = cells.unpack_cells_values(
        index_blob, values_blob, 4, "conflicting")
    return Conflicts(index, base, ours, theirs, chosen)
