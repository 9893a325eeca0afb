"""Figures of a closed-loop run: paper Fig. 2, 4 and 5, events per lap, policy comparison.

Every function takes plain data (numpy arrays, dicts, a :class:`~worlds.spec.WorldSpec`),
validates it (a ``ValueError`` that names the argument and says what is wrong), draws on
a fresh :class:`matplotlib.figure.Figure` (no pyplot, so no global figure state and no
GUI backend) and writes a PNG atomically: into a temporary file next to ``path`` that
replaces ``path`` only once it is complete. When anything fails, ``path`` keeps what it
held before and no temporary file is left behind.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> with tempfile.TemporaryDirectory() as tmp:
...     out = plot_detection_scores(
...         [{"lap": 1, "precision": 1.0, "recall": 0.5, "f1": 0.67}], Path(tmp) / "scores.png"
...     )
...     out.name, out.stat().st_size > 10_000
('scores.png', True)
"""

from __future__ import annotations

from scenarios.results.figures.campaign import plot_metric_distributions, plot_table1_intervals
from scenarios.results.figures.ekf import plot_ekf_corrections
from scenarios.results.figures.events import plot_run_events
from scenarios.results.figures.laps import plot_detection_scores, plot_lap_times
from scenarios.results.figures.polygonal_map import plot_polygonal_map
from scenarios.results.figures.replay_map import plot_replay_map
from scenarios.results.figures.sharing import plot_sharing_traffic
from scenarios.results.figures.tangents import plot_tangent_histograms

__all__ = [
    "plot_detection_scores",
    "plot_ekf_corrections",
    "plot_lap_times",
    "plot_metric_distributions",
    "plot_polygonal_map",
    "plot_replay_map",
    "plot_run_events",
    "plot_sharing_traffic",
    "plot_table1_intervals",
    "plot_tangent_histograms",
]
