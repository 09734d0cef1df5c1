"""The ROS 1 node's settings: its own parameters and the updater's and pose check's, read
from the node's private parameters (``~updater/threshold``, ``~pose_check/max_gain``, ...)
over an optional config file with the same sections. Unknown or misspelt names are refused
at start with the nearest valid one, exactly as the YAML configs refuse them. No ROS import:
the node hands in ``rospy.get_param("~")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

from gridmap import MapUpdatingError
from gridmap.suggest import did_you_mean
from localization.confidence import PoseCheckConfig
from updater import UpdaterConfig

from ..methods import ROBOT_METHODS, check_method
from ..robot_config import ROBOT_UPDATER_DEFAULTS, SECTIONS, load_robot_config, section_config


class NodeSettingsError(MapUpdatingError, ValueError):
    """A node parameter that cannot be used; the message names it."""


@dataclass(frozen=True)
class NodeSettings:
    """The node's own parameters, with ROS's usual defaults."""

    map_frame: str = "map"
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    scan_topics: tuple[str, ...] = ("scan",)
    map_topic: str = "map"               # the reference map, when --map is not given
    publish_period: float = 1.0          # [s] map_updated is published this often, if changed
    save_path: str = "map_updated.yaml"  # where ~save writes (map_server YAML + PGM)
    tf_timeout: float = 0.2              # [s] a scan waits this long for its transforms
    queue_size: int = 200                # scans waiting to be processed; older ones dropped
    use_pose_check: bool = False         # as `mapupdate update --pose-check`
    smooth_poses: float = 2.0            # [s] as `mapupdate update --smooth-poses`; 0: off
    method: str = "paper"                # as `mapupdate update --method`: paper, fuse, hybrid

    def __post_init__(self):
        for name in ("map_frame", "odom_frame", "base_frame", "map_topic", "save_path"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise NodeSettingsError(f"parameter '~{name}' must be a non-empty string, got "
                                        f"{getattr(self, name)!r}")
        if not self.scan_topics or not all(isinstance(t, str) and t for t in self.scan_topics):
            raise NodeSettingsError(f"parameter '~scan_topics' must name one or more topics, "
                                    f"got {list(self.scan_topics)!r}")
        for name, low, high in (("publish_period", 0.01, 3600.0), ("tf_timeout", 0.0, 10.0),
                                ("smooth_poses", 0.0, 60.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or \
                    not (math.isfinite(v) and low <= v <= high):
                raise NodeSettingsError(f"parameter '~{name}' must be a number in "
                                        f"[{low:g}, {high:g}] s, got {v!r}")
        if isinstance(self.queue_size, bool) or not isinstance(self.queue_size, int) or \
                not 1 <= self.queue_size <= 100_000:
            raise NodeSettingsError(f"parameter '~queue_size' must be a whole number in "
                                    f"[1, 100000], got {self.queue_size!r}")
        if not isinstance(self.use_pose_check, bool):
            raise NodeSettingsError(f"parameter '~use_pose_check' must be true or false, got "
                                    f"{self.use_pose_check!r}")

        check_method(self.method, "parameter '~method'", ROBOT_METHODS)


def node_settings(params: dict, base=None):
    """(NodeSettings, UpdaterConfig, PoseCheckConfig) from the node's private parameters
    ``params`` laid key by key over ``base`` (a ``scenarios.robot_config.RobotConfig`` from the
    ``--config`` file, or None). A ``localizer`` section is accepted, for a file shared with
    ``mapupdate update``, and not used: the node takes its poses from tf."""

    if not isinstance(params, dict):
        raise NodeSettingsError(f"private parameters must be a mapping, got {params!r}")
    own = [f.name for f in fields(NodeSettings)]
    for key in params:
        if key not in own and key not in SECTIONS:
            raise NodeSettingsError(f"unknown parameter '~{key}'"
                                    f"{did_you_mean(key, own + list(SECTIONS))}")
    given = load_robot_config(base).to_dict()
    configs = {}
    for name, default in (("updater", UpdaterConfig(**ROBOT_UPDATER_DEFAULTS)),
                          ("pose_check", PoseCheckConfig())):
        merged = given.get(name, default.to_dict())
        extra = params.get(name, {})
        if not isinstance(extra, dict):
            raise NodeSettingsError(f"parameter '~{name}' must be a mapping of keys, got "
                                    f"{extra!r}")
        configs[name] = section_config(name, {**merged, **extra}, "node parameters",
                                       where=f"'~{name}'")
    mine = {k: v for k, v in params.items() if k in own}
    if isinstance(mine.get("scan_topics"), (str, list)):
        topics = mine["scan_topics"]
        mine["scan_topics"] = (topics,) if isinstance(topics, str) else tuple(topics)
    if isinstance(mine.get("publish_period"), int) and not isinstance(mine["publish_period"], bool):
        mine["publish_period"] = float(mine["publish_period"])
    return replace(NodeSettings(), **mine), configs["updater"], configs["pose_check"]
