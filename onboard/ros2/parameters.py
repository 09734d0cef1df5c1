"""The ROS 2 node's parameters in Nav2's style, declared in the node's constructor (so ``ros2
param list`` and ``describe`` see them from the start) with a description and, for numbers,
their range, read-only. Given in a parameters file (``--ros-args --params-file FILE``, under
the node's name or ``/**``) or one by one (``-p updater.threshold:=8``), they are validated as
the project's YAML configs are: a value of the wrong type or out of range, or a misspelt key of
the ``updater`` or ``pose_check`` section, fails the configure transition with one line naming
it. A name that is none of the node's (another node's key in a ``/**`` file, such as
``global_frame``) is left alone, said once in the log with the nearest of the node's names.

The node is made with ``automatically_declare_parameters_from_overrides``: rclpy declares every
name given; ``given_parameters`` reads them and undeclares them, so that each of the node's own
is declared again with its type and range, from the validated value. No private rclpy API."""

from __future__ import annotations

import dataclasses

from gridmap.suggest import did_you_mean
from localization.confidence import POSE_CHECK_BOUNDS
from updater.config import BOUNDS as UPDATER_BOUNDS

from ..robot_config import SECTIONS
from ..ros_common.settings import BOUNDS as NODE_BOUNDS
from ..ros_common.settings import Ros2Settings

# parameters every ROS 2 node has, which are not the node's settings
ROS_OWN = ("use_sim_time", "start_type_description_service")
QOS_PREFIX = "qos_overrides."


def given_parameters(node) -> tuple[dict, list[str]]:
    """(the node's own parameters given at start, as the nested dict the settings take:
    ``updater.threshold`` -> ``{"updater": {"threshold": ...}}``; the names given that are not
    the node's). QoS overrides are left to the subscriptions that declare them."""
    own = [f.name for f in dataclasses.fields(Ros2Settings)]
    nested: dict = {}
    foreign = []
    for name, param in sorted(node.get_parameters_by_prefix("").items()):
        if name in ROS_OWN:
            continue
        node.undeclare_parameter(name)
        if name.startswith(QOS_PREFIX):
            continue
        *sections, key = name.split(".")
        if (sections[0] if sections else key) not in (*own, *SECTIONS):
            foreign.append(name + did_you_mean(name, own))
            continue
        value = param.value
        if not isinstance(value, (str, bytes)) and hasattr(value, "__len__"):
            value = list(value)
        here = nested
        for s in sections:
            here = here.setdefault(s, {})
            if not isinstance(here, dict):
                break
        else:
            here[key] = value
    return nested, foreign


def valueless(argv) -> list[str]:
    """The parameters given no value (``[]``, ``~``) in the parameter files of ``argv``: rclpy
    cannot declare them, and refuses to make the node at all. Named so that the error can say
    which they are."""
    import yaml

    files = [argv[k + 1] for k, a in enumerate(argv[:-1]) if a == "--params-file"]
    found = []

    def walk(tree, prefix):
        for key, value in (tree.items() if isinstance(tree, dict) else ()):
            if isinstance(value, dict):
                walk(value, f"{prefix}{key}.")
            elif value is None or value == []:
                found.append(f"{prefix}{key}")

    for path in files:
        try:
            with open(path, encoding="utf-8") as f:
                nodes = yaml.safe_load(f) or {}
        except (OSError, yaml.YAMLError):
            continue
        for section in (nodes.values() if isinstance(nodes, dict) else ()):
            if isinstance(section, dict):
                walk(section.get("ros__parameters", {}), "")
    return found


def declare_all(node, settings, updater_config, pose_check_config) -> None:
    """Declare every parameter with the value in use, read-only, described, with its range."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    def declare(name, value, bounds=None, about=""):
        if isinstance(value, tuple):
            value = list(value)
        d = ParameterDescriptor(name=name, description=about, read_only=True)
        if bounds is not None and isinstance(value, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(bounds[0]),
                                                         to_value=float(bounds[1]), step=0.0)]
        elif bounds is not None and isinstance(value, int) and not isinstance(value, bool):
            d.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]),
                                            step=1)]
        # the value was read and validated already: a given 2 for a number is 2.0 by now
        node.declare_parameter(name, value, d, ignore_override=True)

    for f in dataclasses.fields(settings):
        declare(f.name, getattr(settings, f.name), NODE_BOUNDS.get(f.name),
                f"the node's {f.name}")
    for section, config, bounds in (("updater", updater_config, UPDATER_BOUNDS),
                                    ("pose_check", pose_check_config, POSE_CHECK_BOUNDS)):
        for key, value in dataclasses.asdict(config).items():
            declare(f"{section}.{key}", value, bounds.get(key),
                    f"{section} key {key} (as in the --config file)")
