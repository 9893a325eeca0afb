"""What a person reads of a search: ranking, best point, Pareto front, importances, curve.

:func:`study_report` summarises a finished study (JSON-ready): every trial with its
parameter values and, per objective, the mean over its runs (every scenario with every
seed), the worst case and the spread;
the ranking by mean and by worst case; the Pareto front (several objectives); parameter
importances (Optuna's fANOVA); the best value after each trial (the search curve); and
the best point as a ready ``--set`` line and a TOML snippet. :func:`format_study` prints
it, :func:`plot_study` draws it.

Examples
--------
>>> print(toml_snippet({"mapper.gate": 0.1, "policy": "adaptive"}))
policy = "adaptive"
<BLANKLINE>
[mapper]
gate = 0.1
<BLANKLINE>
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import optuna

from scenarios.tuning.metrics import METRICS
from scenarios.tuning.points import display_value, toml_value
from scenarios.tuning.search import SearchConfig, finished_trials

__all__ = ["format_study", "plot_study", "set_line", "study_report", "toml_snippet"]

RANKING_ROWS = 15
"""Trials printed in the ranking; every trial is in sweep.csv and study.json."""


def set_line(values: Mapping[str, Any]) -> str:
    """Return the ``--set`` options that reproduce parameter ``values``.

    Examples
    --------
    >>> set_line({"mapper.gate": 0.1, "mapper.outlier_k": 3})
    '--set mapper.gate=0.1 --set mapper.outlier_k=3'
    """
    return " ".join(f"--set {key}={display_value(value)}" for key, value in values.items())


def toml_snippet(values: Mapping[str, Any]) -> str:
    """Return parameter ``values`` as scenario-file TOML (top-level keys, then sections)."""
    top = [f"{key} = {toml_value(value)}" for key, value in values.items() if "." not in key]
    sections: dict[str, list[str]] = {}
    for key, value in values.items():
        if "." in key:
            section, name = key.rsplit(".", 1)
            sections.setdefault(section, []).append(f"{name} = {toml_value(value)}")
    blocks = ["\n".join(top)] if top else []
    blocks += [f"[{section}]\n" + "\n".join(lines) for section, lines in sections.items()]
    return "\n\n".join(blocks) + "\n"


def _order_key(config: SearchConfig, which: str):
    name = config.objectives[0]
    high = METRICS[name].better == "high"

    def key(row: Mapping[str, Any]) -> tuple[bool, float]:
        value = row[which][name]
        if value is None:
            return True, 0.0
        return False, -value if high else value

    return key


def _importances(study: optuna.Study, config: SearchConfig) -> dict[str, float] | None:
    complete = [t for t in study.get_trials(deepcopy=False)
                if t.state == optuna.trial.TrialState.COMPLETE]
    if len(complete) < 2:
        return None
    try:
        # Optuna's default evaluator (PED-ANOVA) asks what makes the target low.
        sign = -1.0 if config.directions()[0] == "maximize" else 1.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            importances = optuna.importance.get_param_importances(
                study, target=lambda trial: sign * trial.values[0],
            )
    except (RuntimeError, ValueError, ZeroDivisionError):
        return None  # e.g. every trial gave the same value: nothing to apportion
    return {key: round(float(value), 4) for key, value in importances.items()}


def study_report(study: optuna.Study, config: SearchConfig) -> dict[str, Any]:
    """Return the study's summary: trials, rankings, front, importances, curve, best.

    The curve is the best mean of the first objective after each finished trial, in
    trial order (how fast the sampler found good points).
    """
    trials = []
    for trial in finished_trials(study):
        trials.append({
            "trial": trial.number,
            "params": {param.key: trial.params[param.key] for param in config.params},
            "mean": trial.user_attrs.get("mean", {}),
            "worst": trial.user_attrs.get("worst", {}),
            "spread": trial.user_attrs.get("spread", {}),
            "seeds": trial.user_attrs.get("seeds", []),
            "runs": trial.user_attrs.get("runs", []),
            "error": trial.user_attrs.get("error"),
            "retried_from": optuna.storages.RetryHeartbeatStaleTrialCallback.retried_trial_number(
                trial
            ),
        })
    by_mean = sorted(trials, key=_order_key(config, "mean"))
    by_worst = sorted(trials, key=_order_key(config, "worst"))
    first = config.objectives[0]
    high = METRICS[first].better == "high"
    curve, best_so_far = [], None
    for row in trials:
        value = row["mean"].get(first)
        if value is not None and (best_so_far is None
                                  or (value > best_so_far if high else value < best_so_far)):
            best_so_far = value
        curve.append(best_so_far)
    front = []
    if len(config.objectives) > 1:
        numbers = {trial.number for trial in study.best_trials}
        front = [row for row in by_mean if row["trial"] in numbers]
    best = next((row for row in by_mean if row["mean"].get(first) is not None), None)
    return {
        "objectives": list(config.objectives),
        "directions": config.directions(),
        "sampler": config.sampler,
        "trials": trials,
        "ranking_by_mean": [row["trial"] for row in by_mean],
        "ranking_by_worst": [row["trial"] for row in by_worst],
        "pareto_front": front,
        "importances": _importances(study, config),
        "curve": curve,
        "best": None if best is None else {
            **best, "set": set_line(best["params"]), "toml": toml_snippet(best["params"]),
        },
    }


def _number(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and math.isfinite(value):
        return f"{value:.4g}"
    return str(value)


def _param_cell(value: Any) -> str:
    # Four significant digits in the table; the --set line and TOML keep the exact value.
    return _number(value) if isinstance(value, float) else display_value(value)


def format_study(report: Mapping[str, Any], out: str | Path) -> str:
    """Return the printed summary: ranking (mean, worst, spread), front, importances, best."""
    objectives = report["objectives"]
    rows = {row["trial"]: row for row in report["trials"]}
    keys = list(report["trials"][0]["params"]) if report["trials"] else []
    header = ["rank", "trial", *keys]
    for name in objectives:
        header += [f"{name} mean", "worst", "spread"]
    table = [header]
    for rank, number in enumerate(report["ranking_by_mean"][:RANKING_ROWS], start=1):
        row = rows[number]
        line = [str(rank), str(number), *(_param_cell(row["params"][k]) for k in keys)]
        for name in objectives:
            line += [_number(row[which].get(name)) for which in ("mean", "worst", "spread")]
        table.append(line)
    widths = [max(len(line[i]) for line in table) for i in range(len(header))]
    text = ["  ".join(cell.rjust(width) for cell, width in zip(line, widths, strict=True))
            for line in table]
    worst_first = report["ranking_by_worst"][:3]
    text.append(f"best worst case ({objectives[0]}): trials {', '.join(map(str, worst_first))}")
    if report["pareto_front"]:
        text.append("Pareto front: trials " + ", ".join(
            str(row["trial"]) for row in report["pareto_front"]))
    if report["importances"]:
        text.append("importance: " + ", ".join(
            f"{key} {value:.2f}" for key, value in report["importances"].items()))
    failed = [row for row in report["trials"] if row["error"]]
    for row in failed:
        text.append(f"trial {row['trial']} failed: {row['error']}")
    best = report["best"]
    if best is not None:
        runs = best["runs"] or [f"seed={seed}" for seed in best["seeds"]]
        text.append(f"best by {objectives[0]} (mean over {len(runs)} run(s): "
                    f"{', '.join(runs)}): "
                    f"{_number(best['mean'][objectives[0]])}")
        text.append(f"  {best['set']}")
        text.append("  as TOML:\n" + "".join(f"    {line}\n" for line in
                                               best["toml"].splitlines()).rstrip())
    text.append(f"results in {out}/ (sweep.csv, sweep.json, study.json, study.db, figures/)")
    return "\n".join(text)


def plot_study(report: Mapping[str, Any], folder: Path) -> None:
    """Draw ``search.png`` (best value per trial) and, with two objectives, ``pareto.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    objectives = report["objectives"]
    first = objectives[0]
    trials = report["trials"]
    figure, axis = plt.subplots(figsize=(6, 4))
    values = [row["mean"].get(first) for row in trials]
    axis.plot(range(1, len(trials) + 1), [v if v is not None else math.nan for v in values],
              "o", color="0.6", label="trial (mean over seeds)")
    axis.plot(range(1, len(trials) + 1),
              [v if v is not None else math.nan for v in report["curve"]], "-", color="C0",
              label="best so far")
    axis.set_xlabel("trials finished")
    axis.set_ylabel(METRICS[first].label)
    axis.set_title(f"{report['sampler']} search")
    axis.legend()
    figure.tight_layout()
    figure.savefig(folder / "search.png", dpi=110)
    plt.close(figure)
    if len(objectives) < 2:
        return
    second = objectives[1]
    figure, axis = plt.subplots(figsize=(6, 4.5))
    points = [(row["mean"].get(first), row["mean"].get(second)) for row in trials]
    points = [p for p in points if None not in p]
    if points:
        axis.scatter(*zip(*points, strict=True), color="0.6", label="trials")
    front = sorted((row["mean"][first], row["mean"][second]) for row in report["pareto_front"])
    if front:
        axis.plot(*zip(*front, strict=True), "o-", color="C3", label="Pareto front")
    axis.set_xlabel(METRICS[first].label)
    axis.set_ylabel(METRICS[second].label)
    axis.set_title("Pareto front (means over seeds)")
    axis.legend()
    figure.tight_layout()
    figure.savefig(folder / "pareto.png", dpi=110)
    plt.close(figure)
