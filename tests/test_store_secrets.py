"""The text a store keeps from people (mapstore.text) is one line of UTF-8 within a limit."""

from __future__ import annotations

import pytest

from mapstore import StoreError
from mapstore.text import NAME_LIMIT, NOTE_LIMIT, check_text


# --- the text a store keeps from people ----------------------------------------------------------
def test_check_text_refuses_what_is_not_one_line_of_utf8():
    assert check_text("note", None, NOTE_LIMIT) is None
    for fine in ("box gone, approved", "🤖 amr-07 🗺️", "été à l'entrepôt", "x" * NAME_LIMIT,
                 "Lagerhalle Süd – Regal 12"):
        assert check_text("note", fine, NOTE_LIMIT) == fine
    assert check_text("note", "déjà".encode(), NOTE_LIMIT) == "déjà"
    refused = {"amr-07\nv9 approved": "control character .U.000A",
               "tab\there": "U.0009", "red \x1b[31m": "U.001B", "nul\x00": "U.0000",
               "del\x7f": "U.007F", "line\u2028sep": "U.2028", "bidi\u202eevil": "U.202E",
               "\udcff": "not valid UTF-8", "caf\udce9": "not valid UTF-8",
               b"caf\xe9": "not valid UTF-8", "x" * (NAME_LIMIT + 1): "65 characters, more than 64"}
    for value, message in refused.items():
        with pytest.raises(StoreError, match=message) as e:
            check_text("robot name", value, NAME_LIMIT)
        assert str(e.value).startswith("robot name: ") and "\n" not in str(e.value)
    with pytest.raises(StoreError, match="2001 characters, more than 2000"):
        check_text("note", "a" * 2001, NOTE_LIMIT)
    assert check_text("note", "a" * 2000, NOTE_LIMIT) == "a" * 2000


def test_check_text_takes_what_argparse_makes_of_invalid_bytes():
    # argparse gives the bytes of an argument that are not UTF-8 as lone surrogates
    # (surrogateescape): b'amr-\xff' arrives as 'amr-\udcff'
    given = b"amr-\xff".decode("utf-8", "surrogateescape")
    with pytest.raises(StoreError, match="robot name: not valid UTF-8"):
        check_text("robot name", given, NAME_LIMIT)
