"""The updater's configuration: one frozen dataclass with the defaults of docs/algorithm.md.

Every parameter of the method lives here, with its unit in brackets. Loading (``from_dict``,
``from_yaml``) refuses unknown keys with the nearest valid name and checks every value.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from gridmap.config import (DEFAULT_PROFILE, check_bounds, config_from_dict,
                            config_from_profile, config_from_yaml)
from gridmap.errors import MapUpdatingError


class UpdaterError(MapUpdatingError, ValueError):
    """An updater argument, configuration, state file or call that cannot be used; the message
    names the key, file or value."""


# Bits 0..N_b-1 of a buffer hold the flags; the rest of the uint16 stays unused.
MAX_BUFFER_SIZE = 16


# The range of every number (docs/reliability.md): wide enough for any lidar and map, narrow
# enough that a slip of a digit (a window of 1e9 degrees, 1e6 virtual beams per beam, a 1e300
# m^2 region) is refused rather than run for hours or failing inside a kernel.
BOUNDS = {
    "gate_min_interval": (0.0, 3600.0), "gate_min_distance": (0.0, 100.0),
    "gate_min_rotation_deg": (0.0, 360.0), "gate_fast_turn_deg_s": (1e-3, 3600.0),
    "gate_recovery_time": (0.0, 3600.0), "gate_recovery_distance": (0.0, 1000.0),
    "gate_velocity_window": (0.0, 60.0), "gate_velocity_max_dt": (0.0, 3600.0),
    "gate_turn_views": (1, 100),
"max_range": (1e-3, 100.0), "cast_margin": (0.0, 5.0),
    "virtual_to_measured_ratio": (1, 16), "window_deg": (0.0, 45.0),
    "pairing_distance_near": (1e-3, 5.0), "pairing_range_near": (0.0, 100.0),
    "pairing_distance_slope": (0.0, 1.0), "pairing_distance_max": (1e-3, 5.0),
    "min_run": (1, 100), "min_run_width": (0.0, 5.0), "lost_fraction": (1e-3, 1.0), "radius_near": (0.0, 5.0),
    "radius_far": (0.0, 5.0), "radius_far_range": (1e-3, 100.0),
    "removed_skip_fraction": (0.0, 0.99), "removed_skip_min": (0.0, 5.0),
    "seen_surface_radius": (0.0, 1.0), "fill_gaps_clearance": (0.0, 1.0),
    "fill_gaps_free_margin": (0.0, 5.0), "n_skip": (0, 100), "free_fraction": (1e-3, 1.0),
    "buffer_size": (1, MAX_BUFFER_SIZE), "threshold": (1, MAX_BUFFER_SIZE),
    "unanimous_min": (0, MAX_BUFFER_SIZE), "spread_max_area": (0.0, 10_000.0),
    "last_check_max_area": (0.0, 10_000.0), "face_band": (2, 20), "face_min_sine": (0.0, 1.0),
    "face_min_passes": (1, 255), "face_free_ratio": (0.0, 1.0), "face_min_hits": (1, 255),
    "face_large_min_hits": (1, 255), "face_draw_ratio": (0.0, 1.0), "face_sessions": (1, 2),
    "face_draw_sessions": (1, 2), "face_max_area": (0.0, 10_000.0),
}


# The robot profile: the keys where it differs from the paper's (the class's defaults), each
# with why (docs/configuration.md's table is made from this; benchmarks/bench_static.py and
# benchmarks/bench_real_changes.py measure it).
ROBOT_PROFILE = {
    "grow_into_unknown": (True, "a robot's map is rarely whole: the map grows into the space "
                          "it had not seen (a hall's unknown bay: 0.85 of its surfaces drawn, "
                          "none without)"),
    "grow_clear_of_surfaces": (True, "... but a hit just behind a surface of M is that "
                               "surface seen from a pose a little off: drawn, it thickens the "
                               "face, session after session (100 sessions, 9 runs: precision "
                               "0.966 -> 0.977, recall 0.554 -> 0.574; a partly mapped "
                               "building's new cells known and right 0-0.05 lower)"),
    "gate_min_interval": (0.0, "recordings of any density and live scanners: a new view is "
                          "what counts, not the time since the last one"),
    "gate_min_distance": (0.2, "a new view every 0.2 m (0.4 m keeps too few views of a sparse "
                          "recording; 0.1-0.15 m frees walls on Freiburg 079)"),
    "gate_min_rotation_deg": (20.0, "... or 20 deg of turn"),
    "gate_velocity_max_dt": (0.5, "the angular velocity judged only over samples at most "
                             "0.5 s apart (a recording that keeps a scan a metre turns tens of "
                             "degrees between scans)"),
    "gate_fast_turn_deg_s": (60.0, "a fast turn is 60 deg/s (the skew of a spinning lidar), "
                             "not 12"),
    "gate_recovery_time": (0.5, "a fast turn holds back 0.5 s of scans ..."),
    "gate_recovery_distance": (0.0, "... not 1.6 m of travel"),
    "gate_turn_cover": (True, "turning in place, a scan is processed while a direction it "
                        "sees was seen fewer than gate_turn_views times from there"),
    "gate_turn_views": (2, "Orebro's robot stops to look round: two views of each direction"),
    "gate_confirm": (True, "scans held back as views already taken still confirm the "
                     "surfaces they hit (a robot that stands and looks round: without it, 34 "
                     "wall cells of Freiburg 079 are freed)"),
    "gate_confirm_once": (True, "... each cell once between two views: a dozen held-back scans "
                          "of a person standing where a removed object was kept it (the "
                          "warehouse's W4: 8 cells)"),
    "unanimous_min": (3, "a cell seen fewer than T times (a corridor seen in passing, a "
                      "recording that keeps a scan a metre) changes when at least 3 flags, "
                      "all of them, say so"),
    "min_run_width": (0.2, "the run filter keeps a run whose ends lie 0.2 m apart: 3 beams of "
                      "a 1 deg lidar span 0.28 m at 8 m"),
    "spread_removed": (True, "a removed object is freed as a whole, its sides seen through "
                       "once or twice with the rest"),
    "support_exact_state": (True, "unknown cells seen through as the map grows lend a wall "
                            "no support"),
    "removed_skip_across": (True, "the removed-obstacle walk ends as far from a surface a beam "
                            "grazes as from one it meets square: a pose a few centimetres off "
                            "across a wall no longer walks beams through its face"),
    "free_with_neighbours": (True, "a cell of M is freed only with what stands beside it: no "
                             "sliver of a face grazed by beams, no wall cell worn by a pose "
                             "error"),
    "move_faces": (True, "a face of M a few cells from where the scans see it is moved there, "
                   "with counts carried from session to session: the errors the paper's "
                   "rules cannot see no longer pile up over the sessions"),
    "face_sessions": (2, "... freeing a cell, or drawing one in front of a wall or rack, once "
                      "two sessions in a row agree: a single recording whose poses are a few "
                      "centimetres off (Freiburg 079) freed 168 wall cells with one; beside an "
                      "object it draws on one session's word (face_draw_sessions 1: 100 "
                      "sessions, 9 runs: recall 0.591 -> 0.630, higher in all 9, precision "
                      "0.976 -> 0.977, cells of what stands freed 514 -> 462)"),
    "face_min_hits": (4, "... on 4 placed scans' hits of a cell, not 5, beside an object (5 "
                      "still in front of a wall or rack, face_large_min_hits): a face the "
                      "route passes sees a cell a few times a session (100 sessions, 9 "
                      "runs, drawing once two sessions agreed: recall 0.580 -> 0.591, higher "
                      "in all 9, precision 0.976 either way)"),
    "face_draw_beside_large": (True, "... and an object set down a few centimetres in front of "
                               "a wall or rack is drawn too, in M's free space, where neither "
                               "the paper's rules nor the rest of this one draw (100 sessions, "
                               "9 runs: recall 0.573 -> 0.580, precision 0.976 either way)"),
}


@dataclass(frozen=True)
class UpdaterConfig:
    # --- 0. Gating (from the authors' code; not in the paper) ---------------------------------
    gating: bool = True                      # False: every scan is processed (benchmarks)
    gate_min_interval: float = 0.3           # [s] since the last processed scan
    gate_min_distance: float = 0.4           # [m] moved since the last processed scan, or ...
    gate_min_rotation_deg: float = 45.0      # [deg] ... turned since then
    gate_fast_turn_deg_s: float = 12.0       # [deg/s] an angular velocity this high starts idling
    gate_recovery_time: float = 1.2          # [s] idle at least this long after a fast turn ...
    gate_recovery_distance: float = 1.6      # [m] ... and until this far travelled
    gate_velocity_window: float = 0.3        # [s] without odometry: poses differenced over this
    # Not in the authors' code (gating.py): the angular velocity is judged only over pose
    # samples at most this far apart (3600: any), and with gate_turn_cover a robot turning
    # without moving gets scans processed for its turning only while a direction they see has
    # been seen fewer than gate_turn_views times from there.
    gate_velocity_max_dt: float = 3600.0     # [s]
    gate_turn_cover: bool = False
    gate_turn_views: int = 1                 # views of each direction from one place
    # Not in the authors' code (MapUpdater._confirm): a scan held back as a view already
    # taken (too soon, no motion, turning in place) still gives its unchanged flags.
    gate_confirm: bool = False
    # ... each cell at most once between two processed scans: the scans held back between two
    # views would otherwise outvote the changes the views see
    gate_confirm_once: bool = False
    # --- Valid beams --------------------------------------------------------------------------
    max_range: float = 18.0                  # [m] beams at or beyond min(this, range_max) invalid
    # --- 1. Beam classifier -------------------------------------------------------------------
    cast_margin: float = 0.8                 # [m] virtual beams are cast to max range + this
    virtual_to_measured_ratio: int = 1       # virtual beams per measured angular step
    window_deg: float = 4.0                  # [deg] half-width of the search window
    pairing_distance_near: float = 0.15      # [m] D(r) at r = pairing_range_near
    pairing_range_near: float = 0.2          # [m]
    pairing_distance_slope: float = 0.013265  # [m/m] growth of D(r) with range
    pairing_distance_max: float = 0.30       # [m] D(r) saturates here
    min_run: int = 3                         # run filter: shortest kept run of changes (1: off)
    # Not in the authors' code: a shorter run of two or more is kept too when its first and
    # last hits lie this far apart (0: off). min_run counts beams, so what it drops depends on
    # the lidar's resolution: 3 beams of a 1 deg lidar span 0.28 m at 8 m, of a 0.25 deg one 7 cm.
    min_run_width: float = 0.0               # [m]
    lost_fraction: float = 0.8               # drop the scan if more valid beams are changes
    # --- 2. Changed-cells evaluator -----------------------------------------------------------
    radius_near: float = 0.10                # [m] tol(r) at r = 0 (new obstacles)
    radius_far: float = 0.20                 # [m] tol(r) at r >= radius_far_range
    radius_far_range: float = 10.0           # [m]
    removed_skip_fraction: float = 0.02      # p_th lies short of the hit by max(fraction * r,
    removed_skip_min: float = 0.15           # [m]                              this)
    # Not in the paper (_classify.skip_across): that skip measured across the surface the beam
    # hits, not along the beam (the skip over the sine of the angle between beam and surface,
    # from the hits of the beam's neighbours). A beam grazing a wall at 10 deg otherwise walks
    # to within 3 cm of it across, and a pose that far off walks it through the wall's face.
    removed_skip_across: bool = False
    # Not in the paper (_flags.mark_seen_surfaces): an occupied cell of M (or an unknown one
    # outside the enclosed regions) within this distance of the hit point of any valid beam of
    # the scan (a surface the scan sees) gets no removed-obstacle flag from that scan. Under a
    # pose error below a cell the rays that graze an object's corner cross its outline cells
    # while the beams that hit the object say it is still there (docs/choices.md).
    seen_surface_radius: float = 0.075       # [m]; 0: off
    # Not in the paper (_flags.flag_gaps): a hit that pairs with M but lands in a cell with
    # nothing of M within fill_gaps_clearance also gets a changed flag. The pairing distance
    # D(r) otherwise hides the gaps of a face that an earlier session mapped only in pieces
    # (docs/choices.md, "fill_gaps").
    fill_gaps: bool = False
    fill_gaps_clearance: float = 0.05        # [m] free square around the hit cell, each way
    fill_gaps_free_margin: float = 0.075     # [m] free flags of agreeing beams this short of
                                             # the hit, with fill_gaps
    # Not in the paper (_walks.unknown_walks, _flags.list_unknown_hits, _buffers.push_hits):
    # the map grows into M's open unknown space (unknown, outside the enclosed regions): cells
    # that beams looking into it see through become free by their changed flags, cells hit
    # become occupied by hit buffers of N_b flags and the threshold T. Without it, a partly
    # mapped place stays as unknown as M had it.
    grow_into_unknown: bool = False          # on in mapupdate update and the ROS node
    # Not in the paper (_flags.list_unknown_hits): with grow_into_unknown, a hit in open unknown
    # space just behind an occupied cell of M as its beam comes (an 8-neighbour on the sensor's
    # side) gives no hit flag. It is M's surface seen from a pose a few centimetres off, as the
    # paper draws no new obstacle within tol(r) of one; drawn, it thickens the face into the
    # object behind it, where no beam can ever undo it.
    grow_clear_of_surfaces: bool = False
    # Not in the paper (``skipped_as_change`` in _scan.process_scan): a beam skipped beside a
    # kept change (within n_skip of it) also walks for removed obstacles: the occupied cells
    # of M it passes through before p_th get changed flags. Such a beam pairs, within the
    # window, with a point past the object, so the paper gives the sides of a removed object
    # no flag from it. Off in every default: with pose noise the same walks wear the edges of
    # walls.
    walk_skipped_beams: bool = False
    # --- 3. Unchanged-cells evaluator ---------------------------------------------------------
    n_skip: int = 2                          # [beams] no unchanged flags this near a change
    free_fraction: float = 0.98              # free cells up to this fraction of the range
    # Not in the paper (_flags.flag_hit_surfaces): a detected change, or a beam within n_skip of
    # one, whose hit lands in a cell M has as occupied or unknown gives the occupied cells of M
    # among that cell and its 4-neighbours an unchanged flag, as an agreeing beam would. A cell
    # the session keeps hitting is then not freed by the walks of other scans, also where M is
    # unknown all around and every beam counts as a change (the Killian Court log).
    confirm_hit_surfaces: bool = True
    # --- Buffers and decision -----------------------------------------------------------------
    buffer_size: int = 10                    # N_b flags per cell
    threshold: int = 7                       # T: changed when n_c (+ support) reaches this
    neighbour_support: bool = True           # count 8-neighbours of the same state with n >= T
    # Not in the paper (_decide.same_state): the support counts only neighbours of the same
    # value of M. The paper's two states put unknown with occupied, so where the map grows
    # into the unknown, the unknown cells in front of a wall, seen through as the scans reach
    # the wall, lend the wall's cells their support and free them.
    support_exact_state: bool = False
    # Not in the paper: a cell observed fewer than T times in all (a corridor seen in passing,
    # a recording that keeps a scan a metre) is changed when every one of its flags says
    # changed and there are at least this many. A later contrary flag undoes it. 0: off.
    unanimous_min: int = 0
    # Not in the paper (_output.spread_freed): a removed object is freed as a whole. An occupied
    # cell of M next to one the rule freed (or to one freed this way), every flag of which says
    # changed, is freed too, however few its flags, within an 8-connected structure of
    # occupied cells of M of at most spread_max_area none of which the scans still see (an
    # object that went, not a wall: pose noise wears a static thing's cells one by one, and
    # the spread would carry that along it). Needs the flag counts (unanimous_min > 0).
    # Applied to the output map.
    spread_removed: bool = False
    spread_max_area: float = 1.0             # [m^2] of occupied cells: larger structures of M
                                             # (walls) get no spread
    # Not in the paper (_output.keep_beside_standing): an occupied cell of M is freed only if
    # none of its 8-neighbours stands: occupied in M and kept occupied by the output, or
    # unknown in M and reached by no flag. A face cell that an object covers by a sliver,
    # grazed by beams that pass through the rest of it, and a wall cell worn by a pose a few
    # centimetres off, each stand beside cells that stay; the cells of an object that went go
    # together, its interior seen through with them. Applied to the output map.
    free_with_neighbours: bool = False
    # Not in the paper (_faces): a face of M a few cells from where the scans see it is moved
    # there. Per cell, the processed scans whose beams end in it (hits) and those whose beams
    # cross it within face_band cells before their hit, meeting the surface they hit at
    # face_min_sine or more (passes). At the output an occupied cell of M crossed this
    # session and by face_min_passes scans in all, ended in by at most face_free_ratio of that
    # many, is freed; a free cell of M 2 to face_band cells from M's surfaces, ended in this
    # session and by face_min_hits scans in all, crossed by at most face_draw_ratio of that
    # many, is drawn. The counts go on from session to session, halved at each new one
    # (MapUpdater.carried_faces).
    move_faces: bool = False
    face_band: int = 4                       # [cells]
    face_min_sine: float = 0.5               # sine of the angle between beam and surface
    face_min_passes: int = 5                 # [scans]
    face_free_ratio: float = 0.2
    face_min_hits: int = 5                   # [scans]
    face_draw_ratio: float = 0.34
    # 2: a cell is freed, or drawn in front of a wall or rack, only when two sessions agree
    face_sessions: int = 1
    # ... and drawn beside an object only when this many agree. 1 in both profiles: a quick
    # route passes an object in some sessions and not the next, and its face would wait for
    # ever; in front of a wall, where the hits of grazing beams land a cell or two off under a
    # pose error, one session's draws thickened the face five times as often
    face_draw_sessions: int = 1
    face_max_area: float = 1.0               # [m^2] only faces of structures of M this small
                                             # move (objects; not walls or racks)
    # ... but a free cell of M 2 to face_band cells in front of a larger structure (a wall, a
    # rack) is drawn too: an object set down beside it, which neither the paper's new-obstacle
    # rule (nothing within tol(r) of a surface) nor the small-structures guard would draw.
    # Only M's free space: its unknown there is the inside of the wall or rack.
    face_draw_beside_large: bool = False
    # ... and hit by this many scans at least (face_min_hits too): under a pose a few
    # centimetres off, the hits of beams that graze a wall land a cell or two in front of it,
    # which the scans of a short session, each placed apart, hardly ever cross
    face_large_min_hits: int = 5             # [scans]
    # only scans the pose check placed where they fit M (refined) count: the rule reads where
    # within a few centimetres a hit lands, and poses a recording gives, taken as given, are
    # that far off along whole stretches (Freiburg 079: 93 wall cells freed in a second session)
    face_refined_only: bool = True
    # --- Last check ---------------------------------------------------------------------------
    last_check: bool = True
    last_check_max_area: float = 25.0        # [m^2] largest enclosed unknown region closed

    def __post_init__(self):
        for name in ("gating", "gate_confirm", "gate_confirm_once", "gate_turn_cover",
                     "neighbour_support", "last_check", "fill_gaps",
                     "grow_into_unknown", "grow_clear_of_surfaces", "confirm_hit_surfaces",
                     "walk_skipped_beams",
                     "spread_removed", "support_exact_state", "free_with_neighbours",
                     "removed_skip_across", "move_faces", "face_refined_only",
                     "face_draw_beside_large"):
            if not isinstance(getattr(self, name), bool):
                raise UpdaterError(f"config key '{name}' must be true or false, "
                                   f"got {getattr(self, name)!r}")
        check_bounds(self, BOUNDS, UpdaterError)
        if self.threshold > self.buffer_size:
            raise UpdaterError(f"config key 'threshold' ({self.threshold}) exceeds "
                               f"'buffer_size' ({self.buffer_size}): no cell could ever change")
        if self.spread_removed and not self.unanimous_min:
            raise UpdaterError("config key 'spread_removed' needs the flag counts: set "
                               "'unanimous_min' above 0")

    # --- the range-dependent distances of docs/algorithm.md [m], for a range or an array of them
    def pairing_distance(self, r):
        """D(r) [m]: a measured point this close to an expected point is explained by the map."""
        return _minimum(self.pairing_distance_near
                        + self.pairing_distance_slope * (r - self.pairing_range_near),
                        self.pairing_distance_max)

    def new_obstacle_radius(self, r):
        """tol(r) [m]: radius around a hit point that must be free in M for a new obstacle."""
        frac = _minimum(r / self.radius_far_range, 1.0)
        return self.radius_near + (self.radius_far - self.radius_near) * frac

    def removed_skip(self, r):
        """|p_i - p_th| [m]: the final chunk of a beam the removed-obstacle walk leaves out."""
        return _maximum(self.removed_skip_fraction * r, self.removed_skip_min)

    # --- loading ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def profile(cls, name: str = DEFAULT_PROFILE, overrides: dict | None = None,
                source: str | None = None) -> UpdaterConfig:
        """The configuration of profile ``name`` (``paper``: the class's defaults; ``robot``:
        those with ``ROBOT_PROFILE``'s keys), with ``overrides`` laid over it key by key."""
        return config_from_profile(cls, ROBOT_PROFILE, name, overrides, UpdaterError, source)

    @classmethod
    def from_dict(cls, values: dict, source: str = "updater config") -> UpdaterConfig:
        """Build from a mapping; an unknown key is refused with the nearest valid name."""
        return config_from_dict(cls, values, UpdaterError, source)

    @classmethod
    def from_yaml(cls, path) -> UpdaterConfig:
        """Load from a YAML file holding the keys at the top level (or under ``updater:``)."""
        return config_from_yaml(cls, path, UpdaterError, "updater")


def _minimum(a, b):
    return np.minimum(a, b) if isinstance(a, np.ndarray) else min(a, b)


def _maximum(a, b):
    return np.maximum(a, b) if isinstance(a, np.ndarray) else max(a, b)
