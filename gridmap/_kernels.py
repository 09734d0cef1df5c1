"""numba kernels of the grid: exact traversal and first hit along beams.

Everything here works in grid units: a point (gx, gy) = ((x - ox) / res, (y - oy) / res), so
cell (row, col) = (floor(gy), floor(gx)). Kernels take arrays and scalars only. Other packages'
kernels call ``traverse`` and ``first_hit`` from inside their own njit functions.
"""

import numpy as np
from numba import njit

from .cells import FREE, OCCUPIED

# Status codes of first_hit.
NO_HIT = 0       # nothing blocking within max length
HIT = 1          # entered a blocking cell at distance t
LEFT_GRID = 2    # left the grid at distance t without hitting


@njit(cache=True)
def clip_to_box(gx0, gy0, dx, dy, width, height):
    """Liang-Barsky: the parameter range [t0, t1] within [0, 1] of p0 + t*d inside the box
    [0, width] x [0, height]; t0 > t1 when the segment misses it."""
    t0 = 0.0
    t1 = 1.0
    ps = (-dx, dx, -dy, dy)
    qs = (gx0, width - gx0, gy0, height - gy0)
    for k in range(4):
        p = ps[k]
        q = qs[k]
        if p == 0.0:
            if q < 0.0:
                return 1.0, 0.0
        else:
            t = q / p
            if p < 0.0:
                if t > t0:
                    t0 = t
            else:
                if t < t1:
                    t1 = t
    return t0, t1


@njit(cache=True)
def _cell_of(v, n):
    c = int(np.floor(v))
    if c < 0:
        return 0
    if c >= n:
        return n - 1
    return c


@njit(cache=True)
def _axis_step(c, g0, d):
    """One axis of the grid walk (Amanatides and Woo) from g0 in cell c along d: (step, the
    parameter between two crossings of that axis's cell edges, the parameter of the first)."""
    step = 1 if d > 0 else -1
    if d == 0.0:
        return step, np.inf, np.inf
    t_max = ((c + 1 - g0) / d) if d > 0 else ((c - g0) / d)
    return step, abs(1.0 / d), t_max


@njit(cache=True)
def _clipped_end_cells(gx0, gy0, gx1, gy1, t0, t1, height, width):
    """(cx, cy, ex, ey): the cells where the segment, clipped to [t0, t1], enters and leaves
    the grid. An end point inside the grid is used as given: gx0 + 1.0 * (gx1 - gx0) can round
    to the other side of a cell edge and lose the end cell."""
    dx = gx1 - gx0
    dy = gy1 - gy0
    if t0 > 0.0:
        cx = _cell_of(gx0 + t0 * dx, width)
        cy = _cell_of(gy0 + t0 * dy, height)
    else:
        cx = _cell_of(gx0, width)
        cy = _cell_of(gy0, height)
    if t1 < 1.0:
        ex = _cell_of(gx0 + t1 * dx, width)
        ey = _cell_of(gy0 + t1 * dy, height)
    else:
        ex = _cell_of(gx1, width)
        ey = _cell_of(gy1, height)
    return cx, cy, ex, ey


@njit(cache=True)
def segment_start(gx0, gy0, gx1, gy1, height, width):
    """Where ``traverse`` starts: (cx, cy, n_x, n_y, step_x, step_y, t_delta_x, t_delta_y,
    t_max_x, t_max_y), the first cell, the unit steps left to take along x and along y to the
    end cell, and the walk's state (Amanatides and Woo); n_x = -1 when the segment misses the
    grid. Kernels that do their own work per cell start from here and step as ``traverse``
    does, so they visit the very same cells."""
    dx = gx1 - gx0
    dy = gy1 - gy0
    t0, t1 = clip_to_box(gx0, gy0, dx, dy, float(width), float(height))
    if t0 > t1:
        return 0, 0, -1, 0, 1, 1, np.inf, np.inf, np.inf, np.inf
    cx, cy, ex, ey = _clipped_end_cells(gx0, gy0, gx1, gy1, t0, t1, height, width)
    step_x, t_delta_x, t_max_x = _axis_step(cx, gx0, dx)
    step_y, t_delta_y, t_max_y = _axis_step(cy, gy0, dy)
    return (cx, cy, abs(ex - cx), abs(ey - cy), step_x, step_y, t_delta_x, t_delta_y, t_max_x,
            t_max_y)


@njit(cache=True)
def traverse(gx0, gy0, gx1, gy1, height, width, rows, cols):
    """Every cell the segment (gx0, gy0)-(gx1, gy1) passes through, in order from the start,
    clipped to the grid. Writes into ``rows``/``cols`` and returns the count (at most their
    length). The walk is 4-connected: where the segment crosses a cell corner exactly, the cell
    beside the corner in x comes first, so no cell is skipped."""
    cx, cy, n_x, n_y, step_x, step_y, t_delta_x, t_delta_y, t_max_x, t_max_y = \
        segment_start(gx0, gy0, gx1, gy1, height, width)
    # Exactly n_x + n_y unit steps lead to the end cell; counting them (rather than testing t
    # against the end) keeps the walk from overshooting through rounding.
    cap = rows.shape[0]
    if n_x < 0 or cap == 0:
        return 0
    rows[0] = cy
    cols[0] = cx
    n = 1
    for _ in range(n_x + n_y):
        if n >= cap:
            break
        go_x = n_x > 0 and (n_y == 0 or t_max_x <= t_max_y)
        if go_x:
            cx += step_x
            t_max_x += t_delta_x
            n_x -= 1
        else:
            cy += step_y
            t_max_y += t_delta_y
            n_y -= 1
        rows[n] = cy
        cols[n] = cx
        n += 1
    return n


@njit(cache=True)
def is_blocking(v, block_unknown):
    return v == OCCUPIED or (block_unknown and v < 0)


@njit(cache=True)
def first_hit(data, gx0, gy0, cos_a, sin_a, max_len, block_unknown):
    """Walk from (gx0, gy0) along the unit direction (cos_a, sin_a) for at most ``max_len`` grid
    units. Returns (t, status): the distance to where the ray enters the first blocking cell
    (status HIT; 0 if it starts in one), or to where it leaves the grid (LEFT_GRID; 0 if it
    starts outside and unknown blocks), or (max_len, NO_HIT)."""
    height = data.shape[0]
    width = data.shape[1]
    if block_unknown and not (0.0 <= gx0 < width and 0.0 <= gy0 < height):
        return 0.0, LEFT_GRID  # outside the map is unknown, so it blocks at once
    # Enter the grid if the start lies outside it.
    t0, t1 = clip_to_box(gx0, gy0, cos_a * max_len, sin_a * max_len, float(width), float(height))
    if t0 > t1:
        return max_len, NO_HIT
    t, t_end, t_safe, cx, cy, step_x, step_y, t_delta_x, t_delta_y, t_max_x, t_max_y = \
        _walk_start(gx0, gy0, cos_a, sin_a, t0, t1, max_len, width, height)
    # While the next crossing lies safely before both the grid exit and max_len, the next cell
    # is inside the grid, so this loop, which takes nearly all of a cast's steps, skips the
    # bounds checks.
    while True:
        if is_blocking(data[cy, cx], block_unknown):
            return t, HIT
        done, t, cx, cy, t_max_x, t_max_y = _safe_step(t, cx, cy, t_max_x, t_max_y, step_x,
                                                      step_y, t_delta_x, t_delta_y, t_safe)
        if done:
            break
    return _last_steps(data, cx, cy, t, t_max_x, t_max_y, step_x, step_y, t_delta_x,
                       t_delta_y, t_end, max_len, block_unknown)


@njit(cache=True, inline="always")
def _walk_start(gx0, gy0, cos_a, sin_a, t0, t1, max_len, width, height):
    """Where a walk (Amanatides and Woo) along the beam clipped to the grid, [t0, t1] of
    ``max_len``, starts: (t, t_end, t_safe, cx, cy, step_x, step_y, t_delta_x, t_delta_y,
    t_max_x, t_max_y). Before ``t_safe`` every crossing lies inside the grid and short of
    ``max_len`` (``_safe_step``)."""
    t = t0 * max_len
    t_end = t1 * max_len
    cx = _cell_of(gx0 + t * cos_a, width)
    cy = _cell_of(gy0 + t * sin_a, height)
    step_x, t_delta_x, t_max_x = _axis_step(cx, gx0, cos_a)
    step_y, t_delta_y, t_max_y = _axis_step(cy, gy0, sin_a)
    t_safe = min(t_end, max_len) - 1e-6
    return t, t_end, t_safe, cx, cy, step_x, step_y, t_delta_x, t_delta_y, t_max_x, t_max_y


@njit(cache=True, inline="always")
def _safe_step(t, cx, cy, t_max_x, t_max_y, step_x, step_y, t_delta_x, t_delta_y, t_safe):
    """The walk's step into the next cell, with no bounds check: (done, t, cx, cy, t_max_x,
    t_max_y), ``done`` and the walk unchanged when the next crossing is at ``t_safe`` or past
    it (``_last_steps`` takes the walk from there)."""
    if t_max_x <= t_max_y:
        if t_max_x >= t_safe:
            return True, t, cx, cy, t_max_x, t_max_y
        return False, t_max_x, cx + step_x, cy, t_max_x + t_delta_x, t_max_y
    if t_max_y >= t_safe:
        return True, t, cx, cy, t_max_x, t_max_y
    return False, t_max_y, cx, cy + step_y, t_max_x, t_max_y + t_delta_y


@njit(cache=True, inline="always")
def _last_steps(data, cx, cy, t, t_max_x, t_max_y, step_x, step_y, t_delta_x, t_delta_y,
                t_end, max_len, block_unknown):
    """The end of ``first_hit``'s walk: the last cell or two before the grid's exit or
    max_len, with every check."""
    height = data.shape[0]
    width = data.shape[1]
    while True:
        if t_max_x <= t_max_y:
            t = t_max_x
            cx += step_x
            t_max_x += t_delta_x
        else:
            t = t_max_y
            cy += step_y
            t_max_y += t_delta_y
        if t > max_len:
            return max_len, NO_HIT
        if cx < 0 or cx >= width or cy < 0 or cy >= height or t > t_end + 1e-9:
            return t, LEFT_GRID
        if is_blocking(data[cy, cx], block_unknown):
            return t, HIT


# --- clear blocks: free space crossed in one jump -------------------------------------------
# A walk through free space needs no look at each cell: where a square of blocks around the
# walk's cell holds only free cells, ``steps_to`` moves the walk to the square's edge at once.


@njit(cache=True)
def clear_blocks(data, shift, out):
    """Per block of 2**shift x 2**shift cells of ``data`` (``out``: one row per block row,
    the last one partial when the size does not divide the map's): the Chebyshev distance in
    blocks to the nearest block that is not clear, at most 255. A block is clear when it lies
    whole on the map (outside is unknown) and all its cells are free, so every block less than
    out[b] blocks from b is clear (0: b is not)."""
    height, width = data.shape
    bh, bw = out.shape
    size = 1 << shift
    for by in range(bh):
        for bx in range(bw):
            out[by, bx] = min(by + 1, bx + 1, bh - by, bw - bx, 255)
            if (by + 1) * size > height or (bx + 1) * size > width:
                out[by, bx] = 0
    for r in range(height):
        for c in range(width):
            if data[r, c] != FREE:
                out[r >> shift, c >> shift] = 0
    # two passes of the 3 x 3 chamfer: exact for the Chebyshev distance
    for by in range(bh):
        for bx in range(bw):
            v = out[by, bx]
            for dy, dx in ((-1, -1), (-1, 0), (-1, 1), (0, -1)):
                y, x = by + dy, bx + dx
                if 0 <= y and 0 <= x < bw:
                    v = min(v, out[y, x] + 1)
            out[by, bx] = v
    for by in range(bh - 1, -1, -1):
        for bx in range(bw - 1, -1, -1):
            v = out[by, bx]
            for dy, dx in ((1, 1), (1, 0), (1, -1), (0, 1)):
                y, x = by + dy, bx + dx
                if y < bh and 0 <= x < bw:
                    v = min(v, out[y, x] + 1)
            out[by, bx] = v


@njit(cache=True, inline="always")
def clear_exit(clear, shift, cx, cy, gx0, gy0, step_x, step_y, t_delta_x, t_delta_y):
    """The parameter at which a walk from (gx0, gy0) (unit steps ``step_x``, ``step_y``; the
    parameter between two edges ``t_delta_x``, ``t_delta_y``) leaves the square of clear
    blocks (``clear_blocks``) centred on the block of cell (cx, cy): every cell it enters
    before then is free. -1 when that block is not clear."""
    k = np.int64(clear[cy >> shift, cx >> shift])
    if k == 0:
        return -1.0
    bx = cx >> shift
    by = cy >> shift
    ex = (((bx + k) << shift) - gx0) if step_x > 0 else (gx0 - ((bx - k + 1) << shift))
    ey = (((by + k) << shift) - gy0) if step_y > 0 else (gy0 - ((by - k + 1) << shift))
    tx = ex * t_delta_x if t_delta_x < np.inf else np.inf
    ty = ey * t_delta_y if t_delta_y < np.inf else np.inf
    return min(tx, ty)


@njit(cache=True, inline="always")
def steps_to(p, t_max_x, t_max_y, t_delta_x, t_delta_y):
    """(kx, ky): the unit steps along x and along y that take a walk (Amanatides and Woo,
    next edges at ``t_max_x``, ``t_max_y``) to parameter p: the x edges at or before p and the
    y edges before p, the walk's own order where two tie, counted at once. The walk's next
    edges are then t_max + k * t_delta, which can differ in the last bits from the sum that
    stepping accumulates."""
    kx = int((p - t_max_x) / t_delta_x) + 1 if t_max_x <= p else 0
    ky = int((p - t_max_y) / t_delta_y) + 1 if t_max_y < p else 0
    return kx, ky


@njit(cache=True)
def first_blocked(data, clear, shift, gx0, gy0, cos_a, sin_a, max_len):
    """``first_hit`` with unknown blocking (the map's outside too), jumping across squares
    of clear blocks (``clear_blocks(data, shift, clear)``) instead of stepping through their
    cells: the same blocking cell, its distance equal up to rounding in the last bits. Its
    steps between the jumps are ``first_hit``'s (``_walk_start``, ``_safe_step``), in a loop of
    its own so that ``first_hit`` (the simulator's and the localiser's casts) keeps one with no
    block lookups. The blocks are looked up where the cast starts and wherever a jump lands,
    and no more once one is not clear: a lookup that finds nothing costs a few steps (a branch
    the processor cannot foresee), and a cast through clutter would pay for many."""
    height = data.shape[0]
    width = data.shape[1]
    if not (0.0 <= gx0 < width and 0.0 <= gy0 < height):
        return 0.0, LEFT_GRID
    t0, t1 = clip_to_box(gx0, gy0, cos_a * max_len, sin_a * max_len, float(width), float(height))
    t, t_end, t_safe, cx, cy, step_x, step_y, t_delta_x, t_delta_y, t_max_x, t_max_y = \
        _walk_start(gx0, gy0, cos_a, sin_a, t0, t1, max_len, width, height)
    looking = True
    while True:
        if data[cy, cx] != FREE:
            return t, HIT
        # a jump taken when it crosses a few cells at least, with a margin inside the
        # square: the jump's closed-form sums may round either way
        if looking:
            p = min(clear_exit(clear, shift, cx, cy, gx0, gy0, step_x, step_y, t_delta_x,
                               t_delta_y), t_safe) - 1e-6
            looking = p > t + 6.0
            if looking:     # and look again from where it lands
                kx, ky = steps_to(p, t_max_x, t_max_y, t_delta_x, t_delta_y)
                if kx > 0:
                    t = max(t, t_max_x + (kx - 1) * t_delta_x)
                    t_max_x += kx * t_delta_x
                    cx += kx * step_x
                if ky > 0:
                    t = max(t, t_max_y + (ky - 1) * t_delta_y)
                    t_max_y += ky * t_delta_y
                    cy += ky * step_y
        done, t, cx, cy, t_max_x, t_max_y = _safe_step(t, cx, cy, t_max_x, t_max_y, step_x,
                                                      step_y, t_delta_x, t_delta_y, t_safe)
        if done:
            break
    return _last_steps(data, cx, cy, t, t_max_x, t_max_y, step_x, step_y, t_delta_x,
                       t_delta_y, t_end, max_len, True)


@njit(cache=True)
def cast_ranges(data, sensor, angles, max_len, block_unknown, res, out):
    """Expected ranges [m] of beams from sensor = (gx, gy, heading [rad]) at ``angles``
    relative to the heading: ``first_hit`` scaled by ``res``, inf where nothing blocks (a beam
    leaving the grid is blocked there only when unknown blocks). Doing the whole conversion
    here saves the wrapper several array passes per scan."""
    for i in range(angles.shape[0]):
        a = sensor[2] + angles[i]
        t, s = first_hit(data, sensor[0], sensor[1], np.cos(a), np.sin(a), max_len,
                         block_unknown)
        if s == HIT or (s == LEFT_GRID and block_unknown):
            out[i] = t * res
        else:
            out[i] = np.inf


@njit(cache=True)
def find_root(parent, k):
    """Union-find: the root of ``k`` in ``parent``, halving the path on the way."""
    while parent[k] != k:
        parent[k] = parent[parent[k]]
        k = parent[k]
    return k
