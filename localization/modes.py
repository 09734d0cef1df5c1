"""Is a global localisation sure where the robot is, or only lucky? A room that looks the same
turned by 180 deg (a bare rectangle), or two identical aisles, gives the particles two places
of equal weight, and the filter keeps one of them by chance.

- ``pose_modes`` / ``ambiguous_modes``: the places a particle set holds, heaviest first.
  Clusters are AMCL's (touching bins of 0.5 m x 0.5 m x 10 deg, ``estimate.cluster_labels``);
  clusters within ``MODE_SEPARATION`` and ``MODE_SEPARATION_DEG`` of a heavier one are one
  place, since the bins split a spread cloud into pieces that are not separate answers. The
  set is ambiguous when a place farther than that holds at least ``SIMILAR_WEIGHT`` of the
  heaviest's weight (and the places hold most of the weight: a cloud still spread over the
  map holds no answer yet).
- ``StartWatch``: at the moment the filter is trusted the weights no longer tell, because the
  filter does not keep two equal places for long. In the bare 8 x 6 m room of the tests
  (5000 particles, KLD down to 500) the second place held 47 % of the weight at one update
  and 3 % at the next, with nothing in the scans to choose between them: the likelihood of
  60 beams is so sharp that the place whose particles happen to lie nearer the true pose
  takes nearly all the weight, and resampling drops the other. The tracking verdict then
  trusts the survivor (it wants 90 % of the weight in one cluster). So every place the
  particles hold with ``FOLLOW_WEIGHT`` of the heaviest's weight while the filter converges
  is followed by odometry and scored against each scan with the pose check's fit (at the
  best pose within its search grids, which also undoes the odometry's drift). Only the scans
  rule a place out: a scan counts against it by how much worse than the best place's its fit
  is, beyond ``FIT_TOLERANCE``, and it is dropped once that sum passes ``REFUTE_FIT``. When
  the filter is first trusted, the places left apart from the one it chose are the
  ambiguity.

Bounds (measured with 40 seeded starts on the tests' 8 x 6 m room; docs/reliability.md):

- 1 m or 30 deg: places that far apart are different answers for the map updater (the pose
  check already refuses 6 cm or 0.75 deg), and no single place's cloud spreads that far once
  the tracking verdict trusts it (0.15 m, 5 deg).
- ``SIMILAR_WEIGHT`` 1/3 for the particle-set check: a place with a third of the heaviest's
  weight is one a single update can overturn by sampling alone (above). It is too high for
  following, though: of the 20 starts in the bare room that settled on the mirror image, 9
  never gave the true place 1/3 of the heaviest's weight, 1 never gave it ``FOLLOW_WEIGHT``
  2 % (10 particles of 500). Following costs one fit per place and scan; the scans, not the
  weights, decide.
- ``FIT_TOLERANCE`` 0.005 and ``REFUTE_FIT`` 0.05: in the bare room a scan fits the mirror
  place worse than the true one by at most 0.004 in 99 % of 2700 comparisons (0.03 at worst),
  which beyond the tolerance summed past 0.05 in 1 of 20 whole logs (78 updates; a start
  here is trusted after 5 to 76, typically 6); a 0.6 m box in view makes it 0.025 (in a far
  corner) to 0.045 worse, which rules the mirror place out within two or three scans, before
  the filter is trusted. With a box in a corner (either of two), 36-37 of 40 starts settle
  on the right place and none of them is refused; the 2-3 that settle on the mirror place
  are refused (the box ruled it out, the filter kept it all the same), and one more settles
  on it unseen (the true place lost all its weight at the first update). On larger places
  no start was refused: the quick warehouse's W2 bag without its localisation (three
  identical shelves) went through several places of similar weight, all ruled out before
  the filter was trusted, and the SENA loop's start through none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gridmap import OccupancyGrid, Pose2D, Scan, wrap_angle

from .config import LocalizationError
from .confidence import PoseCheck, PoseCheckConfig
from .estimate import cluster_labels
from .resample import KldParameters

MODE_SEPARATION = 1.0           # [m] places farther apart than this ...
MODE_SEPARATION_DEG = 30.0      # [deg] ... or turned more than this are different answers
SIMILAR_WEIGHT = 1.0 / 3.0      # [1] a place with this share of the heaviest's weight competes
FOLLOW_WEIGHT = 0.02            # [1] ... and one with this share is followed (StartWatch)
FIT_TOLERANCE = 0.005           # [1] a scan's fit this close to the best place's is a tie ...
REFUTE_FIT = 0.05               # [1] ... and the excess beyond it, summed, rules a place out
HELD_WEIGHT = 0.5               # [1] places that hold less together are a cloud, not answers
MAX_CLUSTERS = 64               # the heaviest clusters merged into places
BINS = (0.5, 0.5, math.radians(10.0))   # [m, m, rad] AMCL's cluster bins


class AmbiguousStart(LocalizationError):
    """A global localisation that settled on one of several places the scans fit as well;
    ``poses``: those places (map frame) at the start of the log, the chosen one first."""

    def __init__(self, poses: list[Pose2D]):
        self.poses = list(poses)
        places = " and ".join(f"{p.x:.2f},{p.y:.2f},{p.theta:.2f}" for p in self.poses)
        super().__init__(f"global localisation is ambiguous: {len(self.poses)} poses of "
                         f"similar weight (x,y,th at the start of the log: {places}); give "
                         f"--initial-pose X Y TH")


@dataclass(frozen=True)
class Mode:
    """One place the particles hold: the weighted mean of its heaviest cluster, and the share
    of the particle weight in all its clusters."""

    pose: Pose2D
    weight: float


def far_apart(a: Pose2D, b: Pose2D) -> bool:
    """Different answers: more than MODE_SEPARATION or MODE_SEPARATION_DEG apart."""
    return math.hypot(a.x - b.x, a.y - b.y) > MODE_SEPARATION or \
        abs(wrap_angle(a.theta - b.theta)) > math.radians(MODE_SEPARATION_DEG)


def _checked(particles, weights) -> tuple[np.ndarray, np.ndarray]:
    p = np.ascontiguousarray(particles, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if p.shape[0] == 0 or p.shape[0] != w.shape[0] or not np.all(np.isfinite(p)) \
            or not np.all(np.isfinite(w)) or w.min() < 0 or w.sum() <= 0:
        raise LocalizationError("pose_modes needs N finite particles and N finite weights >= 0 "
                                "with a positive sum")
    return p, w


def pose_modes(particles, weights, bins=BINS) -> list[Mode]:
    """The places (``Mode``) of a weighted particle set (N, 3), heaviest first, each weight a
    share of the whole set's. ``bins``: the cluster bins [m, m, rad]. Only the
    ``MAX_CLUSTERS`` heaviest clusters count: a cloud in more pieces is still spread over the
    map (44 000 particles uniform over 6400 m^2 make 14 000), and merging them all would take
    minutes."""
    p, w = _checked(particles, weights)
    # only the bins matter to the clustering; the counts are the sampler's
    kld = KldParameters(min_particles=1, max_particles=1, pf_err=0.05, pf_z=0.99,
                        bin_size=np.asarray(bins, dtype=np.float64))
    labels, count = cluster_labels(p, kld)
    total = np.bincount(labels, weights=w, minlength=count)
    top = np.argsort(-total, kind="stable")[:MAX_CLUSTERS]
    top = top[total[top] > 0]
    x, y, s, c = (np.bincount(labels, weights=w * v, minlength=count)[top]
                  for v in (p[:, 0], p[:, 1], np.sin(p[:, 2]), np.cos(p[:, 2])))
    # the heading's circular mean, as the estimate takes it, so a cluster across +-pi holds
    poses = [Pose2D(float(a), float(b), float(t)) for a, b, t in
             zip(x / total[top], y / total[top], np.arctan2(s, c))]
    modes: list[Mode] = []
    for pose, weight in zip(poses, total[top] / w.sum()):
        near = next((k for k, m in enumerate(modes) if not far_apart(m.pose, pose)), None)
        if near is None:
            modes.append(Mode(pose, float(weight)))
        else:
            modes[near] = Mode(modes[near].pose, modes[near].weight + float(weight))
    return sorted(modes, key=lambda m: -m.weight)


def ambiguous_modes(particles, weights, bins=BINS, ratio: float = SIMILAR_WEIGHT
                    ) -> list[Mode]:
    """The places holding at least ``ratio`` of the heaviest's weight, when there are two or
    more of them and together they hold ``HELD_WEIGHT`` of the set's; else [] (one answer,
    or none yet)."""
    modes = pose_modes(particles, weights, bins)
    similar = [m for m in modes if m.weight >= ratio * modes[0].weight]
    held = sum(m.weight for m in similar)
    return similar if len(similar) >= 2 and held >= HELD_WEIGHT else []


@dataclass
class _Place:
    pose: Pose2D          # map frame, at the watch's latest odometry
    behind: float = 0.0   # [1] summed fit behind the best place's


class StartWatch:
    """Follows the places of similar weight a global start goes through, until the filter is
    first trusted (module docstring). ``observe`` after each filter update while it converges;
    ``refuse`` when it is first trusted. ``start_odometry``: the odometry pose at the start of
    the log, where ``AmbiguousStart`` gives its poses (what ``--initial-pose`` takes). The
    places outlive a restart over the whole map (``TrackingConfig.relocalise_after``): only
    the scans rule a place out."""

    def __init__(self, grid: OccupancyGrid, start_odometry: Pose2D,
                 config: PoseCheckConfig | None = None, ratio: float = FOLLOW_WEIGHT):
        self._grid, self._config, self.ratio = grid, config, ratio
        self._check: PoseCheck | None = None      # made when a second place first shows
        self._start = self._odom = start_odometry
        self.places: list[_Place] = []

    def observe(self, localizer, scan: Scan, mount: Pose2D, odometry: Pose2D,
                robot_pose: Pose2D) -> None:
        """After a filter update at ``odometry``: note the places of similar weight the
        particles hold now, and score every place noted so far against ``scan``;
        ``robot_pose``: the filter's estimate at the scan."""
        moved = odometry.relative_to(self._odom)
        self._odom = odometry
        for place in self.places:
            place.pose = place.pose.compose(moved)
        c = localizer.config
        for mode in ambiguous_modes(localizer.particles, localizer.weights,
                                    (c.kld_bin_xy, c.kld_bin_xy, c.kld_bin_theta), self.ratio):
            self._note(mode.pose)
        if self.places:
            self._score(scan, mount, robot_pose)

    def _note(self, pose: Pose2D) -> None:
        """A place of similar weight: the filter's own mean replaces a place noted near it."""
        for place in self.places:
            if not far_apart(place.pose, pose):
                place.pose = pose
                return
        self.places.append(_Place(pose))

    def _score(self, scan: Scan, mount: Pose2D, robot_pose: Pose2D) -> None:
        if self._check is None:
            self._check = PoseCheck(self._grid, self._config)
        best = []
        for place in self.places:
            f = self._check.fit(scan, place.pose, mount)
            if f is None:                  # a scan without a valid beam tells nothing
                return
            if f.gain > 0:                 # to the best pose nearby: odometry drifts
                x, y, th = place.pose.as_array() + f.correction.as_array()
                place.pose = Pose2D(float(x), float(y), wrap_angle(float(th)))
            best.append(f.fit - f.gain)
        # the filter's own estimate may fit better than every place followed: behind it too
        f = self._check.fit(scan, robot_pose, mount)
        floor = min(best + ([f.fit - f.gain] if f is not None else []))
        for place, b in zip(self.places, best):
            place.behind += max(b - floor - FIT_TOLERANCE, 0.0)
        kept: list[_Place] = []
        for place in sorted(self.places, key=lambda p: p.behind):
            # a place the search slid onto another is that place
            if place.behind <= REFUTE_FIT and all(far_apart(place.pose, k.pose) for k in kept):
                kept.append(place)
        self.places = kept

    def ambiguity(self, robot_pose: Pose2D) -> list[Pose2D]:
        """The places the scans still fit as well as ``robot_pose`` (the estimate the filter
        is first trusted with, at the latest odometry), that one first, carried back to the
        start of the log; [] when no other place is left."""
        others = [p.pose for p in self.places if far_apart(p.pose, robot_pose)]
        if not others:
            return []
        back = self._start.relative_to(self._odom)
        return [pose.compose(back) for pose in [robot_pose, *others]]

    def refuse(self, robot_pose: Pose2D) -> None:
        """Raise ``AmbiguousStart`` when ``ambiguity`` finds other places."""
        poses = self.ambiguity(robot_pose)
        if poses:
            raise AmbiguousStart(poses)
