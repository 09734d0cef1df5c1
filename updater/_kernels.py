"""The map updater's numba kernels, by the step of the paper they compute (docs/algorithm.md):

=====================  ===========================================================================
module                 step
=====================  ===========================================================================
``_scan``              a scan past the gate in one call: ``process_scan`` (steps 1 to 4)
``_classify``          1. the beam classifier and the lost check (paper, Sec. IV-A)
``_walks``             the walks along the beams of steps 2 and 3
``_flags``             2. and 3. the changed- and unchanged-cells evaluators (Sec. IV-B, IV-C),
                       with the rules this project adds: ``flag_scan``
``_buffers``           4. the flags into the buffers, and the hit buffers (Sec. IV-D)
``_decide``            4. the decision rule (Sec. IV-D): ``push_and_decide``, ``decide_all``
``_output``            5. the output map and the last check (Sec. IV-D, Fig. 7), made on demand
``_faces``             faces a few cells off, counted per scan and moved at the output (not in
                       the paper)
``_shared``            bit planes, flag counts and verdict codes that every step reads
=====================  ===========================================================================

This module only gathers their names, for the Python side (``steps.kernels()``, which imports
it on first use so that numba is not imported with the package) and for the tests. What the
kernels take is documented in ``_arguments``.

numba's cache (``cache=True``) compiles a kernel again when its own file changes, not when a
file it imports from does: a kernel of ``_flags`` keeps what it inlined of ``_shared`` or
``_walks``. After changing a module the others import from (``_shared``, ``_walks``,
``_classify``, ``_buffers``, ``verdicts``, ``hit_tiles``' TILE_SHIFT, gridmap's kernels),
clear ``updater/__pycache__``.
"""

from ._buffers import (HIT_TILE_MASK, NEVER_SETTLED, decide_drawn, hit_slot,  # noqa: F401
                       is_drawn, make_hit_tiles, missing_hit_tiles, push_flags, push_hits,
                       settled, settled_marks)
from ._arguments import DISTANCES  # noqa: F401
from ._classify import (MIN_INCIDENCE_SINE, beam_directions,  # noqa: F401
                        beam_distances, beam_endpoints, beam_verdicts, cast_virtual, classify,
                        classify_scan, ends_in_unknown, known_changes, prepare_beams,
                        run_classifier, run_filter, scan_is_lost, skip_across, valid_ranges)
from ._decide import (clear_neighbourhoods, decide, decide_all, decide_cell,  # noqa: F401
                      neighbourhood, push_and_decide, same_state)
from ._faces import STEPS_PER_CELL, count_faces, move_faces, small_structures  # noqa: F401
from ._flags import (disc_is_free, flag_gaps, flag_hit_surfaces,  # noqa: F401
                     flag_listed_unchanged, flag_new_obstacles, flag_occupied_unchanged,
                     flag_scan, guard_needed, list_unknown_hits, mark_seen_surfaces,
                     reach_past_gaps, ready_walks, square_is_free, unmark_changing)
from ._output import (apply_changes, apply_drawn, keep_beside_standing,  # noqa: F401
                      link_runs, mark_enclosed, spread_freed, unknown_runs)
from ._scan import NEEDS_ROOM, process_scan, push_scan  # noqa: F401
from ._shared import (CHANGE, CLEAR_SHIFT, INVALID, SKIPPED, UNCHANGED,  # noqa: F401
                      beam_rows, bit_get, clear_bits, confirmed, flag_count, hit_cell,
                      is_open_unknown, own_rays, popcount16, set_bit, test_and_set)
from ._walks import (ENTRY_MARGIN, NO_BLOCKS, NO_ENTRIES, NO_SKIPS,  # noqa: F401
                     WALK_BLOCKED, WALK_FREE, WALK_OPEN_UNKNOWN, flag_unknown_seen_through,
                     free_walk_skips, unknown_walks, walk_beams, walk_scan)
