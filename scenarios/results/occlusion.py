"""Occlusion trials: a worker steps out from behind a box the vehicle has mapped.

An occlusion scenario (``occlusion_hall``, ``warehouse_occlusion``) switches on one
person with ``trigger = "distance"`` (:mod:`scenarios.bench.triggers`) who waits hidden
behind a box and steps into the lane when the vehicle's front is ``d`` metres (along its
path) before the crossing, in every lap. Lap 1 maps the box; from lap 2 on the adaptive
policy no longer slows down for it, so the vehicle meets the worker faster.

:func:`occlusion_trial` runs the scenario with emergence distance ``d`` and reports the
*last* lap, the one with a map: contact (an infraction, never hidden), the least
separation, the vehicle's measured speed when the worker set off, the lap time.

Predicted safe emergence distance (:func:`predicted_distance`): the worker reaches the
protective field's lane (half-width ``W/2`` about the path, plus the body radius ``r``)
after walking ``w`` metres of the route at ``v_p``, ``t_enter = w / v_p``; then
:func:`scenarios.results.emergence.emergence_bound` with the measured speed ``v``:
``v (t_enter + T) + B(v) + max(r, c)``. A box that hides the worker until it is nearly in
the lane makes ``t_enter`` short, which is the hazard.

Measured (:func:`safe_emergence`): the least swept ``d`` with no contact in any seed.
It bisects a sorted grid, which assumes that emerging farther ahead is never less safe
than emerging nearer (the vehicle has more room); :class:`EmergenceSearch` keeps every
trial, so the contact just below the boundary is on record.

Examples
--------
>>> from scenarios.spec.load import load_scenario
>>> spec = load_scenario("occlusion_hall")
>>> # 0.7 m east out from behind the pallet, then north from y = -1.46 m until the body
>>> # (r = 0.25 m) reaches the 0.45 m half-width of the protective field: 0.76 m.
>>> round(walk_to_lane(spec), 3)
1.46
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from scenarios.bench.observer import Observer
from scenarios.bench.testbench import Testbench
from scenarios.bench.triggers import crossing_on_path
from scenarios.results.emergence import emergence_bound
from scenarios.spec.field_sizing import stop_model
from scenarios.spec.layout import robot_preset, scenario_world
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import path_segments
from worlds.checks import build_spline
from worlds.spec import PersonSpec, WorldSpec

__all__ = ["EmergenceSearch", "OcclusionTrial", "hiding_person", "occlusion_trial",
           "predicted_distance", "safe_emergence", "walk_to_lane"]

LANE_POINTS = 2001
"""Points of the path polyline the lane is buffered about."""


@dataclass(frozen=True)
class OcclusionTrial:
    """One occlusion trial, its last lap: what the vehicle did and what followed.

    ``speed_at_emergence`` (m/s) is the vehicle's when the worker set off (``None``: the
    trigger never fired); ``infractions`` are the last lap's ``(kind, detail)`` pairs.
    """

    policy: str
    distance: float
    seed: int
    contact: bool
    min_separation: float | None
    speed_at_emergence: float | None
    lap_time_s: float
    infractions: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class EmergenceSearch:
    """A policy's measured safe emergence distance (m; ``None``: none in the grid) and trials."""

    policy: str
    safe_distance: float | None
    trials: tuple[OcclusionTrial, ...]


class _EmergenceSpeed(Observer):
    """Record the vehicle's speed when ``person`` leaves its first waypoint, per lap."""

    def __init__(self, person: PersonSpec) -> None:
        self.start = np.asarray(person.waypoints[0], dtype=float)
        self.name = person.name
        self.speeds: dict[int, float] = {}

    def on_tick(self, vehicle) -> None:
        if vehicle.lap in self.speeds:
            return
        xy = vehicle.person_positions.get(self.name)
        if xy is not None and float(np.hypot(*(np.asarray(xy) - self.start))) > 1e-6:
            self.speeds[vehicle.lap] = float(vehicle.true_twist[0])


def hiding_person(spec: ScenarioSpec) -> PersonSpec:
    """Return the scenario's one person with a ``distance`` trigger (the hiding worker).

    Raises ``ValueError`` when the scenario switches on no such person, or several.
    """
    hiding = [p for p in scenario_world(spec).active_people if p.trigger == "distance"]
    if len(hiding) != 1:
        raise ValueError(
            f"{spec.source}: people: an occlusion scenario switches on exactly one person with "
            f"trigger = \"distance\", found {[p.name for p in hiding]}"
        )
    return hiding[0]


def _world_with_distance(spec: ScenarioSpec, distance: float) -> WorldSpec:
    world = scenario_world(spec)
    name = hiding_person(spec).name
    people = tuple(dataclasses.replace(p, trigger_distance=float(distance)) if p.name == name
                   else p for p in world.people)
    return dataclasses.replace(world, people=people)


def occlusion_trial(spec: ScenarioSpec, distance: float, *, policy: str,
                    seed: int | None = None) -> OcclusionTrial:
    """Run ``spec`` with the worker emerging ``distance`` m ahead; report the last lap."""
    if seed is not None:
        spec = dataclasses.replace(spec, seed=int(seed))
    speeds = _EmergenceSpeed(hiding_person(spec))
    with Testbench(spec, world=_world_with_distance(spec, distance), policy=policy) as bench:
        bench.add_observer(speeds)
        log = bench.run()
    last = spec.laps
    infractions = tuple((item["kind"], item["detail"])
                        for item in log.safety_record.infractions if item["lap"] == last)
    separation = log.safety_record.min_separation.get("person")
    return OcclusionTrial(
        policy=policy, distance=float(distance), seed=spec.seed,
        contact=any(kind == "contact" for kind, _ in infractions),
        min_separation=None if separation is None else float(separation),
        speed_at_emergence=speeds.speeds.get(last), lap_time_s=log.laps[-1].duration_s,
        infractions=infractions,
    )


def walk_to_lane(spec: ScenarioSpec) -> float:
    """Return the route length (m) the worker walks before its body reaches the lane.

    The lane is the band about the path as wide as the protective field of the segment the
    worker crosses; the body reaches it when its centre is within half that width plus its
    radius of the path.
    """
    world = scenario_world(spec)
    person = hiding_person(spec)
    path = build_spline(world.path)
    s, _, _, _ = crossing_on_path(path, person.waypoints)
    segment = next(seg for seg in path_segments(world, path) if seg.start_s <= s <= seg.end_s)
    lateral = segment.fields.protective[:, 1]
    reach = max(abs(float(lateral.min())), float(lateral.max())) + person.radius
    line = shapely.LineString(path.pose(np.linspace(0.0, path.length, LANE_POINTS))[:, :2])
    route = shapely.LineString(np.asarray(person.waypoints, dtype=float))
    entered = route.intersection(line.buffer(reach, quad_segs=64))
    if entered.is_empty:
        raise ValueError(f"{spec.source}: people.{person.name}: the route never reaches the "
                         f"lane (within {reach:.2f} m of the path)")
    return float(shapely.line_locate_point(route, shapely.points(shapely.get_coordinates(
        entered))).min())


def predicted_distance(spec: ScenarioSpec, speed: float) -> float:
    """Return the predicted safe emergence distance (m) at vehicle speed ``speed`` (m/s)."""
    robot = robot_preset(spec.robot, file=spec.source)
    person = hiding_person(spec)
    t_enter = walk_to_lane(spec) / person.speed
    return emergence_bound(robot, stop_model(spec, robot), speed, t_enter, person.radius)


def safe_emergence(spec: ScenarioSpec, distances: Sequence[float], *, policy: str,
                   seeds: Sequence[int] = (0,),
                   progress: Callable[[OcclusionTrial], None] | None = None,
                   ) -> EmergenceSearch:
    """Bisect the sorted grid ``distances`` for the least ``d`` with no contact in any seed."""
    grid = sorted(float(d) for d in distances)
    trials: list[OcclusionTrial] = []
    verdicts: dict[int, bool] = {}

    def safe(index: int) -> bool:
        if index not in verdicts:
            runs = [occlusion_trial(spec, grid[index], policy=policy, seed=seed)
                    for seed in seeds]
            for run in runs:
                trials.append(run)
                if progress is not None:
                    progress(run)
            verdicts[index] = not any(run.contact for run in runs)
        return verdicts[index]

    if not safe(len(grid) - 1):
        return EmergenceSearch(policy, None, tuple(trials))
    unsafe, known_safe = -1, len(grid) - 1   # invariant: grid[known_safe] is safe
    while known_safe - unsafe > 1:
        middle = (unsafe + known_safe) // 2
        if safe(middle):
            known_safe = middle
        else:
            unsafe = middle
    return EmergenceSearch(policy, grid[known_safe], tuple(trials))
