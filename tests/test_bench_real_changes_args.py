"""The edited-world benchmark's command line (``benchmarks/bench_real_changes.py``): a
mistake in ``--set`` is one line before any case is made (it was a traceback, or one from
each worker)."""

import pytest

from benchmarks import bench_real_changes as brc


@pytest.mark.parametrize("argv, says", [
    (["--set", "move_faces"], "--set takes KEY=VALUE, got 'move_faces'"),
    (["--set", "=1"], "--set takes KEY=VALUE"),
    (["--set", "move_faces=["], "--set: move_faces: '[' is not valid YAML"),
    (["--set", "move_facs=false"], "did you mean 'move_faces'"),
    (["--set", "pc.max_gian=0.1"], "did you mean 'max_gain'"),
    (["--set", "face_draw_sessions=7"], "face_draw_sessions' must be a whole number in [1, 2]"),
])
def test_a_mistake_in_set_is_one_line_before_any_case(argv, says, capsys, tmp_path):
    with pytest.raises(SystemExit) as e:
        brc.main(argv + ["--out", str(tmp_path / "out")])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("usage:") and "error:" in err[-1] and says in err[-1]
    assert not (tmp_path / "out").exists()
