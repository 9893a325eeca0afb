"""The bundled field policies: conservative, adaptive (the paper's) and guarded.

- ``conservative``: every reading counts, the fields as configured.
- ``adaptive``: readings explained by semi-static objects confirmed in earlier laps do
  not count for either field (paper Sec. 4): no slowdown or stop for a known box.
- ``guarded``: readings explained by known objects do not count for the *warning* field,
  but the protective field stays whole, and where a known object could hide a person
  (a gap of at least a person's width between it and the static walls behind it) the
  vehicle keeps the warning field's slowdown while that object is in the warning field.
  A box flush against a wall hides nobody: the vehicle passes it at speed.

Examples
--------
>>> [field_policy(name).name for name in POLICIES]
['conservative', 'adaptive', 'guarded']
>>> field_policy("cautious")
Traceback (most recent call last):
...
ValueError: policy: unknown field policy 'cautious'; bundled: conservative, adaptive, \
guarded (or pass a scenarios.FieldPolicy object)
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import shapely

from scenarios.bench.policies import FieldPolicy, FieldReadings, FieldView
from scenarios.spec.scenario import POLICIES
from semistatic.adaptation import explained_readings
from semistatic.frames import inverse, transform_points
from semistatic.local_map import LocalMap

__all__ = [
    "HIDING_GAP",
    "AdaptivePolicy",
    "ConservativePolicy",
    "GuardedPolicy",
    "field_policy",
    "hiding_objects",
    "known_objects",
]

HIDING_GAP = 0.5
"""Free width (m) behind an object in which a person can stand: a person's diameter."""


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


class GuardedPolicy(AdaptivePolicy):
    """Known objects free the warning field unless they could hide a person.

    As :class:`AdaptivePolicy` for the warning field; the protective field keeps every
    reading. At each lap start the known objects that could hide a person
    (:func:`hiding_objects`: at least :data:`HIDING_GAP` of free space between them and
    the static walls) are noted; while one of them lies in the segment's warning field
    the speed is capped at the warning field's slowdown, as if the object counted.

    Examples
    --------
    >>> GuardedPolicy().name
    'guarded'
    """

    name = "guarded"

    def __init__(self) -> None:
        super().__init__()
        self.hiding: dict[str, list[np.ndarray]] = {}
        self._walls: tuple[np.ndarray, ...] | None = None

    def start_lap(self, local_maps: Mapping[str, LocalMap]) -> None:
        """Take the confirmed objects; which can hide a person is decided at the first view."""
        super().start_lap(local_maps)
        self.hiding = {}

    def refresh_segment(self, name: str, local_map: LocalMap) -> None:
        """Take segment ``name``'s confirmed objects now; decide again which hide people."""
        super().refresh_segment(name, local_map)
        self.hiding.pop(name, None)

    def counted_readings(self, view: FieldView) -> FieldReadings | None:
        """Return the readings not explained by a known object for the warning field."""
        readings = super().counted_readings(view)
        return None if readings is None else FieldReadings(warning=readings.warning)

    def speed_cap(self, view: FieldView) -> float | None:
        """Return the slowdown while an object that could hide a person is in the field."""
        name = view.segment.name
        if name not in self.hiding:
            self.hiding[name] = hiding_objects(self.known.get(name, []), view.walls)
        hiding = self.hiding[name]
        if not hiding:
            return None
        field = view.segment.fields.warning_polygon
        for outline in hiding:
            local = transform_points(inverse(view.robot_pose), outline)
            if shapely.intersects(field, shapely.LineString(local) if len(local) > 1
                                  else shapely.Point(local[0])):
                return view.settings.slowdown
        return None


def hiding_objects(objects: list[np.ndarray],
                   walls: tuple[np.ndarray, ...]) -> list[np.ndarray]:
    """Return the objects (world-frame polylines) a person could stand behind.

    An object hides nobody when a static wall stands closer to it than
    :data:`HIDING_GAP`: there is no room for a person between them.

    Examples
    --------
    >>> wall = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 0.1], [0.0, 0.1]])
    >>> flush = np.array([[1.0, 0.2], [2.0, 0.2]])
    >>> free = np.array([[1.0, 1.5], [2.0, 1.5]])
    >>> [len(line) for line in hiding_objects([flush, free], (wall,))]
    [2]
    """
    if not walls:
        return list(objects)
    static = shapely.union_all([shapely.Polygon(outline) for outline in walls])
    return [outline for outline in objects
            if shapely.distance(static, shapely.LineString(outline) if len(outline) > 1
                                else shapely.Point(outline[0])) >= HIDING_GAP]


_BUNDLED = {"conservative": ConservativePolicy, "adaptive": AdaptivePolicy,
            "guarded": GuardedPolicy}
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


