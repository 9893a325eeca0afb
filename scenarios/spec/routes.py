"""Which vehicles a scenario drives, and each one's route through the world's path segments.

A scenario without ``[[vehicles]]`` drives one vehicle, the scenario's ``robot``, from the
path start (:func:`fleet_vehicles`). A vehicle that starts at another segment drives the
same closed loop with its knots and segments rotated to begin there
(:func:`route_from`): the periodic spline through the same knots in the same cyclic
order is the same curve. A vehicle's ``route`` (segment names in driving order) may also
be a part of the path, an open route (:func:`vehicle_route`). Whatever its route, a
vehicle keeps each segment's map in the fleet's frame of that segment
(:func:`fleet_frames`), so the vehicles share segment maps by name.

Examples
--------
>>> from scenarios.spec.load import load_scenario
>>> [vehicle.name for vehicle in fleet_vehicles(load_scenario("pal1"))]
['robot']
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from scenarios.spec.layout import robot_preset
from scenarios.spec.scenario import ScenarioSpec, VehicleSpec
from scenarios.spec.segments import PathSegment
from semistatic.errors import SpecError
from semistatic.validation import did_you_mean
from worlds.spec import WorldSpec

__all__ = [
    "SINGLE_VEHICLE",
    "check_route",
    "check_vehicles",
    "fleet_frames",
    "fleet_vehicles",
    "route_from",
    "vehicle_route",
]

SINGLE_VEHICLE = "robot"
"""Name of the one vehicle of a scenario without ``[[vehicles]]``."""


def fleet_vehicles(spec: ScenarioSpec) -> tuple[VehicleSpec, ...]:
    """Return the scenario's vehicles, each with its robot preset filled in.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
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


def check_route(world: WorldSpec, route: Sequence[str]) -> tuple[int, str] | None:
    """Return ``(index, what is wrong)`` for the first bad name of ``route``, or ``None``.

    A route names the world's path segments in driving order, each one the segment that
    follows the one before on the path (wrapping round a closed path), none twice.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("warehouse")
    >>> check_route(world, ["north_west", "turn_northwest"]) is None
    True
    >>> check_route(world, ["south_west", "turn_southeast"])   # skips south_east
    (1, "segment 'turn_southeast' does not follow 'south_west' (next on the path: 'south_east')")
    """
    names = [segment.name for segment in world.path.segments]
    for index, name in enumerate(route):
        if name not in names:
            return index, (f"no segment {name!r} in world {world.name!r}"
                           f"{did_you_mean(name, names)}; segments: {', '.join(names)}")
        if name in route[:index]:
            return index, f"segment {name!r} is on the route twice"
        if index == 0:
            continue
        previous = names.index(route[index - 1])
        if previous + 1 == len(names) and not world.path.closed:
            return index, (f"the path of world {world.name!r} is open: no segment follows "
                           f"{route[index - 1]!r}")
        following = names[(previous + 1) % len(names)]
        if name != following:
            return index, (f"segment {name!r} does not follow {route[index - 1]!r} "
                           f"(next on the path: {following!r})")
    return None


def vehicle_route(world: WorldSpec, vehicle: VehicleSpec) -> WorldSpec:
    """Return ``world`` with the path ``vehicle`` drives (its ``route`` or ``start_segment``).

    A route of every segment of a closed path is the loop from its first segment; a
    shorter one is an open path through those segments' knots (the vehicle is carried
    back to its start after each lap). The route must pass :func:`check_route`.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("warehouse")
    >>> part = vehicle_route(world, VehicleSpec("a", route=("north_east", "north_west")))
    >>> [s.name for s in part.path.segments], part.path.closed, part.path.knots[0]
    (['north_east', 'north_west'], False, (33.0, 22.2))
    """
    if not vehicle.route:
        return route_from(world, vehicle.start_segment)
    problem = check_route(world, vehicle.route)
    if problem is not None:
        raise ValueError(f"route[{problem[0]}]: {problem[1]}")
    path = world.path
    base = route_from(world, vehicle.route[0]) if path.closed else world
    names = [segment.name for segment in base.path.segments]
    first = names.index(vehicle.route[0])
    chosen = base.path.segments[first:first + len(vehicle.route)]
    if path.closed and len(chosen) == len(names):
        return base
    offset = chosen[0].start_knot
    knots = base.path.knots[offset:chosen[-1].end_knot + 1]
    segments = tuple(
        dataclasses.replace(segment, start_knot=segment.start_knot - offset,
                            end_knot=segment.end_knot - offset)
        for segment in chosen
    )
    return dataclasses.replace(world, path=dataclasses.replace(
        base.path, knots=knots, segments=segments, closed=False))


def fleet_frames(own: Sequence[PathSegment],
                 fleet: Sequence[PathSegment]) -> tuple[PathSegment, ...]:
    """Return a vehicle's segments with the fleet's frames and safety areas, by name.

    A vehicle's own spans along its route (``start_s``, ``end_s``, ``index``) stay; the
    local map frame (``origin``) and safety areas are the world path's, so a segment map
    means the same to every vehicle whichever route (or rotated loop) it drives.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> from scenarios.spec.segments import path_segments
    >>> world = load_world("warehouse")
    >>> fleet = path_segments(world)
    >>> own = path_segments(route_from(world, "east"))
    >>> mine = fleet_frames(own, fleet)
    >>> mine[0].name, mine[0].start_s, mine[0].origin is fleet[3].origin
    ('east', 0.0, True)
    """
    by_name = {segment.name: segment for segment in fleet}
    return tuple(
        dataclasses.replace(by_name[segment.name], index=segment.index,
                            start_s=segment.start_s, end_s=segment.end_s)
        for segment in own
    )


def check_vehicles(spec: ScenarioSpec, world: WorldSpec) -> None:
    """Raise :class:`SpecError` if a vehicle's preset or start segment does not exist.

    A vehicle starting elsewhere than the path start needs a closed path.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> from scenarios.spec.layout import scenario_world
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
        problem = check_route(world, vehicle.route)
        if problem is not None:
            raise SpecError(spec.source, f"{where}.route[{problem[0]}]", problem[1])
        start = vehicle.start_segment
        problem = check_route(world, [start] if start else [])
        if problem is not None:
            raise SpecError(spec.source, f"{where}.start_segment", problem[1])
        if start and start != names[0] and not world.path.closed:
            raise SpecError(
                spec.source, f"{where}.start_segment",
                f"world {world.name!r} has an open path: every vehicle starts at its start "
                f"(segment {names[0]!r}); leave start_segment out",
            )
