"""numba kernels of the map metrics. Arrays in, arrays out."""

from numba import njit


@njit(cache=True)
def taxicab_distance(targets, out):
    """Manhattan distance [cells] from every cell to the nearest True cell of ``targets``,
    written into ``out`` (int32, same shape). Where ``targets`` has no True cell, every
    distance is height + width, farther than any real distance.

    Two raster passes (Rosenfeld and Pfaltz): the L1 metric is a sum of unit steps, so
    propagating +1 from the up/left neighbours forward and from the down/right ones backward
    gives the exact distance in O(cells)."""
    h, w = targets.shape
    far = h + w
    for r in range(h):
        for c in range(w):
            if targets[r, c]:
                d = 0
            else:
                d = far
                if r > 0 and out[r - 1, c] + 1 < d:
                    d = out[r - 1, c] + 1
                if c > 0 and out[r, c - 1] + 1 < d:
                    d = out[r, c - 1] + 1
            out[r, c] = d
    for r in range(h - 1, -1, -1):
        for c in range(w - 1, -1, -1):
            d = out[r, c]
            if r < h - 1 and out[r + 1, c] + 1 < d:
                d = out[r + 1, c] + 1
            if c < w - 1 and out[r, c + 1] + 1 < d:
                d = out[r, c + 1] + 1
            out[r, c] = d


@njit(cache=True)
def capped_distance_sum(sources, dist, cap):
    """Sum over the True cells of ``sources`` of min(dist, cap), and their count."""
    total = 0.0
    n = 0
    h, w = sources.shape
    for r in range(h):
        for c in range(w):
            if sources[r, c]:
                d = float(dist[r, c])
                total += d if d < cap else cap
                n += 1
    return total, n
