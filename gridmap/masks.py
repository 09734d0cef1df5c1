"""Boolean masks over a grid's cells."""

from __future__ import annotations

import numpy as np


def near(mask: np.ndarray) -> np.ndarray:
    """Cells with a True cell within one cell (8-neighbourhood, itself included): ``mask``
    dilated by a 3 x 3 square."""
    out = mask.copy()
    out[1:, :] |= mask[:-1, :]
    out[:-1, :] |= mask[1:, :]
    tmp = out.copy()
    out[:, 1:] |= tmp[:, :-1]
    out[:, :-1] |= tmp[:, 1:]
    return out
