"""Sick-style warning and protective safety fields, and the supervisor that obeys them.

An industrial safety laser (e.g. a Sick S300) watches two robot-frame polygons per path
segment (paper Sec. 1): an object in the *warning* field slows the vehicle down, an
object in the *protective* field stops it. Here:

- ``FieldSet`` holds one segment's pair of polygons (validated: simple, protective inside
  warning);
- ``field_occupancy`` counts the scan points inside each field and, like the ``min_points``
  of Nav2's collision monitor, only lets a field trigger when at least ``min_points`` points
  fall in it, so a single noisy beam is ignored;
- ``SafetySupervisor`` turns the occupancy of each safety scan into a speed scale for the
  path follower (1 clear, ``warning_speed_scale`` warning, 0 protective), holds a zone for
  ``release_delay`` seconds after it was last occupied (the scanner's restart delay), counts
  stops and slowdowns as events, and switches field sets per path segment.

Scan points arrive in the laser's frame; ``scan_points_in_robot_frame`` maps them into the
robot frame given the laser mount ``(x, y, yaw)``.

Examples
--------
>>> fields = FieldSet(
...     warning=[(0.0, -0.5), (2.0, -0.5), (2.0, 0.5), (0.0, 0.5)],
...     protective=[(0.0, -0.4), (0.8, -0.4), (0.8, 0.4), (0.0, 0.4)],
... )
>>> supervisor = SafetySupervisor(fields, SafetyPolicy(min_points=2))
>>> supervisor.observe([[1.5, 0.0], [1.5, 0.1]], stamp=0.0)
SafetyOutput(speed_scale=0.5, zone='warning')
>>> supervisor.observe([[0.5, 0.0], [0.5, 0.1]], stamp=0.08)
SafetyOutput(speed_scale=0.0, zone='protective')
>>> supervisor.stops, supervisor.slowdowns
(1, 1)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import shapely
from numpy.typing import ArrayLike

from semistatic.frames import transform_points
from semistatic.types import Scan, beam_directions

__all__ = [
    "ZONES",
    "FieldSet",
    "FieldState",
    "SafetyOutput",
    "SafetyPolicy",
    "SafetySupervisor",
    "field_occupancy",
    "points_inside",
    "scan_points_in_robot_frame",
]

# Zones from least to most severe.
ZONES = ("clear", "warning", "protective")
# Slack (m) when checking that the protective field lies inside the warning field, so
# fields that share an edge (the usual drawing) are accepted despite rounding.
CONTAINMENT_TOLERANCE = 1e-9


def _polygon_vertices(name: str, vertices: ArrayLike) -> np.ndarray:
    """Validate one field polygon; return its ``(K, 2)`` vertices without a closing repeat."""
    array = np.array(vertices, dtype=float)
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"FieldSet: {name} must be a (K, 2) array of vertices, got {array.shape}")
    if array.shape[0] > 1 and np.array_equal(array[0], array[-1]):
        array = array[:-1]
    if array.shape[0] < 3:
        raise ValueError(f"FieldSet: {name} needs at least 3 vertices, got {array.shape[0]}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"FieldSet: {name} has non-finite vertices; use metres in the robot frame")
    polygon = shapely.Polygon(array)
    if not polygon.is_valid or not polygon.exterior.is_simple or polygon.area <= 0.0:
        raise ValueError(
            f"FieldSet: {name} must be a simple polygon with positive area "
            f"({shapely.is_valid_reason(polygon)}); list its vertices in order around it"
        )
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class FieldSet:
    """The warning and protective fields of one path segment, robot frame.

    Parameters
    ----------
    warning, protective
        ``(K, 2)`` polygon vertices in metres in the robot frame (x ahead, y left), in
        order around the polygon (either direction; a repeated closing vertex is
        dropped). The protective field must lie inside the warning field.
    name
        Optional label, e.g. the path segment's name.

    Examples
    --------
    >>> fields = FieldSet([(0, -1), (2, -1), (2, 1), (0, 1)], [(0, -1), (1, -1), (1, 1), (0, 1)])
    >>> round(fields.warning_polygon.area, 2), round(fields.protective_polygon.area, 2)
    (4.0, 2.0)
    """

    warning: np.ndarray
    protective: np.ndarray
    name: str = ""
    warning_polygon: shapely.Polygon = field(init=False, repr=False)
    protective_polygon: shapely.Polygon = field(init=False, repr=False)
    # (x_min, y_min, x_max, y_max) of each polygon, for the occupancy test's first pass.
    warning_bounds: tuple[float, ...] = field(init=False, repr=False)
    protective_bounds: tuple[float, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        warning = _polygon_vertices("warning", self.warning)
        protective = _polygon_vertices("protective", self.protective)
        warning_polygon = shapely.Polygon(warning)
        protective_polygon = shapely.Polygon(protective)
        if not warning_polygon.buffer(CONTAINMENT_TOLERANCE).covers(protective_polygon):
            raise ValueError(
                "FieldSet: the protective field must lie inside the warning field "
                f"({protective_polygon.difference(warning_polygon).area:.3f} m^2 of it is "
                "outside); enlarge warning or shrink protective"
            )
        shapely.prepare(warning_polygon)
        shapely.prepare(protective_polygon)
        object.__setattr__(self, "warning", warning)
        object.__setattr__(self, "protective", protective)
        object.__setattr__(self, "warning_polygon", warning_polygon)
        object.__setattr__(self, "protective_polygon", protective_polygon)
        object.__setattr__(self, "warning_bounds", tuple(warning_polygon.bounds))
        object.__setattr__(self, "protective_bounds", tuple(protective_polygon.bounds))


@dataclass(frozen=True)
class FieldState:
    """How many scan points lie in each field, and what that means.

    Parameters
    ----------
    warning_count
        Points inside the warning polygon (which includes the protective area).
    protective_count
        Points inside the protective polygon.
    min_points
        Points a field needs to trigger.

    Examples
    --------
    >>> FieldState(warning_count=4, protective_count=1, min_points=3).zone
    'warning'
    """

    warning_count: int
    protective_count: int
    min_points: int

    @property
    def protective_triggered(self) -> bool:
        """Return whether the protective field holds at least ``min_points`` points."""
        return self.protective_count >= self.min_points

    @property
    def warning_triggered(self) -> bool:
        """Return whether the warning field holds at least ``min_points`` points."""
        return self.warning_count >= self.min_points

    @property
    def zone(self) -> str:
        """Return the most severe triggered zone: ``"protective"``, ``"warning"``, ``"clear"``."""
        if self.protective_triggered:
            return "protective"
        return "warning" if self.warning_triggered else "clear"


def field_occupancy(points_robot: ArrayLike, field_set: FieldSet, min_points: int) -> FieldState:
    """Count the robot-frame points inside each field of ``field_set``.

    Parameters
    ----------
    points_robot
        ``(N, 2)`` scan end points in the robot frame; ``nan`` rows (invalid beams) are
        ignored. Points on a field's boundary count as inside (the conservative side).
    field_set
        The active warning and protective fields.
    min_points
        Points a field needs to trigger (>= 1); a smaller cluster, such as one noisy
        beam, is ignored. As Nav2's collision monitor ``min_points``.

    Returns
    -------
    FieldState
        The counts and the resulting zone.

    Examples
    --------
    >>> fields = FieldSet([(0, -1), (2, -1), (2, 1), (0, 1)], [(0, -1), (1, -1), (1, 1), (0, 1)])
    >>> field_occupancy([[0.5, 0.0], [1.5, 0.0], [np.nan, np.nan], [3.0, 0.0]], fields, 1)
    FieldState(warning_count=2, protective_count=1, min_points=1)
    """
    if isinstance(min_points, bool) or int(min_points) != min_points or min_points < 1:
        raise ValueError(f"field_occupancy: min_points must be an integer >= 1, got {min_points}")
    points = np.asarray(points_robot, dtype=float).reshape(-1, 2)
    x, y = points[:, 0], points[:, 1]
    return FieldState(
        _count_inside(field_set.warning_polygon, field_set.warning_bounds, x, y),
        _count_inside(field_set.protective_polygon, field_set.protective_bounds, x, y),
        int(min_points),
    )


def _count_inside(
    polygon: shapely.Polygon, bounds: tuple[float, ...], x: np.ndarray, y: np.ndarray
) -> int:
    """Return how many points intersect ``polygon`` (see :func:`points_inside`)."""
    return int(np.count_nonzero(_inside(polygon, bounds, x, y)))


def points_inside(geometry: shapely.Geometry, points: ArrayLike) -> np.ndarray:
    """Return which robot-frame points intersect ``geometry`` (boundary counts as inside).

    ``nan`` rows are never inside.

    Examples
    --------
    >>> square = shapely.box(0.0, 0.0, 1.0, 1.0)
    >>> points_inside(square, [[0.5, 0.5], [1.0, 0.2], [2.0, 0.0], [np.nan, np.nan]])
    array([ True,  True, False, False])
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    return _inside(geometry, tuple(geometry.bounds), pts[:, 0], pts[:, 1])


def _inside(
    geometry: shapely.Geometry, bounds: tuple[float, ...], x: np.ndarray, y: np.ndarray
) -> np.ndarray:
    """Return which points intersect ``geometry``, testing only those in its bounding box.

    A scan has hundreds of points and a field holds a few: comparing coordinates with
    the (closed) bounding box first leaves the exact predicate a handful to check, with
    the same answer (a point outside the box cannot touch the polygon; nan never is in).
    """
    x_min, y_min, x_max, y_max = bounds
    near = x >= x_min
    near &= x <= x_max
    near &= y >= y_min
    near &= y <= y_max
    if near.any():
        near[near] = shapely.intersects_xy(geometry, x[near], y[near])
    return near


def scan_points_in_robot_frame(scan: Scan, mount: ArrayLike) -> np.ndarray:
    """Return the valid end points of ``scan`` in the robot frame, ``(M, 2)``.

    Parameters
    ----------
    scan
        A scan in its sensor frame (invalid beams are dropped).
    mount
        ``(x, y, yaw)`` of the laser in the robot's base frame.

    Examples
    --------
    >>> scan = Scan(ranges=[1.0, np.inf], angle_min=0.0, angle_increment=0.1, range_max=10.0)
    >>> scan_points_in_robot_frame(scan, [0.2, 0.0, np.pi]).round(3)  # a rear laser
    array([[-0.8,  0. ]])
    """
    ranges = scan.ranges
    # Scan.valid_mask() without its errstate block (comparisons with nan do not warn).
    valid = np.isfinite(ranges)
    valid &= ranges >= scan.range_min
    valid &= ranges <= scan.range_max
    cosines, sines = beam_directions(ranges.size, scan.angle_min, scan.angle_increment)
    # Scan.points() of the valid beams: the same products, cos and sin looked up.
    valid_ranges = ranges[valid]
    points = np.empty((valid_ranges.size, 2))
    np.multiply(valid_ranges, cosines[valid], out=points[:, 0])
    np.multiply(valid_ranges, sines[valid], out=points[:, 1])
    return transform_points(mount, points)


@dataclass(frozen=True)
class SafetyPolicy:
    """How the supervisor reacts to the fields.

    Parameters
    ----------
    warning_speed_scale
        Speed factor in ``(0, 1]`` while the warning field is occupied.
    release_delay
        Seconds a zone is held after the last scan that triggered it (>= 0); a real
        scanner's restart delay, which also bridges flicker at a field's edge.
    min_points
        Points a field needs to trigger (>= 1), see ``field_occupancy``.
    multiple_sampling
        Consecutive scans with a field occupied before it triggers (>= 1): a safety
        scanner's multiple sampling, which filters single-scan flicker at the price of
        response time.

    Examples
    --------
    >>> SafetyPolicy(warning_speed_scale=0.3).release_delay
    0.5
    >>> SafetyPolicy(release_delay=-1.0)
    Traceback (most recent call last):
    ...
    ValueError: SafetyPolicy: release_delay must be >= 0 s (the hold time), got -1.0
    """

    warning_speed_scale: float = 0.5
    release_delay: float = 0.5
    min_points: int = 3
    multiple_sampling: int = 1

    def __post_init__(self) -> None:
        if not 0.0 < self.warning_speed_scale <= 1.0:
            raise ValueError(
                "SafetyPolicy: warning_speed_scale must be in (0, 1] (use the protective "
                f"field to stop), got {self.warning_speed_scale}"
            )
        if not (self.release_delay >= 0.0 and math.isfinite(self.release_delay)):
            raise ValueError(
                "SafetyPolicy: release_delay must be >= 0 s (the hold time), "
                f"got {self.release_delay}"
            )
        for name in ("min_points", "multiple_sampling"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise ValueError(f"SafetyPolicy: {name} must be an integer >= 1, got {value}")


class SafetyOutput(NamedTuple):
    """The supervisor's answer for one safety scan."""

    speed_scale: float
    zone: str


class SafetySupervisor:
    """Turn each safety scan's field occupancy into a speed scale, with release delay.

    A field triggers when ``policy.multiple_sampling`` consecutive scans occupy it; its
    zone is entered then and left only once no scan has triggered it for
    ``policy.release_delay`` seconds. Events, not ticks, are counted:
    ``stops`` counts entries into the protective zone, ``slowdowns`` entries into the
    warning zone from the clear zone (falling back from protective to warning continues
    the same event).

    Parameters
    ----------
    field_set
        The fields of the first path segment; switch with ``set_fields``.
    policy
        Reaction parameters; defaults to ``SafetyPolicy()``.

    Attributes
    ----------
    zone : str
        The current zone (``"clear"`` before the first scan).
    speed_scale : float
        The current speed factor for the follower.
    stops, slowdowns : int
        Event counters since construction or ``reset``.
    last_occupancy : FieldState or None
        The occupancy of the last scan.

    Examples
    --------
    >>> fields = FieldSet([(0, -1), (2, -1), (2, 1), (0, 1)], [(0, -1), (1, -1), (1, 1), (0, 1)])
    >>> supervisor = SafetySupervisor(fields, SafetyPolicy(release_delay=0.2))
    >>> supervisor.update(FieldState(5, 5, 3), stamp=0.0).zone
    'protective'
    >>> supervisor.update(FieldState(0, 0, 3), stamp=0.1).zone  # held
    'protective'
    >>> supervisor.update(FieldState(0, 0, 3), stamp=0.2)
    SafetyOutput(speed_scale=1.0, zone='clear')
    """

    def __init__(self, field_set: FieldSet, policy: SafetyPolicy | None = None) -> None:
        self.policy = SafetyPolicy() if policy is None else policy
        self.field_set = field_set
        self.reset()

    def reset(self) -> None:
        """Clear the zone, the hold timers and the event counters.

        Examples
        --------
        >>> fields = FieldSet([(0, -1), (2, -1), (2, 1), (0, 1)], [(0, 0), (1, 0), (1, 1)])
        >>> supervisor = SafetySupervisor(fields)
        >>> _ = supervisor.update(FieldState(9, 9, 3), stamp=1.0)
        >>> supervisor.reset()
        >>> supervisor.zone, supervisor.stops
        ('clear', 0)
        """
        self.zone = "clear"
        self.speed_scale = 1.0
        self.stops = 0
        self.slowdowns = 0
        self.last_occupancy: FieldState | None = None
        self._last_stamp = -math.inf
        self._last_triggered = {"warning": -math.inf, "protective": -math.inf}
        self._occupied_scans = {"warning": 0, "protective": 0}

    def set_fields(self, field_set: FieldSet) -> None:
        """Switch to another segment's fields; a held zone stays held.

        Examples
        --------
        >>> wide = FieldSet([(0, -1), (2, -1), (2, 1), (0, 1)], [(0, -1), (1, -1), (1, 1), (0, 1)])
        >>> strip = [(0, -0.3), (1, -0.3), (1, 0.3), (0, 0.3)]
        >>> narrow = FieldSet(strip, [(0, 0), (0.5, 0), (0.5, 0.3)])
        >>> supervisor = SafetySupervisor(wide, SafetyPolicy(min_points=1))
        >>> supervisor.observe([[1.5, 0.8]], stamp=0.0).zone
        'warning'
        >>> supervisor.set_fields(narrow)
        >>> supervisor.observe([[1.5, 0.8]], stamp=1.0).zone
        'clear'
        """
        self.field_set = field_set

    def update(self, occupancy: FieldState, stamp: float) -> SafetyOutput:
        """Take one scan's occupancy at time ``stamp`` (s); return speed scale and zone.

        Examples
        --------
        >>> square = [(0, -1), (2, -1), (2, 1), (0, 1)]
        >>> fields = FieldSet(square, [(0, -1), (1, -1), (1, 1), (0, 1)])
        >>> SafetySupervisor(fields).update(FieldState(4, 0, 3), stamp=0.0)
        SafetyOutput(speed_scale=0.5, zone='warning')
        """
        stamp = float(stamp)
        if not stamp >= self._last_stamp:
            raise ValueError(
                f"SafetySupervisor.update: stamp {stamp} s is before the previous one "
                f"({self._last_stamp} s); feed scans in time order or call reset()"
            )
        self._last_stamp = stamp
        self.last_occupancy = occupancy
        # The protective field lies inside the warning field: occupying it occupies both.
        runs, needed = self._occupied_scans, self.policy.multiple_sampling
        runs["protective"] = runs["protective"] + 1 if occupancy.protective_triggered else 0
        runs["warning"] = (runs["warning"] + 1 if occupancy.warning_triggered
                           or occupancy.protective_triggered else 0)
        for candidate in ("warning", "protective"):
            if runs[candidate] >= needed:
                self._last_triggered[candidate] = stamp

        zone = "clear"
        for candidate in ("warning", "protective"):
            held = stamp - self._last_triggered[candidate]
            if held == 0.0 or held < self.policy.release_delay:
                zone = candidate
        if zone == "protective" and self.zone != "protective":
            self.stops += 1
        elif zone == "warning" and self.zone == "clear":
            self.slowdowns += 1
        self.zone = zone
        self.speed_scale = {
            "clear": 1.0,
            "warning": self.policy.warning_speed_scale,
            "protective": 0.0,
        }[zone]
        return SafetyOutput(self.speed_scale, zone)

    def observe(self, points_robot: ArrayLike, stamp: float) -> SafetyOutput:
        """Check robot-frame scan points against the current fields; see ``update``.

        Examples
        --------
        >>> square = [(0, -1), (2, -1), (2, 1), (0, 1)]
        >>> fields = FieldSet(square, [(0, -1), (1, -1), (1, 1), (0, 1)])
        >>> SafetySupervisor(fields).observe(np.empty((0, 2)), stamp=0.0)
        SafetyOutput(speed_scale=1.0, zone='clear')
        """
        occupancy = field_occupancy(points_robot, self.field_set, self.policy.min_points)
        return self.update(occupancy, stamp)

    def observe_scan(self, scan: Scan, mount: ArrayLike) -> SafetyOutput:
        """Check a safety-laser scan (sensor frame, stamped) taken from ``mount``.

        Parameters
        ----------
        scan
            The safety laser's scan; its ``stamp`` is the time.
        mount
            ``(x, y, yaw)`` of the laser in the robot's base frame.

        Examples
        --------
        >>> square = [(0, -1), (2, -1), (2, 1), (0, 1)]
        >>> fields = FieldSet(square, [(0, -1), (1, -1), (1, 1), (0, 1)])
        >>> scan = Scan(ranges=[0.4] * 5, angle_min=-0.1, angle_increment=0.05, range_max=5.0)
        >>> SafetySupervisor(fields).observe_scan(scan, mount=[0.3, 0.0, 0.0])
        SafetyOutput(speed_scale=0.0, zone='protective')
        """
        return self.observe(scan_points_in_robot_frame(scan, mount), scan.stamp)
