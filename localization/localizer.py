"""The Monte Carlo localiser: AMCL's filter (nav2's parameters) on an occupancy grid.

One filter update, when the robot has moved far enough since the last one:
sample_motion (odometry motion model) -> likelihood_field (log-likelihood of each particle)
-> weights (tempered if the scan alone would leave under min_ess_fraction of the particles
effective) -> estimate (heaviest cluster) -> kld_resample (every resample_interval updates, with
Augmented MCL's random samples). Between updates the estimate is carried forward by odometry:
``Estimate.pose_at``. localization/README.md lists where and why this departs from nav2.
"""

from __future__ import annotations

import math

import numpy as np

from gridmap import FREE, OccupancyGrid, Pose2D, Scan
from gridmap.config import DEFAULT_PROFILE

from .config import LocalizationError, LocalizerConfig
from .estimate import Estimate, estimate
from .motion import sample_motion
from .resample import (KldParameters, Recovery, Scratch, kld_resample, log_sum_exp, normalise,
                       temper)
from .sensor import LikelihoodField, likelihood_field, select_beams

IDENTITY = Pose2D(0.0, 0.0, 0.0)


class MonteCarloLocalizer:
    """AMCL-like localiser. ``config``: None for profile ``profile``'s (robot: nav2's with a
    filter update every 0.1 m; paper: nav2's). ``seed`` (int or ``numpy.random.SeedSequence``) feeds the one
    Generator every random draw of the filter comes from: the same seed and inputs give the same
    particles, bit for bit.

    >>> loc = MonteCarloLocalizer(grid, LocalizerConfig(), seed=7)       # doctest: +SKIP
    >>> loc.initialize(Pose2D(0, -8, 1.57), np.diag([0.25, 0.25, 0.07]))  # doctest: +SKIP
    >>> for odom, scan in log:                                          # doctest: +SKIP
    ...     loc.update(odom, scan, sensor_mount=Pose2D(0.25, 0, 0))
    ...     pose = loc.estimate().pose_at(odom)
    """

    def __init__(self, grid: OccupancyGrid, config: LocalizerConfig | None = None, seed=0, *,
                 profile: str = DEFAULT_PROFILE):
        self.config = LocalizerConfig.profile(profile) if config is None else config
        if not isinstance(self.config, LocalizerConfig):
            raise LocalizationError(f"config must be a LocalizerConfig, got {type(config).__name__}")
        if not isinstance(seed, (int, np.integer, np.random.SeedSequence)) or isinstance(seed, bool):
            raise LocalizationError(f"seed must be an int or a numpy SeedSequence, got {seed!r}")
        self._rng = np.random.default_rng(seed)
        c = self.config
        self._kld = KldParameters(c.min_particles, c.max_particles, c.pf_err, c.pf_z,
                                  np.array([c.kld_bin_xy, c.kld_bin_xy, c.kld_bin_theta]))
        self._recovery = Recovery(c.recovery_alpha_slow, c.recovery_alpha_fast)
        self._particles = np.empty((0, 3))
        self._weights = np.empty(0)
        self._odom_ref: Pose2D | None = None     # odometry at the last filter update
        self._last_odom: Pose2D | None = None
        self._updates = 0                        # sensor updates, for resample_interval
        self._estimate: Estimate | None = None
        self._scratch = Scratch()
        self.set_map(grid)

    # --- the map ---------------------------------------------------------------------------
    def set_map(self, grid: OccupancyGrid) -> None:
        """Use another map from the next update on (e.g. the updater's latest); the particles,
        the estimate and the odometry history are kept."""
        if not isinstance(grid, OccupancyGrid):
            raise LocalizationError(f"the map must be an OccupancyGrid, got {type(grid).__name__}")
        c = self.config
        self._field = LikelihoodField(grid, c.laser_likelihood_max_dist, c.z_hit, c.z_rand,
                                      c.sigma_hit, c.laser_model_type, c.importance_factor)
        self._free_cells = np.flatnonzero(grid.data.reshape(-1) == FREE)

    @property
    def grid(self) -> OccupancyGrid:
        return self._field.grid

    # --- initialisation --------------------------------------------------------------------
    def initialize(self, pose: Pose2D, cov) -> None:
        """Start from a Gaussian around ``pose`` with covariance ``cov`` (3 x 3, x y theta),
        with max_particles particles as AMCL does. ``pose`` is where the robot is at the
        latest odometry (or at the next, if none has been seen yet)."""
        if not isinstance(pose, Pose2D) or not pose.is_finite():
            raise LocalizationError(f"initial pose must be a finite Pose2D, got {pose!r}")
        cov = np.asarray(cov, dtype=np.float64)
        if cov.shape != (3, 3) or not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T):
            raise LocalizationError("initial covariance must be a finite symmetric 3 x 3 array")
        vals, vecs = np.linalg.eigh(cov)
        if vals.min() < -1e-9 * max(1.0, vals.max()):
            raise LocalizationError(f"initial covariance is not positive semi-definite "
                                    f"(eigenvalues {vals})")
        n = self.config.max_particles
        draws = self._rng.standard_normal((n, 3)) @ (vecs * np.sqrt(np.clip(vals, 0, None))).T
        particles = pose.as_array() + draws
        particles[:, 2] = (particles[:, 2] + math.pi) % (2 * math.pi) - math.pi
        self._start(particles, pose, cov)

    def initialize_global(self, particles: int | None = None) -> None:
        """Start from ``particles`` particles (default max_particles, as AMCL) uniform over the
        free cells, headings uniform. A large place needs more than a tracking filter does;
        KLD-sampling brings the count down as the cloud converges."""
        if self._free_cells.size == 0:
            raise LocalizationError("global initialisation needs a map with free cells")
        n = self.config.max_particles if particles is None else particles
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise LocalizationError(f"particles must be an integer >= 1, got {particles!r}")
        self._start(self.random_free_poses(int(n)), None, None)

    @property
    def free_area(self) -> float:
        """[m^2] the free space of the map, where a global start spreads its particles."""
        return float(self._free_cells.size * self._field.grid.resolution ** 2)

    def random_free_poses(self, n: int) -> np.ndarray:
        """``n`` poses (n, 3) uniform over the map's free cells (anywhere within a cell)."""
        grid = self._field.grid
        cells = self._free_cells[self._rng.integers(self._free_cells.size, size=n)]
        rows, cols = np.divmod(cells, grid.width)
        offsets = self._rng.random((n, 2))
        x = grid.origin[0] + (cols + offsets[:, 0]) * grid.resolution
        y = grid.origin[1] + (rows + offsets[:, 1]) * grid.resolution
        theta = self._rng.uniform(-math.pi, math.pi, n)
        return np.column_stack((x, y, theta))

    def _start(self, particles, pose, cov):
        self._particles = np.ascontiguousarray(particles, dtype=np.float64)
        self._weights = np.full(len(particles), 1.0 / len(particles))
        self._recovery.reset()
        self._updates = 0
        # A re-initialisation during a run holds from the latest odometry on.
        self._odom_ref = self._last_odom
        if pose is None:
            mean, cov, share = estimate(self._particles, self._weights, self._kld)
            pose, cov = Pose2D.from_array(mean), cov
        odom = self._last_odom if self._last_odom is not None else IDENTITY
        self._estimate = Estimate(pose, cov.copy(), pose, odom)

    # --- the filter ------------------------------------------------------------------------
    def update(self, odometry_pose: Pose2D, scan: Scan, sensor_mount: Pose2D) -> bool:
        """Feed one scan with the odometry pose at its time and the sensor's mount on the robot.
        Returns True when the filter updated (motion, sensor, and resampling when due): the
        first call only records odometry, and later calls update once the robot has moved
        update_min_d or turned update_min_a since the last update."""
        if self._particles.shape[0] == 0:
            raise LocalizationError("call initialize() or initialize_global() before update()")
        for name, p in (("odometry_pose", odometry_pose), ("sensor_mount", sensor_mount)):
            if not isinstance(p, Pose2D) or not p.is_finite():
                raise LocalizationError(f"{name} must be a finite Pose2D, got {p!r}")
        if not isinstance(scan, Scan):
            raise LocalizationError(f"scan must be a Scan, got {type(scan).__name__}")
        self._last_odom = odometry_pose
        if self._odom_ref is None:
            self._odom_ref = odometry_pose
            e = self._estimate
            self._estimate = Estimate(e.pose, e.cov, e.correction_pose, odometry_pose,
                                      e.cluster_weight)
            return False
        moved = odometry_pose.relative_to(self._odom_ref)
        if math.hypot(moved.x, moved.y) < self.config.update_min_d \
                and abs(moved.theta) < self.config.update_min_a:
            return False
        sample_motion(self._particles, self._odom_ref, odometry_pose, self.config.alphas,
                      self._rng, self._scratch.noise(self._particles.shape[0]))
        self._odom_ref = odometry_pose
        self._sensor_update(scan, sensor_mount)
        mean, cov, share = estimate(self._particles, self._weights, self._kld, self._scratch)
        pose = Pose2D.from_array(mean)
        self._estimate = Estimate(pose, cov, pose, odometry_pose, share)
        self._updates += 1
        if self._updates % self.config.resample_interval == 0:
            self._resample()
        return True

    def _sensor_update(self, scan: Scan, sensor_mount: Pose2D) -> None:
        c = self.config
        beams = select_beams(scan, c.max_beams, c.laser_min_range, c.laser_max_range)
        if beams.count == 0:                     # nothing returned: the scan says nothing
            return
        log_p = likelihood_field(self._field, self._particles, sensor_mount, beams)
        with np.errstate(divide="ignore"):
            log_prior = np.log(self._weights)
        log_avg, self._weights = _weigh(log_prior, log_p, c.min_ess_fraction)
        if c.laser_model_type == "likelihood_field_prob":
            # Per beam (the geometric mean of pz): a product over 60 beams moves by several
            # nats when a few beams meet a moved pallet, which would read as "lost" and scatter
            # most particles; per beam, only a scan that disagrees as a whole does.
            log_avg /= beams.count * c.importance_factor
        self._recovery.observe(log_avg)

    def _resample(self) -> None:
        inject = self._recovery.injection_probability()
        self._particles = np.ascontiguousarray(kld_resample(
            self._particles, self._weights, self._kld, self._rng, self.config.resampler,
            inject, self.random_free_poses, self._scratch))
        self._weights = np.full(self._particles.shape[0], 1.0 / self._particles.shape[0])

    # --- results ---------------------------------------------------------------------------
    def estimate(self) -> Estimate:
        """The latest estimate; valid from initialisation on (``correction_odom`` is the identity
        until the first ``update`` has recorded odometry)."""
        if self._estimate is None:
            raise LocalizationError("no estimate before initialize() or initialize_global()")
        return self._estimate

    @property
    def particles(self) -> np.ndarray:
        """A copy of the particles (N, 3): x [m], y [m], theta [rad]."""
        return self._particles.copy()

    @property
    def weights(self) -> np.ndarray:
        """A copy of the normalised weights (N,)."""
        return self._weights.copy()

    @property
    def particle_count(self) -> int:
        return int(self._particles.shape[0])


def _weigh(log_prior: np.ndarray, log_p: np.ndarray, min_fraction: float):
    """(log of the measurement's likelihood under the prior, the new normalised weights).

    The likelihood, log sum(w_prior * p), feeds the recovery averages (Probabilistic Robotics'
    w_avg; it is mean(p) after a resampling). The weights are prior * p, tempered (``temper``)
    if p alone would leave under ``min_fraction`` of the particles effective. Untempered, the
    sum, the effective fraction and the weights all start from the same exp(log w - max), so it
    is taken once: the very numbers ``log_sum_exp``, ``temper`` and a fresh exp would give."""
    joint = log_prior + log_p
    top = float(np.max(joint))
    if not math.isfinite(top):
        beta = temper(log_prior, log_p, min_fraction)
        log_w = log_prior + beta * log_p
        return log_sum_exp(joint), normalise(np.exp(log_w - np.max(log_w)))
    e = np.exp(joint - top)                  # finite, in [0, 1], its largest 1
    total = e.sum()
    log_avg = top + math.log(float(total))
    if min_fraction <= 0 or float(total ** 2 / (e.size * (e @ e))) >= min_fraction:
        # beta = 1: prior + 1 * p is joint to the bit; e needs none of normalise's checks
        return log_avg, e / total
    beta = temper(log_prior, log_p, min_fraction)
    log_w = log_prior + beta * log_p
    return log_avg, normalise(np.exp(log_w - np.max(log_w)))
