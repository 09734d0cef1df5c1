"""What a pose check says of the pose a scan is to be placed at: the typed answer that the map
updater acts on and the robot pipeline counts. Lives in ``gridmap`` so that the localiser (who
makes the check) and the updater (who obeys it) share it without importing each other."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .types import Pose2D


class Verdict(enum.Enum):
    ACCEPTED = "accepted"   # the pose can be trusted as given
    REFINED = "refined"     # trusted, and a better sensor pose is given to use instead
    REFUSED = "refused"     # not trusted: the scan must change nothing


@dataclass(frozen=True)
class PoseVerdict:
    """A pose check's answer; build it with ``accepted()``, ``refined(pose)`` or
    ``refused(reason)``."""

    verdict: Verdict
    sensor_pose: Pose2D | None = None   # REFINED: the sensor pose (map frame) to use
    reason: str = ""                    # REFUSED: why, for people to read

    @classmethod
    def accepted(cls) -> PoseVerdict:
        return cls(Verdict.ACCEPTED)

    @classmethod
    def refined(cls, sensor_pose: Pose2D) -> PoseVerdict:
        return cls(Verdict.REFINED, sensor_pose=sensor_pose)

    @classmethod
    def refused(cls, reason: str) -> PoseVerdict:
        return cls(Verdict.REFUSED, reason=reason)

    @property
    def is_refused(self) -> bool:
        return self.verdict is Verdict.REFUSED
