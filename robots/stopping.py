"""How far a vehicle travels before it stands, and where a reading must stop it.

A protective stop is not instant: the vehicle keeps its speed while the scanner sees the
object and the controller reacts (the *reaction time*), then brakes. With speed ``v``,
reaction time ``T`` and deceleration ``a`` the stopping distance is

    S = v T + v^2 / (2 a)

(the stopping-distance part of the protective-field length in SICK's scanner manuals and
of ISO 13855's ``S = K T + C``). Anything the vehicle could touch before it stands lies
in its *stop envelope*: the footprint swept ``S`` metres along the direction of travel,
grown by a supplement on every side. A reading there must stop the vehicle whatever a
field policy decides (:mod:`scenarios.bench.policies`).

Examples
--------
>>> round(stopping_distance(1.0, reaction_time=0.1, deceleration=1.0), 3)
0.6
>>> box = [(-0.2, -0.2), (0.2, -0.2), (0.2, 0.2), (-0.2, 0.2)]
>>> stop_envelope(box, reach=0.5, supplement=0.1).bounds
(-0.3, -0.3, 0.8, 0.3)
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from numpy.typing import ArrayLike

__all__ = ["blind_reach", "stop_envelope", "stopping_distance"]


def stopping_distance(speed: float, reaction_time: float, deceleration: float) -> float:
    """Return the distance (m) travelled from a stop request until standstill.

    ``speed`` in m/s (its magnitude counts), ``reaction_time`` (s) at constant speed,
    then constant ``deceleration`` (m/s^2, > 0).

    Examples
    --------
    >>> round(stopping_distance(0.4, reaction_time=0.1, deceleration=1.0), 6)
    0.12
    >>> stopping_distance(0.0, reaction_time=0.1, deceleration=1.0)
    0.0
    """
    if not (reaction_time >= 0.0 and math.isfinite(reaction_time)):
        raise ValueError(f"stopping_distance: reaction_time must be >= 0 s, got {reaction_time}")
    if not (deceleration > 0.0 and math.isfinite(deceleration)):
        raise ValueError(f"stopping_distance: deceleration must be > 0 m/s^2, got {deceleration}")
    v = abs(float(speed))
    return v * reaction_time + v * v / (2.0 * deceleration)


def stop_envelope(footprint: ArrayLike, reach: float, supplement: float) -> shapely.Polygon:
    """Return the robot-frame region in which a reading must stop the vehicle.

    The footprint swept ``reach`` metres along x (negative: reversing), as the convex hull
    of the footprint at both ends, grown by ``supplement`` metres on every side: what the
    vehicle could touch before it stands, from the front, the sides or behind. The sweep
    is straight; on a curve the supplement covers the difference for the short stopping
    distances of indoor vehicles.

    Examples
    --------
    >>> box = [(-0.2, -0.2), (0.2, -0.2), (0.2, 0.2), (-0.2, 0.2)]
    >>> round(stop_envelope(box, reach=0.0, supplement=0.1).area, 3)  # standing: a grown box
    0.351
    >>> stop_envelope(box, reach=-0.3, supplement=0.0).bounds   # reversing sweeps behind
    (-0.5, -0.2, 0.2, 0.2)
    """
    if not (supplement >= 0.0 and math.isfinite(supplement)):
        raise ValueError(f"stop_envelope: supplement must be >= 0 m, got {supplement}")
    if not math.isfinite(reach):
        raise ValueError(f"stop_envelope: reach must be finite, got {reach}")
    outline = np.asarray(footprint, dtype=float).reshape(-1, 2)
    swept = np.vstack([outline, outline + np.array([float(reach), 0.0])])
    hull = shapely.convex_hull(shapely.MultiPoint(swept))
    return shapely.buffer(hull, supplement) if supplement > 0.0 else hull


def blind_reach(footprint: ArrayLike, mount_x: float, range_min: float) -> float:
    """Return how far ahead of the footprint's front a forward scanner sees nothing (m).

    A scanner at ``mount_x`` (robot frame, looking ahead) reports nothing nearer than
    ``range_min``: an object straight ahead is first seen ``mount_x + range_min`` ahead
    of the axle. A stop envelope that ends before that is never watched; this is the
    least reach ahead that it needs (0 when the blind zone ends inside the footprint).

    Examples
    --------
    >>> box = [(-0.27, -0.19), (0.18, -0.19), (0.18, 0.19), (-0.27, 0.19)]
    >>> round(blind_reach(box, mount_x=0.12, range_min=0.5), 3)  # a Pioneer's LMS100
    0.44
    >>> blind_reach(box, mount_x=0.12, range_min=0.05)
    0.0
    """
    front = float(np.asarray(footprint, dtype=float).reshape(-1, 2)[:, 0].max())
    return max(0.0, float(mount_x) + float(range_min) - front)
