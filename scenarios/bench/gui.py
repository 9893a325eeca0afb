"""Watching a run in PyBullet's window: the GUI observer.

Examples
--------
>>> GuiView().refresh_hz, GuiView().follow
(4.0, False)
"""

from __future__ import annotations

import time

import numpy as np

from scenarios.bench.observer import Observer
from scenarios.bench.records import ScanRecord
from semistatic.colours import (
    FIELD_COLOURS,
    PERSON_COLOUR,
    RETURNS_COLOUR,
    STATUS_COLOURS,
    TEXT_COLOUR,
)
from semistatic.frames import transform_points
from sim.debug_view import DebugView, dotted

__all__ = ["DRAW_SHARE", "FOLLOW_WINDOW_M", "GUI_REFRESH_HZ", "LEGEND", "GuiView", "status_line",
           "world_bounds"]

GUI_REFRESH_HZ = 4.0
"""Redraws per simulated second of the GUI's debug items (each redraw costs a frame)."""

DRAW_SHARE = 0.5
"""Most of the wall time that redrawing may take: after a redraw that took ``d`` seconds
the next one waits ``d * (1 - DRAW_SHARE) / DRAW_SHARE`` wall seconds. Every command to
the GUI waits for one of its frames (~10-70 ms under software rendering on a busy
machine), so on a slow display the window is redrawn less often instead of slowing the
run down without bound. The physics is not touched: a run's results never depend on it."""

FOLLOW_WINDOW_M = 12.0
"""Width and height (m) of the area shown around the robot when the camera follows it."""

LEGEND: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("warning field", FIELD_COLOURS["warning"]),
    ("protective field", FIELD_COLOURS["protective"]),
    ("minimum field", FIELD_COLOURS["minimum"]),
    ("laser returns", RETURNS_COLOUR),
    ("polyline new", STATUS_COLOURS["new"]),
    ("polyline confirmed", STATUS_COLOURS["confirmed"]),
    ("polyline blank", STATUS_COLOURS["blank"]),
    ("person", PERSON_COLOUR),
)
"""The legend's entries: label and colour, in the order shown."""

_TEXT_SIZE = 1.2
_MARGIN = 0.5  # m of floor shown around the world


def world_bounds(world) -> tuple[float, float, float, float]:
    """Return ``(x_min, y_min, x_max, y_max)`` (m) of a world's walls, posts and boxes.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> [round(v, 2) for v in world_bounds(load_world("pal1"))]
    [-1.55, -1.65, 13.05, 5.05]
    """
    points = []
    for wall in world.walls:
        half = 0.5 * wall.thickness
        for x, y in (wall.start, wall.end):
            points += [(x - half, y - half), (x + half, y + half)]
    for post in world.posts:
        points += [(post.x - post.radius, post.y - post.radius),
                   (post.x + post.radius, post.y + post.radius)]
    for box in world.boxes:
        reach = 0.5 * float(np.hypot(*box.size[:2]))
        points += [(box.pose[0] - reach, box.pose[1] - reach),
                   (box.pose[0] + reach, box.pose[1] + reach)]
    if not points:
        return (-5.0, -5.0, 5.0, 5.0)
    xy = np.asarray(points, dtype=float)
    return (*xy.min(axis=0).tolist(), *xy.max(axis=0).tolist())


def status_line(vehicle) -> str:
    """Return the status text of a vehicle: time, lap, segment, speed, zone, speed scale.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> vehicle = SimpleNamespace(sim_time=12.345, lap=1, segment=SimpleNamespace(name="s1"),
    ...                           true_twist=np.array([0.4, 0.0, 0.1]), zone="warning",
    ...                           speed_scale=0.5)
    >>> status_line(vehicle)
    't 12.3 s   lap 1   s1   v 0.40 m/s   zone warning   scale 0.50'
    """
    return (f"t {vehicle.sim_time:.1f} s   lap {vehicle.lap}   {vehicle.segment.name}   "
            f"v {float(vehicle.true_twist[0]):.2f} m/s   zone {vehicle.zone}   "
            f"scale {vehicle.speed_scale:.2f}")


class GuiView(Observer):
    """Show the run in PyBullet's window (the bench adds it when ``gui=True``).

    The camera looks straight down at the whole world (``follow=False``) or at a
    :data:`FOLLOW_WINDOW_M` square around the robot. A few times per simulated second
    (``refresh_hz``) the bodies' poses are copied to the window and the debug items
    redrawn, as dots in one GUI command (:func:`~sim.debug_view.dotted`): the current
    segment's warning (orange) and protective (red) fields and the
    last scan's minimum protective field (dark red) where the EKF places the robot, the
    last safety scan's returns (magenta), every local map's polylines coloured by
    life-cycle status (:data:`~semistatic.colours.STATUS_COLOURS`), a legend of these
    colours and a status line (:func:`status_line`). Redrawing takes at most
    ``draw_share`` of the wall time (:data:`DRAW_SHARE`): a slow display shows fewer
    frames. Headless, it draws nothing.

    Examples
    --------
    >>> GuiView(follow=True).wants_polylines
    True
    """

    wants_polylines = True  # for record.fields: the minimum protective field of each scan

    def __init__(self, refresh_hz: float = GUI_REFRESH_HZ, *, follow: bool = False,
                 draw_share: float = DRAW_SHARE) -> None:
        if not 0.0 < draw_share <= 1.0:
            raise ValueError(f"GuiView: draw_share must be in (0, 1] (got {draw_share})")
        self.refresh_hz = float(refresh_hz)
        self.draw_share = float(draw_share)
        self._next_wall = -np.inf
        self.follow = bool(follow)
        self.view: DebugView | None = None
        self._returns = np.empty((0, 2))
        self._minimum = np.empty((0, 2))
        self._drawn_at = -np.inf
        self._window: tuple[float, float, float, float] | None = None

    def on_lap_start(self, bench, lap: int) -> None:
        """Bind to the bench's client and draw at once: the robot is back at the start."""
        if self.view is None or self.view.sim is not bench.sim:
            self.view = DebugView(bench.sim)
            self._window = None
        self._returns = np.empty((0, 2))
        self._minimum = np.empty((0, 2))
        self.draw(bench)

    def on_scan(self, bench, record: ScanRecord) -> None:
        """Keep the scan's returns (world frame) and minimum field for the next redraw."""
        scan = record.scan
        self._returns = scan.world_points()[scan.valid_mask()]
        if record.fields is not None:
            self._minimum = record.fields.minimum

    def on_tick(self, bench) -> None:
        """Redraw when ``1 / refresh_hz`` simulated seconds and the wall-time budget allow."""
        if (bench.sim_time - self._drawn_at >= 1.0 / self.refresh_hz
                and time.perf_counter() >= self._next_wall):
            self.draw(bench)

    def draw(self, bench) -> None:
        """Copy the bodies, aim the camera and redraw every item now."""
        view = self.view
        if view is None or not view.active:
            return
        started = time.perf_counter()
        self._drawn_at = bench.sim_time
        view.sync()
        self._aim(bench)
        pose, fields = bench.ekf_pose, bench.segment.fields
        lines = [transform_points(pose, fields.warning), transform_points(pose, fields.protective)]
        colours = [FIELD_COLOURS["warning"], FIELD_COLOURS["protective"]]
        if len(self._minimum) > 2:
            lines.append(transform_points(pose, self._minimum))
            colours.append(FIELD_COLOURS["minimum"])
        closed = len(lines)
        for local_map in bench.local_maps.values():
            for map_id, line in local_map.world_polylines().items():
                lines.append(line.points)
                colours.append(STATUS_COLOURS[local_map[map_id].status])
        # Fields, maps and returns as dots in one item: one GUI command, where lines
        # took one per segment and each waited for a frame (~20 ms under Xvfb).
        field_dots, field_rgb = dotted(lines[:closed], colours[:closed], closed=True)
        map_dots, map_rgb = dotted(lines[closed:], colours[closed:])
        view.draw_points(
            "scene", np.vstack([field_dots, map_dots, self._returns]),
            np.vstack([field_rgb, map_rgb, np.tile(RETURNS_COLOUR, (len(self._returns), 1))]),
        )
        x_min, _, _, y_max = self._window
        row = self._row()
        view.draw_texts("status", [(status_line(bench), (x_min + row, y_max - row),
                                    TEXT_COLOUR)], size=_TEXT_SIZE)
        view.show()
        finished = time.perf_counter()
        self._next_wall = finished + (finished - started) * (1.0 / self.draw_share - 1.0)

    def _row(self) -> float:
        """Return the height (m) of a text row: a fixed share of the window shown."""
        x_min, y_min, x_max, y_max = self._window
        return 0.045 * max(x_max - x_min, y_max - y_min)

    def _aim(self, bench) -> None:
        """Aim the camera (once when it shows the world) and place the legend beside it."""
        if self.follow:
            x, y = bench.true_pose[:2]
            half = 0.5 * FOLLOW_WINDOW_M
            window = (x - half, y - half, x + half, y + half)
            legend_left = x + half - 0.3 * FOLLOW_WINDOW_M
        elif self._window is None:
            x_min, y_min, x_max, y_max = world_bounds(bench.world)
            span = max(x_max - x_min, y_max - y_min)
            # Room for the status line above the world and the legend right of it.
            window = (x_min - _MARGIN, y_min - _MARGIN,
                      x_max + _MARGIN + 0.3 * span, y_max + _MARGIN + 0.1 * span)
            legend_left = x_max + _MARGIN
        else:
            return
        if window == self._window:
            return
        self._window = window
        self.view.look_at(window)
        x_min, y_min, x_max, y_max = window
        row = self._row()
        left, top = legend_left, y_max - 2.5 * row
        samples, labels = [], []
        for index, (label, _) in enumerate(LEGEND):
            y = top - index * row
            samples.append(((left, y + 0.25 * row), (left + 0.8 * row, y + 0.25 * row)))
            labels.append((label, (left + 1.1 * row, y), TEXT_COLOUR))
        self.view.draw_polylines("legend", samples, [colour for _, colour in LEGEND],
                                 width=6.0)
        self.view.draw_texts("legend text", labels, size=_TEXT_SIZE)
