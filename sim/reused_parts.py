"""The shapes and static bodies a :class:`~sim.client.SimClient` makes once and reuses.

PyBullet never frees a triangle mesh's memory (about 0.4 MB for a 2,000-triangle post),
neither on ``removeBody``, ``resetSimulation`` nor ``disconnect``, and it keeps ~1 KB of
every body it ever created and removed. A bench reset thousands of times must therefore
build its world on one server, from shapes made once, and keep the bodies that never
move: :class:`ReusedParts` gives ``SimClient`` those methods (a module of their own only
to keep ``client.py`` short).
"""

from __future__ import annotations

import numpy as np

__all__ = ["ReusedParts"]


def _frozen(value):
    """Return ``value`` with its lists, tuples and arrays as nested tuples (a dict key)."""
    if isinstance(value, list | tuple | np.ndarray):
        return tuple(_frozen(item) for item in value)
    return value


class ReusedParts:
    """Shape cache and kept static bodies: the base class of :class:`~sim.client.SimClient`.

    They use the client's ``bullet``, ``_require_open`` and the attributes
    ``_shapes``, ``_kept`` and ``_claimed`` its constructor sets.
    """

    def collision_shape(self, shape_type: int, **options) -> int:
        """Return the collision shape of ``shape_type`` and ``options``, made once per server.

        The arguments are ``createCollisionShape``'s; a second call with equal arguments
        returns the same shape (bodies share it), also after :meth:`clear`.

        Examples
        --------
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     ball = sim.collision_shape(sim.bullet.GEOM_SPHERE, radius=0.1)
        ...     same = sim.collision_shape(sim.bullet.GEOM_SPHERE, radius=0.1)
        ...     other = sim.collision_shape(sim.bullet.GEOM_SPHERE, radius=0.2)
        ...     ball == same, ball == other
        (True, False)
        """
        return self._shape("collision", self.bullet.createCollisionShape, shape_type, options)

    def visual_shape(self, shape_type: int, **options) -> int:
        """Return the visual shape of ``shape_type`` and ``options``, made once per server.

        The arguments are ``createVisualShape``'s (see :meth:`collision_shape`).
        """
        return self._shape("visual", self.bullet.createVisualShape, shape_type, options)

    def _shape(self, kind: str, create, shape_type: int, options: dict) -> int:
        self._require_open()
        key = (kind, shape_type, _frozen(sorted(options.items())))
        shape = self._shapes.get(key)
        if shape is None:
            shape = self._shapes[key] = int(create(shape_type, **options))
        return shape

    def static_body(self, key: object, create) -> int:
        """Return the body ``create()`` makes for ``key``: kept through ``clear(keep_static=True)``.

        For bodies that never move (a world's floor, walls, posts) built first, in the
        same order, at every reset: PyBullet keeps ~1 KB of every body it ever created
        and removed, so they are built once. A kept body is taken again when the build
        asks for the same ``key`` at the same place in the order; one asked for after
        other bodies is built and not kept. :meth:`end_static_bodies` removes the kept
        bodies a build did not take.

        Examples
        --------
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     plane = sim.collision_shape(sim.bullet.GEOM_PLANE)
        ...     floor = sim.static_body("floor", lambda: sim.bullet.createMultiBody(0.0, plane))
        ...     sim.clear(keep_static=True)
        ...     again = sim.static_body("floor", lambda: sim.bullet.createMultiBody(0.0, plane))
        ...     sim.end_static_bodies()
        ...     again == floor, sim.bullet.getNumBodies()
        (True, 1)
        """
        self._require_open()
        index = self._claimed
        untouched = self.bullet.getNumBodies() == len(self._kept)  # nothing else built yet
        if untouched and index < len(self._kept) and self._kept[index][0] == key:
            self._claimed += 1
            return self._kept[index][1]
        if untouched:
            self.end_static_bodies()  # another world: the rest of the kept bodies go
        body = int(create())
        if self.bullet.getNumBodies() == len(self._kept) + 1:  # the lowest ids are kept
            self._kept.append((key, body))
            self._claimed += 1
        return body

    def end_static_bodies(self) -> None:
        """Remove the kept static bodies this build did not take (:meth:`static_body`)."""
        self._require_open()
        self._remove([body for _, body in self._kept[self._claimed:]])
        del self._kept[self._claimed:]

    def _bodies(self) -> list[int]:
        bullet = self.bullet
        return sorted(bullet.getBodyUniqueId(index) for index in range(bullet.getNumBodies()))

    def _remove(self, bodies: list[int]) -> None:
        # Highest first: PyBullet gives the id freed last to the next body.
        for body in sorted(bodies, reverse=True):
            self.bullet.removeBody(body)
