"""Bytes exchanged over time: segment-map messages against 5 cm occupancy grids."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from scenarios.results.figures.style import png_path, write_png

__all__ = ["plot_sharing_traffic"]


def plot_sharing_traffic(
    stamps: Sequence[float],
    message_bytes: Sequence[int],
    grid_bytes: Sequence[int],
    path: str | os.PathLike[str],
    *,
    title: str = "segment maps exchanged",
) -> Path:
    """Plot the cumulative bytes of the messages and of the same areas as 5 cm grids.

    Parameters
    ----------
    stamps
        Publication time of each message (s), non-decreasing.
    message_bytes, grid_bytes
        Each message's encoded size and its segment's grid size (bytes).
    path
        The ``.png`` to write.
    title
        Figure title.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     out = plot_sharing_traffic([1.0, 5.0], [120, 90], [4000, 3000], Path(tmp) / "b.png")
    ...     out.stat().st_size > 5_000
    True
    """
    path = png_path(path)
    stamps = np.asarray(stamps, dtype=float).reshape(-1)
    sizes = np.asarray(message_bytes, dtype=float).reshape(-1)
    grids = np.asarray(grid_bytes, dtype=float).reshape(-1)
    if not (stamps.shape == sizes.shape == grids.shape):
        raise ValueError(
            f"stamps, message_bytes, grid_bytes: need one value per message, got "
            f"{stamps.size}, {sizes.size} and {grids.size}"
        )
    if stamps.size == 0:
        raise ValueError("stamps: no message was published; nothing to plot")
    fig = Figure(figsize=(7.0, 4.0))
    axes = fig.add_subplot()
    axes.step(stamps, np.cumsum(grids) / 1e3, where="post", label="same areas as 5 cm grids")
    axes.step(stamps, np.cumsum(sizes) / 1e3, where="post", label="polyline messages")
    axes.set_yscale("log")
    axes.set_xlabel("simulated time (s)")
    axes.set_ylabel("bytes sent, cumulative (kB)")
    ratio = grids.sum() / max(sizes.sum(), 1.0)
    summary = f"{stamps.size} messages, {sizes.sum():.0f} B; grids {ratio:.0f}x larger"
    axes.set_title(f"{title}\n{summary}")
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(loc="lower right")
    return write_png(fig, path)
