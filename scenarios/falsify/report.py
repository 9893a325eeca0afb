"""A falsification's results: samples, coverage, counterexamples, summary and figures.

Per policy, from its study: one row per simulated sample (``runs.parquet``, ``runs.csv``:
the policy, the drawn values, the objectives, whether they were violated and the run's
metrics flattened), the coverage of the varied box (``--bins`` equal bins per range, one
per choice: which were sampled and the violation rate in each), and every violation plus
the ``k`` worst other samples as *counterexamples*: complete scenario files beside their
world that ``semistatic run`` repeats exactly.

Examples
--------
>>> edges = bin_edges((0.0, 2.0), 4)
>>> edges.tolist(), bin_of(1.99, edges), bin_of(2.0, edges)
([0.0, 0.5, 1.0, 1.5, 2.0], 3, 3)
"""

from __future__ import annotations

import itertools
import json
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import optuna

from scenarios.campaign.plan import world_document
from scenarios.campaign.table import flatten_metrics, write_runs
from scenarios.falsify.search import FalsifyConfig
from scenarios.process.staging import write_atomic
from scenarios.spec.load import scenario_table
from scenarios.tuning.search import finished_trials
from worlds.load import world_path

__all__ = [
    "COUNTEREXAMPLES_DIR",
    "SUMMARY_FILE",
    "PolicySearch",
    "bin_edges",
    "bin_of",
    "coverage",
    "important_keys",
    "sample_rows",
    "trial_status",
    "write_counterexamples",
    "write_falsification",
]

SUMMARY_FILE = "summary.json"
COUNTEREXAMPLES_DIR = "counterexamples"


@dataclass(frozen=True)
class PolicySearch:
    """One policy's search: its configuration and its (finished or resumed) study."""

    config: FalsifyConfig
    study: optuna.Study


def bin_edges(bounds: tuple[float, float], bins: int) -> np.ndarray:
    """Return the ``bins + 1`` edges of equal bins over ``bounds``."""
    return np.linspace(float(bounds[0]), float(bounds[1]), bins + 1)


def bin_of(value: float, edges: np.ndarray) -> int:
    """Return the bin of ``value`` (the upper end belongs to the last bin)."""
    return int(min(max(np.searchsorted(edges, value, side="right") - 1, 0), len(edges) - 2))


def trial_status(trial: optuna.trial.FrozenTrial) -> tuple[str, str | None]:
    """Return a finished sample's status (``ok``, ``rejected``, ``error``) and why not ok."""
    error = trial.user_attrs.get("error")
    if error is None:
        return "ok", None
    if str(error).startswith("rejected: "):
        return "rejected", str(error)[len("rejected: "):]
    return "error", str(error)


def sample_rows(search: PolicySearch) -> list[dict[str, Any]]:
    """Return one row per finished sample of a policy's study, in trial order."""
    config = search.config
    scenario = Path(config.scenario).stem  # a bundled name, or the file's
    rows = []
    for trial in finished_trials(search.study):
        status, reason = trial_status(trial)
        metrics = (trial.user_attrs.get("metrics") or [None])[0]
        values = trial.user_attrs.get("mean", {})
        violated = config.violations(values) if status == "ok" else []
        row: dict[str, Any] = {
            "run": f"{scenario} {config.policy} sample={trial.number} seed={config.seed}",
            "scenario": scenario, "policy": config.policy, "seed": config.seed,
            "sample": trial.number, "status": status, "reason": reason,
        }
        row.update({f"vary.{v.key}": trial.params.get(v.key) for v in config.variations})
        row.update({f"objective.{kpi.metric}": values.get(kpi.metric) for kpi in config.kpis})
        row["violation"] = bool(violated) if status == "ok" else None
        row["violated"] = ",".join(violated) or None
        if metrics is not None and status == "ok":
            row.update(flatten_metrics(metrics))
        rows.append(row)
    return rows


def _bins_of(variation, bins: int) -> tuple[list[str], Any]:
    """Return the bin labels of a varied key and a function from a value to its bin."""
    if variation.distribution == "choice":
        labels = [str(choice) for choice in variation.arguments]
        return labels, lambda value: labels.index(str(value))
    edges = bin_edges(tuple(variation.arguments), bins)
    labels = [f"[{low:.4g}, {high:.4g})" for low, high in itertools.pairwise(edges)]
    return labels, lambda value: bin_of(float(value), edges)


def coverage(rows: Sequence[Mapping[str, Any]], config: FalsifyConfig, bins: int,
             pair: Sequence[str]) -> dict[str, Any]:
    """Return the coverage of the varied box by the simulated samples.

    Per key: each bin's samples, violations and violation rate (``None`` when
    unsampled); over the two keys of ``pair``: the grid of bins, sampled cells and the
    violation rate per cell; and the share of all cells of the full box (every key's
    bins) that holds a sample.

    Examples
    --------
    >>> from scenarios.campaign.variations import parse_variations
    >>> from scenarios.falsify.objectives import parse_objectives
    >>> config = FalsifyConfig("pal1", "adaptive", parse_variations(
    ...     ["mapper.gate=uniform(0, 1)"]), parse_objectives([], []), budget=2, seed=0)
    >>> rows = [{"status": "ok", "vary.mapper.gate": 0.1, "violation": True},
    ...         {"status": "ok", "vary.mapper.gate": 0.2, "violation": False}]
    >>> cover = coverage(rows, config, 2, ["mapper.gate"])
    >>> cover["keys"]["mapper.gate"]["samples"], cover["keys"]["mapper.gate"]["violation_rate"]
    ([2, 0], [0.5, None])
    >>> cover["cells_sampled"], cover["cells"]
    (1, 2)
    """
    ok = [row for row in rows if row["status"] == "ok"]
    binned = {v.key: _bins_of(v, bins) for v in config.variations}
    keys: dict[str, Any] = {}
    for key, (labels, which) in binned.items():
        samples, hits = [0] * len(labels), [0] * len(labels)
        for row in ok:
            index = which(row[f"vary.{key}"])
            samples[index] += 1
            hits[index] += bool(row["violation"])
        keys[key] = {"bins": labels, "samples": samples, "violations": hits,
                     "violation_rate": [h / n if n else None for h, n in zip(hits, samples,
                                                                              strict=True)]}
    cells = {tuple(binned[key][1](row[f"vary.{key}"]) for key in binned) for row in ok}
    result: dict[str, Any] = {"bins": bins, "keys": keys, "cells": math.prod(
        len(labels) for labels, _ in binned.values()), "cells_sampled": len(cells)}
    if len(pair) == 2:
        (xl, xw), (yl, yw) = binned[pair[0]], binned[pair[1]]
        samples = np.zeros((len(yl), len(xl)), dtype=int)
        hits = np.zeros_like(samples)
        for row in ok:
            x, y = xw(row[f"vary.{pair[0]}"]), yw(row[f"vary.{pair[1]}"])
            samples[y, x] += 1
            hits[y, x] += bool(row["violation"])
        rate = np.where(samples > 0, hits / np.maximum(samples, 1), np.nan)
        result["pair"] = {"keys": list(pair), "x_bins": xl, "y_bins": yl,
                          "samples": samples.tolist(),
                          "violation_rate": [[None if np.isnan(r) else float(r) for r in line]
                                             for line in rate]}
    return result


def important_keys(search: PolicySearch) -> list[str]:
    """Return the varied keys, most important first for the first objective's worst values.

    Importance is Optuna's PED-ANOVA (which keys tell the worst samples from the rest);
    with fewer than two varied keys or too few samples, the keys in the order given.
    """
    keys = [v.key for v in search.config.variations]
    complete = [t for t in search.study.get_trials(deepcopy=False)
                if t.state == optuna.trial.TrialState.COMPLETE]
    if len(keys) < 2 or len(complete) < 4:
        return keys
    sign = 1.0 if search.config.kpis[0].direction == "minimize" else -1.0
    try:
        with warnings.catch_warnings():  # it warns that it ranks low targets: the sign does
            warnings.simplefilter("ignore")
            scores = optuna.importance.get_param_importances(
                search.study, params=keys, target=lambda trial: sign * trial.values[0],
                evaluator=optuna.importance.PedAnovaImportanceEvaluator())
    except (ValueError, RuntimeError, ZeroDivisionError):  # e.g. every value the same
        return keys
    ranked = [key for key in scores if key in keys]
    return ranked + [key for key in keys if key not in ranked]


def _worse_first(config: FalsifyConfig, rows: Sequence[Mapping[str, Any]]) -> list[Mapping]:
    kpi = config.kpis[0]
    valued = [row for row in rows if row["status"] == "ok"
              and row.get(f"objective.{kpi.metric}") is not None]
    sign = 1.0 if kpi.better == "higher" else -1.0
    return sorted(valued, key=lambda row: (sign * row[f"objective.{kpi.metric}"], row["sample"]))


def write_counterexamples(out: Path, search: PolicySearch, rows: Sequence[Mapping[str, Any]],
                          k_worst: int) -> list[dict[str, Any]]:
    """Write every violation and the ``k_worst`` worst other samples as scenario files.

    Each is ``counterexamples/POLICY-NNNN.toml`` (the scenario with every ``--set`` and
    drawn value written in, and its seed) beside ``POLICY-NNNN.world.toml`` (its world);
    ``semistatic run`` on it gives the sample's metrics. Returns one entry per file.
    """
    config = search.config
    violations = [row for row in rows if row["violation"]]
    others = [row for row in _worse_first(config, rows) if not row["violation"]][:k_worst]
    folder = out / COUNTEREXAMPLES_DIR
    written = []
    by_number = {trial.number: trial for trial in finished_trials(search.study)}
    for kind, chosen in (("violation", violations), ("worst", others)):
        for row in chosen:
            trial = by_number[row["sample"]]
            [run] = config.points(trial.params)
            stem = f"{config.policy}-{row['sample']:04d}"
            folder.mkdir(parents=True, exist_ok=True)
            world_file = world_path(run.spec.world)
            write_atomic(folder / f"{stem}.world.toml", world_file.read_text())
            table = scenario_table(config.scenario,
                                   overrides=[*run.overrides, f"seed={run.seed}"])
            table["name"] = run.spec.name
            table["world"] = f"{stem}.world.toml"
            objectives = {kpi.metric: row[f"objective.{kpi.metric}"] for kpi in config.kpis}
            what = "A violation" if kind == "violation" else f"One of the {k_worst} worst samples"
            header = (
                f"# {what} found by semistatic falsify: sample {row['sample']} of the "
                f"{config.sampler} search of {config.scenario} under policy {config.policy}.\n"
                + "".join(f"# {key} = {value!r}\n" for key, value in run.values)
                + "".join(f"# {metric} = {value}\n" for metric, value in objectives.items())
                + f"# Repeat it: semistatic run {COUNTEREXAMPLES_DIR}/{stem}.toml\n"
            )
            write_atomic(folder / f"{stem}.toml", header + world_document(table))
            written.append({"file": f"{COUNTEREXAMPLES_DIR}/{stem}.toml", "kind": kind,
                            "sample": row["sample"], "policy": config.policy,
                            "values": dict(run.values), "objectives": objectives})
    return written


def _policy_summary(search: PolicySearch, rows: Sequence[Mapping[str, Any]], bins: int,
                    ) -> dict[str, Any]:
    config = search.config
    kpi = config.kpis[0]
    ok = [row for row in rows if row["status"] == "ok"]
    violations = [row for row in ok if row["violation"]]
    worst = _worse_first(config, rows)
    best_so_far, current = [], None
    for row in rows:
        value = row.get(f"objective.{kpi.metric}") if row["status"] == "ok" else None
        if value is not None and (current is None or (value < current if kpi.better == "higher"
                                                      else value > current)):
            current = value
        best_so_far.append(current)
    keys = important_keys(search)
    return {
        "policy": config.policy, "sampler": config.sampler, "budget": config.budget,
        "simulations": len(rows), "ok": len(ok),
        "rejected": sum(row["status"] == "rejected" for row in rows),
        "errors": sum(row["status"] == "error" for row in rows),
        "violations": len(violations),
        "violation_rate": len(violations) / len(ok) if ok else None,
        "first_violation": (min(row["sample"] for row in violations) + 1 if violations
                            else None),
        "worst": {"sample": worst[0]["sample"], "values": {
            v.key: worst[0][f"vary.{v.key}"] for v in config.variations},
            **{k.metric: worst[0][f"objective.{k.metric}"] for k in config.kpis}}
        if worst else None,
        "best_so_far": best_so_far,
        "importance": keys,
        "coverage": coverage(rows, config, bins, keys[:2]),
    }


def _summary_text(summaries: Sequence[Mapping[str, Any]], config: FalsifyConfig, out: Path,
                  files: Sequence[str]) -> str:
    kpi = config.kpis[0]
    lines = [f"{'policy':<13} {'sims':>5} {'violations':>10} {'rate':>6} {'first at':>8}  "
             f"worst {kpi.metric}"]
    for summary in summaries:
        rate = summary["violation_rate"]
        worst = summary["worst"]
        lines.append(
            f"{summary['policy']:<13} {summary['simulations']:>5} {summary['violations']:>10} "
            f"{'-' if rate is None else f'{rate:.0%}':>6} "
            f"{summary['first_violation'] or '-':>8}  "
            + ("-" if worst is None else f"{worst[kpi.metric]:.4g} at sample {worst['sample']}: "
               + ", ".join(f"{key}={value:.4g}" if isinstance(value, float)
                           else f"{key}={value}" for key, value in worst["values"].items())))
    lines.append(f"results in {out}/ ({', '.join(files)})")
    return "\n".join(lines)


def write_falsification(out: Path, searches: Sequence[PolicySearch], *, bins: int,
                        k_worst: int, command: Sequence[str], figures: bool = True) -> str:
    """Write every policy's samples, counterexamples, summary and figures; return the summary."""
    rows_of = [sample_rows(search) for search in searches]
    write_runs([row for rows in rows_of for row in rows], out)
    summaries, counterexamples = [], []
    for search, rows in zip(searches, rows_of, strict=True):
        summaries.append(_policy_summary(search, rows, bins))
        counterexamples += write_counterexamples(out, search, rows, k_worst)
    config = searches[0].config
    summary = {
        "command": list(command), "scenario": config.scenario,
        "vary": {v.key: v.text for v in config.variations},
        "objectives": [{"metric": k.metric, "worse": "lower" if k.better == "higher"
                        else "higher", "threshold": k.threshold} for k in config.kpis],
        "sampler": config.sampler, "sampler_seed": config.sampler_seed, "seed": config.seed,
        "policies": summaries, "counterexamples": counterexamples,
    }
    files = ["runs.parquet", "runs.csv", SUMMARY_FILE, f"{COUNTEREXAMPLES_DIR}/"]
    if figures:
        from scenarios.results.figures.falsify import plot_best_so_far, plot_failure_maps

        plot_best_so_far(summaries, config.kpis[0], out / "figures" / "best_so_far.png",
                         scenario=config.scenario)
        plot_failure_maps(rows_of, summaries, config, out / "figures" / "failure_map.png")
        files += ["figures/best_so_far.png", "figures/failure_map.png"]
    write_atomic(out / SUMMARY_FILE, json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return _summary_text(summaries, config, out, files)

