"""Running a sweep's points: full closed-loop runs or replays of recordings, in a pool.

A point is a validated :class:`~scenarios.spec.scenario.ScenarioSpec`. Without recordings it runs
the whole closed loop (:func:`scenarios.bench.runner.run_scenario`); with recordings
(:mod:`scenarios.logs.recording`) only the mapper, the Table 1 experiment and the detection
scoring are re-run on the recorded scans of the point's seed. Either way the metrics of a
point do not depend on the number of workers.

Examples
--------
>>> run_sweep([], jobs=2)
[]
"""

from __future__ import annotations

import contextlib
import functools
import queue
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from scenarios.logs.recording import Recording, read_recording
from scenarios.logs.recording_replay import replay_recording, replay_setting
from scenarios.process.reaper import start_reaper
from scenarios.process.signals import handlers_kept
from scenarios.process.workers import worker_pool
from scenarios.spec.scenario import ScenarioSpec
from semistatic.errors import SpecError

if TYPE_CHECKING:
    from scenarios.tuning.warm import WarmStarts

__all__ = [
    "BACKENDS",
    "PointResult",
    "PoolBackend",
    "RayBackend",
    "RecordingSet",
    "check_backend",
    "open_backend",
    "run_point",
    "run_points",
    "run_sweep",
    "warm_worker",
]

BACKENDS = ("pool", "ray")
"""Where trials run: worker processes of this machine, or Ray tasks (a local or remote cluster)."""

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

    def defaults(self, laps: int | None, seeds: tuple[int, ...] | None,
                 ) -> tuple[int | None, tuple[int, ...] | None]:
        """Return ``laps`` and ``seeds``, defaulting to the recorded laps and seeds."""
        manifests = [recording.manifest for recording in self.recordings()]
        if laps is None:
            laps = manifests[0]["laps"]
        if seeds is None:
            seeds = tuple(sorted({manifest["seed"] for manifest in manifests}))
        return laps, seeds

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
                replay_setting(recording, spec)  # checked, and decoded once for every point
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


def run_point(spec: ScenarioSpec, recordings: RecordingSet | WarmStarts | None = None,
              ) -> Outcome:
    """Run one point; a run that raises is reported, not fatal.

    One extreme threshold that makes a run fail (e.g. the robot never re-localises)
    should cost its own row, not the hours of the rest of the sweep. ``recordings`` are
    a point's recordings to replay, or its :class:`WarmStarts`.
    """
    from scenarios.tuning.warm import WarmStarts  # the closed loop: loaded in workers only

    try:
        if isinstance(recordings, WarmStarts):
            return recordings.run(spec), None
        if recordings is not None and recordings.paths:
            return replay_recording(recordings.for_spec(spec), spec), None
        from scenarios.bench.runner import run_scenario
        from scenarios.results.outputs import summarize

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


def run_points(specs: Sequence[ScenarioSpec],
               recordings: RecordingSet | WarmStarts | None = None,
               ) -> list[Outcome]:
    """Run the points of one search trial (its seeds) one after the other; return outcomes.

    Examples
    --------
    >>> run_points([])
    []
    """
    return [run_point(spec, recordings) for spec in specs]


SINGLE_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                           "NUMBA_NUM_THREADS")
"""Environment variables that make a Ray worker's thread pools single-threaded."""

WARM_HOLD_S = 0.5
"""How long a warm-up task keeps its worker busy, so each of them starts its own worker."""


def warm_worker(recordings: RecordingSet | None = None, hold_s: float = 0.0) -> int:
    """Do a worker's one-off work before its first trial; return its process id.

    Imports the closed loop, reads the recordings (kept for every later point of this
    worker), then keeps the worker busy ``hold_s`` seconds so that concurrent warm-up
    tasks land on different workers.

    Examples
    --------
    >>> import os
    >>> warm_worker() == os.getpid()
    True
    """
    import os


    if recordings is not None:
        recordings.recordings()
    time.sleep(hold_s)
    return os.getpid()


class PoolBackend:
    """Run tasks in ``jobs`` worker processes of this machine (they die with it).

    ``submit(key, specs, recordings)`` starts :func:`run_points`; ``finished(timeout)``
    returns the ``(key, outcomes)`` pairs done so far, waiting up to ``timeout`` s for one.

    Examples
    --------
    >>> with PoolBackend(1) as backend:
    ...     backend.submit("a", [], None)
    ...     backend.finished(timeout=10.0)
    [('a', [])]
    """

    def __init__(self, jobs: int) -> None:
        self.capacity = jobs
        self._context = worker_pool(jobs)
        self._done: queue.Queue = queue.Queue()

    def __enter__(self) -> PoolBackend:
        self._pool = self._context.__enter__()
        return self

    def __exit__(self, *exc_info) -> bool | None:
        return self._context.__exit__(*exc_info)

    def warm_up(self, recordings: RecordingSet | None = None) -> int:
        """Give every worker its one-off work now (:func:`warm_worker`); return how many ran it."""
        pids = self._pool.starmap(warm_worker, [(recordings, WARM_HOLD_S)] * self.capacity,
                                  chunksize=1)
        return len(set(pids))

    def submit(self, key: Any, specs: Sequence[ScenarioSpec],
               recordings: RecordingSet | WarmStarts | None) -> None:
        """Start the points ``specs`` of task ``key``."""
        self._pool.apply_async(
            run_points, (list(specs), recordings),
            callback=lambda outcomes: self._done.put((key, outcomes)),
            error_callback=lambda error: self._done.put(
                (key, [(None, f"{type(error).__name__}: {error}")] * len(specs))
            ),
        )

    def finished(self, timeout: float) -> list[tuple[Any, list[Outcome]]]:
        """Return the tasks finished since the last call (waiting up to ``timeout`` s)."""
        done = []
        with contextlib.suppress(queue.Empty):
            done.append(self._done.get(timeout=timeout))
            while True:
                done.append(self._done.get_nowait())
        return done


class RayBackend:
    """Run tasks as Ray tasks: a local Ray instance, or the cluster at ``address``.

    Every task asks for one CPU, so ``capacity`` is the cluster's CPU count (or ``jobs``
    on a local instance started here). Workers import this project, so on a cluster
    every node needs it installed (README, "Tuning on a cluster").
    """

    def __init__(self, jobs: int, address: str | None = None) -> None:
        self.jobs = jobs
        self.address = address
        self._pending: dict[Any, Any] = {}

    def __enter__(self) -> RayBackend:
        import ray

        self._ray = ray
        self._started = not ray.is_initialized()
        if self._started:
            # A task holds one CPU: thread pools (BLAS, OpenMP, numba) of one thread each,
            # or the tasks of a node would compete for its cores.
            single = {"env_vars": {name: "1" for name in SINGLE_THREAD_VARIABLES}}
            if self.address is None:
                # Ray's GCS server, raylet and agents would outlive a SIGKILLed driver.
                start_reaper()
            # Ray's own SIGTERM handler exits with 15 at once: ours unwinds (shutdown below).
            with handlers_kept():
                if self.address is None:
                    ray.init(num_cpus=self.jobs, include_dashboard=False, log_to_driver=False,
                             configure_logging=False, runtime_env=single)
                else:
                    ray.init(address=self.address, log_to_driver=False, runtime_env=single)
        cpus = int(ray.cluster_resources().get("CPU", self.jobs))
        self.capacity = cpus if self.address is not None else self.jobs
        self._remote = ray.remote(num_cpus=1, max_retries=0)(run_points)
        return self

    def __exit__(self, *exc_info) -> None:
        for reference, _ in self._pending.values():
            self._ray.cancel(reference, force=True)
        if self._started:
            self._ray.shutdown()

    def warm_up(self, recordings: RecordingSet | None = None) -> int:
        """Start a Ray worker per CPU with its one-off work (:func:`warm_worker`); count them."""
        warm = self._ray.remote(num_cpus=1, max_retries=0)(warm_worker)
        return len(set(self._ray.get(
            [warm.remote(recordings, WARM_HOLD_S) for _ in range(self.capacity)]
        )))

    def submit(self, key: Any, specs: Sequence[ScenarioSpec],
               recordings: RecordingSet | WarmStarts | None) -> None:
        """Start the points ``specs`` of task ``key`` as one Ray task."""
        self._pending[key] = (self._remote.remote(list(specs), recordings), len(specs))

    def finished(self, timeout: float) -> list[tuple[Any, list[Outcome]]]:
        """Return the tasks finished since the last call (waiting up to ``timeout`` s)."""
        if not self._pending:
            return []
        references = [reference for reference, _ in self._pending.values()]
        self._ray.wait(references, num_returns=1, timeout=timeout)
        ready, _ = self._ray.wait(references, num_returns=len(references), timeout=0)
        done = []
        for key, (reference, count) in list(self._pending.items()):
            if reference in ready:
                del self._pending[key]
                try:
                    done.append((key, self._ray.get(reference)))
                except self._ray.exceptions.RayError as error:
                    done.append((key, [(None, f"{type(error).__name__}: {error}")] * count))
        return done


def check_backend(name: str, jobs: int, address: str | None = None) -> None:
    """Raise :class:`~semistatic.errors.SpecError` unless the backend options make sense.

    ``--jobs`` in range, ``--address`` only with Ray, and Ray installed when asked for.

    Examples
    --------
    >>> check_backend("pool", 2, "10.0.0.1:6379")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --address: 10.0.0.1:6379: is a Ray address: add --backend ray
    """
    import importlib.util

    from scenarios.process.errors import check_jobs
    from semistatic.errors import SpecError

    check_jobs(jobs)
    if address is not None and name != "ray":
        raise SpecError("--address", address, "is a Ray address: add --backend ray")
    if name == "ray" and importlib.util.find_spec("ray") is None:
        raise SpecError("--backend", "ray", "Ray is not installed: pip install 'semistatic[ray]'")


def open_backend(name: str, jobs: int, address: str | None = None) -> PoolBackend | RayBackend:
    """Return the backend ``name`` (``pool`` or ``ray``), to use in a ``with`` block.

    Examples
    --------
    >>> open_backend("pool", 2).capacity
    2
    """
    if name == "ray":
        return RayBackend(jobs, address)
    return PoolBackend(jobs)
