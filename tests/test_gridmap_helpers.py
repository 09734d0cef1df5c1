"""The helpers every package shares: the "did you mean" hint and the atomic file writer."""

import pytest

from gridmap.suggest import did_you_mean


def test_did_you_mean_names_the_nearest_choice():
    assert did_you_mean("treshold", ["threshold", "buffer_size"]) == \
        " (did you mean 'threshold'?)"
    assert did_you_mean("W22", ["W1", "W2", "W3"]) == " (did you mean 'W2'?)"


def test_did_you_mean_is_empty_when_nothing_is_near():
    assert did_you_mean("zzz", ["threshold", "buffer_size"]) == ""
    assert did_you_mean("anything", []) == ""


def test_did_you_mean_takes_any_names_and_a_cutoff():
    assert did_you_mean(3, [1, 3.5, "3"]) == " (did you mean '3'?)"
    assert did_you_mean("wnader", ["wander"], cutoff=0.99) == ""
    assert did_you_mean("wnader", ["wander"], cutoff=0.5) == " (did you mean 'wander'?)"
