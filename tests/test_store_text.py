"""What the store keeps from people is one line of text: a robot's name with a newline (which
forged a row of ``store log``), an escape sequence in a log's name, a note that is not UTF-8
(a traceback before) are refused in one line, and nothing is written."""

from __future__ import annotations

import numpy as np
import pytest

from gridmap import OccupancyGrid
from mapstore import StoreError, open_store
from mapupdate import main


def grid(value: int) -> OccupancyGrid:
    return OccupancyGrid(np.full((6, 8), value, np.int8), 0.05)


@pytest.mark.parametrize("meta, said", [
    ({"robot": "amr-07\n   v9  approved"}, "the version's robot: holds a control character"),
    ({"robot": "amr-07\u2028v9"}, "the version's robot: holds a control character"),
    ({"log": "shift\x1b[2J.bag"}, "the version's log: holds a control character"),
    ({"robot": "r" * 65}, "the version's robot: 65 characters, more than 64"),
    ({"method": b"\xff\xfe"}, "the version's method: not valid UTF-8"),
])
def test_a_description_that_would_forge_a_log_line_is_refused(tmp_path, meta, said):
    with open_store(str(tmp_path / "maps.db"), create=True) as s:
        s.commit(grid(0), None)
        with pytest.raises(StoreError, match=said) as e:
            s.commit(grid(100), 1, meta)
        assert "\n" not in str(e.value) and "v9" not in str(e.value)
        assert len(s.log()) == 1
        s.commit(grid(100), 1, {"robot": "amr-07 🤖"})            # plain text passes
        assert s.version(2).meta["robot"] == "amr-07 🤖"


def test_a_note_that_is_not_utf8_or_has_a_newline_is_refused_in_one_line(tmp_path, capsys):
    path = str(tmp_path / "maps.db")
    with open_store(path, create=True) as s:
        s.commit(grid(0), None)
        s.set_require_approval(True)
        s.commit(grid(100), 1)
    for note in ("bad \udcff byte", "two\nlines", "n" * 2001):
        assert main(["store", "approve", "2", "--note", note, "--store", path]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("mapupdate store: error: ") and "\n" not in err
        assert "the note" in err
    with open_store(path) as s:
        assert s.version(2).status == "pending"
    assert main(["store", "approve", "2", "--note", "box gone, checked", "--store", path]) == 0
