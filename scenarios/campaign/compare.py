"""Judge a candidate campaign against a baseline: per metric, worse, better or no change.

Within each ``(scenario, policy)`` group, runs with the same seed and the same sampled
variation values are pairs. A group whose every ok run has its partner is compared
paired (Wilcoxon signed-rank test of the differences), any other unpaired (Mann-Whitney
U test). Every test of one comparison is one family: the p-values are adjusted with
Benjamini-Hochberg, which under the global null (the same code run with other seeds)
keeps the chance of any false alarm at most ``alpha``. A change is reported only when it is
significant *and* at least the metric's ``min_change`` (:mod:`scenarios.campaign.tolerances`).
Runs that raised are counted apart (:data:`ERRORS`): any more of them in a group of the
candidate is a regression.

Examples
--------
>>> from scenarios.campaign.tolerances import Tolerance, Tolerances
>>> tolerances = Tolerances(0.05, {"m": Tolerance("m", "lower", 0.5)})
>>> def rows(shift):
...     return [{"scenario": "s", "policy": "p", "seed": seed, "status": "ok",
...              "m": seed % 3 + shift} for seed in range(10)]
>>> comparison = compare_campaigns(rows(0.0), rows(1.0), tolerances,
...                                rng=np.random.default_rng(0))
>>> comparison.metrics["m"].verdict, comparison.regressions, comparison.exit_status
('worse', ('m',), 1)
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.stats import false_discovery_control

from scenarios.campaign.significance import difference_test
from scenarios.campaign.stats import (
    BOOTSTRAP_RESAMPLES,
    STATUSES,
    VARY_PREFIX,
    finite_values,
    group_rows,
    metric_columns,
    status_counts,
)
from scenarios.campaign.tolerances import Tolerance, Tolerances
from semistatic.errors import SpecError
from semistatic.validation import did_you_mean

__all__ = [
    "BETTER",
    "ERRORS",
    "NOT_ENOUGH",
    "NOT_MEASURED",
    "NO_CHANGE",
    "WORSE",
    "Comparison",
    "GroupComparison",
    "MetricComparison",
    "compare_campaigns",
]

WORSE, BETTER, NO_CHANGE = "worse", "better", "no significant change"
NOT_MEASURED, NOT_ENOUGH = "not measured", "not enough runs"

Rows = Sequence[Mapping[str, Any]]


@dataclass(frozen=True)
class GroupComparison:
    """One metric in one ``(scenario, policy)`` group; ``difference`` is candidate - baseline.

    ``n_baseline`` and ``n_candidate`` count the values compared (paired: both the pairs).
    """

    scenario: str
    policy: str
    paired: bool
    n_baseline: int
    n_candidate: int
    baseline_mean: float | None = None
    candidate_mean: float | None = None
    difference: float | None = None
    ci: tuple[float, float] | None = None
    p: float | None = None
    p_adjusted: float | None = None
    verdict: str = NOT_MEASURED


@dataclass(frozen=True)
class MetricComparison:
    """One judged metric: its verdict over every group, and each group's comparison."""

    tolerance: Tolerance
    verdict: str
    groups: tuple[GroupComparison, ...]
    note: str = ""

    @property
    def worst_group(self) -> GroupComparison | None:
        """Return the compared group whose difference is the worst, or None."""
        compared = [group for group in self.groups if group.difference is not None]
        if not compared:
            return None
        worst = self.tolerance.worst(group.difference for group in compared)
        return next(group for group in compared if group.difference == worst)


@dataclass(frozen=True)
class Comparison:
    """The result of :func:`compare_campaigns`; ``metrics`` in the tolerance file's order."""

    baseline: str
    candidate: str
    alpha: float
    metrics: dict[str, MetricComparison]
    errors: MetricComparison
    runs: dict[str, dict[str, int]]
    versions: dict[str, str | None]

    @property
    def regressions(self) -> tuple[str, ...]:
        """Return the metrics judged worse (:data:`ERRORS` first when runs raised more)."""
        return tuple(name for name, metric in self.judged.items() if metric.verdict == WORSE)

    @property
    def judged(self) -> dict[str, MetricComparison]:
        """Return every verdict: the runs that raised (:data:`ERRORS`), then the metrics."""
        return {ERRORS: self.errors, **self.metrics}

    @property
    def exit_status(self) -> int:
        """Return 1 when a metric is worse, else 0."""
        return 1 if self.regressions else 0

    def markdown(self) -> str:
        """Return the report as GitHub Markdown: header, one line per metric, details.

        Examples
        --------
        >>> from scenarios.campaign.tolerances import default_tolerances
        >>> rows = [{"scenario": "s", "policy": "p", "seed": 0, "status": "ok"}]
        >>> report = compare_campaigns(rows, rows, default_tolerances(),
        ...                            rng=np.random.default_rng(0)).markdown()
        >>> report.splitlines()[0], "**No regression.**" in report
        ('# semistatic compare', True)
        """
        tests = sum(g.p is not None for m in self.metrics.values() for g in m.groups)
        lines = ["# semistatic compare", "", "| | baseline | candidate |", "|---|---|---|",
                 f"| campaign | `{self.baseline}` | `{self.candidate}` |",
                 f"| version | {self.versions['baseline']} | {self.versions['candidate']} |",
                 f"| runs ({' / '.join(STATUSES)}) | {_counts(self.runs['baseline'])} "
                 f"| {_counts(self.runs['candidate'])} |", "",
                 f"alpha = {self.alpha} over {tests} tests (Benjamini-Hochberg); a change "
                 "must also reach the metric's min_change.", "",
                 f"**Regressions: {', '.join(self.regressions)}**" if self.regressions
                 else "**No regression.**", "",
                 "| metric | better | verdict | worst group | its difference [95 % CI] |",
                 "|---|---|---|---|---:|"]
        for name, metric in self.judged.items():
            worst = metric.worst_group
            where = f"{worst.scenario} / {worst.policy}" if worst else metric.note or "-"
            lines.append(f"| {name} | {metric.tolerance.better} | {metric.verdict} "
                         f"| {where} | {_difference(worst)} |")
        for name, metric in self.judged.items():
            if metric.verdict not in (WORSE, BETTER):
                continue
            lines += ["", f"## {name}: {metric.verdict}", "",
                      "| scenario | policy | test | n | baseline | candidate "
                      "| difference [95 % CI] | p | p adjusted | verdict |",
                      "|---|---|---|---:|---:|---:|---:|---:|---:|---|"]
            lines += [f"| {g.scenario} | {g.policy} | {'paired' if g.paired else 'unpaired'} "
                      f"| {g.n_baseline} / {g.n_candidate} | {_number(g.baseline_mean)} "
                      f"| {_number(g.candidate_mean)} | {_difference(g)} | {_number(g.p)} "
                      f"| {_number(g.p_adjusted)} | {g.verdict} |" for g in metric.groups]
        return "\n".join(lines) + "\n"

    def junit_xml(self) -> str:
        """Return JUnit XML: a test case per judged metric and runs.error; a regression fails.

        Examples
        --------
        >>> from scenarios.campaign.tolerances import Tolerance, Tolerances
        >>> rows = [{"scenario": "s", "policy": "p", "seed": 0, "status": "ok", "m": 1.0}]
        >>> tolerances = Tolerances(0.05, {"m": Tolerance("m", "lower", 0.5)})
        >>> print(compare_campaigns(rows, rows, tolerances, rng=np.random.default_rng(0))
        ...       .junit_xml())  # doctest: +NORMALIZE_WHITESPACE
        <?xml version='1.0' encoding='utf-8'?>
        <testsuite name="semistatic compare" tests="2" failures="0" errors="0" skipped="1">
          <testcase classname="semistatic.compare" name="runs.error" />
          <testcase classname="semistatic.compare" name="m">
            <skipped message="m: not enough runs" />
          </testcase>
        </testsuite>
        <BLANKLINE>
        """
        suite = ET.Element("testsuite", name="semistatic compare")
        failures = skipped = 0
        for name, metric in self.judged.items():
            case = ET.SubElement(suite, "testcase", classname="semistatic.compare", name=name)
            worst = metric.worst_group
            summary = (f"{name}: {metric.verdict}; worst {worst.scenario} / {worst.policy}: "
                       f"{_difference(worst)}" if worst else f"{name}: {metric.verdict}")
            if metric.verdict == WORSE:
                failures += 1
                failure = ET.SubElement(case, "failure", message=summary)
                failure.text = "\n".join(
                    f"{g.scenario} / {g.policy}: {g.verdict}, difference {_difference(g)}, "
                    f"p adjusted {_number(g.p_adjusted)}, min_change "
                    f"{metric.tolerance.min_change}" for g in metric.groups)
            elif metric.verdict in (NOT_MEASURED, NOT_ENOUGH):
                skipped += 1
                ET.SubElement(case, "skipped", message=metric.note or summary)
        suite.set("tests", str(len(self.judged)))
        suite.set("failures", str(failures))
        suite.set("errors", "0")
        suite.set("skipped", str(skipped))
        ET.indent(suite)
        return ET.tostring(suite, encoding="unicode", xml_declaration=True) + "\n"


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.4g}"


def _difference(group: GroupComparison | None) -> str:
    if group is None or group.difference is None:
        return "-"
    ci = f" [{group.ci[0]:+.4g}, {group.ci[1]:+.4g}]" if group.ci is not None else ""
    return f"{group.difference:+.4g}{ci}"


def _counts(runs: Mapping[str, int]) -> str:
    return " / ".join(str(runs.get(status, 0)) for status in STATUSES)


def _pair_key(row: Mapping[str, Any]) -> tuple[Any, ...]:
    # repr: a drawn value may be a list (unhashable); equal draws print alike.
    drawn = sorted((name, repr(value)) for name, value in row.items()
                   if name.startswith(VARY_PREFIX))
    return (row.get("seed"), tuple(drawn))


def _partners(baseline: Rows, candidate: Rows) -> list[tuple[Mapping, Mapping]] | None:
    """Return the run pairs of a group, or None unless every run has exactly one partner."""
    before = {_pair_key(row): row for row in baseline}
    after = {_pair_key(row): row for row in candidate}
    unique = len(before) == len(baseline) and len(after) == len(candidate)
    if not unique or before.keys() != after.keys():
        return None
    return [(before[key], after[key]) for key in before]


def _group(
    scenario: str, policy: str, baseline: Rows, candidate: Rows,
    pairs: list[tuple[Mapping, Mapping]] | None, metric: str, rng: np.random.Generator,
    n_resamples: int,
) -> GroupComparison:
    if pairs is not None:
        complete = [(b, c) for b, c in pairs
                    if finite_values([b], metric).size and finite_values([c], metric).size]
        before = finite_values([b for b, _ in complete], metric)
        after = finite_values([c for _, c in complete], metric)
    else:
        before, after = finite_values(baseline, metric), finite_values(candidate, metric)
    common = {"scenario": scenario, "policy": policy, "paired": pairs is not None,
              "n_baseline": before.size, "n_candidate": after.size}
    if not finite_values(baseline, metric).size or not finite_values(candidate, metric).size:
        return GroupComparison(**common, verdict=NOT_MEASURED)
    if before.size < 2 or after.size < 2:
        return GroupComparison(**common, verdict=NOT_ENOUGH)
    difference, ci, p = difference_test(before, after, pairs is not None, rng, n_resamples)
    return GroupComparison(**common, baseline_mean=float(np.mean(before)),
                           candidate_mean=float(np.mean(after)), difference=difference,
                           ci=ci, p=p, verdict=NO_CHANGE)


def _judged(group: GroupComparison, tolerance: Tolerance, alpha: float) -> str:
    if group.p_adjusted is None or group.difference is None:
        return group.verdict
    if group.p_adjusted >= alpha or abs(group.difference) < tolerance.min_change:
        return NO_CHANGE
    if tolerance.is_worse(group.difference):
        return WORSE
    return BETTER if tolerance.is_better(group.difference) else NO_CHANGE


def _metric_verdict(groups: Sequence[GroupComparison]) -> str:
    verdicts = {group.verdict for group in groups}
    for verdict in (WORSE, BETTER, NO_CHANGE, NOT_ENOUGH):
        if verdict in verdicts:
            return verdict
    return NOT_MEASURED


def _unmeasured(metric: str, sides: Mapping[str, Rows]) -> str:
    missing = [side for side, rows in sides.items() if not any(metric in row for row in rows)]
    if not missing:
        return ""
    known = {name for rows in sides.values() for name in metric_columns(rows)}
    return f"no column {metric!r} in {' or '.join(missing)}{did_you_mean(metric, known)}"


ERRORS = "runs.error"
"""The judged count of runs that raised: a candidate with more of them in a group regressed."""


def _errors(before: Mapping[tuple[str, str], Rows], after: Mapping[tuple[str, str], Rows],
            ) -> MetricComparison:
    """Return the verdict on runs that raised: no test, any increase is a regression.

    A run that raises measures nothing, so its metrics cannot show that it got worse;
    counting the errors per group keeps a candidate that crashes from passing.
    """
    groups = []
    for (scenario, policy), rows in before.items():
        counts = [sum(row["status"] == "error" for row in side)
                  for side in (rows, after[(scenario, policy)])]
        verdict = WORSE if counts[1] > counts[0] else BETTER if counts[1] < counts[0] \
            else NO_CHANGE
        groups.append(GroupComparison(
            scenario, policy, paired=False, n_baseline=len(rows),
            n_candidate=len(after[(scenario, policy)]), baseline_mean=float(counts[0]),
            candidate_mean=float(counts[1]), difference=float(counts[1] - counts[0]),
            verdict=verdict))
    return MetricComparison(Tolerance(ERRORS, "lower", 0.0), _metric_verdict(groups),
                            tuple(groups))


def compare_campaigns(
    baseline_rows: Rows,
    candidate_rows: Rows,
    tolerances: Tolerances,
    *,
    rng: np.random.Generator,
    baseline_manifest: Mapping[str, Any] | None = None,
    candidate_manifest: Mapping[str, Any] | None = None,
    baseline_name: str = "baseline",
    candidate_name: str = "candidate",
    n_resamples: int = BOOTSTRAP_RESAMPLES,
) -> Comparison:
    """Compare two campaigns' rows metric by metric (the module's docstring says how).

    Raises :class:`~semistatic.errors.SpecError` (naming the campaigns) when their
    manifests declare different result formats or their ``(scenario, policy)`` groups
    differ. A judged metric that a campaign lacks is "not measured", not an error. Each
    test's bootstrap interval draws from its own generator spawned from ``rng``.

    Examples
    --------
    >>> from scenarios.campaign.tolerances import default_tolerances
    >>> compare_campaigns([], [], default_tolerances(), rng=np.random.default_rng(0),
    ...                   baseline_manifest={"format": 1}, candidate_manifest={"format": 2},
    ...                   baseline_name="runs/a", candidate_name="runs/b")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: runs/b: format: mismatched versions of the result format: \
runs/a has 1, runs/b has 2
    """
    manifests = (baseline_manifest or {}, candidate_manifest or {})
    if manifests[0].get("format") != manifests[1].get("format"):
        raise SpecError(candidate_name, "format", "mismatched versions of the result format: "
                        f"{baseline_name} has {manifests[0].get('format')}, {candidate_name} "
                        f"has {manifests[1].get('format')}")
    before, after = group_rows(baseline_rows), group_rows(candidate_rows)
    if before.keys() != after.keys():
        only = [f"only in {name}: " + ", ".join(f"{s} / {p}" for s, p in sorted(keys))
                for name, keys in ((baseline_name, before.keys() - after.keys()),
                                   (candidate_name, after.keys() - before.keys())) if keys]
        raise SpecError(candidate_name, "groups", "the campaigns ran different scenario / "
                        f"policy groups ({'; '.join(only)}); compare campaigns of one plan")
    runs = {}
    for key in before:
        ok = tuple([row for row in side[key] if row["status"] == "ok"] for side in (before, after))
        runs[key] = (*ok, _partners(*ok))
    streams = iter(rng.spawn(len(tolerances.metrics) * len(runs)))
    compared = {name: [_group(*key, *runs[key], name, next(streams), n_resamples) for key in runs]
                for name in tolerances.metrics}
    tested = [(name, index) for name, groups in compared.items()
              for index, group in enumerate(groups) if group.p is not None]
    if tested:
        adjusted = false_discovery_control([compared[name][index].p for name, index in tested])
        for (name, index), p_adjusted in zip(tested, adjusted, strict=True):
            compared[name][index] = replace(compared[name][index], p_adjusted=float(p_adjusted))
    sides = {baseline_name: baseline_rows, candidate_name: candidate_rows}
    metrics = {}
    for name, groups in compared.items():
        tolerance = tolerances.metrics[name]
        judged = tuple(replace(group, verdict=_judged(group, tolerance, tolerances.alpha))
                       for group in groups)
        metrics[name] = MetricComparison(tolerance, _metric_verdict(judged), judged,
                                         _unmeasured(name, sides))
    return Comparison(
        baseline_name, candidate_name, tolerances.alpha, metrics, _errors(before, after),
        runs={"baseline": status_counts(baseline_rows),
              "candidate": status_counts(candidate_rows)},
        versions={"baseline": manifests[0].get("version"),
                  "candidate": manifests[1].get("version")},
    )
