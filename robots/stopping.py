"""Stopping distances and protective fields sized by the safety standard's formula.

A protective stop is not instant. From the moment an object enters the protective field
the vehicle keeps its speed ``v`` while the scanner confirms it (its *response time*:
``multiple_sampling`` scan periods) and until the controller's next command (the
*command latency*); then it brakes at ``a``. Its stopping distance is

    S_A = v T + B(v),    T = multiple_sampling * scan_period + command_latency

where the braking distance ``B(v) ~ v^2 / (2 a)`` is that of the follower's ramp: its
command drops by ``a T_c`` at every control period ``T_c``, from the first command after
the stop (:meth:`StopModel.braking_distance`; ``v^2 / (2 a) - v T_c / 2`` when
``v / (a T_c)`` is whole)
(Sick's operating instructions for the S300, S3000 and microScan3, "stopping distance"
of mobile applications; ISO 13855's ``S = K (T_M + T_S) + C`` is the stationary
machine's form). The protective field must be at least

    S_L = S_A + Z_G + Z_R + Z_F   long (from the vehicle's front),
    S_B = F_B + 2 (Z_G + Z_R + Z_F)   wide (the vehicle's width F_B plus both sides),

with the supplements for general measurement errors ``Z_G``, for reflection near
retroreflectors ``Z_R`` and for a lack of ground clearance ``Z_F`` (:class:`Supplements`);
and it must reach past the scanner's blind zone, or nothing ahead is ever seen.
Following Sick, the person is assumed to stand still: only the vehicle's speed counts.

Examples
--------
>>> model = StopModel(scanner_response_s=0.16, command_latency_s=0.0, control_period_s=0.02,
...                   deceleration=1.0)
>>> round(model.distance(1.0), 3)          # 0.16 s at 1 m/s, then 0.49 m of braking
0.65
>>> supplements = Supplements(general=0.1, reflector=0.2, ground_clearance=0.15)
>>> [round(value, 3) for value in field_size(model.distance(1.0), supplements, 0.8)]
[1.1, 1.7]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike

__all__ = [
    "FLAT_GROUND_CLEARANCE",
    "FLAT_GROUND_SUPPLEMENT",
    "StopModel",
    "Supplements",
    "blind_reach",
    "field_size",
    "ground_clearance_supplement",
    "minimum_protective_field",
    "required_field",
    "response_time",
    "stopping_distance",
    "visible_distance",
]

FLAT_GROUND_CLEARANCE = 0.12
"""Ground clearance (m) below which Sick's flat-rate supplement ``Z_F`` applies."""

FLAT_GROUND_SUPPLEMENT = 0.15
"""Sick's flat-rate supplement ``Z_F`` (m) for a vehicle with less ground clearance:
a person's foot is detected above the foot, which reaches further under the vehicle."""


def response_time(scan_period: float, multiple_sampling: int) -> float:
    """Return a scanner's response time (s): ``multiple_sampling`` scan periods.

    An object that appears just after a scan is in the next ``multiple_sampling``
    scans before the field triggers: the worst case.

    Examples
    --------
    >>> response_time(0.08, 2)
    0.16
    """
    if not (scan_period > 0.0 and math.isfinite(scan_period)):
        raise ValueError(f"response_time: scan_period must be > 0 s, got {scan_period}")
    if isinstance(multiple_sampling, bool) or int(multiple_sampling) != multiple_sampling \
            or multiple_sampling < 1:
        raise ValueError(f"response_time: multiple_sampling must be an integer >= 1, "
                         f"got {multiple_sampling}")
    return int(multiple_sampling) * float(scan_period)


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


@dataclass(frozen=True)
class StopModel:
    """How a vehicle stops: the scanner responds, the controller acts, the vehicle brakes.

    Parameters
    ----------
    scanner_response_s
        The safety scanner's response time (s), :func:`response_time`.
    command_latency_s
        The longest wait (s) from the scan that confirms the object to the control
        command that acts on it.
    control_period_s
        The control period (s): the follower lowers its command once per period.
    deceleration
        The braking deceleration (m/s^2): the lower of the follower's limit and what the
        motors can give.

    Examples
    --------
    >>> model = StopModel(0.16, 0.0, 0.02, 1.0)
    >>> model.reaction_time, round(model.braking_distance(1.0), 6)
    (0.16, 0.49)
    """

    scanner_response_s: float
    command_latency_s: float
    control_period_s: float
    deceleration: float

    def __post_init__(self) -> None:
        for name in ("scanner_response_s", "command_latency_s", "control_period_s"):
            value = getattr(self, name)
            if not (value >= 0.0 and math.isfinite(value)):
                raise ValueError(f"StopModel: {name} must be >= 0 s, got {value}")
        if not (self.deceleration > 0.0 and math.isfinite(self.deceleration)):
            raise ValueError(f"StopModel: deceleration must be > 0 m/s^2, got {self.deceleration}")

    @property
    def reaction_time(self) -> float:
        """Return the time (s) at full speed before braking starts."""
        return self.scanner_response_s + self.command_latency_s

    def braking_distance(self, speed: float) -> float:
        """Return the distance (m) of the follower's braking ramp from ``speed`` (m/s).

        Commands ``v - a T_c k`` for ``k = 1, 2, ...``, each held one control period
        ``T_c``, until zero; ``v^2 / (2 a)`` when the period is 0.
        """
        v, a, period = abs(float(speed)), self.deceleration, self.control_period_s
        if period == 0.0:
            return v * v / (2.0 * a)
        step = a * period
        steps = math.floor(v / step)  # whole steps above zero
        return period * (steps * v - step * steps * (steps + 1) / 2.0)

    def distance(self, speed: float) -> float:
        """Return the stopping distance (m) from ``speed`` (m/s)."""
        return abs(float(speed)) * self.reaction_time + self.braking_distance(speed)


def ground_clearance_supplement(ground_clearance: float) -> float:
    """Return ``Z_F`` (m): Sick's flat rate below 120 mm of ground clearance, else 0.

    Examples
    --------
    >>> ground_clearance_supplement(0.06), ground_clearance_supplement(0.15)
    (0.15, 0.0)
    """
    return FLAT_GROUND_SUPPLEMENT if ground_clearance < FLAT_GROUND_CLEARANCE else 0.0


@dataclass(frozen=True)
class Supplements:
    """The supplements of a protective field (m): ``Z_G``, ``Z_R`` and ``Z_F``.

    ``reflector`` is 0 where no retroreflector is near the field.

    Examples
    --------
    >>> round(Supplements(general=0.1, reflector=0.0, ground_clearance=0.15).total, 3)
    0.25
    """

    general: float
    reflector: float
    ground_clearance: float

    def __post_init__(self) -> None:
        for name in ("general", "reflector", "ground_clearance"):
            value = getattr(self, name)
            if not (value >= 0.0 and math.isfinite(value)):
                raise ValueError(f"Supplements: {name} must be >= 0 m, got {value}")

    @property
    def total(self) -> float:
        """Return ``Z_G + Z_R + Z_F`` (m)."""
        return self.general + self.reflector + self.ground_clearance


def field_size(stopping: float, supplements: Supplements,
               vehicle_width: float) -> tuple[float, float]:
    """Return the protective field's least length ``S_L`` and width ``S_B`` (m).

    ``stopping`` is the stopping distance ``S_A`` (m); the length is measured from the
    vehicle's front.

    Examples
    --------
    >>> field_size(0.5, Supplements(0.1, 0.0, 0.0), vehicle_width=0.6)
    (0.6, 0.8)
    """
    total = supplements.total
    return stopping + total, vehicle_width + 2.0 * total


def blind_reach(footprint: ArrayLike, mount_x: float, range_min: float) -> float:
    """Return how far ahead of the footprint's front a forward scanner sees nothing (m).

    A scanner at ``mount_x`` (robot frame, looking ahead) reports nothing nearer than
    ``range_min``: an object straight ahead is first seen ``mount_x + range_min`` ahead
    of the axle (0 when the blind zone ends inside the footprint).

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


def required_field(footprint: ArrayLike, length: float, width: float) -> shapely.Polygon:
    """Return the rectangle a protective field must cover (robot frame).

    From the footprint's front ``length`` metres ahead, ``width`` metres wide and centred
    on the footprint's lateral extent.

    Examples
    --------
    >>> box = [(-0.2, -0.2), (0.2, -0.2), (0.2, 0.2), (-0.2, 0.2)]
    >>> required_field(box, 0.5, 0.8).bounds
    (0.2, -0.4, 0.7, 0.4)
    """
    outline = np.asarray(footprint, dtype=float).reshape(-1, 2)
    front = float(outline[:, 0].max())
    centre = 0.5 * float(outline[:, 1].min() + outline[:, 1].max())
    return shapely.box(front, centre - 0.5 * width, front + length, centre + 0.5 * width)


def minimum_protective_field(footprint: ArrayLike, length: float, width: float,
                             general_supplement: float) -> shapely.Geometry:
    """Return the field no field policy may shrink: ahead, beside and behind the vehicle.

    The rectangle the standard's formula asks for at the current speed
    (:func:`required_field`), together with the footprint grown by the general
    supplement on every side: what the vehicle could touch before it stands, from the
    front, the sides or behind.

    Examples
    --------
    >>> box = [(-0.2, -0.2), (0.2, -0.2), (0.2, 0.2), (-0.2, 0.2)]
    >>> minimum_protective_field(box, 0.5, 0.8, 0.1).bounds
    (-0.3, -0.4, 0.7, 0.4)
    """
    outline = np.asarray(footprint, dtype=float).reshape(-1, 2)
    around = shapely.buffer(shapely.Polygon(outline), general_supplement)
    return shapely.union(required_field(outline, length, width), around)


def visible_distance(range_min: float, angular_resolution: float, radius: float,
                     min_points: int) -> float:
    """Return the least distance (m) at which a scanner still sees a round body ahead.

    A body of ``radius`` (m) centred straight ahead at distance ``D`` is seen by the beams
    (``angular_resolution`` rad apart, one on the centre line) that hit its outline at a
    range of at least ``range_min``: near the scanner only the edges of its silhouette are
    that far. It counts as seen with ``min_points`` such beams. Closer, a vehicle that
    stopped for the body no longer sees it and drives on once its field clears.

    Examples
    --------
    >>> round(visible_distance(0.05, math.radians(0.5), 0.25, 3), 3)   # an S300: at once
    0.26
    >>> round(visible_distance(0.5, math.radians(0.5), 0.25, 3), 3)    # an LMS100
    0.61
    """
    step = 0.001
    distance = max(range_min, radius) + step
    while True:
        beams = np.arange(0.0, math.asin(radius / distance), angular_resolution)
        beams = np.concatenate([-beams[1:], beams])
        along = distance * np.cos(beams)
        across = distance * np.sin(beams)
        ranges = along - np.sqrt(np.maximum(radius * radius - across * across, 0.0))
        if np.count_nonzero(ranges >= range_min) >= min_points:
            return distance
        distance += step
