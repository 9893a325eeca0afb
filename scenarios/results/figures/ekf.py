"""Paper Fig. 5: the EKF's corrections within their sigma bounds.

See :mod:`scenarios.results.figures` for the conventions every figure follows.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from numpy.typing import ArrayLike

from scenarios.results.figures.style import count_text, figure_title, png_path, write_png
from scenarios.results.metrics import ekf_correction_metrics
from semistatic.frames import wrap_angle

__all__ = ["plot_ekf_corrections"]

EKF_STATES = ("x", "y", "θ")
EKF_UNITS = ("mm", "mm", "mrad")
EKF_SCALE = 1000.0
"""Metres to millimetres and radians to milliradians: EKF corrections are that small."""

EKF_YLIM_SIGMA_PERCENTILE = 90.0
"""The y range covers the 3 sigma bound up to this percentile of time, so the large
uncertainty right after the initial triangulation does not squash the rest of the run."""

EKF_YLIM_MARGIN = 1.15

EKF_TYPICAL_PERCENTILE = 95.0
"""Percentile of the absolute corrections taken as their typical reach: robust to up to 5%
outliers, and Gaussian corrections stay within 2.7 times it even over 100,000 updates."""

EKF_EDGE_MARKER = 0.93
"""Where (fraction of the y limit) the markers of corrections beyond the axis sit."""

EKF_OUTLIER_FACTOR = 4.0
"""A correction beyond this many times the typical reach (a re-initialisation, a bad
association) is drawn as a marker on the axis edge instead of stretching the y range."""


def _ekf_arrays(
    stamps: ArrayLike, corrections: ArrayLike, sigmas: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    stamps = np.asarray(stamps, dtype=float)
    corrections = np.asarray(corrections, dtype=float)
    sigmas = np.asarray(sigmas, dtype=float)
    if stamps.ndim != 1 or stamps.size == 0:
        raise ValueError(f"stamps: expected a non-empty (N,) array of times, got {stamps.shape}")
    count = stamps.size
    if corrections.shape != (count, 3):
        raise ValueError(
            f"corrections: expected shape ({count}, 3) (one (dx, dy, dtheta) per stamp), "
            f"got {corrections.shape}"
        )
    if sigmas.shape == (count, 3, 3):
        # Covariance matrices: the sigma bounds are the roots of their diagonals.
        sigmas = np.sqrt(np.diagonal(sigmas, axis1=1, axis2=2))
    elif sigmas.shape != (count, 3):
        raise ValueError(
            f"sigmas: expected shape ({count}, 3) standard deviations or ({count}, 3, 3) "
            f"covariances, one per stamp, got {sigmas.shape}"
        )
    for name, array in (("stamps", stamps), ("corrections", corrections), ("sigmas", sigmas)):
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{name}: must be finite (no nan or inf)")
    if np.any(np.diff(stamps) < 0.0):
        index = int(np.argmax(np.diff(stamps) < 0.0)) + 1
        raise ValueError(
            f"stamps: must not decrease, but stamps[{index}] = {stamps[index]:g} s comes "
            f"after {stamps[index - 1]:g} s"
        )
    if np.any(sigmas < 0.0):
        raise ValueError("sigmas: standard deviations must be >= 0")
    corrections = corrections.copy()
    corrections[:, 2] = wrap_angle(corrections[:, 2])
    return stamps, corrections, sigmas


def _correction_axis_limit(correction: np.ndarray, sigma: np.ndarray) -> tuple[float, np.ndarray]:
    """Return the symmetric y limit of a correction panel and which corrections exceed it.

    The limit covers every correction and the 3 sigma bound for most of the run, except
    outliers (over ``EKF_OUTLIER_FACTOR`` times the typical reach), which are flagged.
    """
    size = np.abs(correction)
    bound = 3.0 * float(np.percentile(sigma, EKF_YLIM_SIGMA_PERCENTILE))
    typical = max(float(np.percentile(size, EKF_TYPICAL_PERCENTILE)), bound)
    # typical == 0 (nearly all corrections exactly zero) makes no scale to call anything
    # an outlier against.
    outside = size > EKF_OUTLIER_FACTOR * typical if typical > 0.0 else np.zeros(size.shape, bool)
    reach = max(float(size[~outside].max(initial=0.0)), bound)
    return EKF_YLIM_MARGIN * reach, outside


def plot_ekf_corrections(
    stamps: ArrayLike,
    corrections: ArrayLike,
    sigmas: ArrayLike,
    path: str | os.PathLike[str],
    *,
    reinitialized: ArrayLike | None = None,
    title: str = "",
) -> Path:
    """Draw the EKF's corrections in x, y, theta within their sigma bounds (paper Fig. 5).

    Three stacked panels share the time axis: each update's correction (posterior minus
    prior) as a stem, the ±1 sigma band shaded and the ±3 sigma bounds dashed. x and y
    are in mm, theta in mrad. Each panel states the RMS correction and how many
    corrections fall within ±1 and ±3 sigma. Re-localisations (``reinitialized``: the
    jump of the filter re-initialised by triangulation when the robot was carried back
    to the start) are no corrections: they are drawn as dotted vertical lines only and
    left out of the statistics and the y range. A few corrections far larger than the
    rest (a bad association) are drawn as red triangles on the axis edge, so that they
    do not flatten the others; the panel says how far they reach.

    Parameters
    ----------
    stamps
        ``(N,)`` update times in s, non-decreasing.
    corrections
        ``(N, 3)`` posterior minus prior ``(dx, dy, dtheta)`` in m and rad (dtheta is wrapped).
    sigmas
        ``(N, 3)`` standard deviations (m, m, rad) of the posterior, or ``(N, 3, 3)`` covariances.
    path
        Where to write the PNG (``*.png``).
    reinitialized
        Optional ``(N,)`` booleans: the updates where the filter was re-initialised (from
        triangulation); drawn as dotted vertical lines.
    title
        First line of the figure title, in place of the default that says what it shows.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If the lengths differ, an array has the wrong shape or is not finite, the stamps
        decrease or a sigma is negative.

    Examples
    --------
    >>> import tempfile
    >>> rng = np.random.default_rng(0)
    >>> stamps = np.arange(100) * 0.1
    >>> sigmas = np.tile([0.004, 0.004, 0.01], (100, 1))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     out = plot_ekf_corrections(stamps, rng.normal(0.0, sigmas), sigmas, Path(tmp) / "f.png")
    ...     out.name
    'f.png'
    >>> plot_ekf_corrections(stamps, np.zeros((99, 3)), sigmas, "/tmp/never.png")
    Traceback (most recent call last):
    ...
    ValueError: corrections: expected shape (100, 3) (one (dx, dy, dtheta) per stamp), \
got (99, 3)
    """
    path = png_path(path)
    stamps, corrections, sigmas = _ekf_arrays(stamps, corrections, sigmas)
    restarts = np.zeros(stamps.size, dtype=bool)
    if reinitialized is not None:
        restarts = np.asarray(reinitialized)
        if restarts.shape != stamps.shape or restarts.dtype != bool:
            raise ValueError(
                f"reinitialized: expected ({stamps.size},) booleans (one per stamp), got "
                f"{restarts.dtype} of shape {restarts.shape}"
            )
    statistics = ekf_correction_metrics(corrections, sigmas, restarts)
    # Re-localisations are drawn as lines, not as corrections (they are jumps of metres).
    kept = ~restarts
    restart_stamps = stamps[restarts]
    stamps, corrections, sigmas = stamps[kept], corrections[kept] * EKF_SCALE, sigmas[kept]
    sigmas = sigmas * EKF_SCALE
    if stamps.size == 0:
        raise ValueError("corrections: every update is a re-initialisation; nothing to plot")

    fig = Figure(figsize=(10.0, 8.0), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    clipped_any = False
    for column, (ax, state, unit) in enumerate(zip(axes, EKF_STATES, EKF_UNITS, strict=True)):
        correction, sigma = corrections[:, column], sigmas[:, column]
        ax.fill_between(stamps, -sigma, sigma, color="tab:blue", alpha=0.2, lw=0, label="±1σ")
        ax.plot(stamps, 3.0 * sigma, "--", color="tab:blue", lw=1.0, label="±3σ")
        ax.plot(stamps, -3.0 * sigma, "--", color="tab:blue", lw=1.0)
        ax.vlines(stamps, 0.0, correction, color="0.45", lw=0.6)
        ax.plot(stamps, correction, ".", color="black", ms=3, label="correction")
        ax.axhline(0.0, color="black", lw=0.5)
        for stamp in restart_stamps:
            ax.axvline(stamp, color="tab:purple", ls=":", lw=1.2)
        size = np.abs(correction)
        limit, outside = _correction_axis_limit(correction, sigma)
        largest = float(size.max())
        note = ""
        if np.any(outside):
            clipped_any = True
            for sign, marker in ((1.0, "^"), (-1.0, "v")):
                side = outside & (np.sign(correction) == sign)
                edge = np.full(int(side.sum()), EKF_EDGE_MARKER * sign * limit)
                ax.plot(stamps[side], edge, marker, color="tab:red", ms=6)
            note = f"; {count_text(int(outside.sum()), 'correction')} beyond the axis, "
            note += f"up to {largest:.3g} {unit}"
        if limit > 0.0:
            ax.set_ylim(-limit, limit)
        inside_1 = statistics["within_1_sigma"][column]
        inside_3 = statistics["within_3_sigma"][column]
        rms = statistics["rms"][column] * EKF_SCALE
        # Above the panel, not inside it: a text box would hide the early, large corrections.
        ax.set_title(
            f"Δ{state}: RMS {rms:.3g} {unit}; {inside_1:.1%} within ±1σ, "
            f"{inside_3:.1%} within ±3σ{note}",
            loc="left",
            fontsize=8,
        )
        ax.set_ylabel(f"Δ{state} [{unit}]")
        ax.grid(True, lw=0.3, alpha=0.5)
    handles = [
        Patch(color="tab:blue", alpha=0.2, label="±1σ"),
        Line2D([], [], color="tab:blue", ls="--", lw=1.0, label="±3σ"),
        Line2D([], [], color="black", marker=".", ls="", label="correction"),
    ]
    if restart_stamps.size:
        label = f"re-localised ({restart_stamps.size}, left out)"
        handles.append(Line2D([], [], color="tab:purple", ls=":", label=label))
    if clipped_any:
        handles.append(Line2D([], [], color="tab:red", marker="^", ls="", label="beyond the axis"))
    fig.legend(handles=handles, loc="outside lower center", fontsize=8, ncols=len(handles))
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(
        figure_title(
            title,
            "EKF corrections (posterior − prior) within σ bounds",
            f"{count_text(stamps.size, 'update')} over {stamps[-1] - stamps[0]:.1f} s",
        )
    )
    return write_png(fig, path)
