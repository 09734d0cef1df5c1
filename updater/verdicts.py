"""What the classifier makes of each beam of a scan (``ScanReport.verdicts``, one per beam).

The kernels store these as int8 codes in per-beam arrays; ``updater._shared`` takes its int
constants from here, so the codes are defined once. numba compiles them into the cached
kernels, and its cache notices changes to the kernels' own files only: a code changed here
needs ``updater/__pycache__`` cleared.
"""

from enum import IntEnum


class BeamVerdict(IntEnum):
    INVALID = 0      # not a valid range: no flags
    UNCHANGED = 1    # agrees with M: unchanged flags
    SKIPPED = 2      # agrees with M but within n_skip beams of a change: no flags
    CHANGE = 3       # detected change kept by the run filter: changed flags


# The names the verdicts had before the enum, for callers not moved to it yet.
BEAM_INVALID = BeamVerdict.INVALID
BEAM_UNCHANGED = BeamVerdict.UNCHANGED
BEAM_SKIPPED = BeamVerdict.SKIPPED
BEAM_CHANGE = BeamVerdict.CHANGE
