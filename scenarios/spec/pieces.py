"""Whether every vehicle's safety laser can see the world's personnel-detection test pieces.

ISO 3691-4 (as commonly quoted; see :data:`worlds.spec.TEST_PIECE_SIZES`) checks that a
driverless truck detects a person with two test pieces in its path, a cylinder lying on
the floor and one standing upright (:class:`worlds.spec.TestPieceSpec`), and stops before
touching them. A planar safety laser sees a piece only where its scan plane cuts it: the
mount height ``z`` of the vehicle's safety laser (:class:`robots.presets.LaserMount`) must
lie below the piece's top (a lying 200 mm piece is 0.2 m tall). A vehicle whose scan
plane lies higher drives into that piece whatever its fields say.

Such a piece is refused like an under-sized protective field
(:mod:`scenarios.spec.field_sizing`): an error naming the piece, the vehicle and both
heights, unless the scenario says ``safety.unseen_test_pieces = true`` (it studies what
happens: the contact is then an infraction of the run). ``semistatic check`` prints every
piece against every vehicle, and ``metrics.json`` carries them (``safety.test_pieces``).

Examples
--------
>>> import dataclasses
>>> from scenarios.spec.scenario import ScenarioSpec
>>> from worlds.load import load_world
>>> from worlds.spec import TestPieceSpec
>>> world = dataclasses.replace(load_world("sim1"), test_pieces=(
...     TestPieceSpec("tp1", "lying", (3.0, 0.0, 1.5708)),))
>>> [(s.vehicle, s.scan_height, s.seen) for s in piece_sightings(
...     ScenarioSpec("s", world="sim1", robot="lgv"), world)]
[('robot', 0.15, True)]
>>> check_piece_sightings(ScenarioSpec("s", world="sim1"), world)  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
semistatic.errors.SpecError: ...sim1.toml: test_pieces[0]: test piece 'tp1' (lying, its top 0.2 m \
above the floor) lies under the scan plane of vehicle 'robot' (pioneer3dx, safety laser at \
0.35 m): ...
"""

from __future__ import annotations

from dataclasses import dataclass

from robots.presets import UGVSpec
from scenarios.spec.layout import robot_preset
from scenarios.spec.routes import fleet_vehicles
from scenarios.spec.scenario import ScenarioSpec
from semistatic.errors import SpecError
from worlds.spec import WorldSpec

__all__ = ["PieceSighting", "check_piece_sightings", "piece_sightings"]


@dataclass(frozen=True)
class PieceSighting:
    """One test piece against one vehicle's safety laser (heights in m above the floor).

    ``seen``: the scan plane at ``scan_height`` cuts the piece, whose top is at ``top``.
    """

    piece: str
    kind: str
    top: float
    vehicle: str
    robot: str
    scan_height: float
    seen: bool

    def as_metrics(self) -> dict:
        """Return the ``metrics.json`` entry of ``safety.test_pieces``.

        Examples
        --------
        >>> PieceSighting("tp2", "upright", 0.4, "robot", "lgv", 0.15, True).as_metrics()
        {'piece': 'tp2', 'kind': 'upright', 'top_m': 0.4, 'vehicle': 'robot', 'robot': 'lgv', \
'scan_height_m': 0.15, 'seen': True}
        """
        return {"piece": self.piece, "kind": self.kind, "top_m": round(self.top, 4),
                "vehicle": self.vehicle, "robot": self.robot,
                "scan_height_m": round(self.scan_height, 4), "seen": self.seen}


def piece_sightings(spec: ScenarioSpec, world: WorldSpec,
                    robot: UGVSpec | None = None) -> list[PieceSighting]:
    """Return every test piece of ``world`` against every vehicle of ``spec``, piece by piece.

    ``robot`` replaces the robot of a scenario without ``[[vehicles]]`` (as the
    :class:`~scenarios.bench.testbench.Testbench`'s ``robot`` does).
    """
    sightings = []
    vehicles = fleet_vehicles(spec)
    for piece in world.test_pieces:
        for vehicle in vehicles:
            preset = robot if robot is not None and not spec.vehicles else \
                robot_preset(vehicle.robot, file=spec.source)
            height = preset.safety_laser.z
            sightings.append(PieceSighting(piece.name, piece.kind, piece.top, vehicle.name,
                                           preset.name, height, piece.cut_by(height)))
    return sightings


def check_piece_sightings(spec: ScenarioSpec, world: WorldSpec,
                          robot: UGVSpec | None = None) -> list[PieceSighting]:
    """Return the sightings; raise :class:`SpecError` for the first piece a vehicle cannot see.

    Unless the scenario studies such pieces (``safety.unseen_test_pieces``).
    """
    sightings = piece_sightings(spec, world, robot)
    if spec.safety.unseen_test_pieces:
        return sightings
    index = {piece.name: i for i, piece in enumerate(world.test_pieces)}
    for sighting in sightings:
        if not sighting.seen:
            raise SpecError(
                world.source, f"test_pieces[{index[sighting.piece]}]",
                f"test piece '{sighting.piece}' ({sighting.kind}, its top {sighting.top:g} m "
                f"above the floor) lies under the scan plane of vehicle '{sighting.vehicle}' "
                f"({sighting.robot}, safety laser at {sighting.scan_height:g} m): the vehicle "
                "cannot detect it; use a vehicle whose safety laser scans below "
                f"{sighting.top:g} m, or set safety.unseen_test_pieces = true in the scenario "
                "to study it",
            )
    return sightings
