"""The gridmap package as a whole: numba stays out until a kernel runs, and the world <-> cell
conversions are one consistent pair."""

import subprocess
import sys

import numpy as np

from gridmap import OccupancyGrid


def test_public_modules_import_without_numba():
    code = ("import sys, gridmap, gridmap.map_io, gridmap.metrics, gridmap.mapping, "
            "gridmap.raycast\nprint('numba' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_world_cell_round_trip():
    grid = OccupancyGrid.empty(40, 30, 0.05, origin=(-1.03, 2.17))
    rows, cols = np.mgrid[0:30, 0:40]
    x, y = grid.cell_to_world(rows, cols)
    r2, c2 = grid.world_to_cell(x, y)
    assert np.array_equal(r2, rows) and np.array_equal(c2, cols)
    # The corners of a cell belong to it on the low side only.
    assert grid.world_to_cell(-1.03, 2.17) == (0, 0)
    assert grid.world_to_cell(-1.03 + 40 * 0.05 - 1e-9, 2.17) == (0, 39)
    assert not grid.contains(*grid.world_to_cell(-1.03 + 40 * 0.05 + 1e-9, 2.17))
