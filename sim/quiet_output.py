"""Silencing what a C library prints straight to the process's file descriptors 1 and 2.

PyBullet's C code writes its build time on import and ``argv[0]=`` on every connection,
past Python's ``sys.stdout``. :func:`quiet_stdout` points descriptors 1 and 2 at
``/dev/null`` around such calls and puts them back, safely from any thread.
"""

from __future__ import annotations

import ctypes
import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["quiet_stdout"]

_LIBC = ctypes.CDLL(None)


# One lock for the whole process around the redirection of descriptors 1 and 2: they are
# the process's, not a thread's. Two threads redirecting at once would each save what they
# find, and the later one would save (and restore for good) the other's /dev/null.
_QUIET_LOCK = threading.RLock()
# A fork while another thread has 1 and 2 on /dev/null would give the child a silenced
# stdout and a lock held by a thread it does not have: fork only between redirections.
os.register_at_fork(before=_QUIET_LOCK.acquire, after_in_parent=_QUIET_LOCK.release,
                    after_in_child=_QUIET_LOCK.release)


@contextmanager
def quiet_stdout() -> Iterator[None]:
    """Silence what PyBullet's C library prints straight to file descriptors 1 and 2.

    It writes its build time on import and ``argv[0]=`` on every connection, which would
    clutter the command line's output and any stdout a caller parses. Python exceptions
    are unaffected: they are raised, not printed, inside this block.

    Thread-safe: one process-wide lock is held for the whole block, so blocks in
    different threads run one after the other and each restores what it found (what
    another thread prints meanwhile goes to ``/dev/null`` too: the descriptors are the
    process's). A block inside a block of the same thread is allowed.

    Examples
    --------
    >>> import os
    >>> before = os.fstat(1).st_ino
    >>> with quiet_stdout():
    ...     silenced = os.fstat(1).st_ino == os.stat(os.devnull).st_ino
    >>> silenced, os.fstat(1).st_ino == before
    (True, True)
    """
    with _QUIET_LOCK:
        for stream in (sys.stdout, sys.stderr):
            if stream is not None and not stream.closed:  # None: started with it closed
                stream.flush()
        _hold_closed_descriptors()
        saved = [os.dup(1), os.dup(2)]
        try:
            with open(os.devnull, "w") as devnull:
                os.dup2(devnull.fileno(), 1)
                os.dup2(devnull.fileno(), 2)
                yield
        finally:
            _LIBC.fflush(None)  # C stdio buffers what it printed: flush it into /dev/null
            for descriptor, copy in zip((1, 2), saved, strict=True):
                os.dup2(copy, descriptor)
                os.close(copy)


def _hold_closed_descriptors() -> None:
    # A process started with 1 or 2 closed: the next file opened would get its number and
    # receive what the C library prints. Hold it with /dev/null for good.
    for descriptor in (1, 2):
        try:
            os.fstat(descriptor)
        except OSError:
            held = os.open(os.devnull, os.O_WRONLY)
            if held != descriptor:
                os.dup2(held, descriptor)
                os.close(held)
