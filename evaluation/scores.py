"""Scores of a session, as docs/evaluation.md defines them: observable and target cells,
change detection with one cell of slack, ghosts, the oracle map and APE statistics.

Every function takes whole grids (int8, ROS convention) or pose arrays and returns numbers;
nothing here knows about the simulator.
"""

from __future__ import annotations

import math

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, GridError, OccupancyGrid, Pose2D
from gridmap.masks import near

OBSERVATION_RANGE = 10.0  # [m] beams observe cells up to this distance
MIN_OBSERVATIONS = 7      # the updater's decision threshold T


def _cells(m) -> np.ndarray:
    return m.data if isinstance(m, OccupancyGrid) else np.asarray(m)


class ObservationCounter:
    """Counts, per cell, the scans whose beams hit or pass through it within ``max_range``."""

    def __init__(self, frame: OccupancyGrid, max_range: float = OBSERVATION_RANGE):
        self.frame = frame
        self.max_range = max_range
        self.counts = np.zeros(frame.shape, np.int32)
        self._stamp = np.full(frame.shape, -1, np.int64)
        self._scans = 0
        cap = 4 * int(max_range / frame.resolution) + 8
        self._rows = np.empty(cap, np.int64)
        self._cols = np.empty(cap, np.int64)

    def add_scan(self, sensor_pose: Pose2D, ranges: np.ndarray, angles: np.ndarray) -> None:
        """One noise-free scan; ``inf`` ranges pass through up to ``max_range``."""
        from . import _kernels

        r = np.minimum(np.where(np.isfinite(ranges), ranges, np.inf), self.max_range)
        a = np.asarray(angles, np.float64) + sensor_pose.theta
        res = self.frame.resolution
        ox, oy = self.frame.origin
        gx0, gy0 = (sensor_pose.x - ox) / res, (sensor_pose.y - oy) / res
        end_gx = gx0 + r * np.cos(a) / res
        end_gy = gy0 + r * np.sin(a) / res
        _kernels.count_observations(self.counts, self._stamp, scan_id=self._scans, gx0=gx0,
                                    gy0=gy0, end_gx=end_gx, end_gy=end_gy, rows=self._rows,
                                    cols=self._cols)
        self._scans += 1

    def observable(self, min_scans: int = MIN_OBSERVATIONS) -> np.ndarray:
        return self.counts >= min_scans


def observed_counts(frame: OccupancyGrid, placed, max_range: float) -> np.ndarray:
    """Per cell of ``frame``, how many of the scans ``placed`` ((scan, sensor pose) pairs) hit
    it or see through it with a valid beam (finite, at or past the scan's range_min, short of
    its range_max and of ``max_range``)."""
    counter = ObservationCounter(frame, max_range=max_range)
    for scan, sensor in placed:
        r = scan.ranges.astype(np.float64)
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(r) & (r >= scan.range_min) & (r < min(scan.range_max, max_range))
        counter.add_scan(sensor, np.where(valid, r, 0.0), scan.angles())
    return counter.counts


def scan_hit_counts(frame: OccupancyGrid, placed, max_range: float) -> np.ndarray:
    """Per cell of ``frame``, how many of the scans ``placed`` ((scan, sensor pose) pairs) have
    a valid beam (as ``observed_counts`` takes them) ending in it."""
    counts = np.zeros(frame.data.size, np.int32)
    for scan, sensor in placed:
        r = scan.ranges.astype(np.float64)
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(r) & (r >= scan.range_min) & (r < min(scan.range_max, max_range))
        a = scan.angles()[valid] + sensor.theta
        rows, cols = frame.world_to_cell(sensor.x + r[valid] * np.cos(a),
                                         sensor.y + r[valid] * np.sin(a))
        inside = frame.contains(rows, cols)
        counts[np.unique(rows[inside] * frame.width + cols[inside])] += 1
    return counts.reshape(frame.shape)


def paint_people(mask: np.ndarray, frame: OccupancyGrid, people: np.ndarray) -> None:
    """Mark in ``mask`` the cells covered by people given as rows (x, y, radius) [m]."""
    if len(people) == 0:
        return
    from . import _kernels

    p = np.asarray(people, np.float64)
    res = frame.resolution
    _kernels.paint_discs(mask, (p[:, 0] - frame.origin[0]) / res,
                         (p[:, 1] - frame.origin[1]) / res, p[:, 2] / res)


def wrong_cells(previous, truth) -> tuple[np.ndarray, np.ndarray]:
    """Cells of the previous map that are wrong about the world: (wrongly occupied, wrongly
    free), each with one cell of slack."""
    prev, true = _cells(previous), _cells(truth)
    if prev.shape != true.shape:
        raise GridError(f"maps of shape {prev.shape} and {true.shape} cannot be compared")
    wrong_occ = (prev == OCCUPIED) & (true == FREE) & ~near(true == OCCUPIED)
    wrong_free = (prev == FREE) & (true == OCCUPIED) & ~near(prev == OCCUPIED)
    return wrong_occ, wrong_free


def change_detection(previous, updated, truth, observable: np.ndarray) -> dict:
    """Precision, recall, F1 and recall_all of the changes from ``previous`` to ``updated``."""
    prev, upd, true = _cells(previous), _cells(updated), _cells(truth)
    changed = upd != prev
    to_free = changed & (upd == FREE)
    to_occ = changed & (upd == OCCUPIED)
    correct = (to_free & (true == FREE)) | (to_occ & near(true == OCCUPIED))
    n_changes = int(changed.sum())
    n_correct = int(correct.sum())

    wrong_occ, wrong_free = wrong_cells(prev, true)
    fixed = (wrong_occ & (upd == FREE)) | (wrong_free & near(upd == OCCUPIED))
    wrong = wrong_occ | wrong_free
    targets = wrong & observable
    n_targets, n_wrong = int(targets.sum()), int(wrong.sum())
    precision = n_correct / n_changes if n_changes else None
    recall = int((fixed & targets).sum()) / n_targets if n_targets else None
    recall_all = int((fixed & wrong).sum()) / n_wrong if n_wrong else None
    f1 = (2 * precision * recall / (precision + recall)
          if precision is not None and recall is not None and precision + recall > 0 else None)
    known = int((prev != UNKNOWN).sum())
    return {
        "precision": precision, "recall": recall, "f1": f1, "recall_all": recall_all,
        "changes": n_changes, "correct_changes": n_correct,
        "incorrect_changes": n_changes - n_correct,
        "incorrect_changes_pct_of_known": 100.0 * (n_changes - n_correct) / max(known, 1),
        "target_cells": n_targets, "targets_fixed": int((fixed & targets).sum()),
        "wrong_cells": n_wrong, "observable_cells": int(observable.sum()),
    }


def ghost_cells(updated, truth, people_mask: np.ndarray) -> int:
    """Cells occupied in the updated map, far from every occupied cell of the truth, that a
    person covered at some time."""
    upd, true = _cells(updated), _cells(truth)
    return int(((upd == OCCUPIED) & ~near(true == OCCUPIED) & people_mask).sum())


def oracle_map(previous: OccupancyGrid, truth, observable: np.ndarray) -> OccupancyGrid:
    """The perfect updater's map: the previous map with every target cell set to the truth."""
    wrong_occ, wrong_free = wrong_cells(previous, truth)
    data = previous.data.copy()
    data[wrong_occ & observable] = FREE
    data[wrong_free & observable] = OCCUPIED
    return previous.with_data(data)


def ape_statistics(estimated_xy, true_xy) -> dict:
    """Absolute position error statistics [m], no alignment, as evo reports them."""
    est = np.asarray(estimated_xy, np.float64).reshape(-1, 2)
    true = np.asarray(true_xy, np.float64).reshape(-1, 2)
    if est.shape != true.shape:
        raise ValueError(f"{len(est)} estimated and {len(true)} true positions do not pair up")
    if len(est) == 0:
        return {k: None for k in ("max", "mean", "median", "min", "rmse", "sse", "std")}
    e = np.hypot(*(est - true).T)
    return {
        "max": float(e.max()), "mean": float(e.mean()), "median": float(np.median(e)),
        "min": float(e.min()), "rmse": float(math.sqrt(np.mean(e * e))),
        "sse": float(np.sum(e * e)), "std": float(e.std()),
    }


def growth_scores(before, after, whole, counts: np.ndarray, min_views: int = MIN_OBSERVATIONS,
                  hits: np.ndarray | None = None) -> dict:
    """How an update grew a partial map ``before`` into ``after``, against ``whole`` (a map of
    all of the place), on the cells unknown in ``before``, known in ``whole`` and observed by
    at least ``min_views`` of the update's scans (``counts``, e.g. ``ObservationCounter``):
    the share that became known (``known``) and known right (``agreeing``: free where the
    whole map is free, occupied within one cell of its occupied cells), the share of the
    whole map's surfaces among them drawn (``surfaces_drawn``), and the occupied cells of
    ``before`` freed (``freed``; ``freed_also_in_whole``: of them, occupied in the whole map
    too). With ``hits`` (per cell, the update's scans with a beam ending in it:
    ``scan_hit_counts``), ``walls_freed``: of those, the cells of a structure of the whole map
    (an occupied 8-neighbour there) that the update's scans still hit. The rest are cells the
    whole map has alone amid free cells, or things its first part saw and the update's scans
    see through and never hit, which the whole map, a mixture of both, keeps."""
    b, a, w = _cells(before), _cells(after), _cells(whole)
    unknown = (b == UNKNOWN) & (counts >= min_views) & (w != UNKNOWN)
    out = a[unknown]
    right_free = (out == FREE) & (w[unknown] == FREE)
    right_occupied = (out == OCCUPIED) & near(w == OCCUPIED)[unknown]
    occupied = b == OCCUPIED
    surfaces = w[unknown] == OCCUPIED
    n = int(unknown.sum())
    freed_occupied = occupied & (w == OCCUPIED) & (a == FREE)
    walls = {}
    if hits is not None:
        structure = freed_occupied & (_occupied_neighbours(w == OCCUPIED) > 0)
        walls = {"walls_freed": int((structure & (hits > 0)).sum())}
    return walls | {"cells": n, "known": float((out != UNKNOWN).mean()) if n else math.nan,
            "agreeing": float((right_free | right_occupied).mean()) if n else math.nan,
            "surfaces_drawn": float(right_occupied[surfaces].mean()) if surfaces.any() else 0.0,
            "freed": int((occupied & (a == FREE)).sum()),
            "freed_also_in_whole": int(freed_occupied.sum())}


def _occupied_neighbours(occupied: np.ndarray) -> np.ndarray:
    """Per cell, how many of its 8-neighbours are ``occupied``."""
    p = np.pad(occupied, 1).astype(np.int8)
    h, w = occupied.shape
    return sum(p[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] for dr in (-1, 0, 1) for dc in (-1, 0, 1)
               if dr or dc)
