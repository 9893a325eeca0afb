"""Frozen dataclasses that describe an environment. No PyBullet, no I/O.

A world is data: walls, reflective landmark posts, semi-static boxes, people and the
robot's fixed path with its segments and per-segment safety fields. ``worlds.load``
builds these from TOML; ``sim`` builds them into PyBullet bodies; ``robots`` and
``semistatic`` use the path, segments and fields.

Units are SI, frames REP-103 (x forward, y left, z up, angles CCW in radians).
Points are ``(x, y)`` tuples in the world frame unless stated otherwise; field polygons
are in the robot frame (x ahead of the robot's base, y to its left).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "BoxSpec",
    "PathSpec",
    "PersonSpec",
    "PostSpec",
    "SegmentSpec",
    "WallSpec",
    "WorldSpec",
]

Point = tuple[float, float]


@dataclass(frozen=True)
class WallSpec:
    """A straight wall from ``start`` to ``end`` (centre line), ``thickness`` wide."""

    start: Point
    end: Point
    thickness: float = 0.10
    height: float = 2.5
    remission: float = 0.2


@dataclass(frozen=True)
class PostSpec:
    """A reflective landmark post: a vertical cylinder with high remission."""

    x: float
    y: float
    radius: float = 0.04
    height: float = 2.5
    remission: float = 0.95


@dataclass(frozen=True)
class BoxSpec:
    """A semi-static box: ``size`` (sx, sy, sz) centred at ``pose`` (x, y, yaw) on the floor."""

    name: str
    size: tuple[float, float, float]
    pose: tuple[float, float, float]
    remission: float = 0.3


@dataclass(frozen=True)
class PersonSpec:
    """A person (vertical cylinder) walking kinematically through ``waypoints``.

    Starts at ``waypoints[0]`` at ``start_time`` (s, simulated time since the run began,
    or since the lap began when ``per_lap``), walks at ``speed`` (m/s) to the last
    waypoint and stays there (or loops back to the first when ``loop``).
    """

    name: str
    waypoints: tuple[Point, ...]
    radius: float = 0.25
    height: float = 1.75
    speed: float = 1.0
    start_time: float = 0.0
    loop: bool = False
    per_lap: bool = True
    remission: float = 0.3


@dataclass(frozen=True)
class SegmentSpec:
    """A path segment from knot ``start_knot`` to knot ``end_knot`` and its safety fields.

    ``warning`` and ``protective`` are simple polygons in the robot frame; the protective
    field lies inside the warning field. The segment's local-map frame is anchored at the
    path pose of ``start_knot``.
    """

    name: str
    start_knot: int
    end_knot: int
    warning: tuple[Point, ...]
    protective: tuple[Point, ...]


@dataclass(frozen=True)
class PathSpec:
    """The fixed path: C2 cubic splines through ``knots``, cut into ``segments``.

    ``speed`` is the nominal forward speed u1r (m/s) the follower tracks.
    """

    knots: tuple[Point, ...]
    segments: tuple[SegmentSpec, ...]
    speed: float = 0.4


@dataclass(frozen=True)
class WorldSpec:
    """A whole environment. ``source`` is the file it was loaded from (for messages)."""

    name: str
    walls: tuple[WallSpec, ...]
    posts: tuple[PostSpec, ...]
    boxes: tuple[BoxSpec, ...]
    people: tuple[PersonSpec, ...]
    path: PathSpec
    source: str = "<memory>"
