"""Map quality metrics of docs/evaluation.md, all in percent (100 = identical maps).

Cells are read as probabilities: free 0 -> 0.0, occupied 100 -> 1.0, unknown -1 -> 0.5 (graded
values 1..99 -> v / 100). Every function takes two :class:`OccupancyGrid` s in the same frame, or
two integer arrays of the same shape.

- :func:`cross_correlation`: ``100 (<MN> - <M><N>) / (sigma_M sigma_N)`` over all cells.
- :func:`map_score`: ``100 (1 - mean((m - n)^2))`` over cells occupied in either map.
- :func:`opdf`: occupied picture-distance function, the mean of both directions of
  ``100 (1 - sum(min(d, r)) / (n_occ r))`` with d the Manhattan distance [cells] to the other
  map's nearest occupied cell and r the diagonal of the search window.
"""

from __future__ import annotations

import math

import numpy as np

from .cells import OCCUPIED, UNKNOWN
from .types import GridError, OccupancyGrid


def cross_correlation(a, b) -> float:
    """Cross-correlation [%] of two maps; raises :class:`GridError` when either map is uniform
    (zero standard deviation), where it is undefined."""
    return _cross_correlation(*(_probabilities(x) for x in _cells(a, b)))


def map_score(a, b) -> float:
    """Map score [%] over the cells occupied in at least one of the maps; 100 when neither map
    has an occupied cell (nothing to disagree on)."""
    return _map_score(*(_probabilities(x) for x in _cells(a, b)))


def opdf(a, b, window=(20, 20)) -> float:
    """Occupied picture-distance function [%]: the mean of :func:`opdf_one_way` both ways."""
    ca, cb = _cells(a, b)
    occ_a, occ_b = ca == OCCUPIED, cb == OCCUPIED
    cap = _cap(window)
    return 0.5 * (_opdf_one_way(occ_a, occ_b, cap) + _opdf_one_way(occ_b, occ_a, cap))


def opdf_one_way(a, b, window=(20, 20)) -> float:
    """OPDF_as(A, B) [%]: how close each occupied cell of ``a`` lies to an occupied cell of
    ``b``, distances capped at the window diagonal ``sqrt(w^2 + h^2)`` [cells]. 100 when ``a``
    has no occupied cell; 0 when ``b`` has none and ``a`` has some."""
    ca, cb = _cells(a, b)
    return _opdf_one_way(ca == OCCUPIED, cb == OCCUPIED, _cap(window))


def taxicab_distance(occupied) -> np.ndarray:
    """Manhattan distance [cells] from every cell to the nearest True cell (int32); height +
    width everywhere when there is none."""
    occupied = np.ascontiguousarray(occupied, dtype=np.bool_)
    if occupied.ndim != 2:
        raise GridError(f"distance transform needs a 2D array, got shape {occupied.shape}")
    from . import _metrics_kernels as k  # numba only when a metric is computed

    out = np.empty(occupied.shape, np.int32)
    k.taxicab_distance(occupied, out)
    return out


def compare_maps(a, b, window=(20, 20)) -> dict[str, float]:
    """The three metrics of ``a`` against ``b``: ``{"cc": ..., "ms": ..., "opdf": ...}`` [%]."""
    ca, cb = _cells(a, b)
    m, n = _probabilities(ca), _probabilities(cb)
    occ_a, occ_b = ca == OCCUPIED, cb == OCCUPIED
    cap = _cap(window)
    return {"cc": _cross_correlation(m, n), "ms": _map_score(m, n),
            "opdf": 0.5 * (_opdf_one_way(occ_a, occ_b, cap) + _opdf_one_way(occ_b, occ_a, cap))}


# --- helpers -----------------------------------------------------------------------------------

def _cross_correlation(m: np.ndarray, n: np.ndarray) -> float:
    sm, sn = m.std(), n.std()
    if sm == 0.0 or sn == 0.0:
        which = "first" if sm == 0.0 else "second"
        raise GridError(f"cross-correlation is undefined: every cell of the {which} map has the "
                        "same value (standard deviation 0)")
    # (m * n).mean() rather than a BLAS dot: BLAS threads cost milliseconds on a busy machine.
    return float(100.0 * ((m * n).mean() - m.mean() * n.mean()) / (sm * sn))


def _map_score(m: np.ndarray, n: np.ndarray) -> float:
    either = (m == 1.0) | (n == 1.0)
    if not either.any():
        return 100.0
    return float(100.0 * (1.0 - np.mean((m[either] - n[either]) ** 2)))


def _opdf_one_way(occ_a: np.ndarray, occ_b: np.ndarray, cap: float) -> float:
    from . import _metrics_kernels as k

    if not occ_a.any():
        return 100.0
    if not occ_b.any():
        return 0.0  # every d = r
    dist = taxicab_distance(occ_b)
    total, n = k.capped_distance_sum(occ_a, dist, cap)
    return float(100.0 * (1.0 - total / (n * cap)))


def _cap(window) -> float:
    try:
        w, h = (float(v) for v in window)
    except (TypeError, ValueError):
        raise GridError(f"OPDF window must be (width, height) in cells, got {window!r}") from None
    if not (w > 0 and h > 0 and math.isfinite(w) and math.isfinite(h)):
        raise GridError(f"OPDF window must be positive, got {window!r}")
    return math.hypot(w, h)


def _cells(a, b) -> tuple[np.ndarray, np.ndarray]:
    """The cell arrays of two maps, after checking they can be compared cell by cell."""
    if isinstance(a, OccupancyGrid) and isinstance(b, OccupancyGrid):
        if abs(a.resolution - b.resolution) > 1e-9 * max(a.resolution, b.resolution):
            raise GridError(f"maps have different resolutions: {a.resolution} and {b.resolution} m")
        tol = 1e-3 * a.resolution
        if abs(a.origin[0] - b.origin[0]) > tol or abs(a.origin[1] - b.origin[1]) > tol:
            raise GridError(f"maps have different origins: {a.origin} and {b.origin}")
    ca, cb = _as_cells(a, "first"), _as_cells(b, "second")
    if ca.shape != cb.shape:
        raise GridError(f"maps have different shapes: {ca.shape} and {cb.shape} (rows, cols)")
    return ca, cb


def _as_cells(x, which: str) -> np.ndarray:
    d = x.data if isinstance(x, OccupancyGrid) else np.asarray(x)
    if d.ndim != 2 or d.size == 0:
        raise GridError(f"the {which} map must be a non-empty 2D grid, got shape {d.shape}")
    if d.dtype != np.int8:
        if not np.issubdtype(d.dtype, np.integer):
            raise GridError(f"the {which} map must hold integer cells, got dtype {d.dtype}")
        if d.min() < UNKNOWN or d.max() > OCCUPIED:
            raise GridError(f"the {which} map has cells outside -1..100")
        d = d.astype(np.int8)
    return d


# Probability of every int8 cell value, indexed by the value's byte (-1 is byte 255).
_PROBABILITY = np.full(256, 0.5)
_PROBABILITY[:101] = np.arange(101) / 100.0


def _probabilities(cells: np.ndarray) -> np.ndarray:
    """Free 0.0, occupied 1.0, graded v / 100, unknown (any negative value) 0.5."""
    return _PROBABILITY[cells.view(np.uint8)]
