"""Running a sweep's points: full closed-loop runs or replays of recordings, in a pool.

A point is a validated :class:`~scenarios.spec.ScenarioSpec`. Without recordings it runs
the whole closed loop (:func:`scenarios.runner.run_scenario`); with recordings
(:mod:`scenarios.recording`) only the mapper, the Table 1 experiment and the detection
scoring are re-run on the recorded scans of the point's seed. Either way the metrics of a
point do not depend on the number of workers.

Examples
--------
>>> run_sweep([], jobs=2)
[]
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scenarios.recording import Recording, read_recording, replay
from scenarios.spec import ScenarioSpec
from scenarios.workers import worker_pool
from worlds.errors import SpecError

__all__ = ["PointResult", "RecordingSet", "run_point", "run_sweep"]

Outcome = tuple[dict[str, Any] | None, str | None]


@dataclass(frozen=True)
class PointResult:
    """The outcome of one point: its metrics (``metrics.json`` content) or why it failed.

    ``point`` is anything with ``index``, ``label`` and ``spec`` (a sweep point).

    Examples
    --------
    >>> PointResult(point=None, error="RuntimeError: lost").failed
    True
    """

    point: Any
    metrics: dict[str, Any] | None = None
    error: str | None = None

    @property
    def failed(self) -> bool:
        """Return whether the run raised instead of finishing."""
        return self.error is not None


@functools.lru_cache(maxsize=8)
def _cached_recording(path: str) -> Recording:
    # A worker replays many points of the same few recordings: read each once.
    return read_recording(path)


@dataclass(frozen=True)
class RecordingSet:
    """Recordings to replay points from, one per (scenario, seed), by directory.

    Examples
    --------
    >>> RecordingSet(()).paths
    ()
    """

    paths: tuple[str, ...]

    @classmethod
    def read(cls, paths: Sequence[str | Path]) -> RecordingSet:
        """Read (and so validate) every recording now; refuse two of the same run."""
        seen: dict[tuple[str, int], str] = {}
        for path in paths:
            manifest = _cached_recording(str(path)).manifest
            key = (manifest["scenario"], manifest["seed"])
            if key in seen:
                raise SpecError(
                    "--recording", str(path),
                    f"records {key[0]} seed {key[1]} as {seen[key]} does; give one per seed",
                )
            seen[key] = str(path)
        return cls(tuple(str(path) for path in paths))

    def recordings(self) -> list[Recording]:
        """Return the recordings (read once per process)."""
        return [_cached_recording(path) for path in self.paths]

    def for_spec(self, spec: ScenarioSpec) -> Recording:
        """Return the recording of ``spec``'s scenario and seed, checked to replay ``spec``.

        Raises :class:`SpecError` naming what differs (the seed, a motion-changing field).
        """
        recordings = self.recordings()
        same = [r for r in recordings if r.manifest["scenario"] == spec.name]
        for recording in same:
            if recording.manifest["seed"] == spec.seed:
                recording.check_matches(spec)
                return recording
        if same:
            seeds = sorted(r.manifest["seed"] for r in same)
            raise SpecError(
                "--recording", "seed",
                f"no recording of {spec.name} with seed {spec.seed} (recorded seeds: "
                f"{', '.join(map(str, seeds))}); record it with `semistatic run {spec.name} "
                f"--seed {spec.seed} --record DIR`",
            )
        recordings[0].check_matches(spec)  # names the scenario it records instead
        raise AssertionError("unreachable: check_matches refuses another scenario")


def run_point(spec: ScenarioSpec, recordings: RecordingSet | None = None) -> Outcome:
    """Run one point; a run that raises is reported, not fatal.

    One extreme threshold that makes a run fail (e.g. the robot never re-localises)
    should cost its own row, not the hours of the rest of the sweep.
    """
    from scenarios.outputs import summarize
    from scenarios.runner import run_scenario

    try:
        if recordings is not None and recordings.paths:
            return replay(recordings.for_spec(spec), spec), None
        return summarize(run_scenario(spec)), None
    except Exception as error:  # recorded in the point's row, see the docstring
        return None, f"{type(error).__name__}: {error}"


def run_sweep(
    points: Sequence[Any],
    *,
    jobs: int = 1,
    on_result: Callable[[PointResult], None] | None = None,
    recordings: RecordingSet | None = None,
) -> list[PointResult]:
    """Run every point, ``jobs`` at a time in worker processes; return results in point order.

    Each point is an independent run seeded by its own spec, so the metrics (apart from
    the timing figures) do not depend on ``jobs``. ``on_result`` is called as each point
    finishes (in completion order), e.g. to advance a progress bar. With ``recordings``
    each point is replayed from the recording of its seed.

    Examples
    --------
    >>> run_sweep([], jobs=0)
    Traceback (most recent call last):
    ...
    ValueError: run_sweep: jobs must be >= 1 (got 0)
    """
    if jobs < 1:
        raise ValueError(f"run_sweep: jobs must be >= 1 (got {jobs})")
    results: dict[int, PointResult] = {}

    def record(point: Any, outcome: Outcome) -> None:
        result = PointResult(point, *outcome)
        results[point.index] = result
        if on_result is not None:
            on_result(result)

    if jobs == 1 or len(points) <= 1:
        for point in points:
            record(point, run_point(point.spec, recordings))
    else:
        by_index = {point.index: point for point in points}
        with worker_pool(min(jobs, len(points))) as pool:
            tasks = [(point.index, point.spec, recordings) for point in points]
            for index, outcome in pool.imap_unordered(_run_indexed_point, tasks):
                record(by_index[index], outcome)
    return [results[point.index] for point in points]


def _run_indexed_point(
    task: tuple[int, ScenarioSpec, RecordingSet | None],
) -> tuple[int, Outcome]:
    """Run one point in a worker; return its index with the outcome."""
    index, spec, recordings = task
    return index, run_point(spec, recordings)
