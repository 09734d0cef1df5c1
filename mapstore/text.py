"""The text a store keeps from people (a review's note, a robot's or a tag's name): what a log
line, a terminal and another program reading the store can show as it is. Refused: text that
is not UTF-8 (the command line hands invalid bytes over as lone surrogates, which no database
stores as text), any control character (a newline would forge a line of ``store log``, an
escape sequence would drive the reader's terminal) and text beyond a limit."""

from __future__ import annotations

import unicodedata

from .backends import StoreError

NOTE_LIMIT = 2000            # [characters] a review's note: a paragraph, not a document
NAME_LIMIT = 64              # [characters] a robot's name, a tag


def check_text(what: str, value: str | bytes | None, limit: int) -> str | None:
    """``value`` (bytes decoded) when it is UTF-8 text of at most ``limit`` characters
    without a control character (no Unicode category C: controls such as newline, tab, ESC
    and NUL, format characters, surrogates, private-use and unassigned code points; nor the
    line and paragraph separators U+2028 and U+2029, which end a line as a newline does); None
    for None. Else a one-line ``StoreError`` naming ``what``, never showing the value."""
    if value is None:
        return None
    if isinstance(value, bytes):
        try:
            value = value.decode("utf-8")
        except UnicodeDecodeError as e:
            raise StoreError(f"{what}: not valid UTF-8 (byte {e.start})") from None
    if not isinstance(value, str):
        raise StoreError(f"{what}: not text ({type(value).__name__})")
    if len(value) > limit:       # said first: a long value is not scanned
        raise StoreError(f"{what}: {len(value)} characters, more than {limit}")
    for i, ch in enumerate(value):
        if 0xD800 <= ord(ch) <= 0xDFFF:
            raise StoreError(f"{what}: not valid UTF-8 (an undecodable byte at character "
                             f"{i + 1})")
        if unicodedata.category(ch)[0] == "C" or unicodedata.category(ch) in ("Zl", "Zp"):
            raise StoreError(f"{what}: holds a control character (U+{ord(ch):04X} at character "
                             f"{i + 1}); give one line of plain text")
    return value
