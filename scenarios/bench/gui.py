"""Watching a run in PyBullet's window: the GUI observer.

Examples
--------
>>> GuiView().refresh_hz
4.0
"""

from __future__ import annotations

import numpy as np

from scenarios.bench.observer import Observer
from scenarios.bench.records import ScanRecord
from semistatic.colours import FIELD_COLOURS, RETURNS_COLOUR, STATUS_COLOURS
from semistatic.frames import transform_points
from sim.debug_view import DebugView

__all__ = ["GUI_REFRESH_HZ", "GuiView"]

GUI_REFRESH_HZ = 4.0
"""Redraws per simulated second of the GUI's debug items (each redraw costs a frame)."""



class GuiView(Observer):
    """Show the run in PyBullet's window (the bench adds it when ``gui=True``).

    A few times per simulated second (``refresh_hz``) the camera is put above the robot
    and the debug items are redrawn: the current segment's warning (orange) and
    protective (red) fields where the EKF places the robot, the last safety scan's
    returns (magenta) and every local map's polylines, coloured by life-cycle status
    (:data:`~semistatic.colours.STATUS_COLOURS`). Headless, it draws nothing.

    Examples
    --------
    >>> GuiView().refresh_hz
    4.0
    """

    def __init__(self, refresh_hz: float = GUI_REFRESH_HZ) -> None:
        self.refresh_hz = float(refresh_hz)
        self.view: DebugView | None = None
        self._returns = np.empty((0, 2))
        self._drawn_at = -np.inf

    def on_lap_start(self, bench, lap: int) -> None:
        """Bind to the bench's client and draw at once: the robot is back at the start."""
        if self.view is None or self.view.sim is not bench.sim:
            self.view = DebugView(bench.sim)
        self._returns = np.empty((0, 2))
        self.draw(bench)

    def on_scan(self, bench, record: ScanRecord) -> None:
        """Keep the scan's returns (world frame) for the next redraw."""
        scan = record.scan
        self._returns = scan.world_points()[scan.valid_mask()]

    def on_tick(self, bench) -> None:
        """Redraw when ``1 / refresh_hz`` simulated seconds have passed."""
        if bench.sim_time - self._drawn_at >= 1.0 / self.refresh_hz:
            self.draw(bench)

    def draw(self, bench) -> None:
        """Move the camera and redraw every item now."""
        view = self.view
        if view is None or not view.active:
            return
        self._drawn_at = bench.sim_time
        view.follow(bench.true_pose)
        pose, fields = bench.ekf_pose, bench.segment.fields
        view.draw_polylines(
            "fields",
            [transform_points(pose, fields.warning), transform_points(pose, fields.protective)],
            [FIELD_COLOURS["warning"], FIELD_COLOURS["protective"]],
            closed=True,
        )
        view.draw_points("returns", self._returns, RETURNS_COLOUR)
        lines, colours = [], []
        for local_map in bench.local_maps.values():
            for map_id, line in local_map.world_polylines().items():
                lines.append(line.points)
                colours.append(STATUS_COLOURS[local_map[map_id].status])
        view.draw_polylines("maps", lines, colours, width=3.0)
