"""Beyond the paper: what happened in each lap, over time.

Detection scores are 1.0 in most runs and then say nothing; this figure shows what the
run did instead. One row per lap, time since the lap start on the x axis: the vehicle's
true speed, and markers where a protective stop reached standstill, where an infraction
was recorded and where an object now in the local maps was first seen. Each row's
title gives the lap's time, stops, slowdowns, detection counts and the detection
latency of the boxes moved before it.

See :mod:`scenarios.results.figures` for the conventions every figure follows.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.transforms import blended_transform_factory

from scenarios.results.figures.style import count_text, figure_title, png_path, write_png
from semistatic.colours import FIELD_COLOURS, STATUS_COLOURS, TRUE_COLOUR

__all__ = ["EVENT_GID", "EVENT_KINDS", "SPEED_GID", "lap_speeds", "plot_run_events"]

EVENT_STYLE: dict[str, dict[str, Any]] = {
    # Each kind on its own height of the row (axes fraction), so that events at the same
    # time do not hide each other; colours from semistatic.colours as in every view.
    "stop": {"marker": "v", "color": FIELD_COLOURS["protective"], "y": 0.9,
             "label": "protective stop (at standstill)"},
    "infraction": {"marker": "X", "color": "black", "y": 0.75, "label": "infraction"},
    "new_object": {"marker": "D", "color": STATUS_COLOURS["new"], "y": 0.6,
                   "label": "map object first seen (in the map at the lap's end)"},
}

EVENT_KINDS = tuple(EVENT_STYLE)
"""The kinds of event a row marks."""

EVENT_GID = "event:{kind}"
"""``gid`` of the line holding a row's markers of one kind."""

SPEED_GID = "speed"
"""``gid`` of a row's speed line."""

MAX_LABELLED_EVENTS = 8
"""Up to this many events of one kind in a lap, each marker carries its label."""

ROW_HEIGHT = 1.9
"""Height (inches) of one lap's row."""


def lap_speeds(stamps: Sequence[float], poses: Any) -> tuple[np.ndarray, np.ndarray]:
    """Return the times and speeds (m/s) between consecutive ``(x, y, ...)`` poses.

    Each speed is the distance between two poses over their time step, placed at the
    middle of the step; steps of zero duration are left out.

    Examples
    --------
    >>> t, v = lap_speeds([0.0, 1.0, 2.0], [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.5, 2.0, 0.0]])
    >>> t.tolist(), v.tolist()
    ([0.5, 1.5], [0.5, 2.0])
    """
    stamps = np.asarray(stamps, dtype=float)
    xy = np.asarray(poses, dtype=float).reshape(len(stamps), -1)[:, :2]
    dt = np.diff(stamps)
    moved = dt > 0.0
    speeds = np.hypot(*np.diff(xy, axis=0).T)[moved] / dt[moved]
    return (0.5 * (stamps[1:] + stamps[:-1]))[moved], speeds


def _checked_laps(laps: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    if isinstance(laps, Mapping) or not laps:
        raise ValueError("laps: expected a non-empty list of dicts {'lap', 'duration_s', ...}")
    seen = set()
    for index, row in enumerate(laps):
        if not isinstance(row, Mapping) or "lap" not in row or "duration_s" not in row:
            raise ValueError(f"laps[{index}]: expected a dict with 'lap' and 'duration_s'")
        if not math.isfinite(float(row["duration_s"])) or float(row["duration_s"]) < 0.0:
            raise ValueError(f"laps[{index}].duration_s: must be finite and >= 0")
        if row["lap"] in seen:
            raise ValueError(f"laps: lap {row['lap']} appears twice")
        seen.add(row["lap"])
    return sorted(laps, key=lambda row: row["lap"])


def _checked_events(events: Sequence[Mapping[str, Any]], laps: set) -> list[Mapping[str, Any]]:
    for index, event in enumerate(events):
        where = f"events[{index}]"
        if not isinstance(event, Mapping) or any(k not in event for k in ("lap", "t", "kind")):
            raise ValueError(f"{where}: expected a dict with 'lap', 't' and 'kind'")
        if event["kind"] not in EVENT_STYLE:
            raise ValueError(f"{where}.kind: must be one of {EVENT_KINDS}, got {event['kind']!r}")
        if event["lap"] not in laps:
            raise ValueError(f"{where}.lap: lap {event['lap']} is not in laps")
        if not math.isfinite(float(event["t"])):
            raise ValueError(f"{where}.t: must be finite")
    return list(events)


def _row_title(row: Mapping[str, Any]) -> str:
    """Return a lap's row title: its time, stops, slowdowns, detection and latencies."""
    parts = [f"lap {row['lap']}: {row['duration_s']:.1f} s"]
    if "completed" in row and not row["completed"]:
        parts[0] += " (did not reach the end)"
    if "stops" in row:
        parts.append(f"{count_text(int(row['stops']), 'stop')}"
                     + (f" ({row['stopped_time_s']:.1f} s)" if "stopped_time_s" in row else ""))
    if "slowdowns" in row:
        parts.append(f"{count_text(int(row['slowdowns']), 'slowdown')}"
                     + (f" ({row['slowed_time_s']:.1f} s in warning)"
                        if "slowed_time_s" in row else ""))
    detection = row.get("detection") or {}
    if all(key in detection for key in ("tp", "fp", "fn")):
        parts.append(f"tp {detection['tp']} fp {detection['fp']} fn {detection['fn']}")
    if row.get("false_objects_from_people"):
        parts.append(f"{row['false_objects_from_people']} from people")
    for box, scans in (row.get("latencies") or {}).items():
        parts.append(f"{box} mapped {count_text(scans, 'scan')} after first seen"
                     if scans is not None else f"{box} seen, not mapped")
    return " · ".join(parts)


def plot_run_events(
    laps: Sequence[Mapping[str, Any]],
    path: str | os.PathLike[str],
    *,
    speeds: Mapping[int, tuple[Any, Any]] | None = None,
    events: Sequence[Mapping[str, Any]] = (),
    title: str = "",
) -> Path:
    """Draw each lap's speed over time with its stops, infractions and new map objects.

    One row per lap, the time since the lap start on a shared x axis. Reading a row:
    the black line is the vehicle's true speed (dips are slowdowns in the warning field,
    drops to zero protective stops); red triangles mark protective stops when the vehicle
    stood still, black crosses infractions (labelled with their kind), blue diamonds
    the objects of the final local map first seen in that lap (labelled with their
    segment and id when few). The row's title sums the lap up (:func:`_row_title`).

    Parameters
    ----------
    laps
        One dict per lap: ``lap`` (int) and ``duration_s`` required; ``completed``,
        ``stops``, ``stopped_time_s``, ``slowdowns``, ``slowed_time_s``, ``detection``
        (with ``tp``, ``fp``, ``fn``), ``false_objects_from_people`` and ``latencies``
        (box -> safety scans or ``None``) go into the row's title when present.
    path
        Where to write the PNG (``*.png``).
    speeds
        Lap -> ``(times since the lap start, speeds in m/s)``; laps without are drawn
        without a speed line.
    events
        Dicts ``{"lap", "t" (s since the lap start), "kind" (one of EVENT_KINDS),
        "label" (optional)}``.
    title
        First line of the figure title, in place of the default that says what it shows.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If ``laps`` is empty or malformed, a lap repeats, or an event has an unknown kind,
        an unknown lap or no finite time.

    Examples
    --------
    >>> import tempfile
    >>> laps = [{"lap": 1, "duration_s": 20.0, "stops": 1}, {"lap": 2, "duration_s": 18.0}]
    >>> events = [{"lap": 1, "t": 7.5, "kind": "stop"},
    ...           {"lap": 2, "t": 3.0, "kind": "new_object", "label": "aisle#4"}]
    >>> speeds = {1: ([0.0, 10.0, 20.0], [0.0, 0.5, 0.5])}
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     plot_run_events(laps, Path(tmp) / "events.png", speeds=speeds, events=events).name
    'events.png'
    >>> plot_run_events(laps, "/tmp/never.png", events=[{"lap": 3, "t": 1.0, "kind": "stop"}])
    Traceback (most recent call last):
    ...
    ValueError: events[0].lap: lap 3 is not in laps
    """
    path = png_path(path)
    rows = _checked_laps(laps)
    events = _checked_events(events, {row["lap"] for row in rows})
    speeds = {lap: (np.asarray(t, dtype=float), np.asarray(v, dtype=float))
              for lap, (t, v) in (speeds or {}).items()}
    for lap, (t, v) in speeds.items():
        if t.shape != v.shape or t.ndim != 1:
            raise ValueError(f"speeds[{lap}]: times and speeds must be 1-D of the same length")

    fig = Figure(figsize=(10.0, ROW_HEIGHT * len(rows) + 1.4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0])
    top = max([float(v.max()) for _, v in speeds.values() if v.size] + [0.0])
    longest = max(float(row["duration_s"]) for row in rows)
    counts = dict.fromkeys(EVENT_KINDS, 0)
    for ax, row in zip(axes, rows, strict=True):
        lap = row["lap"]
        if lap in speeds and speeds[lap][0].size:
            ax.plot(*speeds[lap], color=TRUE_COLOUR, lw=1.0, gid=SPEED_GID)
        ax.axvline(float(row["duration_s"]), color="0.6", lw=0.8, ls=":")
        # Events sit at fixed heights of the row (axes fraction), at their time (data).
        where = blended_transform_factory(ax.transData, ax.transAxes)
        for kind, style in EVENT_STYLE.items():
            mine = [event for event in events if event["lap"] == lap and event["kind"] == kind]
            counts[kind] += len(mine)
            if not mine:
                continue
            times = [float(event["t"]) for event in mine]
            ax.plot(times, [style["y"]] * len(mine), ls="", marker=style["marker"], ms=6,
                    color=style["color"], transform=where, gid=EVENT_GID.format(kind=kind),
                    zorder=5, clip_on=False)
            if len(mine) <= MAX_LABELLED_EVENTS:
                for index, (time, event) in enumerate(zip(times, mine, strict=True)):
                    if event.get("label"):
                        # Labels of events close in time step up and down, not on each other.
                        ax.annotate(str(event["label"]), (time, style["y"]), xycoords=where,
                                    textcoords="offset points", xytext=(4, 2 - 8 * (index % 3)),
                                    fontsize=6, color=style["color"])
        ax.set_title(_row_title(row), fontsize=8, loc="left")
        ax.set_ylim(0.0, 1.25 * top if top > 0.0 else 1.0)
        ax.set_ylabel("speed [m/s]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, lw=0.3, alpha=0.5)
    axes[-1].set_xlim(0.0, 1.02 * longest if longest > 0.0 else 1.0)
    axes[-1].set_xlabel("time since the lap start [s]")
    handles = [Line2D([], [], color=TRUE_COLOUR, lw=1.0, label="true speed")]
    handles += [Line2D([], [], ls="", marker=style["marker"], color=style["color"],
                       label=style["label"]) for style in EVENT_STYLE.values()]
    fig.legend(handles=handles, loc="outside lower center", ncols=2, fontsize=8)
    details = ", ".join([count_text(counts["stop"], "protective stop"),
                         count_text(counts["infraction"], "infraction"),
                         count_text(counts["new_object"], "map object") + " first seen"])
    fig.suptitle(figure_title(title, "events per lap", details))
    return write_png(fig, path)
