"""The helpers every package shares: the "did you mean" hint, the atomic file writer and the
one-cell dilation of a mask."""

import numpy as np
import pytest

from gridmap.masks import near
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


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_write_atomically_writes_bytes_and_text(tmp_path):
    from gridmap.atomic import write_atomically

    write_atomically(tmp_path / "a.bin", b"\x00\x01")
    write_atomically(tmp_path / "b.txt", "grün\n")
    assert (tmp_path / "a.bin").read_bytes() == b"\x00\x01"
    assert (tmp_path / "b.txt").read_text(encoding="utf-8") == "grün\n"
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("fails", ["fsync", "replace"])
def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary_file(tmp_path, monkeypatch,
                                                                         fails):
    import gridmap.atomic as atomic

    path = tmp_path / "map.yaml"
    path.write_text("old\n")

    def broken(*args):
        raise OSError(28, "No space left on device")

    # fsync fails after the new bytes went into the temporary file, replace at the rename
    monkeypatch.setattr(atomic.os, fails, broken)
    with pytest.raises(OSError, match="No space left"):
        atomic.write_atomically(path, "new, and much longer than the old one\n")
    monkeypatch.undo()
    assert path.read_text() == "old\n"
    assert _leftovers(tmp_path) == []


def test_write_with_a_writer_that_fails_half_way_touches_nothing(tmp_path):
    from gridmap.atomic import write_with

    path = tmp_path / "masks.npz"
    path.write_bytes(b"old")

    def half_then_fail(f):
        f.write(b"half of the new")
        raise ValueError("the writer broke")

    with pytest.raises(ValueError, match="the writer broke"):
        write_with(path, half_then_fail)
    assert path.read_bytes() == b"old"
    assert _leftovers(tmp_path) == []


def test_write_with_numpy_and_an_interrupted_rename(tmp_path, monkeypatch):
    import numpy as np

    import gridmap.atomic as atomic

    path = tmp_path / "t.npz"
    atomic.write_with(path, lambda f: np.savez(f, x=np.arange(3)))
    with np.load(path) as z:
        assert z["x"].tolist() == [0, 1, 2]

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        atomic.write_with(path, lambda f: np.savez(f, x=np.arange(5)))
    monkeypatch.undo()
    with np.load(path) as z:
        assert z["x"].tolist() == [0, 1, 2]
    assert _leftovers(tmp_path) == []


def test_near_is_the_mask_dilated_by_a_3_by_3_square():
    rng = np.random.default_rng(3)
    for shape in [(1, 1), (1, 7), (6, 1), (9, 13)]:
        mask = rng.random(shape) < 0.1
        kept = mask.copy()
        padded = np.pad(mask, 1)
        h, w = shape
        want = np.zeros(shape, bool)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                want |= padded[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
        assert np.array_equal(near(mask), want)
        assert np.array_equal(mask, kept)
