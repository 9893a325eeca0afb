"""The one validation pass a scenario gets before PyBullet starts, from a file or from code.

``semistatic check``, every command that runs a scenario (through
:func:`scenarios.spec.load.load_scenario`) and the
:class:`~scenarios.bench.testbench.Testbench` constructor (a spec or a world built in code,
a robot given) all call :func:`check_scenario`: what passes ``check`` starts lap 1.

Examples
--------
>>> import dataclasses
>>> from scenarios.spec.load import load_scenario
>>> from worlds.load import load_world
>>> spec = load_scenario("sim1")
>>> check_scenario(spec)
>>> world = load_world("sim1")
>>> into_wall = dataclasses.replace(world.boxes[0], pose=(3.0, -1.5, 0.0))
>>> check_scenario(spec, world=dataclasses.replace(world, boxes=(into_wall,), source="<memory>"))
Traceback (most recent call last):
...
semistatic.errors.SpecError: <memory>: boxes[0]: lap 1: box 'carton_aisle': overlaps walls[0]; \
and 1 more problem(s)
"""

from __future__ import annotations

from collections.abc import Sequence

from robots.presets import UGVSpec
from scenarios.spec.field_sizing import check_field_sizes
from scenarios.spec.layout import check_scenario_layout, enable_people, robot_preset, scenario_world
from scenarios.spec.pieces import check_piece_sightings
from scenarios.spec.routes import check_vehicles
from scenarios.spec.scenario import BoxMove, ScenarioSpec
from scenarios.spec.starts import check_starts
from worlds.spec import WorldSpec

__all__ = ["check_scenario"]


def check_scenario(
    spec: ScenarioSpec,
    *,
    world: WorldSpec | None = None,
    robot: UGVSpec | None = None,
    moves: Sequence[BoxMove] | None = None,
) -> None:
    """Raise :class:`~semistatic.errors.SpecError` for the first thing that stops a run.

    In order: every lap's layout (:func:`~scenarios.spec.layout.check_scenario_layout`),
    the fleet's vehicles and routes, every segment's protective field against the
    standard's formula, every test piece against every safety laser, and each vehicle's
    start (:func:`~scenarios.spec.starts.check_starts`). ``world`` replaces the world
    the scenario names (its people and box moves apply to it), ``robot`` the robot of a
    scenario without ``[[vehicles]]``; ``moves`` as in ``check_scenario_layout``.
    """
    check_scenario_layout(spec, moves=moves, world=world, robot=robot)
    if world is None:
        world = scenario_world(spec)
    else:
        world = enable_people(world, spec.people, file=spec.source)
    if spec.vehicles:
        check_vehicles(spec, world)
    if robot is not None and not spec.vehicles:
        presets = [robot]
    else:
        names = {vehicle.robot or spec.robot for vehicle in spec.vehicles} or {spec.robot}
        presets = [robot_preset(name, file=spec.source) for name in sorted(names)]
    for preset in presets:
        check_field_sizes(spec, world, preset)
    check_piece_sightings(spec, world, robot)
    check_starts(spec, world, robot)
