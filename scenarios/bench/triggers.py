"""People whose walk a vehicle triggers: emergence distance, or timed to meet the vehicle.

A person with ``trigger = "distance"`` or ``"meet"`` (:class:`worlds.spec.PersonSpec`)
stands at the first waypoint until the vehicle it watches comes: :class:`PersonTriggers`
finds where the person's walk first crosses that vehicle's path once (e.g. out from
behind a box, along it, then into the lane), then at every step compares the vehicle's
progress with it.

- ``distance``: fires when the vehicle's front is ``trigger_distance`` along its path
  before the crossing (the person emerges ``d`` metres ahead of the vehicle).
- ``meet``: fires when the vehicle, at its path speed, would reach the point ``M`` of the
  crossing leg that lies ``(meet_at - 0.5)`` vehicle widths to the left of the path no
  sooner than the person walking there: the walk meets the vehicle's front at
  ``meet_at`` of its width (Euro NCAP's timing of pedestrian targets).

A ``per_lap`` person's trigger re-arms when the lap starts; a person limited to some
``laps`` fires only in those. The vehicle's progress and path speed are what the vehicle
itself knows (its follower); the geometry is the world's.

Warm starts (:mod:`scenarios.tuning.warm`) *hold* people: a held trigger does not fire,
so the person stands at the first waypoint, as every variation of its walk does until
its own trigger fires; :meth:`PersonTriggers.fire_ticks` says at which tick of a recorded
run that would have been.

Examples
--------
>>> import numpy as np
>>> from robots.path import SplinePath
>>> path = SplinePath([(0.0, 0.0), (5.0, 0.0), (10.0, 0.0)])
>>> crossing_on_path(path, ((6.0, -2.0), (6.0, 2.0)))   # s, walk, sine and cosine
(6.0, 2.0, 1.0, 0.0)
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import shapely

from robots.path import SplinePath
from worlds.spec import PersonSpec

__all__ = ["CROSSING_STEP", "Crossing", "PersonTriggers", "crossing_on_path"]

CROSSING_STEP = 0.01
"""Arc-length step (m) of the path polyline a first leg is intersected with."""


def crossing_on_path(path: SplinePath,
                     waypoints: tuple[tuple[float, float], ...],
                     ) -> tuple[float, float, float, float]:
    """Return where a person's walk first crosses ``path``.

    ``(s, walk, sine, cosine)``: the path's arc length at the crossing (m), the distance
    walked from the first waypoint to it along the route (m), and the sine and cosine of
    the angle from the path's heading to the crossing leg's (positive sine: the person
    walks to the path's left). Raises ``ValueError`` when no leg crosses the path.
    """
    count = max(2, math.ceil(path.length / CROSSING_STEP) + 1)
    poses = path.pose(np.linspace(0.0, path.length, count))
    line = shapely.LineString(poses[:, :2])
    route = np.asarray(waypoints, dtype=float).reshape(-1, 2)
    walked = 0.0
    for start, end in itertools.pairwise(route):
        crossing = shapely.intersection(line, shapely.LineString([start, end]))
        leg = end - start
        length = float(np.linalg.norm(leg))
        if crossing.is_empty or length == 0.0:
            walked += length
            continue
        point = np.asarray(shapely.get_coordinates(crossing)[0])
        s = float(line.project(shapely.Point(point)))
        heading = float(path.pose(s)[2])
        direction = leg / length
        sine = math.cos(heading) * direction[1] - math.sin(heading) * direction[0]
        cosine = math.cos(heading) * direction[0] + math.sin(heading) * direction[1]
        return (round(s, 6), round(walked + float(np.linalg.norm(point - start)), 6),
                round(float(sine), 6), round(float(cosine), 6) + 0.0)
    raise ValueError(f"the walk {route.tolist()} never crosses the path")


@dataclass(frozen=True)
class Crossing:
    """A triggered person's geometry against one vehicle's path.

    ``s`` is the arc length of the crossing on the vehicle's path, ``walk`` the distance
    from the first waypoint to it along the route, ``sine`` and ``cosine`` the crossing
    leg's angle to the path; ``front`` how far the vehicle's front is ahead of its
    reference point (m).
    """

    person: PersonSpec
    vehicle: object
    s: float
    walk: float
    sine: float
    cosine: float
    front: float

    def ahead(self, progress):
        """Return how far (m) the front is before the crossing at ``progress`` (or array)."""
        return self.s - (progress + self.front)


class PersonTriggers:
    """The trigger times of the people the vehicles of a scene trigger.

    Parameters
    ----------
    people
        Every person of the world (those with ``trigger = "time"`` are left alone).
    fleet
        The scene's vehicles (:class:`~scenarios.bench.vehicle.Vehicle`), the first one the
        default for ``trigger_vehicle``.
    """

    def __init__(self, people, fleet) -> None:
        self._fleet = fleet
        self._crossings = self._crossings_of(people)
        self.fired: dict[str, float | None] = {c.person.name: None for c in self._crossings}
        self.held: frozenset[str] = frozenset()
        self._lap_start: float | None = None

    def _crossings_of(self, people) -> list[Crossing]:
        fleet = self._fleet
        vehicles = {vehicle.name: vehicle for vehicle in fleet}
        crossings: list[Crossing] = []
        for person in people:
            if person.trigger == "time":
                continue
            vehicle = vehicles.get(person.trigger_vehicle) if person.trigger_vehicle \
                else fleet[0]
            if vehicle is None:
                raise ValueError(f"person {person.name}: no vehicle named "
                                 f"{person.trigger_vehicle!r} to trigger on")
            s, walk, sine, cosine = crossing_on_path(vehicle.path, person.waypoints)
            front = float(np.asarray(vehicle.robot.footprint)[:, 0].max())
            crossings.append(Crossing(person, vehicle, s, walk, sine, cosine, front))
        return crossings

    def __bool__(self) -> bool:
        return bool(self._crossings)

    @property
    def watched(self) -> tuple[str, ...]:
        """Return the names of the people a vehicle triggers."""
        return tuple(crossing.person.name for crossing in self._crossings)

    def replace_people(self, people) -> None:
        """Watch for ``people`` from now on; a person's fire time this lap is kept.

        For a run that goes on with new people (``SimWorld.replace_people``): the
        crossings are found anew, the fire times of the people still triggered stay, and
        no one is held any more.
        """
        self._crossings = self._crossings_of(people)
        self.fired = {c.person.name: self.fired.get(c.person.name) for c in self._crossings}
        self.held = frozenset()

    def hold(self, names) -> None:
        """Keep the triggers of the people ``names`` from firing until :meth:`replace_people`."""
        unknown = set(names) - set(self.watched)
        if unknown:
            raise ValueError(f"PersonTriggers: no triggered person named {sorted(unknown)}")
        self.held = frozenset(names)

    def fire_ticks(self, progress: np.ndarray, lap: int) -> dict[str, int | None]:
        """Return the tick of ``progress`` at which each person's trigger would fire.

        ``progress`` is the watched vehicle's progress along its path (m) at successive
        ticks of lap ``lap``, from its first, as :meth:`update` would read it (``NaN``
        while the vehicle waits or is done). ``None``: the person does not fire in those
        ticks (already fired, not in lap ``lap``, or its condition never holds). One
        vehicle only: every person must watch the first vehicle of the fleet.
        """
        progress = np.asarray(progress, dtype=float)
        ticks: dict[str, int | None] = {}
        for crossing in self._crossings:
            person = crossing.person
            if crossing.vehicle is not self._fleet[0]:
                raise ValueError(f"PersonTriggers.fire_ticks: person {person.name} watches "
                                 f"{person.trigger_vehicle}, not the first vehicle")
            # A person that fired earlier and does not re-arm with the lap stays fired.
            already = self.fired[person.name] is not None and not person.per_lap
            if already or not person.acts_in(lap):
                ticks[person.name] = None
                continue
            with np.errstate(invalid="ignore"):
                fire = self._fires(crossing, crossing.ahead(progress))
            fire &= ~np.isnan(progress)
            first = np.flatnonzero(fire)
            ticks[person.name] = int(first[0]) if first.size else None
        return ticks

    def update(self, t: float, lap_start: float, lap: int | None = None,
               ) -> dict[str, float | None]:
        """Fire the triggers whose condition holds at run time ``t``; return every fire time.

        In lap ``lap`` (from 1), people whose ``laps`` leave it out do not fire (``None``:
        every person may).
        """
        if lap_start != self._lap_start:
            self._lap_start = lap_start
            for crossing in self._crossings:
                if crossing.person.per_lap:
                    self.fired[crossing.person.name] = None
        for crossing in self._crossings:
            person, vehicle = crossing.person, crossing.vehicle
            if self.fired[person.name] is not None or vehicle.done or vehicle.waiting:
                continue
            if (lap is not None and not person.acts_in(lap)) or person.name in self.held:
                continue
            if self._fires(crossing, crossing.ahead(vehicle.follower.progress)):
                self.fired[person.name] = t
        return self.fired

    @classmethod
    def _fires(cls, crossing: Crossing, ahead):
        """Return whether the trigger fires with the front ``ahead`` (m, float or array)."""
        if crossing.person.trigger == "distance":
            return ahead <= crossing.person.trigger_distance
        return cls._meets(crossing, ahead)

    @staticmethod
    def _meets(crossing: Crossing, ahead):
        """Return whether the person must set off now to meet the vehicle at ``meet_at``."""
        person, vehicle = crossing.person, crossing.vehicle
        footprint = np.asarray(vehicle.robot.footprint, dtype=float)
        width = float(np.ptp(footprint[:, 1]))
        centre = 0.5 * float(footprint[:, 1].min() + footprint[:, 1].max())
        offset = centre + (person.meet_at - 0.5) * width   # left of the path, m
        if abs(crossing.sine) < 1e-6:
            return np.zeros_like(ahead, dtype=bool)  # a leg along the path never crosses it
        along_leg = offset / crossing.sine            # from the crossing to M, on the leg
        along_path = along_leg * crossing.cosine      # ... and M's place along the path
        person_time = person.start_time + (crossing.walk + along_leg) / person.speed
        vehicle_time = (ahead + along_path) / vehicle.follower.params.speed
        return vehicle_time <= person_time
