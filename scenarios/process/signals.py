"""Every signal that stops a command, and closed output streams: one way to stop.

Python turns SIGINT into ``KeyboardInterrupt``, which unwinds the command: staging
directories are removed (:func:`scenarios.process.staging.stage_and_publish`), worker
pools are terminated (:func:`scenarios.process.workers.worker_pool`), Ray is shut down.
SIGTERM, SIGHUP and SIGQUIT would instead kill the process where it stands (leaving
staging, workers and running trials behind) or, for SIGQUIT, dump core.
:func:`stop_on_signals` makes them raise :class:`Stopped`, a ``KeyboardInterrupt``, so
they unwind the same way; the command line then exits with ``128 + N``, the shell's
convention for a process ended by signal N (:func:`exit_status`). A signal that the
caller ignores (``nohup`` ignores SIGHUP) stays ignored.

A closed stdout or stderr (a pipe whose reader is gone, ``>&-``) cannot show anything:
:func:`stream_problem` says which one is unusable, and :func:`silence_streams` points
both at ``os.devnull`` so that the interpreter's final flush cannot raise again
(Python's documentation on SIGPIPE recommends the same).

Examples
--------
>>> exit_status(KeyboardInterrupt()), exit_status(Stopped(signal.SIGTERM))
(130, 143)
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import sys
import threading
from collections.abc import Iterator

__all__ = [
    "EXIT_BROKEN_STREAM",
    "STOP_SIGNALS",
    "WORKER_IGNORED_SIGNALS",
    "Stopped",
    "broken_stream",
    "exit_status",
    "handlers_kept",
    "ignore_in_worker",
    "raise_if_stopped",
    "silence_streams",
    "stop_on_signals",
    "stream_problem",
]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)
"""Signals that stop a command: each raises :class:`Stopped` (SIGINT too, see below)."""

WORKER_IGNORED_SIGNALS = (signal.SIGINT, signal.SIGHUP, signal.SIGQUIT)
"""Signals a worker process ignores: a terminal sends them to the whole process group,
and the parent alone decides (it terminates its workers with SIGTERM, which they obey)."""

EXIT_BROKEN_STREAM = 128 + signal.SIGPIPE
"""Exit status when stdout or stderr is closed: the shell's status for death by SIGPIPE."""


class Stopped(KeyboardInterrupt):
    """Raised by the handler of a stop signal: it unwinds like Ctrl-C.

    Examples
    --------
    >>> Stopped(signal.SIGHUP).name
    'SIGHUP'
    """

    def __init__(self, signal_number: int) -> None:
        super().__init__(signal_number)
        self.signal_number = signal_number

    @property
    def name(self) -> str:
        """Return the signal's name (``SIGTERM``)."""
        return signal.Signals(self.signal_number).name


def exit_status(interrupt: KeyboardInterrupt) -> int:
    """Return ``128 + N`` for an interrupt by signal N (SIGINT when not a :class:`Stopped`).

    Examples
    --------
    >>> exit_status(Stopped(signal.SIGHUP)), exit_status(Stopped(signal.SIGQUIT))
    (129, 131)
    """
    number = interrupt.signal_number if isinstance(interrupt, Stopped) else signal.SIGINT
    return 128 + int(number)


_received: list[int] = []
"""Stop signals received within :func:`stop_on_signals` (a swallowed one is raised again)."""


def _raise_stopped(signal_number: int, _frame) -> None:
    _received.append(signal_number)
    raise Stopped(signal_number)


def raise_if_stopped() -> None:
    """Raise :class:`Stopped` again if a stop signal came and its exception was swallowed.

    An exception raised by a signal handler while a finalizer (``__del__``, a weakref
    callback: SQLAlchemy's, say) runs is printed as "Exception ignored" and lost, and the
    command would go on. Called before anything is published and between the trials of a
    search, so that a stop is never lost.

    Examples
    --------
    >>> raise_if_stopped()  # no signal came: nothing happens
    """
    if _received:
        raise Stopped(_received[-1])


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """Within the block, make SIGINT, SIGTERM, SIGHUP and SIGQUIT raise :class:`Stopped`.

    SIGINT too (``Stopped`` is a ``KeyboardInterrupt``), so that a Ctrl-C swallowed by a
    finalizer is not lost either (:func:`raise_if_stopped`). Signals the process ignores
    are left ignored; outside the main thread (where Python cannot handle signals)
    nothing changes. The earlier handlers come back at the end.

    Examples
    --------
    >>> with stop_on_signals():
    ...     try:
    ...         signal.raise_signal(signal.SIGTERM)
    ...     except Stopped as stopped:
    ...         print(stopped.name)
    SIGTERM
    >>> signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    True
    """
    _received.clear()
    earlier = {}
    if threading.current_thread() is threading.main_thread():
        for number in STOP_SIGNALS:
            if signal.getsignal(number) != signal.SIG_IGN:
                earlier[number] = signal.signal(number, _raise_stopped)
    hook, sys.unraisablehook = sys.unraisablehook, _quiet_about_stops(sys.unraisablehook)
    try:
        yield
    finally:
        for number, handler in earlier.items():
            signal.signal(number, handler)
        sys.unraisablehook = hook
        _received.clear()


def _quiet_about_stops(hook):
    # A Stopped raised in a finalizer is lost ("Exception ignored in ..." and a traceback
    # on stderr): kept in _received, raised again by raise_if_stopped, never printed.
    def unraisable(report) -> None:
        if not isinstance(report.exc_value, Stopped):
            hook(report)

    return unraisable


@contextlib.contextmanager
def handlers_kept() -> Iterator[None]:
    """Put back, at the end of the block, the handlers of :data:`STOP_SIGNALS` it changed.

    Around a library's set-up that installs handlers of its own (``ray.init`` makes
    SIGTERM exit with status 15, without our line or clean-up).

    Examples
    --------
    >>> with handlers_kept():
    ...     _ = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    >>> signal.getsignal(signal.SIGHUP) == signal.SIG_DFL
    True
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    earlier = {number: signal.getsignal(number) for number in STOP_SIGNALS}
    try:
        yield
    finally:
        for number, handler in earlier.items():
            if handler is not None:
                signal.signal(number, handler)


def ignore_in_worker() -> None:
    """Ignore :data:`WORKER_IGNORED_SIGNALS`; obey SIGTERM at once (a pool's terminate).

    Called first in a worker process: a forked worker inherits its parent's handlers,
    and one raising :class:`Stopped` in the middle of a run would print a traceback.

    Examples
    --------
    >>> import multiprocessing
    >>> worker = multiprocessing.get_context("fork").Process(target=ignore_in_worker)
    >>> worker.start(); worker.join(); worker.exitcode
    0
    """
    for number in WORKER_IGNORED_SIGNALS:
        signal.signal(number, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _unusable(stream) -> bool:
    if stream is None or getattr(stream, "closed", True):
        return True
    try:
        os.fstat(stream.fileno())
    except io.UnsupportedOperation:  # a stream without a file (io.StringIO, pytest's)
        return False
    except (OSError, ValueError):
        return True
    return False


def stream_problem() -> str | None:
    """Return ``"stdout"`` or ``"stderr"`` when that stream is closed, else ``None``.

    Examples
    --------
    >>> saved, sys.stdout = sys.stdout, io.StringIO()
    >>> sys.stdout.close(); problem = stream_problem(); sys.stdout = saved
    >>> problem
    'stdout'
    """
    for name in ("stdout", "stderr"):
        if _unusable(getattr(sys, name)):
            return name
    return None


def broken_stream(error: BaseException) -> bool:
    """Return whether ``error`` comes from writing to a closed stdout or stderr.

    A ``BrokenPipeError`` (the reader of a pipe is gone), or a ``ValueError`` (writing
    to a closed file) or ``AttributeError`` (``sys.stdout`` is ``None``) while a
    stream is unusable.

    Examples
    --------
    >>> broken_stream(BrokenPipeError()), broken_stream(ValueError("x"))
    (True, False)
    """
    if isinstance(error, BrokenPipeError):
        return True
    return isinstance(error, ValueError | AttributeError) and stream_problem() is not None


def silence_streams() -> None:
    """Point stdout and stderr at ``os.devnull`` (their files and ``sys`` objects).

    After a broken pipe, the interpreter's own flush at exit would raise again and print
    ``Exception ignored ... BrokenPipeError``; writes to devnull cannot fail.

    Examples
    --------
    >>> import subprocess
    >>> code = "from scenarios.process.signals import *; silence_streams(); print('x')"
    >>> subprocess.run([sys.executable, "-c", code], capture_output=True).stdout
    b''
    """
    devnull = os.open(os.devnull, os.O_WRONLY)
    for name, number in (("stdout", 1), ("stderr", 2)):
        with contextlib.suppress(OSError):
            os.dup2(devnull, number)
        setattr(sys, name, open(number, "w", closefd=False))  # noqa: SIM115 (lives to exit)
    os.close(devnull)
