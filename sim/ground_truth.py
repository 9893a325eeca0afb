"""Ground truth for scoring: true obstacle footprints, box outlines, people, visible outlines.

Everything here is exact 2D geometry (shapely) of what ``sim.world_builder`` builds, so it
doubles as the slow, obviously-correct reference the raycast laser is tested against
(``reference_ranges``). Functions take a ``SimWorld`` (current box poses after moves) or,
where no engine state is needed, anything with the same ``walls``/``posts``/``boxes``
attributes, such as a ``WorldSpec``.

Examples
--------
>>> from worlds.spec import BoxSpec, PathSpec, SegmentSpec, WorldSpec
>>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
>>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
>>> spec = WorldSpec(name="one box", walls=(), posts=(), people=(),
...                  boxes=(BoxSpec("crate", (2.0, 1.0, 0.5), (3.0, 0.0, 0.0)),), path=path)
>>> box_outlines(spec)["crate"]
array([[ 4. , -0.5],
       [ 4. ,  0.5],
       [ 2. ,  0.5],
       [ 2. , -0.5]])
>>> reference_ranges(obstacle_footprints(spec), (0.0, 0.0, 0.0), [0.0, 1.5], 20.0)
array([ 2., inf])
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from numpy.typing import ArrayLike

__all__ = [
    "CIRCLE_SEGMENTS_PER_QUADRANT",
    "box_outlines",
    "obstacle_footprints",
    "people_positions",
    "reference_ranges",
    "visible_outlines",
]

CIRCLE_SEGMENTS_PER_QUADRANT = 512
"""Polygon resolution of round footprints: the chord error of a 0.5 m circle is < 0.6 um."""

# Sensor-height tolerance: an object shorter than the scan plane by less than this still
# counts as seen (rays graze its top face).
_HEIGHT_TOLERANCE = 1e-9

# Visible-outline pieces: the boundary is cut into pieces no longer than this, and a piece
# is visible when the sight line to its midpoint, stopped this short of it, hits nothing.
_VISIBILITY_STEP = 0.01
_SIGHT_LINE_SHORTFALL = 1e-4
# Round footprints for visibility: 64 sides are within 0.3 mm of a 0.25 m person.
_VISIBILITY_QUAD_SEGS = 16
# Sight lines tested against all edges at once, this many at a time (bounds memory).
_SIGHT_LINE_CHUNK = 1024


def box_outlines(world) -> dict[str, np.ndarray]:
    """Return the true ``(4, 2)`` outline of every semi-static box, world frame, CCW.

    ``world`` is a ``SimWorld`` (boxes as moved) or a ``WorldSpec``.

    Examples
    --------
    >>> from worlds.spec import BoxSpec, PathSpec, SegmentSpec, WorldSpec
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
    >>> spec = WorldSpec(name="b", walls=(), posts=(), people=(),
    ...                  boxes=(BoxSpec("b0", (1.0, 1.0, 1.0), (0.0, 0.0, 0.0)),), path=path)
    >>> box_outlines(spec)["b0"].tolist()
    [[0.5, -0.5], [0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5]]
    """
    return {box.name: box.corners() for box in world.boxes}


def _circle(x: float, y: float, radius: float, quad_segs: int):
    return shapely.Point(x, y).buffer(radius, quad_segs=quad_segs)


def _test_piece_section(piece, scan_height: float, quad_segs: int):
    """Return a test piece's cross-section by the plane at ``scan_height``, or ``None``."""
    if not piece.lying:
        if piece.length + _HEIGHT_TOLERANCE > scan_height:
            return _circle(piece.pose[0], piece.pose[1], 0.5 * piece.diameter, quad_segs)
        return None
    radius = 0.5 * piece.diameter
    if scan_height <= 0.0:
        width = piece.diameter
    elif scan_height < piece.diameter:
        width = 2.0 * math.sqrt(radius**2 - (scan_height - radius) ** 2)
    else:
        return None
    x, y, yaw = piece.pose
    c, s = math.cos(yaw), math.sin(yaw)
    half = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]]) * [0.5 * piece.length, 0.5 * width]
    return shapely.Polygon(half @ np.array([[c, s], [-s, c]]) + [x, y])


def people_positions(world) -> dict[str, np.ndarray]:
    """Return the true ``(x, y)`` of every person present in the scene, read from the engine.

    People parked out of the scene (before their start time) are left out.

    Examples
    --------
    >>> from sim.client import SimClient
    >>> from sim.world_builder import SimWorld
    >>> from worlds.spec import PathSpec, PersonSpec, SegmentSpec, WorldSpec
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
    >>> spec = WorldSpec(name="p", walls=(), posts=(), boxes=(),
    ...                  people=(PersonSpec("ann", ((1.0, 2.0), (3.0, 2.0))),), path=path)
    >>> with SimClient() as sim:
    ...     people_positions(SimWorld(sim, spec))["ann"].tolist()
    [1.0, 2.0]
    """
    positions = {}
    for person in world.people:
        body = world.person_id(person.name)
        (x, y, z), _ = world.sim.bullet.getBasePositionAndOrientation(body)
        if z >= 0.0:
            positions[person.name] = np.array([x, y])
    return positions


def obstacle_footprints(
    world,
    *,
    scan_height: float = 0.0,
    include_people: bool = True,
    quad_segs: int = CIRCLE_SEGMENTS_PER_QUADRANT,
) -> dict:
    """Return ``{name: shapely.Polygon}`` of every obstacle footprint, world frame.

    Walls, posts, boxes and test pieces always; people (at their current engine
    positions) when ``world`` is a ``SimWorld`` and ``include_people``. Objects not taller
    than ``scan_height`` are left out: a laser plane at that height passes over them. A
    lying test piece is cut where the plane crosses it, a strip ``2 sqrt(r^2 - (h - r)^2)``
    wide along its axis (its whole footprint at ``scan_height`` 0, the floor plan). Round
    footprints are polygons with ``4 * quad_segs`` sides.

    Examples
    --------
    >>> from worlds.spec import PathSpec, PostSpec, SegmentSpec, WallSpec, WorldSpec
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
    >>> spec = WorldSpec(name="f", walls=(WallSpec((0.0, 0.0), (2.0, 0.0)),),
    ...                  posts=(PostSpec(1.0, 1.0, height=0.3),), boxes=(), people=(),
    ...                  path=path)
    >>> sorted(obstacle_footprints(spec)), sorted(obstacle_footprints(spec, scan_height=0.5))
    (['post_0', 'wall_0'], ['wall_0'])
    >>> round(obstacle_footprints(spec)["wall_0"].area, 3)
    0.2
    >>> import dataclasses
    >>> from worlds.spec import TestPieceSpec
    >>> lying = dataclasses.replace(spec, test_pieces=(TestPieceSpec("tp1", "lying", (3, 0, 0)),))
    >>> # the 0.2 m piece across 0.2 m, 0.17 m (2 sqrt(0.1^2 - 0.05^2)) at 0.15 m, 0 above
    >>> [round(obstacle_footprints(lying, scan_height=h)["tp1"].bounds[3] * 2, 4)
    ...  for h in (0.0, 0.1, 0.15)], "tp1" in obstacle_footprints(lying, scan_height=0.35)
    ([0.2, 0.2, 0.1732], False)
    """
    footprints: dict[str, shapely.Geometry] = {}

    def tall_enough(height: float) -> bool:
        return height + _HEIGHT_TOLERANCE > scan_height

    for index, wall in enumerate(world.walls):
        if tall_enough(wall.height):
            footprints[f"wall_{index}"] = shapely.Polygon(wall.corners())
    for index, post in enumerate(world.posts):
        if tall_enough(post.height):
            footprints[f"post_{index}"] = _circle(post.x, post.y, post.radius, quad_segs)
    for box in world.boxes:
        if tall_enough(box.size[2]):
            footprints[box.name] = shapely.Polygon(box.corners())
    for piece in getattr(world, "test_pieces", ()):
        section = _test_piece_section(piece, scan_height, quad_segs)
        if section is not None:
            footprints[piece.name] = section
    if include_people and hasattr(world, "sim"):
        positions = people_positions(world)
        for person in world.people:
            if person.name in positions and tall_enough(person.height):
                x, y = positions[person.name]
                footprints[person.name] = _circle(x, y, person.radius, quad_segs)
    return footprints


def reference_ranges(
    footprints, sensor_pose: ArrayLike, angles: ArrayLike, range_max: float
) -> np.ndarray:
    """Return exact ranges of rays from ``sensor_pose`` = (x, y, yaw) against ``footprints``.

    The slow, obviously-correct reference for ``sim.laser.RaycastLaser``: each ray is a
    shapely segment from the sensor to ``range_max``; the range is the distance to the
    nearest point of its intersection with any footprint, ``inf`` when there is none.
    Rays start at the sensor (a footprint containing it reads 0); like the laser, the
    reference keeps ranges below a scanner's ``range_min``.

    Examples
    --------
    >>> square = {"s": shapely.box(1.0, -1.0, 3.0, 1.0)}
    >>> reference_ranges(square, (0.0, 0.0, 0.0), [0.0, math.pi / 4, math.pi], 10.0)
    array([1.        , 1.41421356,        inf])
    """
    x, y, yaw = (float(v) for v in np.asarray(sensor_pose, dtype=float)[[0, 1, -1]])
    angles = np.asarray(angles, dtype=float) + yaw
    ranges = np.full(angles.shape, np.inf)
    if not footprints:
        return ranges
    ends = np.column_stack([x + range_max * np.cos(angles), y + range_max * np.sin(angles)])
    rays = shapely.linestrings(np.stack([np.broadcast_to([x, y], ends.shape), ends], axis=1))
    polygons = np.array(list(footprints.values()), dtype=object)
    # only the (ray, footprint) pairs that meet are intersected exactly
    ray_index, polygon_index = shapely.STRtree(polygons).query(rays, predicate="intersects")
    hits = shapely.intersection(rays[ray_index], polygons[polygon_index])
    distances = shapely.distance(shapely.Point(x, y), hits)
    np.minimum.at(ranges, ray_index, distances)
    return ranges


def visible_outlines(
    world,
    sensor_pose: ArrayLike,
    *,
    fov: float = 2.0 * math.pi,
    range_max: float = math.inf,
    scan_height: float = 0.0,
) -> dict:
    """Return ``{name: shapely.MultiLineString}``: the parts of each outline the sensor sees.

    The outline of every obstacle (``obstacle_footprints``) is cut into pieces of at most
    1 cm; a piece is visible when its midpoint lies inside the field of view (``fov``
    centred on the sensor's heading), within ``range_max``, and the sight line from the
    sensor to it crosses no obstacle. Objects seen nowhere are left out. This is the true
    geometry a perfect scan from ``sensor_pose`` = (x, y, [z,] yaw) would trace.

    Examples
    --------
    >>> from worlds.spec import BoxSpec, PathSpec, SegmentSpec, WorldSpec
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
    >>> spec = WorldSpec(name="v", walls=(), posts=(), people=(),
    ...                  boxes=(BoxSpec("b0", (1.0, 1.0, 1.0), (3.0, 0.0, 0.0)),), path=path)
    >>> round(visible_outlines(spec, (0.0, 0.0, 0.0))["b0"].length, 3)
    1.0
    """
    pose = np.asarray(sensor_pose, dtype=float)
    sensor, yaw = pose[:2], float(pose[-1])
    footprints = obstacle_footprints(
        world, scan_height=scan_height, quad_segs=_VISIBILITY_QUAD_SEGS
    )
    rings = {name: shapely.get_coordinates(f.exterior) for name, f in footprints.items()}
    if not rings:
        return {}
    edge_starts = np.vstack([ring[:-1] for ring in rings.values()])
    edge_ends = np.vstack([ring[1:] for ring in rings.values()])
    visible = {}
    for name, footprint in footprints.items():
        boundary = shapely.segmentize(footprint.exterior, _VISIBILITY_STEP)
        vertices = shapely.get_coordinates(boundary)
        starts, ends = vertices[:-1], vertices[1:]
        offsets = 0.5 * (starts + ends) - sensor
        distances = np.hypot(offsets[:, 0], offsets[:, 1])
        bearings = np.arctan2(offsets[:, 1], offsets[:, 0]) - yaw
        bearings = np.arctan2(np.sin(bearings), np.cos(bearings))
        seen = (distances <= range_max) & (np.abs(bearings) <= 0.5 * fov)
        if not np.any(seen):
            continue
        stop = 1.0 - _SIGHT_LINE_SHORTFALL / np.maximum(distances[seen], _SIGHT_LINE_SHORTFALL)
        seen[seen] = ~_blocked(
            sensor, sensor + offsets[seen] * stop[:, None], edge_starts, edge_ends
        )
        if np.any(seen):
            pieces = shapely.linestrings(np.stack([starts[seen], ends[seen]], axis=1))
            merged = shapely.line_merge(shapely.multilinestrings(pieces))
            if merged.geom_type == "LineString":
                merged = shapely.MultiLineString([merged])
            visible[name] = merged
    return visible


def _blocked(
    sensor: np.ndarray, targets: np.ndarray, edge_starts: np.ndarray, edge_ends: np.ndarray
) -> np.ndarray:
    """Return which sight lines ``sensor -> targets[i]`` properly cross any edge.

    Two segments cross when each one's end points lie strictly on opposite sides of the
    other (signs of 2D cross products); grazing contacts do not block.
    """
    a = edge_starts - sensor
    b = edge_ends - sensor
    edge = edge_ends - edge_starts
    # side of the sensor with respect to each edge's line, cross(edge, sensor - start)
    sensor_side = edge[:, 1] * a[:, 0] - edge[:, 0] * a[:, 1]
    blocked = np.zeros(len(targets), dtype=bool)
    for first in range(0, len(targets), _SIGHT_LINE_CHUNK):
        d = targets[first : first + _SIGHT_LINE_CHUNK] - sensor
        side_a = np.outer(d[:, 0], a[:, 1]) - np.outer(d[:, 1], a[:, 0])
        side_b = np.outer(d[:, 0], b[:, 1]) - np.outer(d[:, 1], b[:, 0])
        target_side = np.outer(d[:, 1], edge[:, 0]) - np.outer(d[:, 0], edge[:, 1]) + sensor_side
        crossing = (side_a * side_b < 0.0) & (sensor_side * target_side < 0.0)
        blocked[first : first + _SIGHT_LINE_CHUNK] = crossing.any(axis=1)
    return blocked
