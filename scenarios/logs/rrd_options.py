"""What a command checks before it records: the rerun package, the .rrd path, a listening viewer.

``semistatic run``, ``replay`` and ``falsify`` call these before any work, so a bad
``--rrd`` or ``--viewer`` costs nothing: :func:`open_timeline` turns the two options into
a :class:`~scenarios.logs.rrd.RerunRecorder` (or ``None``) after :func:`rerun_missing`,
:func:`check_new_rrd_path` and :func:`check_viewer` have passed.
"""

from __future__ import annotations

import os
import socket
import urllib.parse
from pathlib import Path

from scenarios.logs.rrd import RerunRecorder
from scenarios.process.errors import InputError

__all__ = [
    "DEFAULT_VIEWER_URL",
    "check_new_rrd_path",
    "check_viewer",
    "open_timeline",
    "rerun_missing",
]

DEFAULT_VIEWER_URL = "rerun+http://127.0.0.1:9876/proxy"
"""Where ``--viewer`` streams to by default: a ``rerun`` viewer started on this machine."""


def rerun_missing() -> str | None:
    """Return why Rerun recordings cannot be made here, or ``None`` when they can.

    Examples
    --------
    >>> rerun_missing() is None   # the test extra installs rerun-sdk
    True
    """
    try:
        import rerun  # noqa: F401
    except ImportError:
        return ("Rerun recordings need the rerun-sdk package: pip install 'semistatic[rerun]' "
                "(or pip install rerun-sdk)")
    return None


def check_new_rrd_path(path: str | os.PathLike[str], *, option: str = "--rrd",
                       out: Path | None = None) -> Path:
    """Return ``path`` if a recording can be written there, else raise ``ValueError``.

    Called before a run, so a bad ``--rrd`` costs nothing: the name must end in ``.rrd``,
    its directory must exist, and it must not exist yet, unless it lies directly in
    ``out``, the run's output directory (written first, replacing a previous result whole).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> check_new_rrd_path(folder / "run.rrd").name
    'run.rrd'
    >>> check_new_rrd_path(folder / "run.txt")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: ...run.txt: --rrd: a Rerun recording's name ends in .rrd; e.g. --rrd run.rrd
    >>> folder.rmdir()
    """
    path = Path(path)
    if path.suffix != ".rrd":
        raise ValueError(f"{path}: {option}: a Rerun recording's name ends in .rrd; "
                         f"e.g. {option} run.rrd")
    parent = path.resolve().parent
    # That it is not ``out`` itself is every command's overlap check (check_output_paths).
    if out is not None and parent == out.resolve():
        return path  # lands in the new result, which replaces the old one whole
    if path.exists() or path.is_symlink():
        raise ValueError(f"{path}: {option}: exists already; choose a new file name or "
                         "remove the old recording")
    if not parent.is_dir():
        raise ValueError(f"{path}: {option}: the directory {path.parent} does not exist; "
                         "create it first")
    if not os.access(parent, os.W_OK):
        raise ValueError(f"{path}: {option}: the directory {path.parent} is not writable")
    return path


def check_viewer(url: str, *, timeout: float = 2.0) -> None:
    """Raise :class:`~scenarios.process.errors.InputError` unless a viewer listens at ``url``.

    Checked before a run: streaming to an address where nothing listens would hold the
    command at its end, waiting for a viewer.

    Examples
    --------
    >>> check_viewer("http://127.0.0.1:9876")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    scenarios.process.errors.InputError: --viewer: ... a Rerun viewer's address looks like rerun+http://127.0.0.1:9876/proxy
    """
    parsed = urllib.parse.urlsplit(url)
    if parsed.scheme not in ("rerun", "rerun+http", "rerun+https") or parsed.path != "/proxy":
        raise InputError(f"--viewer: {url!r} is not a Rerun viewer's address; a Rerun "
                         f"viewer's address looks like {DEFAULT_VIEWER_URL}")
    host, port = parsed.hostname or "127.0.0.1", parsed.port or 9876
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as error:
        raise InputError(f"--viewer: no Rerun viewer listens at {url} ({error.strerror or error}); "
                         "start one first with: rerun") from None


def open_timeline(rrd: Path | None, viewer: str | None, out: Path | None,
                  recording_id: str) -> RerunRecorder | None:
    """Return a :class:`RerunRecorder` for a command's ``--rrd``/``--viewer``, or ``None``.

    Checked before any work: the rerun-sdk package, and a new ``.rrd`` path (which may lie
    inside ``out``, the run's output directory, written before the recording lands).
    Bad input raises :class:`~scenarios.process.errors.InputError` (one line, exit 2).

    Examples
    --------
    >>> open_timeline(None, None, None, "run") is None
    True
    >>> open_timeline(Path("run.txt"), None, None, "run")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    scenarios.process.errors.InputError: run.txt: --rrd: a Rerun recording's name ends in .rrd...
    """
    if rrd is None and viewer is None:
        return None
    missing = rerun_missing()
    if missing is not None:
        raise InputError(f"--rrd/--viewer: {missing}")
    if viewer is not None:
        check_viewer(viewer)
    staging = None
    if rrd is not None:
        try:
            check_new_rrd_path(rrd, out=out)
        except ValueError as error:
            raise InputError(str(error)) from None
        parent = rrd.resolve().parent
        # A recording inside --out is staged beside --out (same file system), then moved
        # into the new result: staged inside, the result replacing the old one takes it.
        inside = out is not None and parent == out.resolve()
        staging = out.resolve().parent if inside else parent
    return RerunRecorder(rrd, viewer=viewer, recording_id=recording_id, staging_dir=staging)
