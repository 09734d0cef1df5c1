"""numba kernels of the distance field: the exact Euclidean distance transform of
Felzenszwalb and Huttenlocher ("Distance Transforms of Sampled Functions", 2012).

The 2D transform is two passes of a 1D transform of squared distances: down every column, then
along every row. Distances are in cells between cell centres; squared values stay exact in
float64 for any grid that fits in memory. Kernels take arrays and scalars only.
"""

import numpy as np
from numba import njit

from .cells import OCCUPIED


@njit(cache=True)
def edt_1d(f, out, v, z):
    """Lower envelope of the parabolas ``(q - p)^2 + f[p]``: ``out[q] = min_p``. Entries of ``f``
    that are ``inf`` (no obstacle) add no parabola, so no ``inf - inf`` ever occurs; a line
    without any finite entry stays ``inf``. ``v`` (int) and ``z`` (float, len n + 1) are work
    arrays: the envelope's parabola apexes and the boundaries between them."""
    n = f.shape[0]
    k = -1
    for q in range(n):
        if f[q] == np.inf:
            continue
        if k < 0:
            k = 0
            v[0] = q
            z[0] = -np.inf
            z[1] = np.inf
            continue
        s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
        while s <= z[k]:
            k -= 1
            s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
        k += 1
        v[k] = q
        z[k] = s
        z[k + 1] = np.inf
    if k < 0:
        for q in range(n):
            out[q] = np.inf
        return
    j = 0
    for q in range(n):
        while z[j + 1] < q:
            j += 1
        d = q - v[j]
        out[q] = d * d + f[v[j]]


@njit(cache=True)
def squared_edt(cells):
    """Squared Euclidean distance [cells^2] from every cell to the nearest occupied cell
    (value 100) of an int8 grid; ``inf`` everywhere when there is none."""
    h, w = cells.shape
    d2 = np.empty((h, w), np.float64)
    n = max(h, w)
    f = np.empty(n, np.float64)
    out = np.empty(n, np.float64)
    v = np.empty(n, np.int64)
    z = np.empty(n + 1, np.float64)
    for c in range(w):                       # pass 1: down each column
        for r in range(h):
            f[r] = 0.0 if cells[r, c] == OCCUPIED else np.inf
        edt_1d(f[:h], out[:h], v, z)
        for r in range(h):
            d2[r, c] = out[r]
    for r in range(h):                       # pass 2: along each row, over the column results
        for c in range(w):
            f[c] = d2[r, c]
        edt_1d(f[:w], out[:w], v, z)
        for c in range(w):
            d2[r, c] = out[c]
    return d2
