"""The updater's configuration: one frozen dataclass with the defaults of ALGORITHM.md.

Every parameter of the method lives here, with its unit in brackets. Loading (``from_dict``,
``from_yaml``) refuses unknown keys with the nearest valid name and checks every value.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from gridmap.config import config_from_dict, config_from_yaml
from gridmap.errors import MapUpdatingError


class UpdaterError(MapUpdatingError, ValueError):
    """An updater argument, configuration, state file or call that cannot be used; the message
    names the key, file or value."""


# Bits 0..N_b-1 of a buffer hold the flags; the rest of the uint16 stays unused.
MAX_BUFFER_SIZE = 16


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
    lost_fraction: float = 0.8               # drop the scan if more valid beams are changes
    # --- 2. Changed-cells evaluator -----------------------------------------------------------
    radius_near: float = 0.10                # [m] tol(r) at r = 0 (new obstacles)
    radius_far: float = 0.20                 # [m] tol(r) at r >= radius_far_range
    radius_far_range: float = 10.0           # [m]
    removed_skip_fraction: float = 0.02      # p_th lies short of the hit by max(fraction * r,
    removed_skip_min: float = 0.15           # [m]                              this)
    # Not in the paper (steps.guard_seen_surfaces): an occupied cell of M (or an unknown one
    # outside the enclosed regions) within this distance of the hit point of any valid beam of
    # the scan (a surface the scan sees) gets no removed-obstacle flag from that scan. Under a
    # pose error below a cell the rays that graze an object's corner cross its outline cells
    # while the beams that hit the object say it is still there (README, "Choices").
    seen_surface_radius: float = 0.075       # [m]; 0: off
    # Not in the paper (steps.fill_gaps): a hit that pairs with M but lands in a cell with
    # nothing of M within fill_gaps_clearance also gets a changed flag. The pairing distance
    # D(r) otherwise hides the gaps of a face that an earlier session mapped only in pieces
    # (README, "fill_gaps").
    fill_gaps: bool = False
    fill_gaps_clearance: float = 0.05        # [m] free square around the hit cell, each way
    fill_gaps_free_margin: float = 0.075     # [m] free flags of agreeing beams this short of
                                             # the hit, with fill_gaps
    # --- 3. Unchanged-cells evaluator ---------------------------------------------------------
    n_skip: int = 2                          # [beams] no unchanged flags this near a change
    free_fraction: float = 0.98              # free cells up to this fraction of the range
    # --- Buffers and decision -----------------------------------------------------------------
    buffer_size: int = 10                    # N_b flags per cell
    threshold: int = 7                       # T: changed when n_c (+ support) reaches this
    neighbour_support: bool = True           # count 8-neighbours of the same state with n >= T
    # --- Last check ---------------------------------------------------------------------------
    last_check: bool = True
    last_check_max_area: float = 25.0        # [m^2] largest enclosed unknown region closed

    def __post_init__(self):
        for name in ("gating", "neighbour_support", "last_check", "fill_gaps"):
            if not isinstance(getattr(self, name), bool):
                raise UpdaterError(f"config key '{name}' must be true or false, "
                                   f"got {getattr(self, name)!r}")
        for name in ("gate_min_interval", "gate_min_distance", "gate_min_rotation_deg",
                     "gate_recovery_time", "gate_recovery_distance", "gate_velocity_window",
                     "window_deg", "pairing_distance_slope", "radius_near", "radius_far",
                     "removed_skip_fraction", "removed_skip_min", "last_check_max_area",
                     "cast_margin", "pairing_range_near", "fill_gaps_clearance",
                     "fill_gaps_free_margin",
                     "seen_surface_radius"):
            _check_number(name, getattr(self, name), lambda v: v >= 0, "a number >= 0")
        for name in ("gate_fast_turn_deg_s", "max_range", "pairing_distance_near",
                     "pairing_distance_max", "radius_far_range"):
            _check_number(name, getattr(self, name), lambda v: v > 0, "a number > 0")
        for name in ("lost_fraction", "free_fraction"):
            _check_number(name, getattr(self, name), lambda v: 0 < v <= 1, "a number in (0, 1]")
        if self.removed_skip_fraction >= 1:
            raise UpdaterError("config key 'removed_skip_fraction' must be < 1")
        for name, low in (("virtual_to_measured_ratio", 1), ("min_run", 1), ("n_skip", 0),
                          ("buffer_size", 1), ("threshold", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise UpdaterError(f"config key '{name}' must be an integer >= {low}, got {v!r}")
        if self.buffer_size > MAX_BUFFER_SIZE:
            raise UpdaterError(f"config key 'buffer_size' must be <= {MAX_BUFFER_SIZE} "
                               f"(the buffers are uint16), got {self.buffer_size}")
        if self.threshold > self.buffer_size:
            raise UpdaterError(f"config key 'threshold' ({self.threshold}) exceeds "
                               f"'buffer_size' ({self.buffer_size}): no cell could ever change")

    # --- the range-dependent distances of ALGORITHM.md [m], for a range or an array of them ---
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
    def from_dict(cls, values: dict, source: str = "updater config") -> UpdaterConfig:
        """Build from a mapping; an unknown key is refused with the nearest valid name."""
        return config_from_dict(cls, values, UpdaterError, source)

    @classmethod
    def from_yaml(cls, path) -> UpdaterConfig:
        """Load from a YAML file holding the keys at the top level (or under ``updater:``)."""
        return config_from_yaml(cls, path, UpdaterError, "updater")


def _check_number(name, v, ok, what):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not ok(v):
        raise UpdaterError(f"config key '{name}' must be {what}, got {v!r}")


def _minimum(a, b):
    import numpy as np

    return np.minimum(a, b) if isinstance(a, np.ndarray) else min(a, b)


def _maximum(a, b):
    import numpy as np

    return np.maximum(a, b) if isinstance(a, np.ndarray) else max(a, b)
