"""The map updater as it was before the fused walks of ``updater/_kernels.py``: a frozen copy
of its per-scan code (``map_updater``, ``steps``, the updater's kernels and the grid kernels
they call), kept only so that ``benchmarks/bench_updater.py`` can time the two side by side
and the tests can compare their output maps. Configuration, gating and verdicts are the
live package's. Not used by anything else; not maintained."""

from .map_updater import MapUpdater

# Rules of the live updater that came after this copy, set as this copy runs them: the run
# filter by width, the spread of freed objects, the neighbour support by M's value.
AS_BEFORE = {"min_run_width": 0.0, "spread_removed": False, "support_exact_state": False,
             "removed_skip_across": False, "free_with_neighbours": False,
             "gate_confirm_once": False}

__all__ = ["AS_BEFORE", "MapUpdater"]
