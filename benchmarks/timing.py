"""The one timing helper the benchmarks share."""

import time
from collections.abc import Callable

import numpy as np


def median_us(
    run: Callable[[], object], repeats: int, clock: Callable[[], float] = time.perf_counter
) -> float:
    """Return the median time of ``run()`` on ``clock`` in microseconds, after one warm-up.

    ``time.thread_time`` measures CPU time of the calling thread: steadier than wall time
    on a shared machine, where a wall-clock median partly measures waiting for a core.
    """
    run()  # warm up caches and lazy imports
    times = np.empty(repeats)
    for k in range(repeats):
        start = clock()
        run()
        times[k] = clock() - start
    return float(np.median(times) * 1e6)
