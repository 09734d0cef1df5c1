"""The Monte Carlo localiser as it was before its fused kernels (``localization/_kernels.py``:
the blocked likelihood field, one-pass clustering and KLD-sampling): a frozen copy of its
per-update code (``localizer``, ``motion``, ``sensor``, ``resample``, ``estimate`` and their
kernels), kept only so that ``benchmarks/bench_localization.py`` can time the two side by side
and the tests can check that both give the same particles and estimates. Configuration is the
live package's. Not used by anything else; not maintained."""

from .localizer import MonteCarloLocalizer

__all__ = ["MonteCarloLocalizer"]
