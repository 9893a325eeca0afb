"""Watching a run in PyBullet's window: a copy of the scene seen from above, and drawings.

The physics runs headless; with ``SimClient(gui=True)`` a second, GUI server
(``sim.display``) only shows it. :class:`DebugView` copies the physics server's bodies
there (their visual shapes, once) and their poses (:meth:`DebugView.sync`, a few times
per simulated second), points the camera straight down, and draws 2D geometry (world
frame, a little above the floor) as debug items: polygons, points, polylines and text,
each under a name so the next frame replaces the previous one instead of piling up.

Every command to the GUI server may wait for its render thread, so the view sends only
what changed: a body that did not move, a line or a text that is the same as last time
costs nothing.

PyBullet's GUI camera is a perspective camera with a fixed 90 degree vertical field of
view (no orthographic mode, no zoom): the view looks straight down (pitch -89.9 degrees;
-90 exactly leaves its look-at matrix no 'up') from just as far as the drawn area needs.
From ``d`` metres up a 2.5 m wall's top is drawn ``2.5 / (d - 2.5)`` of its distance from
the centre further out (three quarters for sim1, seen from ~6 m) and hides the floor
beside it, so the copies are flattened to at most :data:`FLAT_HEIGHT`: the window shows
a floor plan, with the bodies' footprints exact.

The window's rendering stays off except in :meth:`DebugView.show`, which renders one
frame with everything sent since the last one.

In a headless client nothing is drawn and every call returns at once.

Examples
--------
>>> from sim.client import SimClient
>>> with SimClient() as sim:
...     view = DebugView(sim)
...     view.look_at((0.0, 0.0, 10.0, 8.0))
...     view.draw_polylines("map", [[(0.0, 0.0), (1.0, 0.0)]], [(1.0, 0.0, 0.0)])
...     view.items
{}
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from sim.client import SimClient

__all__ = ["CAMERA_PITCH_DEG", "DRAW_HEIGHT", "FLAT_HEIGHT", "TEXT_HEIGHT", "DebugView", "dotted",
           "fit_distance"]

CAMERA_PITCH_DEG = -89.9
"""Camera pitch (degrees): straight down; exactly -90 leaves PyBullet's camera no 'up'."""

DRAW_HEIGHT = 0.05
"""Height (m) above the floor at which 2D geometry is drawn."""

FLAT_HEIGHT = 0.1
"""Highest (m) a body's copy in the window stands: the top-down view stays a floor plan."""

TEXT_HEIGHT = 0.3
"""Height (m) of text anchors: above the flattened copies, so none hides a label."""

_DEFAULT_PROJECTION = (0.75, 0, 0, 0, 0, 1.0) + (0,) * 10
"""The GUI's projection (1024 x 768 window, 90 degrees vertical), if it gives none."""

_MOVED = 1e-4
"""A body's pose change (m, or quaternion component) below which it is not re-sent."""

_FRAMES_SHOWN = 2
"""Commands :meth:`DebugView.show` sends with rendering on: one pass of the GUI's loop each."""

Colour = tuple[float, float, float]


def fit_distance(half_width: float, half_height: float, projection: Sequence[float]) -> float:
    """Return the camera distance at which a top-down view shows a window of this size.

    ``projection`` is the GUI's OpenGL projection matrix (16 numbers, column-major, as
    ``getDebugVisualizerCamera`` gives it): at distance ``d`` a perspective camera sees
    ``d / P[0]`` to each side and ``d / P[5]`` up and down of its target.

    Examples
    --------
    >>> import math
    >>> f = 1.0 / math.tan(math.radians(30.0))     # 60 degrees vertical field of view
    >>> round(fit_distance(5.0, 5.0, [f / 1.5, 0, 0, 0, 0, f] + [0] * 10), 3)
    8.66
    """
    return max(half_width * projection[0], half_height * projection[5])


def dotted(
    polylines: Sequence[ArrayLike], colours: Sequence[Colour], *, closed: bool = False,
    spacing: float = 0.03,
) -> tuple[np.ndarray, np.ndarray]:
    """Return dots ``(N, 2)`` along ``polylines`` at most ``spacing`` apart, and their colours.

    ``colours`` gives one RGB triple per polyline; ``closed`` also joins the last vertex
    to the first.

    Examples
    --------
    >>> dots, rgb = dotted([[(0.0, 0.0), (0.1, 0.0)]], [(1.0, 0.0, 0.0)], spacing=0.05)
    >>> dots[:, 0].round(3).tolist(), rgb.shape
    ([0.0, 0.05, 0.1], (3, 3))
    """
    dots, dot_colours = [np.empty((0, 2))], [np.empty((0, 3))]
    for line, colour in zip(polylines, colours, strict=True):
        points = np.asarray(line, dtype=float).reshape(-1, 2)
        if closed and len(points) > 2:
            points = np.vstack([points, points[:1]])
        for start, end in itertools.pairwise(points):
            count = max(2, int(np.ceil(np.linalg.norm(end - start) / spacing - 1e-9)) + 1)
            dots.append(start + np.linspace(0.0, 1.0, count)[:, None] * (end - start))
            dot_colours.append(np.tile(np.asarray(colour, dtype=float), (count, 1)))
    return np.vstack(dots), np.vstack(dot_colours)


class DebugView:
    """Mirror the physics bodies in the GUI server, aim its camera and draw named items.

    Parameters
    ----------
    sim
        The client; without a display (``gui=False``) the view does nothing.

    Examples
    --------
    >>> from sim.client import SimClient
    >>> with SimClient() as sim:
    ...     DebugView(sim).active
    False
    """

    def __init__(self, sim: SimClient) -> None:
        self.sim = sim
        self.display = getattr(sim, "display", None)
        self.active = self.display is not None
        self.items: dict[str, list[int]] = {}
        self._drawn: dict[str, list[tuple]] = {}  # what each item shows, to skip repeats
        # physics body id -> (its visual shapes' data, [(link, display body, last pose)])
        self._copies: dict[int, tuple[tuple, list | None]] = {}
        self._tick: int | None = None  # the empty text show() re-sends

    # ------------------------------------------------------------------ camera

    def look_at(self, window: Sequence[float]) -> None:
        """Look straight down at ``window = (x_min, y_min, x_max, y_max)`` (m), all in view.

        The world's +x points right and +y up on screen.
        """
        if not self.active:
            return
        x_min, y_min, x_max, y_max = (float(v) for v in window)
        width, height, _, projection = self.display.getDebugVisualizerCamera()[:4]
        if width > 0 and projection[5] > 0.0:
            # The horizontal scale from the window's aspect: with rendering off, the GUI
            # can report a matrix from before its window had its size (P[0] = P[5]).
            projection = (projection[5] * height / width, 0, 0, 0, 0, projection[5])
        else:
            projection = _DEFAULT_PROJECTION
        distance = fit_distance(0.5 * (x_max - x_min), 0.5 * (y_max - y_min), projection)
        # PyBullet's camera yaw 0 with the pitch straight down puts +y at the top.
        self.display.resetDebugVisualizerCamera(
            cameraDistance=distance, cameraYaw=0.0, cameraPitch=CAMERA_PITCH_DEG,
            cameraTargetPosition=[0.5 * (x_min + x_max), 0.5 * (y_min + y_max), 0.0],
        )

    def show(self) -> None:
        """Render the window with everything sent so far; it keeps showing that frame.

        The display's rendering stays off between these frames (``SimClient`` opens it
        so): its render thread would otherwise redraw the unchanged scene as fast as it
        can, taking a core from the simulation under software rendering. Its loop
        handles one command from us per pass and renders at the end of each pass while
        rendering is on: two commands after switching it on make sure a whole frame
        with the latest items was rendered before it is switched off (with none, the
        window kept showing frames several redraws old).
        """
        if not self.active:
            return
        display = self.display
        display.configureDebugVisualizer(display.COV_ENABLE_RENDERING, 1)
        if self._tick is None:
            self._tick = display.addUserDebugText("", [0.0, 0.0, 0.0])
        for _ in range(_FRAMES_SHOWN):
            # a text that shows nothing, re-sent: a command the render thread handles
            display.addUserDebugText("", [0.0, 0.0, 0.0], replaceItemUniqueId=self._tick)
        display.configureDebugVisualizer(display.COV_ENABLE_RENDERING, 0)

    # ------------------------------------------------------------------ bodies

    def sync(self) -> None:
        """Copy new bodies to the display, drop removed ones, re-send the ones that moved."""
        if not self.active:
            return
        physics = self.sim.bullet
        present = {physics.getBodyUniqueId(k) for k in range(physics.getNumBodies())}
        for body in list(self._copies):
            if body not in present:
                self._drop(body)
        for body in sorted(present):
            shapes = tuple(physics.getVisualShapeData(body))
            if body in self._copies and self._copies[body][0] != shapes:
                self._drop(body)  # pybullet re-used the id of a removed body
            if body not in self._copies:
                self._copies[body] = (shapes, self._copy(body, shapes))
            copy = self._copies[body][1]
            if copy is None:
                continue
            target, sent = copy
            position, orientation = physics.getBasePositionAndOrientation(body)
            pose = (*position, *orientation)
            if sent is None or max(abs(a - b) for a, b in zip(pose, sent, strict=True)) > _MOVED:
                self.display.resetBasePositionAndOrientation(target, position, orientation)
                copy[1] = pose

    def _copy(self, body: int, shapes: tuple) -> list | None:
        """Create ``body``'s visual-only copy in the display: ``[its id, last pose sent]``.

        One display body per physics body, its links' shapes fixed where they are now
        relative to the base: a pose update is one command (wheels do not turn in a
        floor plan). ``None`` when it has nothing to show (the floor plane).
        """
        physics = self.sim.bullet
        base = physics.getBasePositionAndOrientation(body)
        to_base = physics.invertTransform(*base)
        visuals, frames = [], []
        for shape in shapes:
            visual = self._visual(shape)
            if visual is None:
                continue
            link = shape[1]
            if link < 0:
                frame = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
            else:  # the link's centre of mass: visual frames are given relative to it
                frame = physics.multiplyTransforms(*to_base, *physics.getLinkState(body, link)[:2])
            visuals.append(visual)
            frames.append(frame)
        if not visuals:
            return None
        more = len(visuals) - 1
        target = self.display.createMultiBody(
            baseMass=0.0, baseVisualShapeIndex=visuals[0],
            linkMasses=[0.0] * more, linkCollisionShapeIndices=[-1] * more,
            linkVisualShapeIndices=visuals[1:],
            linkPositions=[f[0] for f in frames[1:]],
            linkOrientations=[f[1] for f in frames[1:]],
            linkInertialFramePositions=[(0.0, 0.0, 0.0)] * more,
            linkInertialFrameOrientations=[(0.0, 0.0, 0.0, 1.0)] * more,
            linkParentIndices=[0] * more, linkJointTypes=[self.display.JOINT_FIXED] * more,
            linkJointAxis=[(0.0, 0.0, 1.0)] * more,
        )
        return [target, None]

    def _visual(self, shape: tuple) -> int | None:
        """Create the display's visual shape of one ``getVisualShapeData`` entry, flattened."""
        display = self.display
        kind, dims, mesh, position, orientation, rgba = shape[2:8]
        dims, position = list(dims), list(position)
        upright = abs(orientation[0]) < 1e-6 and abs(orientation[1]) < 1e-6
        tall = {display.GEOM_BOX: 2, display.GEOM_CYLINDER: 0}.get(kind)
        if upright and tall is not None and dims[tall] > FLAT_HEIGHT:
            # Flattened, standing on the floor as the original does.
            position[2] *= FLAT_HEIGHT / dims[tall]
            dims[tall] = FLAT_HEIGHT
        if kind == display.GEOM_BOX:
            args = dict(halfExtents=[0.5 * d for d in dims])
        elif kind in (display.GEOM_CYLINDER, display.GEOM_CAPSULE):
            args = dict(length=dims[0], radius=dims[1])
        elif kind == display.GEOM_SPHERE:
            args = dict(radius=dims[0])
        elif kind == display.GEOM_MESH and mesh:
            args = dict(fileName=mesh.decode(), meshScale=dims)
        else:  # planes have no visual; meshes built from vertices cannot be read back
            return None
        return display.createVisualShape(
            kind, rgbaColor=list(rgba), visualFramePosition=position,
            visualFrameOrientation=list(orientation), **args,
        )

    def _drop(self, body: int) -> None:
        copy = self._copies.pop(body)[1]
        if copy is not None:
            self.display.removeBody(copy[0])

    # ----------------------------------------------------------------- drawing

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
        lines = []
        for line, colour in zip(polylines, colours, strict=True):
            points = np.asarray(line, dtype=float).reshape(-1, 2)
            if closed and len(points) > 2:
                points = np.vstack([points, points[:1]])
            heights = np.full((len(points), 1), DRAW_HEIGHT)
            points = np.hstack([points, heights]).tolist()
            colour = list(colour)
            lines.extend(
                dict(lineFromXYZ=points[k], lineToXYZ=points[k + 1], lineColorRGB=colour,
                     lineWidth=width)
                for k in range(len(points) - 1)
            )
        self._replace(name, self.display.addUserDebugLine, lines)

    def draw_dotted(
        self, name: str, polylines: Sequence[ArrayLike], colours: Sequence[Colour],
        *, closed: bool = False, spacing: float = 0.03, size: float = 3.0,
    ) -> None:
        """Draw ``polylines`` as dots ``spacing`` (m) apart under ``name``: one GUI command.

        For what changes at every redraw (fields that move with the robot, a map that
        grows): :meth:`draw_polylines` sends a command per segment, and each may wait for
        a frame of the GUI.

        Examples
        --------
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     DebugView(sim).draw_dotted("field", [[(0, 0), (1, 0), (1, 1)]], [(1, 0, 0)])
        """
        if not self.active:
            return
        self.draw_points(name, *dotted(polylines, colours, closed=closed, spacing=spacing),
                         size=size)

    def draw_points(self, name: str, points: ArrayLike, colour: Colour | ArrayLike, *,
                    size: float = 3.0) -> None:
        """Draw ``(N, 2)`` world points under ``name`` (e.g. laser returns), replacing its last.

        ``colour`` is one RGB triple or ``(N, 3)``, one per point.
        """
        if not self.active:
            return
        xy = np.asarray(points, dtype=float).reshape(-1, 2)
        rgb = np.broadcast_to(np.asarray(colour, dtype=float), (len(xy), 3))
        keep = np.isfinite(xy).all(axis=1)
        xy, rgb = xy[keep], rgb[keep]
        positions = np.column_stack([xy, np.full(len(xy), DRAW_HEIGHT)]).tolist()
        calls = [dict(pointPositions=positions, pointColorsRGB=rgb.tolist(),
                      pointSize=size)] if positions else []
        self._replace(name, self.display.addUserDebugPoints, calls)

    def draw_texts(self, name: str, texts: Sequence[tuple[str, ArrayLike, Colour]],
                   *, size: float = 1.0) -> None:
        """Draw ``(text, (x, y), colour)`` labels under ``name`` (left-aligned at ``(x, y)``)."""
        if not self.active:
            return
        calls = [
            dict(text=text, textPosition=[*np.asarray(xy, dtype=float).tolist()[:2], TEXT_HEIGHT],
                 textColorRGB=list(colour), textSize=size)
            for text, xy, colour in texts
        ]
        self._replace(name, self.display.addUserDebugText, calls)

    def _replace(self, name: str, add, calls: list[dict]) -> None:
        """Show ``calls``' items under ``name``: re-send only those that changed."""
        old, shown = self.items.get(name, []), self._drawn.get(name, [])
        ids = []
        for index, args in enumerate(calls):
            key = tuple(_frozen(v) for v in args.values())
            if index < len(old):
                if shown[index] == key:
                    ids.append(old[index])
                    continue
                # In place: removing first would leave the GUI a frame without the item.
                args = {**args, "replaceItemUniqueId": old[index]}
            ids.append(add(**args))
        for item in old[len(calls):]:
            self.display.removeUserDebugItem(item)
        self.items[name] = ids
        self._drawn[name] = [tuple(_frozen(v) for v in args.values()) for args in calls]

    def clear(self) -> None:
        """Remove every item drawn."""
        if self.active:
            for ids in self.items.values():
                for item in ids:
                    self.display.removeUserDebugItem(item)
        self.items, self._drawn = {}, {}


def _frozen(value):
    """Return ``value`` hashable and comparable (nested lists as tuples)."""
    if isinstance(value, list):
        return tuple(_frozen(v) for v in value)
    return value
