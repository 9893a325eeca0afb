"""Threshold search with Optuna: a study in a storage, trials on a backend, resumable.

``semistatic tune SCENARIO --param mapper.gate=0.05:0.20 --trials 20`` asks Optuna's
sampler (TPE, random or grid) for parameter values, runs each trial (every scenario of
``SCENARIO[,SCENARIO...]`` with every seed, replayed from recordings or re-simulated) on a
backend (:mod:`scenarios.tuning.run`) and tells the study the objectives: the mean over the
trial's runs of each ``--objective`` (several make a multi-objective study with a Pareto
front). Every trial keeps its full metrics, per run, in the study's user attributes, with
the worst case and the spread (robust thresholds: rank by either).

The study lives in an Optuna RDB storage (default ``DIR/study.db``, SQLite). The driver
records itself (:mod:`scenarios.tuning.drivers`) and heartbeats on each trial it runs; a
trial a stopped driver left running is failed and queued again with the same values
(``RetryHeartbeatStaleTrialCallback``): at once if its driver ran on this host, else once
its heartbeat is ``GRACE_S`` old. Re-running the command finishes the study, exactly.

Examples
--------
>>> from scenarios.tuning.params import parse_params
>>> config = SearchConfig("pal1", parse_params(["mapper.gate=0.05:0.2"]), trials=4)
>>> config.directions()
['minimize']
>>> [p.label for p in config.points({"mapper.gate": 0.1})]
['mapper.gate=0.1 seed=0']
"""

from __future__ import annotations

import itertools
import json
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import optuna

from scenarios.process.signals import raise_if_stopped
from scenarios.tuning.drivers import DRIVER_ATTR, driver_identity, fail_orphaned_trials
from scenarios.tuning.metrics import DEFAULT_SORT, METRICS, NEES_TARGET, metric_value
from scenarios.tuning.params import PARAM_OPTION, SearchParam, grid_size
from scenarios.tuning.points import ScenarioSources, sweep_points
from scenarios.tuning.run import PointResult, RecordingSet
from scenarios.tuning.storage import HEARTBEAT_S, STORAGE_OPTION, open_storage
from semistatic.errors import SpecError
from semistatic.validation import did_you_mean

__all__ = [
    "SAMPLERS",
    "RejectedPoint",
    "SearchConfig",
    "finished_trials",
    "open_study",
    "resumed_seed",
    "run_study",
    "trial_results",
]

# The heartbeat API we build resumption on is marked experimental (stable since Optuna 2.9)
# and meant for Study.optimize; our driver records the heartbeats itself. Optuna's INFO
# log would repeat every trial that our progress line already reports.
warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
warnings.filterwarnings("ignore", message="Heartbeat of storage is supposed to be used")
optuna.logging.set_verbosity(optuna.logging.WARNING)

SAMPLERS = ("tpe", "random", "grid")
OBJECTIVE_OPTION = "--objective"
CONFIG_ATTR = "semistatic_search"
"""Study user attribute holding what defines the search (checked on resume)."""


class RejectedPoint(Exception):
    """Raised by a search's ``points(values)`` for values that make no valid scenario.

    (A drawn box pushed into a wall, say.) :func:`run_study` tells the trial failed, with
    the message as its ``error``: the values are tried, not run.
    """


@dataclass(frozen=True)
class SearchConfig:
    """What one search is: scenario, parameters, objectives, seeds, sampler, trials.

    Examples
    --------
    >>> SearchConfig("pal1", (), objectives=("f2",))
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --objective: f2: unknown metric
    """

    scenario: str
    params: tuple[SearchParam, ...]
    objectives: tuple[str, ...] = (DEFAULT_SORT,)
    seeds: tuple[int, ...] | None = None
    laps: int | None = None
    overrides: tuple[str, ...] = ()
    sampler: str = "tpe"
    trials: int = 20
    grid_points: int = 5
    sampler_seed: int = 0
    also: tuple[str, ...] = ()
    """Further scenarios every trial runs (each with every seed): robust thresholds."""
    sources: ScenarioSources = field(default_factory=ScenarioSources, compare=False, repr=False)
    """The scenario files (and worlds) as read first: every trial's points reuse them."""

    def __post_init__(self) -> None:
        if len(set(self.scenarios)) != len(self.scenarios):
            raise SpecError("scenario", ",".join(self.scenarios), "a scenario twice")
        for name in self.objectives:
            if name not in METRICS:
                raise SpecError(OBJECTIVE_OPTION, name,
                                f"unknown metric{did_you_mean(name, METRICS)}")
        if len(set(self.objectives)) != len(self.objectives):
            raise SpecError(OBJECTIVE_OPTION, ",".join(self.objectives), "an objective twice")
        if self.sampler not in SAMPLERS:
            raise SpecError("--sampler", self.sampler,
                            f"unknown sampler{did_you_mean(self.sampler, SAMPLERS)}")
        if self.trials < 1:
            raise SpecError("--trials", "trials", f"must be >= 1, got {self.trials}")
        if self.grid_points < 2:
            raise SpecError("--grid-points", "grid_points",
                            f"must be >= 2, got {self.grid_points}")
        if self.sampler == "grid" and self.params:
            size = grid_size(self.params, self.grid_points)
            if self.trials > size:
                raise SpecError("--trials", "trials",
                                f"{self.trials} exceeds the grid's {size} points")

    @property
    def scenarios(self) -> tuple[str, ...]:
        """Return every scenario a trial runs: ``scenario``, then ``also``."""
        return (self.scenario, *self.also)

    def directions(self) -> list[str]:
        """Return Optuna's direction of each objective."""
        return ["maximize" if METRICS[name].better == "high" else "minimize"
                for name in self.objectives]

    def fingerprint(self) -> dict[str, Any]:
        """Return what defines the study (JSON): a resumed study must have the same."""
        return json.loads(json.dumps({
            "scenario": self.scenario, "params": [repr(p) for p in self.params],
            "objectives": list(self.objectives), "seeds": self.seeds, "laps": self.laps,
            "overrides": list(self.overrides), "sampler": self.sampler,
            "grid_points": self.grid_points, "sampler_seed": self.sampler_seed,
            # Only when given, so that the studies of one scenario keep their fingerprint.
            **({"also": list(self.also)} if self.also else {}),
        }))

    def distributions(self) -> dict[str, optuna.distributions.BaseDistribution]:
        """Return Optuna's distribution of each parameter, by key."""
        return {param.key: param.distribution() for param in self.params}

    def points(self, values: Mapping[str, Any]):
        """Return the validated sweep points of ``values``: each scenario with each seed."""
        return self._points({key: (value,) for key, value in values.items()})

    def _points(self, grids: Mapping[str, Sequence[Any]]):
        return [point for scenario in self.scenarios
                for point in sweep_points(self.sources(scenario), grids, seeds=self.seeds,
                                          laps=self.laps, overrides=self.overrides)]

    def validate(self, recordings: RecordingSet | None = None) -> None:
        """Check every parameter's ends (or choices) against the scenario and recordings.

        Raises :class:`SpecError` naming ``--param`` for an unknown key or a value out
        of bounds, ``--recording`` for what a recording cannot replay.
        """
        if not self.params:
            raise SpecError(PARAM_OPTION, "KEY=LOW:HIGH", "nothing to search: give a --param")
        for param in self.params:
            try:
                points = self._points({param.key: param.endpoints()})
            except SpecError as error:
                if error.file != "--grid":
                    raise
                raise SpecError(PARAM_OPTION, error.key, error.message) from None
            if recordings is not None:
                for point in points:
                    recordings.for_spec(point.spec)

    def sampler_object(self, resumed: int = 0) -> optuna.samplers.BaseSampler:
        """Return the Optuna sampler seeded by :func:`resumed_seed` (``resumed``: trials held)."""
        seed = resumed_seed(self.sampler_seed, resumed)
        if self.sampler in ("grid", "random"):
            # The grid's points are queued when the study is made (grid_trials): Optuna's
            # GridSampler stops the study from inside tell(), which only works in optimize().
            return optuna.samplers.RandomSampler(seed=seed)
        return optuna.samplers.TPESampler(seed=seed)

    def grid_trials(self) -> list[dict[str, Any]]:
        """Return every point of the grid sampler's grid, in product order (else ``[]``).

        Examples
        --------
        >>> from scenarios.tuning.params import parse_params
        >>> SearchConfig("pal1", parse_params(["mapper.gate=0.1:0.2", "mapper.outlier_k=2,3"]),
        ...              sampler="grid", grid_points=2, trials=4).grid_trials()[:2]
        [{'mapper.gate': 0.1, 'mapper.outlier_k': 2}, {'mapper.gate': 0.1, 'mapper.outlier_k': 3}]
        """
        if self.sampler != "grid":
            return []
        keys = [param.key for param in self.params]
        values = [param.grid_values(self.grid_points) for param in self.params]
        return [dict(zip(keys, combination, strict=True))
                for combination in itertools.product(*values)]

    def objective_values(self, metrics: Sequence[Mapping[str, Any] | None]) -> dict[str, Any]:
        """Return the per-objective mean, worst case and spread over a trial's runs' metrics.

        The runs are every scenario with every seed. The optimised value is the mean (for
        NEES: the mean distance to :data:`~scenarios.tuning.metrics.NEES_TARGET`). ``None`` values
        when a run lacks one.

        Examples
        --------
        >>> config = SearchConfig("pal1", (), objectives=("f1",))
        >>> config.objective_values([{"detection": {"f1": 0.8}}, {"detection": {"f1": 0.6}}])
        {'mean': {'f1': 0.7}, 'worst': {'f1': 0.6}, 'spread': {'f1': 0.2}}
        """
        result: dict[str, dict[str, Any]] = {"mean": {}, "worst": {}, "spread": {}}
        for name in self.objectives:
            values = [metric_value(m, name) for m in metrics]
            if not values or any(v is None for v in values):
                result["mean"][name] = result["worst"][name] = result["spread"][name] = None
                continue
            metric = METRICS[name]
            if metric.better == "nees":
                values = [abs(v - NEES_TARGET) for v in values]
            result["mean"][name] = round(math.fsum(values) / len(values), 6)
            result["worst"][name] = min(values) if metric.better == "high" else max(values)
            result["spread"][name] = round(max(values) - min(values), 6)
        return result


def resumed_seed(seed: int, resumed: int) -> int:
    """Return the sampler seed of a study resumed with ``resumed`` trials (``seed`` when new).

    A sampler made again with its first seed would propose the values it proposed before
    the interruption: a resumed study's sampler continues from a seed of its own.

    Examples
    --------
    >>> resumed_seed(7, 0), resumed_seed(7, 12) == resumed_seed(7, 12) != resumed_seed(7, 13)
    (7, True)
    """
    if resumed == 0:
        return seed
    return int(np.random.SeedSequence([seed, resumed]).generate_state(1)[0])


def open_study(config: SearchConfig, url: str, name: str,
               ) -> tuple[optuna.Study, optuna.storages.RDBStorage]:
    """Open study ``name`` in storage ``url`` (created when new); return it and the storage.

    A study made by a different search (other parameters, objectives, seeds...) is left
    untouched and refused with :class:`SpecError`. ``config`` is a :class:`SearchConfig`
    or another search with its ``sampler_object(resumed)``, ``fingerprint()``,
    ``directions()`` and ``grid_trials()``.
    """
    storage = open_storage(url)
    if name in optuna.study.get_all_study_names(storage):
        study = optuna.load_study(study_name=name, storage=storage)
        stored, wanted = study.user_attrs.get(CONFIG_ATTR), config.fingerprint()
        if stored != wanted:
            stored = stored if isinstance(stored, dict) else {}
            differs = [key for key in wanted if stored.get(key) != wanted[key]] or ["all"]
            raise SpecError(
                STORAGE_OPTION, name,
                f"study {name!r} in {url} belongs to another search (its "
                f"{', '.join(differs)} differ); use another --out, --storage or --study",
            )
        study.sampler = config.sampler_object(resumed=len(study.get_trials(deepcopy=False)))
        return study, storage
    study = optuna.create_study(storage=storage, study_name=name, sampler=config.sampler_object(),
                                directions=config.directions())
    study.set_user_attr(CONFIG_ATTR, config.fingerprint())
    for values in config.grid_trials()[:config.trials]:
        study.enqueue_trial(values)
    return study, storage


def _is_finished(trial: optuna.trial.FrozenTrial) -> bool:
    # A trial whose runs raised is finished (told FAIL with an "error"); a stale one is not.
    return trial.state == optuna.trial.TrialState.COMPLETE or (
        trial.state == optuna.trial.TrialState.FAIL and "error" in trial.user_attrs
    )


def finished_trials(study: optuna.Study) -> list[optuna.trial.FrozenTrial]:
    """Return the study's finished trials (complete, or failed by their runs), by number."""
    return [trial for trial in study.get_trials(deepcopy=False) if _is_finished(trial)]


def _tell(study: optuna.Study, trial: optuna.trial.Trial, config: SearchConfig,
          outcomes: Sequence[tuple[dict | None, str | None]], seeds: Sequence[int],
          runs: Sequence[str]) -> None:
    from scenarios.results.outputs import json_text

    metrics = [json.loads(json_text(m)) if m is not None else None for m, _ in outcomes]
    errors = [error for _, error in outcomes]
    objectives = config.objective_values(metrics)
    trial.set_user_attr("seeds", list(seeds))
    trial.set_user_attr("runs", list(runs))
    trial.set_user_attr("metrics", metrics)
    trial.set_user_attr("errors", errors)
    for key, values in objectives.items():
        trial.set_user_attr(key, values)
    means = [objectives["mean"][name] for name in config.objectives]
    failure = next((error for error in errors if error), None)
    if failure is None and any(value is None for value in means):
        failure = "no value for " + ", ".join(
            name for name, value in zip(config.objectives, means, strict=True) if value is None
        )
    if failure is not None:
        trial.set_user_attr("error", failure)
        study.tell(trial, state=optuna.trial.TrialState.FAIL)
    else:
        study.tell(trial, means)


def run_study(study: optuna.Study, storage: optuna.storages.RDBStorage, config: SearchConfig,
              backend,
              recordings: RecordingSet | None = None,
              on_trial: Callable[[int, str], None] | None = None,
              until: Callable[[optuna.Study], bool] | None = None) -> int:
    """Run trials on ``backend`` until the study has ``config.trials`` finished ones.

    Returns how many trials this call ran. Trials another driver is running count as
    in flight; once abandoned (no heartbeat for ``GRACE_S``) they are queued again and
    run here. ``on_trial(number, label)`` is called as each trial is told. When
    ``until(study)`` holds, no further trial is asked for (those in flight finish).

    ``config`` is a :class:`SearchConfig` or any search with the same ``trials``,
    ``distributions()``, ``points(values)`` (which may raise :class:`RejectedPoint`),
    ``objectives`` and ``objective_values(metrics)``.
    """
    distributions = config.distributions()
    identity = driver_identity()
    inflight: dict[int, tuple[optuna.trial.Trial, list]] = {}
    ran = 0
    beat = -math.inf  # when the driver last recorded heartbeats (time.monotonic)
    seen: set[int] = set()  # other drivers' running trials, each given one heartbeat
    changed = True    # a trial was told since the study was last read
    while True:
        # Reading the study and recording heartbeats are database round trips: once per
        # HEARTBEAT_S, or when a trial was told (the workers share the CPUs with us).
        raise_if_stopped()  # a stop signal whose exception a finalizer swallowed
        due = time.monotonic() - beat >= HEARTBEAT_S
        if changed or due:
            optuna.storages.fail_stale_trials(study)
            fail_orphaned_trials(study, storage, own=inflight.keys())
            trials = study.get_trials(deepcopy=False)
            finished = sum(1 for trial in trials if _is_finished(trial))
            running = [trial for trial in trials if trial.state == optuna.trial.TrialState.RUNNING
                       and trial.number not in inflight]
            foreign = len(running)
            for trial in running:
                if trial.number not in seen:
                    # One heartbeat at first sight: a trial left running without one (its
                    # driver died between asking and beating) goes stale GRACE_S from now,
                    # while a live driver's own heartbeats keep its trial fresh.
                    storage.record_heartbeat(trial._trial_id)
                    seen.add(trial.number)
            changed = False
        done = until is not None and until(study)
        if (finished >= config.trials or done) and not inflight:
            return ran
        free = 0 if done else config.trials - finished - len(inflight) - foreign
        # One trial more than the workers: it waits in the backend's queue and starts the
        # moment a worker is free, while the driver asks for and plans the next one.
        while free > 0 and len(inflight) < backend.capacity + 1:
            trial = study.ask(distributions)
            # Optuna's Trial has no public id; the heartbeat API takes the storage id.
            # At once: a running trial without a heartbeat is never taken for stale, so
            # one asked just before the driver dies would hold a resumed study forever.
            storage.record_heartbeat(trial._trial_id)
            storage.set_trial_system_attr(trial._trial_id, DRIVER_ATTR, identity)
            free -= 1
            changed = True
            try:
                points = config.points(trial.params)
            except RejectedPoint as rejected:
                trial.set_user_attr("error", f"rejected: {rejected}")
                study.tell(trial, state=optuna.trial.TrialState.FAIL)
                ran += 1
                if on_trial is not None:
                    on_trial(trial.number, f"rejected: {rejected}")
                continue
            inflight[trial.number] = (trial, points)
            backend.submit(trial.number, [point.spec for point in points], recordings)
        if due:
            for trial, _ in inflight.values():
                storage.record_heartbeat(trial._trial_id)
            beat = time.monotonic()
        wait = max(0.0, beat + HEARTBEAT_S - time.monotonic())
        if not inflight:
            time.sleep(wait)  # others' trials: wait for them to finish or go stale
            continue
        for number, outcomes in backend.finished(timeout=wait):
            trial, points = inflight.pop(number)
            _tell(study, trial, config, outcomes, [point.seed for point in points],
                  [point.run for point in points])
            ran += 1
            changed = True
            if on_trial is not None:
                values = " ".join(f"{key}={value:.6g}" if isinstance(value, float)
                                  else f"{key}={value}" for key, value in trial.params.items())
                on_trial(number, values)


def trial_results(study: optuna.Study, config: SearchConfig) -> list[PointResult]:
    """Return one :class:`~scenarios.tuning.run.PointResult` per finished trial and seed.

    The points are numbered in trial order, so ``sweep.csv`` lists trial after trial.
    """
    results = []
    for trial in finished_trials(study):
        ordered = {param.key: trial.params[param.key] for param in config.params}
        points = config.points(ordered)
        metrics = trial.user_attrs.get("metrics", [None] * len(points))
        errors = trial.user_attrs.get("errors", [trial.user_attrs.get("error")] * len(points))
        for point, point_metrics, error in zip(points, metrics, errors, strict=True):
            numbered = type(point)(len(results), point.settings, point.spec)
            results.append(PointResult(numbered, point_metrics, error))
    return results
