"""Figures of a falsification: best-so-far against simulations, and failure-region maps.

Examples
--------
>>> import tempfile
>>> from scenarios.falsify.objectives import Objective
>>> kpi = Objective("safety.min_separation_m.person", "higher", 0.0)
>>> summaries = [{"policy": "adaptive", "best_so_far": [0.5, 0.2, 0.0], "sampler": "tpe"}]
>>> with tempfile.TemporaryDirectory() as tmp:
...     plot_best_so_far(summaries, kpi, Path(tmp) / "b.png").name
'b.png'
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from scenarios.results.figures.style import png_path, write_png

__all__ = ["plot_best_so_far", "plot_failure_maps"]


def plot_best_so_far(summaries: Sequence[Mapping[str, Any]], kpi,
                     path: str | os.PathLike[str], *, scenario: str = "") -> Path:
    """Draw each policy's worst objective value so far against the simulations run.

    The threshold is a dashed line: a curve that crosses it found a violation.
    """
    path = png_path(path)
    fig = Figure(figsize=(7.0, 4.0), layout="constrained")
    ax = fig.subplots()
    for summary in summaries:
        values = np.array([np.nan if v is None else v for v in summary["best_so_far"]],
                          dtype=float)
        ax.step(np.arange(1, values.size + 1), values, where="post", label=summary["policy"])
    ax.axhline(kpi.threshold, color="crimson", linestyle="--", linewidth=1.0,
               label=f"violation threshold {kpi.threshold:g}")
    ax.set_xlabel("simulations")
    ax.set_ylabel(f"worst {kpi.metric} so far")
    sampler = summaries[0].get("sampler", "") if summaries else ""
    ax.set_title(f"{scenario or 'Falsification'}, {sampler} search: worst {kpi.metric} so far")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    return write_png(fig, path)


def plot_failure_maps(rows_of: Sequence[Sequence[Mapping[str, Any]]],
                      summaries: Sequence[Mapping[str, Any]], config,
                      path: str | os.PathLike[str]) -> Path:
    """Draw, per policy, every sample over its two most important varied keys.

    Colour is the first objective's value; violations are red crosses; grey lines are
    the coverage bins. With one varied key, the objective against it.
    """
    path = png_path(path)
    kpi = config.kpis[0]
    panels = len(summaries)
    fig = Figure(figsize=(5.2 * panels, 4.4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, panels, squeeze=False)).ravel()
    values = [row.get(f"objective.{kpi.metric}") for rows in rows_of for row in rows
              if row["status"] == "ok"]
    finite = [v for v in values if v is not None]
    low, high = (min(finite), max(finite)) if finite else (0.0, 1.0)
    scatter = None
    for ax, rows, summary in zip(axes, rows_of, summaries, strict=True):
        ok = [row for row in rows if row["status"] == "ok"
              and row.get(f"objective.{kpi.metric}") is not None]
        keys = summary["importance"][:2]
        x = [row[f"vary.{keys[0]}"] for row in ok]
        c = np.array([row[f"objective.{kpi.metric}"] for row in ok], dtype=float)
        hit = np.array([bool(row["violation"]) for row in ok])
        y = [row[f"vary.{keys[1]}"] for row in ok] if len(keys) == 2 else c
        if ok:
            scatter = ax.scatter(np.array(x)[~hit], np.array(y)[~hit], c=c[~hit], s=22,
                                 cmap="viridis", vmin=low, vmax=high, edgecolors="none")
            ax.scatter(np.array(x)[hit], np.array(y)[hit], marker="x", color="crimson", s=40,
                       label=f"violation ({int(hit.sum())})")
        cover = summary["coverage"]
        _bin_lines(ax.axvline, ax.set_xlim, config, keys[0], cover["bins"])
        if len(keys) == 2:
            _bin_lines(ax.axhline, ax.set_ylim, config, keys[1], cover["bins"])
        ax.set_xlabel(keys[0])
        ax.set_ylabel(keys[1] if len(keys) == 2 else kpi.metric)
        grid = np.array(cover["pair"]["samples"] if "pair" in cover
                        else [cover["keys"][keys[0]]["samples"]])
        ax.set_title(f"{config.scenario}, {summary['policy']}: {summary['violations']} of "
                     f"{summary['ok']} violate\n({int((grid > 0).sum())}/{grid.size} bins of "
                     "this map sampled)", fontsize="medium")
        if hit.any():
            ax.legend(fontsize="small", loc="best")
    if scatter is not None:
        fig.colorbar(scatter, ax=list(axes), label=kpi.metric, shrink=0.9)
    return write_png(fig, path)


def _bin_lines(draw, limits, config, key: str, bins: int) -> None:
    """Draw the inner bin edges of a range and show the whole range (unexplored parts too)."""
    variation = next(v for v in config.variations if v.key == key)
    if variation.distribution == "choice":
        return
    low, high = map(float, variation.arguments)
    for edge in np.linspace(low, high, bins + 1)[1:-1]:
        draw(edge, color="grey", linewidth=0.5, alpha=0.5)
    limits(low, high)
