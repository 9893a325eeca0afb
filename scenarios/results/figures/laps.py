"""Beyond the paper: lap times by field policy and detection scores per lap.

See :mod:`scenarios.results.figures` for the conventions every figure follows.
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from scenarios.results.figures.style import figure_title, png_path, write_png

__all__ = ["plot_detection_scores", "plot_lap_times"]

POLICY_COLORS = {"conservative": "tab:gray", "adaptive": "tab:green"}
"""Bar colours of the two speed policies; other policies take the default colour cycle."""

SCORE_NAMES = ("precision", "recall", "f1")

FIGURE_WIDTH_RANGE = (6.5, 16.0)
"""Width (inches) of the per-lap figures: they grow with the laps, within this range."""

MAX_LABELLED_LAPS = 12
"""Up to this many laps, bars carry their values as text."""


def _lap_arrays(
    lap_times: Mapping[str, Sequence[float]], stops: Mapping[str, Sequence[int]] | None
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    if not isinstance(lap_times, Mapping) or not lap_times:
        raise ValueError(
            "lap_times: expected a non-empty dict policy -> lap times in s, "
            f"e.g. {{'conservative': [...], 'adaptive': [...]}}, got {lap_times!r}"
        )
    times = {str(policy): np.asarray(values, dtype=float) for policy, values in lap_times.items()}
    laps = None
    for policy, values in times.items():
        if values.ndim != 1 or values.size == 0:
            raise ValueError(f"lap_times[{policy!r}]: expected a non-empty list of lap times")
        if not np.all(np.isfinite(values)) or np.any(values <= 0.0):
            raise ValueError(f"lap_times[{policy!r}]: lap times must be finite and > 0 s")
        if laps is None:
            laps = values.size
        elif values.size != laps:
            raise ValueError(
                f"lap_times[{policy!r}]: has {values.size} laps but the first policy has "
                f"{laps}; every policy must run the same laps"
            )
    counts: dict[str, np.ndarray] = {}
    for policy, values in (stops or {}).items():
        if policy not in times:
            raise ValueError(f"stops: unknown policy {policy!r}, lap_times has {list(times)}")
        array = np.asarray(values)
        if array.shape != (laps,):
            raise ValueError(
                f"stops[{policy!r}]: expected {laps} stop counts (one per lap), got shape "
                f"{array.shape}"
            )
        as_float = array.astype(float)
        if not np.all(np.isfinite(as_float) & (as_float >= 0) & (as_float == np.round(as_float))):
            raise ValueError(f"stops[{policy!r}]: stop counts must be integers >= 0")
        counts[policy] = array.astype(int)
    return times, counts


def _lap_summary(times: Mapping[str, np.ndarray], stops: Mapping[str, np.ndarray]) -> str:
    """Return the totals, the time saved relative to "conservative" and the stop counts."""
    totals = {policy: float(values.sum()) for policy, values in times.items()}
    summary = "total: " + ", ".join(f"{policy} {total:.1f} s" for policy, total in totals.items())
    if "conservative" in totals:
        reference = totals["conservative"]
        for policy, total in totals.items():
            if policy != "conservative":
                saved = 100.0 * (reference - total) / reference
                verb = "saves" if saved >= 0.0 else "loses"
                summary += f"; {policy} {verb} {abs(saved):.1f}%"
    if stops:
        summary += "\nprotective stops: " + ", ".join(
            f"{policy} {int(values.sum())}" for policy, values in stops.items()
        )
    return summary


def plot_lap_times(
    lap_times: Mapping[str, Sequence[float]],
    path: str | os.PathLike[str],
    *,
    stops: Mapping[str, Sequence[int]] | None = None,
    title: str = "",
) -> Path:
    """Compare the lap times of speed policies as grouped bars per lap.

    The title gives each policy's total and, when a ``"conservative"`` policy is present,
    the time every other policy saves relative to it. Each bar is labelled with its time
    (and stop count) when there are few laps.

    Parameters
    ----------
    lap_times
        Policy name -> lap times in s, the same number of laps for every policy, e.g.
        ``{"conservative": [...], "adaptive": [...]}``.
    path
        Where to write the PNG (``*.png``).
    stops
        Optional policy name -> number of protective stops in each lap.
    title
        First line of the figure title, in place of the default that says what it shows.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If a policy has no laps, a different number of laps, a time that is not > 0, or
        ``stops`` names an unknown policy or has the wrong length.

    Examples
    --------
    >>> import tempfile
    >>> times = {"conservative": [40.0, 41.0], "adaptive": [32.0, 33.5]}
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     plot_lap_times(times, Path(tmp) / "laps.png", stops={"adaptive": [1, 0]}).name
    'laps.png'
    >>> plot_lap_times({"conservative": [40.0, 41.0], "adaptive": [32.0]}, "/tmp/never.png")
    Traceback (most recent call last):
    ...
    ValueError: lap_times['adaptive']: has 1 laps but the first policy has 2; every policy \
must run the same laps
    """
    path = png_path(path)
    times, counts = _lap_arrays(lap_times, stops)
    laps = next(iter(times.values())).size
    policies = list(times)
    totals = {policy: float(values.sum()) for policy, values in times.items()}

    figure_width = float(np.clip(0.55 * laps * len(policies) + 3.0, *FIGURE_WIDTH_RANGE))
    fig = Figure(figsize=(figure_width, 4.8), layout="constrained")
    ax = fig.subplots()
    width = 0.8 / len(policies)
    centres = np.arange(1, laps + 1)
    cycle = itertools.cycle(f"C{index}" for index in range(10))
    for index, policy in enumerate(policies):
        color = POLICY_COLORS.get(policy) or next(cycle)
        offsets = centres + (index - 0.5 * (len(policies) - 1)) * width
        bars = ax.bar(
            offsets,
            times[policy],
            width,
            color=color,
            edgecolor="black",
            lw=0.5,
            label=f"{policy}: total {totals[policy]:.1f} s",
        )
        if laps <= MAX_LABELLED_LAPS:
            labels = [f"{value:.1f}" for value in times[policy]]
            if policy in counts:
                # Only laps with stops say so: a row of "0 stops" would hide the ones that matter.
                labels = [
                    f"{label}\n{stop} stop{'s' if stop != 1 else ''}" if stop else label
                    for label, stop in zip(labels, counts[policy], strict=True)
                ]
            ax.bar_label(bars, labels, fontsize=7, padding=2)
    ax.set_xticks(centres, [f"lap {lap}" for lap in centres])
    ax.set_ylabel("lap time [s]")
    ax.set_ylim(0.0, 1.2 * max(float(values.max()) for values in times.values()))
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    fig.legend(loc="outside lower center", ncols=len(policies), fontsize=8)

    fig.suptitle(figure_title(title, "lap times per speed policy", _lap_summary(times, counts)))
    return write_png(fig, path)


def _score_table(per_lap: Sequence[Mapping[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(per_lap, Mapping) or not per_lap:
        raise ValueError(
            "per_lap: expected a non-empty list of dicts {'lap', 'precision', 'recall', 'f1'}"
        )
    laps, scores = [], []
    for index, row in enumerate(per_lap):
        where = f"per_lap[{index}]"
        if not isinstance(row, Mapping):
            raise ValueError(f"{where}: expected a dict, got {row!r}")
        missing = [key for key in ("lap", *SCORE_NAMES) if key not in row]
        if missing:
            raise ValueError(f"{where}: missing key(s) {missing}")
        lap = row["lap"]
        if isinstance(lap, bool) or not isinstance(lap, int | np.integer):
            raise ValueError(f"{where}.lap: must be an integer, got {lap!r}")
        values = [float(row[name]) for name in SCORE_NAMES]
        for name, value in zip(SCORE_NAMES, values, strict=True):
            # nan is allowed: e.g. precision is undefined in a lap without detections.
            if not math.isnan(value) and not 0.0 <= value <= 1.0:
                raise ValueError(f"{where}.{name}: must be in [0, 1] (or nan), got {value:g}")
        laps.append(int(lap))
        scores.append(values)
    laps_array = np.array(laps)
    unique, repeats = np.unique(laps_array, return_counts=True)
    if np.any(repeats > 1):
        raise ValueError(f"per_lap: lap {int(unique[np.argmax(repeats > 1)])} appears twice")
    order = np.argsort(laps_array)
    return laps_array[order], np.array(scores)[order]


SCORE_COLOURS = {"precision": "tab:blue", "recall": "tab:orange", "f1": "tab:green"}

COUNT_NAMES = ("tp", "fp", "fn", "false_objects_from_people")
"""Optional per-lap counts written under each lap's bars when a row has them."""

COUNT_LABELS = {"tp": "tp", "fp": "fp", "fn": "fn", "false_objects_from_people": "from people"}


def _lap_counts(row: Mapping[str, Any]) -> str:
    """Return a lap's detection counts as a tick label line (empty when the row has none)."""
    return " · ".join(f"{COUNT_LABELS[name]} {int(row[name])}" for name in COUNT_NAMES
                      if name in row)


def plot_detection_scores(
    per_lap: Sequence[Mapping[str, Any]], path: str | os.PathLike[str], *, title: str = ""
) -> Path:
    """Draw semi-static object detection precision, recall and F1 per lap as labelled bars.

    Each lap is a group of three bars, each labelled with its value, so that scores that
    are all 1.0 read as such instead of three lines drawn on top of each other. When the
    rows carry the counts behind the scores (``tp``, ``fp``, ``fn``) and the false objects
    made from people (``false_objects_from_people``), they are written under the lap.

    Parameters
    ----------
    per_lap
        Dicts ``{"lap": int, "precision": float, "recall": float, "f1": float}``, scores in
        ``[0, 1]`` (``nan`` where undefined: no bar, "no score" when all three are), in
        any lap order; optionally with the integer counts :data:`COUNT_NAMES`.
    path
        Where to write the PNG (``*.png``).
    title
        First line of the figure title, in place of the default that says what it shows.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If the list is empty, a key is missing, a lap repeats or a score is outside [0, 1].

    Examples
    --------
    >>> import tempfile
    >>> rows = [{"lap": 2, "precision": 0.9, "recall": 0.8, "f1": 0.85, "tp": 9, "fp": 1},
    ...         {"lap": 3, "precision": 1.0, "recall": 0.9, "f1": 0.95}]
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     plot_detection_scores(rows, Path(tmp) / "scores.png").name
    'scores.png'
    >>> plot_detection_scores([{**rows[0], "recall": 1.2}], "/tmp/never.png")
    Traceback (most recent call last):
    ...
    ValueError: per_lap[0].recall: must be in [0, 1] (or nan), got 1.2
    """
    path = png_path(path)
    laps, scores = _score_table(per_lap)
    rows = {int(row["lap"]): row for row in per_lap}

    figure_width = float(np.clip(1.3 * laps.size + 3.0, *FIGURE_WIDTH_RANGE))
    fig = Figure(figsize=(figure_width, 4.5), layout="constrained")
    ax = fig.subplots()
    centres = np.arange(laps.size)
    width = 0.8 / len(SCORE_NAMES)
    means = {}
    for column, name in enumerate(SCORE_NAMES):
        values = scores[:, column]
        defined = values[~np.isnan(values)]
        means[name] = float(defined.mean()) if defined.size else math.nan
        label = "F1" if name == "f1" else name
        offsets = centres + (column - 0.5 * (len(SCORE_NAMES) - 1)) * width
        bars = ax.bar(offsets, np.nan_to_num(values), width, color=SCORE_COLOURS[name],
                      edgecolor="black", lw=0.5, label=f"{label} (mean {means[name]:.2f})",
                      gid=f"score:{name}")
        if laps.size <= MAX_LABELLED_LAPS:
            ax.bar_label(bars, ["" if math.isnan(v) else f"{v:.2f}" for v in values],
                         fontsize=7, padding=2)
    for index in np.flatnonzero(np.all(np.isnan(scores), axis=1)):
        # Say so where a lap has no score at all, rather than leave a silent gap.
        ax.text(centres[index], 0.5, "no score", rotation=90, ha="center", va="center",
                color="0.5")
    labels = [f"lap {lap}" for lap in laps]
    if laps.size <= MAX_LABELLED_LAPS:
        labels = [f"{label}\n{_lap_counts(rows[lap])}".rstrip() for label, lap in
                  zip(labels, laps, strict=True)]
    ax.set_xticks(centres, labels, fontsize=8)
    # Headroom above 1.0 for the value labels and the legend.
    ax.set_ylim(0.0, 1.3)
    ax.set_yticks(np.linspace(0.0, 1.0, 6))
    ax.set_ylabel("score")
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    ax.legend(loc="upper center", ncols=len(SCORE_NAMES), fontsize=8, framealpha=0.9)
    details = ", ".join(
        f"{'F1' if name == 'f1' else name} {means[name]:.2f}" for name in SCORE_NAMES
    )
    fig.suptitle(
        figure_title(title, "semi-static object detection per lap", f"mean over laps: {details}")
    )
    return write_png(fig, path)
