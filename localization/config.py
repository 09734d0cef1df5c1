"""The localiser's configuration: one frozen dataclass, defaults of ROS 2 nav2 AMCL.

Keys carry nav2's parameter names, so a nav2 ``amcl`` parameter block can be copied across; keys
that nav2 does not have are marked below. Loading refuses unknown keys with the nearest valid name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gridmap.config import (DEFAULT_PROFILE, check_bounds, config_from_dict,
                            config_from_profile, config_from_yaml, config_to_dict)
from gridmap.errors import MapUpdatingError


class LocalizationError(MapUpdatingError, ValueError):
    """A localiser argument, configuration or call that cannot be used; the message names it."""


RESAMPLERS = ("systematic", "stratified", "residual", "multinomial")
# The range of every number (docs/reliability.md): wide enough for any robot, narrow enough
# that a slip of a digit is refused rather than run for hours.
BOUNDS = {
    "alpha1": (0.0, 10.0), "alpha2": (0.0, 10.0), "alpha3": (0.0, 10.0), "alpha4": (0.0, 10.0),
    "importance_factor": (1e-3, 10.0), "min_ess_fraction": (0.0, 1.0),
    "laser_likelihood_max_dist": (1e-3, 20.0), "laser_min_range": (-1.0, 100.0),
    "laser_max_range": (-1.0, 1000.0), "z_hit": (0.0, 1.0), "z_rand": (0.0, 1.0),
    "sigma_hit": (1e-3, 5.0), "max_beams": (2, 10_000), "min_particles": (1, 100_000),
    "max_particles": (1, 100_000), "pf_err": (1e-4, 1.0), "pf_z": (0.0, 10.0),
    "kld_bin_xy": (1e-3, 10.0), "kld_bin_theta": (1e-3, math.pi), "update_min_d": (0.0, 100.0),
    "update_min_a": (0.0, 2 * math.pi), "resample_interval": (1, 1000),
    "recovery_alpha_slow": (0.0, 1.0), "recovery_alpha_fast": (0.0, 1.0),
}
MODELS = ("likelihood_field", "likelihood_field_prob")
# The robot profile: the keys where it differs from nav2's defaults (the class's, the paper
# profile's), each with why (docs/configuration.md).
ROBOT_PROFILE = {
    "update_min_d": (0.1, "a filter update every 0.1 m, not 0.25 m: a scan placed between "
                     "updates carries the odometry since the last one, and a recording's "
                     "odometry can lag its scans (SENA: 0.30 m of error at one scan with "
                     "updates every 0.25 m, 0.17 m with every 0.1 m)"),
}


@dataclass(frozen=True)
class LocalizerConfig:
    # Odometry motion model (sample_motion_model_odometry), variances as in nav2:
    alpha1: float = 0.2      # rotation noise from rotation
    alpha2: float = 0.2      # rotation noise from translation
    alpha3: float = 0.2      # translation noise from translation
    alpha4: float = 0.2      # translation noise from rotation
    # Likelihood-field sensor model: nav2's laser_model_type "likelihood_field" (AMCL's
    # 1 + sum pz^3) or "likelihood_field_prob" (the product of pz^importance_factor). The
    # default model differs from nav2's; localization/README.md gives the measurements.
    laser_model_type: str = "likelihood_field_prob"
    importance_factor: float = 1.0           # (nav2 fixes it at 1)
    min_ess_fraction: float = 0.02           # adaptive tempering floor, 0: off (not in nav2)
    laser_likelihood_max_dist: float = 2.0   # [m] distance field cap
    laser_min_range: float = -1.0            # [m] <= 0: the scan's range_min
    laser_max_range: float = -1.0            # [m] <= 0: the scan's range_max
    z_hit: float = 0.5
    z_rand: float = 0.5
    sigma_hit: float = 0.2                   # [m]
    max_beams: int = 60
    # KLD-sampling:
    min_particles: int = 500
    max_particles: int = 2000
    pf_err: float = 0.05
    pf_z: float = 0.99       # used as the normal quantile itself, exactly as nav2 does
    kld_bin_xy: float = 0.5                  # [m]     (not in nav2: AMCL's fixed kd-tree bins)
    kld_bin_theta: float = math.radians(10)  # [rad]   (not in nav2)
    # Filter schedule:
    update_min_d: float = 0.25               # [m]
    update_min_a: float = 0.2                # [rad]
    resample_interval: int = 1
    # Augmented MCL recovery: 0 / 0 is off (nav2's default); e.g. 0.001 / 0.1 for kidnapping.
    recovery_alpha_slow: float = 0.0
    recovery_alpha_fast: float = 0.0
    resampler: str = "systematic"            # (not in nav2, whose sampler is multinomial)

    def __post_init__(self):
        check_bounds(self, BOUNDS, LocalizationError)
        for name in ("alpha1", "alpha2", "alpha3", "alpha4", "z_hit", "z_rand",
                     "recovery_alpha_slow", "recovery_alpha_fast", "pf_z", "min_ess_fraction",
                     "update_min_d", "update_min_a"):
            _check(name, getattr(self, name), lambda v: v >= 0, "a number >= 0")
        for name in ("laser_likelihood_max_dist", "sigma_hit", "pf_err", "kld_bin_xy",
                     "importance_factor",
                     "kld_bin_theta"):
            _check(name, getattr(self, name), lambda v: v > 0, "a number > 0")
        for name in ("laser_min_range", "laser_max_range"):
            _check(name, getattr(self, name), lambda v: True, "a number")
        for name in ("max_beams", "min_particles", "max_particles", "resample_interval"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise LocalizationError(f"config key '{name}' must be an integer >= 1, got {v!r}")
        if self.max_beams < 2:
            raise LocalizationError("config key 'max_beams' must be >= 2 (AMCL's minimum)")
        if self.min_particles > self.max_particles:
            raise LocalizationError(f"config key 'min_particles' ({self.min_particles}) exceeds "
                                    f"'max_particles' ({self.max_particles})")
        if self.z_hit + self.z_rand <= 0:
            raise LocalizationError("config keys 'z_hit' and 'z_rand' must not both be 0")
        for name in ("recovery_alpha_slow", "recovery_alpha_fast", "min_ess_fraction"):
            if getattr(self, name) > 1:
                raise LocalizationError(f"config key '{name}' must be <= 1")
        if self.laser_model_type not in MODELS:
            raise LocalizationError(f"config key 'laser_model_type' must be one of {MODELS}, "
                                    f"got {self.laser_model_type!r}")
        if self.resampler not in RESAMPLERS:
            raise LocalizationError(f"config key 'resampler' must be one of {RESAMPLERS}, "
                                    f"got {self.resampler!r}")

    @property
    def alphas(self) -> tuple[float, float, float, float]:
        return self.alpha1, self.alpha2, self.alpha3, self.alpha4

    @property
    def recovery_enabled(self) -> bool:
        return self.recovery_alpha_slow > 0 and self.recovery_alpha_fast > 0

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def profile(cls, name: str = DEFAULT_PROFILE, overrides: dict | None = None,
                source: str | None = None) -> LocalizerConfig:
        """The configuration of profile ``name`` (``paper``: nav2's defaults; ``robot``: those
        with ``ROBOT_PROFILE``'s keys), with ``overrides`` laid over it key by key."""
        return config_from_profile(cls, ROBOT_PROFILE, name, overrides, LocalizationError,
                                   source)

    @classmethod
    def from_dict(cls, values: dict, source: str = "config") -> LocalizerConfig:
        """Build from a mapping; an unknown key is refused with the nearest valid name."""
        return config_from_dict(cls, values, LocalizationError, source)

    @classmethod
    def from_yaml(cls, path) -> LocalizerConfig:
        """Load from a YAML file holding the keys at the top level (or under ``localization:``,
        or ``localizer:`` as in the robot configuration file of ``onboard.robot_config``)."""
        return config_from_yaml(cls, path, LocalizationError, "localization", "localizer")


def _check(name, value, ok, what):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not ok(value):
        raise LocalizationError(f"config key '{name}' must be {what}, got {value!r}")
