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
    updater_config: object | None = None      # an updater.UpdaterConfig; None: its defaults
    # a localization.LocalizerConfig; None: session.localizer_config_for(scenario)
    localizer_config: object | None = None
    observer: SessionObserver | None = None   # told of every update session's scans
    # The safeguard against mislocalisation (localization.confidence): scans whose pose the
    # localiser's covariance or the scan's own fit to M_{i-1} calls unsure change nothing.
    pose_check: bool = True
    pose_check_config: object | None = None   # a localization.confidence.PoseCheckConfig
    resume: bool = False       # continue the run in ``out`` after its last finished session
    method: str = "paper"      # what updates the map: one of scenarios.methods.METHODS


class SessionObserver(Protocol):
    """What ``RunOptions.observer`` is told, e.g. to record a run (``rerun_log``). Its calls
    happen outside the timed parts of the session, so its cost never shows in the scores."""

    def session_start(self, scenario, session: int, world, previous: OccupancyGrid,
                      initial: OccupancyGrid, updater, localizer) -> None: ...

    def scan(self, msg, estimate: Pose2D, report, world, updater, localizer) -> None: ...

    def session_end(self, result: SessionResult) -> None: ...
