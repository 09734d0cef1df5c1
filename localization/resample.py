"""Resampling: filterpy's resampling schemes, reproducible, with any output count; KLD-sampling;
Augmented MCL's recovery.

filterpy.monte_carlo's resamplers draw from NumPy's global random state, return exactly as many
indices as there are weights, and run a Python loop per particle (systematic and stratified).
``resample_indices`` keeps filterpy's schemes exactly (same positions, same selection rule:
the first particle whose cumulative weight exceeds the position) but draws its random numbers
from the localiser's own Generator, vectorises the search with ``np.searchsorted`` and takes the
output count as an argument, which KLD-sampling needs. The tests check it index for index against
filterpy fed the same random numbers; filterpy itself is a dependency of the tests and the
benchmark only, never imported here. Residual resampling deliberately differs: filterpy 2.0 takes
the fractional parts as ``weights - floor(N * weights)``, which is not a distribution; here they
are ``N * weights - floor(N * weights)`` (Liu and Chen 1998).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import RESAMPLERS, LocalizationError


def _kernels():
    from . import _kernels

    return _kernels


def normalise(weights) -> np.ndarray:
    """Weights as float64 summing to 1; uniform when they carry no information (all zero)."""
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.size == 0:
        raise LocalizationError(f"weights must be a non-empty 1D array, got shape {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise LocalizationError("weights must be finite and >= 0")
    total = w.sum()
    if total <= 0:
        return np.full(w.size, 1.0 / w.size)
    return w / total


def cumulative(weights: np.ndarray) -> np.ndarray:
    """Cumulative sum of normalised weights with the last entry exactly 1, so that no position
    in [0, 1) can fall past the end through round-off."""
    return _cumulative(normalise(weights))


def _cumulative(w: np.ndarray) -> np.ndarray:
    """``cumulative`` of weights that ``normalise`` has already checked: normalised again, as
    the result has always been (their sum is 1 only to round-off)."""
    total = w.sum()
    c = np.cumsum(np.full(w.size, 1.0 / w.size) if total <= 0 else w / total)
    c[-1] = 1.0
    return c


def resample_indices(weights, count: int, rng: np.random.Generator,
                     scheme: str = "systematic") -> np.ndarray:
    """Indices (count,) of the particles drawn in proportion to ``weights``; a particle of weight
    0 is never drawn. Systematic and stratified indices come out sorted."""
    if scheme not in RESAMPLERS:
        raise LocalizationError(f"unknown resampling scheme {scheme!r}; one of {RESAMPLERS}")
    if count < 1:
        raise LocalizationError(f"resampling count must be >= 1, got {count}")
    w = normalise(weights)
    if scheme == "residual":
        copies = np.floor(count * w).astype(np.int64)
        fixed = np.repeat(np.arange(w.size), copies)
        rest = count - fixed.size
        if rest == 0:
            return fixed
        c = cumulative(count * w - copies)
        return np.concatenate((fixed, np.searchsorted(c, rng.random(rest), side="right")))
    c = _cumulative(w)
    if scheme == "systematic":
        u = rng.random()
        out = np.empty(count, np.int64)
        if _kernels().systematic_take(c, u, count, out):
            return out
        positions = (u + np.arange(count)) / count
    elif scheme == "stratified":
        positions = (rng.random(count) + np.arange(count)) / count
    else:
        positions = rng.random(count)
    return np.searchsorted(c, positions, side="right")


class Scratch:
    """Buffers one filter reuses from update to update: the open-addressing set of the KLD and
    cluster kernels (all -1 between calls: the kernels empty the slots they fill, so no update
    fills a whole fresh set) and the motion model's noise."""

    def __init__(self):
        self._table = np.empty(0, np.int64)
        self._noise = np.empty((0, 3))

    def table(self, n: int) -> np.ndarray:
        """A set with room for ``n`` keys at most half full."""
        size = 1 << max(4, (2 * n - 1).bit_length())
        if self._table.size < size:
            self._table = np.full(size, -1, np.int64)
        return self._table

    def noise(self, n: int) -> np.ndarray:
        """An (n, 3) float64 buffer for the motion model's standard normals."""
        if self._noise.shape[0] != n:
            self._noise = np.empty((n, 3))
        return self._noise


def hash_table(n: int, scratch: Scratch | None) -> np.ndarray:
    """An empty set (all -1) with room for ``n`` keys: the scratch's, else a fresh one."""
    return np.full(1 << max(4, (2 * n - 1).bit_length()), -1, np.int64) if scratch is None \
        else scratch.table(n)


@dataclass
class KldParameters:
    min_particles: int
    max_particles: int
    pf_err: float
    pf_z: float
    bin_size: np.ndarray     # (3,) [m, m, rad]

    @property
    def n_theta(self) -> int:
        return max(1, math.ceil(2 * math.pi / self.bin_size[2] - 1e-9))


def histogram_keys(poses: np.ndarray, kld: KldParameters) -> np.ndarray:
    """The KLD histogram bin of each pose (N, 3) as an int64 key."""
    keys = np.empty(poses.shape[0], np.int64)
    _kernels().bin_keys(poses, kld.bin_size, kld.n_theta, keys)
    return keys


def kld_resample(poses: np.ndarray, weights: np.ndarray, kld: KldParameters,
                 rng: np.random.Generator, scheme: str = "systematic",
                 inject: float = 0.0, random_poses=None, scratch: Scratch | None = None
                 ) -> np.ndarray:
    """KLD-sampling (Fox 2003) as AMCL: draw samples until their count exceeds the bound for the
    number of histogram bins they occupy. Returns the new poses (M, 3).

    AMCL draws one sample at a time (multinomial) because a low-variance sampler needs the count
    in advance. Here ``max_particles`` candidates are drawn by ``scheme`` and put in random order,
    so every prefix is an unbiased sample that keeps the scheme's low variance, and the kernel
    finds where the bound stops the prefix, copying only the samples it keeps. With ``inject``
    > 0 each candidate is, with that probability, replaced by ``random_poses(n)`` (Augmented
    MCL); those count in the histogram like any other sample, as in AMCL. ``scratch`` lends
    the kernel its hash set (a fresh one without).
    """
    n = kld.max_particles
    idx = resample_indices(weights, n, rng, scheme)
    order = idx[rng.permutation(n)]
    source = poses
    if inject > 0:
        if random_poses is None:
            raise LocalizationError("injection needs a random pose generator")
        fresh = rng.random(n) < inject
        if fresh.any():
            source = poses[order]
            source[fresh] = random_poses(int(fresh.sum()))
            order = np.arange(n)
    out = np.empty((n, 3), poses.dtype)
    # plain float and int arguments: one compiled specialisation whatever the config holds
    m = _kernels().kld_take(source, order, kld.bin_size, kld.n_theta, float(kld.pf_err),
                            float(kld.pf_z), int(kld.min_particles), int(n),
                            hash_table(n, scratch), out)
    return out[:m]


def log_sum_exp(log_w: np.ndarray) -> float:
    top = float(np.max(log_w))
    if not math.isfinite(top):
        return top
    return top + math.log(float(np.exp(log_w - top).sum()))


def effective_fraction(log_w: np.ndarray) -> float:
    """Effective sample size over particle count, 1 / (N sum w^2) of the normalised weights."""
    w = np.exp(log_w - np.max(log_w))
    return float(w.sum() ** 2 / (w.size * (w @ w)))


def temper(log_prior: np.ndarray, log_p: np.ndarray, min_fraction: float) -> float:
    """The largest exponent beta in [0, 1] for which the weights prior * p^beta keep at least
    ``min_fraction`` of the particles effective (adaptive tempering, Jasra et al. 2011); 1 when
    the full likelihood already does. A likelihood sharper than the particle cloud is resolved
    over several scans instead of killing every hypothesis but a lucky one in the first."""
    if min_fraction <= 0 or effective_fraction(log_prior + log_p) >= min_fraction:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(16):                      # bisection to 1.5e-5, ample for a weight exponent
        mid = 0.5 * (lo + hi)
        if effective_fraction(log_prior + mid * log_p) >= min_fraction:
            lo = mid
        else:
            hi = mid
    return lo


@dataclass
class Recovery:
    """Augmented MCL (Probabilistic Robotics table 8.3): short- and long-term averages of the
    measurement likelihood; while the short one is below the long one, a fraction
    1 - w_fast / w_slow of the new samples is drawn at random. Off when either alpha is 0.

    The averages are kept as logarithms, since a likelihood of 60 beams can leave the range of
    a float. Unlike AMCL, they are not restarted after each injection: AMCL's restart sets both
    to the lost filter's likelihood, after which nothing is injected any more and a kidnapped
    robot mostly stays lost (localization/README.md: 2 of 20 kidnaps found with the restart,
    20 of 20 without).
    """

    alpha_slow: float
    alpha_fast: float
    log_w_slow: float | None = None
    log_w_fast: float | None = None

    def observe(self, log_w_avg: float) -> None:
        if not math.isfinite(log_w_avg):
            return
        self.log_w_slow = _ema(self.log_w_slow, log_w_avg, self.alpha_slow)
        self.log_w_fast = _ema(self.log_w_fast, log_w_avg, self.alpha_fast)

    def injection_probability(self) -> float:
        if self.alpha_slow <= 0 or self.alpha_fast <= 0 or self.log_w_slow is None:
            return 0.0
        return max(0.0, 1.0 - math.exp(self.log_w_fast - self.log_w_slow))

    def reset(self) -> None:
        self.log_w_slow = self.log_w_fast = None


def _ema(log_avg, log_value, alpha):
    """log of (1 - alpha) * avg + alpha * value; the average starts at the first value."""
    if log_avg is None:
        return log_value
    if alpha <= 0:
        return log_avg
    if alpha >= 1:
        return log_value
    return float(np.logaddexp(math.log1p(-alpha) + log_avg, math.log(alpha) + log_value))
