"""Frozen dataclasses that describe an environment. No PyBullet, no I/O.

A world is data: walls, reflective landmark posts, semi-static boxes, people, the safety
standard's personnel-detection test pieces and the robot's fixed path with its segments
and per-segment safety fields. ``worlds.load``
builds these from TOML; ``sim`` builds them into PyBullet bodies; ``robots`` and
``semistatic`` use the path, segments and fields.

Units are SI, frames REP-103 (x forward, y left, z up, angles CCW in radians).
Points are ``(x, y)`` tuples in the world frame unless stated otherwise; field polygons
are in the robot frame (x ahead of the robot's base, y to its left).

Every class validates itself in ``__post_init__`` (so a spec built in Python is checked
as well as one loaded from a file) and raises :class:`~semistatic.errors.SpecError` with the
offending key relative to the object; the loader re-anchors it in the file. Sequences
are normalised to tuples of floats, so specs are hashable and immutable.

Examples
--------
>>> segment = SegmentSpec(
...     name="straight", start_knot=0, end_knot=1,
...     warning=[(0.25, -0.5), (1.4, -0.5), (1.4, 0.5), (0.25, 0.5)],
...     protective=[(0.25, -0.3), (0.6, -0.3), (0.6, 0.3), (0.25, 0.3)],
... )
>>> path = PathSpec(knots=[(0.0, 0.0), (10.0, 0.0)], segments=[segment])
>>> world = WorldSpec(name="demo", walls=[WallSpec((0.0, -1.2), (10.0, -1.2))],
...                   posts=[PostSpec(1.0, -1.1)], boxes=[], people=[], path=path)
>>> world.path.knots
((0.0, 0.0), (10.0, 0.0))
>>> PostSpec(0.0, 0.0, radius=-1.0)
Traceback (most recent call last):
...
semistatic.errors.SpecError: <memory>: radius: must be > 0.0 and <= 2.0, got -1.0
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely

from semistatic.errors import MEMORY, SpecError
from semistatic.validation import (
    SAFE_NAME,
    bounds,
    check_fields,
    did_you_mean,
    printable,
    safe_name,
)

__all__ = [
    "BOX_SIZE",
    "COORDINATE",
    "FIELD_POINT",
    "MAX_ITEMS",
    "MAX_VERTICES",
    "TEST_PIECE_KINDS",
    "TEST_PIECE_SIZES",
    "TRIGGERS",
    "BoxSpec",
    "PathSpec",
    "PersonSpec",
    "PostSpec",
    "SegmentSpec",
    "TestPieceSpec",
    "WallSpec",
    "WorldSpec",
]

Point = tuple[float, float]

MIN_KNOT_SPACING = 1e-3
"""Consecutive path knots closer than this (m) would make the spline degenerate."""

FIELD_INSIDE_TOLERANCE = 1e-9
"""Slack (m) when checking that the protective field lies inside the warning field."""

WORLD_EXTENT = 1000.0
"""Largest |coordinate| (m) of anything in a world: a square kilometre holds any building."""

FIELD_REACH = 20.0
"""Largest |coordinate| (m) of a field polygon in the robot frame: a safety laser's reach."""

COORDINATE = bounds(ge=-WORLD_EXTENT, le=WORLD_EXTENT)
"""World-frame coordinates (m); also bounds a yaw, which any real angle meets."""

FIELD_POINT = bounds(ge=-FIELD_REACH, le=FIELD_REACH)
BOX_SIZE = bounds(gt=0.0, le=20.0)
"""Box edges (m): a carton to a stack of pallets or a parked vehicle."""

THICKNESS = bounds(gt=0.0, le=5.0)
HEIGHT = bounds(gt=0.0, le=30.0)
RADIUS = bounds(gt=0.0, le=2.0)
UNIT_INTERVAL = bounds(ge=0.0, le=1.0)
KNOT_INDEX = bounds(ge=0, le=10_000)
PERSON_SPEED = bounds(gt=0.0, le=3.0)
"""A walking (1.4 m/s) or hurrying person; nobody runs through a plant at more."""

PATH_SPEED = bounds(gt=0.0, le=2.0)
"""Nominal path speed (m/s): industrial vehicles drive up to about 2 m/s."""

START_TIME = bounds(ge=0.0, le=86_400.0)

LAP_NUMBER = bounds(ge=1, le=1000)
"""A lap of a run, counted from 1 (scenarios run at most 1000 laps)."""

MAX_ITEMS = 1000
"""Most walls, posts, boxes, people or test pieces a world may have (each kind): the
largest bundled world (warehouse) has 10 walls, 40 posts, 5 boxes; the layout checks
compare every pair, so 10^5 boxes kept `check` busy for minutes."""

MAX_VERTICES = 10_000
"""Most points of one list: the path's knots, a person's waypoints, a field polygon (the
bundled worlds have at most a few dozen; a spline through 10,000 knots is a 10 km path)."""


def _check_count(items: Any, limit: int, key: str) -> None:
    """Refuse more than ``limit`` entries in ``items``, before each is looked at."""
    if len(items) > limit:
        raise SpecError(MEMORY, key, f"has {len(items)} entries, more than the limit of "
                        f"{limit}; split the world or simplify it")


def _set(obj: object, name: str, value: Any) -> None:
    object.__setattr__(obj, name, value)


def _rectangle(center: np.ndarray, yaw: float, length: float, width: float) -> np.ndarray:
    """Return the 4 corners (counter-clockwise) of a ``length`` x ``width`` rectangle."""
    c, s = math.cos(yaw), math.sin(yaw)
    half = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]], dtype=float) * [length / 2, width / 2]
    return half @ np.array([[c, s], [-s, c]]) + center


@dataclass(frozen=True)
class WallSpec:
    """A straight wall from ``start`` to ``end`` (centre line), ``thickness`` wide.

    Parameters
    ----------
    start
        ``[x, y]`` of one end of the centre line (m).
    end
        ``[x, y]`` of the other end (m).
    thickness
        Wall thickness (m).
    height
        Wall height (m).
    remission
        Share of laser light reflected (0-1); posts read above 0.9, walls well below.

    Examples
    --------
    >>> wall = WallSpec((0.0, 0.0), (4.0, 0.0), thickness=0.2)
    >>> wall.length
    4.0
    >>> wall.corners().round(2).tolist()
    [[4.0, -0.1], [4.0, 0.1], [0.0, 0.1], [0.0, -0.1]]
    """

    start: Point = field(metadata=COORDINATE)
    end: Point = field(metadata=COORDINATE)
    thickness: float = field(default=0.10, metadata=THICKNESS)
    height: float = field(default=2.5, metadata=HEIGHT)
    remission: float = field(default=0.2, metadata=UNIT_INTERVAL)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.length < MIN_KNOT_SPACING:
            raise SpecError(MEMORY, "end", f"wall has zero length: end equals start {self.start}")

    @property
    def length(self) -> float:
        """Length of the centre line (m)."""
        return math.dist(self.start, self.end)

    @property
    def yaw(self) -> float:
        """Direction of the centre line from ``start`` to ``end`` (rad)."""
        return math.atan2(self.end[1] - self.start[1], self.end[0] - self.start[0])

    def corners(self) -> np.ndarray:
        """Return the ``(4, 2)`` footprint corners, counter-clockwise."""
        center = (np.asarray(self.start) + np.asarray(self.end)) / 2.0
        return _rectangle(center, self.yaw, self.length, self.thickness)


@dataclass(frozen=True)
class PostSpec:
    """A reflective landmark post: a vertical cylinder with high remission.

    Parameters
    ----------
    x
        x of the post centre (m).
    y
        y of the post centre (m).
    radius
        Post radius (m).
    height
        Post height (m).
    remission
        Share of laser light reflected (0-1): high, so the localizer picks it out.

    Examples
    --------
    >>> PostSpec(1, 2).xy
    (1.0, 2.0)
    """

    x: float = field(metadata=COORDINATE)
    y: float = field(metadata=COORDINATE)
    radius: float = field(default=0.04, metadata=RADIUS)
    height: float = field(default=2.5, metadata=HEIGHT)
    remission: float = field(default=0.95, metadata=UNIT_INTERVAL)

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def xy(self) -> Point:
        """Centre of the post in the world frame."""
        return (self.x, self.y)


@dataclass(frozen=True)
class BoxSpec:
    """A semi-static box: ``size`` (sx, sy, sz) centred at ``pose`` (x, y, yaw) on the floor.

    Parameters
    ----------
    name
        Unique name (moves refer to it).
    size
        ``[sx, sy, sz]`` edges of the box (m).
    pose
        ``[x, y, yaw]`` of the box centre on the floor (m, m, rad).
    remission
        Share of laser light reflected (0-1).

    Examples
    --------
    >>> box = BoxSpec("a", size=(0.6, 0.4, 0.5), pose=(1.0, 0.0, 0.0))
    >>> box.corners().round(2).tolist()
    [[1.3, -0.2], [1.3, 0.2], [0.7, 0.2], [0.7, -0.2]]
    """

    name: str = field(metadata=safe_name())
    size: tuple[float, float, float] = field(metadata=BOX_SIZE)
    pose: tuple[float, float, float] = field(metadata=COORDINATE)
    remission: float = field(default=0.3, metadata=UNIT_INTERVAL)

    def __post_init__(self) -> None:
        check_fields(self)

    def corners(self) -> np.ndarray:
        """Return the ``(4, 2)`` footprint corners in the world frame, counter-clockwise."""
        return _rectangle(np.asarray(self.pose[:2]), self.pose[2], self.size[0], self.size[1])


TEST_PIECE_KINDS = ("lying", "upright")
"""The two personnel-detection test pieces: a cylinder lying on the floor (test piece 1, a
person lying down) and one standing upright (test piece 2, a leg)."""

TEST_PIECE_SIZES = {"lying": (0.2, 0.6), "upright": (0.07, 0.4)}
"""Default ``(diameter, length)`` (m) of each kind, as ISO 3691-4 (and EN 1525 before it) is
commonly quoted: test piece 1 200 mm across and 600 mm long, test piece 2 70 mm across and
400 mm high. The standard's own text was not available to us: check it before relying on
them; a piece's ``diameter`` and ``length`` override them."""


@dataclass(frozen=True)
class TestPieceSpec:
    """A personnel-detection test piece: a static cylinder the vehicle must stop before.

    A ``lying`` piece rests on the floor with its axis horizontal, along ``yaw`` (put it
    at right angles to the direction of travel, as the standard does): its top is
    ``diameter`` above the floor, so a safety laser whose scan plane lies higher passes
    over it. An ``upright`` piece stands on its base, ``length`` high.

    Parameters
    ----------
    name
        Unique name (contacts and stops name it).
    kind
        ``lying`` (test piece 1, a person lying down) or ``upright`` (test piece 2, a leg).
    pose
        ``[x, y, yaw]`` of the centre of the piece's footprint on the floor and the
        direction of a lying piece's axis (m, m, rad).
    diameter
        Diameter of the cylinder (m); default 0.2 for a lying piece, 0.07 for an
        upright one (``TEST_PIECE_SIZES``).
    length
        Length of the cylinder along its axis (m): a lying piece's length, an upright
        piece's height; default 0.6 lying, 0.4 upright.
    remission
        Share of laser light reflected (0-1).

    Examples
    --------
    >>> piece = TestPieceSpec("tp1", kind="lying", pose=(3.0, 0.0, math.pi / 2))
    >>> piece.diameter, piece.length, piece.top
    (0.2, 0.6, 0.2)
    >>> [round(b, 3) for b in piece.footprint().bounds]  # 0.2 m along x, 0.6 m along y
    [2.9, -0.3, 3.1, 0.3]
    >>> TestPieceSpec("tp2", kind="upright", pose=(3.0, 0.0, 0.0)).top
    0.4
    >>> TestPieceSpec("tp3", kind="standing", pose=(3.0, 0.0, 0.0))
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: kind: must be one of lying, upright, got 'standing'
    """

    __test__ = False  # a name starting with "Test" is not a test class

    name: str = field(metadata=safe_name())
    kind: str
    pose: tuple[float, float, float] = field(metadata=COORDINATE)
    diameter: float | None = field(
        default=None, metadata=bounds(gt=0.0, le=2.0, fix="metres across, e.g. 0.2"))
    length: float | None = field(
        default=None, metadata=bounds(gt=0.0, le=5.0, fix="metres along the axis, e.g. 0.6"))
    remission: float = field(default=0.3, metadata=UNIT_INTERVAL)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.kind not in TEST_PIECE_KINDS:
            raise SpecError(MEMORY, "kind", f"must be one of {', '.join(TEST_PIECE_KINDS)}, "
                            f"got {self.kind!r}{did_you_mean(self.kind, TEST_PIECE_KINDS)}")
        diameter, length = TEST_PIECE_SIZES[self.kind]
        # Filled in by kind: the two pieces' defaults differ, a dataclass default cannot.
        if self.diameter is None:
            _set(self, "diameter", diameter)
        if self.length is None:
            _set(self, "length", length)

    @property
    def lying(self) -> bool:
        """Whether the piece lies on the floor (its axis horizontal)."""
        return self.kind == "lying"

    @property
    def top(self) -> float:
        """Height (m) of the piece's highest point above the floor."""
        return self.diameter if self.lying else self.length

    def cut_by(self, scan_height: float) -> bool:
        """Return whether a horizontal scan plane at ``scan_height`` (m) passes through the piece.

        A plane level with the top only grazes it (no return to rely on): not cut.

        Examples
        --------
        >>> piece = TestPieceSpec("tp1", kind="lying", pose=(3.0, 0.0, 0.0))
        >>> piece.cut_by(0.15), piece.cut_by(0.2), piece.cut_by(0.35)
        (True, False, False)
        """
        return 0.0 < scan_height < self.top

    def corners(self) -> np.ndarray:
        """Return the ``(4, 2)`` corners, counter-clockwise, of the box round its footprint.

        A lying piece's footprint is that rectangle (``length`` along the axis, ``diameter``
        across); an upright piece's is the disc inside it.
        """
        along = self.length if self.lying else self.diameter
        return _rectangle(np.asarray(self.pose[:2]), self.pose[2], along, self.diameter)

    def footprint(self) -> shapely.Polygon:
        """Return the piece's footprint on the floor (world frame) as a shapely polygon.

        Examples
        --------
        >>> upright = TestPieceSpec("tp2", kind="upright", pose=(1.0, 2.0, 0.0))
        >>> round(upright.footprint().area, 5), round(math.pi * 0.035**2, 5)
        (0.00385, 0.00385)
        """
        if self.lying:
            return shapely.Polygon(self.corners())
        return shapely.Point(self.pose[:2]).buffer(0.5 * self.diameter, quad_segs=64)


TRIGGERS = ("time", "distance", "meet")
"""What starts a person's walk: a clock, or a vehicle coming (see :class:`PersonSpec`)."""


@dataclass(frozen=True)
class PersonSpec:
    """A person (vertical cylinder) walking kinematically through ``waypoints``.

    With ``trigger = "time"`` the person appears at ``waypoints[0]`` at ``start_time``
    (s, simulated time since the run began, or since the lap began when ``per_lap``).
    The other triggers react to a vehicle (``trigger_vehicle``, default the first): the
    person stands at ``waypoints[0]`` (e.g. hidden behind a box) until

    - ``"distance"``: the vehicle's front is ``trigger_distance`` (m) along its path
      before the point where the person's walk crosses the path: the *emergence
      distance*;
    - ``"meet"``: the walk at ``speed`` would meet the vehicle's front at ``meet_at`` of
      its width (0 its right corner, 1 its left) if the vehicle kept its path speed (as
      Euro NCAP times its pedestrian targets);

    then waits ``start_time`` more seconds and walks. A person walks at ``speed`` (m/s) to
    the last waypoint and stays there (or loops back to the first when ``loop``); a
    ``per_lap`` person starts again with every lap. A world may carry people that are off
    (``enabled = false``) for scenarios to switch on with :meth:`WorldSpec.enable_people`.
    A person with ``laps`` acts only in those laps (counted from 1): in the others it is
    not in the scene (parked below the floor, as before its start), its trigger does not
    fire and it counts in no separation, contact or score.

    Parameters
    ----------
    name
        Unique name (scenarios switch people on by it).
    waypoints
        ``[[x, y], ...]`` the person walks through (m).
    radius
        Radius of the body cylinder (m).
    height
        Height of the body cylinder (m).
    speed
        Walking speed (m/s).
    start_time
        When the walk starts (s), from the run or, with ``per_lap``, the lap start; with
        another trigger, the delay after it fires.
    loop
        Walk back to the first waypoint and start again.
    per_lap
        Restart the walk at every lap.
    remission
        Share of laser light reflected (0-1).
    enabled
        Spawned unless a scenario leaves it off (``false``: only when a scenario names it).
    trigger
        ``time``, ``distance`` or ``meet`` (above).
    trigger_vehicle
        Name of the vehicle the trigger watches (empty: the first vehicle).
    trigger_distance
        Emergence distance (m) of the ``distance`` trigger.
    meet_at
        Where across the vehicle's front the ``meet`` trigger aims (0 right, 1 left).
    dwell
        Seconds the person stands at each waypoint (empty: walks on; else one per waypoint).
    laps
        The laps (from 1, ascending) in which the person acts (empty: every lap).

    Examples
    --------
    >>> walker = PersonSpec("walker", waypoints=[(0, -2), (0, 2)], speed=1.0)
    >>> walker.path_length
    4.0
    >>> late = PersonSpec("late", waypoints=[(0, -2), (0, 2)], laps=[3])
    >>> late.laps, late.acts_in(2), late.acts_in(3), walker.acts_in(2)
    ((3,), False, True, True)
    >>> PersonSpec("late", waypoints=[(0, -2), (0, 2)], laps=[3, 2])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: laps: must list laps in ascending order, each once, \
got [3, 2]
    >>> PersonSpec("late", waypoints=[(0, -2), (0, 2)], laps=[0])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: laps[0]: must be >= 1 and <= 1000, got 0
    """

    name: str = field(metadata=safe_name())
    waypoints: tuple[Point, ...] = field(metadata=COORDINATE)
    radius: float = field(default=0.25, metadata=RADIUS)
    height: float = field(default=1.75, metadata=HEIGHT)
    speed: float = field(default=1.0, metadata=PERSON_SPEED)
    start_time: float = field(default=0.0, metadata=START_TIME)
    loop: bool = False
    per_lap: bool = True
    remission: float = field(default=0.3, metadata=UNIT_INTERVAL)
    enabled: bool = True
    trigger: str = "time"
    trigger_vehicle: str = ""
    trigger_distance: float = field(default=2.0, metadata=bounds(ge=0.0, le=100.0))
    meet_at: float = field(default=0.5, metadata=UNIT_INTERVAL)
    dwell: tuple[float, ...] = field(default=(), metadata=START_TIME)
    laps: tuple[int, ...] = field(default=(), metadata=LAP_NUMBER)

    def __post_init__(self) -> None:
        _check_count(self.waypoints, MAX_VERTICES, "waypoints")
        check_fields(self)
        if any(later <= earlier for earlier, later in itertools.pairwise(self.laps)):
            raise SpecError(MEMORY, "laps", "must list laps in ascending order, each once, "
                            f"got {list(self.laps)}")
        if not self.waypoints:
            raise SpecError(MEMORY, "waypoints", "needs at least 1 waypoint, got none")
        if self.trigger not in TRIGGERS:
            raise SpecError(MEMORY, "trigger", f"must be one of {', '.join(TRIGGERS)}, got "
                            f"{self.trigger!r}{did_you_mean(self.trigger, TRIGGERS)}")
        if self.dwell and len(self.dwell) != len(self.waypoints):
            raise SpecError(MEMORY, "dwell", f"needs one time per waypoint ({len(self.waypoints)}),"
                            f" got {len(self.dwell)}")
        if self.trigger_vehicle and not SAFE_NAME.fullmatch(self.trigger_vehicle):
            raise SpecError(MEMORY, "trigger_vehicle",
                            f"must be a vehicle's name, got {self.trigger_vehicle!r}")
        if self.trigger != "time" and len(self.waypoints) < 2:
            raise SpecError(MEMORY, "waypoints", f"trigger '{self.trigger}' needs a walk "
                            "(two waypoints or more) that crosses the vehicle's path")

    def acts_in(self, lap: int) -> bool:
        """Return whether the person is in the scene in lap ``lap`` (from 1)."""
        return not self.laps or lap in self.laps

    @property
    def path_length(self) -> float:
        """Length of the walk from the first to the last waypoint (m)."""
        steps = np.diff(np.asarray(self.waypoints), axis=0)
        return float(np.linalg.norm(steps, axis=1).sum())


def _field_polygon(points: tuple[Point, ...], name: str) -> shapely.Polygon:
    """Return the field as a shapely polygon, or raise if it is empty or not simple."""
    if len(points) < 3:
        raise SpecError(
            MEMORY, name, f"a field polygon needs at least 3 vertices, got {len(points)}"
        )
    polygon = shapely.Polygon(points)
    if shapely.MultiPoint(points).convex_hull.area <= 0.0:
        raise SpecError(MEMORY, name, "polygon is empty (zero area): its vertices are collinear")
    if not shapely.LinearRing(points).is_simple:
        raise SpecError(
            MEMORY, name, "polygon is not simple (its edges cross); list the vertices in order"
        )
    return polygon


@dataclass(frozen=True)
class SegmentSpec:
    """A path segment from knot ``start_knot`` to knot ``end_knot`` and its safety fields.

    ``warning`` and ``protective`` are simple polygons in the robot frame; the protective
    field lies inside the warning field. The segment's local-map frame is anchored at the
    path pose of ``start_knot``.

    Parameters
    ----------
    name
        Unique segment name (local maps are kept per segment).
    start_knot
        Index of the knot where the segment starts.
    end_knot
        Index of the knot where it ends.
    warning
        Warning field polygon ``[[x, y], ...]`` in the robot frame (m).
    protective
        Protective field polygon ``[[x, y], ...]`` in the robot frame (m), inside warning.

    Examples
    --------
    >>> square = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> SegmentSpec("s", 0, 1, warning=square, protective=[(0.3, -0.3), (0.9, 0.0), (0.3, 0.3)])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: protective: protective field is not inside the \
warning field (0.045 m2 of it sticks out); shrink protective or widen warning
    """

    name: str = field(metadata=safe_name())
    start_knot: int = field(metadata=KNOT_INDEX)
    end_knot: int = field(metadata=KNOT_INDEX)
    warning: tuple[Point, ...] = field(metadata=FIELD_POINT)
    protective: tuple[Point, ...] = field(metadata=FIELD_POINT)

    def __post_init__(self) -> None:
        _check_count(self.warning, MAX_VERTICES, "warning")
        _check_count(self.protective, MAX_VERTICES, "protective")
        check_fields(self)
        if self.end_knot <= self.start_knot:
            raise SpecError(
                MEMORY,
                "end_knot",
                f"must be greater than start_knot ({self.start_knot}), got {self.end_knot}",
            )
        warning = _field_polygon(self.warning, "warning")
        protective = _field_polygon(self.protective, "protective")
        outside = protective.difference(warning).area
        if outside > FIELD_INSIDE_TOLERANCE:
            raise SpecError(
                MEMORY,
                "protective",
                f"protective field is not inside the warning field ({outside:.3g} m2 of it "
                "sticks out); shrink protective or widen warning",
            )

    def warning_polygon(self) -> shapely.Polygon:
        """Return the warning field as a shapely polygon in the robot frame.

        Examples
        --------
        >>> square = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
        >>> round(SegmentSpec("s", 0, 1, square, square).warning_polygon().area, 3)
        0.18
        """
        return shapely.Polygon(self.warning)

    def protective_polygon(self) -> shapely.Polygon:
        """Return the protective field as a shapely polygon in the robot frame.

        Examples
        --------
        >>> square = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
        >>> SegmentSpec("s", 0, 1, square, square).protective_polygon().bounds
        (0.3, -0.3, 0.6, 0.3)
        """
        return shapely.Polygon(self.protective)


@dataclass(frozen=True)
class PathSpec:
    """The fixed path: C2 cubic splines through ``knots``, cut into ``segments``.

    ``speed`` is the nominal forward speed u1r (m/s) the follower tracks. Segments are
    listed in path order and cover it without gaps: the first starts at knot 0, each
    starts where the previous ended, the last ends at the last knot.

    Parameters
    ----------
    knots
        ``[[x, y], ...]`` the spline passes through, in driving order (m).
    segments
        The segments, in path order (array of tables ``[[path.segments]]``).
    speed
        Nominal forward speed the follower tracks (m/s).
    closed
        The path is a loop driven lap after lap: the last knot repeats the first, the
        splines join C2 there and vehicles are not carried back to the start between laps.

    Examples
    --------
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> segments = [SegmentSpec("a", 0, 1, field, field), SegmentSpec("b", 1, 2, field, field)]
    >>> PathSpec(knots=[(0, 0), (1, 0), (2, 1)], segments=segments).segment_of_knot(1)
    1
    """

    knots: tuple[Point, ...] = field(metadata=COORDINATE)
    segments: tuple[SegmentSpec, ...]
    speed: float = field(default=0.4, metadata=PATH_SPEED)
    closed: bool = False

    def __post_init__(self) -> None:
        _check_count(self.knots, MAX_VERTICES, "knots")
        _check_count(self.segments, MAX_VERTICES, "segments")
        check_fields(self)
        knots = self.knots
        if len(knots) < 2:
            raise SpecError(MEMORY, "knots", f"needs at least 2 knots, got {len(knots)}")
        if self.closed and (len(knots) < 4 or tuple(knots[0]) != tuple(knots[-1])):
            raise SpecError(
                MEMORY, "knots", "a closed path needs at least 4 knots and must end with its "
                f"first knot {list(knots[0])} repeated (got {list(knots[-1])})"
            )
        steps = np.linalg.norm(np.diff(np.asarray(knots), axis=0), axis=1)
        if np.any(steps < MIN_KNOT_SPACING):
            index = int(np.argmin(steps)) + 1
            raise SpecError(
                MEMORY, f"knots[{index}]", f"repeats the previous knot {knots[index - 1]}"
            )
        _set(self, "segments", tuple(self.segments))
        if not self.segments:
            raise SpecError(MEMORY, "segments", "needs at least 1 segment, got none")
        last = len(knots) - 1
        expected_start = 0
        names: set[str] = set()
        for index, segment in enumerate(self.segments):
            where = f"segments[{index}]"
            if segment.name in names:
                raise SpecError(MEMORY, f"{where}.name", f"duplicate segment name {segment.name!r}")
            names.add(segment.name)
            for name in ("start_knot", "end_knot"):
                knot = getattr(segment, name)
                if knot > last:
                    raise SpecError(
                        MEMORY,
                        f"{where}.{name}",
                        f"knot index {knot} is out of range: the path has {len(knots)} knots "
                        f"(indices 0..{last})",
                    )
            if segment.start_knot != expected_start:
                raise SpecError(
                    MEMORY,
                    f"{where}.start_knot",
                    f"must be {expected_start} so segments cover the path without gaps "
                    f"or overlaps, got {segment.start_knot}",
                )
            expected_start = segment.end_knot
        if expected_start != last:
            raise SpecError(
                MEMORY,
                f"segments[{len(self.segments) - 1}].end_knot",
                f"the last segment must end at the last knot ({last}), got {expected_start}",
            )

    def segment_of_knot(self, knot: int) -> int:
        """Return the index of the segment that starts at or contains ``knot``.

        The last knot belongs to the last segment.
        """
        for index, segment in enumerate(self.segments):
            if segment.start_knot <= knot < segment.end_knot:
                return index
        return len(self.segments) - 1


def _unique(items: tuple[Any, ...], kind: str) -> None:
    seen: dict[str, int] = {}
    for index, item in enumerate(items):
        if item.name in seen:
            raise SpecError(
                MEMORY,
                f"{kind}[{index}].name",
                f"duplicate name {item.name!r} (also {kind}[{seen[item.name]}])",
            )
        seen[item.name] = index


@dataclass(frozen=True)
class WorldSpec:
    """A whole environment. ``source`` is the file it was loaded from (for messages).

    Posts must not overlap each other or a wall; names of boxes and people are unique, and
    so are the test pieces' (among themselves and against boxes and people: contacts name
    them).

    Parameters
    ----------
    name
        World name (default: the file's stem); printable characters only.
    walls
        Static walls (array of inline tables).
    posts
        Reflective landmark posts (array of inline tables).
    boxes
        Semi-static boxes (array of tables ``[[boxes]]``).
    people
        People walking (array of tables ``[[people]]``).
    path
        The robot's path and its segments (table ``[path]``).
    description
        Free text.
    test_pieces
        Personnel-detection test pieces (array of tables ``[[test_pieces]]``).
    source
        Set by the loader to the file read; not a key of the file.

    Examples
    --------
    >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    >>> path = PathSpec([(0, 0), (5, 0)], [SegmentSpec("a", 0, 1, field, field)])
    >>> WorldSpec("w", walls=[], posts=[PostSpec(1, 1), PostSpec(1.05, 1)], boxes=[],
    ...           people=[], path=path)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: posts[1]: overlaps posts[0] (centres 0.05 m apart, \
radii 0.04 + 0.04 m)
    """

    # Any printable text (it defaults to the file's stem), never a control character.
    name: str = field(metadata=printable())
    walls: tuple[WallSpec, ...]
    posts: tuple[PostSpec, ...]
    boxes: tuple[BoxSpec, ...]
    people: tuple[PersonSpec, ...]
    path: PathSpec
    description: str = ""
    # After description, so that every positional call of the older fields still works.
    test_pieces: tuple[TestPieceSpec, ...] = ()
    source: str = MEMORY

    def __post_init__(self) -> None:
        for name in ("walls", "posts", "boxes", "people", "test_pieces"):
            _check_count(getattr(self, name), MAX_ITEMS, name)
        check_fields(self)
        for name in ("walls", "posts", "boxes", "people", "test_pieces"):
            _set(self, name, tuple(getattr(self, name)))
        _unique(self.boxes, "boxes")
        _unique(self.people, "people")
        _unique(self.test_pieces, "test_pieces")
        others = {item.name: kind for kind in ("boxes", "people") for item in getattr(self, kind)}
        for index, piece in enumerate(self.test_pieces):
            if piece.name in others:
                raise SpecError(MEMORY, f"test_pieces[{index}].name", f"{piece.name!r} is also "
                                f"the name of one of the {others[piece.name]}; give it its own")
        centres = np.array([post.xy for post in self.posts], dtype=float).reshape(-1, 2)
        radii = np.array([post.radius for post in self.posts], dtype=float)
        for index in range(1, len(self.posts)):
            gaps = np.linalg.norm(centres[:index] - centres[index], axis=1)
            clash = np.flatnonzero(gaps < radii[:index] + radii[index])
            if clash.size:
                other = int(clash[0])
                raise SpecError(
                    MEMORY,
                    f"posts[{index}]",
                    f"overlaps posts[{other}] (centres {gaps[other]:.2f} m apart, radii "
                    f"{radii[other]:g} + {radii[index]:g} m)",
                )
        walls = [shapely.Polygon(wall.corners()) for wall in self.walls]
        for index, post in enumerate(self.posts):
            disc = shapely.Point(post.xy).buffer(post.radius)
            for wall_index, wall in enumerate(walls):
                if disc.intersection(wall).area > 0.0:
                    raise SpecError(
                        MEMORY,
                        f"posts[{index}]",
                        f"overlaps walls[{wall_index}]; move the post off the wall "
                        f"(its centre at least thickness/2 + radius from the centre line)",
                    )

    @property
    def active_people(self) -> tuple[PersonSpec, ...]:
        """The people with ``enabled = true`` (the ones a simulation should spawn)."""
        return tuple(person for person in self.people if person.enabled)

    def enable_people(self, *names: str) -> WorldSpec:
        """Return a copy of this world with the named people switched on.

        Examples
        --------
        >>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
        >>> path = PathSpec([(0, 0), (5, 0)], [SegmentSpec("a", 0, 1, field, field)])
        >>> walker = PersonSpec("walker", [(2, -1), (2, 1)], enabled=False)
        >>> world = WorldSpec("w", [], [], [], [walker], path)
        >>> [p.name for p in world.enable_people("walker").active_people]
        ['walker']
        >>> world.enable_people("waker")
        Traceback (most recent call last):
        ...
        semistatic.errors.SpecError: <memory>: people: no person named 'waker' (did you mean \
'walker'?)
        """
        known = [person.name for person in self.people]
        for name in names:
            if name not in known:
                raise SpecError(
                    self.source, "people", f"no person named {name!r}{did_you_mean(name, known)}"
                )
        people = tuple(
            dataclasses.replace(person, enabled=True) if person.name in names else person
            for person in self.people
        )
        return dataclasses.replace(self, people=people)
