"""The map updater: a reference map M, per-cell flag buffers, and one call per scan.

State, for an H x W map (nothing else grows with the map):

=================  ==============  ==========================================================
array              bytes per cell  what
=================  ==============  ==========================================================
reference          1               M, int8 (0 free, 100 occupied, -1 unknown), never changed
buffers            2               uint16 shift registers of the last N_b flags
flag counts        0 or 1          flags a cell got (saturating; a settled free cell's stays
                                   at T or past it, a full buffer's of changes at N_b or past
                                   it): above the flags in the buffer (N_b <= 12), else a
                                   uint8 (at 255)
decided            1/8             bit per cell: the decision rule says "changed"
enclosed           1/8             bit per cell: unknown cell of an enclosed region of M
scan marks         2/8             bits per cell, set and cleared within one scan (the
                                   unchanged-flag marks stay set on settled free cells, the
                                   changed-flag marks on buffers full of changes)
hit buffers        2 where used    uint16 shift registers of hits in open unknown space, in
                                   tiles of 64 x 64 cells made where a scan first hits it
drawn, hit marks   2/8             bits per cell: drawn from hits; hit this scan
=================  ==============  ==========================================================

The flag counts are kept only for the unanimous rule (``UpdaterConfig.unanimous_min``). The
last two rows are the growth into the unknown (``UpdaterConfig.grow_into_unknown``; with
it off the hit buffers and hit marks take no room).

A scan touches only the cells its beams reach: the flags of a scan are kept in lists, made
unique with the scan-mark bits (set when a cell is listed, cleared after the push), never by
zeroing a map-sized array.

Bad input: NaN, inf, negative and zero ranges are invalid beams. A non-finite sensor pose,
odometry pose or scan time raises ``UpdaterError`` before anything is changed. A sensor pose
off the map is a counted skip (``ScanReport.status is ScanStatus.OFF_MAP``), and so is a pose
the caller's ``pose_check`` refuses (``ScanStatus.REFUSED``; e.g.
``localization.confidence.PoseCheck``).
"""

from __future__ import annotations

import enum
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from gridmap import GridError, OccupancyGrid, Pose2D, PoseVerdict, Scan, Verdict
from gridmap.atomic import write_atomically
from gridmap.config import DEFAULT_PROFILE
from gridmap.files import FileInputError, check_regular_file

from . import saved_state, steps
from ._arguments import Buffers, MapCells
from .config import UpdaterConfig, UpdaterError
from .faces import STATE_KEYS as FACE_STATE_KEYS, FaceCounts
from .gating import CONFIRMING, DIRECTION_BINS, SKIPPED_OFF_MAP, Gate
from .hit_tiles import HitTiles

# 2: the buffers are saved as held, the flag counts above the flags when they fit there (a
# ``seen`` array otherwise). 1 (still read): the buffers hold the flags alone, ``seen`` the
# counts, when saved at all.
STATE_FORMAT = 2

_SUMMARY_BLOCK = 1 << 20    # cells per block of evidence_summary (a multiple of 8)


class ScanStatus(enum.Enum):
    """What became of a scan given to ``MapUpdater.process``."""

    PROCESSED = "processed"   # classified, flagged, pushed and decided
    LOST = "lost"             # classified, then dropped by the lost check: no flags
    GATED = "gated"           # not processed: the gate (``ScanReport.reason`` says which rule)
    OFF_MAP = "off map"       # not processed: the sensor pose lies off the map
    REFUSED = "refused"       # not processed: the pose check refused the pose


@dataclass(eq=False, slots=True)
class ScanReport:
    """What one call of ``MapUpdater.process`` did. (Slots, and not frozen: a frozen
    dataclass sets each field through ``object.__setattr__``, which took 1.6 µs a report
    against 0.3, for a report made at every scan.)"""

    time: float                    # [s] the scan's time
    status: ScanStatus
    reason: str = ""               # for people: the gate's rule, or the pose check's reason
    valid_beams: int = 0
    detected_changes: int = 0      # beams kept as detected changes by the run filter
    raw_detected_changes: int = 0  # beams the classifier found changed, before the run filter
    # cells that got a changed flag, but for those whose buffers are full of them
    # (docs/algorithm.md, "Changed flags that would change nothing")
    changed_flags: int = 0
    new_obstacle_flags: int = 0    # ... of them, hit cells of new obstacles
    # cells that got an unchanged flag, but for the free cells where one would change nothing
    # (docs/algorithm.md, "Unchanged flags that would change nothing")
    unchanged_flags: int = 0
    changed_cells: int = 0         # cells whose state differs from M, after this scan
    verdicts: np.ndarray | None = None   # a BeamVerdict per beam (int8), None when not classified
    # the sensor pose the scan was placed at: as given, or as the pose check refined it; None
    # when the pose check refused it
    sensor_pose: Pose2D | None = None

    @property
    def processed(self) -> bool:
        """Classified (then flagged, or dropped as lost)."""
        return self.status in (ScanStatus.PROCESSED, ScanStatus.LOST)

    @property
    def dropped_as_lost(self) -> bool:
        return self.status is ScanStatus.LOST

    def summary(self) -> dict:
        """The report without the per-beam verdicts, as plain values."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "verdicts"}
        out["status"] = self.status.value
        if self.sensor_pose is not None:
            out["sensor_pose"] = list(self.sensor_pose.as_array())
        return out


class MapUpdater:
    """The map updater of docs/algorithm.md on a fixed reference map.

    ``config``: None for profile ``profile``'s (``robot``, what a robot should run, or
    ``paper``, the paper and its authors' code: ``UpdaterConfig.profile``).
    ``process(scan, sensor_pose, odometry)`` once per scan; ``updated_map()`` at any time.
    ``sensor_pose`` is the lidar's pose in the map frame (the robot pose already composed with
    the lidar's mount); ``odometry`` the robot's odom-frame pose at the scan's time, used for
    gating only.
    """

    def __init__(self, reference_map: OccupancyGrid, config: UpdaterConfig | None = None, *,
                 profile: str = DEFAULT_PROFILE, faces: FaceCounts | None = None):
        if not isinstance(reference_map, OccupancyGrid):
            raise UpdaterError(f"reference_map must be a gridmap.OccupancyGrid, got "
                               f"{type(reference_map).__name__}")
        config = UpdaterConfig.profile(profile) if config is None else config
        if not isinstance(config, UpdaterConfig):
            raise UpdaterError(f"config must be an UpdaterConfig, got {type(config).__name__}")
        if reference_map.data.size >= 2**31:
            raise UpdaterError(f"reference map of shape {reference_map.shape} has too many "
                               f"cells (at most 2**31 - 1)")
        self.config = config
        self._ref = np.ascontiguousarray(reference_map.data, dtype=np.int8).copy()
        self._ref.flags.writeable = False
        # where M is free in whole blocks: the casts and walks cross those in jumps
        self._clear = steps.clear_blocks(self._ref)
        self._res = reference_map.resolution
        self._origin = reference_map.origin
        self._hist = np.zeros(self._ref.shape, np.uint16)
        # flags ever pushed, saturating: only the unanimous rule needs them, and the spare bits
        # of the buffers hold them when there are enough (steps.count_shift)
        own = config.unanimous_min and not steps.count_shift(config)
        self._seen = np.zeros(self._ref.shape if own else (0, 0), np.uint8)
        n_bytes = (self._ref.size + 7) // 8
        self._decided = np.zeros(n_bytes, np.uint8)
        # set between scans on the cells where a changed flag would change nothing
        self._ch_marks = np.zeros(n_bytes, np.uint8)
        # set between scans on the free cells where an unchanged flag would change nothing
        self._un_marks = steps.settled_marks(self._ref, self._hist, config)
        self._enclosed = np.zeros(n_bytes, np.uint8)
        # growth into the unknown: hit buffers of open unknown cells, their drawn bits, marks
        self._hits = HitTiles(self._ref.shape, config.grow_into_unknown)
        self._drawn = np.zeros(n_bytes, np.uint8)
        self._hit_marks = np.zeros(n_bytes if config.grow_into_unknown else 0, np.uint8)
        self._n_drawn = 0
        if config.last_check:
            max_cells = int(math.floor(config.last_check_max_area / self._res**2 + 1e-9))
            self._enclosed, _ = steps.enclosed_unknown(self._ref, max_cells)
        self._cells = MapCells(self._ref, self._clear, self._enclosed)
        self._faces = FaceCounts.start(self._ref.shape, config.move_faces, faces)
        self._refined = False       # the pose check placed the last scan (Verdict.REFINED)
        self._state: Buffers | None = None      # the buffers as the kernels take them
        self._n_changed = 0
        # with gate_confirm_once: the cells held-back scans confirmed since the last processed
        # scan (sorted), so that the scans held back between two views confirm a cell once
        # (not saved: after a load, the scans held back before the next view may confirm a
        # cell once more)
        self._once = config.gate_confirm and config.gate_confirm_once
        self._confirmed = np.zeros(0, np.int32)
        self._gate = Gate(config)
        self._counts = {"scans": 0, "processed": 0, "gated": 0, "lost": 0, "skipped": 0}
        self._ws = steps.Workspace()

    # --- the per-scan call --------------------------------------------------------------------
    def process(self, scan: Scan, sensor_pose: Pose2D, odometry: Pose2D | None = None,
                pose_check: Callable[[], PoseVerdict] | None = None) -> ScanReport:
        """Gate, classify, flag, push and decide for one scan. See the module docstring for
        bad input.

        ``pose_check``, when given, is asked only for scans that pass the gate (so a costly
        check runs a few times per metre, not at the scan rate) and returns a
        ``gridmap.PoseVerdict``: accepted (the pose is used as given), refined (that sensor
        pose, e.g. ``sensor_pose`` matched to M, is used instead) or refused (the scan is a
        counted skip that, like a lost scan, does not advance the gate)."""
        self._check_input(scan, sensor_pose, odometry)
        cfg, res, ws = self.config, self._res, self._ws
        self._counts["scans"] += 1
        t = float(scan.time)
        gate_pose = sensor_pose if odometry is None else odometry
        if cfg.gating:
            reason = self._gate.check(t, gate_pose, odometry is not None,
                                      math.degrees(scan.fov()))
            if reason:
                self._counts["gated"] += 1
                n_un = self._confirm(scan, sensor_pose) if reason in CONFIRMING else 0
                return ScanReport(t, ScanStatus.GATED, reason, unchanged_flags=n_un,
                                  changed_cells=self._n_changed, sensor_pose=sensor_pose)
        placed, sensor, status, reason = self._placed_pose(sensor_pose, pose_check)
        if status is not None:
            self._counts["skipped"] += 1
            return ScanReport(t, status, reason, changed_cells=self._n_changed,
                              sensor_pose=placed)

        # the guard, fill_gaps, the growth into the unknown and the hits that confirm M's
        # surfaces (flag_hit_surfaces) are not in the paper
        n_valid, raw, kept, flags = steps.process_scan(scan, sensor, res, cfg, ws, self._cells,
                                                       self._buffers(), self._hits)
        self._counts["processed"] += 1
        if flags is None:
            self._counts["lost"] += 1
            return ScanReport(t, ScanStatus.LOST, "", n_valid, kept, raw,
                              changed_cells=self._n_changed, verdicts=ws.verdict.copy(),
                              sensor_pose=placed)
        n_ch, n_new, n_un, d_changed, d_drawn = flags
        if cfg.move_faces and (self._refined or not cfg.face_refined_only):
            self._faces.count(ws, sensor, cfg)
        self._n_changed += d_changed
        self._n_drawn += d_drawn
        if self._confirmed.size:
            self._confirmed = np.zeros(0, np.int32)      # a new view
        if cfg.gating:
            self._gate.mark_processed(t, gate_pose)
        return ScanReport(t, ScanStatus.PROCESSED, "", n_valid, kept, raw, n_ch, n_new, n_un,
                          self._n_changed + self._n_drawn, ws.verdict.copy(), placed)

    def confirm(self, scan: Scan, sensor_pose: Pose2D) -> int:
        """What a scan held back as a view already taken gives with ``gate_confirm``, for a
        gate kept outside this updater (a fleet's robots in front of one shared updater):
        the unchanged flags of the occupied cells of M it hits (``_confirm``). Returns their
        count."""
        self._check_input(scan, sensor_pose, None)
        return self._confirm(scan, sensor_pose)

    def _confirm(self, scan: Scan, sensor_pose: Pose2D) -> int:
        """With ``gate_confirm``: the unchanged flags of the occupied cells of M that a scan the
        gate held back as a view already taken (the robot has not moved, or only turned) hits,
        and none of its other flags. A robot standing still or spinning then cannot fill a
        buffer with changes seen from one place, and its scans still confirm the surfaces it
        sees, as the scans around them do (with ``gate_confirm_once``, each cell once
        between two views: the scans held back between two views would otherwise outvote the
        changes the views see). (Not their free walks: the pose check, asked only
        for the scans let through, does not vouch for these poses, and a walk placed a little
        off crosses the face of a new object.) Returns the count of unchanged flags (0 for a
        scan not confirmed: the option off, the sensor off the map, or the scan lost)."""
        cfg, ref, ws = self.config, self._ref, self._ws
        sensor = steps.to_grid(sensor_pose, self._origin, self._res)
        if not cfg.gate_confirm or not self._on_map(sensor):
            return 0
        beams = steps.classify_beams(ref, scan, sensor, self._res, cfg, ws, self._clear)
        if steps.is_lost(beams, cfg, ref):
            return 0
        n_un = steps.flag_unchanged_surfaces(ref, beams, self._un_marks, ws)
        n_un = steps.flag_hit_surfaces(ref, beams, cfg, self._un_marks, ws, n_un)
        if self._once:
            n_un, self._confirmed = steps.once_per_view(ws, n_un, self._confirmed,
                                                        self._un_marks)
        self._push_and_decide(0, n_un)
        return n_un

    def _push_and_decide(self, n_changed: int, n_unchanged: int) -> None:
        """The scan's flags listed in the workspace into the buffers, then the decision."""
        self._n_changed += steps.push_and_decide(self._buffers(), self._ref, n_changed,
                                                 n_unchanged, self.config, self._res, self._ws)

    def _buffers(self) -> Buffers:
        """The state a scan changes, as the kernels take it (``_arguments.Buffers``): made
        again after a load, or when the hit buffers' pool grew (``HitTiles.make``)."""
        got = self._state
        if got is None or got.tile_pool is not self._hits.pool:
            got = self._state = Buffers(
                self._hist.reshape(-1), self._seen.reshape(-1), self._decided, self._ch_marks,
                self._un_marks, self._hit_marks, self._drawn, self._hits.directory,
                self._hits.pool, self._hits.count)
        return got

    def _placed_pose(self, sensor_pose: Pose2D, pose_check):
        """(pose, its grid coordinates, None, "") for a scan to process: the given sensor pose,
        or the one the pose check refined it to; (pose or None, ..., status, reason) for one to
        skip."""
        placed, refused = sensor_pose, None
        self._refined = False
        sensor = steps.to_grid(placed, self._origin, self._res)
        if pose_check is not None and self._on_map(sensor):
            verdict = pose_check()
            if not isinstance(verdict, PoseVerdict):
                raise UpdaterError(f"pose_check must return a gridmap.PoseVerdict, got "
                                   f"{type(verdict).__name__}")
            if verdict.verdict is Verdict.REFINED:
                if not verdict.sensor_pose.is_finite():
                    raise UpdaterError(f"pose_check returned a non-finite sensor pose "
                                       f"{verdict.sensor_pose}")
                placed = verdict.sensor_pose
                sensor = steps.to_grid(placed, self._origin, self._res)
                self._refined = True        # placed where the scan fits M (the faces rule)
            if verdict.is_refused:
                refused = verdict.reason
        if not self._on_map(sensor):
            return placed, sensor, ScanStatus.OFF_MAP, SKIPPED_OFF_MAP
        if refused is not None:
            return None, sensor, ScanStatus.REFUSED, refused
        return placed, sensor, None, ""

    def _on_map(self, sensor: np.ndarray) -> bool:
        height, width = self._ref.shape
        return 0 <= sensor[0] < width and 0 <= sensor[1] < height

    @staticmethod
    def _check_input(scan, sensor_pose, odometry):
        if not isinstance(scan, Scan):
            raise UpdaterError(f"scan must be a gridmap.Scan, got {type(scan).__name__}")
        if not isinstance(sensor_pose, Pose2D):
            raise UpdaterError(f"sensor_pose must be a gridmap.Pose2D, got "
                               f"{type(sensor_pose).__name__}")
        if not sensor_pose.is_finite():
            raise UpdaterError(f"sensor pose must be finite, got {sensor_pose}")
        if odometry is not None and not (isinstance(odometry, Pose2D) and odometry.is_finite()):
            raise UpdaterError(f"odometry must be None or a finite gridmap.Pose2D, got "
                               f"{odometry!r}")
        if not math.isfinite(scan.time):
            raise UpdaterError(f"scan time must be finite, got {scan.time}")

    # --- results ------------------------------------------------------------------------------
    @property
    def reference_map(self) -> OccupancyGrid:
        """A copy of M."""
        return OccupancyGrid(self._ref.copy(), self._res, self._origin)

    @property
    def stats(self) -> dict:
        """Counts of scans: seen, processed (classified), gated, lost (processed, then dropped
        by the lost check), skipped (sensor off the map, or refused by the pose check)."""
        return dict(self._counts)

    def updated_map(self) -> OccupancyGrid:
        """M with the changed cells flipped and the last check applied (O(map); on demand)."""
        # with the unanimous rule, interiors seen through are not closed (docs/real_changes.md)
        spare = self._hist if self.config.unanimous_min else None
        cells, _ = steps.close_outlines(self._ref, self._output_bits(), self._enclosed,
                                        self.config.last_check, self._drawn, spare,
                                        steps.buffer_mask(self.config))
        if self.config.move_faces:
            self._faces.move(self._ref, cells, self.config, self._res)
        return OccupancyGrid(cells, self._res, self._origin)

    def face_cells(self) -> int:
        """Cells the faces rule holds counts for, carried or this session's."""
        return self._faces.cells

    def carried_faces(self) -> FaceCounts:
        """What the next session's updater starts from (``faces=``): the counts of the faces
        rule (``UpdaterConfig.move_faces``), halved, and the cells it would move now. Empty
        with the rule off. O(map): the output is worked out to find those cells."""
        if self.config.move_faces:
            self.updated_map()
        return self._faces.decayed()

    def _output_bits(self) -> np.ndarray:
        """The decided bits, with the cells freed with their objects (``spread_removed``) and
        without those beside a surface that stands (``free_with_neighbours``)."""
        bits = self._decided
        if self.config.spread_removed:
            bits = bits | steps.spread_freed(self._hist.reshape(-1), self._seen.reshape(-1),
                                             self._ref.reshape(-1), self._decided,
                                             self._ref.shape[1], self._res, self.config)
        return steps.keep_beside_standing(self._hist.reshape(-1), self._seen.reshape(-1),
                                          self._ref.reshape(-1), bits, self._ref.shape[1],
                                          self._res, self.config)

    def changed_cells(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the cells the decision rule marks changed, in row-major order.
        Cells drawn by the last check, and those of unknown space drawn by the growth into
        it (``drawn_cells``), are not among them (see ``updated_map``)."""
        bits = np.unpackbits(self._decided, bitorder="little")[:self._ref.size]
        return np.unravel_index(np.flatnonzero(bits), self._ref.shape)

    def drawn_cells(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the open unknown cells of M that the scans hit often enough to be
        drawn occupied (``UpdaterConfig.grow_into_unknown``)."""
        bits = np.unpackbits(self._drawn, bitorder="little")[:self._ref.size]
        return np.unravel_index(np.flatnonzero(bits), self._ref.shape)

    @property
    def n_changed(self) -> int:
        return self._n_changed

    def change_counts(self) -> np.ndarray:
        """n_c, the changed flags in each cell's buffer, as a uint8 (H, W) array."""
        return np.bitwise_count(self._hist & steps.buffer_mask(self.config)).astype(np.uint8)

    def evidence_summary(self) -> dict:
        """Cells whose buffers hold evidence of change that has not (or not yet) changed them:
        ``pending_cells`` (at least one changed flag among the last N_b, not changed in the
        output), of which ``pending_few_observations`` were observed fewer than T times in
        all and ``pending_outvoted`` more often (their unchanged flags outweigh the changed
        ones); those two are None when the flags are not counted (``unanimous_min`` 0).
        O(map); for summaries, not per scan."""
        mask, shift = np.uint16(steps.buffer_mask(self.config)), steps.count_shift(self.config)
        counted = bool(self.config.unanimous_min)
        hist, seen = self._hist.reshape(-1), self._seen.reshape(-1)
        output = self._output_bits()
        n_pending = n_few = 0
        # in blocks: temporaries the size of a large map would outweigh the state itself
        for lo in range(0, hist.size, _SUMMARY_BLOCK):
            hi = min(lo + _SUMMARY_BLOCK, hist.size)
            bits = np.unpackbits(output[lo >> 3:(hi + 7) >> 3], bitorder="little")
            pending = ((hist[lo:hi] & mask) != 0) & (bits[:hi - lo] == 0)
            n_pending += int(pending.sum())
            if counted:
                counts = hist[lo:hi] >> np.uint16(shift) if shift else seen[lo:hi]
                n_few += int((pending & (counts < self.config.threshold)).sum())
        if not counted:             # flags not counted (unanimous_min 0): not split
            return {"pending_cells": n_pending, "pending_few_observations": None,
                    "pending_outvoted": None}
        return {"pending_cells": n_pending, "pending_few_observations": n_few,
                "pending_outvoted": n_pending - n_few}

    def _flag_counts(self) -> np.ndarray | None:
        """Each cell's flag count, flat (saturated counts read as many), None when the flags
        are not counted."""
        shift = steps.count_shift(self.config)
        if shift:
            return self._hist.reshape(-1) >> np.uint16(shift)
        return self._seen.reshape(-1) if self._seen.size else None

    def enclosed_unknown(self) -> np.ndarray:
        """Boolean (H, W) mask of the cells the last check may close."""
        bits = np.unpackbits(self._enclosed, bitorder="little")[:self._ref.size]
        return bits.reshape(self._ref.shape).astype(bool)

    def state_bytes(self) -> int:
        """Bytes of every array the updater holds, the per-scan workspace included."""
        arrays = (self._ref, self._clear, self._hist, self._seen, self._decided,
                  self._ch_marks, self._un_marks, self._enclosed, self._drawn, self._hit_marks,
                  self._confirmed)
        return sum(a.nbytes for a in arrays) + self._hits.nbytes + self._ws.nbytes() + \
            self._faces.nbytes

    # --- stop and resume ----------------------------------------------------------------------
    def save(self, path) -> None:
        """Write the whole state to ``path`` (npz): written to a temporary file beside it and
        renamed, so a crash never leaves a half-written state."""
        path = Path(path)
        arrays = {"reference": self._ref, "hist": self._hist, "hits": self._hits.dense(),
                  "seen": self._seen, **self._faces.state_arrays()}
        meta = {"format": STATE_FORMAT, "config": self.config.to_dict(),
                "resolution": self._res, "origin": list(self._origin),
                "gate": self._gate.state(), "counts": self._counts,
                "checksums": saved_state.checksums(arrays)}
        buf = io.BytesIO()
        np.savez_compressed(buf, meta=np.array(json.dumps(meta)), **arrays)
        try:
            write_atomically(path, buf.getvalue())
        except OSError as e:
            raise UpdaterError(f"{path}: cannot save the updater state: {e}") from None

    def _restore_buffers(self, path, hist: np.ndarray, hits: np.ndarray | None,
                         seen: np.ndarray | None = None, packed: bool = False) -> None:
        """Take saved buffers (refused unless they fit the map and the configuration) and
        decide every cell from them. ``packed``: the saved buffers hold the flag counts above
        the flags, as this updater keeps them; else they hold the flags alone and the counts
        come from ``seen``. A state saved before the flags were counted gives each cell with
        flags the most observations (so none of them is decided by few)."""
        mask = steps.buffer_mask(self.config)
        hit_shape = self._ref.shape if self.config.grow_into_unknown else (0, 0)
        for name, saved, shape, bits in (("buffers", hist, self._hist.shape,
                                          0xFFFF if packed else mask),
                                         ("hit buffers", hits, hit_shape, mask)):
            if saved is None or (saved.size == 0 and shape == (0, 0)):
                continue
            if saved.shape != shape or saved.dtype != np.uint16 or \
                    np.any(saved & np.uint16(0xFFFF & ~bits)):
                raise UpdaterError(f"{path}: {name} do not fit the reference map and config")
        if hist is not None:
            self._hist[...] = hist
        if hits is not None and hits.size:
            self._hits = HitTiles.from_dense(hits)
        if not packed:
            self._restore_counts(path, hist, seen)
        self._un_marks = steps.settled_marks(self._ref, self._hist, self.config)
        self._ch_marks = steps.full_marks(self._hist, self.config)
        self._state = None
        ref = self._ref.reshape(-1)
        self._decided, self._n_changed = steps.decide_all(self._hist.reshape(-1),
                                                          self._seen.reshape(-1), ref,
                                                          self._ref.shape[1], self.config)
        if self.config.grow_into_unknown:
            self._n_drawn = steps.decide_drawn(self._hits, self._ref, self._enclosed,
                                               self.config, self._drawn)

    def _restore_counts(self, path, hist: np.ndarray, seen: np.ndarray | None) -> None:
        """The flag counts of a state whose buffers hold the flags alone (``seen``, or None
        when saved before they were counted), into this updater's layout. A count past what
        its field holds saturates there: the rule reads every count from N_b on alike."""
        counted = bool(self.config.unanimous_min)
        if seen is None:            # saved before flags were counted
            seen = np.where(hist != 0, 255, 0).astype(np.uint8) if counted else \
                np.zeros((0, 0), np.uint8)
        if seen.shape != (self._ref.shape if counted else (0, 0)) or seen.dtype != np.uint8:
            raise UpdaterError(f"{path}: flag counts do not fit the reference map and config")
        shift = steps.count_shift(self.config)
        if shift:
            top = np.uint16(0xFFFF >> shift)
            self._hist |= np.minimum(seen.astype(np.uint16), top) << np.uint16(shift)
        else:
            self._seen[...] = seen

    @classmethod
    def load(cls, path) -> MapUpdater:
        """An updater in exactly the state ``save`` wrote."""
        path = Path(path)

        try:
            check_regular_file(path, "updater state file")
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                ref, hist = z["reference"], z["hist"]
                # states saved before the growth into the unknown have no hit buffers
                hits = z["hits"] if "hits" in z.files else None
                seen = z["seen"] if "seen" in z.files else None
                # states saved before the faces rule have no face counts
                face_arrays = {k: z[k] if k in z.files else None for k in FACE_STATE_KEYS}
        except FileInputError as e:
            raise UpdaterError(str(e)) from None
        # A truncated, damaged or foreign file: zipfile, zlib and numpy's header parser raise
        # many kinds of error (EOFError when empty, zlib.error and tokenize's TokenError for
        # overwritten bytes); whatever they raise, the file is not a state.
        except Exception as e:  # noqa: BLE001
            raise UpdaterError(f"{path}: not a readable updater state file "
                               f"({type(e).__name__}: {' '.join(str(e).split())})") from None
        got = meta.get("format") if isinstance(meta, dict) else None
        if got not in (1, STATE_FORMAT) or isinstance(got, bool):
            raise UpdaterError(f"{path}: state format {got!r}, expected 1 or {STATE_FORMAT}")
        missing = [k for k in ("config", "resolution", "origin", "gate", "counts")
                   if k not in meta]
        if missing:
            raise UpdaterError(f"{path}: state lacks {', '.join(missing)}")
        saved_state.check_checksums(path, meta.get("checksums"), {
            "reference": ref, "hist": hist, "hits": hits, "seen": seen, **face_arrays})
        faces = FaceCounts.from_state(face_arrays)
        config = UpdaterConfig.from_dict(meta["config"], source=str(path))
        try:
            grid = OccupancyGrid(ref, meta["resolution"], tuple(meta["origin"]))
        except (GridError, TypeError, ValueError) as e:
            raise UpdaterError(f"{path}: the saved reference map is not usable: {e}") from None
        try:
            updater = cls(grid, config, faces=faces)
        except UpdaterError as e:
            raise UpdaterError(f"{path}: {e}") from None
        packed = got == STATE_FORMAT and steps.count_shift(config) > 0
        updater._restore_buffers(path, hist, hits, seen, packed)
        saved_state.check_flags_counted(path, updater._hist.reshape(-1),
                                        updater._flag_counts(), steps.buffer_mask(config),
                                        config.buffer_size, grid.width)
        _check_gate_state(path, meta["gate"])
        try:
            updater._gate.restore(meta["gate"])
        except (ValueError, TypeError) as e:
            raise UpdaterError(f"{path}: {e}") from None
        updater._counts = _saved_counts(path, meta["counts"], updater._counts)
        return updater


# The gate's saved times and poses: each group is all NaN (no such scan yet) or all finite.
_GATE_GROUPS = {"last": ("last_t", "last_x", "last_y", "last_th"),
                "processed": ("proc_t", "proc_x", "proc_y", "proc_th")}


def _check_gate_state(path, gate) -> None:
    """Refuse a saved gate that would shut for ever: JSON carries Infinity and NaN, and an
    infinite last time (or a NaN one beside a pose) makes every later scan look too soon or
    unmoved, so the next recording would process nothing and say only that it was gated."""
    if not isinstance(gate, dict):
        raise UpdaterError(f"{path}: the saved gate is not a mapping: {gate!r:.60}")
    state = dict(gate)

    def number(key, none_yet=True):
        value = state.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or math.isinf(value) or (math.isnan(value) and not none_yet):
            raise UpdaterError(f"{path}: the saved gate's {key} must be a finite number"
                               f"{' (or NaN: none yet)' if none_yet else ''}, got "
                               f"{value!r:.40}")
        return float(value)

    for name, keys in _GATE_GROUPS.items():
        nan = [math.isnan(number(k)) for k in keys]
        if any(nan) and not all(nan):
            raise UpdaterError(f"{path}: the saved gate's {name} scan is part NaN "
                               f"({', '.join(f'{k}={state[k]!r}' for k in keys)})")
    if number("travel", none_yet=False) < 0:
        raise UpdaterError(f"{path}: the saved gate's travel must be >= 0, got "
                           f"{state['travel']!r}")
    views = state.get("turn_views", [0] * DIRECTION_BINS)   # none in states saved before it
    if not isinstance(views, list) or len(views) != DIRECTION_BINS or not all(
            isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in views):
        raise UpdaterError(f"{path}: the saved gate's turn_views must be {DIRECTION_BINS} "
                           f"whole numbers >= 0, got {views!r:.60}")
    if not isinstance(state.get("idle"), bool) or state.get("source") not in (
            "", "odometry", "localised"):
        raise UpdaterError(f"{path}: the saved gate's idle {state.get('idle')!r:.20} or source "
                           f"{state.get('source')!r:.40} is not the gate's")
    # shut after a fast turn at no time, the gate would never open again
    number("idle_t", none_yet=not state["idle"])


def _saved_counts(path, saved, counts: dict) -> dict:
    """The saved scan counts, each a whole number >= 0."""
    try:
        out = {k: saved[k] for k in counts}
    except (KeyError, TypeError) as e:
        raise UpdaterError(f"{path}: scan counts unreadable: {e}") from None
    for key, value in out.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not (math.isfinite(value) and value >= 0 and value == int(value)):
            raise UpdaterError(f"{path}: the saved scan count {key} must be a whole number "
                               f">= 0, got {value!r}")
    return {k: int(v) for k, v in out.items()}
