"""The "did you mean" hint every error about an unknown name carries, written once."""

from __future__ import annotations

import difflib


def did_you_mean(name, choices, cutoff: float = 0.6) -> str:
    """`` (did you mean 'x'?)`` with ``x`` the choice nearest to ``name``, or "" when none is
    near enough (``difflib``'s ratio below ``cutoff``)."""
    near = difflib.get_close_matches(str(name), [str(c) for c in choices], n=1, cutoff=cutoff)
    return f" (did you mean {near[0]!r}?)" if near else ""
