"""Figures of a closed-loop run: paper Fig. 2, 4 and 5 and the speed-policy comparison.

Every function takes plain data (numpy arrays, dicts, a :class:`~worlds.spec.WorldSpec`),
validates it (a ``ValueError`` that names the argument and says what is wrong), draws on
a fresh :class:`matplotlib.figure.Figure` (no pyplot, so no global figure state and no
GUI backend) and writes a PNG atomically: into a temporary file next to ``path`` that
replaces ``path`` only once it is complete. When anything fails, ``path`` keeps what it
held before and no temporary file is left behind.

Examples
--------
>>> import tempfile
>>> with tempfile.TemporaryDirectory() as tmp:
...     out = plot_detection_scores(
...         [{"lap": 1, "precision": 1.0, "recall": 0.5, "f1": 0.67}], Path(tmp) / "scores.png"
...     )
...     out.name, out.stat().st_size > 10_000
('scores.png', True)
"""

from __future__ import annotations

import itertools
import math
import os
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator
from numpy.typing import ArrayLike

from robots.path import SplinePath
from semistatic.frames import wrap_angle
from semistatic.similarity import similarity, tangent_function
from worlds.plot import draw_box, draw_posts, draw_walls, figure_size
from worlds.spec import WorldSpec

__all__ = [
    "plot_detection_scores",
    "plot_ekf_corrections",
    "plot_lap_times",
    "plot_polygonal_map",
    "plot_replay_map",
    "plot_tangent_histograms",
]

DPI = 150
"""Resolution of every PNG (dots per inch)."""

PNG_MODE = 0o644
"""File mode of a written PNG (``mkstemp`` creates its files private to the owner)."""

MAP_STATUSES = ("confirmed", "new", "blank")
"""Life-cycle states of a map polyline, in the order the legend lists them."""

STATUS_STYLE: dict[str, dict[str, Any]] = {
    # Confirmed polylines are the bulk of a map; new ones (semi-static objects just seen)
    # and blank ones (missed while they should have been visible) are what a reader looks
    # for, so they get the loud colours and blank ones a dashed, hollow look.
    "confirmed": {"color": "tab:blue", "lw": 1.8, "ls": "-", "mfc": "tab:blue", "zorder": 8},
    "new": {"color": "tab:red", "lw": 2.2, "ls": "-", "mfc": "tab:red", "zorder": 9},
    "blank": {"color": "tab:gray", "lw": 1.6, "ls": "--", "mfc": "white", "zorder": 7},
}

MAP_COLORS = {
    "wall": "0.82",
    "path": "0.45",
    "post": "0.25",
    "trajectory": "black",
    "estimate": "tab:orange",
}

PATH_SAMPLE_SPACING = 0.02
"""Spacing (m) of the points that draw the planned spline path."""

POLICY_COLORS = {"conservative": "tab:gray", "adaptive": "tab:green"}
"""Bar colours of the two speed policies; other policies take the default colour cycle."""

STEP_PLOT_MARGIN = 0.08
"""Fraction of the y range left free above and below the tangent functions."""

SCORE_NAMES = ("precision", "recall", "f1")

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

FIGURE_WIDTH_RANGE = (6.5, 16.0)
"""Width (inches) of the per-lap figures: they grow with the laps, within this range."""

MAX_LABELLED_LAPS = 12
"""Up to this many laps, bars carry their values as text."""


# --------------------------------------------------------------------------------------
# Input checks and the atomic write


def _output_path(path: str | os.PathLike[str]) -> Path:
    """Return ``path`` as a ``Path`` or raise if it does not name a ``.png`` file."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"path: figures are PNG files, name it '*.png' (got {str(path)!r})")
    return path


def _write_png(fig: Figure, path: Path) -> Path:
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


def _polyline_points(polyline: Any, name: str, minimum: int = 1) -> np.ndarray:
    """Return the vertices of a ``Polyline`` or ``(N, 2)`` array as float64, checked."""
    points = np.asarray(getattr(polyline, "points", polyline), dtype=float)
    if points.ndim != 2 or points.shape[1] != 2:
        raise ValueError(f"{name}: expected an (N, 2) array of vertices, got shape {points.shape}")
    if points.shape[0] < minimum:
        raise ValueError(f"{name}: needs at least {minimum} vertices, got {points.shape[0]}")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{name}: vertices must be finite (no nan or inf)")
    return points


def _poses(poses: ArrayLike, name: str) -> np.ndarray:
    """Return an ``(N, 2)`` or ``(N, 3)`` pose array as float64, checked."""
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] not in (2, 3) or poses.shape[0] == 0:
        raise ValueError(
            f"{name}: expected a non-empty (N, 3) array of poses (x, y, theta), "
            f"got shape {poses.shape}"
        )
    return poses


def _counted(count: int, noun: str, plural: str = "") -> str:
    """Return ``"1 edge"`` or ``"3 edges"``."""
    return f"{count} {noun if count == 1 else plural or noun + 's'}"


def _heading(title: str, kind: str, details: str) -> str:
    """Return a figure title: the caller's ``title`` (or ``kind``) over a line of details."""
    return f"{title or kind}\n{details}"


# --------------------------------------------------------------------------------------
# Fig. 2: tangent histograms


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
    path = _output_path(path)
    polylines = [_polyline_points(p, name, 2) for p, name in ((p0, "p0"), (p1, "p1"))]
    tangents = [tangent_function(points) for points in polylines]
    for (_, angles), name in zip(tangents, ("p0", "p1"), strict=True):
        if angles.size == 0:
            raise ValueError(
                f"{name}: has zero length (fewer than 2 distinct vertices): no tangent function"
            )
    score = similarity(polylines[0], polylines[1])
    lengths = [float(np.sum(np.hypot(*np.diff(p, axis=0).T))) for p in polylines]
    (breaks0, angles0), (breaks1, angles1) = tangents
    # theta_0 is the mean of T1 - T0 over s (DESIGN.md detail 4).
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
        shape_ax.set_title(f"P{row}: {_counted(len(points), 'vertex', 'vertices')}, {length:.2f} m")
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
        tangent_ax.set_title(f"tangent function of P{row}, {_counted(angles.size, 'edge')}")
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
        _heading(
            title,
            "shape similarity from tangent histograms",
            f"s(P0, P1) = {score:.4g}   (length ratio {ratio:.2f}; 0 means the same shape)",
        )
    )
    return _write_png(fig, path)


# --------------------------------------------------------------------------------------
# Fig. 4: the polygonal map over ground truth


def _check_map_polylines(map_polylines: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    checked = []
    for index, polyline in enumerate(map_polylines):
        where = f"map_polylines[{index}]"
        if not isinstance(polyline, Mapping):
            raise ValueError(
                f"{where}: expected a dict with 'points' and 'status', got {polyline!r}"
            )
        for key in ("points", "status"):
            if key not in polyline:
                raise ValueError(f"{where}: missing key {key!r}")
        status = polyline["status"]
        if status not in STATUS_STYLE:
            raise ValueError(f"{where}.status: must be one of {MAP_STATUSES}, got {status!r}")
        points = _polyline_points(polyline["points"], f"{where}.points")
        checked.append({"points": points, "status": status})
    return checked


def _draw_path(ax: Axes, world: WorldSpec) -> None:
    """Draw the planned path thinly, with segment boundaries and names."""
    spline = SplinePath(world.path.knots)
    samples = max(2, math.ceil(spline.length / PATH_SAMPLE_SPACING) + 1)
    ax.plot(
        *spline.point(np.linspace(0.0, spline.length, samples)).T,
        color=MAP_COLORS["path"],
        lw=1.0,
        ls=":",
        zorder=5,
    )
    for segment in world.path.segments:
        start_s = float(spline.knot_s[segment.start_knot])
        end_s = float(spline.knot_s[segment.end_knot])
        boundary = spline.pose(start_s)
        tick = 0.25 * np.array([-np.sin(boundary[2]), np.cos(boundary[2])])
        ax.plot(
            *np.stack([boundary[:2] - tick, boundary[:2] + tick]).T,
            color=MAP_COLORS["path"],
            lw=1.2,
            zorder=5,
        )
        middle = spline.pose(0.5 * (start_s + end_s))
        normal = np.array([-np.sin(middle[2]), np.cos(middle[2])])
        ax.annotate(
            segment.name,
            middle[:2] + 0.45 * normal,
            ha="center",
            va="center",
            fontsize=7,
            color="0.3",
            bbox={"facecolor": "white", "alpha": 0.6, "linewidth": 0, "pad": 0.5},
            zorder=6,
        )


def plot_polygonal_map(
    world: WorldSpec,
    map_polylines: Sequence[Mapping[str, Any]],
    path: str | os.PathLike[str],
    *,
    truth_outlines: Mapping[str, ArrayLike] | None = None,
    trajectory: ArrayLike | None = None,
    estimate: ArrayLike | None = None,
    title: str = "",
) -> Path:
    """Draw the polygonal map over the world and the ground truth, as in Fig. 4 (b)/(d).

    Walls are light grey, reflective posts blue discs, the true box outlines dashed
    brown with their names, the planned path dotted with its segments, the true
    trajectory black and the EKF estimate dashed orange. The map polylines go on top,
    coloured by life-cycle status (confirmed blue, new red, blank dashed grey), with
    their vertices marked.

    Parameters
    ----------
    world
        The environment (walls, posts, path).
    map_polylines
        Dicts ``{"points": (N, 2) world frame, "status": "new" | "confirmed" | "blank",
        "segment": str, "id": int}``; only ``points`` and ``status`` are drawn, other keys
        are ignored.
    path
        Where to write the PNG (``*.png``).
    truth_outlines
        Box name -> ``(4, 2)`` footprint corners where the box really stood.
    trajectory, estimate
        ``(N, 3)`` true and EKF poses ``(x, y, theta)`` (``(N, 2)`` positions also work).
    title
        First line of the figure title, in place of the default that says what it shows.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If a polyline lacks ``points``/``status`` or has an unknown status, or an array
        has the wrong shape.

    Examples
    --------
    >>> import tempfile
    >>> from worlds.load import load_world
    >>> wall = {"points": [[0.0, 1.0], [4.0, 1.0]], "status": "confirmed", "id": 0}
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     plot_polygonal_map(load_world("sim1"), [wall], Path(tmp) / "map.png").name
    'map.png'
    >>> plot_polygonal_map(load_world("sim1"), [{**wall, "status": "old"}], "/tmp/x.png")
    Traceback (most recent call last):
    ...
    ValueError: map_polylines[0].status: must be one of ('confirmed', 'new', 'blank'), \
got 'old'
    """
    path = _output_path(path)
    polylines = _check_map_polylines(map_polylines)
    outlines = {
        str(name): _polyline_points(corners, f"truth_outlines[{name!r}]", 3)
        for name, corners in (truth_outlines or {}).items()
    }
    tracks = {
        key: _poses(poses, key)
        for key, poses in (("trajectory", trajectory), ("estimate", estimate))
        if poses is not None
    }

    fig = Figure(figsize=figure_size(world))
    ax = fig.subplots()
    draw_walls(ax, world.walls, color=MAP_COLORS["wall"])
    draw_posts(ax, world.posts, color=MAP_COLORS["post"])
    for name, corners in outlines.items():
        draw_box(ax, corners, name, outline=True)
    _draw_path(ax, world)
    handles: list[Any] = [
        Patch(color=MAP_COLORS["wall"], label="wall"),
        Line2D([], [], ls="", marker="o", color=MAP_COLORS["post"], label="reflective post"),
        Line2D([], [], color=MAP_COLORS["path"], ls=":", label="planned path, segments"),
    ]
    if outlines:
        handles.append(
            Patch(
                facecolor=(0.55, 0.34, 0.29, 0.15),
                edgecolor="tab:brown",
                ls="--",
                label="true box outline",
            )
        )
    track_styles = {
        "trajectory": {"color": MAP_COLORS["trajectory"], "ls": "-", "label": "true trajectory"},
        "estimate": {"color": MAP_COLORS["estimate"], "ls": "--", "label": "EKF estimate"},
    }
    for key, poses in tracks.items():
        (line,) = ax.plot(*poses[:, :2].T, lw=1.0, zorder=6, **track_styles[key])
        ax.plot(*poses[0, :2], "o", color=line.get_color(), ms=5, zorder=6)
        handles.append(line)

    counts = dict.fromkeys(MAP_STATUSES, 0)
    for polyline in polylines:
        style = STATUS_STYLE[polyline["status"]]
        ax.plot(*polyline["points"].T, marker="o", ms=3.5, mec=style["color"], **style)
        counts[polyline["status"]] += 1
    for status in MAP_STATUSES:
        style = STATUS_STYLE[status]
        handles.append(
            Line2D(
                [],
                [],
                marker="o",
                ms=3.5,
                mec=style["color"],
                label=f"map: {status} ({counts[status]})",
                **{k: v for k, v in style.items() if k != "zorder"},
            )
        )

    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    summary = ", ".join(f"{counts[status]} {status}" for status in MAP_STATUSES)
    ax.set_title(
        _heading(
            title,
            f"polygonal map of {world.name}",
            f"{_counted(len(polylines), 'map polyline')}: {summary}",
        ),
        fontsize=10,
    )
    return _write_png(fig, path)


# --------------------------------------------------------------------------------------
# Fig. 5: EKF corrections within sigma bounds


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
    corrections fall within ±1 and ±3 sigma. A few corrections far larger than the rest
    (a re-initialisation) are drawn as red triangles on the axis edge, so that they do
    not flatten the others; the panel says how far they reach.

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
    path = _output_path(path)
    stamps, corrections, sigmas = _ekf_arrays(stamps, corrections, sigmas)
    restarts = np.zeros(stamps.size, dtype=bool)
    if reinitialized is not None:
        restarts = np.asarray(reinitialized)
        if restarts.shape != stamps.shape or restarts.dtype != bool:
            raise ValueError(
                f"reinitialized: expected ({stamps.size},) booleans (one per stamp), got "
                f"{restarts.dtype} of shape {restarts.shape}"
            )
    corrections = corrections * EKF_SCALE
    sigmas = sigmas * EKF_SCALE

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
        for stamp in stamps[restarts]:
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
            note = f"; {_counted(int(outside.sum()), 'correction')} beyond the axis, "
            note += f"up to {largest:.3g} {unit}"
        if limit > 0.0:
            ax.set_ylim(-limit, limit)
        inside_1 = float(np.mean(size <= sigma))
        inside_3 = float(np.mean(size <= 3.0 * sigma))
        rms = float(np.sqrt(np.mean(correction**2)))
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
    if np.any(restarts):
        handles.append(Line2D([], [], color="tab:purple", ls=":", label="re-initialised"))
    if clipped_any:
        handles.append(Line2D([], [], color="tab:red", marker="^", ls="", label="beyond the axis"))
    fig.legend(handles=handles, loc="outside lower center", fontsize=8, ncols=len(handles))
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(
        _heading(
            title,
            "EKF corrections (posterior − prior) within σ bounds",
            f"{_counted(stamps.size, 'update')} over {stamps[-1] - stamps[0]:.1f} s",
        )
    )
    return _write_png(fig, path)


# --------------------------------------------------------------------------------------
# Policy comparison


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
    path = _output_path(path)
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

    fig.suptitle(_heading(title, "lap times per speed policy", _lap_summary(times, counts)))
    return _write_png(fig, path)


# --------------------------------------------------------------------------------------
# Detection scores per lap


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


def plot_detection_scores(
    per_lap: Sequence[Mapping[str, Any]], path: str | os.PathLike[str], *, title: str = ""
) -> Path:
    """Draw semi-static object detection precision, recall and F1 per lap.

    Parameters
    ----------
    per_lap
        Dicts ``{"lap": int, "precision": float, "recall": float, "f1": float}``, scores in
        ``[0, 1]`` (``nan`` where undefined: drawn as a gap), in any lap order.
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
    >>> rows = [{"lap": 2, "precision": 0.9, "recall": 0.8, "f1": 0.85},
    ...         {"lap": 3, "precision": 1.0, "recall": 0.9, "f1": 0.95}]
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     plot_detection_scores(rows, Path(tmp) / "scores.png").name
    'scores.png'
    >>> plot_detection_scores([{**rows[0], "recall": 1.2}], "/tmp/never.png")
    Traceback (most recent call last):
    ...
    ValueError: per_lap[0].recall: must be in [0, 1] (or nan), got 1.2
    """
    path = _output_path(path)
    laps, scores = _score_table(per_lap)

    figure_width = float(np.clip(0.5 * laps.size + 3.0, *FIGURE_WIDTH_RANGE))
    fig = Figure(figsize=(figure_width, 4.5), layout="constrained")
    ax = fig.subplots()
    styles = {
        "precision": {"marker": "o", "color": "tab:blue", "lw": 1.5},
        "recall": {"marker": "s", "color": "tab:orange", "lw": 1.5},
        "f1": {"marker": "D", "color": "tab:green", "lw": 2.5},
    }
    means = {}
    for column, name in enumerate(SCORE_NAMES):
        values = scores[:, column]
        defined = values[~np.isnan(values)]
        means[name] = float(defined.mean()) if defined.size else math.nan
        label = "F1" if name == "f1" else name
        ax.plot(laps, values, ms=6, label=f"{label} (mean {means[name]:.2f})", **styles[name])
    for lap in laps[np.all(np.isnan(scores), axis=1)]:
        # Say so where a lap has no score at all, rather than leave a silent gap.
        ax.text(lap, 0.5, "no score", rotation=90, ha="center", va="center", color="0.5")
    ax.set_ylim(0.0, 1.05)
    ax.set_xlim(laps[0] - 0.5, laps[-1] + 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("lap")
    ax.set_ylabel("score")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(loc="lower right", fontsize=8, framealpha=0.9)
    details = ", ".join(
        f"{'F1' if name == 'f1' else name} {means[name]:.2f}" for name in SCORE_NAMES
    )
    fig.suptitle(
        _heading(title, "semi-static object detection per lap", f"mean over laps: {details}")
    )
    return _write_png(fig, path)


# --------------------------------------------------------------------------------------
# Real-log replay


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
    path = _output_path(path)
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
    return _write_png(fig, path)
