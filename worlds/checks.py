"""Check that a world's layout makes a usable testbench for the robot driving its path.

The robot drives the world's path; at arc length ``s`` it carries the warning and
protective fields of the segment it is on, placed at ``path.pose(s)``. A good layout
(paper Sec. 6: "obstacles have been placed so that [...] such objects partially or
totally lie inside the warning or the protective areas", docs/design.md) has

- at least three reflective posts in view from every path pose (three-object
  triangulation, paper Sec. 5.1), the line of sight blocked by walls and boxes;
- every semi-static box reaching into some warning field, but staying clear of every
  protective field (a box in a protective field would stop the robot for good);
- walls and posts out of every warning field (only semi-static objects slow the robot);
- the robot's footprint, swept along the path, clear of boxes and walls;
- boxes, posts and test pieces standing free (not inside walls or each other) and people
  walking in free space.

The personnel-detection test pieces (:class:`~worlds.spec.TestPieceSpec`) belong on the
path: no field or footprint check applies to them. Whether a vehicle's safety laser can see
one depends on its scan plane's height, :func:`piece_scan_margins` (the robot is the
scenario's: ``scenarios.spec.pieces`` turns the margins into findings).

Each check is a pure function that returns its measure (gaps in m, overlap areas in m2,
post counts), so tests can assert on numbers; :func:`layout_problems` turns the measures
into readable :class:`LayoutProblem` s against :class:`Clearances`. Geometry is checked
with shapely every ``Clearances.path_step`` metres along the path. No PyBullet.

Examples
--------
>>> from worlds.load import load_world
>>> layout_problems(load_world("sim1"))
[]
>>> import dataclasses
>>> world = load_world("sim1")
>>> box = dataclasses.replace(world.boxes[0], pose=(3.0, -0.3, 0.0))  # onto the path
>>> for problem in layout_problems(dataclasses.replace(world, boxes=(box,))):
...     print(problem)
box 'carton_aisle': overlaps a protective field (needs a gap of >= 0.05 m)
box 'carton_aisle': the swept robot footprint overlaps it (needs a gap of >= 0.1 m)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterable, Sequence

import numpy as np
import shapely
from numpy.typing import ArrayLike

from robots.path import SplinePath
from semistatic.errors import MEMORY, SpecError
from semistatic.frames import transform_points, wrap_angle
from worlds.spec import PathSpec, PersonSpec, WorldSpec

__all__ = [
    "PIONEER_FOOTPRINT",
    "Clearances",
    "LayoutProblem",
    "box_footprint_gaps",
    "box_polygons",
    "box_protective_gaps",
    "box_warning_overlaps",
    "fields_along_path",
    "layout_problems",
    "overlapping_solids",
    "path_poses",
    "people_in_obstacles",
    "person_area",
    "person_walk",
    "piece_scan_margins",
    "placed",
    "post_discs",
    "segment_indices",
    "spline_of",
    "static_in_warning",
    "swept_footprint",
    "visible_post_counts",
    "visible_posts",
    "wall_footprint_gaps",
    "wall_polygons",
]

PIONEER_FOOTPRINT = ((0.2275, -0.1905), (0.2275, 0.1905), (-0.2275, 0.1905), (-0.2275, -0.1905))
"""Pioneer 3-DX base (0.455 m x 0.381 m) centred on base_link, counter-clockwise.

Centred rather than 4.5 cm behind the axle as the URDF body is: the worlds were laid out
with this box, which reaches further forward, where the fields and boxes are.
"""

PATH_CACHE_SIZE = 32
"""Paths whose sampled fields and swept footprint are kept (one per world and footprint)."""

AREA_TOLERANCE = 0.0
"""Overlap area (m2) above which two solids count as overlapping: any at all."""


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0.0):
        raise SpecError(MEMORY, name, f"must be a finite number > 0, got {value}")


@dataclasses.dataclass(frozen=True)
class Clearances:
    """The numbers a layout must meet (SI units).

    Parameters
    ----------
    protective
        Smallest gap (m) between a box and any protective field along the path.
    footprint
        Smallest gap (m) between the swept robot footprint and a box or a wall.
    min_warning_overlap
        Smallest area (m2) of a box inside one warning field: the box must be seen.
    min_visible_posts
        Posts the robot must see from every path pose (three-object triangulation).
    post_range
        Range (m) up to which a post counts as visible (Sick LMS100: 20 m at 90 % remission,
        kept shorter for the narrow posts).
    field_of_view
        Laser field of view (rad), centred on the robot's heading.
    path_step
        Spacing (m) of the checked path poses.

    Examples
    --------
    >>> Clearances().min_visible_posts
    3
    >>> Clearances(protective=-0.05)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: protective: must be a finite number > 0, got -0.05
    """

    protective: float = 0.05
    footprint: float = 0.10
    min_warning_overlap: float = 0.01
    min_visible_posts: int = 3
    post_range: float = 15.0
    field_of_view: float = math.radians(270.0)
    path_step: float = 0.05

    def __post_init__(self) -> None:
        for name in ("protective", "footprint", "min_warning_overlap", "post_range", "path_step"):
            _positive(name, float(getattr(self, name)))
        if not 0.0 < self.field_of_view <= 2.0 * math.pi:
            raise SpecError(
                MEMORY, "field_of_view", f"must be in (0, 2 pi] rad, got {self.field_of_view}"
            )
        count = self.min_visible_posts
        if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 0:
            raise SpecError(
                MEMORY,
                "min_visible_posts",
                f"must be an integer >= 0, got {self.min_visible_posts!r}",
            )


@dataclasses.dataclass(frozen=True)
class LayoutProblem:
    """One way a layout fails a check.

    ``check`` names the check (``"posts"``, ``"warning"``, ``"protective"``, ``"footprint"``,
    ``"static"``, ``"solids"``, ``"people"``), ``subject`` the thing at fault, ``boxes`` the
    semi-static boxes involved (so a box move that causes the problem can be blamed).

    Examples
    --------
    >>> print(LayoutProblem("warning", "box 'a'", "never enters a warning field", ("a",)))
    box 'a': never enters a warning field
    """

    check: str
    subject: str
    message: str
    boxes: tuple[str, ...] = ()

    def __str__(self) -> str:
        return f"{self.subject}: {self.message}"


def placed(polygon: shapely.Polygon | ArrayLike, pose: ArrayLike) -> shapely.Polygon:
    """Return a robot-frame polygon (shapely or ``(N, 2)`` vertices) moved to ``pose``.

    Examples
    --------
    >>> placed([(0, 0), (1, 0), (1, 1)], [2.0, 0.0, np.pi / 2]).bounds
    (1.0, 0.0, 2.0, 1.0)
    """
    if isinstance(polygon, shapely.Polygon):
        polygon = np.asarray(polygon.exterior.coords)[:-1]
    return shapely.Polygon(transform_points(pose, np.asarray(polygon, dtype=float)))


def wall_polygons(world: WorldSpec) -> list[shapely.Polygon]:
    """Return each wall's footprint as a polygon, in ``world.walls`` order.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> round(wall_polygons(load_world("sim1"))[0].area, 2)  # 11 m x 0.1 m
    1.1
    """
    return _polygons([wall.corners() for wall in world.walls])


def box_polygons(world: WorldSpec) -> list[shapely.Polygon]:
    """Return each box's footprint as a polygon, in ``world.boxes`` order.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> round(box_polygons(load_world("sim1"))[0].area, 2)  # 0.6 m x 0.5 m
    0.3
    """
    return _polygons([box.corners() for box in world.boxes])


def _polygons(corners: list[np.ndarray]) -> list[shapely.Polygon]:
    """Return one polygon per ``(4, 2)`` corner array, made in one call."""
    return list(shapely.polygons(np.array(corners, dtype=float))) if corners else []


def post_discs(world: WorldSpec) -> list[shapely.Polygon]:
    """Return each post's cross-section as a (buffered) disc, in ``world.posts`` order.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> round(post_discs(load_world("sim1"))[0].area, 4)  # radius 4 cm
    0.005
    """
    if not world.posts:
        return []
    # (One GEOS call for all posts; the same discs as one Point.buffer each.)
    return list(shapely.buffer(shapely.points([post.xy for post in world.posts]),
                               [post.radius for post in world.posts], quad_segs=16))


def build_spline(path: PathSpec) -> SplinePath:
    """Return a new spline for ``path``: periodic when the path is closed, else natural.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> build_spline(load_world("sim1").path).closed
    False
    """
    return SplinePath(path.knots, bc_type="periodic" if path.closed else "natural")


@functools.lru_cache(maxsize=PATH_CACHE_SIZE)
def spline_of(path: PathSpec) -> SplinePath:
    """Return the spline the robot drives for ``path`` (cached: specs are immutable).

    Examples
    --------
    >>> from worlds.load import load_world
    >>> round(spline_of(load_world("sim1").path).length, 2)
    10.4
    """
    return build_spline(path)


def path_poses(path: PathSpec, step: float = Clearances.path_step) -> np.ndarray:
    """Return ``(M, 3)`` path poses every ``step`` metres or less, both ends included.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> path_poses(load_world("sim1").path)[0].round(3).tolist()
    [1.0, 0.0, 0.0]
    """
    return spline_of(path).sample(step)[1]


def segment_indices(path: PathSpec, s: ArrayLike) -> np.ndarray:
    """Return the index of the segment driven at each arc length ``s``.

    A segment owns its start knot; the last segment also owns the path's end.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> path = load_world("sim1").path
    >>> segment_indices(path, [0.0, 4.4, 4.5, 100.0]).tolist()
    [0, 0, 1, 2]
    """
    spline = spline_of(path)
    starts = np.array([spline.knot_s[segment.start_knot] for segment in path.segments])
    s = np.asarray(s, dtype=float)
    return np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(starts) - 1)


@functools.lru_cache(maxsize=PATH_CACHE_SIZE)
def _fields(path: PathSpec, step: float) -> tuple[tuple[shapely.Polygon, ...], ...]:
    s, poses = spline_of(path).sample(step)
    segments = [path.segments[index] for index in segment_indices(path, s)]
    warning = tuple(
        placed(segment.warning, pose) for segment, pose in zip(segments, poses, strict=True)
    )
    protective = tuple(
        placed(segment.protective, pose) for segment, pose in zip(segments, poses, strict=True)
    )
    return warning, protective


@functools.lru_cache(maxsize=PATH_CACHE_SIZE)
def _protective_union(path: PathSpec, step: float) -> shapely.Geometry:
    return shapely.union_all(list(_fields(path, float(step))[1]))


def fields_along_path(
    path: PathSpec, step: float = Clearances.path_step
) -> tuple[tuple[shapely.Polygon, ...], tuple[shapely.Polygon, ...]]:
    """Return the warning and protective fields (world frame) at each pose of :func:`path_poses`.

    Cached per path and step: a world's boxes may move, its path does not.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> warning, protective = fields_along_path(load_world("sim1").path)
    >>> len(warning) == len(protective) == len(path_poses(load_world("sim1").path))
    True
    >>> [round(b, 2) for b in warning[0].bounds]  # aisle field at the start pose (1, 0, 0)
    [1.25, -0.95, 2.4, 0.95]
    """
    return _fields(path, float(step))


@functools.lru_cache(maxsize=PATH_CACHE_SIZE)
def _swept(path: PathSpec, footprint: tuple[tuple[float, float], ...], step: float):
    return shapely.union_all([placed(footprint, pose) for pose in path_poses(path, step)])


def swept_footprint(
    path: PathSpec, footprint: ArrayLike = PIONEER_FOOTPRINT, step: float = Clearances.path_step
) -> shapely.Geometry:
    """Return the area the robot's ``footprint`` (robot frame) covers driving ``path``.

    Examples
    --------
    >>> from worlds.spec import SegmentSpec
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> path = PathSpec([(0, 0), (2, 0)], [SegmentSpec("a", 0, 1, field, field)])
    >>> [round(b, 3) for b in swept_footprint(path).bounds]
    [-0.228, -0.191, 2.228, 0.191]
    """
    vertices = tuple((float(x), float(y)) for x, y in np.asarray(footprint, dtype=float))
    return _swept(path, vertices, float(step))


def visible_post_counts(
    world: WorldSpec,
    poses: ArrayLike,
    *,
    post_range: float = Clearances.post_range,
    field_of_view: float = Clearances.field_of_view,
) -> np.ndarray:
    """Return how many posts each pose sees: in range, in the field of view, unoccluded.

    The line of sight from the pose to a post's centre must not cross a wall or a box.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("sim1")
    >>> visible_post_counts(world, [[1.0, 0.0, 0.0], [1.0, 0.0, np.pi]]).tolist()
    [6, 2]
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    rows, _ = visible_posts(world, poses, post_range=post_range, field_of_view=field_of_view)
    return np.bincount(rows, minlength=len(poses)).astype(int)


def visible_posts(
    world: WorldSpec,
    poses: ArrayLike,
    *,
    post_range: float = Clearances.post_range,
    field_of_view: float = Clearances.field_of_view,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the ``(pose index, post index)`` pairs of every post a pose sees.

    Seen as :func:`visible_post_counts` counts: within ``post_range`` of the pose, inside
    the ``field_of_view`` centred on its heading, the line of sight to the post's centre
    crossing no wall and no box. Pairs are ordered by pose, then post.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> rows, posts = visible_posts(load_world("sim1"), [[1.0, 0.0, np.pi]])
    >>> rows.tolist(), posts.tolist()
    ([0, 0], [0, 5])
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    empty = np.zeros(0, dtype=int)
    if not world.posts:
        return empty, empty
    rows, cols = _candidate_sight_lines(world, poses, post_range, field_of_view)
    if rows.size == 0:
        return empty, empty
    blockers = shapely.union_all(wall_polygons(world) + box_polygons(world))
    shapely.prepare(blockers)
    clear = ~shapely.intersects(blockers, _sight_lines(world, poses, rows, cols))
    return rows[clear], cols[clear]


def _candidate_sight_lines(
    world: WorldSpec, poses: np.ndarray, post_range: float, field_of_view: float
) -> tuple[np.ndarray, np.ndarray]:
    """Return (pose index, post index) pairs in range and inside the field of view."""
    posts = np.array([post.xy for post in world.posts]).reshape(-1, 2)
    offsets = posts[None, :, :] - poses[:, None, :2]
    distance = np.linalg.norm(offsets, axis=2)
    bearing = wrap_angle(np.arctan2(offsets[..., 1], offsets[..., 0]) - poses[:, 2:3])
    return np.nonzero((distance <= post_range) & (np.abs(bearing) <= field_of_view / 2))


def _sight_lines(
    world: WorldSpec, poses: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> np.ndarray:
    posts = np.array([post.xy for post in world.posts]).reshape(-1, 2)
    if rows.size == 0:
        return np.empty(0, dtype=object)
    return shapely.linestrings(np.stack([poses[rows, :2], posts[cols]], axis=1))


def _occluding_boxes(
    world: WorldSpec, poses: np.ndarray, post_range: float, field_of_view: float
) -> tuple[str, ...]:
    """Return the boxes that block some line of sight from ``poses`` to a post."""
    rows, cols = _candidate_sight_lines(world, poses, post_range, field_of_view)
    sight = _sight_lines(world, poses, rows, cols)
    return tuple(
        box.name
        for box, polygon in zip(world.boxes, box_polygons(world), strict=True)
        if np.any(shapely.intersects(polygon, sight))
    )


def _hiding_boxes(world: WorldSpec, short: np.ndarray, limits: Clearances) -> tuple[str, ...]:
    """Return the boxes to blame for the ``short`` poses seeing too few posts.

    A box is to blame when taking it away alone lets some of those poses see enough.
    When no single box does, but taking them all away does (boxes hiding posts together),
    every box that blocks a line of sight from those poses is. Where the walls alone hide
    too much, no box is at fault.
    """

    def enough(boxes: tuple) -> np.ndarray:
        counts = visible_post_counts(
            dataclasses.replace(world, boxes=boxes),
            short,
            post_range=limits.post_range,
            field_of_view=limits.field_of_view,
        )
        return counts >= limits.min_visible_posts

    boxes = world.boxes
    decisive = tuple(
        box.name
        for index, box in enumerate(boxes)
        if np.any(enough(boxes[:index] + boxes[index + 1 :]))
    )
    if decisive:
        return decisive
    fixable = short[enough(())]
    return _occluding_boxes(world, fixable, limits.post_range, limits.field_of_view)


def box_warning_overlaps(world: WorldSpec, warning: Sequence[shapely.Polygon]) -> dict[str, float]:
    """Return, per box name, its largest overlap area (m2) with any one warning field.

    ``warning`` are the world-frame fields from :func:`fields_along_path`.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("sim1")
    >>> overlaps = box_warning_overlaps(world, fields_along_path(world.path)[0])
    >>> {name: round(area, 3) for name, area in overlaps.items()}
    {'carton_aisle': 0.133, 'pallet_turn': 0.064, 'carton_north': 0.14}
    """
    tree = shapely.STRtree(list(warning))
    overlaps = {}
    for box, polygon in zip(world.boxes, box_polygons(world), strict=True):
        hits = tree.query(polygon, predicate="intersects")
        areas = shapely.area(shapely.intersection(tree.geometries.take(hits), polygon))
        overlaps[box.name] = float(np.max(areas)) if hits.size else 0.0
    return overlaps


def box_protective_gaps(
    world: WorldSpec, protective: Sequence[shapely.Polygon] | shapely.Geometry
) -> dict[str, float]:
    """Return, per box name, its distance (m) to the nearest protective field (0 if inside).

    ``protective`` are the world-frame fields from :func:`fields_along_path`, or their
    union (one geometry) when it is at hand.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("sim1")
    >>> gaps = box_protective_gaps(world, fields_along_path(world.path)[1])
    >>> {name: round(gap, 3) for name, gap in gaps.items()}
    {'carton_aisle': 0.085, 'pallet_turn': 0.261, 'carton_north': 0.127}
    """
    union = (
        protective
        if isinstance(protective, shapely.Geometry)
        else shapely.union_all(list(protective))
    )
    return {
        box.name: float(union.distance(polygon))
        for box, polygon in zip(world.boxes, box_polygons(world), strict=True)
    }


def box_footprint_gaps(world: WorldSpec, swept: shapely.Geometry) -> dict[str, float]:
    """Return, per box name, its distance (m) to the swept robot footprint.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("sim1")
    >>> gaps = box_footprint_gaps(world, swept_footprint(world.path))
    >>> {name: round(gap, 2) for name, gap in gaps.items()}
    {'carton_aisle': 0.54, 'pallet_turn': 0.77, 'carton_north': 0.41}
    """
    return {
        box.name: float(swept.distance(polygon))
        for box, polygon in zip(world.boxes, box_polygons(world), strict=True)
    }


def wall_footprint_gaps(world: WorldSpec, swept: shapely.Geometry) -> np.ndarray:
    """Return each wall's distance (m) to the swept robot footprint, in ``world.walls`` order.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("sim1")
    >>> round(float(wall_footprint_gaps(world, swept_footprint(world.path)).min()), 2)
    1.02
    """
    return shapely.distance(swept, np.array(wall_polygons(world), dtype=object)).astype(float)


def static_in_warning(world: WorldSpec, warning: Sequence[shapely.Polygon]) -> list[str]:
    """Return the walls and posts (``"walls[i]"``, ``"posts[j]"``) that enter a warning field.

    Only semi-static objects should slow the robot down; a wall in a warning field would
    slow it on every lap.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = load_world("sim1")
    >>> static_in_warning(world, fields_along_path(world.path)[0])
    []
    """
    tree = shapely.STRtree(list(warning))
    labelled = [(f"walls[{i}]", polygon) for i, polygon in enumerate(wall_polygons(world))]
    labelled += [(f"posts[{i}]", disc) for i, disc in enumerate(post_discs(world))]
    return [label for label, polygon in labelled if tree.query(polygon, "intersects").size]


def piece_scan_margins(world: WorldSpec, scan_height: float) -> dict[str, float]:
    """Return, per test piece, how far (m) its top rises above a scan plane at ``scan_height``.

    Positive: the plane cuts the piece (a lying piece's top is its diameter, an upright
    piece's its height); zero or negative: the plane passes over it, and a safety laser
    scanning there cannot detect it.

    Examples
    --------
    >>> import dataclasses
    >>> from worlds.load import load_world
    >>> from worlds.spec import TestPieceSpec
    >>> pieces = (TestPieceSpec("lying", "lying", (3.0, 0.0, np.pi / 2)),
    ...           TestPieceSpec("upright", "upright", (5.0, 0.0, 0.0)))
    >>> world = dataclasses.replace(load_world("sim1"), test_pieces=pieces)
    >>> {name: round(gap, 3) for name, gap in piece_scan_margins(world, 0.35).items()}
    {'lying': -0.15, 'upright': 0.05}
    """
    return {piece.name: piece.top - float(scan_height) for piece in world.test_pieces}


def _solids(world: WorldSpec) -> list[tuple[str, shapely.Polygon]]:
    """Return the labelled footprints of boxes, posts and test pieces."""
    solids = [
        (f"box {box.name!r}", polygon)
        for box, polygon in zip(world.boxes, box_polygons(world), strict=True)
    ]
    solids += [(f"posts[{i}]", disc) for i, disc in enumerate(post_discs(world))]
    solids += [(f"test piece {piece.name!r}", piece.footprint()) for piece in world.test_pieces]
    return solids


def overlapping_solids(world: WorldSpec) -> list[tuple[str, str]]:
    """Return pairs of solids whose footprints overlap: in a wall or in each other.

    Solids are boxes, posts and test pieces, labelled ``"box 'name'"``, ``"posts[j]"`` and
    ``"test piece 'name'"``, and walls, ``"walls[i]"``; walls may meet each other
    (corners), so wall pairs are not checked.

    Examples
    --------
    >>> import dataclasses
    >>> from worlds.load import load_world
    >>> world = load_world("sim1")
    >>> overlapping_solids(world)
    []
    >>> box = dataclasses.replace(world.boxes[0], pose=(3.0, -1.5, 0.0))  # into the wall
    >>> overlapping_solids(dataclasses.replace(world, boxes=(box,)))
    [("box 'carton_aisle'", 'walls[0]')]
    """
    solids = _solids(world)
    walls = list(enumerate(wall_polygons(world)))
    pairs = []
    for index, (label, polygon) in enumerate(solids):
        pairs += [
            (label, f"walls[{i}]")
            for i, wall in walls
            if wall.intersection(polygon).area > AREA_TOLERANCE
        ]
        pairs += [
            (label, other_label)
            for other_label, other in solids[index + 1 :]
            if polygon.intersection(other).area > AREA_TOLERANCE
        ]
    return pairs


def people_in_obstacles(world: WorldSpec) -> dict[str, tuple[str, ...]]:
    """Return, per person whose walk (body swept along the waypoints) hits a solid, the solids.

    Every person is checked, enabled or not: a scenario may switch them on.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> people_in_obstacles(load_world("pal3"))
    {}
    """
    solids = _solids(world)
    boxes = len(world.boxes)
    # Boxes, walls, then posts and test pieces: the order the messages have always listed.
    labelled = solids[:boxes]
    labelled += [(f"walls[{i}]", polygon) for i, polygon in enumerate(wall_polygons(world))]
    labelled += solids[boxes:]
    blocked = {}
    for person in world.people:
        body = person_area(person)
        hits = tuple(label for label, polygon in labelled if body.intersects(polygon))
        if hits:
            blocked[person.name] = hits
    return blocked


def person_area(person: PersonSpec) -> shapely.Polygon:
    """Return the ground a person covers: the body's disc swept along its waypoints.

    Examples
    --------
    >>> from worlds.spec import PersonSpec
    >>> standing = PersonSpec(name="p", waypoints=((1.0, 0.0),), radius=0.25)
    >>> round(person_area(standing).area, 2), person_area(standing).bounds
    (0.2, (0.75, -0.25, 1.25, 0.25))
    """
    return person_walk(person).buffer(person.radius)


def person_walk(person: PersonSpec) -> shapely.LineString | shapely.Point:
    """Return the line a person's centre walks (a point for one standing still).

    A shape meets the person's body exactly when it lies within ``person.radius`` of this
    line (``shapely.dwithin``): exact, where :func:`person_area`'s buffer is a polygon
    whose chords cut the disc by up to a few tenths of a millimetre.

    Examples
    --------
    >>> from worlds.spec import PersonSpec
    >>> person_walk(PersonSpec(name="p", waypoints=((1.0, 0.0), (2.0, 0.0)))).length
    1.0
    """
    if len(person.waypoints) > 1:
        return shapely.LineString(person.waypoints)
    return shapely.Point(person.waypoints[0])


def _box_names(labels: Iterable[str], world: WorldSpec) -> tuple[str, ...]:
    names = {f"box {box.name!r}": box.name for box in world.boxes}
    return tuple(names[label] for label in labels if label in names)


def layout_problems(
    world: WorldSpec,
    *,
    footprint: ArrayLike = PIONEER_FOOTPRINT,
    clearances: Clearances | None = None,
) -> list[LayoutProblem]:
    """Return every way ``world``'s layout fails the checks of this module (empty if none).

    Parameters
    ----------
    world
        The environment, boxes where they stand for the lap in question.
    footprint
        The robot's footprint, ``(N, 2)`` vertices in its base frame (REP-103).
    clearances
        The numbers to meet; :class:`Clearances` defaults when ``None``.

    Examples
    --------
    >>> import dataclasses
    >>> from worlds.load import load_world
    >>> world = load_world("pal1")
    >>> layout_problems(world)
    []
    >>> back = dataclasses.replace(world.boxes[0], pose=(5.0, -1.025, 0.0))  # against the wall
    >>> for problem in layout_problems(dataclasses.replace(world, boxes=(back,))):
    ...     print(problem)
    box 'carton_west': never enters a warning field (largest overlap 0.000 m2, needs >= 0.01 m2)
    """
    limits = clearances or Clearances()
    problems: list[LayoutProblem] = []

    poses = path_poses(world.path, limits.path_step)
    counts = visible_post_counts(
        world, poses, post_range=limits.post_range, field_of_view=limits.field_of_view
    )
    short = np.flatnonzero(counts < limits.min_visible_posts)
    if short.size:
        worst = int(short[np.argmin(counts[short])])
        x, y, _ = poses[worst]
        hiding = _hiding_boxes(world, poses[short], limits)
        by = f"; hidden by {', '.join(f'box {name!r}' for name in hiding)}" if hiding else ""
        problems.append(
            LayoutProblem(
                "posts",
                "path",
                f"{short.size} pose(s) see fewer than {limits.min_visible_posts} posts, the "
                f"worst {counts[worst]} at ({x:.2f}, {y:.2f}){by}",
                hiding,
            )
        )

    warning, _ = fields_along_path(world.path, limits.path_step)
    for name, area in box_warning_overlaps(world, warning).items():
        if area <= limits.min_warning_overlap:
            problems.append(
                LayoutProblem(
                    "warning",
                    f"box {name!r}",
                    f"never enters a warning field (largest overlap {area:.3f} m2, needs "
                    f">= {limits.min_warning_overlap:g} m2)",
                    (name,),
                )
            )
    protective_union = _protective_union(world.path, limits.path_step)
    for name, gap in box_protective_gaps(world, protective_union).items():
        if gap < limits.protective:
            where = f"is {gap:.3f} m from" if gap > 0.0 else "overlaps"
            problems.append(
                LayoutProblem(
                    "protective",
                    f"box {name!r}",
                    f"{where} a protective field (needs a gap of >= {limits.protective:g} m)",
                    (name,),
                )
            )

    swept = swept_footprint(world.path, footprint, limits.path_step)
    box_gaps = box_footprint_gaps(world, swept)
    wall_gaps = wall_footprint_gaps(world, swept)
    labelled_gaps = [(f"box {name!r}", gap, (name,)) for name, gap in box_gaps.items()]
    labelled_gaps += [(f"walls[{i}]", float(gap), ()) for i, gap in enumerate(wall_gaps)]
    for label, gap, boxes in labelled_gaps:
        if gap < limits.footprint:
            where = f"is {gap:.3f} m from" if gap > 0.0 else "overlaps"
            problems.append(
                LayoutProblem(
                    "footprint",
                    label,
                    f"the swept robot footprint {where} it "
                    f"(needs a gap of >= {limits.footprint:g} m)",
                    boxes,
                )
            )

    problems += [
        LayoutProblem("static", label, "enters a warning field: only semi-static boxes may")
        for label in static_in_warning(world, warning)
    ]
    problems += [
        LayoutProblem("solids", first, f"overlaps {second}", _box_names((first, second), world))
        for first, second in overlapping_solids(world)
    ]
    problems += [
        LayoutProblem(
            "people",
            f"person {name!r}",
            f"walks into {', '.join(hits)}",
            _box_names(hits, world),
        )
        for name, hits in people_in_obstacles(world).items()
    ]
    return problems
