"""Draw a world: walls, posts, boxes, people, the path, its segments and safety fields.

``python -m worlds.plot OUT_DIR`` writes ``OUT_DIR/<world>.png`` for every bundled world.

Examples
--------
>>> import matplotlib
>>> matplotlib.use("Agg")
>>> from worlds.load import load_world
>>> ax = plot_world(load_world("sim1"))
>>> ax.get_xlabel()
'x [m]'
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import to_rgb
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Polygon
from numpy.typing import ArrayLike

from robots.path import SplinePath
from semistatic.frames import transform_points
from worlds.checks import build_spline
from worlds.spec import PostSpec, WallSpec, WorldSpec

__all__ = [
    "COLORS",
    "draw_box",
    "draw_posts",
    "draw_walls",
    "figure_size",
    "main",
    "plot_world",
    "save_world_figure",
]

FIELD_POSES_PER_SEGMENT = 3
"""Poses per segment at which its fields are drawn (start, middle, end)."""

FIELD_END_INSET = 0.15
"""Fields are drawn this far (m) inside a segment's ends, so neighbours do not overlap."""

FOOTPRINT_HALF = (0.455 / 2, 0.381 / 2)
"""Half length and half width (m) of the Pioneer 3-DX base drawn at the path start."""

MIN_POST_RADIUS = 0.06
"""Posts are drawn at least this big (m): real ones (4 cm) vanish at a whole-world scale."""

DPI = 150
AXES_WIDTH = 7.5  # inches of plot area
LEGEND_WIDTH = 3.0  # inches right of it for the legend
FIGURE_MARGIN = 1.3  # inches for the title and axis labels
FIGURE_HEIGHT_RANGE = (4.0, 10.0)

COLORS = {
    "wall": "0.35",
    "post": "tab:blue",
    "box": "tab:brown",
    "person": "tab:purple",
    "test_piece": "black",
    "path": "black",
    "warning": "gold",
    "protective": "red",
    "robot": "tab:green",
}


def _field_poses(path: SplinePath, start_s: float, end_s: float) -> np.ndarray:
    inset = min(FIELD_END_INSET, 0.25 * (end_s - start_s))
    return path.pose(np.linspace(start_s + inset, end_s - inset, FIELD_POSES_PER_SEGMENT))


def draw_walls(ax: Axes, walls: Iterable[WallSpec], *, color: str = COLORS["wall"]) -> None:
    """Fill each wall's footprint on ``ax`` in ``color``.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from worlds.spec import WallSpec
    >>> ax = Figure().subplots()
    >>> draw_walls(ax, [WallSpec((0, 0), (4, 0)), WallSpec((4, 0), (4, 3))])
    >>> len(ax.patches)
    2
    """
    for wall in walls:
        ax.add_patch(Polygon(wall.corners(), closed=True, color=color, zorder=3))


def draw_posts(ax: Axes, posts: Iterable[PostSpec], *, color: str = COLORS["post"]) -> None:
    """Draw each reflective post as a disc (at least 6 cm in radius, to stay visible).

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from worlds.spec import PostSpec
    >>> ax = Figure().subplots()
    >>> draw_posts(ax, [PostSpec(1.0, 2.0)])
    >>> ax.patches[0].radius
    0.06
    """
    for post in posts:
        radius = max(post.radius, MIN_POST_RADIUS)
        ax.add_patch(Circle(post.xy, radius, color=color, zorder=4))


def draw_box(ax: Axes, corners: ArrayLike, name: str, *, outline: bool = False,
             color: Any = COLORS["box"]) -> None:
    """Draw a semi-static box footprint ``corners`` (4, 2) and its ``name`` below it.

    A filled box by default; with ``outline`` only a dashed outline over a faint fill,
    so that lines drawn on top (a map of the box) stay visible. ``color`` is any
    matplotlib colour (brown by default).

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> ax = Figure().subplots()
    >>> draw_box(ax, [[0, 0], [1, 0], [1, 1], [0, 1]], "crate", outline=True)
    >>> ax.patches[0].get_linestyle(), ax.texts[0].get_text()
    ('--', 'crate')
    """
    corners = np.asarray(corners, dtype=float)
    if outline:
        style = {"facecolor": (*to_rgb(color), 0.15), "edgecolor": color}
        style |= {"linestyle": "--", "linewidth": 1.2}
    else:
        style = {"facecolor": color, "edgecolor": "black", "alpha": 0.8}
    ax.add_patch(Polygon(corners, closed=True, zorder=4, **style))
    ax.annotate(
        name,
        corners.mean(axis=0),
        textcoords="offset points",
        xytext=(0, -18),
        ha="center",
        fontsize=7,
        color=color,
        bbox={"facecolor": "white", "alpha": 0.6, "linewidth": 0, "pad": 0.5},
        zorder=6,
    )


def plot_world(spec: WorldSpec, ax: Axes | None = None) -> Axes:
    """Draw ``spec`` on ``ax`` (a new figure when ``None``) and return the axes.

    Walls are grey, reflective posts blue dots, semi-static boxes brown (named), people's
    waypoints purple (dotted when the person is off by default), the path black with its
    knots and segment boundaries, and each segment's warning (yellow) and protective (red)
    fields at a few poses along it. The Pioneer 3-DX footprint is drawn at the start.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from worlds.load import load_world
    >>> ax = plot_world(load_world("pal3"))
    >>> len(ax.get_legend().get_texts()) >= 6
    True
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(9, 6.5))
    path = build_spline(spec.path)

    draw_walls(ax, spec.walls)
    draw_posts(ax, spec.posts)
    for box in spec.boxes:
        draw_box(ax, box.corners(), box.name)
    for piece in spec.test_pieces:
        outline = np.asarray(piece.footprint().exterior.coords)
        ax.add_patch(Polygon(outline, closed=True, facecolor=COLORS["test_piece"], zorder=6))
        ax.annotate(f"{piece.name} ({piece.kind})", piece.pose[:2], textcoords="offset points",
                    xytext=(4, 4), fontsize=7, color=COLORS["test_piece"])

    for index, segment in enumerate(spec.path.segments):
        start_s = float(path.knot_s[segment.start_knot])
        end_s = float(path.knot_s[segment.end_knot])
        for pose in _field_poses(path, start_s, end_s):
            for polygon, kind, alpha in (
                (segment.warning, "warning", 0.25),
                (segment.protective, "protective", 0.45),
            ):
                ax.add_patch(
                    Polygon(
                        transform_points(pose, polygon),
                        closed=True,
                        facecolor=COLORS[kind],
                        edgecolor=COLORS[kind],
                        alpha=alpha,
                        lw=0.6,
                        zorder=2,
                    )
                )
        mid = path.pose(0.5 * (start_s + end_s))
        normal = np.array([-np.sin(mid[2]), np.cos(mid[2])])
        ax.annotate(
            f"{index}: {segment.name}",
            mid[:2] + 0.8 * normal,
            ha="center",
            va="center",
            fontsize=7,
            bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0, "pad": 1},
            zorder=7,
        )
        boundary = path.pose(start_s)
        tick = np.array([-np.sin(boundary[2]), np.cos(boundary[2])]) * 0.3
        ax.plot(*np.stack([boundary[:2] - tick, boundary[:2] + tick]).T, color="black", lw=1.5)

    s = np.linspace(0.0, path.length, 400)
    ax.plot(*path.point(s).T, color=COLORS["path"], lw=1.2, zorder=5)
    ax.plot(*np.asarray(spec.path.knots).T, "o", ms=3, color=COLORS["path"], zorder=5)
    start = path.pose(0.0)
    corners = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]], dtype=float) * FOOTPRINT_HALF
    ax.add_patch(
        Polygon(
            transform_points(start, corners),
            closed=True,
            facecolor="none",
            edgecolor=COLORS["robot"],
            lw=1.5,
            zorder=6,
        )
    )
    ax.annotate(
        "",
        start[:2] + 0.6 * np.array([np.cos(start[2]), np.sin(start[2])]),
        start[:2],
        arrowprops={"arrowstyle": "->", "color": COLORS["robot"]},
        zorder=6,
    )

    for person in spec.people:
        style = "-" if person.enabled else ":"
        waypoints = np.asarray(person.waypoints)
        ax.plot(*waypoints.T, style, marker="o", ms=3, color=COLORS["person"], zorder=5)
        label = person.name if person.enabled else f"{person.name} (off)"
        ax.annotate(
            "",
            waypoints[-1],
            waypoints[-2] if len(waypoints) > 1 else waypoints[-1],
            arrowprops={"arrowstyle": "->", "color": COLORS["person"]},
            zorder=5,
        )
        ax.annotate(
            label,
            waypoints[0],
            textcoords="offset points",
            xytext=(4, -10),
            fontsize=7,
            color=COLORS["person"],
        )

    ax.legend(handles=_legend_handles(spec), loc="upper left", bbox_to_anchor=(1.01, 1.0),
              fontsize=7)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    title = f"{spec.name}: path {path.length:.1f} m, {len(spec.path.segments)} segments"
    ax.set_title(f"{title}\n{spec.description}" if spec.description else title, fontsize=9)
    return ax


def _legend_handles(spec: WorldSpec) -> list:
    handles = [
        Patch(color=COLORS["wall"], label="wall"),
        Line2D([], [], ls="", marker="o", color=COLORS["post"], label="reflective post"),
        Patch(facecolor=COLORS["box"], edgecolor="black", label="semi-static box"),
        Line2D([], [], color=COLORS["path"], marker="o", ms=3, label="path (knots, segments)"),
        Patch(facecolor=COLORS["warning"], alpha=0.4, label="warning field"),
        Patch(facecolor=COLORS["protective"], alpha=0.6, label="protective field"),
        Line2D([], [], color=COLORS["person"], marker="o", ms=3, label="person waypoints"),
        Patch(facecolor="none", edgecolor=COLORS["robot"], label="Pioneer 3-DX at start"),
    ]
    if spec.test_pieces:
        handles.append(Patch(color=COLORS["test_piece"], label="test piece"))
    return handles


def figure_size(spec: WorldSpec) -> tuple[float, float]:
    """Return a figure size (inches) that fits the world's extent at equal aspect.

    The plot area is ``AXES_WIDTH`` wide; the legend sits to its right.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> width, height = figure_size(load_world("pal1"))
    >>> width, height < 6
    (10.5, True)
    """
    points = [wall.corners() for wall in spec.walls]
    points += [np.asarray(spec.path.knots), np.asarray([post.xy for post in spec.posts])]
    points += [np.asarray(person.waypoints) for person in spec.people]
    extent = np.vstack([p.reshape(-1, 2) for p in points])
    span = np.ptp(extent, axis=0) + 1.0
    height = AXES_WIDTH * span[1] / span[0] + FIGURE_MARGIN
    return (AXES_WIDTH + LEGEND_WIDTH, float(np.clip(height, *FIGURE_HEIGHT_RANGE)))


def save_world_figure(spec: WorldSpec, out_dir: str | Path) -> Path:
    """Write ``out_dir/<name>.png`` of ``spec`` and return its path.

    Examples
    --------
    >>> import tempfile, matplotlib
    >>> matplotlib.use("Agg")
    >>> from worlds.load import load_world
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     save_world_figure(load_world("sim2"), tmp).name
    'sim2.png'
    """
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=figure_size(spec))
    plot_world(spec, ax)
    fig.tight_layout()
    out = out_dir / f"{spec.name}.png"
    fig.savefig(out, dpi=DPI)
    plt.close(fig)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Write a picture of every bundled world into the directory given on the command line.

    Examples
    --------
    >>> import contextlib, io, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()) as out:
    ...     status = main([tmp])
    >>> from worlds.load import bundled_worlds
    >>> status, out.getvalue().count(".png") == len(bundled_worlds())  # one per bundled world
    (0, True)
    """
    import matplotlib

    from worlds.load import bundled_worlds, load_world

    matplotlib.use("Agg")
    parser = argparse.ArgumentParser(prog="python -m worlds.plot", description=__doc__)
    parser.add_argument("out_dir", type=Path, help="directory for <world>.png files")
    args = parser.parse_args(argv)
    for name in bundled_worlds():
        print(save_world_figure(load_world(name), args.out_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main())
