"""The live nodes' settings: their own parameters and the updater's and pose check's, read
from the node's parameters (ROS 1: ``~updater/threshold``; ROS 2: ``updater.threshold``) over
an optional config file with the same sections. Unknown or misspelt names are refused at start
with the nearest valid one, exactly as the YAML configs refuse them. No ROS import: a node
hands in its parameters as a nested dict.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, fields, replace
from pathlib import Path

from gridmap import MapUpdatingError
from gridmap.config import DEFAULT_PROFILE, check_profile
from gridmap.suggest import did_you_mean

from ..methods import ROBOT_METHODS, check_method
from ..outputs import check_outputs, map_files, map_inputs
from ..robot_config import (POSE_CHECK_ON, SECTIONS, differences, load_robot_config,
                            section_config)
from .scans import MAX_BEAMS


# A ROS topic name (ROS 1 and 2 agree on these): relative, absolute or private
TOPIC_NAME = re.compile(r"[~/]?/?[A-Za-z][A-Za-z0-9_/]*")
TOPIC_FIELDS = ("map_topic", "odom_topic", "pose_topic")
POSE_SOURCES = ("tf", "amcl_pose")
# [low, high] of the numeric parameters, checked here and declared as their ranges in ROS 2
BOUNDS = {"publish_period": (0.01, 3600.0), "tf_timeout": (0.0, 10.0),
          "smooth_poses": (0.0, 60.0), "store_poll_period": (0.1, 3600.0),
          "max_mount_tilt": (0.0, 0.5), "queue_size": (1, 100_000),
          "max_beams": (1, 1_000_000)}


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
    profile: str = DEFAULT_PROFILE       # the defaults of the configurations (robot, paper)
    use_pose_check: bool = True          # as `mapupdate update --pose-check` (default: the
                                         # profile's)
    smooth_poses: float = 2.0            # [s] as `mapupdate update --smooth-poses`; 0: off
    method: str = "paper"                # as `mapupdate update --method`: paper, fuse, hybrid
    store: str = ""                      # a map store (SQLite file or postgresql:// URL); "": none
    robot_name: str = ""                 # who commits to the store ("": the host's name)
    store_poll_period: float = 10.0      # [s] how often the store is asked for a newer version
    max_beams: int = MAX_BEAMS           # a scan with more beams is skipped, counted
    max_mount_tilt: float = 0.05         # [rad] a laser tilted more from level is not used

    def __post_init__(self):
        for name in ("map_frame", "odom_frame", "base_frame", "map_topic", "save_path"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise NodeSettingsError(f"parameter '~{name}' must be a non-empty string, got "
                                        f"{getattr(self, name)!r}")
        if not self.scan_topics or not all(isinstance(t, str) and t for t in self.scan_topics):
            raise NodeSettingsError(f"parameter '~scan_topics' must name one or more topics, "
                                    f"got {list(self.scan_topics)!r}")
        for name, topic in [("scan_topics", t) for t in self.scan_topics] + \
                [(n, getattr(self, n)) for n in TOPIC_FIELDS if hasattr(self, n)]:
            if not TOPIC_NAME.fullmatch(topic) or "//" in topic or topic.endswith("/"):
                raise NodeSettingsError(f"parameter '~{name}': {topic!r} is not a valid ROS "
                                        "topic name (letters, digits, _ and /, starting with a "
                                        "letter, / or ~)")
        for name in ("store", "robot_name"):
            if not isinstance(getattr(self, name), str):
                raise NodeSettingsError(f"parameter '~{name}' must be a string, got "
                                        f"{getattr(self, name)!r}")
        for name in ("publish_period", "tf_timeout", "smooth_poses", "store_poll_period",
                     "max_mount_tilt"):
            (low, high), v = BOUNDS[name], getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or \
                    not (math.isfinite(v) and low <= v <= high):
                unit = "rad" if name == "max_mount_tilt" else "s"
                raise NodeSettingsError(f"parameter '~{name}' must be a number in "
                                        f"[{low:g}, {high:g}] {unit}, got {v!r}")
        for name in ("queue_size", "max_beams"):
            (low, high), v = BOUNDS[name], getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
                raise NodeSettingsError(f"parameter '~{name}' must be a whole number in "
                                        f"[{low}, {high}], got {v!r}")
        check_profile(self.profile, NodeSettingsError, "parameter '~profile'")
        if not isinstance(self.use_pose_check, bool):
            raise NodeSettingsError(f"parameter '~use_pose_check' must be true or false, got "
                                    f"{self.use_pose_check!r}")

        check_method(self.method, "parameter '~method'", ROBOT_METHODS)


@dataclass(frozen=True)
class Ros2Settings(NodeSettings):
    """The ROS 2 node's parameters: the ROS 1 node's, and where its poses come from:
    ``pose_source`` "tf" (``map -> odom -> base_frame -> laser`` from /tf and /tf_static, as
    Nav2's nodes take them), or "amcl_pose" (amcl's pose with the odometry, composed as amcl
    composes its map -> odom, and the laser's mount from ``laser_mount``), for a graph whose
    tf2_msgs cannot be had."""

    pose_source: str = "tf"              # "tf" or "amcl_pose"
    odom_topic: str = "odom"             # nav_msgs/Odometry (pose_source amcl_pose)
    pose_topic: str = "amcl_pose"        # PoseWithCovarianceStamped (pose_source amcl_pose)
    laser_mount: tuple[float, float, float] = (0.0, 0.0, 0.0)   # [m, m, rad] (amcl_pose)
    autostart: bool = False              # configure and activate at once (no lifecycle manager)

    def __post_init__(self):
        super().__post_init__()
        if self.pose_source not in POSE_SOURCES:
            raise NodeSettingsError(f"parameter 'pose_source' must be one of "
                                    f"{', '.join(POSE_SOURCES)}, got {self.pose_source!r}")
        for name in ("odom_topic", "pose_topic"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise NodeSettingsError(f"parameter '{name}' must be a non-empty string, got "
                                        f"{getattr(self, name)!r}")
        m = self.laser_mount
        if not (isinstance(m, tuple) and len(m) == 3 and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                and abs(v) <= 100 for v in m)):
            raise NodeSettingsError(f"parameter 'laser_mount' must be three finite numbers "
                                    f"[x, y, yaw] (m, m, rad; at most 100), got {m!r}")
        if not isinstance(self.autostart, bool):
            raise NodeSettingsError(f"parameter 'autostart' must be true or false, got "
                                    f"{self.autostart!r}")


def node_settings(params: dict, base=None, kind: type = NodeSettings):
    """(settings, UpdaterConfig, PoseCheckConfig) from the node's parameters ``params`` laid
    key by key over ``base`` (a ``onboard.robot_config.RobotConfig`` from the ``--config`` file,
    or None); ``kind``: ``NodeSettings`` (ROS 1) or ``Ros2Settings``. A ``localizer`` section is
    accepted, for a file shared with ``mapupdate update``, and not used: the node takes its
    poses from the robot's localisation."""

    if not isinstance(params, dict):
        raise NodeSettingsError(f"private parameters must be a mapping, got {params!r}")
    own = [f.name for f in fields(kind)]
    for key in params:
        if key not in own and key not in SECTIONS:
            raise NodeSettingsError(f"unknown parameter '~{key}'"
                                    f"{did_you_mean(key, own + list(SECTIONS))}")
    file = load_robot_config(base)
    profile = params.get("profile", file.profile)
    check_profile(profile, NodeSettingsError, "parameter '~profile'")
    configs = {}
    for name in ("updater", "pose_check"):
        extra = params.get(name, {})
        if not isinstance(extra, dict):
            raise NodeSettingsError(f"parameter '~{name}' must be a mapping of keys, got "
                                    f"{extra!r}")
        # the profile's, the file's keys over it, the parameters' over those
        configs[name] = section_config(name, {**file.given.get(name, {}), **extra},
                                       "node parameters", where=f"'~{name}'", profile=profile)
    mine = {k: v for k, v in params.items() if k in own}
    mine["profile"] = profile
    mine.setdefault("use_pose_check", POSE_CHECK_ON[profile][0])
    if isinstance(mine.get("scan_topics"), (str, list)):
        topics = mine["scan_topics"]
        # a topic named twice is one subscription, not every scan taken twice
        mine["scan_topics"] = (topics,) if isinstance(topics, str) else \
            tuple(dict.fromkeys(topics))
    for name in ("publish_period", "tf_timeout", "smooth_poses", "store_poll_period",
                 "max_mount_tilt"):
        if isinstance(mine.get(name), int) and not isinstance(mine[name], bool):
            mine[name] = float(mine[name])        # YAML's 2 for 2.0
    if isinstance(mine.get("laser_mount"), list):
        mine["laser_mount"] = tuple(mine["laser_mount"])
    return replace(kind(), **mine), configs["updater"], configs["pose_check"]


def check_save_path(save_path: str) -> None:
    """Refuse, at start, a ``save_path`` that cannot be written: a folder, or a file in a
    folder that does not exist or cannot be written to (found at start, not at the first
    save, hours later)."""
    path = Path(save_path)
    if path.is_dir() or save_path.endswith(("/", os.sep)) or path.name in ("", ".", ".."):
        raise NodeSettingsError(f"parameter '~save_path' must name a map file (.yaml), got the "
                                f"folder {save_path!r}")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise NodeSettingsError(f"parameter '~save_path': the folder {str(folder)!r} does not "
                                "exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise NodeSettingsError(f"parameter '~save_path': the folder {str(folder)!r} cannot be "
                                "written to")


def refuse_saving_over_the_map(save_path: str, map_path) -> None:
    """A node's ``save_path`` may not be its input map (the YAML or the image it names): saving
    would overwrite the map the node started from. Refused at start."""
    if map_path is not None:
        check_outputs({"--map": map_inputs(map_path)}, {"~save_path": map_files(save_path)})


def profile_line(settings: NodeSettings, updater_config, pose_check_config) -> str:
    """What the node's startup log says of its configuration: the profile and every key that
    differs from it."""
    over = differences(settings.profile, updater_config, None, pose_check_config)
    if settings.use_pose_check != POSE_CHECK_ON[settings.profile][0]:
        over.insert(0, f"use_pose_check: {settings.use_pose_check} (profile "
                       f"{settings.profile}: {POSE_CHECK_ON[settings.profile][0]})")
    return (f"profile {settings.profile}, pose check {'on' if settings.use_pose_check else 'off'}"
            + (f"; over the profile: {'; '.join(over)}" if over else "; as the profile has it"))
