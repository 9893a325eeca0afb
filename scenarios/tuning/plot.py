"""The figure of a threshold sweep (:mod:`scenarios.commands.tune`), drawn from its summary.

One grid key: each metric against the value (the best value marked, single-seed dots
when there are several seeds); two keys: heatmaps of Table 1, F1 and lap time with the
best cell outlined; three or more: the ranked combinations as bars.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from scenarios.tuning.metrics import METRICS, NEES_TARGET
from scenarios.tuning.points import display_value, settings_text, toml_value

__all__ = ["plot_sweep"]


LINE_PANELS = (
    ("Table 1 mean (cm), lower is better", ("table1_mean_avg_cm", "table1_mean_max_cm")),
    ("detection, higher is better", ("f1", "precision", "recall")),
    ("total lap time (s), lower is better", ("total_lap_time_s",)),
    ("safety events, lower is better", ("collisions", "stops")),
    (f"mean NEES (consistent filter: {NEES_TARGET:g})", ("nees_mean",)),
    ("wall time per run (s)", ("wall_time_s",)),
)
HEATMAP_METRICS = ("table1_mean_avg_cm", "f1", "total_lap_time_s")
BAR_METRICS = ("table1_mean_avg_cm", "f1", "total_lap_time_s")
SCORE_METRICS = ("f1", "precision", "recall")
"""Metrics in [0, 1]: their axes and colour scales are fixed to it, so 0.98 looks good."""
MAX_BARS = 40
"""Combinations drawn in the ranked bar chart of a sweep over three or more keys."""
FIGURE_DPI = 150


def _as_float(value: Any) -> float:
    return float(value) if isinstance(value, int | float) else math.nan


def _numeric_axis(values: Sequence[Any]) -> bool:
    return all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for v in values
    )


def plot_sweep(summary: Mapping[str, Any], path: Path) -> None:
    """Draw the sweep: lines for one grid key, heatmaps for two, ranked bars for more."""
    from matplotlib.figure import Figure

    grid = dict(summary["grid"])
    combinations = list(summary["ranking"])
    best = summary["best"]
    if not grid:
        # A seed-only sweep: the seed is the axis, each run its own combination.
        grid = {"seed": list(summary["seeds"])}
        combinations = [{**row, "settings": {"seed": row["seed"]}} for row in summary["points"]]
        best = None
    title = (
        f"{summary['scenario']}: threshold sweep, {len(summary['points'])} runs of "
        f"{summary['laps']} laps, seed{'s' * (len(summary['seeds']) > 1)} "
        f"{', '.join(map(str, summary['seeds']))}"
    )
    sort_label = METRICS[summary["sort"]].label
    if best is not None:
        title += f"\nbest by {sort_label}: {settings_text(best['settings'])}"
    fig = Figure(layout="constrained")
    if len(grid) == 1:
        _plot_lines(fig, summary, grid, combinations, best)
    elif len(grid) == 2:
        _plot_heatmaps(fig, grid, combinations, best)
        title += " (outlined)" if best is not None else ""
    else:
        _plot_bars(fig, combinations)
        title += f"\ncombinations ranked by {sort_label}, best on top"
    fig.suptitle(title, fontsize=11)
    fig.savefig(path, format="png", dpi=FIGURE_DPI)


def _plot_lines(fig, summary, grid, combinations, best) -> None:
    """One panel per group of metrics against the single grid key's values."""
    import numpy as np

    (key, values), = grid.items()
    numeric = _numeric_axis(values)
    x = np.array(values, dtype=float) if numeric else np.arange(len(values), dtype=float)
    by_value = {toml_value(row["settings"][key]): row for row in combinations}
    # A seed-only sweep has one run per x: there is no seed mean to draw dots around.
    several_seeds = len(summary["seeds"]) > 1 and key != "seed"
    fig.set_size_inches(14.0, 7.5)
    for ax, (heading, names) in zip(fig.subplots(2, 3).flat, LINE_PANELS, strict=True):
        for name in names:
            y = [_as_float(by_value[toml_value(value)][name]) for value in values]
            ax.plot(x, y, marker="o", lw=2.2 if name == names[0] else 1.2,
                    label=METRICS[name].label + (" (seed mean)" if several_seeds else ""))
        if several_seeds:
            # Each run's own value, faint, so the spread behind the seed mean shows.
            for point in summary["points"]:
                value = point["seed"] if key == "seed" else point["settings"][key]
                position = float(value) if numeric else float(values.index(value))
                for name in names:
                    ax.plot(position, _as_float(point[name]), ".", color="0.55", ms=5)
        if best is not None:
            chosen = best["settings"][key]
            ax.axvline(float(chosen) if numeric else float(values.index(chosen)),
                       color="tab:green", lw=1.2, ls=":", label="best")
        if names[0] in SCORE_METRICS:
            ax.set_ylim(-0.03, 1.05)
        ax.set_title(heading, fontsize=10)
        ax.set_xlabel(key)
        if not numeric or len(values) <= 12:
            ax.set_xticks(x, [display_value(value) for value in values],
                          rotation=0 if numeric else 20)
        ax.grid(True, lw=0.3, alpha=0.5)
        ax.legend(fontsize=7)


def _plot_heatmaps(fig, grid, combinations, best) -> None:
    """Heatmaps over the two grid keys (rows: the first key), bright is better."""
    import numpy as np
    from matplotlib.patches import Rectangle

    rows_key, cols_key = grid
    table = {
        (toml_value(row["settings"][rows_key]), toml_value(row["settings"][cols_key])): row
        for row in combinations
    }
    fig.set_size_inches(4.8 * len(HEATMAP_METRICS), 1.8 + 0.5 * max(3, len(grid[rows_key])))
    for ax, name in zip(fig.subplots(1, len(HEATMAP_METRICS)), HEATMAP_METRICS, strict=True):
        cells = np.array([
            [_as_float(table[(toml_value(r), toml_value(c))][name]) for c in grid[cols_key]]
            for r in grid[rows_key]
        ])
        limits = {"vmin": 0.0, "vmax": 1.0} if name in SCORE_METRICS else {}
        # Bright is good in every panel: lower-is-better metrics get the reversed colours.
        cmap = "viridis" if METRICS[name].better == "high" else "viridis_r"
        image = ax.imshow(cells, cmap=cmap, aspect="auto", **limits)
        fig.colorbar(image, ax=ax, shrink=0.85)
        for (i, j), value in np.ndenumerate(cells):
            ax.text(j, i, "n/a" if math.isnan(value) else f"{value:.3g}", ha="center",
                    va="center", fontsize=8, color="white",
                    bbox={"facecolor": "black", "alpha": 0.35, "lw": 0, "pad": 1})
        if best is not None:
            i = grid[rows_key].index(best["settings"][rows_key])
            j = grid[cols_key].index(best["settings"][cols_key])
            ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1.0, 1.0, fill=False, lw=2.5,
                                   edgecolor="tab:red"))
        ax.set_xticks(range(len(grid[cols_key])), [display_value(v) for v in grid[cols_key]])
        ax.set_yticks(range(len(grid[rows_key])), [display_value(v) for v in grid[rows_key]])
        ax.set_xlabel(cols_key)
        ax.set_ylabel(rows_key)
        ax.set_title(f"{METRICS[name].label} (bright is better)", fontsize=10)


def _plot_bars(fig, combinations) -> None:
    """Horizontal bars of the best combinations (three or more grid keys), best on top."""
    import numpy as np

    shown = combinations[:MAX_BARS]
    positions = np.arange(len(shown))
    fig.set_size_inches(14.0, 1.6 + 0.3 * len(shown))
    axes = fig.subplots(1, len(BAR_METRICS), sharey=True)
    for ax, name in zip(axes, BAR_METRICS, strict=True):
        ax.barh(positions, [_as_float(row[name]) for row in shown], color="tab:blue")
        if name in SCORE_METRICS:
            ax.set_xlim(0.0, 1.0)
        ax.set_title(METRICS[name].label, fontsize=10)
        ax.grid(True, axis="x", lw=0.3, alpha=0.5)
    axes[0].set_yticks(positions, [settings_text(row["settings"]) for row in shown], fontsize=7)
    axes[0].invert_yaxis()


# --------------------------------------------------------------------------------------
# Command line

