"""Output directories that are replaced whole, checked before any work starts.

A command first checks that its output directory can be created
(:func:`check_output_dir`, before anything runs), then writes everything into a staging
directory beside it and swaps the two at the end (:func:`stage_and_publish`): an old
result is replaced as a whole, never mixed with a new one, and a run that fails or is
interrupted leaves it untouched. Staging directories left by killed runs (their process
is gone) are removed by the next check of the same directory.

A directory is a semistatic result when it holds ``RESULT_MARKER`` (or, written before
the marker existed, one of ``LEGACY_RESULT_FILES``); a non-empty directory that is not
is never replaced.

Examples
--------
>>> import tempfile
>>> folder = Path(tempfile.mkdtemp())
>>> out = check_output_dir(folder / "run")
>>> stage_and_publish(out, lambda staging: (staging / "a.txt").write_text("1"))
>>> stage_and_publish(out, lambda staging: (staging / "b.txt").write_text("2"))
>>> sorted(path.name for path in out.iterdir())
['.semistatic-result', 'b.txt']
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
import tempfile
from collections.abc import Callable
from pathlib import Path

from scenarios.process.signals import raise_if_stopped
from semistatic.errors import SpecError
from semistatic.validation import loads_json

__all__ = [
    "LEGACY_RESULT_FILES",
    "RESULT_MARKER",
    "check_output_dir",
    "check_resumable_dir",
    "check_writable_parent",
    "is_result_dir",
    "remove_stale_staging",
    "stage_and_publish",
    "write_atomic",
]

RESULT_MARKER = ".semistatic-result"
"""File that marks a directory as written by semistatic (so it may be replaced)."""

LEGACY_RESULT_FILES = ("metrics.json", "sweep.json", "table1.md")
"""Files that mark a result written before ``RESULT_MARKER`` existed."""

FILE_MODE = 0o644
"""File mode of a file written by :func:`write_atomic`: readable by all, as ``open`` makes it."""

_LEFTOVER = re.compile(r"\.(?P<name>.+)\.(?P<kind>staging|previous)-(?P<pid>\d+)-[^.]+$")


def is_result_dir(path: Path) -> bool:
    """Return whether ``path`` is a directory semistatic wrote (or an empty one).

    Examples
    --------
    >>> is_result_dir(Path(tempfile.mkdtemp()))
    True
    """
    if not path.is_dir():
        return False
    if (path / RESULT_MARKER).exists() or any((path / n).exists() for n in LEGACY_RESULT_FILES):
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
    remove_stale_staging(out)
    return out


def stage_and_publish(out: Path, fill: Callable[[Path], None]) -> None:
    """Let ``fill`` write into a staging directory, then make it ``out`` as a whole.

    If ``fill`` raises (or the process is interrupted), ``out`` is untouched; otherwise
    an earlier result in ``out`` is replaced entirely, nothing of it is kept.
    """
    out = check_output_dir(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.staging-{os.getpid()}-",
                                    dir=out.parent))
    try:
        fill(staging)
        raise_if_stopped()  # a stop signal whose exception a finalizer swallowed
        (staging / RESULT_MARKER).write_text("written by semistatic; replaced as a whole\n")
        if out.exists():
            previous = Path(tempfile.mkdtemp(prefix=f".{out.name}.previous-{os.getpid()}-",
                                             dir=out.parent))
            os.replace(out, previous)
            os.rename(staging, out)
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
    writes ``manifest`` with its ``kind`` and ``definition``: the same command resumes it;
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
    if out.is_dir() and manifest_file.is_file():
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
    if out.is_dir() and any(out.iterdir()):
        what = "a result of another command" if is_result_dir(out) else "files of yours"
        raise SpecError("--out", str(out), f"holds {what}; choose a new or empty directory")
    check_writable_parent(out / RESULT_MARKER if out.exists() else out, option="--out")
    return False
