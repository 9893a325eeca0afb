"""Collisions of the robot with the world: which body it touches, and how many times.

``ContactMonitor.check`` reads PyBullet's contact points of the robot after a step and
reports one ``Contact`` per other body it touches, floor excluded (the wheels always
touch it). A collision is an *event*: a contact that lasts many steps, or flickers on and
off for less than ``separation_time`` as a pushing robot bounces, is one collision.

Examples
--------
>>> from sim.client import SimClient
>>> from sim.world_builder import SimWorld
>>> from worlds.spec import PathSpec, SegmentSpec, WorldSpec
>>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
>>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
>>> empty = WorldSpec(name="e", walls=(), posts=(), boxes=(), people=(), path=path)
>>> with SimClient() as sim:
...     world = SimWorld(sim, empty)
...     b = sim.bullet
...     ball = b.createMultiBody(1.0, b.createCollisionShape(b.GEOM_SPHERE, radius=0.1),
...                              -1, [0.0, 0.0, 0.1])
...     monitor = ContactMonitor(sim, ball, world)
...     sim.step(240)
...     monitor.check(), monitor.collisions
([], 0)
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from operator import itemgetter

import numpy as np

__all__ = ["TOUCH_DISTANCE", "Contact", "ContactMonitor"]

TOUCH_DISTANCE = 1e-3
"""Contact points farther apart than this (m) are near misses, not touches."""

# Index of fields in a pybullet getContactPoints tuple.
_BODY_B, _POSITION_ON_B, _DISTANCE, _NORMAL_FORCE = 2, 6, 8, 9
_OTHER_BODY = itemgetter(_BODY_B)


@dataclass(frozen=True)
class Contact:
    """The robot touching one other body at one check.

    Attributes
    ----------
    body_id, name, tag
        The other body and what it is (``SimWorld.name_of`` / ``tag_of``).
    position
        ``(3,)`` world position of the deepest contact point on the other body.
    normal_force
        Sum of the contact normal forces (N) over the contact points.
    time
        Simulated time of the check, seconds.
    new
        True when this contact starts a new collision event.
    """

    body_id: int
    name: str
    tag: str
    position: np.ndarray
    normal_force: float
    time: float
    new: bool


class ContactMonitor:
    """Counts the robot's collisions with anything but the floor.

    Parameters
    ----------
    sim
        The ``sim.client.SimClient`` (its ``sim_time`` dates contacts).
    robot_body_id
        Body id of the robot.
    world
        The ``sim.world_builder.SimWorld`` that names and tags bodies and owns the floor.
    separation_time
        A contact with a body counts as a new collision only after the robot has been
        apart from that body for longer than this (s).

    Attributes
    ----------
    events
        The ``Contact`` that started each collision, in order.
    """

    def __init__(self, sim, robot_body_id: int, world, *, separation_time: float = 0.1) -> None:
        if not separation_time >= 0.0:
            raise ValueError(
                f"ContactMonitor: separation_time must be >= 0 s, got {separation_time}"
            )
        self.sim = sim
        self.robot_body_id = int(robot_body_id)
        self.world = world
        self.separation_time = float(separation_time)
        self.events: list[Contact] = []
        self._last_seen: dict[int, float] = {}
        # Bound once: BulletClient builds a new partial on every attribute access, and
        # this runs after every physics step.
        self._contact_points = sim.bullet.getContactPoints

    @property
    def collisions(self) -> int:
        """Return the number of distinct collision events so far."""
        return len(self.events)

    def reset(self) -> None:
        """Forget ongoing contacts (e.g. after teleporting the robot); keep the event count."""
        self._last_seen.clear()

    def check(self) -> list[Contact]:
        """Return the robot's current contacts, one per other body, and record new collisions."""
        ignored = {self.robot_body_id, self.world.floor_id}
        # Engine time, inline: the engine_timer context manager costs more than this call.
        start = time.perf_counter()
        points = self._contact_points(bodyA=self.robot_body_id)
        self.sim.engine_time_s += time.perf_counter() - start
        # Nearly every step only the wheels and casters touch the floor: a scan of the
        # touched bodies in C says so before any per-point Python.
        if ignored.issuperset(map(_OTHER_BODY, points)):
            return []
        touching = [
            point
            for point in points
            if point[_BODY_B] not in ignored and not point[_DISTANCE] > TOUCH_DISTANCE
        ]
        if not touching:
            return []
        now = float(self.sim.sim_time)
        by_body: dict[int, list] = {}
        for point in touching:
            by_body.setdefault(point[_BODY_B], []).append(point)
        contacts = []
        for other, points in sorted(by_body.items()):
            last = self._last_seen.get(other)
            new = last is None or now - last > self.separation_time
            deepest = min(points, key=lambda p: p[_DISTANCE])
            contact = Contact(
                body_id=other,
                name=self.world.name_of(other),
                tag=self.world.tag_of(other),
                position=np.array(deepest[_POSITION_ON_B], dtype=float),
                normal_force=float(sum(p[_NORMAL_FORCE] for p in points)),
                time=now,
                new=new,
            )
            self._last_seen[other] = now
            if new:
                self.events.append(contact)
            contacts.append(contact)
        return contacts
