"""Output directories that are replaced whole, checked before any work starts.

A command first checks that its output directory can be created
(:func:`check_output_dir`, before anything runs), then writes everything into a staging
directory beside it and swaps the two at the end (:func:`stage_and_publish`): an old
result is replaced as a whole, never mixed with a new one, and a run that fails or is
interrupted leaves it untouched. Staging directories left by killed runs (their process
is gone) are removed by the next check of the same directory.

A directory is a semistatic result only when its ``RESULT_MARKER`` file is the small JSON
document our commands write (:func:`write_result_marker`: the command and a random id);
a file of that name with any other content, or result-like files such as a
``metrics.json``, do not make a directory ours, and a non-empty directory that is not
ours is never replaced.

Examples
--------
>>> import tempfile
>>> folder = Path(tempfile.mkdtemp())
>>> out = check_output_dir(folder / "run")
>>> stage_and_publish(out, lambda staging: (staging / "a.txt").write_text("1"),
...                   command="run")
>>> stage_and_publish(out, lambda staging: (staging / "b.txt").write_text("2"),
...                   command="run")
>>> sorted(path.name for path in out.iterdir())
['.semistatic-result', 'b.txt']
>>> read_result_marker(out)["command"]
'run'
>>> check_output_dir(folder / "run" / "b.txt" / "deeper")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
semistatic.errors.SpecError: --out: .../b.txt/deeper: cannot create it: .../b.txt is a file...
>>> shutil.rmtree(folder)
"""

from __future__ import annotations

import json
import os
import re
import shutil
import stat
import tempfile
import uuid
from collections.abc import Callable
from pathlib import Path

from scenarios.process.errors import WRITE_ERRNOS
from scenarios.process.signals import raise_if_stopped
from semistatic.errors import SpecError
from semistatic.validation import loads_json

__all__ = [
    "MARKER_FORMAT",
    "RESULT_MARKER",
    "check_output_dir",
    "check_resumable_dir",
    "check_writable_parent",
    "is_result_dir",
    "read_result_marker",
    "remove_stale_staging",
    "stage_and_publish",
    "write_atomic",
    "write_result_marker",
]

RESULT_MARKER = ".semistatic-result"
"""File that marks a directory as written by semistatic (so it may be replaced)."""

MARKER_FORMAT = 1
"""Version of the marker document (its ``"semistatic"`` key)."""

_MARKER_BYTES = 4096  # a real marker is ~90 bytes; a larger file is not one of ours
_MARKER_ID = re.compile(r"[0-9a-f]{32}")
_MARKER_COMMAND = re.compile(r"[a-z][a-z-]{0,31}")

FILE_MODE = 0o644
"""File mode of a file written by :func:`write_atomic`: readable by all, as ``open`` makes it."""

_LEFTOVER = re.compile(r"\.(?P<name>.+)\.(?P<kind>staging|previous)-(?P<pid>\d+)-[^.]+$")


def write_result_marker(directory: Path, command: str) -> dict:
    """Mark ``directory`` as a result of ``command``; return the marker document written.

    The marker is ``{"semistatic": 1, "command": COMMAND, "id": RANDOM_HEX}``: a random
    id (``uuid4``) that no user file carries by chance. Written atomically, so a killed
    command leaves the old marker or the new one.

    Examples
    --------
    >>> folder = Path(tempfile.mkdtemp())
    >>> sorted(write_result_marker(folder, "tune"))
    ['command', 'id', 'semistatic']
    >>> read_result_marker(folder) == json.loads((folder / RESULT_MARKER).read_text())
    True
    >>> shutil.rmtree(folder)
    """
    if _MARKER_COMMAND.fullmatch(command) is None:
        raise ValueError(f"write_result_marker: {command!r} is not a command name")
    marker = {"semistatic": MARKER_FORMAT, "command": command, "id": uuid.uuid4().hex}
    write_atomic(directory / RESULT_MARKER, json.dumps(marker) + "\n")
    return marker


def read_result_marker(directory: Path) -> dict | None:
    """Return the marker document of ``directory``, or ``None`` when it carries none.

    Only a regular file of at most a few kB whose JSON is exactly the document
    :func:`write_result_marker` writes counts: an empty file, other text, a FIFO or a
    symlink named like the marker do not.

    Examples
    --------
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / RESULT_MARKER).write_text("written by me")
    >>> read_result_marker(folder) is None
    True
    >>> read_result_marker(folder / "missing") is None
    True
    >>> shutil.rmtree(folder)
    """
    marker_file = directory / RESULT_MARKER
    try:
        # lstat, not stat: a symlink named like the marker could point at anything.
        info = marker_file.lstat()
        if not stat.S_ISREG(info.st_mode) or info.st_size > _MARKER_BYTES:
            return None
        found = json.loads(marker_file.read_bytes())
    except (OSError, ValueError, RecursionError):
        return None
    if (not isinstance(found, dict) or set(found) != {"semistatic", "command", "id"}
            or found["semistatic"] != MARKER_FORMAT or isinstance(found["semistatic"], bool)
            or not isinstance(found["command"], str)
            or _MARKER_COMMAND.fullmatch(found["command"]) is None
            or not isinstance(found["id"], str) or _MARKER_ID.fullmatch(found["id"]) is None):
        return None
    return found


def is_result_dir(path: Path) -> bool:
    """Return whether ``path`` is a directory semistatic wrote (or an empty one).

    Examples
    --------
    >>> folder = Path(tempfile.mkdtemp())
    >>> is_result_dir(folder)
    True
    >>> _ = (folder / "metrics.json").write_text("{}")
    >>> is_result_dir(folder)
    False
    >>> _ = write_result_marker(folder, "run")
    >>> is_result_dir(folder)
    True
    >>> shutil.rmtree(folder)
    """
    if not path.is_dir():
        return False
    if read_result_marker(path) is not None:
        return True
    return not any(path.iterdir())


def _process_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # somebody else's process: alive
        return True
    return True


def remove_stale_staging(out: Path) -> None:
    """Remove the staging directories of ``out`` whose process is gone.

    A ``previous`` copy (the old result moved aside for the swap) is put back when the
    swap never finished, so a kill at the worst moment still leaves the old result.
    """
    if not out.parent.is_dir():
        return
    for leftover in out.parent.glob(f".{out.name}.*-*"):
        match = _LEFTOVER.fullmatch(leftover.name)
        if match is None or match["name"] != out.name or _process_alive(int(match["pid"])):
            continue
        if match["kind"] == "previous" and not out.exists():
            os.rename(leftover, out)
        else:
            shutil.rmtree(leftover, ignore_errors=True)


def check_writable_parent(path: Path, *, option: str) -> None:
    """Raise :class:`SpecError` naming ``option`` unless ``path`` can be created.

    The nearest existing ancestor must be a directory in which a directory can be made
    (tried, not guessed from permission bits, which root ignores).

    Examples
    --------
    >>> check_writable_parent(Path("/proc/semistatic/x"), option="--bag")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --bag: /proc/semistatic/x: cannot create it in /proc: ...
    """
    ancestor = path.parent.absolute()
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise SpecError(
            option, str(path), f"cannot create it: {ancestor} is a file, not a directory"
        )
    try:
        Path(tempfile.mkdtemp(prefix=".semistatic-probe-", dir=ancestor)).rmdir()
    except OSError as error:
        reason = error.strerror or str(error)
        raise SpecError(option, str(path), f"cannot create it in {ancestor}: {reason}") from None


def check_output_dir(out: str | os.PathLike[str], *, option: str = "--out") -> Path:
    """Return ``out`` as a path if a result can be published there, else raise.

    Call it before any work: ``out`` must be new, empty or an earlier semistatic result,
    and creatable. Stale staging directories of ``out`` are removed on the way.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise SpecError(option, str(out), "exists and is not a directory; choose a directory")
    if out.exists() and not is_result_dir(out):
        raise SpecError(
            option, str(out),
            "is a non-empty directory that is not a semistatic result; choose a new or "
            "empty directory (results replace the directory as a whole)",
        )
    check_writable_parent(out / RESULT_MARKER if out.exists() else out, option=option)
    remove_stale_staging(out.resolve())
    return out


def stage_and_publish(out: Path, fill: Callable[[Path], None], *, command: str) -> None:
    """Let ``fill`` write into a staging directory, then make it ``out`` as a whole.

    If ``fill`` raises (a full disk included) or the process is interrupted, ``out`` is
    untouched and the staging directory removed; otherwise an earlier result in ``out``
    is replaced entirely, nothing of it is kept, and the new one is marked as written by
    ``command`` (:func:`write_result_marker`).
    """
    # Published where ``out`` really is: a symlink to a result keeps pointing at the new one.
    out = check_output_dir(out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.staging-{os.getpid()}-",
                                    dir=out.parent))
    try:
        try:
            fill(staging)
            raise_if_stopped()  # a stop signal whose exception a finalizer swallowed
            write_result_marker(staging, command)
        except OSError as error:
            if error.filename is not None or error.errno not in WRITE_ERRNOS:
                raise
            # A write through an open file names no path: name the result being written.
            raise OSError(error.errno, error.strerror, str(out)) from error
        if out.exists():
            previous = Path(tempfile.mkdtemp(prefix=f".{out.name}.previous-{os.getpid()}-",
                                             dir=out.parent))
            os.replace(out, previous)
            try:
                os.rename(staging, out)
            except BaseException:
                os.rename(previous, out)  # the old result back in place, whole
                raise
            shutil.rmtree(previous, ignore_errors=True)
        else:
            os.rename(staging, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def write_atomic(path: Path, data: str | bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder, renamed.

    Readers (and a later run after a kill) see the old file or the whole new one, never
    a truncated one.

    Examples
    --------
    >>> target = Path(tempfile.mkdtemp()) / "note.txt"
    >>> write_atomic(target, "one")
    >>> write_atomic(target, b"two")
    >>> target.read_text(), [p.name for p in target.parent.iterdir()]
    ('two', ['note.txt'])
    """
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(data.encode() if isinstance(data, str) else data)
        os.chmod(temporary, FILE_MODE)  # mkstemp makes its files private to the owner
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def check_resumable_dir(out: Path, *, manifest: str, kind: str, definition: dict,
                        noun: str) -> bool:
    """Return whether ``out`` holds the same resumable result to go on with; raise if unusable.

    A command whose directory fills as it works (a campaign, a falsification search)
    marks it (:func:`write_result_marker`) and writes ``manifest`` with its ``kind`` and
    ``definition``: the same command resumes it (a manifest without a marker is not ours);
    another ``noun`` (other definition values), another result or files of the user's are
    refused, and a new or empty directory must be creatable.

    Examples
    --------
    >>> folder = Path(tempfile.mkdtemp())
    >>> check_resumable_dir(folder / "new", manifest="m.json", kind="k", definition={},
    ...                     noun="search")
    False
    >>> (folder / "mine").mkdir(); _ = (folder / "mine" / "notes.md").write_text("mine")
    >>> check_resumable_dir(folder / "mine", manifest="m.json", kind="k", definition={},
    ...                     noun="search")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --out: .../mine: holds files of yours; choose a new or empty \
directory
    >>> shutil.rmtree(folder)
    """
    manifest_file = out / manifest
    if out.exists() and not out.is_dir():
        raise SpecError("--out", str(out), "exists and is not a directory; choose a directory")
    ours = out.is_dir() and read_result_marker(out) is not None
    if ours and manifest_file.is_file():
        try:
            found = loads_json(manifest_file.read_text(), file="--out", key=str(manifest_file))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, SpecError):
            found = None  # unreadable or absurdly nested: not a manifest this command wrote
        if not isinstance(found, dict) or found.get("kind") != kind:
            raise SpecError("--out", str(out), f"holds a result that is not a {noun}; choose "
                            "a new or empty directory")
        differs = [key for key, value in definition.items()
                   if found.get("definition", {}).get(key) != value]
        if differs:
            raise SpecError("--out", str(out), f"holds another {noun} (its {', '.join(differs)}"
                            " differ); choose another --out, or delete it to start again")
        return True
    # Only our marker (a command killed before its manifest was written): start afresh.
    if out.is_dir() and any(path.name != RESULT_MARKER or not ours for path in out.iterdir()):
        what = "a result of another command" if ours else "files of yours"
        raise SpecError("--out", str(out), f"holds {what}; choose a new or empty directory")
    check_writable_parent(out / RESULT_MARKER if out.exists() else out, option="--out")
    return False
