"""The ROS 2 node's parameters in Nav2's style: given in a parameters file
(``--ros-args --params-file FILE``) or one by one (``-p updater.threshold:=8``), validated as
the project's YAML configs are (a misspelt name is refused with the nearest valid one), then
declared read-only with a description and, for numbers, their range, so that ``ros2 param
describe`` shows them. No rclpy import at module level: the node hands itself in."""

from __future__ import annotations

import dataclasses

from localization.confidence import POSE_CHECK_BOUNDS
from updater.config import BOUNDS as UPDATER_BOUNDS

# parameters every ROS 2 node has, which are not the node's settings
ROS_OWN = ("use_sim_time", "start_type_description_service")


def overrides_as_dict(node) -> dict:
    """The parameters given to ``node`` at start (file or command line), as the nested dict
    the settings take: ``updater.threshold`` -> ``{"updater": {"threshold": ...}}``."""
    out: dict = {}
    # rclpy keeps the values given for names the node has not declared (yet) here
    for name, param in node._parameter_overrides.items():
        if name in ROS_OWN or name.startswith("qos_overrides."):
            continue
        value = param.value
        if not isinstance(value, (str, bytes)) and hasattr(value, "__len__"):
            value = list(value)
        *sections, key = name.split(".")
        here = out
        for s in sections:
            here = here.setdefault(s, {})
            if not isinstance(here, dict):
                break
        else:
            here[key] = value
    return out


def declare_all(node, settings, updater_config, pose_check_config) -> None:
    """Declare every parameter with the value in use, read-only, described."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    def declare(name, value, bounds=None, about=""):
        if node.has_parameter(name):
            return
        if isinstance(value, tuple):
            value = list(value)
        d = ParameterDescriptor(name=name, description=about, read_only=True)
        if bounds is not None and isinstance(value, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(bounds[0]),
                                                         to_value=float(bounds[1]), step=0.0)]
        elif bounds is not None and isinstance(value, int) and not isinstance(value, bool):
            d.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]),
                                            step=1)]
        node.declare_parameter(name, value, d)

    for f in dataclasses.fields(settings):
        declare(f.name, getattr(settings, f.name), about=f"the node's {f.name}")
    for section, config, bounds in (("updater", updater_config, UPDATER_BOUNDS),
                                    ("pose_check", pose_check_config, POSE_CHECK_BOUNDS)):
        for key, value in dataclasses.asdict(config).items():
            declare(f"{section}.{key}", value, bounds.get(key),
                    f"{section} key {key} (as in the --config file)")
