"""How commands fail: bad input the user can fix, exit statuses, checks of options.

Bad input ends a command with exit status 2 and one line ``error: <file or option>:
<key>: <what is wrong>`` before any work starts (:class:`~semistatic.errors.SpecError`
for files and keys, :class:`InputError` for everything else); a run whose lap cannot
complete exits with 1; an interruption with 130.

Examples
--------
>>> check_jobs(2)
>>> check_jobs(0)
Traceback (most recent call last):
...
semistatic.errors.SpecError: --jobs: jobs: must be >= 1 and <= 256, got 0
"""

from __future__ import annotations

import os
import sys

from semistatic.errors import SpecError
from semistatic.validation import Range, as_int

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_INTERRUPTED",
    "EXIT_RUN_FAILED",
    "MAX_JOBS",
    "InputError",
    "check_display",
    "check_jobs",
]

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 1
EXIT_INTERRUPTED = 130

MAX_JOBS = 256
"""More worker processes than this is a typo, not a machine."""


class InputError(Exception):
    """Bad input the user can fix; printed as one ``error:`` line, exit status 2."""


def check_jobs(jobs: int) -> None:
    """Raise :class:`~semistatic.errors.SpecError` naming ``--jobs`` unless 1 <= jobs <= 256."""
    as_int(jobs, file="--jobs", key="jobs", valid=Range(ge=1, le=MAX_JOBS))


def check_display(gui: bool) -> None:
    """Refuse ``--gui`` without a display before PyBullet tries (and dies silently)."""
    if gui and sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        raise SpecError("--gui", "DISPLAY", "no display to open the PyBullet GUI on (DISPLAY "
                        "is not set); run without --gui or set DISPLAY")
