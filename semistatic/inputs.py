r"""Read user files within stated limits: regular files only, bounded size and decompression.

Every file a command reads (a world, a scenario, a log, a recording's manifest and scans,
a storage) goes through :func:`check_regular_file` before it is opened: a FIFO would block
the open for ever, ``/dev/zero`` or a character device never ends, a directory is not a
file. The size limits are a small multiple of the largest valid input we know, so a
hostile file is refused before the reader allocates anything in proportion to it.

Compressed logs are read through :func:`open_bounded`, which stops as soon as more than
its limit of decompressed bytes came out (a gzip bomb of zeros never reaches memory), and
:func:`bounded_lines` yields lines no longer than ``MAX_LINE_BYTES`` (a file without line
breaks is not read whole into one string).

Examples
--------
>>> import tempfile, pathlib
>>> folder = tempfile.TemporaryDirectory()
>>> path = pathlib.Path(folder.name) / "w.toml"
>>> _ = path.write_text("name = 'w'\n")
>>> read_bounded(path, limit=MAX_SPEC_BYTES, what="TOML file")
b"name = 'w'\n"
>>> check_regular_file(folder.name, limit=MAX_SPEC_BYTES, what="TOML file")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
semistatic.errors.SpecError: ...: <file>: is a directory, expected a regular TOML file
>>> folder.cleanup()
"""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import os
import stat
from collections.abc import Iterator
from typing import BinaryIO

from semistatic.errors import SpecError

__all__ = [
    "FILE_KEY",
    "MAX_JSON_BYTES",
    "MAX_LINE_BYTES",
    "MAX_LOG_BYTES",
    "MAX_RECORDING_BYTES",
    "MAX_SPEC_BYTES",
    "BoundedReader",
    "bounded_lines",
    "check_regular_file",
    "open_bounded",
    "read_bounded",
]

FILE_KEY = "<file>"
"""The key reported for problems with the file as a whole (missing, unreadable)."""

MIB = 1 << 20

MAX_SPEC_BYTES = 1 * MIB
"""Largest world or scenario TOML file: the largest bundled one (``worlds/data/warehouse``,
9.5 kB) a hundred times over, room for the 1000 boxes a world may have (about 70 bytes
each); a file at the limit parses in a fraction of a second."""

MAX_JSON_BYTES = 16 * MIB
"""Largest JSON manifest (a recording's ``manifest.json``): a two-lap recording of the
test world's is 3.6 kB (segments, box layouts and the metrics, which grow with the laps),
so this is thousands of times a real one."""

MAX_LOG_BYTES = 64 * MIB
"""Largest laser log, on disk and decompressed: the largest real log we evaluate
(``freiburg-079-corrected.log``, 9.5 MB of text, 2.0 MB gzipped) about seven times over.
``evaluate`` keeps every scan; at the limit that is ~100 MB of float64 ranges."""

MAX_LINE_BYTES = 256 * 1024
"""Longest line of a text log: a ROBOTLASER1 record of ``MAX_BEAMS`` (semistatic.types)
beams with one remission each is ~100 kB; the longest real line is 2.2 kB (csail)."""

MAX_RECORDING_BYTES = 1024 * MIB
"""Largest ``scans.npz`` of a recording: a scan of 541 beams takes 4.6 kB (a two-lap run
of the test world: 387 scans, 1.8 MB), so this holds about 230,000 scans, hundreds of
laps of the bundled scenarios."""

_CHUNK = MIB
"""Bytes read from a decompressor at a time: the most a bounded read overshoots by."""

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)

_MAGIC = (
    (b"\x1f\x8b", lambda raw: gzip.GzipFile(fileobj=raw)),
    (b"BZh", bz2.BZ2File),
    (b"\xfd7zXZ\x00", lzma.LZMAFile),
)


def _mib(size: int) -> str:
    return f"{size / MIB:.1f} MiB" if size >= MIB else f"{size} bytes"


def check_regular_file(path: str | os.PathLike[str], *, limit: int, what: str,
                       file: str | None = None, key: str = FILE_KEY) -> int:
    """Return the size of ``path`` if it is a regular file of at most ``limit`` bytes.

    Checked with ``os.stat`` before anything opens the file, so a FIFO is never opened
    (opening one for reading blocks until a writer comes). Raises :class:`SpecError`
    naming ``file`` (default: the path) and ``key``: no such file, not a regular file
    (a directory, a FIFO, a device, a socket), or larger than ``limit``.

    Examples
    --------
    >>> check_regular_file("/dev/zero", limit=MAX_LOG_BYTES, what="log")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: /dev/zero: <file>: is a character device, expected a \
regular log
    """
    name = str(path) if file is None else file
    try:
        status = os.stat(path)
    except FileNotFoundError:
        raise SpecError(name, key, "no such file") from None
    except OSError as error:
        raise SpecError(name, key, f"cannot read: {error.strerror}") from None
    if not stat.S_ISREG(status.st_mode):
        kind = next((text for test, text in _KINDS if test(status.st_mode)), "not a file")
        raise SpecError(name, key, f"is {kind}, expected a regular {what}")
    if status.st_size > limit:
        raise SpecError(name, key, f"is {_mib(status.st_size)}, more than the limit of "
                        f"{_mib(limit)} for a {what}; is it the right file?")
    return status.st_size


def read_bounded(path: str | os.PathLike[str], *, limit: int, what: str,
                 file: str | None = None, key: str = FILE_KEY) -> bytes:
    """Return the bytes of the regular file ``path`` (:func:`check_regular_file` first).

    The read itself stops at ``limit + 1`` bytes: a file that grew after the check is
    refused the same way.

    Examples
    --------
    >>> read_bounded("/no/such.toml", limit=MAX_SPEC_BYTES, what="TOML file")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: /no/such.toml: <file>: no such file
    """
    check_regular_file(path, limit=limit, what=what, file=file, key=key)
    name = str(path) if file is None else file
    try:
        with open(path, "rb") as stream:
            raw = stream.read(limit + 1)
    except OSError as error:
        raise SpecError(name, key, f"cannot read: {error.strerror}") from None
    if len(raw) > limit:
        raise SpecError(name, key, f"is more than the limit of {_mib(limit)} for a {what}")
    return raw


class BoundedReader(io.RawIOBase):
    """A read-only binary stream over ``stream`` that raises past ``limit`` bytes.

    The error is a :class:`SpecError` naming ``file``: more than ``limit`` bytes
    (decompressed, when ``stream`` is a decompressor) came out.

    Examples
    --------
    >>> reader = BoundedReader(io.BytesIO(b"abcdef"), limit=4, file="x.log", what="log")
    >>> reader.read(4)
    b'abcd'
    >>> reader.read(1)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: x.log: <file>: decompresses to more than the limit of \
4 bytes for a log; is it the right file?
    """

    def __init__(self, stream: BinaryIO, *, limit: int, file: str, what: str) -> None:
        super().__init__()
        self._stream, self._limit, self._file, self._what = stream, limit, file, what
        self._count = 0

    def readable(self) -> bool:
        """Return True: this is a reading stream."""
        return True

    def readinto(self, buffer: memoryview) -> int:  # type: ignore[override]
        """Fill ``buffer`` from the underlying stream, counting the bytes."""
        data = self._stream.read(min(len(buffer), _CHUNK))
        self._count += len(data)
        if self._count > self._limit:
            raise SpecError(self._file, FILE_KEY, f"decompresses to more than the limit of "
                            f"{_mib(self._limit)} for a {self._what}; is it the right file?")
        buffer[: len(data)] = data
        return len(data)

    def close(self) -> None:
        """Close the underlying stream too."""
        self._stream.close()
        super().close()


def open_bounded(path: str | os.PathLike[str], *, limit: int, what: str) -> io.BufferedReader:
    """Open a regular file, decompressed when gzip/bz2/xz (by its first bytes), bounded.

    The file on disk must be at most ``limit`` bytes (:func:`check_regular_file`) and
    reading raises :class:`SpecError` as soon as more than ``limit`` bytes came out of it.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = tempfile.TemporaryDirectory()
    >>> bomb = pathlib.Path(folder.name) / "bomb.log.gz"
    >>> _ = bomb.write_bytes(gzip.compress(bytes(10_000)))
    >>> with open_bounded(bomb, limit=1000, what="log") as stream:  # doctest: +ELLIPSIS
    ...     _ = stream.read()
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: ...bomb.log.gz: <file>: decompresses to more than the \
limit of 1000 bytes for a log; is it the right file?
    >>> folder.cleanup()
    """
    check_regular_file(path, limit=limit, what=what)
    raw: BinaryIO = open(path, "rb")  # noqa: SIM115 (closed by the returned stream)
    magic = raw.read(6)
    raw.seek(0)
    opener = next((make for prefix, make in _MAGIC if magic.startswith(prefix)), None)
    stream = raw if opener is None else opener(raw)
    return io.BufferedReader(BoundedReader(stream, limit=limit, file=str(path), what=what),
                             buffer_size=_CHUNK)


def bounded_lines(stream: io.BufferedReader, *, file: str, limit: int = MAX_LINE_BYTES,
                  ) -> Iterator[str]:
    r"""Yield the lines of ``stream`` (latin-1) at most ``limit`` bytes each, else raise.

    latin-1 decodes every byte, so binary garbage surfaces as a field a parser names.

    Examples
    --------
    >>> list(bounded_lines(io.BufferedReader(io.BytesIO(b"a b\nc\n")), file="x.log"))
    ['a b\n', 'c\n']
    >>> lines = bounded_lines(io.BufferedReader(io.BytesIO(b"x" * 9)), file="x.log", limit=8)
    >>> list(lines)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: x.log: line 1: longer than 8 bytes (no line break); ...
    """
    number = 0
    while True:
        line = stream.readline(limit + 1)
        if not line:
            return
        number += 1
        if len(line) > limit:
            raise SpecError(file, f"line {number}",
                            f"longer than {limit} bytes (no line break); is it a text log?")
        yield line.decode("latin-1")

