"""What the vehicles of a Testbench share: physics, the world and its boxes, people, seeds.

A :class:`Scene` is built by :meth:`Testbench.reset <scenarios.bench.testbench.Testbench.reset>`
and handed to every :class:`~scenarios.bench.vehicle.Vehicle`: the vehicles read the clock,
the world, the people and the fleet from it, never from the bench, so data flows one way
(bench -> vehicles -> scene). Box changes go through the scene, which counts them in
``layout_revision`` (what ground-truth scoring keys its cache on).

Examples
--------
>>> from scenarios.bench.testbench import Testbench
>>> with Testbench("pal1") as bench:
...     bench.reset()
...     scene = bench.scene
...     revision = scene.layout_revision
...     scene.move_box("carton_west", (2.5, -0.75, 0.0))
...     scene.layout_revision - revision, len(scene.fleet)
(1, 1)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scenarios.bench.triggers import PersonTriggers
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment
from semistatic.fleet import FleetMapStore
from sim.client import SimClient
from sim.people import People
from sim.random_streams import RandomStreams
from sim.world_builder import SimWorld
from worlds.spec import BoxSpec, PersonSpec, WorldSpec

__all__ = ["Scene"]


@dataclass(eq=False)
class Scene:
    """The shared state of one run of a bench.

    Parameters
    ----------
    spec
        The run's scenario (its seed applied).
    sim
        The PyBullet client.
    world
        The simulated world (walls, posts, boxes as they stand now).
    segments
        The world path's segments: the frames every vehicle's maps use.
    streams
        The run's random streams (:mod:`sim.random_streams`).
    store
        The fleet map store, or ``None`` when vehicles do not share maps.

    Attributes
    ----------
    fleet : list of Vehicle
        The vehicles in the order of the scenario.
    person_positions : dict
        Where each person stands after the last tick (``None``: not in the scene).
    layout_revision : int
        Counts box changes.
    """

    spec: ScenarioSpec
    sim: SimClient
    world: SimWorld
    segments: tuple[PathSegment, ...]
    streams: RandomStreams
    store: FleetMapStore | None = None
    fleet: list = field(default_factory=list)  # the Vehicles (scenarios.bench.vehicle)
    person_positions: dict[str, np.ndarray | None] = field(default_factory=dict)
    layout_revision: int = 0

    def __post_init__(self) -> None:
        self._segment_keys = {segment.name: segment.index for segment in self.segments}
        self._people: People | None = None
        self._triggers: PersonTriggers | None = None

    @property
    def triggers(self) -> PersonTriggers | None:
        """Return the triggers of the people a vehicle triggers (``None``: no such person)."""
        return self._triggers

    @property
    def sim_time(self) -> float:
        """Return the simulated seconds since the run started."""
        return self.sim.sim_time

    def segment_key(self, name: str) -> int:
        """Return the fleet-wide index of segment ``name`` (its place in the world's path)."""
        return self._segment_keys[name]

    def add_people(self) -> None:
        """Put the world's people into the simulation (after the vehicles' bodies).

        People a vehicle triggers watch the fleet from now on (:mod:`scenarios.bench.triggers`).
        """
        # A world without people costs no per-tick call (person_positions stays empty).
        self._people = People(self.world) if self.world.people else None
        self._triggers = PersonTriggers(self.world.people, self.fleet) if self._people else None

    def walk_people(self, lap_start: float, lap: int | None = None) -> None:
        """Move the people to where they are now (their walks restart with each lap).

        ``lap`` (from 1) keeps the people whose ``laps`` leave it out parked.
        """
        if self._people is not None:
            t = self.sim.sim_time
            fired = self._triggers.update(t, lap_start, lap) if self._triggers else None
            self.person_positions = self._people.update(t, lap_start=lap_start, triggered=fired,
                                                        lap=lap)

    def replace_people(self, people: tuple[PersonSpec, ...]) -> None:
        """Go on with new specs of the world's people (same bodies; new walks and triggers).

        ``people`` are the world's people (``WorldSpec.people``) with the same names,
        ``enabled``, ``radius`` and ``height`` (``SimWorld.replace_people`` checks).
        A parked person whose first waypoint moved is parked below the new one.
        """
        self.world.replace_people(people)
        if self._people is not None:
            self._people.refresh()
        if self._triggers is not None:
            self._triggers.replace_people(self.world.people)

    def move_box(self, name: str, pose: tuple[float, float, float]) -> None:
        """Teleport box ``name`` to ``pose`` = (x, y, yaw)."""
        self.world.move_box(name, tuple(float(value) for value in pose))
        self.layout_revision += 1

    def add_box(self, box: BoxSpec) -> None:
        """Put a new box into the world."""
        self.world.add_box(box)
        self.layout_revision += 1

    def remove_box(self, name: str) -> None:
        """Take box ``name`` out of the world."""
        self.world.remove_box(name)
        self.layout_revision += 1

    def apply_layout(self, layout: WorldSpec) -> None:
        """Make the simulated boxes match ``layout`` (move, add, remove by name)."""
        world = self.world
        wanted = {box.name: box for box in layout.boxes}
        current = {box.name: box for box in world.boxes}
        changed = False
        for name in current.keys() - wanted.keys():
            world.remove_box(name)
            changed = True
        for name, box in wanted.items():
            if name not in current:
                world.add_box(box)
                changed = True
            elif tuple(current[name].pose) != tuple(box.pose):
                world.move_box(name, box.pose)
                changed = True
        if changed:
            self.layout_revision += 1
