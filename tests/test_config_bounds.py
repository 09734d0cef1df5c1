"""Every number of every configuration has a range, the range is enforced, and
docs/reliability.md lists it as the code has it."""

import dataclasses
import importlib
import pathlib

import pytest

from gridmap import MapUpdatingError

DOC = (pathlib.Path(__file__).resolve().parents[1] / "docs" / "reliability.md").read_text()
CONFIGS = [("localization.config", "LocalizerConfig", "BOUNDS"),
           ("localization.confidence", "PoseCheckConfig", "POSE_CHECK_BOUNDS"),
           ("updater.config", "UpdaterConfig", "BOUNDS"),
           ("localization.tracking", "TrackingConfig", "TRACKING_BOUNDS")]


def configs():
    for module, cls, bounds in CONFIGS:
        mod = importlib.import_module(module)
        if hasattr(mod, bounds):
            yield getattr(mod, cls), getattr(mod, bounds)


@pytest.mark.parametrize("cls, bounds", list(configs()), ids=lambda v: getattr(v, "__name__", ""))
def test_every_number_has_a_range_that_is_enforced_and_documented(cls, bounds):
    numbers = [f.name for f in dataclasses.fields(cls) if f.type in ("int", "float")]
    assert sorted(numbers) == sorted(bounds), "a number without a range, or a stale range"
    for name, (low, high) in bounds.items():
        assert f"| `{name}` | [{low:g}, {high:g}] |" in DOC, f"{name} not in the docs"
        default = getattr(cls(), name)
        assert low <= default <= high
        for bad in (high * 10 + 1, low - 1 - abs(low) * 10, float("nan")):
            value = int(bad) if isinstance(default, int) and bad == bad else bad
            with pytest.raises(MapUpdatingError, match=f"'{name}' must be"):
                cls(**{name: value})
