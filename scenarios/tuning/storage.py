"""Check an Optuna storage URL before Optuna touches it: never another program's database.

Optuna opens an SQLite URL by creating its tables in whatever database it finds: a user's
own database given by mistake as ``--storage sqlite:///mine.db`` would get 13 tables added
beside theirs. :func:`check_storage` refuses that before Optuna connects: an SQLite file
that exists must be a regular file, empty (0 bytes, or a database without tables) or an
Optuna storage (:data:`OPTUNA_TABLES`), read through a read-only connection, and writable
with its directory (SQLite writes a journal beside it). Other URLs (a PostgreSQL server)
are left to Optuna, whose errors :mod:`scenarios.tuning.search` reports in one line.

Examples
--------
>>> import sqlite3, tempfile, pathlib
>>> folder = tempfile.TemporaryDirectory()
>>> mine = pathlib.Path(folder.name) / "mine.db"
>>> with sqlite3.connect(mine) as db:
...     _ = db.execute("CREATE TABLE notes (text)")
>>> check_storage(f"sqlite:///{mine}")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
semistatic.errors.SpecError: --storage: sqlite:///...mine.db: ...mine.db is a database of \
another program (tables: notes), not an Optuna storage; name a new file
>>> check_storage(f"sqlite:///{pathlib.Path(folder.name) / 'new.db'}")
>>> folder.cleanup()
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import stat
import urllib.parse
from pathlib import Path

import optuna

from scenarios.process.output_paths import sqlite_path
from semistatic.errors import SpecError
from semistatic.inputs import check_regular_file

__all__ = [
    "GRACE_S",
    "HEARTBEAT_S",
    "MAX_STORAGE_BYTES",
    "OPTUNA_TABLES",
    "STORAGE_OPTION",
    "check_storage",
    "open_storage",
]

STORAGE_OPTION = "--storage"
HEARTBEAT_S = 2
"""Seconds between heartbeats of a running trial (Optuna wants an integer)."""
GRACE_S = 6
"""Seconds without a heartbeat after which a running trial counts as abandoned."""

OPTUNA_TABLES = frozenset({"studies", "trials", "version_info", "alembic_version"})
"""Tables every Optuna RDB storage has (of its 13): a database holding them is one."""

MAX_STORAGE_BYTES = 16 << 30
"""Largest SQLite storage file: SQLite reads pages on demand, so this only catches a wrong
file; a 10,000-trial study takes about 50 MB."""

SQLITE_MAGIC = b"SQLite format 3\x00"


def _read_only(path: Path) -> bool:
    # os.access says "writable" to root whatever the mode; a file or directory without
    # any write bit was made read-only on purpose, and Optuna would fail on it half-way.
    mode = os.stat(path).st_mode
    return not os.access(path, os.W_OK) or stat.S_IMODE(mode) & 0o222 == 0


def check_storage(url: str) -> None:
    """Raise :class:`SpecError` unless ``url`` is a storage Optuna may open and write.

    For an SQLite URL: the file is new (its directory writable), or a regular writable
    file that is empty, a database without tables or an Optuna storage; anything else
    is refused untouched (read through ``mode=ro``). Other URLs pass unchecked.

    Examples
    --------
    >>> check_storage("postgresql://host/db")
    >>> check_storage("sqlite:////dev/zero")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --storage: sqlite:////dev/zero: is a character device, \
expected a regular SQLite file
    """
    path = sqlite_path(url)
    if path is None:
        return
    if not path.exists():
        parent = path.parent if str(path.parent) else Path(".")
        if not parent.is_dir():
            raise SpecError(STORAGE_OPTION, url, f"cannot open the storage: its directory "
                            f"{parent} does not exist; create it or name another file")
        if _read_only(parent):
            raise SpecError(STORAGE_OPTION, url, f"cannot open the storage: its directory "
                            f"{parent} is read-only; name a file in a writable directory")
        return
    size = check_regular_file(path, limit=MAX_STORAGE_BYTES, what="SQLite file",
                              file=STORAGE_OPTION, key=url)
    if _read_only(path) or _read_only(path.parent if str(path.parent) else Path(".")):
        raise SpecError(STORAGE_OPTION, url, f"{path} is read-only (the file or its "
                        "directory): a study must write its trials; copy it somewhere "
                        "writable")
    if size == 0:
        return
    with open(path, "rb") as stream:
        if stream.read(len(SQLITE_MAGIC)) != SQLITE_MAGIC:
            raise SpecError(STORAGE_OPTION, url, f"{path} is not an SQLite database; name a "
                            "new file for the study")
    uri = f"file:{urllib.parse.quote(str(path.resolve()))}?mode=ro"
    try:
        with contextlib.closing(sqlite3.connect(uri, uri=True)) as database:
            tables = {row[0] for row in database.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'")}
    except sqlite3.DatabaseError as error:
        raise SpecError(STORAGE_OPTION, url, f"cannot read the SQLite database "
                        f"({error}); name a new file for the study") from None
    if tables and not tables >= OPTUNA_TABLES:
        listed = ", ".join(sorted(tables)[:5]) + (", ..." if len(tables) > 5 else "")
        raise SpecError(STORAGE_OPTION, url, f"{path} is a database of another program "
                        f"(tables: {listed}), not an Optuna storage; name a new file")


def open_storage(url: str) -> optuna.storages.RDBStorage:
    """Return the Optuna storage at ``url``, checked first (:func:`check_storage`).

    Heartbeats every ``HEARTBEAT_S``; a trial without one for ``GRACE_S`` is failed and
    queued again. Any driver or URL problem is one :class:`SpecError` line.

    Examples
    --------
    >>> open_storage("nosuchdb://x")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --storage: nosuchdb://x: cannot open the storage: ...
    """
    check_storage(url)  # before Optuna adds its tables to a foreign or read-only database
    try:
        return optuna.storages.RDBStorage(
            url, heartbeat_interval=HEARTBEAT_S, grace_period=GRACE_S,
            heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback(),
        )
    except Exception as error:  # any driver/URL problem: one error line, not a traceback
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise SpecError(STORAGE_OPTION, url, f"cannot open the storage: {reason}") from None
