"""Figures of a campaign: metric distributions per scenario and policy, Table 1 with CIs.

Examples
--------
>>> import tempfile
>>> values = {"table1_cm.mean.avg": {"pal1 adaptive": [1.8, 2.1, 2.4]}}
>>> with tempfile.TemporaryDirectory() as tmp:
...     plot_metric_distributions(values, Path(tmp) / "d.png").name
'd.png'
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from scenarios.results.figures.style import figure_title, png_path, write_png

__all__ = ["plot_metric_distributions", "plot_table1_intervals"]

COLUMNS = 2
"""Panels per row of the distributions figure."""


def plot_metric_distributions(
    values: Mapping[str, Mapping[str, Sequence[float]]],
    path: str | os.PathLike[str],
    *,
    title: str = "",
) -> Path:
    """Draw one panel per metric: a box plot and every run's value, per group.

    ``values`` maps a metric to ``{group label: the runs' values}``; ``None`` and NaN
    values (a run without that figure) are left out and counted in the tick label.

    Examples
    --------
    >>> plot_metric_distributions({}, "/tmp/never.png")
    Traceback (most recent call last):
    ...
    ValueError: values: no metric to draw
    """
    path = png_path(path)
    if not values:
        raise ValueError("values: no metric to draw")
    rows = -(-len(values) // COLUMNS)
    fig = Figure(figsize=(6.0 * COLUMNS, 2.2 + 2.6 * rows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, COLUMNS, squeeze=False)).ravel()
    rng = np.random.default_rng(0)  # the points' sideways jitter only: drawing, not data
    for ax, (metric, groups) in zip(axes, values.items(), strict=False):
        labels, data = [], []
        for label, raw in groups.items():
            clean = np.array([v for v in raw if v is not None], dtype=float)
            clean = clean[np.isfinite(clean)]
            missing = len(raw) - clean.size
            labels.append(label + (f"\n({missing} without)" if missing else ""))
            data.append(clean)
        positions = np.arange(1, len(data) + 1)
        drawn = [d if d.size else np.array([np.nan]) for d in data]
        ax.boxplot(drawn, positions=positions, widths=0.5, showfliers=False)
        for position, points in zip(positions, data, strict=True):
            jitter = rng.uniform(-0.12, 0.12, points.size)
            ax.plot(position + jitter, points, "o", ms=3, alpha=0.6, color="tab:blue")
        ax.set_xticks(positions, labels, rotation=30, ha="right", fontsize=7)
        ax.set_title(metric, fontsize=9)
        ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    for ax in axes[len(values):]:
        ax.set_visible(False)
    runs = max((len(v) for groups in values.values() for v in groups.values()), default=0)
    fig.suptitle(figure_title(title, "metric distributions per scenario and policy",
                              f"box: quartiles and median; points: runs (up to {runs} a group)"))
    return write_png(fig, path)


def plot_table1_intervals(
    means: Mapping[str, Mapping[str, tuple[float, tuple[float, float] | None] | None]],
    paper: Mapping[str, float],
    path: str | os.PathLike[str],
    *,
    title: str = "",
) -> Path:
    """Draw Table 1's mean restricted Hausdorff distance per scenario: ours with 95 % CIs.

    ``means`` maps a scenario to ``{policy: (mean, (low, high) or None) or None}`` (cm);
    ``paper`` the paper's value per scenario, drawn beside them as a black diamond.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     plot_table1_intervals({"pal1": {"conservative": (2.2, (1.9, 2.5))}},
    ...                           {"pal1": 2.46}, Path(tmp) / "t.png").name
    't.png'
    """
    path = png_path(path)
    if not means:
        raise ValueError("means: no scenario to draw")
    policies = list(dict.fromkeys(p for by_policy in means.values() for p in by_policy))
    width = 0.7 / (len(policies) + 1)
    fig = Figure(figsize=(max(5.0, 1.4 * len(means) + 2.0), 4.5), layout="constrained")
    ax = fig.subplots()
    centres = np.arange(len(means))
    for k, policy in enumerate(policies):
        offset = (k - len(policies) / 2) * width
        for centre, by_policy in zip(centres, means.values(), strict=True):
            value = by_policy.get(policy)
            if value is None:
                continue
            mean, interval = value
            error = None if interval is None else [[mean - interval[0]], [interval[1] - mean]]
            ax.errorbar(centre + offset, mean, yerr=error, fmt="o", capsize=4,
                        color=f"C{k}", label=policy if centre == centres[0] else None)
    papers = [(c, paper[name]) for c, name in zip(centres, means, strict=True) if name in paper]
    if papers:
        x, y = zip(*papers, strict=True)
        ax.plot(np.array(x) + len(policies) / 2 * width, y, "kD", label="paper")
    ax.set_xticks(centres, list(means))
    ax.set_ylabel("Table 1 mean avg (cm)")
    ax.set_ylim(bottom=0.0)
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    fig.suptitle(figure_title(title, "Table 1 mean restricted Hausdorff distance",
                              "ours: mean over runs with its 95 % bootstrap CI"))
    return write_png(fig, path)
