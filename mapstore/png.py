"""The picture of a diff: the map with the cells freed and drawn in the colours of the run
figures (scenarios/topview.py), written as a PNG with numpy and zlib alone so that a robot
install, which has no figure library, can draw it."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from gridmap import FREE, OCCUPIED
from gridmap.atomic import write_atomically

# scenarios/topview.py's CELL_COLORS, which this package may not import
COLORS = {"free": (255, 255, 255), "occupied": (40, 40, 40), "unknown": (190, 190, 190),
          "freed": (150, 230, 150), "drawn": (220, 60, 200), "unknown_now": (250, 170, 60)}
# margin [cells] kept around the changes when the picture is cropped to them
MARGIN = 40


def diff_picture(before: np.ndarray, after: np.ndarray, crop: bool = True) -> np.ndarray:
    """(H, W, 3) uint8, north up: ``after`` in the map's greys, its cells freed green, drawn
    magenta and made unknown orange. ``crop``: only the box round the changes (with
    ``MARGIN``), as a site map is too large to look at whole; no change, the whole map."""
    out = np.empty(after.shape + (3,), np.uint8)
    out[...] = COLORS["unknown"]
    out[after == FREE] = COLORS["free"]
    out[after == OCCUPIED] = COLORS["occupied"]
    changed = before != after
    out[changed & (after == FREE)] = COLORS["freed"]
    out[changed & (after == OCCUPIED)] = COLORS["drawn"]
    out[changed & (after != FREE) & (after != OCCUPIED)] = COLORS["unknown_now"]
    if crop and changed.any():
        rows, cols = np.nonzero(changed.any(axis=1))[0], np.nonzero(changed.any(axis=0))[0]
        r0, r1 = max(rows[0] - MARGIN, 0), min(rows[-1] + MARGIN + 1, after.shape[0])
        c0, c1 = max(cols[0] - MARGIN, 0), min(cols[-1] + MARGIN + 1, after.shape[1])
        out = out[r0:r1, c0:c1]
    return np.ascontiguousarray(out[::-1])


def png_bytes(rgb: np.ndarray) -> bytes:
    """An 8-bit RGB PNG of ``rgb`` (H, W, 3) uint8: every row with filter 0, one IDAT chunk."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w = rgb.shape[:2]
    rows = np.zeros((h, 1 + 3 * w), np.uint8)    # a zero byte (no filter) before each row
    rows[:, 1:] = rgb.reshape(h, 3 * w)

    def chunk(kind: bytes, body: bytes) -> bytes:
        return (struct.pack(">I", len(body)) + kind + body
                + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))
    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6)) + chunk(b"IEND", b""))


def write_diff_png(path, before: np.ndarray, after: np.ndarray) -> tuple[int, int]:
    """Write the diff's picture to ``path`` atomically; returns its (width, height)."""
    rgb = diff_picture(before, after)
    write_atomically(path, png_bytes(rgb))
    return rgb.shape[1], rgb.shape[0]
