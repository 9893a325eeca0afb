"""The process table (Linux ``/proc``), and a reaper that ends a dead parent's descendants.

Worker pools stop with their parent by themselves (:mod:`scenarios.process.workers`).
Processes a library starts do not always: a local Ray instance's GCS server, raylet,
dashboard and runtime-env agents outlive a driver killed with SIGKILL. :func:`start_reaper`
forks a small process that keeps a list of its parent's descendants and, once the
parent is gone, kills those still alive (each checked by its start time, so that a
later process given the same id is spared).

Examples
--------
>>> import os
>>> start_time(os.getpid()) is not None, start_time(-1)
(True, None)
"""

from __future__ import annotations

import contextlib
import os
import signal
import time

__all__ = ["REAPER_POLL_S", "children", "descendants", "start_reaper", "start_time"]

REAPER_POLL_S = 0.2
"""How often (s) the reaper lists its parent's descendants and checks the parent."""


def _stat(pid: int) -> list[str] | None:
    try:
        with open(f"/proc/{pid}/stat") as stream:
            text = stream.read()
    except OSError:
        return None
    return text[text.rindex(")") + 2 :].split()


def start_time(pid: int) -> int | None:
    """Return when process ``pid`` started (clock ticks since boot), ``None`` if gone.

    ``None`` for a zombie too (it has ended; only its exit status is left).
    """
    fields = _stat(pid)
    if fields is None or fields[0] == "Z":
        return None
    return int(fields[19])


def children(pid: int) -> set[int]:
    """Return the ids of the live processes whose parent is ``pid``.

    Examples
    --------
    >>> import subprocess, sys
    >>> child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    >>> child.pid in children(os.getpid()), os.getpid() in children(child.pid)
    (True, False)
    >>> child.kill(); _ = child.wait()
    >>> child.pid in children(os.getpid())  # reaped: gone from the process table
    False
    """
    found = set()
    for entry in os.listdir("/proc"):
        fields = _stat(int(entry)) if entry.isdigit() else None
        if fields is not None and int(fields[1]) == pid and fields[0] != "Z":
            found.add(int(entry))
    return found


def descendants(pid: int) -> set[int]:
    """Return the ids of the live descendants of ``pid`` (children, theirs, ...).

    Examples
    --------
    >>> import subprocess, sys
    >>> script = ("import subprocess, sys, time; subprocess.Popen([sys.executable, '-c', "
    ...           "'import time; time.sleep(60)']); print(flush=True); time.sleep(60)")
    >>> child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE)
    >>> _ = child.stdout.readline()  # its own child has started
    >>> grandchildren = descendants(child.pid)
    >>> len(grandchildren), grandchildren < descendants(os.getpid())
    (1, True)
    >>> for pid in grandchildren | {child.pid}:
    ...     os.kill(pid, 9)
    >>> _ = child.wait(); child.stdout.close()
    """
    found, todo = set(), [pid]
    while todo:
        new = children(todo.pop()) - found
        todo.extend(new)
        found |= new
    return found


def _reap(parent: int) -> None:
    for number in (signal.SIGINT, signal.SIGHUP, signal.SIGQUIT, signal.SIGTERM):
        signal.signal(number, signal.SIG_IGN)  # the parent's stop is ours to outlive
    known: dict[int, int | None] = {}
    while os.getppid() == parent:
        for pid in descendants(parent) - known.keys() - {os.getpid()}:
            known[pid] = start_time(pid)
        time.sleep(REAPER_POLL_S)
    for pid, started in known.items():
        if started is not None and start_time(pid) == started:
            with contextlib.suppress(OSError):  # gone meanwhile
                os.kill(pid, signal.SIGKILL)


def start_reaper() -> int:
    """Fork the reaper of this process's descendants; return its process id.

    It exits when this process is gone, after killing every descendant of this process
    it saw that still lives. Fork it before starting the processes it is to reap.

    Examples
    --------
    >>> import subprocess, sys
    >>> code = ("import subprocess; from scenarios.process.reaper import start_reaper; "
    ...         "import time; start_reaper(); print(subprocess.Popen(['sleep', '60']).pid); "
    ...         "time.sleep(1)")  # exits without waiting for its child
    >>> orphan = int(subprocess.run([sys.executable, "-c", code], capture_output=True,
    ...                              text=True, timeout=60).stdout)
    >>> deadline = time.monotonic() + 10
    >>> while start_time(orphan) is not None and time.monotonic() < deadline:
    ...     time.sleep(0.1)
    >>> start_time(orphan) is None  # the sleep was killed once its parent had exited
    True
    """
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:
        try:
            _reap(parent)
        finally:
            os._exit(0)
    return pid
