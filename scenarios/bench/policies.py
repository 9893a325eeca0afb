"""Safety-field policies: which laser readings count against a segment's fields.

The paper leaves the use of the local maps to "the developers of the navigation system";
a policy is that choice. At every safety scan the vehicle hands the policy a
:class:`FieldView` (the readings in the robot frame, read-only; the segment, its local
map, the EKF pose) and the policy answers with :class:`FieldReadings`: masks of the
readings that count for the warning field and for the protective field. ``None`` (or
:data:`ALL_READINGS`) keeps every reading, as a plain safety scanner does.

A policy may reshape or ignore the fields as it likes (count fewer readings, or none),
but it cannot configure the stop away: whatever it answers, every reading inside the
vehicle's *stop envelope* counts for both fields. The envelope is what the vehicle could
touch before it stands: its footprint swept over the stopping distance at the measured
speed (never less than ``safety.min_protective_depth``), grown by
``safety.general_supplement`` on every side (:func:`robots.stopping.stop_envelope`). So a
person in front of or beside the vehicle always stops it, and a field drawn too short
does not hide them.

Write a policy as a subclass of :class:`FieldPolicy` with a ``name`` and a
``counted_readings(view)`` method (and, where it needs them, the hooks ``start_lap`` and
``refresh_segment``)::

    class IgnoreWarning(FieldPolicy):
        name = "ignore-warning"

        def counted_readings(self, view):
            none = np.zeros(len(view.points), dtype=bool)
            return FieldReadings(warning=none, protective=None)

Two policies are bundled: ``conservative`` (every reading counts) and ``adaptive`` (the
readings explained by semi-static objects confirmed in earlier laps do not count).

Examples
--------
>>> field_policy("adaptive").name
'adaptive'
>>> field_policy("cautious")
Traceback (most recent call last):
...
ValueError: policy: unknown field policy 'cautious'; bundled: conservative, adaptive \
(or pass a scenarios.FieldPolicy object)
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import shapely

from robots.safety import FieldSet, FieldState, points_inside
from scenarios.spec.scenario import POLICIES, SafetySettings
from scenarios.spec.segments import PathSegment
from semistatic.adaptation import explained_readings
from semistatic.frames import transform_points
from semistatic.local_map import LocalMap

__all__ = [
    "ALL_READINGS",
    "AdaptivePolicy",
    "ConservativePolicy",
    "FieldPolicy",
    "FieldReadings",
    "FieldView",
    "checked_readings",
    "counted_occupancy",
    "field_policy",
    "known_objects",
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
    stop_envelope
        The vehicle's stop envelope now (robot frame): readings inside it count for both
        fields, whatever the policy answers.
    robot_pose
        The EKF's robot pose ``(x, y, theta)`` in the world frame.
    local_map
        The segment's local map as it stands before this scan's update.
    settings
        The scenario's safety settings (``adaptive_margin`` and the others).

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
    stop_envelope: shapely.Geometry
    robot_pose: np.ndarray
    local_map: LocalMap
    settings: SafetySettings

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
    >>> field_policy(IgnoreWarning()).name
    'ignore-warning'
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


class ConservativePolicy(FieldPolicy):
    """Every reading counts: the fields as configured, whatever the local maps know.

    Examples
    --------
    >>> ConservativePolicy().counted_readings(None) is None
    True
    """

    name = "conservative"

    def counted_readings(self, view: FieldView) -> FieldReadings | None:
        """Return ``None``: every reading counts for both fields."""
        return None


class AdaptivePolicy(FieldPolicy):
    """Readings explained by known semi-static objects do not count (paper Sec. 4).

    At each lap start the policy takes the *confirmed* polylines of every segment's local
    map (:func:`known_objects`); during the lap, a reading within
    ``settings.adaptive_margin`` of one of its segment's known objects no longer counts
    for either field. The known objects stay fixed for the lap: what the robot learns
    now serves the next lap.

    Examples
    --------
    >>> policy = AdaptivePolicy()
    >>> local_map = LocalMap()
    >>> _ = local_map.add([[1.0, -1.0], [1.0, 1.0]])
    >>> policy.start_lap({"a": local_map})
    >>> policy.known["a"]   # a polyline seen once is not confirmed yet
    []
    """

    name = "adaptive"

    def __init__(self) -> None:
        self.known: dict[str, list[np.ndarray]] = {}

    def start_lap(self, local_maps: Mapping[str, LocalMap]) -> None:
        """Take the confirmed objects of every segment's map as they stand now."""
        self.known = {name: known_objects(local_map) for name, local_map in local_maps.items()}

    def refresh_segment(self, name: str, local_map: LocalMap) -> None:
        """Take segment ``name``'s confirmed objects now (its map was merged with the fleet's).

        A vehicle calls this as it enters a segment whose map it fetched from the fleet
        map store: what another vehicle confirmed serves this vehicle's fields at once.

        Examples
        --------
        >>> import dataclasses
        >>> policy = AdaptivePolicy()
        >>> shared = LocalMap()
        >>> _ = shared.add([[1.0, -1.0], [1.0, 1.0]])
        >>> shared.restore(dataclasses.replace(shared[0], status="confirmed"), replace=True)
        >>> policy.refresh_segment("a", shared)
        >>> len(policy.known["a"])
        1
        """
        self.known[name] = known_objects(local_map)

    def counted_readings(self, view: FieldView) -> FieldReadings | None:
        """Return the readings not explained by a known object of the view's segment."""
        known = self.known.get(view.segment.name)
        if not known:
            return None
        world_points = transform_points(view.robot_pose, view.points)
        unexplained = ~explained_readings(world_points, known, view.settings.adaptive_margin)
        return FieldReadings(warning=unexplained, protective=unexplained)


def known_objects(local_map: LocalMap) -> list[np.ndarray]:
    """Return the confirmed semi-static objects of a local map (world frame) for adaptation.

    Only ``confirmed`` polylines count: seen again after their first scan, so a person
    who walked past once is not "known" and never shrinks a field.

    Examples
    --------
    >>> local_map = LocalMap()
    >>> _ = local_map.add([[1.0, 0.0], [1.0, 1.0]])
    >>> known_objects(local_map)
    []
    """
    return [
        line.points
        for map_id, line in local_map.world_polylines().items()
        if local_map[map_id].status == "confirmed"
    ]


_BUNDLED = {"conservative": ConservativePolicy, "adaptive": AdaptivePolicy}
assert tuple(_BUNDLED) == POLICIES


def field_policy(policy: str | FieldPolicy) -> FieldPolicy:
    """Return a fresh bundled policy by name, or ``policy`` itself if it is a policy object.

    Raises ``ValueError`` naming ``policy`` for an unknown name or an object that does not
    follow :class:`FieldPolicy`.

    Examples
    --------
    >>> field_policy("conservative").name
    'conservative'
    >>> custom = ConservativePolicy()
    >>> field_policy(custom) is custom
    True
    """
    if isinstance(policy, str):
        if policy not in _BUNDLED:
            raise ValueError(
                f"policy: unknown field policy {policy!r}; bundled: {', '.join(POLICIES)} "
                "(or pass a scenarios.FieldPolicy object)"
            )
        return _BUNDLED[policy]()
    if not isinstance(policy, FieldPolicy) or not (isinstance(policy.name, str) and policy.name):
        raise ValueError(
            f"policy: {policy!r} is no field policy: subclass scenarios.FieldPolicy, give it "
            "a name (str) and a counted_readings(view) method"
        )
    return policy


def policy_name(policy: str | FieldPolicy) -> str:
    """Return the name of a policy given by name or as an object.

    Examples
    --------
    >>> policy_name("adaptive"), policy_name(ConservativePolicy())
    ('adaptive', 'conservative')
    """
    return policy if isinstance(policy, str) else str(policy.name)


def checked_readings(policy: FieldPolicy, readings: object, count: int) -> FieldReadings | None:
    """Return a policy's answer for ``count`` readings, or raise naming what is wrong.

    An answer is ``None`` or :class:`FieldReadings` whose masks are ``None`` or ``(count,)``
    boolean arrays; anything else (an integer array would silently index instead of
    mask) is a ``TypeError`` naming the policy and the hook.

    Examples
    --------
    >>> checked_readings(ConservativePolicy(), FieldReadings(np.ones(2, dtype=bool)), 2)
    FieldReadings(warning=array([ True,  True]), protective=None)
    >>> checked_readings(ConservativePolicy(), FieldReadings(np.ones(3, dtype=int)), 3)
    Traceback (most recent call last):
    ...
    TypeError: policy 'conservative': counted_readings(view).warning must be None or a \
(3,) bool array (one entry per view.points row), got int64 array of shape (3,)
    """
    if readings is None:
        return None
    name = f"policy {policy_name(policy)!r}: counted_readings(view)"
    if not isinstance(readings, FieldReadings):
        raise TypeError(
            f"{name} must return FieldReadings or None, got {type(readings).__name__}"
        )
    for field_name in ("warning", "protective"):
        mask = getattr(readings, field_name)
        if mask is None:
            continue
        if not (isinstance(mask, np.ndarray) and mask.dtype == bool and mask.shape == (count,)):
            got = (f"{mask.dtype} array of shape {mask.shape}" if isinstance(mask, np.ndarray)
                   else type(mask).__name__)
            raise TypeError(
                f"{name}.{field_name} must be None or a ({count},) bool array (one entry "
                f"per view.points row), got {got}"
            )
    return readings


def counted_occupancy(
    points: np.ndarray,
    fields: FieldSet,
    stop_envelope: shapely.Geometry,
    readings: FieldReadings | None,
    min_points: int,
) -> FieldState:
    """Count the readings a policy lets count in each field, and every one that must stop.

    A reading counts for a field when it lies inside the field and the policy's mask lets
    it count, or when it lies inside ``stop_envelope`` (what the vehicle could touch
    before it stands, :func:`robots.stopping.stop_envelope`), wherever that is: a policy
    can shrink a field, it cannot configure the stop away, and a field drawn too short or
    too narrow does not hide what stands beside or just ahead of the vehicle.

    Examples
    --------
    >>> fields = FieldSet([(0, -1), (2, -1), (2, 1), (0, 1)], [(0, -1), (1, -1), (1, 1), (0, 1)])
    >>> envelope = shapely.box(-0.5, -0.5, 0.2, 0.5)
    >>> points = np.array([[0.1, 0.0], [0.5, 0.0], [1.5, 0.0], [-0.3, 0.4]])
    >>> nothing = np.zeros(4, dtype=bool)
    >>> counted_occupancy(points, fields, envelope, FieldReadings(nothing, nothing), 1)
    FieldState(warning_count=2, protective_count=2, min_points=1)
    >>> counted_occupancy(points, fields, envelope, None, 1)
    FieldState(warning_count=4, protective_count=3, min_points=1)
    """
    must_stop = points_inside(stop_envelope, points)
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
