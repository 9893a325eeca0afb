"""A falsification search: samplers over the ``--vary`` box, one Optuna study per policy.

Each trial is one run of the scenario with the values a sampler proposes for the varied
keys (``--set`` keys or world objects, as :mod:`scenarios.campaign.variations` reads
them; only ``uniform`` ranges and ``choice`` lists, the box a search explores). The study
is told the run's objectives (:mod:`scenarios.falsify.objectives`), each the worse way,
so a guided sampler walks toward violations. Trials run on the tuning's backends and are
stored, heartbeats and all, like a tuning study (:func:`scenarios.tuning.search.run_study`):
the same command resumes a killed search and runs no sample twice.

Samplers (``--sampler``):

- ``random``: independent uniform draws, the baseline every guided search must beat;
- ``halton``, ``sobol``: scrambled low-discrepancy sequences (Optuna's ``QMCSampler``)
  that cover the box evenly, for coverage rather than speed;
- ``tpe``: Optuna's tree-structured Parzen estimator (multivariate, with a constant liar
  so parallel trials spread out);
- ``cmaes``: CMA-ES (Optuna's ``CmaEsSampler``), a single objective over ranges.

Examples
--------
>>> from scenarios.campaign.variations import parse_variations
>>> from scenarios.falsify.objectives import parse_objectives
>>> config = FalsifyConfig("occlusion_hall", "adaptive",
...                        parse_variations(["world.people.worker.speed=uniform(0.5, 1.5)"]),
...                        parse_objectives([], []), budget=10, seed=0)
>>> config.directions(), config.objectives
(['minimize'], ('safety.min_separation_m.person',))
>>> config.distributions()["world.people.worker.speed"]
FloatDistribution(high=1.5, log=False, low=0.5, step=None)
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import optuna

from scenarios.campaign.plan import CampaignRun, check_campaign, plan_campaign
from scenarios.campaign.variations import VARY_OPTION, Variation
from scenarios.falsify.objectives import Objective
from scenarios.spec.scenario import ScenarioSpec
from scenarios.tuning.search import RejectedPoint, resumed_seed
from semistatic.errors import SpecError
from semistatic.validation import did_you_mean

__all__ = ["DEFAULT_SAMPLER", "MAX_BUDGET", "SAMPLERS", "FalsifyConfig"]

SAMPLERS = ("random", "halton", "sobol", "tpe", "cmaes")
DEFAULT_SAMPLER = "tpe"
"""The sampler that found the seeded faults' violations in the fewest runs
(docs/falsification.md)."""
MAX_BUDGET = 100_000
"""More simulations than this is a typo, not a search."""

TPE_STARTUP = 8
"""Random trials before TPE models the objective: enough for a first split of a 2-4 key box."""

# Sobol wants power-of-two counts and both QMC and CMA-ES hand categorical keys to an
# independent sampler; the budget and the box are the user's choice, not a warning.
warnings.filterwarnings("ignore", message=".*(Sobol|power of 2|independent|QMCSampler).*")


@dataclass(frozen=True)
class FalsifyConfig:
    """What one falsification is: scenario, policy, varied keys, objectives, sampler, budget.

    ``seed`` is the scenario seed of every run (the varied keys are what changes);
    ``worlds_dir`` is where the varied worlds of world-object keys are written.

    Examples
    --------
    >>> from scenarios.campaign.variations import parse_variations
    >>> FalsifyConfig("pal1", "adaptive", parse_variations(["mapper.gate=normal(0.1, 0.01)"]),
    ...               (), budget=5, seed=0)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --vary: mapper.gate: a search explores a box: write \
uniform(LOW, HIGH) or choice(V1, V2, ...), not normal()
    """

    scenario: str
    policy: str
    variations: tuple[Variation, ...]
    kpis: tuple[Objective, ...]
    budget: int
    seed: int
    sampler: str = DEFAULT_SAMPLER
    sampler_seed: int = 0
    laps: int | None = None
    overrides: tuple[str, ...] = ()
    worlds_dir: Path | None = None
    # The scenario's and world's tables as read for the first plan: every sample's plan
    # uses them, whatever happens to the files during the search.
    read_files: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        for variation in self.variations:
            if variation.distribution == "normal":
                raise SpecError(VARY_OPTION, variation.key, "a search explores a box: write "
                                "uniform(LOW, HIGH) or choice(V1, V2, ...), not normal()")
        if self.sampler not in SAMPLERS:
            raise SpecError("--sampler", self.sampler,
                            f"unknown sampler{did_you_mean(self.sampler, SAMPLERS)}; "
                            f"one of {', '.join(SAMPLERS)}")
        if self.sampler == "cmaes" and len(self.kpis) > 1:
            raise SpecError("--sampler", self.sampler, "CMA-ES searches one objective; use "
                            "tpe, random, halton or sobol for a Pareto search")
        if not 1 <= self.budget <= MAX_BUDGET:
            raise SpecError("--budget", "budget", f"must be >= 1 and <= {MAX_BUDGET}, "
                            f"got {self.budget}")

    @property
    def trials(self) -> int:
        """Return the number of simulations to finish (the budget)."""
        return self.budget

    @property
    def objectives(self) -> tuple[str, ...]:
        """Return the objectives' metric names."""
        return tuple(kpi.metric for kpi in self.kpis)

    def directions(self) -> list[str]:
        """Return Optuna's direction of each objective: toward violations."""
        return [kpi.direction for kpi in self.kpis]

    def distributions(self) -> dict[str, optuna.distributions.BaseDistribution]:
        """Return Optuna's distribution of each varied key."""
        return {v.key: optuna.distributions.CategoricalDistribution(v.arguments)
                if v.distribution == "choice" else
                optuna.distributions.FloatDistribution(*map(float, v.arguments))
                for v in self.variations}

    def check(self) -> None:
        """Raise :class:`SpecError` unless the scenario takes the policy and every range.

        Both ends of every range and every choice are checked, as a campaign's are.
        """
        if not self.variations:
            raise SpecError(VARY_OPTION, "KEY=uniform(LOW, HIGH)",
                            "nothing to search: give at least one --vary")
        check_campaign([self.scenario], [self.policy], self.variations, seeds=[self.seed],
                       laps=self.laps, overrides=self.overrides)

    def fingerprint(self) -> dict[str, Any]:
        """Return what defines the study (JSON): a resumed study must have the same."""
        return json.loads(json.dumps({
            "scenario": self.scenario, "policy": self.policy,
            "vary": {v.key: v.text for v in self.variations},
            "objectives": [[kpi.metric, kpi.threshold] for kpi in self.kpis],
            "seed": self.seed, "laps": self.laps, "overrides": list(self.overrides),
            "sampler": self.sampler, "sampler_seed": self.sampler_seed,
        }))

    def sampler_object(self, resumed: int = 0) -> optuna.samplers.BaseSampler:
        """Return the seeded Optuna sampler (a search is repeatable from its command).

        A study resumed with ``resumed`` trials gets a sampler seeded anew
        (:func:`~scenarios.tuning.search.resumed_seed`), which draws no earlier values
        again; a low-discrepancy sequence keeps its seed and goes on where it stopped (the
        study stores its position).
        """
        if self.sampler in ("halton", "sobol"):
            return optuna.samplers.QMCSampler(
                qmc_type=self.sampler, scramble=True, seed=self.sampler_seed,
                independent_sampler=optuna.samplers.RandomSampler(
                    seed=resumed_seed(self.sampler_seed, resumed)),
                warn_asynchronous_seeding=False, warn_independent_sampling=False)
        seed = resumed_seed(self.sampler_seed, resumed)
        if self.sampler == "random":
            return optuna.samplers.RandomSampler(seed=seed)
        if self.sampler == "cmaes":
            return optuna.samplers.CmaEsSampler(
                seed=seed, n_startup_trials=TPE_STARTUP, warn_independent_sampling=False,
                independent_sampler=optuna.samplers.RandomSampler(seed=seed))
        return optuna.samplers.TPESampler(seed=seed, multivariate=True, constant_liar=True,
                                          n_startup_trials=TPE_STARTUP)

    def base_spec(self) -> ScenarioSpec:
        """Return the scenario every sample varies: its policy, seed, laps and ``--set``."""
        [run] = plan_campaign([self.scenario], [self.policy], [self.seed], (), [{}],
                              laps=self.laps, overrides=self.overrides, worlds_dir=None,
                              read_files=self.read_files)
        return run.spec

    def warm_lap(self) -> int | None:
        """Return the lap samples can start from a warm start, or ``None`` (full runs).

        When every varied key is a field (not the body) of people who act only from lap
        ``L >= 2`` on (their ``laps``), the laps before ``L`` are the same in every sample:
        :class:`~scenarios.tuning.warm.WarmStarts` simulates them once per worker.
        """
        from scenarios.spec.layout import lap_worlds
        from scenarios.spec.routes import fleet_vehicles
        from scenarios.tuning.warm import BODY_FIELDS

        base = self.base_spec()
        if not self.variations or len(fleet_vehicles(base)) > 1:
            return None
        people = {person.name: person for person in lap_worlds(base)[0].people}
        first = []
        for variation in self.variations:
            path = variation.world_path
            if path is None or path[0] != "people" or path[2] in BODY_FIELDS:
                return None
            person = people.get(path[1])
            if person is None or not person.laps:
                return None
            first.append(min(person.laps))
        lap = min(first)
        return lap if lap >= 2 else None

    def grid_trials(self) -> list[dict[str, Any]]:
        """Return the trials to queue when the study is made: none (samplers propose all)."""
        return []

    def points(self, values: Mapping[str, Any]) -> list[CampaignRun]:
        """Return the one run of ``values``; raise :class:`RejectedPoint` if it cannot run."""
        ordered = {v.key: values[v.key] for v in self.variations}
        [run] = plan_campaign([self.scenario], [self.policy], [self.seed], self.variations,
                              [ordered], laps=self.laps, overrides=self.overrides,
                              worlds_dir=self.worlds_dir, read_files=self.read_files)
        if run.spec is None:
            raise RejectedPoint(run.reason)
        return [run]

    def objective_values(self, metrics: Sequence[Mapping[str, Any] | None]) -> dict[str, Any]:
        """Return a trial's objectives as a tuning trial's (mean, worst, spread) of one run.

        Examples
        --------
        >>> from scenarios.falsify.objectives import parse_objectives
        >>> config = FalsifyConfig("pal1", "adaptive", (), parse_objectives([], []),
        ...                        budget=1, seed=0)
        >>> config.objective_values([{"safety": {"min_separation_m": {"person": 0.25}}}])
        {'mean': {'safety.min_separation_m.person': 0.25}, \
'worst': {'safety.min_separation_m.person': 0.25}, \
'spread': {'safety.min_separation_m.person': 0.0}}
        """
        [run_metrics] = metrics
        values = {kpi.metric: kpi.value(run_metrics) for kpi in self.kpis}
        return {"mean": values, "worst": dict(values),
                "spread": {name: None if value is None else 0.0
                           for name, value in values.items()}}

    def violated(self, trial: optuna.trial.FrozenTrial) -> bool:
        """Return whether a finished trial of this search's study ran and violated."""
        return ("error" not in trial.user_attrs
                and bool(self.violations(trial.user_attrs.get("mean", {}))))

    def violations(self, values: Mapping[str, float | None]) -> list[str]:
        """Return the objectives whose value in ``values`` reaches the threshold."""
        return [kpi.metric for kpi in self.kpis if kpi.violated(values.get(kpi.metric))]
