"""Stopping distances measured in the closed loop, beside the analytic model.

:func:`measure_stop` drives a vehicle preset down a straight corridor at a set speed and,
right after a safety scan, puts a box into its protective field: the worst moment, for
the scanner needs ``multiple_sampling`` more scans to confirm it. The distance the
vehicle travels from that moment to standstill is its measured stopping distance; the
model's is :meth:`robots.stopping.StopModel.distance` with the scenario's rates and the
vehicle's laser and brakes (:func:`scenarios.spec.field_sizing.stop_model`).

Examples
--------
>>> from robots.presets import PIONEER3DX
>>> stop = measure_stop(PIONEER3DX, speed=0.4)
>>> round(stop.predicted, 3), abs(stop.measured - stop.predicted) < 0.02
(0.14, True)
"""

from __future__ import annotations

from dataclasses import dataclass

from robots.presets import UGVSpec
from scenarios.bench.observer import Observer
from scenarios.bench.testbench import Testbench
from scenarios.spec.field_sizing import stop_model
from scenarios.spec.scenario import SafetySettings, ScenarioSpec
from semistatic.params import MapperParams
from worlds.spec import BoxSpec, PathSpec, PostSpec, SegmentSpec, WallSpec, WorldSpec

__all__ = ["CORRIDOR_LENGTH", "StopMeasurement", "measure_stop", "stop_corridor"]

CORRIDOR_LENGTH = 14.0
"""Length (m) of the straight path: room to reach the speed and stop far from its end."""

STANDSTILL = 1e-3
"""Speed (m/s) below which the vehicle counts as standing."""

TRIGGER_AFTER = 0.55
"""Share of the path driven before the box appears (the vehicle is at speed by then)."""


@dataclass(frozen=True)
class StopMeasurement:
    """One protective stop: speed (m/s), measured and predicted stopping distance (m).

    ``error`` is ``measured - predicted``.
    """

    robot: str
    speed: float
    measured: float
    predicted: float

    @property
    def error(self) -> float:
        """Return ``measured - predicted`` (m)."""
        return self.measured - self.predicted


def stop_corridor(robot: UGVSpec, speed: float) -> WorldSpec:
    """Return a straight corridor whose one segment's fields reach 3 m ahead of ``robot``.

    The fields are large on purpose (the measurement is of the stop, not of the field):
    the box appears well inside the protective field and well beyond the stopping
    distance. Posts stand irregularly along both walls (triangulation needs it).
    """
    half = 2.5
    # The end wall stands beyond the warning field at the path end (walls stay out of it).
    x0, x1 = -3.0, CORRIDOR_LENGTH + 5.0
    walls = (
        WallSpec((x0, -half), (x1, -half)), WallSpec((x0, half), (x1, half)),
        WallSpec((x0, -half), (x0, half)), WallSpec((x1, -half), (x1, half)),
    )
    inside = half - 0.11
    rng_free = (-2.2, -0.4, 1.3, 3.4, 4.9, 7.1, 8.6, 10.9, 12.2, 14.6, 16.3)
    posts = (
        *(PostSpec(x, -inside) for x in rng_free),
        *(PostSpec(x + 0.7 + 0.13 * (i % 3), inside) for i, x in enumerate(rng_free)),
        PostSpec(x0 + 0.11, 0.4), PostSpec(x1 - 0.11, -0.6),
    )
    front = max(x for x, _ in robot.footprint)
    side = 0.5 * (max(y for _, y in robot.footprint) - min(y for _, y in robot.footprint))
    protective = ((front, -side - 0.5), (front + 3.0, -side - 0.5),
                  (front + 3.0, side + 0.5), (front, side + 0.5))
    warning = ((front, -side - 0.7), (front + 3.5, -side - 0.7),
               (front + 3.5, side + 0.7), (front, side + 0.7))
    segment = SegmentSpec("straight", 0, 2, warning=warning, protective=protective)
    path = PathSpec(((0.0, 0.0), (CORRIDOR_LENGTH / 2, 0.0), (CORRIDOR_LENGTH, 0.0)),
                    (segment,), speed=speed)
    return WorldSpec(name="stop_corridor", walls=walls, posts=posts, boxes=(), people=(),
                     path=path, description="scenarios.results.stopping.stop_corridor")


class _ScanClock(Observer):
    """Notes that a safety scan was just taken (the box is placed right after one)."""

    def __init__(self) -> None:
        self.scanned = False

    def on_scan(self, vehicle, record) -> None:
        self.scanned = True


def measure_stop(robot: UGVSpec, speed: float, *, seed: int = 0) -> StopMeasurement:
    """Drive ``robot`` at ``speed`` (m/s), trigger a protective stop, measure the distance.

    The box appears right after a safety scan, as far ahead as the predicted stopping
    distance plus half a metre, in the middle of the protective field.
    """
    spec = ScenarioSpec(name=f"stop-{robot.name}", world="stop_corridor", robot=robot.name,
                        laps=1, seed=seed, lap_timeout=120.0,
                        safety=SafetySettings(undersized_fields=True),
                        mapper=MapperParams(hausdorff_restriction="projection"))
    predicted = stop_model(spec, robot).distance(speed)
    clock = _ScanClock()
    with Testbench(spec, world=stop_corridor(robot, speed), robot=robot) as bench:
        bench.add_observer(clock)
        bench.reset(seed=seed)
        while bench.true_pose[0] < TRIGGER_AFTER * CORRIDOR_LENGTH:
            bench.step()
        clock.scanned = False
        while not clock.scanned:
            bench.step()
        start = float(bench.true_pose[0])
        front = max(x for x, _ in robot.footprint)
        bench.add_box(BoxSpec("obstacle", (0.3, 0.3, 0.6),
                              (start + front + predicted + 0.5 + 0.15, 0.0, 0.0)))
        still = 0
        while still < 24:
            bench.step()
            still = still + 1 if abs(float(bench.true_twist[0])) < STANDSTILL else 0
        measured = float(bench.true_pose[0]) - start
        collided = bench.fleet[0].contacts.collisions
    if collided:
        raise RuntimeError(f"measure_stop: {robot.name} at {speed} m/s hit the box")
    return StopMeasurement(robot.name, float(speed), measured, predicted)

