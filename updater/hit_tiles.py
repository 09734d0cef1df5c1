"""The hit buffers of the growth into the unknown, kept in tiles of 64 x 64 cells that are made
when a scan first hits open unknown space inside them.

A hit buffer is two bytes a cell, as many as the flag buffers, but only the cells where a beam
ends in M's open unknown space ever use one: the surfaces of the places the map did not know.
A tile directory (an int32 per tile, -1 where there is no tile yet) points into a pool of
tiles that grows by doubling; the kernels address a cell through both
(``_buffers.hit_slot``). Empty, the buffers of a 2000 x 2000 map take 4 KB instead of 8 MB.
"""

from __future__ import annotations

import numpy as np

TILE_SHIFT = 6                       # a tile is 2**6 = 64 cells on a side
TILE_CELLS = 1 << (2 * TILE_SHIFT)


class HitTiles:
    """Hit buffers (uint16 shift registers, as ``MapUpdater``'s flag buffers) of an H x W map,
    stored by tile. ``enabled`` False: no directory at all (the growth is off)."""

    def __init__(self, shape: tuple[int, int], enabled: bool = True):
        height, width = shape
        self.shape = (height, width)
        n_rows = -(-height >> TILE_SHIFT) if enabled else 0
        n_cols = -(-width >> TILE_SHIFT) if enabled else 0
        self.directory = np.full((n_rows, n_cols), -1, np.int32)
        self.pool = np.zeros((0, TILE_CELLS), np.uint16)
        # tiles of the pool in use, in an array so that a kernel can make tiles while the pool
        # has room (``_buffers.make_hit_tiles``); the rows past them are all zero
        self.count = np.zeros(1, np.int64)

    @property
    def used(self) -> int:
        return int(self.count[0])

    @property
    def nbytes(self) -> int:
        return self.directory.nbytes + self.pool.nbytes + self.count.nbytes

    def ensure(self, cells: np.ndarray) -> None:
        """Make the tiles holding ``cells`` (flat indices into the map) where there are none."""
        if cells.size == 0:
            return
        width = self.shape[1]
        rows, cols = cells // width, cells % width
        self.make((rows >> TILE_SHIFT) * self.directory.shape[1] + (cols >> TILE_SHIFT))

    def make(self, tiles: np.ndarray) -> None:
        """Make the ``tiles`` (flat indices into the directory, repeats allowed) there are not
        yet."""
        flat = self.directory.reshape(-1)
        missing = np.unique(tiles[flat[tiles] < 0])
        if missing.size == 0:
            return
        used = self.used
        need = used + missing.size
        if need > self.pool.shape[0]:
            grown = np.zeros((max(need, 2 * self.pool.shape[0], 4), TILE_CELLS), np.uint16)
            grown[:used] = self.pool[:used]
            self.pool = grown
        flat[missing] = np.arange(used, need, dtype=np.int32)
        self.count[0] = need

    def dense(self) -> np.ndarray:
        """The buffers as one (H, W) uint16 array (for saving)."""
        height, width = self.shape
        if self.directory.size == 0:
            return np.zeros((0, 0), np.uint16)
        out = np.zeros((self.directory.shape[0] << TILE_SHIFT,
                        self.directory.shape[1] << TILE_SHIFT), np.uint16)
        side = 1 << TILE_SHIFT
        for tr, tc in zip(*np.nonzero(self.directory >= 0)):
            out[tr * side:(tr + 1) * side, tc * side:(tc + 1) * side] = \
                self.pool[self.directory[tr, tc]].reshape(side, side)
        return out[:height, :width]

    @classmethod
    def from_dense(cls, buffers: np.ndarray) -> HitTiles:
        """Tiles of (H, W) buffers: one for each 64 x 64 block holding a non-zero buffer."""
        tiles = cls(buffers.shape)
        tiles.ensure(np.flatnonzero(buffers))
        side = 1 << TILE_SHIFT
        for tr, tc in zip(*np.nonzero(tiles.directory >= 0)):
            block = buffers[tr * side:(tr + 1) * side, tc * side:(tc + 1) * side]
            tile = np.zeros((side, side), np.uint16)
            tile[:block.shape[0], :block.shape[1]] = block
            tiles.pool[tiles.directory[tr, tc]] = tile.reshape(-1)
        return tiles
