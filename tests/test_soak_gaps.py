"""The lifelong and soak benchmarks' count of gaps in what stands (``bench_soak.outline_gaps``):
a cell of a wall that a session freed is a gap only where M_i keeps no occupied cell beside it."""

from __future__ import annotations

import numpy as np

from gridmap import FREE, OCCUPIED

from benchmarks import bench_soak as soak


def test_a_wall_redrawn_a_cell_over_leaves_no_gap_and_a_hole_in_it_does():
    freed = np.zeros((10, 10), bool)
    freed[2:8, 5] = True                 # the truth's wall, column 5, freed along its length
    updated = np.full((10, 10), FREE, np.int8)
    updated[2:8, 4] = OCCUPIED           # ... and drawn in column 4: the same wall a cell over
    assert not soak.outline_gaps(freed, updated).any()
    updated[3:7, 4] = FREE               # column 4 kept only at rows 2 and 7
    gaps = soak.outline_gaps(freed, updated)
    # rows 3 and 6 of column 5 touch rows 2 and 7 of column 4 diagonally; rows 4 and 5 do not
    assert sorted(zip(*np.nonzero(gaps))) == [(4, 5), (5, 5)]
    assert not (gaps & ~freed).any()     # only freed cells count
