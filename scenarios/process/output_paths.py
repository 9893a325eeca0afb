"""Every path a command writes, resolved and checked against the others before any work.

A command names the paths it will write (``--out``, ``--record``, ``--bag``, ``--rrd``,
a ``sqlite:///`` ``--storage``, report files) and the files it reads, and calls
:func:`check_output_paths` once, before anything runs. Paths are compared resolved
(symlinks, ``.``, ``..``), so two spellings of one place are one place. Refused, with
one line naming both options:

- two outputs at the same place, or one inside another (one would overwrite or delete
  the other), except the outputs a command puts into its new result on purpose
  (``--bag OUT/bag``);
- a storage (a study that outlives the command) inside a directory that is replaced as
  a whole, except the storage the command keeps there itself (tune's ``OUT/study.db``);
  inside a directory filled in place (falsify's ``--out``) it is kept and allowed;
- a replaced directory that is the current directory, holds it, or holds an input.

Examples
--------
>>> import tempfile
>>> folder = Path(tempfile.mkdtemp())
>>> check_output_paths({"--out": folder / "out", "--record": folder / "rec"})
>>> check_output_paths({"--out": folder / "out", "--record": folder / "out/../out"})
... # doctest: +ELLIPSIS
Traceback (most recent call last):
...
semistatic.errors.SpecError: --record: .../out: is --out .../out, which is replaced as a \
whole; choose a path outside it
>>> folder.rmdir()
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path

from semistatic.errors import SpecError

__all__ = ["check_output_paths", "sqlite_path"]

_Paths = str | os.PathLike[str] | Iterable[str | os.PathLike[str]] | None


def sqlite_path(url: str | None) -> Path | None:
    """Return the file of an SQLite storage URL, ``None`` for other storages.

    Parsed as Optuna's SQLAlchemy parses it (``sqlite:///``, ``sqlite+pysqlite:///``, a
    query string); an in-memory database and a string that is no URL have no file.

    Examples
    --------
    >>> sqlite_path("sqlite:////tmp/out/study.db"), sqlite_path("sqlite:///study.db")
    (PosixPath('/tmp/out/study.db'), PosixPath('study.db'))
    >>> sqlite_path("postgresql://host/db") is None, sqlite_path("sqlite:///:memory:")
    (True, None)
    """
    if url is None:
        return None
    import sqlalchemy.engine  # Optuna's dependency: imported only where a storage is named
    import sqlalchemy.exc

    try:
        parsed = sqlalchemy.engine.make_url(url)
    except sqlalchemy.exc.ArgumentError:
        return None  # not a URL: Optuna's own error says so
    if parsed.get_backend_name() != "sqlite" or parsed.database in (None, "", ":memory:"):
        return None
    return Path(parsed.database)


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def check_output_paths(
    outputs: Mapping[str, str | os.PathLike[str] | None],
    *,
    replaced: str | None = "--out",
    into_result: Iterable[str] = (),
    storages: Iterable[str] = (),
    managed: Iterable[str | os.PathLike[str]] = (),
    inputs: Mapping[str, _Paths] | None = None,
) -> None:
    """Raise :class:`SpecError` when the paths a command writes overlap; see the module.

    Parameters
    ----------
    outputs
        Option name to the path it writes (``None``: not given, skipped).
    replaced
        The option (in ``outputs``) whose directory is replaced as a whole, if any.
    into_result
        Options written into the new ``replaced`` directory after it is published: they
        may lie inside it (not be it).
    storages
        Options in ``outputs`` that are storages (they must outlive ``replaced``).
    managed
        Storage files the command keeps inside ``replaced`` itself (carried over).
    inputs
        Option (or ``"scenario file"``, ``"LOG"``) to the file or directory (or a list of
        them) the command reads.

    Examples
    --------
    >>> check_output_paths({"--out": "/tmp/o", "--storage": "/tmp/o/mine.db"},
    ...                    storages=["--storage"])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --storage: /tmp/o/mine.db: is inside --out /tmp/o, which \
is replaced as a whole when the command ends (the study would be deleted); keep the \
storage outside it
    >>> check_output_paths({"--out": "/tmp/o", "--storage": "/tmp/o/study.db"},
    ...                    storages=["--storage"], managed=["/tmp/o/study.db"])
    >>> check_output_paths({"--out": "/tmp/o", "--bag": "/tmp/o/bag"}, into_result=["--bag"])
    """
    given = {option: Path(path).resolve() for option, path in outputs.items()
             if path is not None}
    spelled = {option: str(path) for option, path in outputs.items() if path is not None}
    storages, into_result = set(storages), set(into_result)
    managed_files = {Path(path).resolve() for path in managed}
    read = [(source, str(path), Path(path).resolve())
            for source, paths in (inputs or {}).items() for path in _listed(paths)]
    folder = given.get(replaced) if replaced is not None else None
    if folder is not None:
        _check_replaced(replaced, folder, spelled[replaced], read)
    names = list(given)
    for index, option in enumerate(names):
        for other in names[index + 1:]:
            _check_pair(option, other, given, spelled, replaced=replaced,
                        into_result=into_result, storages=storages, managed=managed_files)
    for option, path in given.items():
        for source, _, input_path in read:
            if path == input_path and option not in storages:
                raise SpecError(option, spelled[option],
                                f"is the {source} the command reads; choose another path")


def _listed(paths: _Paths) -> list[str | os.PathLike[str]]:
    if paths is None:
        return []
    if isinstance(paths, (str, os.PathLike)):
        return [paths]
    return [path for path in paths if path is not None]


def _check_replaced(option: str, folder: Path, spelled: str,
                    read: list[tuple[str, str, Path]]) -> None:
    """Refuse a replaced directory that holds the current directory or an input."""
    cwd = Path.cwd().resolve()
    if _inside(cwd, folder):
        where = "is the current directory" if cwd == folder else "holds the current directory"
        raise SpecError(option, spelled, f"{where} ({cwd}), which would be replaced as a "
                        "whole; choose a new directory, e.g. results/NAME")
    for source, path, resolved in read:
        if _inside(resolved, folder):
            raise SpecError(option, spelled, f"holds the {source} {path}, which would be "
                            "deleted when the directory is replaced; choose another directory")


def _check_pair(option: str, other: str, given: dict[str, Path], spelled: dict[str, str], *,
                replaced: str | None, into_result: set[str], storages: set[str],
                managed: set[Path]) -> None:
    """Refuse two outputs at one place, or one inside the other (with the stated exceptions)."""
    first, second = given[option], given[other]
    if first == second:
        what = (", which is replaced as a whole; choose a path outside it"
                if replaced in (option, other) else "; give each its own path")
        later = option if other == replaced else other  # named: the one to change
        earlier = other if later == option else option
        raise SpecError(later, spelled[later], f"is {earlier} {spelled[earlier]}{what}")
    for inner, outer in ((option, other), (other, option)):
        if not _inside(given[inner], given[outer]):
            continue
        if outer == replaced and inner in storages:
            if given[inner] in managed:
                return
            raise SpecError(inner, spelled[inner], f"is inside {outer} {spelled[outer]}, which "
                            "is replaced as a whole when the command ends (the study would be "
                            "deleted); keep the storage outside it")
        if outer == replaced and inner in into_result:
            return
        if inner in storages:
            return  # a directory that is kept (filled in place) may hold the study
        if outer == replaced:
            raise SpecError(inner, spelled[inner], f"is inside {outer} {spelled[outer]}, which "
                            "is replaced as a whole; choose a path outside it")
        raise SpecError(inner, spelled[inner], f"is inside {outer} {spelled[outer]}; give each "
                        "its own path")
