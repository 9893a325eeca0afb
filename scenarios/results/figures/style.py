"""Shared style, input checks and the atomic PNG write of :mod:`scenarios.results.figures`.

Examples
--------
>>> print(figure_title("", "Polygonal map", "sim1, 5 laps"))
Polygonal map
sim1, 5 laps
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

__all__ = [
    "DPI",
    "PNG_MODE",
    "checked_poses",
    "checked_vertices",
    "count_text",
    "figure_title",
    "png_path",
    "run_title",
    "write_png",
]

DPI = 150
"""Resolution of every PNG (dots per inch)."""

PNG_MODE = 0o644
"""File mode of a written PNG (``mkstemp`` creates its files private to the owner)."""


def png_path(path: str | os.PathLike[str]) -> Path:
    """Return ``path`` as a ``Path`` or raise if it does not name a ``.png`` file."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"path: figures are PNG files, name it '*.png' (got {str(path)!r})")
    return path


def write_png(fig: Figure, path: Path) -> Path:
    """Save ``fig`` to ``path`` atomically: a temporary file in the same folder, renamed."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # Same directory, so os.replace is a rename on one file system: readers see either
    # the old picture or the whole new one, never a truncated PNG.
    descriptor, temporary = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"
    )
    try:
        with os.fdopen(descriptor, "wb") as stream:
            fig.savefig(stream, format="png", dpi=DPI, bbox_inches="tight")
        os.chmod(temporary, PNG_MODE)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def checked_vertices(polyline: Any, name: str, minimum: int = 1) -> np.ndarray:
    """Return the vertices of a ``Polyline`` or ``(N, 2)`` array as float64, checked."""
    points = np.asarray(getattr(polyline, "points", polyline), dtype=float)
    if points.ndim != 2 or points.shape[1] != 2:
        raise ValueError(f"{name}: expected an (N, 2) array of vertices, got shape {points.shape}")
    if points.shape[0] < minimum:
        raise ValueError(f"{name}: needs at least {minimum} vertices, got {points.shape[0]}")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{name}: vertices must be finite (no nan or inf)")
    return points


def checked_poses(poses: ArrayLike, name: str) -> np.ndarray:
    """Return an ``(N, 2)`` or ``(N, 3)`` pose array as float64, checked."""
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] not in (2, 3) or poses.shape[0] == 0:
        raise ValueError(
            f"{name}: expected a non-empty (N, 3) array of poses (x, y, theta), "
            f"got shape {poses.shape}"
        )
    return poses


def count_text(count: int, noun: str, plural: str = "") -> str:
    """Return ``"1 edge"`` or ``"3 edges"``.

    Examples
    --------
    >>> count_text(1, "edge"), count_text(3, "edge"), count_text(2, "vertex", "vertices")
    ('1 edge', '3 edges', '2 vertices')
    """
    return f"{count} {noun if count == 1 else plural or noun + 's'}"


def run_title(scenario: str, policy: str, seed: int, laps: int) -> str:
    """Return the line that names a run in every figure title: scenario, policy, seed, laps.

    A reader who finds the PNG alone (in a report, a chat, a folder of several runs)
    still knows which run drew it.

    Examples
    --------
    >>> run_title("sim1", "adaptive", 0, 2)
    'sim1 · policy adaptive · seed 0 · 2 laps'
    >>> run_title("pal1", "conservative, adaptive", 3, 1)
    'pal1 · policy conservative, adaptive · seed 3 · 1 lap'
    """
    return f"{scenario} · policy {policy} · seed {seed} · {count_text(laps, 'lap')}"


def figure_title(title: str, kind: str, details: str) -> str:
    """Return a figure title: the caller's ``title`` (or ``kind``) over a line of details."""
    return f"{title or kind}\n{details}"
