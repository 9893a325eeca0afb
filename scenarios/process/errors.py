"""How commands fail: bad input the user can fix, exit statuses, checks of options.

Bad input ends a command with exit status 2 and one line ``error: <file or option>:
<key>: <what is wrong>`` before any work starts (:class:`~semistatic.errors.SpecError`
for files and keys, :class:`InputError` for everything else); a run whose lap cannot
complete exits with 1; an interruption with 130. A full disk or a permission refused
while a command writes (:func:`write_failure`) also ends with 2 and one line: the user
frees space or fixes the permissions; the previous result is left whole.

Examples
--------
>>> check_jobs(2)
>>> check_jobs(0)  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
semistatic.errors.SpecError: --jobs: jobs: must be >= 1 and <= ..., got 0 (4 per CPU of the ...
"""

from __future__ import annotations

import errno
import os
import sys

from semistatic.errors import SpecError
from semistatic.validation import Range, as_int

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_INTERRUPTED",
    "EXIT_RUN_FAILED",
    "JOBS_PER_CPU",
    "WRITE_ERRNOS",
    "InputError",
    "check_display",
    "check_jobs",
    "max_jobs",
    "usable_cpus",
    "write_failure",
]

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 1
EXIT_INTERRUPTED = 130

JOBS_PER_CPU = 4
"""More worker processes per CPU than this is a typo, not a machine (see :func:`max_jobs`)."""


_DISK_FULL = frozenset({errno.ENOSPC, errno.EDQUOT})
WRITE_ERRNOS = _DISK_FULL | {errno.EACCES, errno.EPERM, errno.EROFS}
"""``OSError`` numbers a user fixes outside the program: space, quota, permissions."""


class InputError(Exception):
    """Bad input the user can fix; printed as one ``error:`` line, exit status 2."""


def usable_cpus() -> int:
    """Return how many CPUs this process may run on (its affinity mask, where there is one).

    ``os.cpu_count()`` counts the machine's CPUs, also those a container or ``taskset``
    keeps this process off.

    Examples
    --------
    >>> 1 <= usable_cpus() <= (os.cpu_count() or 1)
    True
    """
    if hasattr(os, "sched_getaffinity"):
        return max(len(os.sched_getaffinity(0)), 1)
    return os.cpu_count() or 1


def max_jobs() -> int:
    """Return the most ``--jobs`` a command accepts: ``JOBS_PER_CPU`` per usable CPU.

    A run is CPU-bound, so more workers than CPUs only share them; a few per CPU are
    still allowed (a command line written for a somewhat bigger machine runs), a hundred
    thousand would fork until the machine gives out. At least ``JOBS_PER_CPU`` on one
    CPU.

    Examples
    --------
    >>> max_jobs() == JOBS_PER_CPU * usable_cpus()
    True
    """
    return JOBS_PER_CPU * usable_cpus()


def check_jobs(jobs: int) -> None:
    """Raise :class:`~semistatic.errors.SpecError` naming ``--jobs`` unless 1 <= jobs <= max.

    The maximum is :func:`max_jobs`; the message states it and the CPUs it comes from.
    :func:`scenarios.cli.main` calls it before any process starts (the kernel compilation
    forks too); the commands call it again for a caller that skips the command line.

    Examples
    --------
    >>> check_jobs(max_jobs())
    >>> check_jobs(max_jobs() + 1)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --jobs: jobs: must be >= 1 and <= ..., got ... (4 per CPU ...
    """
    cpus = usable_cpus()
    as_int(jobs, file="--jobs", key="jobs", valid=Range(
        ge=1, le=JOBS_PER_CPU * cpus,
        fix=f"{JOBS_PER_CPU} per CPU of the {cpus} this process may use",
    ))


def check_display(gui: bool) -> None:
    """Refuse ``--gui`` without a display before PyBullet tries (and dies silently)."""
    if gui and sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        raise SpecError("--gui", "DISPLAY", "no display to open the PyBullet GUI on (DISPLAY "
                        "is not set); run without --gui or set DISPLAY")


def write_failure(error: OSError) -> str | None:
    """Return the ``error:`` line for a full disk or a refused permission, else ``None``.

    Other ``OSError``s are bugs or faults to see whole (``None``: the caller re-raises).

    Examples
    --------
    >>> write_failure(OSError(errno.ENOSPC, "No space left on device", "/r/out/metrics.json"))
    '/r/out/metrics.json: No space left on device; free some space (or choose an --out on \
another disk) and run again; earlier results are left as they were'
    >>> write_failure(OSError(errno.EROFS, "Read-only file system", "/r"))
    '/r: Read-only file system; choose a path you may write (or fix its permissions); \
earlier results are left as they were'
    >>> write_failure(OSError(errno.EIO, "Input/output error")) is None
    True
    """
    if error.errno not in WRITE_ERRNOS:
        return None
    where = error.filename if error.filename is not None else "output"
    reason = error.strerror or os.strerror(error.errno)
    fix = ("free some space (or choose an --out on another disk) and run again"
           if error.errno in _DISK_FULL
           else "choose a path you may write (or fix its permissions)")
    return f"{where}: {reason}; {fix}; earlier results are left as they were"
