"""CARMEN log files: a text line per message, the first word naming the message.

Read here (every line ends ``timestamp [host logger_timestamp]``; the timestamp is used):

- ``FLASER n r1..rn x y theta odom_x odom_y odom_theta`` and ``RLASER`` (same fields, rear
  laser): ``x y theta`` is the laser's pose and ``odom_*`` the robot's odometry pose, both as
  the log has them (in a corrected log, the corrected poses). The beams cover 180 degrees from
  -90 degrees: ``pi / n`` apart for an even ``n`` (180 beams at 1 degree, the Intel lab log),
  ``pi / (n - 1)`` for an odd ``n`` (181 beams from -90 to +90 degrees). A reading at or beyond
  the lidar's "no return" value (81.83 m for the SICK LMS) becomes ``inf``.
- ``ROBOTLASER1`` / ``ROBOTLASER2 laser_type start_angle fov resolution max_range accuracy
  remission_mode n r1..rn m rem1..remm laser_x laser_y laser_theta robot_x robot_y robot_theta
  tv rv forward_safety side_safety turn_axis``: the scan brings its own angles and range limit
  (a reading at or beyond ``max_range`` is ``inf``).
- ``ODOM x y theta tv rv accel``: the robot's odometry pose.
- ``TRUEPOS x y theta odom_x odom_y odom_theta``: a simulator's true pose.

Other CARMEN messages (``PARAM``, ``SYNC``, ``NEFF``, ``RAWLASER1`` ...) and ``#`` comments are
counted and left out. A malformed line (truncated, a beam count that disagrees with the line, a
pose or timestamp that is not a finite number, an unknown message) raises :class:`LogError`
naming the line with ``strict=True``; by default it is skipped and counted in
:class:`ReadStats`. A bad range (NaN, negative) is not a bad line: as in a ROS LaserScan it is
an invalid beam (NaN in the scan), the line's other beams are kept, and such ranges are counted
(``ReadStats.invalid_ranges``). Readings below 1 cm (0.0 is "no valid return" in the SENA
logs) are invalid beams too, being below the scan's ``range_min``.

The file is read by :class:`.text_lines.TextLines`: plain or gzip, within the bounds of
:class:`.text_lines.LogLimits` (lines, bytes of text), and a gzip file cut short up to the cut,
which ``ReadStats.cut`` then says (``strict`` or ``LogLimits.refuse_cut``: refused).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gridmap import Pose2D, Scan
from gridmap.types import GridError

from .records import LogError, OdomRecord, PoseRecord, ReadStats, Record, ScanRecord
from .rosbag import check_angle_increment
from .text_lines import LogLimits, TextLines

# The SICK LMS reports 8183 cm when no echo came back; CARMEN logs keep that value.
FLASER_NO_RETURN = 81.83
# Readings below 1 cm are the lidar's error codes (dazzle, no measurement), not obstacles.
RANGE_MIN = 0.01

OLD_LASERS = {"FLASER": "front_laser", "RLASER": "rear_laser"}
ROBOT_LASERS = {"ROBOTLASER1": "laser1", "ROBOTLASER2": "laser2"}
# Well-formed CARMEN messages this reader has no use for: counted, never an error.
IGNORED = frozenset({
    "PARAM", "SYNC", "NEFF", "RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4", "LASER3",
    "LASER4", "POSITIONLASER", "NMEAGGA", "NMEARMC", "GPSNMEA", "SONAR", "BUMPER", "SCANMARK",
    "IMU", "VECTORMOVE", "ROBOTVELOCITY", "FOLLOWTRAJECTORY", "BASEVELOCITY", "ARM",
})


class _LineProblem(Exception):
    """A malformed line: ``kind`` groups the counts, the message says what is wrong."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


@dataclass
class CarmenLog:
    """The records of a CARMEN log in time order, and what was skipped on the way."""

    source: str
    records: list[Record] = field(default_factory=list)
    stats: ReadStats = field(default_factory=ReadStats)

    def __iter__(self):
        return iter(self.records)

    def scans(self) -> list[ScanRecord]:
        return [r for r in self.records if isinstance(r, ScanRecord)]

    def odometry(self) -> list[OdomRecord]:
        return [r for r in self.records if isinstance(r, OdomRecord)]


def read_carmen(path, *, strict: bool = False, flaser_no_return: float = FLASER_NO_RETURN,
                limits: LogLimits | None = None) -> CarmenLog:
    """Read a CARMEN log file (see the module docstring for the lines understood).

    ``strict`` turns the first malformed line into a :class:`LogError` naming it; otherwise
    such lines are skipped and counted in ``.stats``. A log with no usable line at all is an
    error either way. ``limits``: what the file may hold (``text_lines.LogLimits``; default:
    a gzip file's bounds from its size); a gzip file cut short is read up to the cut and
    ``.stats.cut`` says so, unless ``strict`` or ``limits.refuse_cut`` refuse it.
    """
    path = Path(path)
    limits = limits or LogLimits()
    if strict:
        limits = replace(limits, refuse_cut=True)
    try:
        with TextLines(path, limits) as lines:
            log = parse_carmen(lines, source=str(path), strict=strict,
                               flaser_no_return=flaser_no_return)
            log.stats.cut = lines.cut
    except (IsADirectoryError, FileNotFoundError, PermissionError):
        raise
    except (OSError, EOFError, zlib.error) as e:     # gzip's errors for a damaged archive
        raise LogError(f"{path}: cannot read: {e}") from None
    if not log.records:
        cut = log.stats.cut.removeprefix(f"{path} is ")
        raise LogError(f"{path}: no usable CARMEN line (laser, ODOM or TRUEPOS); "
                       f"{log.stats.summary()}" + (f"; {cut}" if cut else ""))
    return log


def parse_carmen(lines: Iterable[str], *, source: str = "<lines>", strict: bool = False,
                 flaser_no_return: float = FLASER_NO_RETURN) -> CarmenLog:
    """Parse CARMEN lines; records come back sorted by time (stable, so ties keep file order)."""
    log = CarmenLog(source)
    for lineno, line in enumerate(lines, start=1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        try:
            record = parse_line(words, flaser_no_return)
        except _LineProblem as p:
            message = f"{source}, line {lineno}: {p}"
            if strict:
                raise LogError(message) from None
            log.stats.skip(p.kind, message)
            continue
        if record is None:
            log.stats.ignored[words[0]] += 1
            continue
        if isinstance(record, ScanRecord):
            log.stats.count_invalid_ranges(record.scan.ranges)
        log.records.append(record)
    log.records.sort(key=lambda r: r.time)
    return log


def parse_line(words: list[str], flaser_no_return: float = FLASER_NO_RETURN) -> Record | None:
    """One CARMEN line split into words -> a record, or None for a message left out.

    Raises ``_LineProblem`` for a malformed line."""
    kind = words[0]
    if kind in OLD_LASERS:
        return _old_laser(words, flaser_no_return)
    if kind in ROBOT_LASERS:
        return _robot_laser(words)
    if kind == "ODOM":
        v = _numbers(words, 1, 8, "ODOM x y theta tv rv accel timestamp")
        _check_trailing(words, 8)
        return OdomRecord(v[6], Pose2D(*v[0:3]), velocity=(v[3], 0.0, v[4]),
                          topic="ODOM")
    if kind == "TRUEPOS":
        v = _numbers(words, 1, 8, "TRUEPOS x y theta odom_x odom_y odom_theta timestamp")
        _check_trailing(words, 8)
        return PoseRecord(v[6], Pose2D(*v[0:3]), topic="TRUEPOS")
    if kind in IGNORED:
        return None
    raise _LineProblem("unknown message", f"unknown message type {kind[:40]!r}")


def _old_laser(words: list[str], no_return: float) -> ScanRecord:
    """FLASER / RLASER: beam count, ranges, laser pose, odometry pose, timestamp."""
    name = words[0]
    n = _count(words, 1, name)
    fixed = 6 + 1  # two poses and the timestamp after the ranges
    _check_length(words, 2 + n + fixed, name, f"{n} ranges")
    r = _ranges(words, 2, 2 + n, name)
    v = _numbers(words, 2 + n, 2 + n + fixed, f"{name} pose or timestamp")
    _check_trailing(words, 2 + n + fixed)
    if n > 0 and n % 2 == 1:
        increment = math.pi / max(n - 1, 1)
    else:
        increment = math.pi / max(n, 1)
    with np.errstate(invalid="ignore"):
        r[r >= no_return - 1e-6] = np.inf
    scan = _scan(r, -math.pi / 2, increment, RANGE_MIN, no_return, v[6], name)
    return ScanRecord(v[6], scan, frame_id=OLD_LASERS[name], topic=name,
                      laser_pose=Pose2D(*v[0:3]),
                      odom_pose=Pose2D(*v[3:6]))


def _robot_laser(words: list[str]) -> ScanRecord:
    """ROBOTLASER1/2: the scan's own angles and range limit, remissions, laser and robot pose."""
    name = words[0]
    head = _numbers(words, 2, 8, f"{name} start_angle fov resolution max_range accuracy mode")
    # head[1] is the field of view, which the beam count and resolution already imply
    start, fov, resolution, max_range = head[0], head[1], head[2], head[3]
    n = _count(words, 8, name)
    _check_fan(fov, resolution, n, name)
    _check_length(words, 9 + n + 1, name, f"{n} ranges and a remission count")
    r = _ranges(words, 9, 9 + n, name)
    m = _count(words, 9 + n, f"{name} remission")
    base = 10 + n + m
    fixed = 6 + 5 + 1  # laser pose, robot pose, tv rv safety distances turn axis, timestamp
    _check_length(words, base + fixed, name, f"{n} ranges and {m} remissions")
    v = _numbers(words, base, base + fixed, f"{name} pose, velocity or timestamp")
    _check_trailing(words, base + fixed)
    if not (max_range > 0):
        raise _LineProblem("bad value", f"{name} max_range must be positive, got {max_range}")
    with np.errstate(invalid="ignore"):
        r[r >= max_range] = np.inf
    scan = _scan(r, start, resolution, min(RANGE_MIN, 0.5 * max_range), max_range, v[11], name)
    return ScanRecord(v[11], scan, frame_id=ROBOT_LASERS[name], topic=name,
                      laser_pose=Pose2D(*v[0:3]),
                      odom_pose=Pose2D(*v[3:6]))


# --- field helpers -----------------------------------------------------------------------------

def _numbers(words: list[str], start: int, stop: int, what: str) -> list[float]:
    """Words [start, stop) as floats; the problem names the field (1-based word number)."""
    if len(words) < stop:
        raise _LineProblem("truncated", f"{words[0]} line truncated: {len(words)} fields, "
                                        f"{stop} needed ({what})")
    out = []
    for i in range(start, stop):
        try:
            x = float(words[i])
        except ValueError:
            raise _LineProblem("not a number", f"{words[0]} field {i + 1} ({what}) is not a "
                                               f"number: {words[i][:40]!r}") from None
        if not math.isfinite(x):
            raise _LineProblem("not a number", f"{words[0]} field {i + 1} ({what}) is not "
                                               f"finite: {words[i][:40]!r}")
        out.append(x)
    return out


def _ranges(words: list[str], start: int, stop: int, name: str) -> np.ndarray:
    """Words [start, stop) as ranges [m]; a word that is not a number spoils the line, but a
    NaN or negative reading is only an invalid beam (NaN), as in a ROS LaserScan."""
    if len(words) < stop:
        raise _LineProblem("truncated", f"{name} line truncated: {len(words)} fields, "
                                        f"{stop} needed ({name} range)")
    try:
        r = np.array([float(w) for w in words[start:stop]], np.float64)
    except ValueError:
        bad = next(i for i in range(start, stop) if not _is_float(words[i]))
        raise _LineProblem("not a number", f"{name} field {bad + 1} ({name} range) is not a "
                                           f"number: {words[bad][:40]!r}") from None
    r[~(r >= 0)] = np.nan      # negative, -inf and NaN alike
    return r


def _is_float(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def _count(words: list[str], i: int, what: str) -> int:
    if len(words) <= i:
        raise _LineProblem("truncated", f"{words[0]} line truncated before its {what} count")
    try:
        n = int(words[i])
    except ValueError:
        raise _LineProblem("not a number", f"{words[0]} field {i + 1} ({what} count) is not "
                                           f"an integer: {words[i][:40]!r}") from None
    if n < 0 or n > 100_000:
        raise _LineProblem("wrong beam count", f"{words[0]} field {i + 1}: {what} count {n} "
                                               "is out of range")
    return n


def _check_fan(fov: float, increment: float, n: int, name: str) -> None:
    """The beam count must fit the angles: lasers log ``fov = (n - 1) * increment`` (a beam at
    each edge) or ``n * increment``; more than a beam and a half off means a corrupt line, whose
    beams would be placed at the wrong angles."""
    if n > 1 and abs(abs(fov) - (n - 1) * abs(increment)) > 1.5 * abs(increment) + 1e-6:
        raise _LineProblem("wrong beam count", f"{name} has {n} beams {increment:g} rad apart, "
                                               f"which does not fit its field of view {fov:g} rad")


def _check_length(words: list[str], need: int, name: str, declared: str) -> None:
    if len(words) < need:
        raise _LineProblem(
            "truncated", f"{name} declares {declared} and needs at least {need} fields, found "
                         f"{len(words)} (truncated line or wrong beam count)")


def _check_trailing(words: list[str], end: int) -> None:
    """After the timestamp only ``host logger_timestamp`` may follow."""
    extra = len(words) - end
    if extra > 2:
        raise _LineProblem(
            "wrong beam count", f"{words[0]} has {extra} fields after its timestamp where at "
                                "most 2 (host, logger timestamp) belong (wrong beam count?)")
    if extra == 2:
        try:
            float(words[end + 1])
        except ValueError:
            raise _LineProblem(
                "not a number", f"{words[0]} field {end + 2} (logger timestamp) is not a "
                                f"number: {words[end + 1][:40]!r}") from None


def _scan(ranges: np.ndarray, angle_min: float, increment: float, range_min: float,
          range_max: float, time: float, name: str) -> Scan:
    try:
        check_angle_increment(float(increment))     # as the LaserScan a robot would send
        return Scan(ranges.astype(np.float32), float(angle_min), float(increment),
                    float(range_min), float(range_max), float(time))
    except (GridError, LogError) as e:
        raise _LineProblem("bad value", f"{name}: {e}") from None
