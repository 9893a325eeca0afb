"""Paper Fig. 2: the tangent functions of an associated pair of polylines.

See :mod:`scenarios.results.figures` for the conventions every figure follows.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

from scenarios.results.figures.style import (
    checked_vertices,
    count_text,
    figure_title,
    png_path,
    write_png,
)
from semistatic.similarity import similarity, tangent_function

__all__ = ["plot_tangent_histograms"]

STEP_PLOT_MARGIN = 0.08
"""Fraction of the y range left free above and below the tangent functions."""


def _step_values(breaks: np.ndarray, angles: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Return the step function ``(breaks, angles)`` evaluated at ``at``."""
    index = np.searchsorted(breaks, at, side="right") - 1
    return angles[np.clip(index, 0, angles.size - 1)]


def plot_tangent_histograms(
    p0: ArrayLike, p1: ArrayLike, path: str | os.PathLike[str], *, title: str = ""
) -> Path:
    """Draw two polylines beside their tangent functions T(s), as in the paper's Fig. 2.

    The left column shows the polylines (P0 top, P1 bottom) at equal aspect with their
    vertices and start vertex marked (the traversal direction matters). The right column
    shows their tangent step functions over normalised arc length; the bottom one also
    shows T0 rotated by the minimising ``theta_0`` and shades the difference that the
    similarity integrates. The title carries ``s(P0, P1)``.

    Parameters
    ----------
    p0, p1
        ``(N, 2)`` vertex arrays (or :class:`~semistatic.polyline.Polyline`) of non-zero
        length, traversed in the same direction.
    path
        Where to write the PNG (``*.png``; parent folders are created).
    title
        First line of the figure title, in place of the default that says what it shows.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If a polyline is not ``(N, 2)``, not finite, or has zero length.

    Examples
    --------
    >>> import tempfile
    >>> corner = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     plot_tangent_histograms(corner, [[0, 0], [2, 0]], Path(tmp) / "fig2.png").name
    'fig2.png'
    >>> plot_tangent_histograms(corner, [[1.0, 1.0], [1.0, 1.0]], "/tmp/never.png")
    Traceback (most recent call last):
    ...
    ValueError: p1: has zero length (fewer than 2 distinct vertices): no tangent function
    """
    path = png_path(path)
    polylines = [checked_vertices(p, name, 2) for p, name in ((p0, "p0"), (p1, "p1"))]
    tangents = [tangent_function(points) for points in polylines]
    for (_, angles), name in zip(tangents, ("p0", "p1"), strict=True):
        if angles.size == 0:
            raise ValueError(
                f"{name}: has zero length (fewer than 2 distinct vertices): no tangent function"
            )
    score = similarity(polylines[0], polylines[1])
    lengths = [float(np.sum(np.hypot(*np.diff(p, axis=0).T))) for p in polylines]
    (breaks0, angles0), (breaks1, angles1) = tangents
    # theta_0 is the mean of T1 - T0 over s (docs/design.md#detail-4).
    theta_0 = float(np.diff(breaks1) @ angles1 - np.diff(breaks0) @ angles0)

    fig = Figure(figsize=(10.5, 7.0), layout="constrained")
    axes = fig.subplots(2, 2, width_ratios=(1.0, 1.35))
    colors = ("tab:blue", "tab:orange")
    for row, (points, (breaks, angles), length) in enumerate(
        zip(polylines, tangents, lengths, strict=True)
    ):
        shape_ax, tangent_ax = axes[row]
        color = colors[row]
        shape_ax.plot(*points.T, "-o", color=color, lw=2, ms=5, label="edges, vertices")
        shape_ax.plot(*points[0], "s", ms=10, mfc="none", mec="black", mew=1.5, label="start")
        shape_ax.set_aspect("equal", adjustable="datalim")
        shape_ax.margins(0.12)
        vertices = count_text(len(points), "vertex", "vertices")
        shape_ax.set_title(f"P{row}: {vertices}, {length:.2f} m")
        shape_ax.set_xlabel("x [m]")
        shape_ax.set_ylabel("y [m]")
        shape_ax.grid(True, lw=0.3, alpha=0.5)
        shape_ax.legend(loc="best", fontsize=8)

        tangent_ax.stairs(
            np.degrees(angles), breaks, baseline=None, color=color, lw=2, label=f"$T_{row}(s)$"
        )
        tangent_ax.set_xlim(0.0, 1.0)
        tangent_ax.set_xlabel("normalised arc length s")
        tangent_ax.set_ylabel(f"$T_{row}(s)$ [deg]")
        tangent_ax.set_title(f"tangent function of P{row}, {count_text(angles.size, 'edge')}")
        tangent_ax.grid(True, lw=0.3, alpha=0.5)

    union = np.union1d(breaks0, breaks1)
    middle = 0.5 * (union[:-1] + union[1:])
    rotated = np.degrees(_step_values(breaks0, angles0, middle) + theta_0)
    current = np.degrees(_step_values(breaks1, angles1, middle))
    tangent_ax = axes[1, 1]
    tangent_ax.stairs(
        rotated,
        union,
        baseline=None,
        color="0.3",
        ls="--",
        lw=1.5,
        label=f"$T_0(s) + \\theta_0$ ($\\theta_0$ = {math.degrees(theta_0):.1f} deg)",
    )
    tangent_ax.stairs(
        current,
        union,
        baseline=rotated,
        fill=True,
        color=colors[1],
        alpha=0.25,
        label="difference integrated by s",
    )
    # Fills with an array baseline pin the y limits to its minimum (sticky edges): set
    # them here so both step functions keep a margin and neither hides under a spine.
    low = min(rotated.min(), current.min())
    high = max(rotated.max(), current.max())
    margin = STEP_PLOT_MARGIN * max(high - low, 1.0)
    tangent_ax.set_ylim(low - margin, high + margin)
    handles, labels = tangent_ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower right", ncols=3, fontsize=8)

    ratio = max(lengths) / min(lengths)
    fig.suptitle(
        figure_title(
            title,
            "shape similarity from tangent histograms",
            f"s(P0, P1) = {score:.4g}   (length ratio {ratio:.2f}; 0 means the same shape)",
        )
    )
    return write_png(fig, path)
