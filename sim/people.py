"""People walking kinematically through the world along their waypoints.

A person is a static cylinder built by ``sim.world_builder.SimWorld`` and teleported
(``resetBasePositionAndOrientation``) to where its route puts it at time ``t``. The route
is the polyline ``PersonSpec.waypoints`` walked at ``speed`` from ``start_time``; a
``loop`` person walks back to the first waypoint and starts again, any other person stays
at the last waypoint. Before ``start_time`` a person is not in the scene: it is parked
below the floor, out of every scan plane and out of the robot's reach.

A ``per_lap`` person's clock restarts with every lap (``update(t, lap_start=...)``), so it
crosses the path at the same point of every lap; other people follow the run's clock.

Examples
--------
>>> from worlds.spec import PersonSpec
>>> ann = PersonSpec("ann", ((0.0, 0.0), (2.0, 0.0), (2.0, 2.0)), speed=1.0, start_time=1.0)
>>> person_position(ann, 0.5) is None
True
>>> [person_position(ann, t).tolist() for t in (1.0, 2.5, 4.0, 10.0)]
[[0.0, 0.0], [1.5, 0.0], [2.0, 1.0], [2.0, 2.0]]
"""

from __future__ import annotations

import bisect
import time

import numpy as np

from worlds.spec import PersonSpec

__all__ = ["PARKED_Z", "People", "person_position"]

PARKED_Z = -50.0
"""Height (m) of the body frame of a person who is not in the scene (below the floor)."""


def _route(person: PersonSpec) -> np.ndarray:
    points = np.asarray(person.waypoints, dtype=float).reshape(-1, 2)
    if person.loop and len(points) > 1:
        points = np.vstack([points, points[:1]])
    return points


def person_position(person: PersonSpec, t: float) -> np.ndarray | None:
    """Return the ``(x, y)`` of ``person`` at time ``t`` on its clock, ``None`` before it starts.

    ``t`` is run time, or lap time for a ``per_lap`` person (the caller picks the clock).

    Examples
    --------
    >>> from worlds.spec import PersonSpec
    >>> bob = PersonSpec("bob", ((0.0, 0.0), (1.0, 0.0)), speed=0.5, loop=True)
    >>> [person_position(bob, t).tolist() for t in (1.0, 3.0, 4.5)]
    [[0.5, 0.0], [0.5, 0.0], [0.25, 0.0]]
    """
    position = _Walk(person).position(t)
    return None if position is None else np.array(position)


class _Walk:
    """One person's route precomputed as floats, walked without numpy per call.

    ``People.update`` runs at every physics step; rebuilding the route's arc lengths with
    numpy each time cost more than the engine's teleport.
    """

    def __init__(self, person: PersonSpec) -> None:
        route = _route(person)
        steps = np.hypot(*np.diff(route, axis=0).T)
        arc = np.concatenate([[0.0], np.cumsum(steps)])
        self.person = person
        self.route = route.tolist()
        self.steps = steps.tolist()
        self.arc = arc.tolist()
        self.total = float(arc[-1])

    def position(self, t: float) -> tuple[float, float] | None:
        """Return ``(x, y)`` at ``t`` on this person's clock, ``None`` before the start."""
        person = self.person
        if t < person.start_time:
            return None
        if self.total <= 0.0:
            x, y = self.route[0]
            return x, y
        walked = person.speed * (t - person.start_time)
        walked = walked % self.total if person.loop else min(walked, self.total)
        leg = min(max(bisect.bisect_right(self.arc, walked) - 1, 0), len(self.steps) - 1)
        step = self.steps[leg]
        fraction = 0.0 if step == 0.0 else (walked - self.arc[leg]) / step
        (x0, y0), (x1, y1) = self.route[leg], self.route[leg + 1]
        return x0 + fraction * (x1 - x0), y0 + fraction * (y1 - y0)


class People:
    """Moves the person bodies of a ``SimWorld`` to their positions at a given time.

    A body is teleported only when its position changed since the last update: a
    person waiting for their start (parked) or standing at the end of their route
    costs no engine call.

    Parameters
    ----------
    world
        The ``sim.world_builder.SimWorld`` whose people to move.

    Examples
    --------
    >>> from sim.client import SimClient
    >>> from sim.world_builder import SimWorld
    >>> from worlds.spec import PathSpec, PersonSpec, SegmentSpec, WorldSpec
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
    >>> spec = WorldSpec(name="p", walls=(), posts=(), boxes=(),
    ...                  people=(PersonSpec("ann", ((0.0, 0.0), (4.0, 0.0)), speed=1.0),),
    ...                  path=path)
    >>> with SimClient() as sim:
    ...     people = People(SimWorld(sim, spec))
    ...     people.update(12.0, lap_start=10.0)["ann"].tolist()
    [2.0, 0.0]
    """

    def __init__(self, world) -> None:
        self.world = world
        self._sim = world.sim
        self._bullet = world.sim.bullet
        # The people built into the world are fixed when it is built.
        self._walks = [_Walk(person) for person in world.people]
        self._ids = {walk.person.name: world.person_id(walk.person.name) for walk in self._walks}
        self._upright = self._bullet.getQuaternionFromEuler([0.0, 0.0, 0.0])
        # Where each body was last put (None: not yet, so the first update places all).
        self._placed: dict[str, tuple[float, float, float] | None] = dict.fromkeys(self._ids)

    def update(self, t: float, lap_start: float = 0.0) -> dict[str, np.ndarray | None]:
        """Place every person where its route puts it at run time ``t``.

        ``lap_start`` is the run time at which the current lap began (the clock of
        ``per_lap`` people). Returns ``{name: (x, y) or None}``, ``None`` for people not
        yet in the scene.
        """
        positions: dict[str, np.ndarray | None] = {}
        for walk in self._walks:
            person = walk.person
            clock = t - lap_start if person.per_lap else t
            xy = walk.position(clock)
            if xy is None:
                positions[person.name] = None
                xyz = (float(person.waypoints[0][0]), float(person.waypoints[0][1]), PARKED_Z)
            else:
                positions[person.name] = np.array(xy)
                xyz = (xy[0], xy[1], 0.0)  # body frames sit on the floor
            if xyz != self._placed[person.name]:
                start = time.perf_counter()  # engine time, inline (see SimClient)
                self._bullet.resetBasePositionAndOrientation(
                    self._ids[person.name], xyz, self._upright
                )
                self._sim.engine_time_s += time.perf_counter() - start
                self._placed[person.name] = xyz
        return positions
