"""Paper Fig. 4: the polygonal local maps over the ground truth of the world.

See :mod:`scenarios.results.figures` for the conventions every figure follows.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch
from numpy.typing import ArrayLike

from scenarios.results.figures.style import (
    checked_poses,
    checked_vertices,
    count_text,
    figure_title,
    png_path,
    write_png,
)
from semistatic.colours import (
    BOX_COLOUR,
    EKF_COLOUR,
    PERSON_COLOUR,
    POST_COLOUR,
    STATUS_COLOURS,
    TRUE_COLOUR,
)
from worlds.checks import build_spline
from worlds.plot import draw_box, draw_posts, draw_walls, figure_size
from worlds.spec import PersonSpec, WorldSpec

__all__ = ["PERSON_GID", "draw_people", "plot_polygonal_map"]

MAP_STATUSES = ("confirmed", "new", "blank")
"""Life-cycle states of a map polyline, in the order the legend lists them."""

STATUS_STYLE: dict[str, dict[str, Any]] = {
    # The colours are the GUI's and the recordings' (semistatic.colours), so a status
    # reads the same in every view. New polylines (semi-static objects just seen) are
    # drawn thickest and on top, blank ones (missed while they should have been visible)
    # dashed and hollow: they are what a reader looks for among the confirmed bulk.
    "confirmed": {"color": STATUS_COLOURS["confirmed"], "lw": 1.8, "ls": "-",
                  "mfc": STATUS_COLOURS["confirmed"], "zorder": 8},
    "new": {"color": STATUS_COLOURS["new"], "lw": 2.2, "ls": "-", "mfc": STATUS_COLOURS["new"],
            "zorder": 9},
    "blank": {"color": STATUS_COLOURS["blank"], "lw": 1.6, "ls": "--", "mfc": "white",
              "zorder": 7},
}

MAP_COLORS = {
    # Walls stay light grey, not the palette's dark WALL_COLOUR: most map polylines lie
    # on walls and must stay visible over them.
    "wall": "0.82",
    "path": "0.45",
    "post": POST_COLOUR,
    "trajectory": TRUE_COLOUR,
    "estimate": EKF_COLOUR,
    "person": PERSON_COLOUR,
}

PERSON_GID = "person:{name}"
"""``gid`` of the line that draws a person's route (``name`` is the person's): tests and
tools find it by that."""

PATH_SAMPLE_SPACING = 0.02
"""Spacing (m) of the points that draw the planned spline path."""


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
        points = checked_vertices(polyline["points"], f"{where}.points")
        checked.append({"points": points, "status": status})
    return checked


def _draw_path(ax: Axes, world: WorldSpec) -> None:
    """Draw the planned path thinly, with segment boundaries and names."""
    spline = build_spline(world.path)
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


def draw_people(ax: Axes, people: Sequence[PersonSpec]) -> list[Any]:
    """Draw where each person walks and stands; return the legend handles (none without people).

    A person's route is its waypoints joined in order (back to the first when it loops),
    an arrow on its last leg, a disc of its body radius where it waits or appears
    (``waypoints[0]``) and its name there; a person limited to some laps says which.
    The route's line carries ``gid`` :data:`PERSON_GID`.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> ann = PersonSpec("ann", ((0.0, 0.0), (2.0, 0.0), (2.0, 1.0)), laps=(3,))
    >>> ax = Figure().subplots()
    >>> [handle.get_label() for handle in draw_people(ax, [ann])]
    ['person: route, body where it waits']
    >>> route = next(line for line in ax.lines if line.get_gid() == "person:ann")
    >>> route.get_xydata().tolist()
    [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0]]
    >>> [text.get_text() for text in ax.texts if text.get_text()]
    ['ann (lap 3)']
    """
    colour = MAP_COLORS["person"]
    for person in people:
        waypoints = np.asarray(person.waypoints, dtype=float)
        route = np.vstack([waypoints, waypoints[:1]]) if person.loop else waypoints
        ax.plot(*route.T, color=colour, lw=1.2, ls="-", marker=".", ms=4, zorder=6,
                gid=PERSON_GID.format(name=person.name))
        if len(route) > 1:
            ax.annotate("", route[-1], route[-2], zorder=6,
                        arrowprops={"arrowstyle": "->", "color": colour, "lw": 1.2})
        ax.add_patch(Circle(waypoints[0], person.radius, facecolor=(*colour, 0.35),
                            edgecolor=colour, zorder=6))
        word = "lap" if len(person.laps) == 1 else "laps"
        laps = f" ({word} {', '.join(map(str, person.laps))})" if person.laps else ""
        ax.annotate(f"{person.name}{laps}", waypoints[0], textcoords="offset points",
                    xytext=(5, 5), fontsize=7, color=colour, zorder=6,
                    bbox={"facecolor": "white", "alpha": 0.6, "linewidth": 0, "pad": 0.5})
    if not people:
        return []
    return [Line2D([], [], color=colour, marker="o", ms=6, mfc=(*colour, 0.35),
                   label="person: route, body where it waits")]


def plot_polygonal_map(
    world: WorldSpec,
    map_polylines: Sequence[Mapping[str, Any]],
    path: str | os.PathLike[str],
    *,
    truth_outlines: Mapping[str, ArrayLike] | None = None,
    trajectory: ArrayLike | None = None,
    estimate: ArrayLike | None = None,
    trajectories: Mapping[str, ArrayLike] | None = None,
    title: str = "",
) -> Path:
    """Draw the polygonal map over the world and the ground truth, as in Fig. 4 (b)/(d).

    Walls are light grey, reflective posts teal discs, the true box outlines dashed
    brown with their names, the people the world spawns (``world.active_people``) with
    their routes and where they wait (:func:`draw_people`), the planned path dotted with
    its segments, the true trajectory black and the EKF estimate dashed blue. The map
    polylines go on top, coloured by life-cycle status in the palette of
    :mod:`semistatic.colours` (confirmed green, new blue, blank dashed grey), with their
    vertices marked.

    Parameters
    ----------
    world
        The environment (walls, posts, path, people).
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
    trajectories
        Vehicle name -> ``(N, 3)`` true poses: a fleet's vehicles, one colour each.
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
    path = png_path(path)
    polylines = _check_map_polylines(map_polylines)
    outlines = {
        str(name): checked_vertices(corners, f"truth_outlines[{name!r}]", 3)
        for name, corners in (truth_outlines or {}).items()
    }
    tracks = {
        key: checked_poses(poses, key)
        for key, poses in (("trajectory", trajectory), ("estimate", estimate))
        if poses is not None
    }

    fleet = {
        str(name): checked_poses(poses, f"trajectories[{name!r}]")
        for name, poses in (trajectories or {}).items()
    }

    fig = Figure(figsize=figure_size(world))
    ax = fig.subplots()
    draw_walls(ax, world.walls, color=MAP_COLORS["wall"])
    draw_posts(ax, world.posts, color=MAP_COLORS["post"])
    for name, corners in outlines.items():
        draw_box(ax, corners, name, outline=True, color=BOX_COLOUR)
    _draw_path(ax, world)
    people_handles = draw_people(ax, world.active_people)
    handles: list[Any] = [
        Patch(color=MAP_COLORS["wall"], label="wall"),
        Line2D([], [], ls="", marker="o", color=MAP_COLORS["post"], label="reflective post"),
        Line2D([], [], color=MAP_COLORS["path"], ls=":", label="planned path, segments"),
    ]
    if outlines:
        handles.append(
            Patch(
                facecolor=(*BOX_COLOUR, 0.15),
                edgecolor=BOX_COLOUR,
                ls="--",
                label="true box outline",
            )
        )
    handles += people_handles
    track_styles = {
        "trajectory": {"color": MAP_COLORS["trajectory"], "ls": "-", "label": "true trajectory"},
        "estimate": {"color": MAP_COLORS["estimate"], "ls": "--", "label": "EKF estimate"},
    }
    for key, poses in tracks.items():
        (line,) = ax.plot(*poses[:, :2].T, lw=1.0, zorder=6, **track_styles[key])
        ax.plot(*poses[0, :2], "o", color=line.get_color(), ms=5, zorder=6)
        handles.append(line)
    for index, (name, poses) in enumerate(fleet.items()):
        (line,) = ax.plot(*poses[:, :2].T, lw=1.0, zorder=6, color=f"C{index % 10}",
                          label=f"{name}: true trajectory")
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
        figure_title(
            title,
            f"polygonal map of {world.name}",
            f"{count_text(len(polylines), 'map polyline')}: {summary}",
        ),
        fontsize=10,
    )
    return write_png(fig, path)
