"""The standard's personnel-detection test: a test piece on the path; the vehicle must stop.

ISO 3691-4 (as commonly quoted, :data:`worlds.spec.TEST_PIECE_SIZES`) asks a driverless
truck to detect a test piece in its path and stop before touching it: a 200 mm cylinder
lying across the path (a person lying down) and a 70 mm one standing upright (a leg).
:func:`piece_trial` puts one on the straight path of the emergence corridor
(:func:`scenarios.results.emergence.sized_corridor`: the protective field as long and
wide as the formula asks for the vehicle at its speed, the warning field the same, so
no slowdown comes first), ``PIECE_X`` metres from the start, a lying piece's axis at
right angles to the path, drives the vehicle at it and reports what happened: the
vehicle stands, or it touches the piece, which is then a ``contact`` infraction of the
run like any other (never hidden).

Whether the vehicle can see the piece at all is geometry: its safety laser's scan plane
must lie below the piece's top (:mod:`scenarios.spec.pieces`). The Pioneer's LMS100
scans at 0.35 m, over the lying piece; the trial runs such a pairing all the same (the
scenario says ``safety.unseen_test_pieces``) and reports ``seen = False`` beside the
contact that follows. A laser with a blind zone (the LMS100 sees nothing nearer than
0.5 m) loses a piece that its stop brings closer than that: the field clears, the vehicle
drives on, and that contact is reported too.

Examples
--------
>>> from robots.presets import LGV
>>> trial = piece_trial(LGV, speed=1.0, kind="upright")
>>> trial.seen, trial.contact, trial.gap > 0.0
(True, False, True)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import shapely

from robots.presets import UGVSpec
from scenarios.bench.testbench import Testbench
from scenarios.results.emergence import sized_corridor
from scenarios.spec.pieces import piece_sightings
from scenarios.spec.scenario import SafetySettings, ScenarioSpec
from semistatic.frames import transform_points
from semistatic.params import MapperParams
from worlds.spec import TestPieceSpec, WorldSpec

__all__ = ["PIECE_X", "PieceTrial", "piece_corridor", "piece_trial"]

PIECE_X = 3.0
"""Where (m along the straight path) the test piece's centre stands: the LGV reaches
1 m/s in about 0.5 m, and the field reaches it well after that."""

STANDING_TIME = 2.0
"""Seconds the vehicle must stand still before the trial ends: it stays stopped."""

STANDSTILL = 1e-3
"""Speed (m/s) below which the vehicle counts as standing."""


@dataclass(frozen=True)
class PieceTrial:
    """One trial: a ``kind`` test piece in the path of ``robot`` at ``speed`` (m/s).

    ``seen``: the safety laser's scan plane cuts the piece; ``contact``: the vehicle
    touched it (a ``contact`` infraction); ``gap`` (m): the distance between the vehicle's
    footprint and the piece's when the trial ended; ``stops``: the run's protective stops
    (:mod:`scenarios.bench.safety_record`); ``infractions``: ``(kind, detail)`` pairs;
    ``min_separation`` (m): the least footprint distance to the piece the record kept.
    """

    robot: str
    kind: str
    speed: float
    seen: bool
    contact: bool
    gap: float
    stops: tuple[dict, ...]
    infractions: tuple[tuple[str, str], ...]
    min_separation: float | None


def piece_corridor(robot: UGVSpec, speed: float, kind: str) -> WorldSpec:
    """Return the sized corridor with one ``kind`` test piece (standard size) on the path.

    Examples
    --------
    >>> from robots.presets import LGV
    >>> piece = piece_corridor(LGV, 1.0, "lying").test_pieces[0]
    >>> piece.name, [round(b, 3) for b in piece.footprint().bounds]
    ('lying', [2.9, -0.3, 3.1, 0.3])
    """
    # A lying piece's axis at right angles to the path (along y), as the standard lays it.
    piece = TestPieceSpec(kind, kind, (PIECE_X, 0.0, math.pi / 2))
    return dataclasses.replace(sized_corridor(robot, speed), name="test_piece",
                               test_pieces=(piece,),
                               description="scenarios.results.pieces.piece_corridor")


def _gap(robot: UGVSpec, pose: np.ndarray, piece: TestPieceSpec) -> float:
    """Return the distance (m) between the vehicle's footprint at ``pose`` and the piece's."""
    footprint = shapely.Polygon(transform_points(pose, np.asarray(robot.footprint, dtype=float)))
    return float(shapely.distance(footprint, piece.footprint()))


def piece_trial(robot: UGVSpec, speed: float, kind: str, *, seed: int = 0,
                policy: str = "conservative", time_limit: float = 40.0) -> PieceTrial:
    """Drive ``robot`` at ``speed`` (m/s) toward a ``kind`` test piece; report what happened.

    The trial ends once the vehicle has stood still for ``STANDING_TIME`` s (stopped
    before the piece or pressed against it), when its lap ends (it drove past), or after
    ``time_limit`` s of simulated time.
    """
    spec = ScenarioSpec(name="test_piece", world="test_piece", robot=robot.name, laps=1,
                        seed=seed, policy=policy, lap_timeout=time_limit,
                        safety=SafetySettings(undersized_fields=True, unseen_test_pieces=True),
                        mapper=MapperParams(hausdorff_restriction="projection"))
    world = piece_corridor(robot, speed, kind)
    piece = world.test_pieces[0]
    (sighting,) = piece_sightings(spec, world, robot)
    with Testbench(spec, world=world, robot=robot) as bench:
        bench.reset(seed=seed)
        moved, still = False, 0
        standing = round(STANDING_TIME / bench.time_step)
        while not bench.done and still < standing:
            bench.step()
            moving = abs(float(bench.true_twist[0])) >= STANDSTILL
            moved = moved or moving
            still = still + 1 if moved and not moving else 0
        gap = _gap(robot, bench.true_pose, piece)
        record = bench.fleet[0].log.safety_record
    infractions = tuple((item["kind"], item["detail"]) for item in record.infractions)
    contact = any(kind == "contact" for kind, _ in infractions)
    return PieceTrial(robot.name, kind, float(speed), sighting.seen, contact, gap,
                      tuple(record.protective_stops), infractions,
                      record.min_separation["test_piece"])
