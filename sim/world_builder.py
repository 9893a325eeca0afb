"""Build a ``worlds.spec.WorldSpec`` into PyBullet bodies and keep track of what each body is.

``SimWorld`` owns the bodies of one environment inside a ``sim.client.SimClient``: the
floor plane, walls and semi-static boxes as boxes, landmark posts and people as
cylinders (people are kinematic: ``sim.people`` moves them), and the personnel-detection
test pieces as cylinders standing or lying on the floor. Walls, boxes, posts, people and
test pieces are exact triangle meshes (prisms) so that laser rays hit them to the
micrometre.
Every body gets a semantic tag and a remission (what a laser reads as intensity);
``remission_of`` maps the body ids that ``rayTestBatch`` returns to remissions in one
vectorised lookup.

All world bodies are static (mass 0): walls, posts, boxes and test pieces do not move
when the robot touches them, so the ground truth stays exactly the spec, and boxes move
only when the experiment moves them between laps (``move_box``, ``add_box``,
``remove_box``).

Examples
--------
>>> from sim.client import SimClient
>>> from worlds.spec import BoxSpec, PathSpec, PostSpec, SegmentSpec, WallSpec, WorldSpec
>>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
>>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
>>> spec = WorldSpec(name="demo", walls=(WallSpec((0.0, -1.0), (0.0, 1.0)),),
...                  posts=(PostSpec(2.0, 0.0),),
...                  boxes=(BoxSpec("crate", (0.4, 0.4, 0.5), (1.0, 1.0, 0.0)),),
...                  people=(), path=path)
>>> with SimClient() as sim:
...     world = SimWorld(sim, spec)
...     crate = world.box_id("crate")
...     print(world.tag_of(crate), world.remission_of([crate, -1]))
box [0.3 0. ]
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from semistatic.colours import PERSON_COLOUR
from worlds.spec import BoxSpec, PersonSpec, PostSpec, TestPieceSpec, WallSpec, WorldSpec

__all__ = [
    "CIRCLE_SAGITTA",
    "DEFAULT_REMISSION",
    "NO_HIT_REMISSION",
    "TAG_BOX",
    "TAG_FLOOR",
    "TAG_PERSON",
    "TAG_POST",
    "TAG_TEST_PIECE",
    "TAG_UNKNOWN",
    "TAG_WALL",
    "BodyInfo",
    "SimWorld",
    "circle_footprint",
    "lying_cylinder_mesh",
    "prism_mesh",
    "wall_pose",
]

TAG_FLOOR = "floor"
TAG_WALL = "wall"
TAG_POST = "post"
TAG_BOX = "box"
TAG_PERSON = "person"
TAG_TEST_PIECE = "test_piece"
TAG_UNKNOWN = "unknown"

NO_HIT_REMISSION = 0.0
"""Intensity of a beam that hit nothing (``body id == -1``)."""

DEFAULT_REMISSION = 0.3
"""Remission of bodies the world did not build (e.g. another robot): a matte surface."""

FLOOR_REMISSION = 0.1

CIRCLE_SAGITTA = 1e-6
"""Largest gap (m) between a round footprint's polygon sides and the true circle."""

MIN_CIRCLE_SIDES = 32

_FLOOR_VISUAL_HALF_SIZE = 50.0

_RGBA = {
    TAG_FLOOR: (0.8, 0.8, 0.8, 1.0),
    TAG_WALL: (0.6, 0.6, 0.65, 1.0),
    TAG_POST: (0.95, 0.85, 0.1, 1.0),
    TAG_BOX: (0.7, 0.45, 0.2, 1.0),
    # the palette's, as the GUI's legend shows it (blue is a new polyline's)
    TAG_PERSON: (*PERSON_COLOUR, 1.0),
    TAG_TEST_PIECE: (0.1, 0.1, 0.1, 1.0),
}


@dataclass(frozen=True)
class BodyInfo:
    """What a world body is: its ``name`` (unique in the world), ``tag`` and ``remission``."""

    name: str
    tag: str
    remission: float


def wall_pose(wall: WallSpec) -> tuple[float, float, float, float]:
    """Return ``(cx, cy, yaw, length)`` of the box that models ``wall``.

    The box spans exactly from ``start`` to ``end`` along the centre line (no end caps)
    and is ``thickness`` wide: the footprint ``WallSpec.corners()`` describes.

    Examples
    --------
    >>> [round(v, 4) for v in wall_pose(WallSpec((0.0, 0.0), (0.0, 2.0)))]
    [0.0, 1.0, 1.5708, 2.0]
    """
    (x0, y0), (x1, y1) = wall.start, wall.end
    return 0.5 * (x0 + x1), 0.5 * (y0 + y1), wall.yaw, wall.length


def circle_footprint(radius: float, sagitta: float = CIRCLE_SAGITTA) -> np.ndarray:
    """Return the ``(N, 2)`` vertices of a regular polygon inscribed in a circle, CCW.

    ``N`` is the smallest count (at least ``MIN_CIRCLE_SIDES``) whose sides stray at most
    ``sagitta`` from the circle, so a round post reads the same as the true circle.

    Examples
    --------
    >>> ring = circle_footprint(0.04)
    >>> len(ring), bool(np.allclose(np.hypot(*ring.T), 0.04))
    (445, True)
    """
    if not (radius > 0.0 and sagitta > 0.0):
        raise ValueError(
            f"circle_footprint: radius and sagitta must be > 0, got {radius} and {sagitta}"
        )
    half_step = np.arccos(max(1.0 - sagitta / radius, -1.0))
    sides = max(MIN_CIRCLE_SIDES, int(np.ceil(np.pi / half_step)))
    angles = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    return radius * np.column_stack([np.cos(angles), np.sin(angles)])


def prism_mesh(footprint: ArrayLike, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(vertices (2N, 3), indices (M,))`` of the closed prism over a convex polygon.

    The footprint (``(N, 2)``, counter-clockwise) is extruded from ``z = 0`` to
    ``height``; sides are two triangles each, the caps are fans, all faces wound
    outwards.

    Examples
    --------
    >>> vertices, indices = prism_mesh([[0, 0], [1, 0], [1, 1], [0, 1]], 2.0)
    >>> vertices.shape, indices.size // 3
    ((8, 3), 12)
    """
    ring = np.asarray(footprint, dtype=float)
    count = len(ring)
    vertices = np.vstack(
        [np.column_stack([ring, np.zeros(count)]), np.column_stack([ring, np.full(count, height)])]
    )
    this = np.arange(count)
    after = (this + 1) % count
    sides = np.column_stack([this, after, count + after, this, count + after, count + this])
    fan = np.arange(1, count - 1)
    bottom = np.column_stack([np.zeros_like(fan), fan + 1, fan])
    top = np.column_stack([np.full_like(fan, count), count + fan, count + fan + 1])
    indices = np.concatenate([sides.ravel(), bottom.ravel(), top.ravel()])
    return vertices, indices


def lying_cylinder_mesh(diameter: float, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(vertices (2N, 3), indices (M,))`` of a closed cylinder lying on the floor.

    Its axis runs along x at height ``diameter / 2``, from ``-length / 2`` to ``length / 2``:
    the vertical prism of :func:`prism_mesh` over :func:`circle_footprint`, its axes
    renamed cyclically (z to x, x to y, y to z), a rotation, so faces stay wound outwards.

    Examples
    --------
    >>> vertices, indices = lying_cylinder_mesh(0.2, 0.6)
    >>> vertices.min(axis=0).round(6).tolist(), vertices.max(axis=0).round(6).tolist()
    ([-0.3, -0.1, 0.0], [0.3, 0.1, 0.2])
    """
    radius = 0.5 * diameter
    vertices, indices = prism_mesh(circle_footprint(radius), length)
    u, v, w = vertices.T
    return np.column_stack([w - 0.5 * length, u, v + radius]), indices


class SimWorld:
    """The PyBullet bodies of one ``WorldSpec`` inside a ``SimClient``.

    Parameters
    ----------
    sim
        The ``sim.client.SimClient`` to build into (its ``.bullet`` is the bound client).
    spec
        The environment (validated by ``worlds.spec``). Only its ``active_people`` are
        built; they start at their first waypoint and ``sim.people`` moves them.

    Attributes
    ----------
    spec
        The spec the world was built from (box moves do not change it; see ``boxes``).
    floor_id
        Body id of the floor plane.

    Examples
    --------
    >>> from sim.client import SimClient
    >>> from worlds.spec import PathSpec, SegmentSpec, WorldSpec
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
    >>> empty = WorldSpec(name="empty", walls=(), posts=(), boxes=(), people=(), path=path)
    >>> with SimClient() as sim:
    ...     world = SimWorld(sim, empty)
    ...     world.tag_of(world.floor_id), world.name_of(world.floor_id)
    ('floor', 'floor')
    """

    def __init__(self, sim, spec: WorldSpec) -> None:
        self.sim = sim
        self.spec = spec
        self._bullet = sim.bullet
        self._info: dict[int, BodyInfo] = {}
        self._ids_by_name: dict[str, int] = {}
        self._boxes: dict[str, BoxSpec] = {}
        # remission lookup indexed by body id + 1, so that id -1 (no hit) reads index 0
        self._remission_lut = np.full(16, DEFAULT_REMISSION)
        self._remission_lut[0] = NO_HIT_REMISSION

        self.floor_id = self._create_floor()
        for index, wall in enumerate(spec.walls):
            self._add_wall(f"wall_{index}", wall)
        for index, post in enumerate(spec.posts):
            self._add_post(f"post_{index}", post)
        sim.end_static_bodies()  # what never moves comes first: kept through resets
        for box in spec.boxes:
            self.add_box(box)
        for person in spec.active_people:
            self._add_person(person)
        for piece in spec.test_pieces:
            self._add_test_piece(piece)

    # ----------------------------------------------------------------- queries

    @property
    def boxes(self) -> tuple[BoxSpec, ...]:
        """Return the semi-static boxes as they are now (after moves, additions, removals)."""
        return tuple(self._boxes.values())

    @property
    def walls(self) -> tuple[WallSpec, ...]:
        """Return the walls of the spec (they never move)."""
        return self.spec.walls

    @property
    def posts(self) -> tuple[PostSpec, ...]:
        """Return the landmark posts of the spec (they never move)."""
        return self.spec.posts

    @property
    def test_pieces(self) -> tuple[TestPieceSpec, ...]:
        """Return the personnel-detection test pieces of the spec (they never move)."""
        return self.spec.test_pieces

    @property
    def people(self) -> tuple[PersonSpec, ...]:
        """Return the people built into the world, the spec's ``active_people``."""
        return self.spec.active_people

    @property
    def body_ids(self) -> tuple[int, ...]:
        """Return the ids of every body this world built, floor included."""
        return tuple(self._info)

    def body_id(self, name: str) -> int:
        """Return the body id of the world object called ``name`` (e.g. ``"wall_0"``)."""
        try:
            return self._ids_by_name[name]
        except KeyError:
            raise KeyError(
                f"no body named {name!r} in world {self.spec.name!r}; "
                f"known: {sorted(self._ids_by_name)}"
            ) from None

    def box_id(self, name: str) -> int:
        """Return the body id of the semi-static box called ``name``."""
        if name not in self._boxes:
            raise KeyError(
                f"no box named {name!r} in world {self.spec.name!r}; known: {sorted(self._boxes)}"
            )
        return self._ids_by_name[name]

    def person_id(self, name: str) -> int:
        """Return the body id of the person called ``name``."""
        return self.body_id(name)

    def replace_people(self, people: tuple[PersonSpec, ...]) -> None:
        """Give the built people new specs: walks, triggers and remissions (bodies stay).

        ``people`` must name the same people, in the same order, with the same
        ``enabled``, ``radius`` and ``height`` (their bodies); anything else raises
        ``ValueError``. Call ``sim.people.People.refresh`` after it.

        Examples
        --------
        >>> from sim.client import SimClient
        >>> from worlds.spec import PathSpec, PersonSpec, SegmentSpec, WorldSpec
        >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
        >>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
        >>> ann = PersonSpec("ann", ((0.0, 0.0), (4.0, 0.0)))
        >>> spec = WorldSpec(name="p", walls=(), posts=(), boxes=(), people=(ann,), path=path)
        >>> sim = SimClient()
        >>> world = SimWorld(sim, spec)
        >>> world.replace_people((replace(ann, speed=2.0, remission=0.9),))
        >>> world.people[0].speed, world.remission_of([world.person_id("ann")]).tolist()
        (2.0, [0.9])
        >>> world.replace_people((replace(ann, radius=0.3),))
        Traceback (most recent call last):
        ...
        ValueError: person ann: its body is built (name, enabled, radius, height); only its \
walk and remission can change
        >>> sim.close()
        """
        people = tuple(people)
        body = ("name", "enabled", "radius", "height")
        old = self.spec.people
        if len(people) != len(old):
            raise ValueError(f"replace_people: the world has {len(old)} people, got {len(people)}")
        for before, after in zip(old, people, strict=True):
            if any(getattr(before, key) != getattr(after, key) for key in body):
                raise ValueError(f"person {before.name}: its body is built ({', '.join(body)}); "
                                 "only its walk and remission can change")
        self.spec = replace(self.spec, people=people)
        for person in self.spec.active_people:
            info = replace(self._info[self._ids_by_name[person.name]], remission=person.remission)
            self._register(self._ids_by_name[person.name], info)

    def info(self, body_id: int) -> BodyInfo:
        """Return the ``BodyInfo`` of ``body_id`` (``unknown`` for bodies not built here)."""
        info = self._info.get(int(body_id))
        if info is None:
            return BodyInfo(f"body_{int(body_id)}", TAG_UNKNOWN, DEFAULT_REMISSION)
        return info

    def tag_of(self, body_id: int) -> str:
        """Return the tag of ``body_id``: floor, wall, post, box, person, test_piece or unknown."""
        return self.info(body_id).tag

    def name_of(self, body_id: int) -> str:
        """Return the name of ``body_id`` (``wall_3``, ``post_0``, a box or person name)."""
        return self.info(body_id).name

    def remission_of(self, body_ids: ArrayLike) -> np.ndarray:
        """Return the remission of each body id; ``-1`` (no hit) reads ``NO_HIT_REMISSION``.

        Vectorised: one fancy-indexing lookup, as ray casts return hundreds of ids per scan.

        Examples
        --------
        >>> from sim.client import SimClient
        >>> from worlds.spec import PathSpec, PostSpec, SegmentSpec, WorldSpec
        >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
        >>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
        >>> spec = WorldSpec(name="one post", walls=(), posts=(PostSpec(1.0, 0.0),), boxes=(),
        ...                  people=(), path=path)
        >>> with SimClient() as sim:
        ...     world = SimWorld(sim, spec)
        ...     world.remission_of([world.body_id("post_0"), -1, 999])
        array([0.95, 0.  , 0.3 ])
        """
        ids = np.asarray(body_ids, dtype=np.int64)
        if ids.size and ids.max() + 1 >= self._remission_lut.size:
            self._grow_lut(int(ids.max()) + 1)
        return self._remission_lut[ids + 1]

    # ------------------------------------------------------------ box changes

    def add_box(self, box: BoxSpec) -> int:
        """Create the body of a new semi-static box and return its id."""
        self._require_new_name(box.name, "box")
        sx, sy, sz = box.size
        x, y, yaw = box.pose
        footprint = 0.5 * np.array([[sx, -sy], [sx, sy], [-sx, sy], [-sx, -sy]])
        visual = self.sim.visual_shape(
            self._bullet.GEOM_BOX,
            halfExtents=[0.5 * sx, 0.5 * sy, 0.5 * sz],
            visualFramePosition=[0.0, 0.0, 0.5 * sz],
            rgbaColor=_RGBA[TAG_BOX],
        )
        info = BodyInfo(box.name, TAG_BOX, box.remission)
        body = self._add_prism(info, footprint, sz, visual, (x, y, yaw))
        self._boxes[box.name] = box
        return body

    def move_box(self, name: str, pose: tuple[float, float, float]) -> None:
        """Teleport box ``name`` to ``pose`` = (x, y, yaw), resting on the floor."""
        body = self.box_id(name)
        box = replace(self._boxes[name], pose=pose)
        x, y, yaw = box.pose
        self._bullet.resetBasePositionAndOrientation(
            body, [x, y, 0.0], self._bullet.getQuaternionFromEuler([0.0, 0.0, yaw])
        )
        self._boxes[name] = box

    def remove_box(self, name: str) -> None:
        """Remove box ``name`` from the simulation."""
        body = self.box_id(name)
        self._bullet.removeBody(body)
        del self._boxes[name]
        del self._ids_by_name[name]
        del self._info[body]
        # pybullet may hand this id to a later body: reset its lookup entry
        self._remission_lut[body + 1] = DEFAULT_REMISSION

    # --------------------------------------------------------------- building

    def _register(self, body: int, info: BodyInfo) -> None:
        self._info[body] = info
        self._ids_by_name[info.name] = body
        if body + 1 >= self._remission_lut.size:
            self._grow_lut(body + 1)
        self._remission_lut[body + 1] = info.remission

    def _grow_lut(self, min_index: int) -> None:
        size = max(2 * self._remission_lut.size, min_index + 1)
        grown = np.full(size, DEFAULT_REMISSION)
        grown[: self._remission_lut.size] = self._remission_lut
        self._remission_lut = grown

    def _create_floor(self) -> int:
        bullet = self._bullet
        body = self.sim.static_body("floor", lambda: bullet.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=self.sim.collision_shape(bullet.GEOM_PLANE),
            # a thin slab as the floor's look: pybullet has no visual for GEOM_PLANE
            baseVisualShapeIndex=self.sim.visual_shape(
                bullet.GEOM_BOX,
                halfExtents=[_FLOOR_VISUAL_HALF_SIZE, _FLOOR_VISUAL_HALF_SIZE, 0.005],
                visualFramePosition=[0.0, 0.0, -0.005],
                rgbaColor=_RGBA[TAG_FLOOR],
            ),
            basePosition=[0.0, 0.0, 0.0],
        ))
        self._register(body, BodyInfo("floor", TAG_FLOOR, FLOOR_REMISSION))
        return body

    def _require_new_name(self, name: str, kind: str) -> None:
        if name in self._ids_by_name:
            raise ValueError(
                f"world {self.spec.name!r} already has a body named {name!r}; "
                f"give the {kind} a unique name"
            )

    def _add_prism(
        self,
        info: BodyInfo,
        footprint: np.ndarray,
        height: float,
        visual: int,
        pose: tuple[float, float, float],
        keep: object = None,
    ) -> int:
        """Create a static body whose collision shape is the exact prism over ``footprint``.

        A triangle mesh, not a Bullet box or cylinder primitive: rays against convex
        primitives go through an iterative convex cast that misses by millimetres (up to
        5 mm on cylinders, 1.5 mm on boxes near edges), rays against triangles are exact.
        The body frame sits on the floor under the footprint's origin.
        """
        vertices, indices = prism_mesh(footprint, height)
        return self._add_mesh(info, vertices, indices, visual, pose, keep)

    def _add_mesh(
        self,
        info: BodyInfo,
        vertices: np.ndarray,
        indices: np.ndarray,
        visual: int,
        pose: tuple[float, float, float],
        keep: object = None,
    ) -> int:
        """Create a static body of the triangle mesh, its frame at ``pose`` on the floor.

        ``keep``: the key of a body that never moves, kept through resets
        (``SimClient.static_body``).
        """
        bullet = self._bullet
        # Made once per server and shared (SimClient.collision_shape): PyBullet never
        # frees a mesh, and a world rebuilt at each reset would grow by its meshes.
        shape = self.sim.collision_shape(
            bullet.GEOM_MESH, vertices=vertices.tolist(), indices=indices.tolist()
        )
        x, y, yaw = pose

        def create() -> int:
            return bullet.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                baseVisualShapeIndex=visual,
                basePosition=[x, y, 0.0],
                baseOrientation=bullet.getQuaternionFromEuler([0.0, 0.0, yaw]),
            )

        body = create() if keep is None else self.sim.static_body(keep, create)
        self._register(body, info)
        return body

    def _add_wall(self, name: str, wall: WallSpec) -> int:
        cx, cy, yaw, length = wall_pose(wall)
        half_x, half_y = 0.5 * length, 0.5 * wall.thickness
        footprint = np.array(
            [[half_x, -half_y], [half_x, half_y], [-half_x, half_y], [-half_x, -half_y]]
        )
        visual = self.sim.visual_shape(
            self._bullet.GEOM_BOX,
            halfExtents=[half_x, half_y, 0.5 * wall.height],
            visualFramePosition=[0.0, 0.0, 0.5 * wall.height],
            rgbaColor=_RGBA[TAG_WALL],
        )
        info = BodyInfo(name, TAG_WALL, wall.remission)
        return self._add_prism(info, footprint, wall.height, visual, (cx, cy, yaw),
                               keep=("wall", wall))

    def _add_cylinder(
        self, info: BodyInfo, x: float, y: float, radius: float, height: float,
        keep: object = None,
    ) -> int:
        visual = self.sim.visual_shape(
            self._bullet.GEOM_CYLINDER,
            radius=radius,
            length=height,
            visualFramePosition=[0.0, 0.0, 0.5 * height],
            rgbaColor=_RGBA[info.tag],
        )
        return self._add_prism(info, circle_footprint(radius), height, visual, (x, y, 0.0),
                               keep)

    def _add_post(self, name: str, post: PostSpec) -> int:
        info = BodyInfo(name, TAG_POST, post.remission)
        return self._add_cylinder(info, post.x, post.y, post.radius, post.height,
                                  keep=("post", post))

    def _add_person(self, person: PersonSpec) -> int:
        self._require_new_name(person.name, "person")
        x, y = person.waypoints[0]
        info = BodyInfo(person.name, TAG_PERSON, person.remission)
        return self._add_cylinder(info, x, y, person.radius, person.height)

    def _add_test_piece(self, piece: TestPieceSpec) -> int:
        self._require_new_name(piece.name, "test piece")
        info = BodyInfo(piece.name, TAG_TEST_PIECE, piece.remission)
        if not piece.lying:
            x, y, _ = piece.pose
            return self._add_cylinder(info, x, y, 0.5 * piece.diameter, piece.length)
        radius = 0.5 * piece.diameter
        vertices, indices = lying_cylinder_mesh(piece.diameter, piece.length)
        visual = self.sim.visual_shape(
            self._bullet.GEOM_CYLINDER,
            radius=radius,
            length=piece.length,
            visualFramePosition=[0.0, 0.0, radius],
            # Bullet's cylinder stands along z; a quarter turn about y lays it along x.
            visualFrameOrientation=self._bullet.getQuaternionFromEuler([0.0, 0.5 * np.pi, 0.0]),
            rgbaColor=_RGBA[TAG_TEST_PIECE],
        )
        return self._add_mesh(info, vertices, indices, visual, piece.pose)
