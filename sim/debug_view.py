"""Watching a run in PyBullet's window: a camera that follows the robot, and debug drawings.

PyBullet's GUI opens with its camera wherever the last user left it, usually outside a
wall with the robot out of sight. :class:`DebugView` points the camera down at the robot
from above the walls and keeps following it, and draws 2D geometry (world frame, drawn a
little above the floor) as debug items: polygons, points and polylines, each under a
name so the next frame replaces the previous one instead of piling up. Redrawing costs
the GUI a frame, so callers refresh a few times per second, not every physics step.

In a headless (``DIRECT``) client nothing is drawn and every call returns at once.

Examples
--------
>>> from sim.client import SimClient
>>> with SimClient() as sim:
...     view = DebugView(sim)
...     view.follow((1.0, 2.0, 0.5))
...     view.draw_polylines("map", [[(0.0, 0.0), (1.0, 0.0)]], [(1.0, 0.0, 0.0)])
...     view.items
{}
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from sim.client import SimClient

__all__ = ["CAMERA_DISTANCE", "CAMERA_PITCH_DEG", "DRAW_HEIGHT", "DebugView"]

CAMERA_DISTANCE = 5.5
"""Metres from the camera to the robot: with the pitch below, well above 2.5 m walls."""

CAMERA_PITCH_DEG = -80.0
"""Camera pitch (degrees, negative looks down): nearly top-down, a little perspective."""

DRAW_HEIGHT = 0.05
"""Height (m) above the floor at which 2D geometry is drawn."""

Colour = tuple[float, float, float]


class DebugView:
    """Follow the robot with the GUI camera and draw named 2D items (world frame).

    Parameters
    ----------
    sim
        The client; in ``DIRECT`` mode the view does nothing.
    distance, pitch_deg
        Camera distance (m) and pitch (degrees) while following.

    Examples
    --------
    >>> from sim.client import SimClient
    >>> with SimClient() as sim:
    ...     DebugView(sim).active
    False
    """

    def __init__(
        self, sim: SimClient, *, distance: float = CAMERA_DISTANCE,
        pitch_deg: float = CAMERA_PITCH_DEG,
    ) -> None:
        self.sim = sim
        self.active = bool(sim.gui)
        self.distance = float(distance)
        self.pitch_deg = float(pitch_deg)
        self.items: dict[str, list[int]] = {}

    def follow(self, pose: ArrayLike) -> None:
        """Point the camera at the robot pose ``(x, y, theta)``, looking along its heading."""
        if not self.active:
            return
        x, y, theta = np.asarray(pose, dtype=float).reshape(3).tolist()
        # PyBullet's camera yaw 0 looks along +y; the robot's heading theta is from +x.
        self.sim.bullet.resetDebugVisualizerCamera(
            cameraDistance=self.distance,
            cameraYaw=math.degrees(theta) - 90.0,
            cameraPitch=self.pitch_deg,
            cameraTargetPosition=[x, y, 0.0],
        )

    def draw_polylines(
        self, name: str, polylines: Sequence[ArrayLike], colours: Sequence[Colour],
        *, closed: bool = False, width: float = 2.0,
    ) -> None:
        """Draw ``polylines`` (``(N, 2)`` each, world frame) under ``name``, replacing its last.

        ``colours`` gives one RGB triple (0-1) per polyline; ``closed`` also joins the last
        vertex to the first (polygons).
        """
        if not self.active:
            return
        segments = []
        for line, colour in zip(polylines, colours, strict=True):
            points = np.asarray(line, dtype=float).reshape(-1, 2)
            if closed and len(points) > 2:
                points = np.vstack([points, points[:1]])
            segments.extend(
                (start, end, colour) for start, end in itertools.pairwise(points)
            )
        bullet = self.sim.bullet
        old = self.items.get(name, [])
        ids = []
        for index, (start, end, colour) in enumerate(segments):
            args = dict(lineFromXYZ=[*start.tolist(), DRAW_HEIGHT],
                        lineToXYZ=[*end.tolist(), DRAW_HEIGHT],
                        lineColorRGB=list(colour), lineWidth=width)
            if index < len(old):
                args["replaceItemUniqueId"] = old[index]
            ids.append(bullet.addUserDebugLine(**args))
        for item in old[len(segments):]:
            bullet.removeUserDebugItem(item)
        self.items[name] = ids

    def draw_points(self, name: str, points: ArrayLike, colour: Colour, *, size: float = 3.0
                    ) -> None:
        """Draw ``(N, 2)`` world points under ``name`` (e.g. laser returns), replacing its last."""
        if not self.active:
            return
        xy = np.asarray(points, dtype=float).reshape(-1, 2)
        xy = xy[np.isfinite(xy).all(axis=1)]
        bullet = self.sim.bullet
        old = self.items.pop(name, [])
        if len(xy) == 0:
            for item in old:
                bullet.removeUserDebugItem(item)
            return
        positions = np.column_stack([xy, np.full(len(xy), DRAW_HEIGHT)]).tolist()
        # Replaced in place: removing first would leave the GUI a frame without the points.
        replace = {"replaceItemUniqueId": old[0]} if old else {}
        item = bullet.addUserDebugPoints(
            positions, [list(colour)] * len(positions), size, **replace
        )
        self.items[name] = [item]

    def clear(self) -> None:
        """Remove every item drawn."""
        if self.active:
            for ids in self.items.values():
                for item in ids:
                    self.sim.bullet.removeUserDebugItem(item)
        self.items = {}
