"""People walking kinematically through the world along their waypoints.

A person is a static cylinder built by ``sim.world_builder.SimWorld`` and teleported
(``resetBasePositionAndOrientation``) to where its route puts it at time ``t``. The route
is the polyline ``PersonSpec.waypoints`` walked at ``speed`` from ``start_time``, standing
``dwell`` seconds at a waypoint where asked; a ``loop`` person walks back to the first
waypoint and starts again, any other person stays at the last waypoint. Before
``start_time`` a person is not in the scene: it is parked below the floor, out of every
scan plane and out of the robot's reach.

A ``per_lap`` person's clock restarts with every lap (``update(t, lap_start=...)``), so it
crosses the path at the same point of every lap; other people follow the run's clock. A
person whose walk a vehicle triggers (``PersonSpec.trigger``) stands at its first
waypoint until the caller says when the trigger fired (``update(..., triggered=...)``).
A person limited to some ``laps`` is parked in the others (``update(..., lap=...)``).

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
import math
import time
from collections.abc import Mapping

import numpy as np

from worlds.spec import PersonSpec

__all__ = ["PARKED_Z", "People", "Walk", "parked_place", "person_position"]

PARKED_Z = -50.0
"""Height (m) of the body frame of a person who is not in the scene (below the floor)."""


def parked_place(person: PersonSpec) -> tuple[float, float, float]:
    """Return where ``person``'s body waits out of the scene: below its first waypoint.

    Examples
    --------
    >>> from worlds.spec import PersonSpec
    >>> parked_place(PersonSpec("ann", ((1.0, 2.0), (3.0, 2.0))))
    (1.0, 2.0, -50.0)
    """
    x, y = person.waypoints[0]
    return (float(x), float(y), PARKED_Z)


def person_position(person: PersonSpec, t: float) -> np.ndarray | None:
    """Return the ``(x, y)`` of ``person`` at time ``t`` on its clock, ``None`` before it starts.

    ``t`` is run time, or lap time for a ``per_lap`` person (the caller picks the clock).

    Examples
    --------
    >>> from worlds.spec import PersonSpec
    >>> bob = PersonSpec("bob", ((0.0, 0.0), (1.0, 0.0)), speed=0.5, loop=True)
    >>> [person_position(bob, t).tolist() for t in (1.0, 3.0, 4.5)]
    [[0.5, 0.0], [0.5, 0.0], [0.25, 0.0]]
    >>> eve = PersonSpec("eve", ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0)), dwell=(0.0, 2.0, 0.0))
    >>> [person_position(eve, t).tolist() for t in (0.5, 2.5, 3.5)]   # stands 2 s at the corner
    [[0.5, 0.0], [1.0, 0.0], [1.0, 0.5]]
    """
    xy = Walk(person).position(t)
    return None if xy is None else np.array(xy)


class Walk:
    """One person's route as keyframes: where it is at each time of its clock.

    The route's waypoints (back to the first for a ``loop`` person) are reached at the
    times walking at ``speed`` gives, and held for their ``dwell``; in between the person
    moves in a straight line. Floats, not numpy: ``People.update`` asks at every physics
    step.
    """

    def __init__(self, person: PersonSpec) -> None:
        self.person = person
        points = [tuple(map(float, point)) for point in person.waypoints]
        dwell = list(person.dwell) or [0.0] * len(points)
        if person.loop and len(points) > 1:
            points.append(points[0])
            dwell.append(0.0)
        times, keyframes, clock = [], [], 0.0
        for index, point in enumerate(points):
            if index:
                (x0, y0), (x1, y1) = points[index - 1], point
                clock += math.hypot(x1 - x0, y1 - y0) / person.speed
            times.append(clock)
            keyframes.append(point)
            if dwell[index] > 0.0:
                clock += dwell[index]
                times.append(clock)
                keyframes.append(point)
        self.times, self.keyframes, self.total = times, keyframes, clock

    def position(self, t: float) -> tuple[float, float] | None:
        """Return ``(x, y)`` at ``t`` on this person's clock, ``None`` before the start."""
        person = self.person
        if t < person.start_time:
            return None
        if self.total <= 0.0:
            return self.keyframes[0]
        clock = t - person.start_time
        clock = clock % self.total if person.loop else min(clock, self.total)
        k = min(max(bisect.bisect_right(self.times, clock) - 1, 0), len(self.times) - 2)
        t0, t1 = self.times[k], self.times[k + 1]
        fraction = 0.0 if t1 == t0 else (clock - t0) / (t1 - t0)
        (x0, y0), (x1, y1) = self.keyframes[k], self.keyframes[k + 1]
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

    A person limited to lap 2 is parked in lap 1:

    >>> import dataclasses
    >>> late = PersonSpec("ann", ((0.0, 0.0), (4.0, 0.0)), laps=(2,))
    >>> with SimClient() as sim:
    ...     people = People(SimWorld(sim, dataclasses.replace(spec, people=(late,))))
    ...     people.update(12.0, lap_start=10.0, lap=1), people.update(12.0, 10.0, lap=2)
    ({'ann': None}, {'ann': array([2., 0.])})
    """

    def __init__(self, world) -> None:
        self.world = world
        self._sim = world.sim
        self._bullet = world.sim.bullet
        # The people built into the world are fixed when it is built.
        self._walks = [Walk(person) for person in world.people]
        self._ids = {walk.person.name: world.person_id(walk.person.name) for walk in self._walks}
        self._upright = self._bullet.getQuaternionFromEuler([0.0, 0.0, 0.0])
        # Where each body was last put (None: not yet, so the first update places all).
        self._placed: dict[str, tuple[float, float, float] | None] = dict.fromkeys(self._ids)
        # Built at its first waypoint, a person who sits out lap 1 would stand there while
        # the robot settles and re-localises before the first tick: park it now.
        for walk in self._walks:
            if not walk.person.acts_in(1):
                self._park(walk.person)

    def update(self, t: float, lap_start: float = 0.0,
               triggered: Mapping[str, float | None] | None = None,
               lap: int | None = None) -> dict[str, np.ndarray | None]:
        """Place every person where its route puts it at run time ``t``.

        ``lap_start`` is the run time at which the current lap began (the clock of
        ``per_lap`` people). ``triggered`` gives, for people a vehicle triggers, the run
        time their trigger fired (``None``: not yet; they stand at their first waypoint).
        ``lap`` (from 1) parks the people whose ``laps`` leave it out (``None``: none).
        Returns ``{name: (x, y) or None}``, ``None`` for people not in the scene.
        """
        positions: dict[str, np.ndarray | None] = {}
        for walk in self._walks:
            person = walk.person
            if lap is not None and not person.acts_in(lap):
                xy = None
            elif person.trigger != "time":
                fired = (triggered or {}).get(person.name)
                # Waiting for the trigger, then its delay: standing at the first waypoint.
                xy = walk.position(person.start_time if fired is None
                                   else max(t - fired, person.start_time))
            else:
                clock = t - lap_start if person.per_lap else t
                xy = walk.position(clock)
            if xy is None:
                positions[person.name] = None
                xyz = parked_place(person)
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

    def _park(self, person: PersonSpec) -> None:
        place = parked_place(person)
        self._bullet.resetBasePositionAndOrientation(self._ids[person.name], place, self._upright)
        self._placed[person.name] = place

    def refresh(self) -> None:
        """Take up the world's people anew (after ``SimWorld.replace_people``).

        Each person walks its new route from the next update; a parked person whose
        parked place changed (a new first waypoint) is moved there now, so the bodies
        stand where a world built with the new people would have parked them.
        """
        self._walks = [Walk(person) for person in self.world.people]
        for walk in self._walks:
            name, place = walk.person.name, parked_place(walk.person)
            placed = self._placed[name]
            if placed is not None and placed[2] == PARKED_Z and placed != place:
                self._park(walk.person)
