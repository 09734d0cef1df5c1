"""The lines of a text log, plain or gzip, within bounds; a gzip file cut short is read up to
the cut.

A file that starts with gzip's magic bytes (``killian.clf.gz``) is read through gzip. What a
log may hold is bounded (:class:`LogLimits`): a line at most ``MAX_LINE_BYTES``; a gzip file at
most ``GZIP_MAX_RATIO`` times its size in text (and at least ``GZIP_MIN_BYTES``) and a line per
``GZIP_BYTES_PER_LINE`` bytes of the file (and at least ``GZIP_MIN_LINES`` lines); a plain file
only the bounds given. A log with bounds is measured before a line is parsed (its lines and
bytes counted chunk by chunk), and past a bound it is refused with a :class:`LogError` naming
the file and the bound, before the memory fills or the reading takes minutes.

A gzip file that ends before its end-of-stream marker (a robot's disk filled, the power went) is
read up to the cut: :class:`TextLines` yields its complete lines, drops the line the cut went
through, and says so in ``cut``; with ``LogLimits.refuse_cut`` it is refused instead. A gzip
file damaged inside (a CRC that does not match, bytes that do not inflate) is refused either
way: what it holds may be wrong, not only short.
"""

from __future__ import annotations

import gzip
import io
import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from .records import LogError

GZIP_MAGIC = b"\x1f\x8b"
# A line holds at most 2 x 100 000 numbers (ranges and remissions, the beam counts' bound), far
# less than this in any real log (2 KB in the Radish logs); a line without an end, or one of
# gigabytes, is refused when it passes this instead of filling the memory.
MAX_LINE_BYTES = 8 * 1024 * 1024
# Text logs compress 3 to 6 times (the Radish and Killian logs); gzip can reach 1000 times on
# one repeated line, so a small file may expand to gigabytes of comments that take hours to
# read. The reading stops at this many times the file's size, or GZIP_MIN_BYTES if more.
GZIP_MAX_RATIO = 100
GZIP_MIN_BYTES = 64 * 1024 * 1024
# Each line of a real log costs 14 bytes or more of the gzip file (a line of zero odometry
# still has its own timestamps: 0.07 lines per byte in the Intel and Seattle logs, under 0.05
# over the whole of every log in data/), while short comment lines cost next to nothing and take
# a microsecond each to parse: 500 MB of 10-byte lines would take a minute. A log may hold a
# line per this many bytes of the file, or GZIP_MIN_LINES lines if more.
GZIP_BYTES_PER_LINE = 4
GZIP_MIN_LINES = 1_000_000
CHUNK = 1024 * 1024


@dataclass(frozen=True)
class LogLimits:
    """What a text log may hold. ``max_lines`` / ``max_bytes``: its lines and its bytes of
    text (a gzip file's once decompressed); None: a gzip file's bounds follow from its size
    (the module's docstring), a plain file has none. ``refuse_cut``: a gzip file cut short is
    refused instead of read up to the cut."""

    max_lines: int | None = None
    max_bytes: int | None = None
    refuse_cut: bool = False

    def __post_init__(self):
        for name in ("max_lines", "max_bytes"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                      or value < 1):
                raise LogError(f"{name} must be a whole number >= 1, got {value!r}")


def is_gzip(path) -> bool:
    """True when the file at ``path`` starts with gzip's magic bytes."""
    with Path(path).open("rb") as f:
        return f.read(2) == GZIP_MAGIC


def bounds(path, limits: LogLimits) -> tuple[int | None, int | None]:
    """(most lines, most bytes of text) for the log at ``path``: the limits given, else for a
    gzip file the bounds its size sets, else None (no bound)."""
    lines, size = limits.max_lines, limits.max_bytes
    if is_gzip(path):
        packed = Path(path).stat().st_size
        lines = lines or max(GZIP_MIN_LINES, packed // GZIP_BYTES_PER_LINE)
        size = size or max(GZIP_MIN_BYTES, GZIP_MAX_RATIO * packed)
    return lines, size


class _ReadToCut(io.RawIOBase):
    """A gzip file's content up to where it ends, cut or not: ``cut`` turns True where the
    stream ends without its end marker (gzip raises ``EOFError`` there only once every byte
    before the cut has come out, and ``read1`` hands over what it has at each call)."""

    def __init__(self, gz: gzip.GzipFile):
        self.gz, self.cut = gz, False

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        try:
            data = self.gz.read1(len(buffer))
        except EOFError:
            self.cut = True
            return 0
        buffer[:len(data)] = data
        return len(data)


class TextLines:
    """The lines (``str``) of the text log at ``path`` within ``limits``, as a context manager
    and an iterator. Once the iteration ends, ``cut`` is "" for a whole file, or the line that
    says where a gzip file cut short ended and what was dropped."""

    def __init__(self, path, limits: LogLimits | None = None):
        self.path, self.limits = Path(path), limits or LogLimits()
        self.max_lines, self.max_bytes = bounds(self.path, self.limits)
        self.cut = ""
        self.raw = None
        if is_gzip(self.path):
            self.raw = _ReadToCut(gzip.open(self.path, "rb"))
            self.file = io.BufferedReader(self.raw, CHUNK)
        else:
            self.file = self.path.open("rb")

    def __enter__(self) -> TextLines:
        if self.max_lines is not None or self.max_bytes is not None:
            try:
                self._measure()
            except BaseException:
                self.__exit__()
                raise
        return self

    def __exit__(self, *exc) -> None:
        self.file.close()
        if self.raw is not None:
            self.raw.gz.close()

    def _measure(self) -> None:
        """Refuse a log past its bounds, or cut short when that is refused, before a line is
        parsed: its lines are counted chunk by chunk first (inflating is fast, a line parsed
        takes a microsecond), so 2.7 GB of comment lines are refused once the bound's 1.6
        million lines are counted, in 0.04 s where parsing them took 1-2 s."""
        lines = run = total = 0
        with (gzip.open(self.path, "rb") if self.raw is not None else self.path.open("rb")) as f:
            while True:
                try:
                    chunk = f.read1(CHUNK)
                except EOFError:        # cut short: what came before the cut is measured
                    if self.limits.refuse_cut:
                        self._at_cut(lines, total - run, run)
                    break
                if not chunk:
                    break
                total, newlines = total + len(chunk), chunk.count(b"\n")
                first = chunk.find(b"\n")
                # a chunk is shorter than a line may be: only the line it continues can be too long
                if run + (len(chunk) if first < 0 else first + 1) > MAX_LINE_BYTES:
                    raise LogError(self._too_long(lines + 1))
                run = run + len(chunk) if first < 0 else len(chunk) - chunk.rfind(b"\n") - 1
                lines += newlines
                if self.max_bytes is not None and total > self.max_bytes:
                    raise LogError(self._too_much("bytes"))
                if self.max_lines is not None and lines + (run > 0) > self.max_lines:
                    raise LogError(self._too_much("lines"))

    def _too_long(self, lineno: int) -> str:
        return (f"{self.path}, line {lineno}: longer than {MAX_LINE_BYTES} bytes, where a "
                "CARMEN line is a few KB; refused")

    def __iter__(self) -> Iterator[str]:
        total = 0
        for lineno in itertools.count(1):
            # one byte more than a line may hold, so that a longer line shows without being read
            line = self.file.readline(MAX_LINE_BYTES + 1)
            if not line:
                break
            if len(line) > MAX_LINE_BYTES:
                raise LogError(self._too_long(lineno))
            total += len(line)
            if self.raw is not None and self.raw.cut and not line.endswith(b"\n"):
                self._at_cut(lineno - 1, total - len(line), len(line))
                return
            yield line.decode("utf-8", errors="replace")
        if self.raw is not None and self.raw.cut:       # the cut fell at a line's end
            self._at_cut(lineno - 1, total, 0)

    def _too_much(self, what: str) -> str:
        """The refusal of a log past its bound of ``what`` (bytes or lines)."""
        given = {"bytes": self.limits.max_bytes, "lines": self.limits.max_lines}[what]
        flag = f"--max-log-{what}"
        if given is not None:
            unit = "bytes of text" if what == "bytes" else "lines"
            return f"{self.path}: holds more than {given} {unit}, the bound {flag} gives; refused"
        if what == "bytes":
            return (f"{self.path}: the gzip file expands to more than {self.max_bytes} bytes, "
                    f"over {GZIP_MAX_RATIO} times its size where a log compresses 3 to 6 times "
                    f"(a gzip bomb?); refused ({flag} N raises the bound)")
        return (f"{self.path}: the gzip file holds more than {self.max_lines} lines, over a line "
                f"per {GZIP_BYTES_PER_LINE} bytes of it where a log's line takes 14 or more "
                f"(a gzip bomb of short lines?); refused ({flag} N raises the bound)")

    def _at_cut(self, lines: int, kept: int, dropped: int) -> None:
        """Say (``cut``) or refuse a gzip file cut short after ``lines`` complete lines of
        ``kept`` bytes, ``dropped`` bytes of a line after them."""
        where = (f"{self.path} is cut short: its gzip stream ends without its end marker after "
                 f"{lines} complete lines ({kept} bytes of text)")
        if self.limits.refuse_cut:
            raise LogError(f"{where}; refused (--refuse-truncated or --strict; without them a "
                           "cut log is read up to the cut)")
        half = f"the {dropped} bytes of the line it cut through are dropped, and " if dropped \
            else ""
        self.cut = f"{where}; read up to the cut: {half}whatever followed it is lost"


def gzip_head(path, size: int = 4096) -> bytes:
    """The first ``size`` bytes of a gzip file's content, also of a file cut short."""
    with gzip.open(path, "rb") as gz, io.BufferedReader(_ReadToCut(gz), CHUNK) as f:
        return f.read(size)
