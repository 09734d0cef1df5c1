"""numba kernels of the evaluation: counting the scans that observe each cell."""

import numpy as np
from numba import njit

from gridmap._kernels import traverse


@njit(cache=True)
def count_observations(counts, stamp, scan_id, gx0, gy0, end_gx, end_gy, rows, cols):
    """Add one to ``counts`` for every cell the beams from (gx0, gy0) to their end points pass
    through, at most once per scan (``stamp`` remembers the last scan that counted a cell)."""
    height, width = counts.shape
    for i in range(end_gx.shape[0]):
        n = traverse(gx0, gy0, end_gx[i], end_gy[i], height, width, rows, cols)
        for k in range(n):
            r = rows[k]
            c = cols[k]
            if stamp[r, c] != scan_id:
                stamp[r, c] = scan_id
                counts[r, c] += 1


@njit(cache=True)
def paint_discs(mask, gx, gy, gr):
    """Mark every cell whose centre lies within one of the discs (grid units)."""
    height, width = mask.shape
    for i in range(gx.shape[0]):
        r0 = max(int(np.floor(gy[i] - gr[i])), 0)
        r1 = min(int(np.ceil(gy[i] + gr[i])), height - 1)
        c0 = max(int(np.floor(gx[i] - gr[i])), 0)
        c1 = min(int(np.ceil(gx[i] + gr[i])), width - 1)
        rr = gr[i] * gr[i]
        for r in range(r0, r1 + 1):
            dy = r + 0.5 - gy[i]
            for c in range(c0, c1 + 1):
                dx = c + 0.5 - gx[i]
                if dx * dx + dy * dy <= rr:
                    mask[r, c] = True
