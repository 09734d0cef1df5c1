"""filterpy's own resamplers, the reference ``localization.resample.resample_indices`` is
checked against (tests) and measured against (benchmarks/bench_localization.py). filterpy is
a dependency of the tests and benchmarks only (the ``dev`` extra), never of the product."""

from __future__ import annotations

import numpy as np

from localization.resample import normalise


def filterpy_indices(weights, rng: np.random.Generator, scheme: str = "systematic") -> np.ndarray:
    """filterpy's own resampler, as many indices as weights, made reproducible by seeding the
    global state from ``rng`` for the call and restoring it afterwards (nothing leaks)."""
    from filterpy import monte_carlo

    fn = getattr(monte_carlo, f"{scheme}_resample")
    saved = np.random.get_state()
    try:
        np.random.seed(int(rng.integers(2**32)))
        return np.asarray(fn(normalise(weights)), dtype=np.int64)
    finally:
        np.random.set_state(saved)
