"""Safety figures of a run, from ground truth: separations, time to collision, stops, infractions.

:class:`SafetyRecorder` watches one vehicle (the bench attaches one to each) and keeps:

- the *minimum separation* between the vehicle's true footprint and each kind of object
  (``person``: body cylinders, every physics step; ``box``, ``vehicle`` and
  ``test_piece``, the footprints of the personnel-detection test pieces: at every safety
  scan), with where and when it happened;
- the *minimum time to collision*: separation over closing speed, while closing;
- every *protective stop*: speed when the protective field triggered, distance travelled
  until standstill and the separation to the nearest object (person, box, vehicle, test
  piece or wall) once standing;
- the time spent in each zone;
- a timestamped list of *infractions*: every ``contact`` (any body but the floor, as the
  contact monitor reports it), ``near_miss`` (a person closer than
  ``safety.near_miss_distance`` without contact), ``person_in_protective_while_moving``
  (a person inside the segment's protective field while the vehicle drives faster than
  ``safety.creep_speed`` and faster than it would if it had started braking one response
  time after the person entered: the field did not stop it as it should) and
  ``unnecessary_stop`` (a protective stop with nothing in the field but semi-static boxes
  the vehicle had mapped).

Nothing is smoothed away: every contact is an infraction. The figures go to
``log.safety_record`` and, through :func:`scenarios.results.outputs.summarize`, to the
``safety`` block of ``metrics.json``.

Examples
--------
>>> record = SafetyRecord()
>>> record.note_separation("person", 0.8, t=2.0, lap=1, where=(1.0, 0.0), name="walker")
>>> record.note_separation("person", 0.5, t=3.0, lap=1, where=(1.2, 0.0), name="walker")
>>> record.min_separation["person"], record.min_separation_at["person"]["t"]
(0.5, 3.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely

from robots.stopping import StopModel
from scenarios.bench.ground_truth import box_is_mapped
from scenarios.bench.observer import Observer
from scenarios.bench.records import ScanRecord
from semistatic.frames import inverse, transform_points

__all__ = ["INFRACTION_KINDS", "KINDS", "SafetyRecord", "SafetyRecorder", "merged_record"]

KINDS = ("person", "box", "vehicle", "test_piece")
"""The objects whose separation from the vehicle is kept."""

INFRACTION_KINDS = ("contact", "near_miss", "person_in_protective_while_moving",
                    "unnecessary_stop")
"""The kinds of infraction a run records (the module docstring says when)."""

STANDSTILL = 0.01
"""Speed (m/s) under which a stopping vehicle counts as standing."""

CLOSING = 0.01
"""Closing speed (m/s) under which a separation does not count towards time to collision."""

MAPPED_DISTANCE = 0.05
"""A reading this close (m) to a box outline is a reading of that box."""

BRAKING_SLACK = 0.1
"""Speed (m/s) a braking vehicle may run above its expected braking profile."""


@dataclass
class SafetyRecord:
    """The safety figures of one vehicle's run so far (see the module docstring)."""

    min_separation: dict[str, float | None] = field(
        default_factory=lambda: dict.fromkeys(KINDS))
    min_separation_at: dict[str, dict | None] = field(default_factory=lambda: dict.fromkeys(KINDS))
    min_ttc_s: float | None = None
    protective_stops: list[dict] = field(default_factory=list)
    time_in_zone_s: dict[str, float] = field(
        default_factory=lambda: {"free": 0.0, "warning": 0.0, "protective": 0.0})
    infractions: list[dict] = field(default_factory=list)

    def note_separation(self, kind: str, distance: float, *, t: float, lap: int,
                        where: tuple[float, float], name: str) -> None:
        """Keep ``distance`` (m) to a ``kind`` object if it is the smallest so far."""
        best = self.min_separation[kind]
        if best is None or distance < best:
            self.min_separation[kind] = round(float(distance), 4)
            self.min_separation_at[kind] = {"t": round(float(t), 4), "lap": int(lap),
                                            "x": round(float(where[0]), 3),
                                            "y": round(float(where[1]), 3), "object": name}

    def note_ttc(self, ttc: float) -> None:
        """Keep a time to collision (s) if it is the smallest so far."""
        if self.min_ttc_s is None or ttc < self.min_ttc_s:
            self.min_ttc_s = round(float(ttc), 4)

    def infraction(self, kind: str, *, t: float, vehicle: str, lap: int,
                   where: tuple[float, float], detail: str) -> None:
        """Add an infraction (one of :data:`INFRACTION_KINDS`) to the record."""
        if kind not in INFRACTION_KINDS:
            raise ValueError(f"infraction: kind must be one of {INFRACTION_KINDS}, got {kind!r}")
        self.infractions.append({"t": round(float(t), 4), "vehicle": vehicle, "lap": int(lap),
                                 "kind": kind, "x": round(float(where[0]), 3),
                                 "y": round(float(where[1]), 3), "detail": detail})

    def as_metrics(self) -> dict:
        """Return the record as ``metrics.json``'s ``safety`` keys."""
        return {
            "min_separation_m": dict(self.min_separation),
            "min_separation_at": dict(self.min_separation_at),
            "min_ttc_s": self.min_ttc_s,
            "protective_stops": list(self.protective_stops),
            "time_in_zone_s": {zone: round(seconds, 4)
                               for zone, seconds in self.time_in_zone_s.items()},
            "infractions": sorted(self.infractions, key=lambda item: item["t"]),
        }


class SafetyRecorder(Observer):
    """Observer of one vehicle (a :class:`~scenarios.bench.vehicle.Vehicle`) filling a record.

    Parameters
    ----------
    model
        How the vehicle stops (:class:`robots.stopping.StopModel`): when a person has been
        in the protective field for its reaction time, the vehicle must be braking at its
        deceleration.
    """

    def __init__(self, model: StopModel) -> None:
        self.record = SafetyRecord()
        self.response_time = model.reaction_time
        self.deceleration = model.deceleration
        self._footprint: shapely.Polygon | None = None
        self._last_contacts = 0
        self._separations: dict[tuple[str, str], tuple[float, float]] = {}
        self._near: set[str] = set()
        self._inside_since: dict[str, tuple[float, float]] = {}
        self._reported_inside: set[str] = set()
        self._zone = "free"
        self._stop: dict | None = None
        self._box_revision = -1
        self._boxes: dict[str, shapely.Polygon] = {}
        # Each protective field's reach from the footprint, by id (the field kept alive).
        self._reaches: dict[int, tuple[shapely.Polygon, float]] = {}

    # ------------------------------------------------------------------ hooks
    def on_lap_start(self, vehicle, lap: int) -> None:
        """Bind the footprint; forget what was near (the vehicle was carried back)."""
        self._footprint = shapely.Polygon(np.asarray(vehicle.robot.footprint, dtype=float))
        shapely.prepare(self._footprint)
        world = vehicle.world
        self._radii = {person.name: person.radius for person in world.people}
        self._walls = [shapely.Polygon(wall.corners()) for wall in world.walls]
        self._pieces = {piece.name: piece.footprint() for piece in world.test_pieces}
        vehicle.log.safety_record = self.record  # the live record: readable during the run
        self._reaches.clear()
        self._separations.clear()
        self._near.clear()
        self._inside_since.clear()
        self._stop = None

    def on_tick(self, vehicle) -> None:
        """Contacts, people's separations and the people inside the protective field."""
        contacts = vehicle.contacts.events
        if len(contacts) > self._last_contacts:
            for contact in contacts[self._last_contacts:]:
                self._contact(vehicle, contact)
            self._last_contacts = len(contacts)
        people = [(name, xy) for name, xy in vehicle.person_positions.items() if xy is not None]
        if people:
            self._people(vehicle, people)

    def on_scan(self, vehicle, record: ScanRecord) -> None:
        """Zones, stops, boxes and vehicles at every safety scan."""
        t = record.scan.stamp
        zone = vehicle.zone
        # Each scan stands for one scan period in its zone, as the lap logs count it.
        self.record.time_in_zone_s[zone] += 1.0 / vehicle.spec.rates.safety_hz
        pose = vehicle.true_pose
        speed = float(vehicle.true_twist[0])
        if zone == "protective" and self._zone != "protective":
            self._stop = {"t": round(t, 4), "lap": vehicle.lap, "speed": round(speed, 4),
                          "start": (float(pose[0]), float(pose[1]))}
            self._check_unnecessary(vehicle, record, pose)
        self._zone = zone
        if self._stop is not None and abs(speed) < STANDSTILL:
            self._standstill(vehicle, pose)
        self._boxes_and_vehicles(vehicle, pose, t)

    # ------------------------------------------------------------------ pieces
    def _contact(self, vehicle, contact) -> None:
        self.record.infraction(
            "contact", t=contact.time, vehicle=vehicle.name, lap=vehicle.lap,
            where=(float(contact.position[0]), float(contact.position[1])),
            detail=f"{contact.tag} {contact.name}, {contact.normal_force:.0f} N",
        )

    def _people(self, vehicle, people) -> None:
        pose = vehicle.true_pose
        t, lap = vehicle.sim_time, vehicle.lap
        radii = self._radii
        local = transform_points(inverse(pose), np.array([xy for _, xy in people], dtype=float))
        centres = shapely.points(local)
        distances = shapely.distance(self._footprint, centres)
        # The true twist costs an engine query and a cross product: asked only when a
        # person is near or inside (with a person in the scene it was a third of a tick).
        twist: list[float] = []

        def speed() -> float:
            if not twist:
                twist.append(float(vehicle.true_twist[0]))
            return twist[0]

        field = vehicle.segment.fields.protective_polygon
        reach = self._reach(field)
        settings = vehicle.spec.safety
        for (name, xy), centre, distance in zip(people, centres, distances, strict=True):
            separation = max(0.0, float(distance) - radii[name])
            where = (float(xy[0]), float(xy[1]))
            self.record.note_separation("person", separation, t=t, lap=lap, where=where,
                                        name=name)
            self._ttc(("person", name), separation, t)
            if separation < settings.near_miss_distance and separation > 0.0:
                if name not in self._near:
                    self._near.add(name)
                    self.record.infraction(
                        "near_miss", t=t, vehicle=vehicle.name, lap=lap, where=where,
                        detail=f"person {name} {separation:.3f} m from the vehicle at "
                               f"{speed():.2f} m/s")
            elif separation > 1.5 * settings.near_miss_distance:
                self._near.discard(name)
            # Farther than the field reaches from the footprint: not in it (no query).
            inside = distance <= reach + radii[name] \
                and shapely.distance(field, centre) <= radii[name]
            if inside and abs(speed()) > settings.creep_speed:
                since, entry_speed = self._inside_since.setdefault(name, (t, abs(speed())))
                late = t - since - self.response_time
                expected = entry_speed - self.deceleration * max(0.0, late)
                if late > 0.0 and abs(speed()) > expected + BRAKING_SLACK \
                        and name not in self._reported_inside:
                    self._reported_inside.add(name)
                    self.record.infraction(
                        "person_in_protective_while_moving", t=t, vehicle=vehicle.name,
                        lap=lap, where=where,
                        detail=f"person {name} in the protective field of segment "
                               f"{vehicle.segment.name} for {t - since:.2f} s at "
                               f"{speed():.2f} m/s")
            else:
                self._inside_since.pop(name, None)
                self._reported_inside.discard(name)

    def _reach(self, field: shapely.Polygon) -> float:
        """Return how far (m) ``field`` reaches from the footprint (its farthest vertex)."""
        key = id(field)
        if key not in self._reaches:
            vertices = shapely.points(shapely.get_coordinates(field))
            # A micrometre more: rounding never decides a person's place in the field.
            reach = float(shapely.distance(self._footprint, vertices).max()) + 1e-6
            self._reaches[key] = (field, reach)
        return self._reaches[key][1]

    def _ttc(self, key: tuple[str, str], separation: float, t: float) -> None:
        previous = self._separations.get(key)
        self._separations[key] = (separation, t)
        if previous is None or t <= previous[1]:
            return
        closing = (previous[0] - separation) / (t - previous[1])
        if closing > CLOSING:
            self.record.note_ttc(separation / closing)

    def _boxes_and_vehicles(self, vehicle, pose: np.ndarray, t: float) -> None:
        lap = vehicle.lap
        if self._box_revision != vehicle.layout_revision:
            self._box_revision = vehicle.layout_revision
            self._boxes = {box.name: shapely.Polygon(box.corners()) for box in vehicle.world.boxes}
        footprint = shapely.Polygon(transform_points(pose, shapely.get_coordinates(
            self._footprint)[:-1]))
        for kind, shapes in (("box", self._boxes), ("vehicle", _other_vehicles(vehicle)),
                             ("test_piece", self._pieces)):
            for name, shape in shapes.items():
                separation = float(shapely.distance(footprint, shape))
                nearest = shapely.shortest_line(footprint, shape).coords[1]
                self.record.note_separation(kind, separation, t=t, lap=lap, where=nearest,
                                            name=name)
                self._ttc((kind, name), separation, t)

    def _standstill(self, vehicle, pose: np.ndarray) -> None:
        stop, self._stop = self._stop, None
        footprint = shapely.Polygon(transform_points(pose, shapely.get_coordinates(
            self._footprint)[:-1]))
        candidates = {f"box {name}": shape for name, shape in self._boxes.items()}
        candidates |= {f"vehicle {name}": shape
                       for name, shape in _other_vehicles(vehicle).items()}
        candidates |= {f"person {name}": shapely.Point(xy).buffer(self._radii[name])
                       for name, xy in vehicle.person_positions.items() if xy is not None}
        candidates |= {f"test_piece {name}": shape for name, shape in self._pieces.items()}
        candidates |= {f"wall {index}": wall for index, wall in enumerate(self._walls)}
        distances = {name: float(shapely.distance(footprint, shape))
                     for name, shape in candidates.items()}
        nearest = min(distances, key=distances.get) if distances else None
        start = stop.pop("start")
        stop["travelled_m"] = round(math.hypot(pose[0] - start[0], pose[1] - start[1]), 4)
        stop["distance_to_object_m"] = round(distances[nearest], 4) if nearest else None
        stop["object"] = nearest
        self.record.protective_stops.append(stop)

    def _check_unnecessary(self, vehicle, record: ScanRecord, pose: np.ndarray) -> None:
        """Note a stop with nothing in the protective field but boxes the vehicle had mapped."""
        scan = record.scan
        points = scan.world_points()[scan.valid_mask()]
        field = shapely.Polygon(transform_points(
            pose, np.asarray(vehicle.segment.fields.protective, dtype=float)))
        inside = points[shapely.contains_xy(field, points[:, 0], points[:, 1])]
        if not len(inside) or not self._boxes:
            return
        local_maps = vehicle.local_maps.values()
        mapped = [name for name, box in self._boxes.items()
                  if box_is_mapped(local_maps, shapely.get_coordinates(box)[:-1])]
        if not mapped:
            return
        outlines = shapely.union_all([self._boxes[name].exterior for name in mapped])
        if bool(np.all(shapely.distance(outlines, shapely.points(inside)) <= MAPPED_DISTANCE)):
            self.record.infraction(
                "unnecessary_stop", t=scan.stamp, vehicle=vehicle.name, lap=vehicle.lap,
                where=(float(pose[0]), float(pose[1])),
                detail=f"only mapped boxes ({', '.join(mapped)}) in the protective field")


def _other_vehicles(vehicle) -> dict[str, shapely.Polygon]:
    """Return the true footprints of the fleet's other vehicles on the route, by name."""
    return {other.name: shapely.Polygon(transform_points(other.true_pose,
                                                         np.asarray(other.robot.footprint)))
            for other in vehicle.scene.fleet if other is not vehicle and not other.done}


def merged_record(records: list[SafetyRecord]) -> SafetyRecord:
    """Return one record for a fleet: least separations, every stop and infraction.

    Times to collision: the least; zone times: added up.

    Examples
    --------
    >>> a, b = SafetyRecord(), SafetyRecord()
    >>> a.note_ttc(2.0)
    >>> b.note_ttc(1.5)
    >>> merged_record([a, b]).min_ttc_s
    1.5
    """
    merged = SafetyRecord()
    for record in records:
        for kind in KINDS:
            at = record.min_separation_at[kind]
            if at is not None:
                merged.note_separation(kind, record.min_separation[kind], t=at["t"],
                                       lap=at["lap"], where=(at["x"], at["y"]),
                                       name=at["object"])
        if record.min_ttc_s is not None:
            merged.note_ttc(record.min_ttc_s)
        merged.protective_stops += record.protective_stops
        merged.infractions += record.infractions
        for zone, seconds in record.time_in_zone_s.items():
            merged.time_in_zone_s[zone] += seconds
    merged.protective_stops.sort(key=lambda stop: stop["t"])
    return merged
