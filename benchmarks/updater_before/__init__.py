"""The map updater as it was before the fused walks of ``updater/_kernels.py``: a frozen copy
of its per-scan code (``map_updater``, ``steps``, the updater's kernels and the grid kernels
they call), kept only so that ``benchmarks/bench_updater.py`` can time the two side by side
and the tests can compare their output maps. Configuration, gating and verdicts are the
live package's. Not used by anything else; not maintained."""

from .map_updater import MapUpdater

__all__ = ["MapUpdater"]
