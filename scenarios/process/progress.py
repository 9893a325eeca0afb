"""Progress of long commands: a bar on a terminal, plain lines in a log.

On a terminal (stderr is a TTY) tqdm draws a bar that disappears when done. When stderr
is a file or a pipe (CI, ``nohup``, ``2> log``), a bar would be noise, so one line is
printed per lap (as estimated from the simulated time) or per finished item instead;
logs then show that a run is alive and how far it got.

Examples
--------
>>> with count_progress(2, "table", "scenario") as advance:
...     advance("sim1")
...     advance("sim2")
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Iterator

from tqdm import tqdm

__all__ = ["SCANS_PER_LINE", "count_progress", "scan_progress", "sim_progress"]

SCANS_PER_LINE = 500
"""Off a terminal, :func:`scan_progress` prints one line per this many scans."""


def _duration(seconds: float) -> str:
    """Return ``seconds`` as ``1 h 05 min``, ``4 min 10 s`` or ``12 s``.

    Examples
    --------
    >>> _duration(3900), _duration(250), _duration(12.4)
    ('1 h 05 min', '4 min 10 s', '12 s')
    """
    seconds = round(seconds)
    if seconds >= 3600:
        return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"
    if seconds >= 60:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds} s"


def _line(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


@contextlib.contextmanager
def sim_progress(total: float, label: str, laps: int) -> Iterator[Callable[[float], None]]:
    """Yield a callback advancing by simulated seconds out of about ``total``.

    Off a terminal it prints ``label: about lap K of N (S sim s)`` each time another
    ``total / laps`` simulated seconds have passed.
    """
    if not sys.stderr.isatty():
        step = total / max(laps, 1)
        state = {"done": 0.0, "next": step, "lap": 1}

        def report(seconds: float) -> None:
            state["done"] += seconds
            if state["done"] >= state["next"] and state["lap"] < laps:
                state["lap"] += 1
                state["next"] += step
                _line(f"{label}: about lap {state['lap']} of {laps} "
                      f"({state['done']:.0f} sim s)")

        _line(f"{label}: lap 1 of {laps} (about {total:.0f} sim s in all)")
        yield report
        _line(f"{label}: done ({state['done']:.0f} sim s)")
        return
    with tqdm(total=round(total, 1), desc=label, unit="sim s", leave=False,
              bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} sim s "
                         "[{elapsed}<{remaining}]") as bar:
        pending = [0.0]

        def advance(seconds: float) -> None:
            pending[0] += seconds
            if pending[0] >= 0.5:
                bar.update(min(pending[0], bar.total - bar.n))
                pending[0] = 0.0

        yield advance


@contextlib.contextmanager
def count_progress(total: int, label: str, unit: str) -> Iterator[Callable[[str], None]]:
    """Yield a callback to call with a short description as each of ``total`` items ends.

    Off a terminal it prints ``label: K/total UNITs done (DESCRIPTION; about T left)``
    per item, T extrapolated from the time per item so far.
    """
    if not sys.stderr.isatty():
        done = [0]
        start = time.monotonic()

        def report(what: str) -> None:
            done[0] += 1
            left = (time.monotonic() - start) / done[0] * (total - done[0])
            eta = f"; about {_duration(left)} left" if done[0] < total else ""
            _line(f"{label}: {done[0]}/{total} {unit}s done ({what}{eta})")

        yield report
        return
    with tqdm(total=total, desc=label, unit=unit, leave=False) as bar:
        yield lambda _what: bar.update(1)


@contextlib.contextmanager
def scan_progress(label: str) -> Iterator[Callable[[int], None]]:
    """Yield a callback advancing by a number of scans (the total is not known).

    Off a terminal it prints ``label: N scans`` every ``SCANS_PER_LINE`` scans (nothing
    before the first, so that a log rejected at once gives its one error line alone).
    """
    if not sys.stderr.isatty():
        state = {"done": 0, "next": SCANS_PER_LINE}

        def report(scans: int = 1) -> None:
            state["done"] += scans
            if state["done"] >= state["next"]:
                state["next"] += SCANS_PER_LINE
                _line(f"{label}: {state['done']} scans")

        yield report
        return
    with tqdm(desc=label, unit="scan", leave=False) as bar:
        yield bar.update
