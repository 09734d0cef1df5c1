"""What a run is asked to do (``RunOptions``) and who is told of its scans (``SessionObserver``):
shared by the runner and the run's checkpoints, which record the options and read them back."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from gridmap import MapUpdatingError

if TYPE_CHECKING:
    from gridmap import OccupancyGrid, Pose2D

    from .session import SessionResult


class RunError(MapUpdatingError, ValueError):
    """Run options no run can have; the message names the option."""


@dataclass
class RunOptions:
    out: Path | None = None
    seed: int | None = None
    sessions: int | None = None
    quick: bool = False
    progress: bool = True
    # The defaults of every configuration left None: "robot" or "paper" (onboard.robot_config);
    # None: robot, or, resuming, the run's own.
    profile: str | None = None
    updater_config: object | None = None      # an updater.UpdaterConfig; None: the profile's
    # a localization.LocalizerConfig, or a mapping of its keys laid over the profile's with
    # the scenario's odometry noise as alphas (session.localizer_config_for); None: no keys
    localizer_config: object | None = None
    observer: SessionObserver | None = None   # told of every update session's scans
    # The safeguard against mislocalisation (localization.confidence): scans whose pose the
    # localiser's covariance or the scan's own fit to M_{i-1} calls unsure change nothing.
    # None: as the profile has it.
    pose_check: bool | None = None
    pose_check_config: object | None = None   # a localization.confidence.PoseCheckConfig
    # Beside the updater of the profile, the paper profile's on the same scans and poses, for
    # the report's comparison columns (only when the run's profile is not the paper's)
    compare_paper: bool = True
    resume: bool = False       # continue the run in ``out`` after its last finished session
    method: str = "paper"      # what updates the map: one of onboard.methods.METHODS


class SessionObserver(Protocol):
    """What ``RunOptions.observer`` is told, e.g. to record a run (``rerun_log``). Its calls
    happen outside the timed parts of the session, so its cost never shows in the scores."""

    def session_start(self, scenario, session: int, world, previous: OccupancyGrid,
                      initial: OccupancyGrid, updater, localizer) -> None: ...

    def scan(self, msg, estimate: Pose2D, report, world, updater, localizer) -> None: ...

    def session_end(self, result: SessionResult) -> None: ...
