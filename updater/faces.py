"""The counts of the faces rule (``UpdaterConfig.move_faces``; the kernels are ``_faces``): per
cell, the processed scans whose beams ended in it, those whose beams crossed it just before
their hit, and those whose beams ended just before it. They belong to the world's cells, not to a map, so they go on from one session to the
next (``MapUpdater.carried_faces``, ``MapUpdater(..., faces=)``), halved at each new session:
a face that one session sees only a few times is moved once a few sessions have seen it so.
With ``face_sessions`` 2 a cell is freed, or drawn in front of a wall or rack, only when the
rule would have done so at the end of the last session too (``confirmed``): what a single
session saw, a pose a few centimetres off along a whole recording, frees nothing and thickens
no wall; ``face_draw_sessions`` 2 asks the same of a draw beside an object.
Three bytes per cell once a scan has counted, none before (the rule off, or only poses
taken as given); bounded, however many sessions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gridmap.cells import OCCUPIED

from .config import UpdaterConfig, UpdaterError
from .steps import kernels


# the arrays a state file holds, by their names there; face_crossed since the crossed plane
STATE_KEYS = ("face_hits", "face_passes", "face_behind", "face_now", "face_confirmed",
              "face_crossed")


@dataclass
class FaceCounts:
    hits: np.ndarray       # uint8 (H, W): scans whose beams ended in the cell (saturating)
    passes: np.ndarray     # uint8 (H, W): scans whose beams crossed it before their hit
    behind: np.ndarray     # uint8 (H, W): scans whose beams ended just before it
    # bit plane of the cells this session's beams ended in: the session's own, never carried
    # (None: none yet)
    now: np.ndarray | None = None
    # bit plane of the cells the rule would have moved at the end of the last session (None:
    # none): with face_sessions 2 a cell is freed or drawn in front of a wall, with
    # face_draw_sessions 2 drawn beside an object, only when two sessions in a row agree
    confirmed: np.ndarray | None = None
    # bit plane of the cells this session's steep beams crossed (counted in ``passes``): the
    # session's own, never carried; a cell is freed only when crossed this session too
    crossed: np.ndarray | None = None

    @classmethod
    def start(cls, shape: tuple[int, int], on: bool, carried: FaceCounts | None
              ) -> FaceCounts:
        """The counts a session starts from: ``carried`` (checked against the map's shape),
        or none yet, made at the first scan that counts (``count``): a session whose scans
        never count (the rule off, or poses taken as given) holds no byte of them."""
        empty = cls(*(np.zeros((0, 0), np.uint8) for _ in range(3)))
        if not on:
            return empty
        if carried is not None and not isinstance(carried, FaceCounts):
            raise UpdaterError(f"faces must be a FaceCounts, got {type(carried).__name__}")
        if carried is None or carried.hits.size == 0:
            empty._shape = tuple(shape)
            return empty
        for name in ("hits", "passes", "behind"):
            a = getattr(carried, name)
            if not isinstance(a, np.ndarray) or a.shape != tuple(shape) or a.dtype != np.uint8:
                raise UpdaterError(f"the face counts' {name} do not fit the map: "
                                   f"{getattr(a, 'shape', None)} {getattr(a, 'dtype', None)}, "
                                   f"the map is {tuple(shape)}, uint8 expected")
        return cls(carried.hits.copy(), carried.passes.copy(), carried.behind.copy(),
                   *(None if a is None else a.copy()
                     for a in (carried.now, carried.confirmed, carried.crossed)))

    @classmethod
    def from_state(cls, arrays: dict) -> FaceCounts | None:
        """The counts of a state file's ``arrays`` (by ``STATE_KEYS``, None where the file has
        none): None for a state saved before the faces rule; one saved before the crossed
        plane has no crossing of its session yet (a cell is freed once crossed again)."""
        if any(arrays[k] is None for k in STATE_KEYS[:5]):
            return None
        return cls(*(arrays[k] for k in STATE_KEYS))

    def state_arrays(self) -> dict:
        """The arrays ``from_state`` reads, by their names in a state file."""
        return dict(zip(STATE_KEYS, (self.hits, self.passes, self.behind, self.now,
                                     self.confirmed, self.crossed)))

    def __post_init__(self):
        self._shape = self.hits.shape
        self._scratch(self.hits.shape)

    def _scratch(self, shape) -> None:
        n = int(np.prod(shape)) if self.hits.size else 0
        self._marks = np.zeros((n + 7) // 8, np.uint8)
        if self.now is None or self.now.shape != self._marks.shape:
            self.now = np.zeros((n + 7) // 8, np.uint8)
        if self.confirmed is None or self.confirmed.shape != self._marks.shape:
            self.confirmed = np.zeros((n + 7) // 8, np.uint8)
        if self.crossed is None or self.crossed.shape != self._marks.shape:
            self.crossed = np.zeros((n + 7) // 8, np.uint8)
        self.candidates = np.zeros((n + 7) // 8, np.uint8)
        self._listed = np.zeros(0, np.int64)

    @property
    def nbytes(self) -> int:
        return self.hits.nbytes + self.passes.nbytes + self.behind.nbytes + \
            self._marks.nbytes + self.now.nbytes + self.confirmed.nbytes + \
            self.crossed.nbytes + self.candidates.nbytes + self._listed.nbytes

    @property
    def cells(self) -> int:
        """Cells with a count."""
        if self.hits.size == 0:
            return 0
        return int(np.count_nonzero(self.hits | self.passes | self.behind))

    def count(self, ws, sensor: np.ndarray, cfg: UpdaterConfig) -> None:
        """A processed scan's beams (``ws.hits``, as the classifier left them) at ``sensor``."""
        if self.hits.size == 0:                 # the session's first scan that counts
            self.hits, self.passes, self.behind = (np.zeros(self._shape, np.uint8)
                                                   for _ in range(3))
            self.now = self.confirmed = self.crossed = None
            self._scratch(self._shape)
        n = ws.hits.shape[0]
        room = n * (2 * kernels().STEPS_PER_CELL * cfg.face_band + 1)
        if self._listed.size < room:
            self._listed = np.zeros(room, np.int64)
        kernels().count_faces(ws.hits, sensor, cfg.face_band, cfg.face_min_sine, self.hits,
                              self.passes, self.behind, self._marks, self._listed, self.now,
                              self.crossed)

    def move(self, ref: np.ndarray, out: np.ndarray, cfg: UpdaterConfig,
             res: float) -> tuple[int, int]:
        """``out`` (the output cells) with the faces moved; (cells freed, cells drawn). The
        cells the rule would move are left in ``candidates``."""
        if self.hits.size == 0:                 # nothing counted: nothing to move
            return 0, 0
        if getattr(self, "_small", None) is None:       # once per reference map
            self._small = small_structure_bits(ref, cfg.face_max_area, res)
        planes = (self.now, self.crossed, self.confirmed, self.candidates, self._small)
        return kernels().move_faces(ref, out, (self.hits, self.passes, self.behind), planes,
                                    cfg.face_band, cfg.face_min_passes, cfg.face_free_ratio,
                                    cfg.face_min_hits, cfg.face_draw_ratio,
                                    (cfg.face_sessions > 1, cfg.face_draw_sessions > 1,
                                     cfg.face_sessions > 1),
                                    cfg.face_draw_beside_large,
                                    cfg.face_large_min_hits)

    def decayed(self) -> FaceCounts:
        """What a new session starts from: the counts halved, and the cells the rule would
        move now (``candidates``, as the last ``move`` left them) as ``confirmed``."""
        return FaceCounts(self.hits >> np.uint8(1), self.passes >> np.uint8(1),
                          self.behind >> np.uint8(1), None, self.candidates.copy())


def small_structure_bits(ref: np.ndarray, max_area: float, res: float) -> np.ndarray:
    """A bit plane of the occupied cells of ``ref`` in 8-connected structures of at most
    ``max_area`` [m^2] of cells (``_faces.small_structures``)."""
    max_cells = int(np.floor(max_area / res**2 + 1e-9))
    n_bytes = (ref.size + 7) // 8
    small, seen = np.zeros(n_bytes, np.uint8), np.zeros(n_bytes, np.uint8)
    stack = np.zeros(max(1, int(np.count_nonzero(ref == OCCUPIED))), np.int64)
    kernels().small_structures(ref, max_cells, small, seen, stack,
                               np.zeros(max_cells + 1, np.int64))
    return small
