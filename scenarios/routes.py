"""Which vehicles a scenario drives, and each one's route: the world's path from its start.

A scenario without ``[[vehicles]]`` drives one vehicle, the scenario's ``robot``, from the
path start (:func:`fleet_vehicles`). A vehicle that starts at another segment drives the
same closed loop with its knots and segments rotated to begin there
(:func:`route_from`): the periodic spline through the same knots in the same cyclic
order is the same curve, so every vehicle's segments keep their names, their frames and
their safety areas (to rounding) and the vehicles can share segment maps by name.

Examples
--------
>>> from scenarios.load import load_scenario
>>> [vehicle.name for vehicle in fleet_vehicles(load_scenario("pal1"))]
['robot']
"""

from __future__ import annotations

import dataclasses

from scenarios.layout import robot_preset
from scenarios.spec import ScenarioSpec, VehicleSpec
from semistatic.errors import SpecError
from semistatic.validation import did_you_mean
from worlds.spec import WorldSpec

__all__ = ["SINGLE_VEHICLE", "check_vehicles", "fleet_vehicles", "route_from"]

SINGLE_VEHICLE = "robot"
"""Name of the one vehicle of a scenario without ``[[vehicles]]``."""


def fleet_vehicles(spec: ScenarioSpec) -> tuple[VehicleSpec, ...]:
    """Return the scenario's vehicles, each with its robot preset filled in.

    Examples
    --------
    >>> from scenarios.load import load_scenario
    >>> [(v.name, v.robot) for v in fleet_vehicles(load_scenario("warehouse_fleet"))]
    [('lgv1', 'lgv'), ('lgv2', 'lgv'), ('lgv3', 'lgv')]
    """
    robot = spec.robot if isinstance(spec.robot, str) else spec.robot.name
    if not spec.vehicles:
        return (VehicleSpec(SINGLE_VEHICLE, robot=robot),)
    return tuple(
        vehicle if vehicle.robot else dataclasses.replace(vehicle, robot=robot)
        for vehicle in spec.vehicles
    )


def route_from(world: WorldSpec, start_segment: str) -> WorldSpec:
    """Return ``world`` with its closed path starting at segment ``start_segment``.

    An empty name or the first segment returns ``world`` itself.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("warehouse")
    >>> rotated = route_from(world, "north_east")
    >>> [s.name for s in rotated.path.segments][:2], rotated.path.knots[0]
    (['north_east', 'north_west'], (33.0, 22.2))
    >>> route_from(world, "") is world
    True
    """
    path = world.path
    names = [segment.name for segment in path.segments]
    if not start_segment or start_segment == names[0]:
        return world
    index = names.index(start_segment)
    shift = path.segments[index].start_knot
    count = len(path.knots) - 1  # a closed path repeats its first knot at the end
    knots = tuple(path.knots[shift:count]) + tuple(path.knots[:shift]) + (path.knots[shift],)
    segments = []
    for segment in path.segments[index:] + path.segments[:index]:
        start = (segment.start_knot - shift) % count
        end = start + (segment.end_knot - segment.start_knot)
        segments.append(dataclasses.replace(segment, start_knot=start, end_knot=end))
    return dataclasses.replace(world, path=dataclasses.replace(path, knots=knots,
                                                               segments=tuple(segments)))


def check_vehicles(spec: ScenarioSpec, world: WorldSpec) -> None:
    """Raise :class:`SpecError` if a vehicle's preset or start segment does not exist.

    A vehicle starting elsewhere than the path start needs a closed path.

    Examples
    --------
    >>> from scenarios.load import load_scenario
    >>> from scenarios.layout import scenario_world
    >>> spec = load_scenario("warehouse_fleet")
    >>> check_vehicles(spec, scenario_world(spec))
    >>> bad = dataclasses.replace(spec, vehicles=(VehicleSpec("a", start_segment="eats"),))
    >>> check_vehicles(bad, scenario_world(spec))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: ...: vehicles[0].start_segment: no segment 'eats' in ...
    """
    names = [segment.name for segment in world.path.segments]
    for index, vehicle in enumerate(spec.vehicles):
        where = f"vehicles[{index}]"
        if vehicle.robot:
            try:
                robot_preset(vehicle.robot, file=spec.source)
            except SpecError as error:
                raise SpecError(spec.source, f"{where}.robot", error.message) from None
        start = vehicle.start_segment
        if start and start not in names:
            raise SpecError(
                spec.source, f"{where}.start_segment",
                f"no segment {start!r} in world {world.name!r}{did_you_mean(start, names)}; "
                f"segments: {', '.join(names)}",
            )
        if start and start != names[0] and not world.path.closed:
            raise SpecError(
                spec.source, f"{where}.start_segment",
                f"world {world.name!r} has an open path: every vehicle starts at its start "
                f"(segment {names[0]!r}); leave start_segment out",
            )
