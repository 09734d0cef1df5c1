"""Scoring updated maps against the truth, as docs/evaluation.md defines it: observable
and target cells, change detection with one cell of slack, ghosts, the oracle map and APE
statistics. Functions over whole grids and pose arrays; imports only ``gridmap``."""

from .scores import (MIN_OBSERVATIONS, OBSERVATION_RANGE, ObservationCounter, ape_statistics,
                     change_detection, ghost_cells, growth_scores, near, observed_counts,
                     oracle_map, paint_people, scan_hit_counts, wrong_cells)

__all__ = ["MIN_OBSERVATIONS", "OBSERVATION_RANGE", "ObservationCounter", "ape_statistics",
           "change_detection", "ghost_cells", "growth_scores", "near", "observed_counts",
           "oracle_map", "paint_people", "scan_hit_counts", "wrong_cells"]
