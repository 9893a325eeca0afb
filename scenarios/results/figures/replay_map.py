"""The polyline map of a replayed real log over its raw laser points.

See :mod:`scenarios.results.figures` for the conventions every figure follows.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

from scenarios.results.figures.style import png_path, write_png

__all__ = ["plot_replay_map"]


def plot_replay_map(
    polylines: Sequence[ArrayLike],
    raw_points: ArrayLike,
    trajectory: ArrayLike,
    path: str | os.PathLike[str],
    *,
    title: str = "",
) -> Path:
    """Draw the replayed polyline map over the raw laser points and the logged trajectory.

    ``polylines`` are ``(N, 2)`` world-frame arrays, ``raw_points`` ``(M, 2)`` end points
    (a subsample of the log), ``trajectory`` ``(K, 2+)`` sensor positions.

    Examples
    --------
    >>> import tempfile, os
    >>> out = os.path.join(tempfile.mkdtemp(), "replay.png")
    >>> plot_replay_map([[[0, 0], [1, 0]]], [[0.5, 0.01]], [[0.5, -1.0]], out).name
    'replay.png'
    """
    path = png_path(path)
    raw = np.asarray(raw_points, dtype=float).reshape(-1, 2)
    track = np.asarray(trajectory, dtype=float)
    track = track.reshape(len(track), -1)[:, :2] if track.size else np.empty((0, 2))
    lines = [np.asarray(line, dtype=float).reshape(-1, 2) for line in polylines]
    fig = Figure(figsize=(9.0, 8.0))
    ax = fig.add_subplot()
    ax.scatter(raw[:, 0], raw[:, 1], s=0.3, color="0.7", label=f"laser points ({len(raw)})",
               rasterized=True)
    if len(track):
        ax.plot(track[:, 0], track[:, 1], color="tab:orange", lw=0.8, label="logged pose")
    for index, line in enumerate(lines):
        ax.plot(line[:, 0], line[:, 1], "-", color="tab:blue", lw=1.2, marker=".", ms=2.5,
                label=f"map polylines ({len(lines)})" if index == 0 else None)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or "polyline map over the raw laser points")
    fig.tight_layout()
    return write_png(fig, path)
