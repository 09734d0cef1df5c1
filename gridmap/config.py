"""Building frozen configuration dataclasses from mappings and YAML files, the one way every
package does it: unknown keys are refused with the nearest valid name."""

from __future__ import annotations

import math
from dataclasses import asdict, fields
from pathlib import Path

from .files import FileInputError, load_yaml
from .suggest import did_you_mean


def check_keys(values: dict, known, error: type[Exception], source: str,
               where: str | None = None) -> None:
    """Refuse the first key of ``values`` that is not in ``known`` with an ``error`` naming
    ``source``, ``where`` in it if given (e.g. "section 'updater'") and the nearest valid key."""
    known = list(known)
    for key in values:
        if key not in known:
            place = f" in {where}" if where else ""
            raise error(f"{source}: unknown key '{key}'{place}{did_you_mean(key, known)}")


def config_from_dict(cls, values, error: type[Exception], source: str):
    """``cls(**values)`` after refusing unknown keys (with a did-you-mean) and accepting ints
    where floats are expected (YAML writes 2 for 2.0); errors are ``error``s naming ``source``."""
    if not isinstance(values, dict):
        raise error(f"{source}: expected a mapping of keys, got {type(values).__name__}")
    check_keys(values, [f.name for f in fields(cls)], error, source)
    kwargs = {}
    for f in fields(cls):
        if f.name in values:
            v = values[f.name]
            if f.type in ("float", float) and isinstance(v, int) and not isinstance(v, bool):
                v = float(v)
            kwargs[f.name] = v
    try:
        return cls(**kwargs)
    except error as e:
        raise error(f"{source}: {e}") from None


def check_bounds(config, bounds: dict, error: type[Exception]) -> None:
    """Every field of ``config`` named in ``bounds`` ({name: (low, high)}) is a finite number
    (a whole one where the field is an int) within [low, high]; else an ``error`` naming the
    key, the range and the value. A bound on every number keeps a misspelt order of magnitude
    (a window of 1e9 degrees, a 1e300 m^2 area) from running for hours or failing deep inside a
    kernel."""
    for f in fields(config):
        if f.name not in bounds:
            continue
        low, high = bounds[f.name]
        v = getattr(config, f.name)
        whole = f.type in ("int", int)
        if isinstance(v, bool) or not isinstance(v, int if whole else (int, float)) or \
                not math.isfinite(v) or not low <= v <= high:
            kind = "a whole number" if whole else "a number"
            raise error(f"config key '{f.name}' must be {kind} in [{low:g}, {high:g}], "
                        f"got {v!r}")


def config_to_dict(config) -> dict:
    """The keys and values of a configuration dataclass, as ``config_from_dict`` takes them."""
    return asdict(config)


def config_from_yaml(cls, path, error: type[Exception], section: str, *also: str):
    """Load a configuration from YAML holding the keys at the top level or under ``section``
    (or under one of the other names ``also``)."""
    path = Path(path)
    try:
        values = load_yaml(path, f"{section} configuration", error) or {}
    except (OSError, FileInputError) as e:
        raise error(f"{path}: cannot read the {section} configuration: {e}") from None
    if isinstance(values, dict) and len(values) == 1 and next(iter(values)) in (section, *also):
        values = next(iter(values.values())) or {}
    return config_from_dict(cls, values, error, str(path))


# --- profiles ---------------------------------------------------------------------------------
# Two named sets of defaults for every configuration: ``paper`` (the paper and its authors'
# code: each class's own defaults) and ``robot`` (what a robot should run: the class's
# defaults with the keys of its module's ``ROBOT_PROFILE`` changed). docs/configuration.md
# lists every key where they differ and why.
PROFILES = ("paper", "robot")
DEFAULT_PROFILE = "robot"


def check_profile(name, error: type[Exception], where: str = "profile") -> str:
    """``name`` if it names a profile, else an ``error`` naming it, the nearest profile and
    the profiles there are."""
    if not isinstance(name, str) or name not in PROFILES:
        raise error(f"{where}: unknown profile {name!r}{did_you_mean(str(name), PROFILES)} "
                    f"(profiles: {', '.join(PROFILES)})")
    return name


def profile_values(robot_profile: dict, name: str) -> dict:
    """The keys a profile sets over the class's defaults: none for ``paper``, the values of
    ``robot_profile`` ({key: (value, why)}) for ``robot``."""
    return {k: v for k, (v, _why) in robot_profile.items()} if name == "robot" else {}


def config_from_profile(cls, robot_profile: dict, name: str, overrides: dict | None,
                        error: type[Exception], source: str | None = None):
    """``cls`` with the profile ``name``'s values, then ``overrides`` key by key (checked as
    ``config_from_dict`` checks a mapping)."""
    check_profile(name, error)
    if overrides is not None and not isinstance(overrides, dict):
        raise error(f"{source or 'config'}: expected a mapping of keys, got "
                    f"{type(overrides).__name__}")
    values = {**profile_values(robot_profile, name), **(overrides or {})}
    return config_from_dict(cls, values, error, source or f"profile '{name}'")
