"""Worker processes that stop with their parent: Ctrl-C, a crash or a SIGKILL.

``table`` and ``tune`` run scenarios in worker processes. Workers ignore SIGINT, SIGHUP
and SIGQUIT (a terminal sends them to the whole process group): the parent alone decides
(:mod:`scenarios.process.signals`), and on an interruption, a stop signal or an error it
terminates them at once instead of letting them finish their runs or print tracebacks.
A parent killed with SIGKILL cannot do that, so every worker watches its parent and
exits within ``PARENT_POLL_S`` when it is gone.

Examples
--------
>>> with worker_pool(2) as pool:
...     sorted(pool.imap_unordered(abs, [-2, 1, -3]))
[1, 2, 3]
"""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.pool
import os
import threading
import time
from collections.abc import Iterator

from scenarios.process.signals import ignore_in_worker

__all__ = ["PARENT_POLL_S", "worker_pool"]

PARENT_POLL_S = 0.2
"""How often (s) a worker checks that its parent process still exists."""


def _exit_with_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)  # the parent is gone: nobody will read the result


def _init_worker(parent: int) -> None:
    ignore_in_worker()
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True).start()


@contextlib.contextmanager
def worker_pool(jobs: int) -> Iterator[multiprocessing.pool.Pool]:
    """Yield a pool of ``jobs`` worker processes that never outlive this process.

    Leaving the block normally waits for the workers to finish; leaving it by an
    exception (``KeyboardInterrupt`` included) terminates them first.
    """
    if jobs < 1:
        raise ValueError(f"worker_pool: jobs must be >= 1 (got {jobs})")
    pool = multiprocessing.Pool(jobs, initializer=_init_worker, initargs=(os.getpid(),))
    try:
        yield pool
    except BaseException:
        pool.terminate()
        pool.join()
        raise
    pool.close()
    pool.join()
