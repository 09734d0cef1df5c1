"""What a saved updater state must hold to be loaded, beyond its shapes and types: the arrays
as they were saved, and buffers the updater could have filled.

A bit flipped on the disk fails the zip's own CRC when numpy reads the file; an array written
again by other means (a tool, a hand edit, a bug) is whole as a file and wrong as a state. So
``MapUpdater.save`` keeps each array's CRC-32 in the state's metadata (``checksums``) and
``MapUpdater.load`` refuses arrays that differ from it. States saved before the checksums
(none in their metadata) are checked by the second rule alone: a cell's buffer holds its last
min(count, N_b) flags, every flag pushed counting one, so a flag further back than the cell's
count was never pushed. (With the flag counts kept, N_b <= 12, the bits above the N_b flags
hold the count: those bits are the state's, not beyond it.)
"""

from __future__ import annotations

import zlib

import numpy as np

from .config import UpdaterError

# what each saved array is, for the messages
ARRAYS = {"reference": "reference map", "hist": "buffers", "hits": "hit buffers",
          "seen": "flag counts", "face_hits": "face hit counts",
          "face_passes": "face crossing counts", "face_behind": "face behind counts",
          "face_now": "face hits of the session",
          "face_confirmed": "faces the last session would have moved",
          "face_crossed": "face crossings of the session"}
_BLOCK = 1 << 20           # cells per block of the flag check


def checksums(arrays: dict) -> dict:
    """CRC-32 of each array's bytes (C order), by its name in the state file."""
    return {name: zlib.crc32(np.ascontiguousarray(a).data) for name, a in arrays.items()}


def check_checksums(path, saved, arrays: dict) -> None:
    """Refuse arrays (by name; None: not in the file) whose CRC-32 is not the one saved."""
    if saved is None:           # a state saved before the checksums
        return
    if not isinstance(saved, dict):
        raise UpdaterError(f"{path}: a damaged state: its checksums are not a mapping")
    for name, array in arrays.items():
        if array is None and name not in saved:
            continue
        want, got = saved.get(name), None if array is None else checksums({name: array})[name]
        if got != want:
            raise UpdaterError(f"{path}: a damaged state: its {ARRAYS[name]} are not as saved "
                               f"(CRC-32 {_hex(got)}, saved {_hex(want)})")


def _hex(value) -> str:
    return f"{value:#010x}" if isinstance(value, int) and not isinstance(value, bool) \
        else repr(value)[:20]


def check_flags_counted(path, hist: np.ndarray, counts: np.ndarray | None, mask: int,
                        buffer_size: int, width: int) -> None:
    """Refuse buffers (``hist``, flat) holding a flag further back than the cell's flag count
    (``counts``, flat; None when the flags are not counted: nothing to check)."""
    if counts is None:
        return
    bad, first = 0, -1
    for lo in range(0, hist.size, _BLOCK):      # in blocks: no temporaries of the map's size
        hi = min(lo + _BLOCK, hist.size)
        flags = (hist[lo:hi] & np.uint16(mask)).astype(np.int32)
        window = np.minimum(counts[lo:hi], buffer_size).astype(np.int32)
        wrong = np.flatnonzero(flags >> window)
        if wrong.size and first < 0:
            first = lo + int(wrong[0])
        bad += int(wrong.size)
    if bad:
        row, col = divmod(first, width)
        raise UpdaterError(
            f"{path}: a damaged state: {bad} cells' buffers hold flags further back than the "
            f"cell's flag count, which no scan pushed (the first at row {row}, column {col}: "
            f"count {int(counts[first])}, flags {int(hist[first]) & mask:#b})")
