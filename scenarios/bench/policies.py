"""Safety-field policies: which laser readings count against a segment's fields.

The paper leaves the use of the local maps to "the developers of the navigation system";
a policy is that choice. At every safety scan the vehicle hands the policy a
:class:`FieldView` (the readings in the robot frame, read-only; the segment, its local
map, the EKF pose) and the policy answers with :class:`FieldReadings`: masks of the
readings that count for the warning field and for the protective field. ``None`` (or
:data:`ALL_READINGS`) keeps every reading, as a plain safety scanner does.

A policy may reshape or ignore the fields as it likes (count fewer readings, or none),
but it cannot configure the stop away: whatever it answers, every reading inside the
vehicle's *minimum protective field* counts for both fields: the field the safety
standard's formula asks for at the measured speed, and the footprint grown by the
laser's general supplement on every side (:mod:`scenarios.bench.fields`). So a person in
front of or beside the vehicle always stops it, and a policy sees read-only readings.

A policy may also cap the vehicle's speed (``speed_cap(view)``, a fraction of the path
speed), e.g. where a known object could hide a person.

Write a policy as a subclass of :class:`FieldPolicy` with a ``name`` and a
``counted_readings(view)`` method (and, where it needs them, the hooks ``start_lap``,
``refresh_segment`` and ``speed_cap``)::

    class IgnoreWarning(FieldPolicy):
        name = "ignore-warning"

        def counted_readings(self, view):
            none = np.zeros(len(view.points), dtype=bool)
            return FieldReadings(warning=none, protective=None)

The bundled policies are in :mod:`scenarios.bench.bundled_policies`.

Examples
--------
>>> FieldReadings(warning=np.array([True, False])).protective is None
True
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import shapely

from robots.safety import FieldSet, FieldState, points_inside
from scenarios.spec.scenario import SafetySettings
from scenarios.spec.segments import PathSegment
from semistatic.local_map import LocalMap

__all__ = [
    "ALL_READINGS",
    "FieldPolicy",
    "FieldReadings",
    "FieldView",
    "checked_readings",
    "checked_speed_cap",
    "counted_occupancy",
    "policy_label",
    "policy_name",
]


@dataclass(frozen=True, eq=False)
class FieldView:
    """What a policy may look at for one safety scan.

    Parameters
    ----------
    points
        ``(N, 2)`` valid safety-laser end points in the robot frame (x ahead, y left),
        read-only: the vehicle counts its own copy.
    segment
        The path segment the robot is on; ``segment.fields`` holds its warning and
        protective polygons (robot frame).
    minimum_field
        The vehicle's minimum protective field now (robot frame): readings inside it count
        for both fields, whatever the policy answers.
    robot_pose
        The EKF's robot pose ``(x, y, theta)`` in the world frame.
    local_map
        The segment's local map as it stands before this scan's update.
    settings
        The scenario's safety settings (``adaptive_margin`` and the others).
    walls
        The static map the vehicle knows: every wall's ``(4, 2)`` outline, world frame.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> from scenarios.spec.segments import path_segments
    >>> from worlds import load_world
    >>> segment = path_segments(load_world("pal1"))[0]
    >>> view = FieldView(np.zeros((0, 2)), segment, shapely.Polygon(), np.zeros(3),
    ...                  LocalMap(), load_scenario("pal1").safety)
    >>> view.segment.name
    'niches'
    >>> view.points.flags.writeable
    False
    """

    points: np.ndarray
    segment: PathSegment
    minimum_field: shapely.Geometry
    robot_pose: np.ndarray
    local_map: LocalMap
    settings: SafetySettings
    walls: tuple[np.ndarray, ...] = ()

    def __post_init__(self) -> None:
        # A copy the policy may look at but not write: the vehicle counts its own.
        points = np.array(self.points, dtype=float)
        points.flags.writeable = False
        object.__setattr__(self, "points", points)


@dataclass(frozen=True)
class FieldReadings:
    """Which readings count for each field: ``(N,)`` boolean masks, ``None`` for all.

    Examples
    --------
    >>> FieldReadings(warning=np.array([True, False])).protective is None
    True
    """

    warning: np.ndarray | None = None
    protective: np.ndarray | None = None


ALL_READINGS = FieldReadings()
"""Every reading counts for both fields (a plain safety scanner)."""


class FieldPolicy(abc.ABC):
    """Base class of field policies: which readings count against a segment's fields.

    A subclass sets ``name`` and implements :meth:`counted_readings`; the two lap hooks do
    nothing unless overridden.

    Examples
    --------
    >>> class IgnoreWarning(FieldPolicy):
    ...     name = "ignore-warning"
    ...     def counted_readings(self, view):
    ...         return FieldReadings(warning=np.zeros(len(view.points), dtype=bool))
    >>> IgnoreWarning().speed_cap(None) is None   # the hooks it does not override: no-ops
    True
    """

    name: str = ""
    """The policy's name, as metrics.json and the summaries report it."""

    @abc.abstractmethod
    def counted_readings(self, view: FieldView) -> FieldReadings | None:
        """Return the readings of ``view.points`` that count for each field (``None``: all)."""

    def start_lap(self, local_maps: Mapping[str, LocalMap]) -> None:  # noqa: B027 (a hook)
        """Prepare for a lap; ``local_maps`` are the segments' maps of the laps before."""

    def refresh_segment(self, name: str, local_map: LocalMap) -> None:  # noqa: B027 (a hook)
        """Take segment ``name``'s map: it was just merged with what the fleet shares."""

    def speed_cap(self, view: FieldView) -> float | None:
        """Return a cap on the speed, a fraction of the path speed in [0, 1] (``None``: none)."""
        return None


def policy_name(policy: str | FieldPolicy) -> str:
    """Return the name of a policy given by name or as an object.

    Examples
    --------
    >>> class Mine(FieldPolicy):
    ...     name = "mine"
    ...     def counted_readings(self, view):
    ...         return None
    >>> policy_name("adaptive"), policy_name(Mine())
    ('adaptive', 'mine')
    """
    return policy if isinstance(policy, str) else str(policy.name)


def policy_label(policy: FieldPolicy) -> str:
    """Return how errors name a policy object: its class and its ``name``.

    Examples
    --------
    >>> class Mine(FieldPolicy):
    ...     name = "mine"
    ...     def counted_readings(self, view):
    ...         return None
    >>> policy_label(Mine())
    "policy Mine ('mine')"
    """
    return f"policy {type(policy).__name__} ({policy_name(policy)!r})"


def _described(answer: object) -> str:
    """Return what an answer is, for an error: its type, and for arrays dtype and shape."""
    if isinstance(answer, np.ndarray):
        return f"a {answer.dtype} array of shape {answer.shape}"
    return "None" if answer is None else f"a {type(answer).__name__}"


def checked_readings(policy: FieldPolicy, readings: object, count: int) -> FieldReadings | None:
    """Return a policy's answer for ``count`` readings, or raise naming what is wrong.

    An answer is ``None`` or :class:`FieldReadings` whose masks are ``None`` or ``(count,)``
    boolean arrays; anything else (an integer array would silently index instead of
    mask, a float one would not mask at all) is a ``TypeError`` naming the policy's
    class, the hook and what was expected. A few attribute reads per scan: no cost.

    Examples
    --------
    >>> class Mine(FieldPolicy):
    ...     name = "mine"
    ...     def counted_readings(self, view):
    ...         return None
    >>> checked_readings(Mine(), FieldReadings(np.ones(2, dtype=bool)), 2)
    FieldReadings(warning=array([ True,  True]), protective=None)
    >>> checked_readings(Mine(), FieldReadings(np.ones(3, dtype=int)), 3)
    Traceback (most recent call last):
    ...
    TypeError: policy Mine ('mine').counted_readings returned warning = a int64 array of \
shape (3,); expected None or a boolean numpy array of shape (3,) (one entry per view.points row)
    >>> checked_readings(Mine(), (None, None), 3)
    Traceback (most recent call last):
    ...
    TypeError: policy Mine ('mine').counted_readings returned a tuple; expected \
FieldReadings(warning=..., protective=...) or None
    """
    if readings is None:
        return None
    if not isinstance(readings, FieldReadings):
        raise TypeError(
            f"{policy_label(policy)}.counted_readings returned {_described(readings)}; "
            "expected FieldReadings(warning=..., protective=...) or None"
        )
    for field_name in ("warning", "protective"):
        mask = getattr(readings, field_name)
        if mask is None:
            continue
        if not (isinstance(mask, np.ndarray) and mask.dtype == bool and mask.shape == (count,)):
            raise TypeError(
                f"{policy_label(policy)}.counted_readings returned {field_name} = "
                f"{_described(mask)}; expected None or a boolean numpy array of shape "
                f"({count},) (one entry per view.points row)"
            )
    return readings


def checked_speed_cap(policy: FieldPolicy, cap: object) -> float | None:
    """Return a policy's ``speed_cap`` answer, or raise naming the policy and the hook.

    ``None`` (no cap) or a real number in [0, 1], a fraction of the path speed; a bool,
    a tuple, an array, a string or ``nan`` is an error (``nan`` would never cap).

    Examples
    --------
    >>> class Mine(FieldPolicy):
    ...     name = "mine"
    ...     def counted_readings(self, view):
    ...         return None
    >>> checked_speed_cap(Mine(), 0.5), checked_speed_cap(Mine(), None)
    (0.5, None)
    >>> checked_speed_cap(Mine(), (0.5,))
    Traceback (most recent call last):
    ...
    TypeError: policy Mine ('mine').speed_cap returned a tuple; expected None or a number \
in [0, 1] (a fraction of the path speed)
    >>> checked_speed_cap(Mine(), 1.5)
    Traceback (most recent call last):
    ...
    ValueError: policy Mine ('mine').speed_cap returned 1.5; expected None or a number \
in [0, 1] (a fraction of the path speed)
    """
    if cap is None:
        return None
    expected = "expected None or a number in [0, 1] (a fraction of the path speed)"
    if isinstance(cap, bool) or not isinstance(cap, int | float | np.integer | np.floating):
        raise TypeError(f"{policy_label(policy)}.speed_cap returned {_described(cap)}; {expected}")
    if not 0.0 <= cap <= 1.0:  # nan fails this too
        raise ValueError(f"{policy_label(policy)}.speed_cap returned {cap!r}; {expected}")
    return float(cap)


def counted_occupancy(
    points: np.ndarray,
    fields: FieldSet,
    minimum_field: shapely.Geometry | None,
    readings: FieldReadings | None,
    min_points: int,
) -> FieldState:
    """Count the readings a policy lets count in each field, and every one that must stop.

    A reading counts for a field when it lies inside the field and the policy's mask lets
    it count, or when it lies inside ``minimum_field`` (what the vehicle could touch
    before it stands, :func:`robots.stopping.minimum_protective_field`), wherever that
    is: a policy can shrink a field, it cannot configure the stop away, and a field drawn
    too short or too narrow does not hide what stands beside or just ahead of the
    vehicle. ``minimum_field = None`` drops that rule: only the seeded fault
    ``faults.unguarded_minimum_field`` (:class:`~scenarios.spec.scenario.Faults`) does.

    Examples
    --------
    >>> fields = FieldSet([(0, -1), (2, -1), (2, 1), (0, 1)], [(0, -1), (1, -1), (1, 1), (0, 1)])
    >>> minimum = shapely.box(-0.5, -0.5, 0.2, 0.5)
    >>> points = np.array([[0.1, 0.0], [0.5, 0.0], [1.5, 0.0], [-0.3, 0.4]])
    >>> nothing = np.zeros(4, dtype=bool)
    >>> counted_occupancy(points, fields, minimum, FieldReadings(nothing, nothing), 1)
    FieldState(warning_count=2, protective_count=2, min_points=1)
    >>> counted_occupancy(points, fields, minimum, None, 1)
    FieldState(warning_count=4, protective_count=3, min_points=1)
    >>> counted_occupancy(points, fields, None, FieldReadings(nothing, nothing), 1)
    FieldState(warning_count=0, protective_count=0, min_points=1)
    """
    if minimum_field is None:
        must_stop = np.zeros(len(points), dtype=bool)
    else:
        must_stop = points_inside(minimum_field, points)
    warning = points_inside(fields.warning_polygon, points)
    protective = points_inside(fields.protective_polygon, points)
    if readings is not None:
        if readings.warning is not None:
            warning &= readings.warning
        if readings.protective is not None:
            protective &= readings.protective
    warning |= must_stop
    protective |= must_stop
    return FieldState(
        int(np.count_nonzero(warning)), int(np.count_nonzero(protective)), int(min_points)
    )
