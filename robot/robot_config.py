"""The robot software's configuration in one file: the updater, the localiser and the pose check.

    updater:                 # keys of updater.UpdaterConfig
      threshold: 8
    localizer:               # keys of localization.LocalizerConfig
      max_particles: 3000
    pose_check:              # keys of localization.confidence.PoseCheckConfig
      slack_cells: 1

``mapupdate run --config FILE`` and ``mapupdate update --config FILE`` read it, the gymnasium
environment takes the same as a dict (``config=``) and a run's checkpoint reads its recorded
configurations back through it. Every section is optional; a section left out (or empty) leaves
its component as the caller would have it without a file. A section given is the whole
configuration of its component: the keys left out take that dataclass's defaults (for the
localiser nav2's, alpha1..alpha4 = 0.2, not the robot's odometry noise that ``mapupdate run``
gives it without a ``localizer`` section). Unknown sections and keys are refused with the
nearest valid name before anything runs.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

from gridmap import MapUpdatingError
from gridmap.config import check_keys
from gridmap.files import FileInputError, load_yaml
from gridmap.suggest import did_you_mean
from localization import LocalizerConfig
from localization.confidence import PoseCheckConfig
from updater import UpdaterConfig

# What ``mapupdate update`` and the ROS node give the updater without an ``updater`` section:
# the class's defaults, and
# - the growth into the unknown, since a real robot's map is rarely whole (a synthetic hall
#   with an unknown bay: 0.85 of the bay's surfaces drawn, none without;
#   tests/test_logs_partly_mapped.py);
# - a gate for recordings of any density and live scanners (docs/real_changes.md): a new view
#   every 0.1 m or 10 deg, the angular velocity judged only over samples at most 0.5 s apart
#   (a recording that keeps a scan a metre turns tens of degrees between scans), a fast turn
#   at 60 deg/s (the skewed scans of a spinning lidar) holding back 0.5 s of scans rather than
#   1.6 m of travel, turning in place processed while a direction it sees was seen fewer than
#   twice from there (gate_turn_views 2), and the scans held back still confirming the
#   surfaces they hit (gate_confirm);
# - the unanimous rule for cells observed fewer than T times (unanimous_min 3): corridors seen
#   in passing, recordings that keep a scan a metre;
# - the run filter by width as well as by beams (min_run_width 0.2 m): a lidar of 1 deg steps
#   needs 0.28 m of face at 8 m for 3 beams, so far objects were dropped as thin ones;
# - a removed object freed as a whole (spread_removed): the sides of a box that a sparse
#   recording sees through once or twice go with the rest of it;
# - the neighbour support by the map's value (support_exact_state): unknown cells seen
#   through as the map grows do not support freeing the wall behind them.
# ``mapupdate run`` keeps the class's defaults (the paper's and its authors' code): its
# figures are the paper's method's.
ROBOT_UPDATER_DEFAULTS = {
    "grow_into_unknown": True,
    "gate_min_interval": 0.0, "gate_min_distance": 0.2, "gate_min_rotation_deg": 20.0,
    "gate_velocity_max_dt": 0.5, "gate_fast_turn_deg_s": 60.0, "gate_recovery_time": 0.5,
    "gate_recovery_distance": 0.0, "gate_turn_cover": True, "gate_turn_views": 2,
    "gate_confirm": True,
    "unanimous_min": 3, "min_run_width": 0.2, "spread_removed": True,
    "support_exact_state": True,
}

# The sections of the file and the configuration each holds.
CLASSES = {"updater": UpdaterConfig, "localizer": LocalizerConfig, "pose_check": PoseCheckConfig}
SECTIONS = tuple(CLASSES)


class ConfigError(MapUpdatingError, ValueError):
    """A configuration file or mapping that cannot be used; the message names the file, the
    section and the key."""


@dataclass(frozen=True)
class RobotConfig:
    """One configuration per component; None where none was given (the caller's default)."""

    updater: UpdaterConfig | None = None
    localizer: LocalizerConfig | None = None
    pose_check: PoseCheckConfig | None = None

    def to_dict(self) -> dict:
        """The sections given, as ``load_robot_config`` takes them."""
        return {name: getattr(self, name).to_dict() for name in SECTIONS
                if getattr(self, name) is not None}


def load_robot_config(given, source: str | None = None) -> RobotConfig:
    """A ``RobotConfig`` from a YAML file's path, a mapping of sections, a ``RobotConfig`` (as
    it is) or None (nothing given). ``source`` names the origin in errors (default: the path,
    or "config"). Raises ``ConfigError`` for an unreadable file, an unknown section or key, and
    the component's own error (a ``MapUpdatingError``) for a bad value."""
    if given is None or isinstance(given, RobotConfig):
        return given or RobotConfig()
    if isinstance(given, (str, Path)):
        source = source or str(given)
        given = _read_yaml(Path(given))
    source = source or "config"
    if given is None:
        return RobotConfig()      # an empty file
    if not isinstance(given, dict):
        raise ConfigError(f"{source}: expected a mapping of sections ({', '.join(SECTIONS)}), "
                          f"got {type(given).__name__}")
    for name in given:
        if name not in SECTIONS:
            raise ConfigError(f"{source}: unknown section '{name}'{_section_hint(name)}")
    # an empty section (YAML "updater:" with nothing under it) is no section
    return RobotConfig(**{name: section_config(name, given[name], source)
                          for name in SECTIONS if given.get(name) not in (None, {})})


def _section_hint(name) -> str:
    """The nearest section; or, for a key of a section at the top level (a file of updater keys
    alone, as ``mapupdate update --config`` once read), the section it belongs under."""
    near = did_you_mean(name, SECTIONS)
    if near:
        return near
    for section, cls in CLASSES.items():
        if name in [f.name for f in fields(cls)]:
            return f" ('{name}' is a key of section '{section}': put it under '{section}:')"
    return f" (sections: {', '.join(SECTIONS)})"


def section_config(name: str, values, source: str, where: str | None = None):
    """The configuration of section ``name`` (one of ``SECTIONS``) from its mapping of keys;
    ``where`` says in errors where the mapping is (default: "section '<name>'")."""
    cls = CLASSES[name]
    where = where or f"section '{name}'"
    if not isinstance(values, dict):
        raise ConfigError(f"{source}: {where} must be a mapping of keys, got "
                          f"{type(values).__name__}")
    check_keys(values, [f.name for f in fields(cls)], ConfigError, source, where)
    return cls.from_dict(values, source=f"{source}, {where}")


def _read_yaml(path: Path):
    try:
        return load_yaml(path, "configuration file", ConfigError)
    except FileNotFoundError:
        raise ConfigError(f"{path}: configuration file not found") from None
    except FileInputError as e:
        raise ConfigError(str(e)) from None
