r"""Stream laser scans out of CARMEN log files (plain text, gzip, bz2 or xz).

CARMEN logs are text, one message per line. Two laser records are read:

``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta timestamp host logger_timestamp``
    A front laser with no angle fields; CARMEN's convention by beam count: from -90 deg
    in 1 deg steps for 180/181 beams, 0.5 deg for 360/361, from -50 deg in 0.25 deg
    steps for 400/401 (a 100 deg scanner), otherwise 180 deg from -90 deg in
    ``pi / (n - 1)`` steps. The no-return value (a sentinel such as 81.83 or 50.0) is not
    in the record; :func:`infer_no_return` finds it (see there).
``ROBOTLASER1 type start_angle fov angular_res max_range accuracy remission_mode n r_1 .. r_n
m rem_1 .. rem_m laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
forward_safety_dist side_safety_dist turn_axis timestamp host logger_timestamp``
    Carries its own angles and maximum range; ``m == n`` remissions become intensities.

Every other line (``ODOM``, ``PARAM``, ``NEFF``, ``#`` comments, unknown messages) is
skipped. The scan pose is the laser pose of the record (in the ``*-corrected`` logs the
SLAM-corrected pose). Readings at or above the no-return value / maximum range become
``inf``.

Examples
--------
>>> import tempfile, pathlib
>>> folder = tempfile.TemporaryDirectory()
>>> log = pathlib.Path(folder.name) / "tiny.log"
>>> _ = log.write_text(
...     "# a comment\n"
...     "ODOM 0 0 0 0 0 0 0.5 host 0.5\n"
...     "FLASER 4 1.0 2.0 80.0 3.0 1.0 2.0 0.5 1.0 2.0 0.5 12.5 host 12.5\n"
... )
>>> scans = list(read_carmen(log, max_range=80.0))
>>> scans[0].ranges
array([ 1.,  2., inf,  3.])
>>> scans[0].pose, scans[0].stamp
(array([1. , 2. , 0.5]), 12.5)
>>> folder.cleanup()
"""

from __future__ import annotations

import contextlib
import lzma
import math
import os
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semistatic.errors import SpecError
from semistatic.frames import wrap_angle
from semistatic.inputs import MAX_LOG_BYTES, bounded_lines, check_regular_file, open_bounded
from semistatic.types import MAX_BEAMS, Scan

__all__ = [
    "LogFormatError",
    "ReadStats",
    "flaser_angles",
    "infer_no_return",
    "read_carmen",
]

# The no-return sentinel of a FLASER log is the largest reading, provided it repeats:
# real readings at the far end of a room almost never coincide to the centimetre, the
# sentinel appears on every beam that saw nothing (thousands of times in the four
# reference logs, 620 times in the smallest count, aces).
NO_RETURN_MIN_REPEATS = 5
# Fallback when a FLASER log shows no repeated maximum: a SICK LMS in CARMEN's 80 m mode.
DEFAULT_FLASER_MAX_RANGE = 80.0
# A FLASER line is: name, n, n ranges, then these 9 fields.
FLASER_TRAILING_FIELDS = 9
# A ROBOTLASER1 line is: name, 7 config fields, n, ranges, m, remissions, then these 14.
ROBOTLASER1_CONFIG_FIELDS = 7
ROBOTLASER1_TRAILING_FIELDS = 14
# (angle_min, angle_increment) CARMEN assumes for FLASER records, by beam count
# (carmen_laser_guess_fov / _angle_increment); other counts span 180 deg.
FLASER_ANGLES = {
    180: (math.radians(-90.0), math.radians(1.0)),
    181: (math.radians(-90.0), math.radians(1.0)),
    360: (math.radians(-90.0), math.radians(0.5)),
    361: (math.radians(-90.0), math.radians(0.5)),
    400: (math.radians(-50.0), math.radians(0.25)),
    401: (math.radians(-50.0), math.radians(0.25)),
}
# How many error messages a lenient ReadStats keeps (the count is always exact).
MAX_KEPT_MESSAGES = 20


class LogFormatError(ValueError):
    """Raise when a log line cannot be parsed; the message starts with ``file:line:``.

    Examples
    --------
    >>> str(LogFormatError("run.log:12: FLASER: expected 191 fields, got 120"))
    'run.log:12: FLASER: expected 191 fields, got 120'
    """


@dataclass
class ReadStats:
    """Count what a lenient read skipped; filled in while the scans stream out.

    Attributes
    ----------
    lines
        Lines read so far.
    scans
        Laser records turned into scans.
    malformed
        Laser records skipped because they could not be parsed (``lenient=True``).
    messages
        The first ``MAX_KEPT_MESSAGES`` error messages, ``file:line: what`` each.

    Examples
    --------
    >>> stats = ReadStats()
    >>> stats.malformed, stats.messages
    (0, [])
    """

    lines: int = 0
    scans: int = 0
    malformed: int = 0
    messages: list[str] = field(default_factory=list)


def flaser_angles(beam_count: int) -> tuple[float, float]:
    """Return ``(angle_min, angle_increment)`` of a FLASER record with ``beam_count`` beams.

    Examples
    --------
    >>> [round(math.degrees(a), 3) for a in flaser_angles(180)]
    [-90.0, 1.0]
    >>> [round(math.degrees(a), 3) for a in flaser_angles(360)]
    [-90.0, 0.5]
    >>> [round(math.degrees(a), 3) for a in flaser_angles(401)]
    [-50.0, 0.25]
    """
    if beam_count < 2:
        raise ValueError(f"flaser_angles: beam_count must be >= 2, got {beam_count}")
    return FLASER_ANGLES.get(beam_count, (-math.pi / 2, math.pi / (beam_count - 1)))


def infer_no_return(path: str | os.PathLike[str]) -> float | None:
    r"""Return the no-return sentinel of a CARMEN log's FLASER records, or None.

    The sentinel is the largest FLASER reading when it occurs at least
    ``NO_RETURN_MIN_REPEATS`` times; None when there are no FLASER records or the
    maximum does not repeat (then no reading is a sentinel). Malformed lines are
    ignored here; :func:`read_carmen` reports them.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = tempfile.TemporaryDirectory()
    >>> log = pathlib.Path(folder.name) / "tiny.log"
    >>> line = "FLASER 4 1.0 50 50 2.0 0 0 0 0 0 0 1.0 host 1.0\n"
    >>> _ = log.write_text(line * 3)
    >>> infer_no_return(log)
    50.0
    >>> folder.cleanup()
    """
    largest = -math.inf
    repeats = 0
    with _open_text(Path(path)) as lines:
        for line in lines:
            if not line.startswith("FLASER"):
                continue
            tokens = line.split()
            try:
                count = int(tokens[1])
                ranges = np.array(tokens[2 : 2 + count], dtype=np.float64)
            except (IndexError, ValueError):
                continue
            finite = ranges[np.isfinite(ranges)]
            if finite.size == 0:
                continue
            line_max = float(finite.max())
            if line_max > largest:
                largest, repeats = line_max, 0
            if line_max == largest:
                repeats += int(np.count_nonzero(finite == largest))
    return largest if repeats >= NO_RETURN_MIN_REPEATS else None


def read_carmen(
    path: str | os.PathLike[str],
    *,
    max_range: float | None = None,
    lenient: bool = False,
    stats: ReadStats | None = None,
) -> Iterator[Scan]:
    r"""Yield the laser scans of a CARMEN log, one line at a time.

    Parameters
    ----------
    path
        A ``.log`` file, plain or gzip-compressed (detected from its first bytes).
    max_range
        Readings ``>=`` this (m) become ``inf``. None: FLASER records use the log's
        no-return value from :func:`infer_no_return` (one extra streaming pass), or
        ``DEFAULT_FLASER_MAX_RANGE`` when it has none; ROBOTLASER1 records use their
        own ``max_range`` field (and the smaller of both when ``max_range`` is given).
    lenient
        Skip malformed laser records (counted in ``stats``) instead of raising.
    stats
        Optional :class:`ReadStats` updated as the scans stream out.

    Yields
    ------
    Scan
        Ranges, beam angles, ``range_max``, ``stamp`` (the record's timestamp, s),
        ``pose`` (the laser pose ``(x, y, theta)``) and, for ROBOTLASER1 records with
        one remission per beam, ``intensities``.

    Raises
    ------
    FileNotFoundError
        At the call, when ``path`` is not a file.
    LogFormatError
        While iterating: a malformed laser record (``"file:line: what"``; not with
        ``lenient=True``), a corrupt gzip stream (already at the call when the
        no-return value is inferred), or a file without laser records.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = tempfile.TemporaryDirectory()
    >>> log = pathlib.Path(folder.name) / "bad.log"
    >>> _ = log.write_text("FLASER 3 1.0 2.0\n")
    >>> next(read_carmen(log))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.logs.carmen.LogFormatError: ...bad.log:1: FLASER: truncated record...
    >>> folder.cleanup()
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such CARMEN log file")
    try:  # before anything opens it: a FIFO blocks the open, /dev/zero never ends
        check_regular_file(path, limit=MAX_LOG_BYTES, what="log")
    except SpecError as error:
        raise LogFormatError(str(error)) from None
    if max_range is not None and not max_range > 0:
        raise ValueError(f"read_carmen: max_range must be > 0 m or None, got {max_range}")
    if max_range is None:
        try:
            no_return = infer_no_return(path)
        except (EOFError, OSError, zlib.error, lzma.LZMAError) as error:
            raise LogFormatError(
                f"{path}: cannot read the file ({error}); is it a complete log?"
            ) from error
        flaser_max_range = DEFAULT_FLASER_MAX_RANGE if no_return is None else no_return
    else:
        flaser_max_range = float(max_range)
    stats = ReadStats() if stats is None else stats
    return _scan_stream(path, flaser_max_range, max_range, lenient, stats)


def _scan_stream(
    path: Path,
    flaser_max_range: float,
    max_range: float | None,
    lenient: bool,
    stats: ReadStats,
) -> Iterator[Scan]:
    number = 0
    with _open_text(path) as lines:
        try:
            for number, line in enumerate(lines, start=1):
                stats.lines = number
                if not line.startswith(("FLASER", "ROBOTLASER1")):
                    continue
                tokens = line.split()
                try:
                    if tokens[0] == "FLASER":
                        scan = _parse_flaser(tokens, flaser_max_range)
                    elif tokens[0] == "ROBOTLASER1":
                        scan = _parse_robotlaser1(tokens, max_range)
                    else:  # e.g. FLASERX: an unknown message
                        continue
                except _RecordError as error:
                    message = f"{path}:{number}: {error}"
                    if not lenient:
                        raise LogFormatError(message) from None
                    stats.malformed += 1
                    if len(stats.messages) < MAX_KEPT_MESSAGES:
                        stats.messages.append(message)
                    continue
                stats.scans += 1
                yield scan
        except (EOFError, OSError, zlib.error, lzma.LZMAError) as error:
            # A truncated or corrupt .gz file fails while decompressing, not while parsing.
            raise LogFormatError(
                f"{path}:{number + 1}: cannot read the file ({error}); is it a complete log?"
            ) from error
    if stats.scans == 0:
        skipped = f" ({stats.malformed} malformed skipped)" if stats.malformed else ""
        raise LogFormatError(
            f"{path}: no laser records (FLASER or ROBOTLASER1 lines){skipped}; "
            "is this a CARMEN log?"
        )


class _RecordError(Exception):
    """What is wrong with one record; the caller adds file and line."""


@contextlib.contextmanager
def _open_text(path: Path) -> Iterator[Iterator[str]]:
    """Yield the lines of ``path``, decompressed when gzip/bz2/xz, within the limits.

    At most ``MAX_LOG_BYTES`` on disk and decompressed and ``MAX_LINE_BYTES`` a line
    (:mod:`semistatic.inputs`): a gzip bomb or a file without line breaks is refused
    before it fills the memory. Its SpecError becomes a :class:`LogFormatError`.
    """
    try:
        with open_bounded(path, limit=MAX_LOG_BYTES, what="log") as stream:
            yield bounded_lines(stream, file=str(path))
    except SpecError as error:
        raise LogFormatError(str(error)) from None


def _floats(tokens: list[str], what: str) -> np.ndarray:
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise _RecordError(f"{what}: non-numeric field {bad!r}") from None


def _finite(values: np.ndarray, what: str) -> np.ndarray:
    """Return ``values`` if every one is finite (a pose or a stamp), else raise."""
    if not np.all(np.isfinite(values)):
        raise _RecordError(f"{what}: must be finite numbers, got {values.tolist()}")
    return values


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _count(tokens: list[str], index: int, record: str, what: str) -> int:
    if len(tokens) <= index:
        raise _RecordError(f"{record}: truncated record, no {what} field")
    try:
        value = int(tokens[index])
    except ValueError:
        # A remission count that is not an integer usually means the beam count is off.
        hint = " (is the beam count right?)" if what == "remission count" else ""
        raise _RecordError(
            f"{record}: {what} must be an integer, got {tokens[index]!r}{hint}"
        ) from None
    if value < 0:
        raise _RecordError(f"{record}: {what} must be >= 0, got {value}")
    return value


def _check_beams(beams: int, record: str) -> None:
    if beams > MAX_BEAMS:
        raise _RecordError(f"{record}: {beams} beams, more than the limit of {MAX_BEAMS} "
                           "(real 2D lasers have a few thousand at most)")


def _check_length(tokens: list[str], expected: int, record: str, beams: int) -> None:
    if len(tokens) < expected:
        raise _RecordError(
            f"{record}: truncated record (or wrong beam count): {beams} beams declared "
            f"means {expected} fields, got {len(tokens)}"
        )
    if len(tokens) > expected:
        raise _RecordError(
            f"{record}: wrong beam count: {beams} beams declared means {expected} fields, "
            f"got {len(tokens)}"
        )


def _no_return_to_inf(ranges: np.ndarray, limit: float | None) -> np.ndarray:
    if limit is not None:
        with np.errstate(invalid="ignore"):
            ranges[ranges >= limit] = np.inf
    return ranges


def _parse_flaser(tokens: list[str], limit: float) -> Scan:
    beams = _count(tokens, 1, "FLASER", "beam count")
    if beams < 2:
        raise _RecordError(f"FLASER: wrong beam count, need >= 2 beams, got {beams}")
    _check_beams(beams, "FLASER")
    _check_length(tokens, 2 + beams + FLASER_TRAILING_FIELDS, "FLASER", beams)
    ranges = _floats(tokens[2 : 2 + beams], "FLASER range")
    tail = 2 + beams
    # x y theta odom_x odom_y odom_theta timestamp host logger_timestamp
    numbers = _finite(_floats(tokens[tail : tail + 7], "FLASER pose/timestamp"),
                      "FLASER pose/timestamp")
    pose, stamp = numbers[:3], numbers[6]
    _floats(tokens[tail + 8 : tail + 9], "FLASER logger timestamp")
    angle_min, increment = flaser_angles(beams)
    return Scan(
        ranges=_no_return_to_inf(ranges, limit),
        angle_min=angle_min,
        angle_increment=increment,
        range_max=limit,
        stamp=stamp,
        pose=(pose[0], pose[1], wrap_angle(pose[2])),
    )


def _parse_robotlaser1(tokens: list[str], limit: float | None) -> Scan:
    beams = _count(tokens, 1 + ROBOTLASER1_CONFIG_FIELDS, "ROBOTLASER1", "beam count")
    _check_beams(beams, "ROBOTLASER1")
    remissions_at = 2 + ROBOTLASER1_CONFIG_FIELDS + beams
    remissions = _count(tokens, remissions_at, "ROBOTLASER1", "remission count")
    expected = remissions_at + 1 + remissions + ROBOTLASER1_TRAILING_FIELDS
    _check_length(tokens, expected, "ROBOTLASER1", beams)
    # type start_angle fov angular_res max_range accuracy remission_mode
    config = _floats(tokens[1 : 1 + ROBOTLASER1_CONFIG_FIELDS], "ROBOTLASER1 config")
    start_angle, increment, record_max_range = config[1], config[3], config[4]
    if not increment > 0:
        raise _RecordError(f"ROBOTLASER1: angular_res must be > 0, got {increment}")
    if not record_max_range > 0:
        raise _RecordError(f"ROBOTLASER1: max_range must be > 0, got {record_max_range}")
    ranges = _floats(tokens[remissions_at - beams : remissions_at], "ROBOTLASER1 range")
    intensities = None
    if remissions:
        values = _floats(
            tokens[remissions_at + 1 : remissions_at + 1 + remissions], "ROBOTLASER1 remission"
        )
        intensities = values if remissions == beams else None
    tail = remissions_at + 1 + remissions
    # laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv fsd ssd turn_axis
    # timestamp host logger_timestamp
    numbers = _floats(tokens[tail : tail + 12], "ROBOTLASER1 pose")
    _finite(numbers[[0, 1, 2, 11]], "ROBOTLASER1 laser pose/timestamp")
    _floats(tokens[tail + 13 : tail + 14], "ROBOTLASER1 logger timestamp")
    range_max = float(record_max_range) if limit is None else min(limit, record_max_range)
    return Scan(
        ranges=_no_return_to_inf(ranges, range_max),
        angle_min=start_angle,
        angle_increment=increment,
        range_max=range_max,
        intensities=intensities,
        stamp=numbers[11],
        pose=(numbers[0], numbers[1], wrap_angle(numbers[2])),
    )
