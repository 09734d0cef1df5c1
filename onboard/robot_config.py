"""The robot software's configuration in one file: a profile, and the updater's, the localiser's
and the pose check's keys laid over it.

    profile: robot           # or paper; optional (the command's --profile wins)
    updater:                 # keys of updater.UpdaterConfig
      threshold: 8
    localizer:               # keys of localization.LocalizerConfig
      max_particles: 3000
    pose_check:              # keys of localization.confidence.PoseCheckConfig
      slack_cells: 1

Two profiles, each defined once, in its component's module (``ROBOT_PROFILE`` in
``updater.config``, ``localization.config`` and ``localization.confidence``, and
``POSE_CHECK_ON`` here): ``paper``, the paper and its authors' code (the classes' own
defaults), and ``robot``, what a robot should run, the default of every entry point. A file,
a ROS parameter or a mapping lays its keys over the profile key by key: a section given
replaces no key it does not name. ``mapupdate run --config FILE``, ``mapupdate update
--config FILE`` and the nodes read a file, the gymnasium environment and sweep specs take the
same as a mapping (``config=``), and a run's checkpoint reads its recorded configurations
back through it. Unknown sections and keys are refused with the nearest valid name before
anything runs. docs/configuration.md lists every key where the profiles differ, and why.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path

from gridmap import MapUpdatingError
from gridmap.config import DEFAULT_PROFILE, check_keys, check_profile
from gridmap.files import FileInputError, load_yaml
from gridmap.suggest import did_you_mean
from localization import LocalizerConfig
from localization.confidence import PoseCheckConfig
from updater import UpdaterConfig

# Whether the pose check runs (``localization.confidence.PoseCheck``: scans whose pose the
# scan's own fit to the map, or the localiser's covariance, calls unsure change nothing), per
# profile, and why. The command line's --pose-check/--no-pose-check and the nodes'
# use_pose_check parameter say otherwise.
POSE_CHECK_ON = {
    "paper": (False, "the paper has no pose check"),
    "robot": (True, "a pose that is off frees what stands; the check refuses the scans whose "
              "pose a nearby one explains clearly better, and places a scan a few "
              "centimetres off at the pose nearby that fits it"),
}

# The sections of the file and the configuration each holds.
CLASSES = {"updater": UpdaterConfig, "localizer": LocalizerConfig, "pose_check": PoseCheckConfig}
SECTIONS = tuple(CLASSES)
TOP_KEYS = ("profile", *SECTIONS)


class ConfigError(MapUpdatingError, ValueError):
    """A configuration file or mapping that cannot be used; the message names the file, the
    section and the key."""


@dataclass(frozen=True, eq=True)
class RobotConfig:
    """A profile and the keys given over it (``given``: section -> {key: value}). The
    components' configurations are the profile's with those keys (``updater``, ``localizer``,
    ``pose_check``)."""

    profile: str = DEFAULT_PROFILE
    given: dict = field(default_factory=dict)

    @cached_property
    def updater(self) -> UpdaterConfig:
        return UpdaterConfig.profile(self.profile, self.given.get("updater"))

    @cached_property
    def localizer(self) -> LocalizerConfig:
        return LocalizerConfig.profile(self.profile, self.given.get("localizer"))

    @cached_property
    def pose_check(self) -> PoseCheckConfig:
        return PoseCheckConfig.profile(self.profile, self.given.get("pose_check"))

    @property
    def use_pose_check(self) -> bool:
        """Whether the profile runs the pose check."""
        return POSE_CHECK_ON[self.profile][0]

    def localizer_over(self, base: dict) -> LocalizerConfig:
        """The localiser's configuration with ``base`` (e.g. the alphas of a simulated robot's
        known odometry noise) laid over the profile, and the keys given over that."""
        return LocalizerConfig.profile(self.profile, {**base, **self.given.get("localizer", {})})

    def to_dict(self) -> dict:
        """The profile and the keys given, as ``load_robot_config`` takes them."""
        return {"profile": self.profile, **{k: dict(v) for k, v in self.given.items()}}

    def differences(self) -> list[str]:
        """Every key whose value differs from the profile's, as ``section.key: value (profile
        P: default)``; empty when the configuration is the profile's."""
        return differences(self.profile, self.updater, self.localizer, self.pose_check)


def differences(profile: str, updater=None, localizer=None, pose_check=None) -> list[str]:
    """The keys of the configurations given (None: not compared) whose values differ from
    profile ``profile``'s, one line each."""
    out = []
    for name, config in (("updater", updater), ("localizer", localizer),
                         ("pose_check", pose_check)):
        if config is None:
            continue
        default = CLASSES[name].profile(profile).to_dict()
        for key, value in config.to_dict().items():
            if value != default[key]:
                out.append(f"{name}.{key}: {value!r} (profile {profile}: {default[key]!r})")
    return out


def load_robot_config(given, source: str | None = None, profile: str | None = None
                      ) -> RobotConfig:
    """A ``RobotConfig`` from a YAML file's path, a mapping of sections, a ``RobotConfig`` or
    None (nothing given). ``profile``: the profile to lay the keys over (None: the file's
    ``profile`` key, else ``robot``); given, it wins over the file's. ``source`` names the
    origin in errors (default: the path, or "config"). Raises ``ConfigError`` for an
    unreadable file, an unknown profile, section or key, and the component's own error (a
    ``MapUpdatingError``) for a bad value."""
    if profile is not None:
        check_profile(profile, ConfigError, "--profile")
    if isinstance(given, RobotConfig):
        given = given.to_dict()
    if isinstance(given, (str, Path)):
        source = source or str(given)
        given = _read_yaml(Path(given))
    source = source or "config"
    if given is None:
        given = {}            # nothing given, or an empty file
    if not isinstance(given, dict):
        raise ConfigError(f"{source}: expected a mapping of sections ({', '.join(SECTIONS)}), "
                          f"got {type(given).__name__}")
    for name in given:
        if name not in TOP_KEYS:
            raise ConfigError(f"{source}: unknown section '{name}'{_section_hint(name)}")
    name = profile or given.get("profile") or DEFAULT_PROFILE
    check_profile(name, ConfigError, f"{source}: profile")
    # an empty section (YAML "updater:" with nothing under it) is no section
    sections = {}
    for section in SECTIONS:
        values = given.get(section)
        if values in (None, {}):
            continue
        section_config(section, values, source, profile=name)      # checked now, once
        sections[section] = dict(values)
    return RobotConfig(name, sections)


def _section_hint(name) -> str:
    """The nearest section; or, for a key of a section at the top level (a file of updater keys
    alone, as ``mapupdate update --config`` once read), the section it belongs under."""
    near = did_you_mean(name, TOP_KEYS)
    if near:
        return near
    for section, cls in CLASSES.items():
        if name in [f.name for f in fields(cls)]:
            return f" ('{name}' is a key of section '{section}': put it under '{section}:')"
    return f" (sections: {', '.join(SECTIONS)})"


def section_config(name: str, values, source: str, where: str | None = None,
                   profile: str = DEFAULT_PROFILE):
    """The configuration of section ``name`` (one of ``SECTIONS``): profile ``profile``'s
    with the keys of ``values`` laid over it; ``where`` says in errors where the mapping is
    (default: "section '<name>'")."""
    cls = CLASSES[name]
    where = where or f"section '{name}'"
    if not isinstance(values, dict):
        raise ConfigError(f"{source}: {where} must be a mapping of keys, got "
                          f"{type(values).__name__}")
    check_keys(values, [f.name for f in fields(cls)], ConfigError, source, where)
    return cls.profile(profile, values, source=f"{source}, {where}")


def profile_table() -> list[tuple[str, str, str, str, str]]:
    """(component, key, paper, robot, why) for every key where the profiles differ: the table
    of docs/configuration.md."""
    from localization import config as localizer_module
    from localization import confidence
    from updater import config as updater_module

    rows = [("pipeline", "pose check", str(POSE_CHECK_ON["paper"][0]).lower(),
             str(POSE_CHECK_ON["robot"][0]).lower(), POSE_CHECK_ON["robot"][1])]
    for name, module in (("updater", updater_module), ("localizer", localizer_module),
                         ("pose_check", confidence)):
        paper = CLASSES[name]().to_dict()
        for key, (value, why) in module.ROBOT_PROFILE.items():
            rows.append((name, key, _show(paper[key]), _show(value), why))
    return rows


def _show(value) -> str:
    return str(value).lower() if isinstance(value, bool) else f"{value:g}" \
        if isinstance(value, float) else str(value)


def profile_table_markdown() -> str:
    lines = ["| component | key | paper | robot | why |", "|---|---|---|---|---|"]
    lines += [f"| {c} | `{k}` | {p} | {r} | {w} |" for c, k, p, r, w in profile_table()]
    return "\n".join(lines) + "\n"


def _read_yaml(path: Path):
    try:
        return load_yaml(path, "configuration file", ConfigError)
    except FileNotFoundError:
        raise ConfigError(f"{path}: configuration file not found") from None
    except FileInputError as e:
        raise ConfigError(str(e)) from None


if __name__ == "__main__":      # python -m onboard.robot_config: the table of the profiles
    print(profile_table_markdown(), end="")
