"""Safe emergence distance: how far ahead a person may step into the path without contact.

A person stands beside a straight path, outside the protective field, and steps into the
vehicle's lane when the vehicle's front is ``d`` metres (along the path) before the
person's crossing point (``trigger = "distance"``, :mod:`scenarios.bench.triggers`); the
person then stands in the lane for a few seconds, as Sick's sizing assumes a person who
sees the danger does, and walks on. The *safe emergence distance* is the least ``d``
after which no contact follows.

Predicted: the person reaches the protective field ``t_enter = (y0 - r - W/2) / v_p``
after stepping out, the scanner confirms within its response time, the vehicle brakes;
it stands ``v (t_enter + T) + B(v)`` after the emergence point (:class:`robots.stopping.
StopModel`). The person standing in the lane must be ``r`` ahead of its front, and still
seen by the safety laser (``c`` ahead of its front: the mount plus
:func:`robots.stopping.visible_distance`, which a laser with a blind zone needs), or the
vehicle, seeing nothing, drives on once its field clears:

    d_safe = v (t_enter + T) + B(v) + max(r, c).

The trial's warning field is its protective field: no slowdown before the stop.

Measured: :func:`emergence_trial` runs one trial, :func:`safe_emergence_distance` sweeps
``d`` in steps over several seeds. A contact is never hidden: every trial reports its
infractions.

Examples
--------
>>> from robots.presets import PIONEER3DX
>>> trial = emergence_trial(PIONEER3DX, speed=0.4, distance=1.5)
>>> trial.contact, trial.infractions
(False, ())
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robots.presets import UGVSpec
from robots.stopping import StopModel, Supplements, visible_distance
from scenarios.bench.testbench import Testbench
from scenarios.spec.field_sizing import required_size, stop_model
from scenarios.spec.scenario import SafetySettings, ScenarioSpec
from semistatic.params import MapperParams
from worlds.spec import PathSpec, PersonSpec, PostSpec, SegmentSpec, WallSpec, WorldSpec

__all__ = ["CROSSING_X", "EmergenceTrial", "emergence_bound", "emergence_corridor",
           "emergence_trial", "predicted_safe_emergence", "safe_emergence_distance",
           "sized_corridor"]

CROSSING_X = 4.5
"""Where (m along the straight path) the person steps into the lane."""

PATH_LENGTH = 7.0
PERSON_RADIUS = 0.25
WALKING_SPEED = 1.0
"""m/s: a brisk walk (ISO 13855 takes 1.6 m/s for an approaching body)."""

STANDING_CLEARANCE = 0.3
"""Metres between the waiting person's body and the protective field's side."""

STANDING_TIME = 3.0
"""Seconds the person stands in the lane before walking on to the far side."""


@dataclass(frozen=True)
class EmergenceTrial:
    """One trial: emergence distance (m), contact with the person, the run's infractions.

    ``infractions`` are ``(kind, detail)`` pairs; ``min_separation`` the least distance (m)
    between the vehicle and the person.
    """

    distance: float
    seed: int
    contact: bool
    min_separation: float | None
    infractions: tuple[tuple[str, str], ...]


def _supplements(robot: UGVSpec) -> Supplements:
    laser = robot.safety_laser.laser
    # The corridor's posts stand 2.4 m from the path: no reflector supplement.
    return Supplements(laser.general_supplement, 0.0, 0.15 if robot.ground_clearance < 0.12
                       else 0.0)


def sized_corridor(robot: UGVSpec, speed: float) -> WorldSpec:
    """Return the straight corridor of the trials, empty: fields sized by the formula.

    The protective field is as long and wide as the standard's formula asks for ``robot``
    at ``speed`` (m/s) on this path (:func:`scenarios.spec.field_sizing.required_size`);
    the warning field is the same (no slowdown before a stop, the worst case).
    :mod:`scenarios.results.pieces` puts a test piece on its path.
    """
    spec = ScenarioSpec(name="emergence", world="emergence", robot=robot.name)
    length, width = required_size(stop_model(spec, robot), _supplements(robot), robot, speed)
    front = max(x for x, _ in robot.footprint)
    half = 2.5
    x0, x1 = -3.0, PATH_LENGTH + 3.0
    walls = (WallSpec((x0, -half), (x1, -half)), WallSpec((x0, half), (x1, half)),
             WallSpec((x0, -half), (x0, half)), WallSpec((x1, -half), (x1, half)))
    xs = (-2.2, -0.4, 1.3, 3.4, 4.9, 7.1, 8.6)
    posts = (*(PostSpec(x, -2.39) for x in xs),
             *(PostSpec(x + 0.7 + 0.13 * (i % 3), 2.39) for i, x in enumerate(xs)),
             PostSpec(x0 + 0.11, 0.4), PostSpec(x1 - 0.11, -0.6))
    protective = ((front, -width / 2), (front + length, -width / 2),
                  (front + length, width / 2), (front, width / 2))
    # The warning field is the protective one: no slowdown before the stop, the worst case.
    segment = SegmentSpec("straight", 0, 2, warning=protective, protective=protective)
    path = PathSpec(((0.0, 0.0), (PATH_LENGTH / 2, 0.0), (PATH_LENGTH, 0.0)), (segment,),
                    speed=speed)
    return WorldSpec(name="emergence", walls=walls, posts=posts, boxes=(), people=(),
                     path=path, description="scenarios.results.emergence")


def emergence_corridor(robot: UGVSpec, speed: float, distance: float,
                       walking_speed: float = WALKING_SPEED) -> WorldSpec:
    """Return the corridor of one trial: formula-sized fields, a person to the right."""
    corridor = sized_corridor(robot, speed)
    protective = corridor.path.segments[0].protective
    width = max(y for _, y in protective) - min(y for _, y in protective)
    y0 = width / 2 + PERSON_RADIUS + STANDING_CLEARANCE
    # Out into the lane, stand there (as Sick's sizing assumes), then on to the far side.
    person = PersonSpec("worker", ((CROSSING_X, -y0), (CROSSING_X, 0.0), (CROSSING_X, y0)),
                        radius=PERSON_RADIUS, speed=walking_speed, trigger="distance",
                        trigger_distance=distance, dwell=(0.0, STANDING_TIME, 0.0))
    return dataclasses.replace(corridor, people=(person,))


def emergence_bound(robot: UGVSpec, model: StopModel, speed: float, t_enter: float,
                    person_radius: float) -> float:
    """Return the least safe emergence distance (m) for a person who needs ``t_enter`` s.

    ``speed`` (m/s) is the vehicle's when the person sets off, ``t_enter`` the time the
    person then takes to reach the protective field: ``v (t_enter + T) + B(v) + max(r, c)``
    (see the module docstring).

    Examples
    --------
    >>> from robots.presets import PIONEER3DX
    >>> from robots.stopping import StopModel
    >>> model = StopModel(scanner_response_s=0.04, command_latency_s=0.0,
    ...                   control_period_s=0.0, deceleration=1.0)
    >>> # Standing still, only the LMS100's 0.5 m blind zone counts: it sees a 0.25 m body
    >>> # from 0.61 m; its mount is 0.12 m ahead of the axle, the front 0.1825 m.
    >>> round(emergence_bound(PIONEER3DX, model, 0.0, 1.0, 0.25), 3)
    0.548
    """
    front = float(np.asarray(robot.footprint, dtype=float)[:, 0].max())
    mount, laser = robot.safety_laser, robot.safety_laser.laser
    # Standing, the vehicle must still see the person, or it drives on.
    seen = mount.x + visible_distance(laser.range_min, laser.angular_resolution,
                                      person_radius, SafetySettings().min_points) - front
    return speed * (t_enter + model.reaction_time) + model.braking_distance(speed) \
        + max(person_radius, seen)


def predicted_safe_emergence(robot: UGVSpec, speed: float,
                             walking_speed: float = WALKING_SPEED) -> float:
    """Return the predicted safe emergence distance (m) of the corridor's trial."""
    spec = ScenarioSpec(name="emergence", world="emergence", robot=robot.name)
    model = stop_model(spec, robot)
    _, width = required_size(model, _supplements(robot), robot, speed)
    y0 = width / 2 + PERSON_RADIUS + STANDING_CLEARANCE
    t_enter = max(0.0, y0 - PERSON_RADIUS - width / 2) / walking_speed
    return emergence_bound(robot, model, speed, t_enter, PERSON_RADIUS)


def emergence_trial(robot: UGVSpec, speed: float, distance: float, *, seed: int = 0,
                    policy: str = "conservative",
                    walking_speed: float = WALKING_SPEED) -> EmergenceTrial:
    """Run one trial with emergence distance ``distance`` (m); report what happened."""
    spec = ScenarioSpec(name="emergence", world="emergence", robot=robot.name, laps=1,
                        seed=seed, policy=policy, lap_timeout=120.0, people=("worker",),
                        safety=SafetySettings(undersized_fields=True),
                        mapper=MapperParams(hausdorff_restriction="projection"))
    world = emergence_corridor(robot, speed, distance, walking_speed)
    with Testbench(spec, world=world, robot=robot) as bench:
        log = bench.run()
    record = log.safety_record
    infractions = tuple((item["kind"], item["detail"]) for item in record.infractions)
    contact = any(kind == "contact" for kind, _ in infractions)
    return EmergenceTrial(distance, seed, contact, record.min_separation["person"], infractions)


def safe_emergence_distance(robot: UGVSpec, speed: float, distances: Sequence[float],
                            seeds: Sequence[int], *, policy: str = "conservative",
                            walking_speed: float = WALKING_SPEED,
                            ) -> tuple[float | None, list[EmergenceTrial]]:
    """Return the safe emergence distance among ``distances`` and every trial.

    The least swept distance with no contact in any seed such that every larger one is
    contact-free too (``None``: even the largest saw a contact).
    """
    trials = [emergence_trial(robot, speed, d, seed=seed, policy=policy,
                              walking_speed=walking_speed)
              for d in distances for seed in seeds]
    safe = {d: not any(t.contact for t in trials if t.distance == d) for d in distances}
    ordered = sorted(distances)
    boundary = None
    for d in reversed(ordered):
        if not safe[d]:
            break
        boundary = d
    return boundary, trials

