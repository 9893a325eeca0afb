"""A campaign's results: its table, statistics, figures and the summary it prints.

Examples
--------
>>> from scenarios.campaign.plan import CampaignRun
>>> run = CampaignRun("pal1 adaptive sample=0 seed=0", "pal1", "adaptive", 0, 0,
...                   (("mapper.gate", 0.1),), None, "a box in a wall")
>>> row = run_row(run, None, digest=None)
>>> row["status"], row["reason"], row["vary.mapper.gate"]
('rejected', 'a box in a wall', 0.1)
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.campaign.journal import JournalEntry
from scenarios.campaign.plan import CampaignRun
from scenarios.campaign.stats import group_statistics
from scenarios.campaign.table import flatten_metrics, write_runs
from scenarios.process.staging import write_atomic

__all__ = ["FIGURE_METRICS", "STATISTICS_SEED", "SUMMARY_FILE", "run_row", "write_report"]

SUMMARY_FILE = "summary.json"

STATISTICS_SEED = 0
"""Seed of the bootstrap resamples: the same runs give the same intervals."""

FIGURE_METRICS = (
    "table1_cm.mean.avg",
    "detection.f1",
    "localization.rmse_xy_m",
    "safety.total_time_s",
    "safety.min_separation_m.person",
    "safety.min_separation_m.box",
    "safety.stops",
    "safety.min_ttc_s",
)
"""The metrics drawn in ``figures/campaign_distributions.png``."""

TABLE1 = "table1_cm.mean.avg"


def run_row(run: CampaignRun, entry: JournalEntry | None, *, digest: str | None,
            ) -> dict[str, Any]:
    """Return the table row of ``run``: axes, status, drawn values, flattened metrics."""
    metrics, error = entry if entry is not None else (None, None)
    if run.spec is None:
        status, reason = "rejected", run.reason
    elif error is not None:
        status, reason = "error", error
    else:
        status, reason = "ok", None
    row: dict[str, Any] = {"run": run.run, "scenario": run.scenario, "policy": run.policy,
                           "seed": run.seed, "sample": run.sample, "status": status,
                           "reason": reason, "digest": digest}
    row.update({f"vary.{key}": value for key, value in run.values})
    if metrics is not None and status == "ok":
        row.update(flatten_metrics(metrics))
    return row


def _figures(out: Path, rows: Sequence[Mapping[str, Any]], statistics: dict) -> list[str]:
    from scenarios.results.figures.campaign import (
        plot_metric_distributions,
        plot_table1_intervals,
    )
    from scenarios.results.outputs import PAPER_TABLE1

    ok = [row for row in rows if row["status"] == "ok"]
    groups = list(dict.fromkeys((row["scenario"], row["policy"]) for row in ok))
    if not groups:
        return []
    values = {
        metric: {f"{s} {p}": [row.get(metric) for row in ok
                              if (row["scenario"], row["policy"]) == (s, p)] for s, p in groups}
        for metric in FIGURE_METRICS if any(row.get(metric) is not None for row in ok)
    }
    written = []
    if values:
        plot_metric_distributions(values, out / "figures" / "campaign_distributions.png")
        written.append("figures/campaign_distributions.png")
    means: dict[str, dict[str, Any]] = {}
    for group in statistics["groups"]:
        figure = group["metrics"].get(TABLE1)
        if figure and figure["n"]:
            interval = tuple(figure["ci95"]) if figure["ci95"] is not None else None
            means.setdefault(group["scenario"], {})[group["policy"]] = (figure["mean"], interval)
    if means:
        paper = {name: row[0] for name, row in PAPER_TABLE1.items()}
        plot_table1_intervals(means, paper, out / "figures" / "table1_campaign.png")
        written.append("figures/table1_campaign.png")
    return written


def _interval_text(figure: Mapping[str, Any] | None, digits: int = 2) -> str:
    if not figure or not figure["n"]:
        return "-"
    text = f"{figure['mean']:.{digits}f}"
    if figure["ci95"] is not None:
        low, high = figure["ci95"]
        text += f" [{low:.{digits}f}, {high:.{digits}f}]"
    return text


def summary_text(statistics: dict, out: Path, runs: int, figures: Sequence[str]) -> str:
    """Return the lines ``semistatic campaign`` prints: per group the key figures."""
    lines = [f"{'scenario':<20} {'policy':<13} {'ok':>4} {'rej':>4} {'err':>4}  "
             f"{'Table 1 mean avg cm [95% CI]':<28} {'F1':<20} {'least sep. person m':<20}"]
    for group in statistics["groups"]:
        figures_of = group["metrics"]
        counts = group["runs"]
        lines.append(
            f"{group['scenario']:<20} {group['policy']:<13} {counts['ok']:>4} "
            f"{counts['rejected']:>4} {counts['error']:>4}  "
            f"{_interval_text(figures_of.get(TABLE1)):<28} "
            f"{_interval_text(figures_of.get('detection.f1'), 3):<20} "
            f"{_interval_text(figures_of.get('safety.min_separation_m.person')):<20}"
        )
    listing = ", ".join(["runs.parquet", "runs.csv", "summary.json", *figures])
    lines.append(f"{runs} runs; results in {out}/ ({listing})")
    return "\n".join(lines)


def write_report(out: Path, runs: Sequence[CampaignRun], finished: Mapping[str, JournalEntry],
                 manifest: Mapping[str, Any], *, figures: bool = True) -> str:
    """Write the table, ``summary.json`` and the figures of a campaign; return its summary.

    Runs not finished yet (an interrupted campaign) are left out of the table.
    """
    digests = manifest["runs"]
    rows = [run_row(run, finished.get(run.run), digest=digests[run.run]["digest"])
            for run in runs if run.spec is None or run.run in finished]
    write_runs(rows, out)
    statistics = group_statistics(rows, np.random.default_rng(STATISTICS_SEED))
    written = _figures(out, rows, statistics) if figures else []
    summary = {"runs": len(rows), "statistics_seed": STATISTICS_SEED, **statistics}
    write_atomic(out / SUMMARY_FILE, json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return summary_text(statistics, out, len(rows), written)
