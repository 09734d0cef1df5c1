"""What the kernels of every step share: bit planes, a buffer's flag count, the verdicts as
plain ints and the size of M's clear blocks.

Per-scan marks and the decided state are bit planes: one bit per cell, eight to a byte
(``bits[idx >> 3] >> (idx & 7)``), cells by flat index ``row * width + col``.
"""

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from gridmap.cells import FREE, OCCUPIED

from ._arguments import Beams, OwnRays
from .verdicts import BeamVerdict

# The blocks of ``clear_blocks`` (gridmap): 8 x 8 cells, 1/64 byte a cell. numba compiles it
# into the kernels that read it (``_kernels``' docstring: what that means for their cache).
CLEAR_SHIFT = 3

# The per-beam verdicts as plain ints, which numba compiles in as constants.
INVALID = int(BeamVerdict.INVALID)
UNCHANGED = int(BeamVerdict.UNCHANGED)
SKIPPED = int(BeamVerdict.SKIPPED)
CHANGE = int(BeamVerdict.CHANGE)


@njit(cache=True, inline="always")
def bit_get(bits, idx):
    """The bit of cell ``idx``."""
    return (bits[idx >> 3] >> (idx & 7)) & 1


@njit(cache=True, inline="always")
def test_and_set(bits, idx):
    """Set the bit of cell ``idx``; False if it was already set."""
    b = idx >> 3
    m = 1 << (idx & 7)
    if bits[b] & m:
        return False
    bits[b] = bits[b] | m
    return True


@njit(cache=True, inline="always")
def set_bit(bits, idx, value):
    """Set cell ``idx``'s bit to ``value``."""
    b = idx >> 3
    bits[b] = (bits[b] & ~np.uint8(1 << (idx & 7))) | np.uint8(np.int64(value) << (idx & 7))


@njit(cache=True)
def clear_bits(bits, cells, n):
    """Clear the bits of the first ``n`` listed cells, and only those."""
    for k in range(n):
        idx = cells[k]
        bits[idx >> 3] = bits[idx >> 3] & ~(1 << (idx & 7))


@intrinsic
def _ctpop64(typingctx, x):
    """The processor's population count of an int64 (LLVM's ctpop)."""
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.ctpop(args[0])

    return sig, codegen


@njit(cache=True)
def popcount16(v):
    """The number of set bits of a uint16."""
    return _ctpop64(np.int64(v) & 0xFFFF)


# A cell's flag count lives in a uint8 array of its own (``shift`` 0) or in the bits of its
# buffer above the flags (``shift`` = N_b): the spare bits of a short buffer hold it for free.


@njit(cache=True, inline="always")
def flag_count(hist, seen, idx, shift):
    """The flags cell ``idx`` ever got, saturating (0 when they are not counted). The count
    saturates at its field's largest value (255 in the array of its own), where the rule reads
    it as 'many'."""
    if shift > 0:
        return np.int64(hist[idx]) >> shift
    if seen.shape[0] == 0:
        return 0
    return np.int64(seen[idx])


@njit(cache=True, inline="always")
def confirmed(hist, seen, ref, idx, mask, shift=0):
    """An occupied cell of M whose recent flags are not all changed: a surface the scans still
    see. The unanimous rule frees no occupied cell next to one. (Why a count must reach N_b
    before it saturates: the last min(count, N_b) flags are the ones to look at.)"""
    if ref[idx] != OCCUPIED:
        return False
    seen_n = flag_count(hist, seen, idx, shift)
    if seen_n == 0:
        return False
    window = popcount16(mask)
    return popcount16(hist[idx] & mask) < min(seen_n, window)


@njit(cache=True, inline="always")
def hit_cell(ref, px, py):
    """The flat index of the cell of point (px, py), -1 when it lies off the map."""
    height, width = ref.shape
    if not (0.0 <= px < width and 0.0 <= py < height):
        return -1
    return int(np.floor(py)) * width + int(np.floor(px))


@njit(cache=True, inline="always")
def is_open_unknown(ref_flat, enclosed, idx):
    """Unknown in M and outside the enclosed regions: space M never saw, where the map grows
    (an enclosed region is an object's interior, which the last check closes)."""
    v = ref_flat[idx]
    return v != FREE and v != OCCUPIED and not bit_get(enclosed, idx)


@njit(cache=True, inline="always")
def behind_occupied(ref, row, col, dx, dy):
    """Whether an 8-neighbour of the cell on the side a beam along (dx, dy) comes from (the
    offset's dot product with the beam's direction below 0) is occupied in M."""
    height, width = ref.shape
    for r in range(max(row - 1, 0), min(row + 2, height)):
        for c in range(max(col - 1, 0), min(col + 2, width)):
            if ref[r, c] == OCCUPIED and (c - col) * dx + (r - row) * dy < 0.0:
                return True
    return False


# --- the per-beam arrays by name ----------------------------------------------------------
@njit(cache=True, inline="always")
def beam_rows(work):
    """A scan's per-beam arrays (``_arguments.Beams``): views of the rows of ``work``'s
    ``floats``, ``bools``, ``verdicts``, ``points`` and ``rays``, in the order of ``Beams``'
    fields (the order ``steps.Workspace`` names them in), and its ``found``."""
    f, b, v, p, r = work.floats, work.bools, work.verdicts, work.points, work.rays
    return Beams(f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], b[0], b[1], b[2], b[3], b[4],
                 v[0], v[1], p[0], p[1], r[0], r[1], work.found)


@njit(cache=True, inline="always")
def own_rays(beams, n, ratio):
    """The n measured beams' own virtual beams, every ``ratio``-th (``_arguments.OwnRays``)."""
    own = slice(0, n * ratio, ratio)
    return OwnRays(beams.expected[own], beams.virtual[own], beams.found[own])
