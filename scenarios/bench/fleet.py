"""Vehicles among vehicles: what the mapper must not map, and where finished vehicles park.

In a fleet the other vehicles are dynamic obstacles. Their bodies are in every other
vehicle's laser (``sim.laser.vehicle_laser_group``) and in its safety fields, so a
vehicle stops for another one; but the mapper never sees them: the readings that fall
on another vehicle's footprint, placed where that vehicle's own EKF says it is (the pose
every fleet vehicle reports to the others), become ``nan`` (no information) before the
local-map update. Why not ground truth: a real fleet knows its vehicles' reported poses,
not the truth; why not the mapper's life cycle: a vehicle standing still in a queue would
be confirmed like a pallet, and a safety map must not hold it.

Examples
--------
>>> import numpy as np
>>> from semistatic.types import Scan
>>> scan = Scan(ranges=[1.0, 3.0], angle_min=0.0, angle_increment=0.1, range_max=10.0)
>>> square = np.array([[-0.2, -0.2], [0.2, -0.2], [0.2, 0.2], [-0.2, 0.2]])
>>> without_vehicles(scan, np.zeros(3), [square + (1.0, 0.0)]).ranges   # the first hit a vehicle
array([nan,  3.])
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import shapely

from semistatic.types import Scan

__all__ = ["FLEET_POSE_MARGIN", "PARKING", "without_vehicles"]

FLEET_POSE_MARGIN = 0.25
"""Metres around another vehicle's reported footprint whose readings the mapper skips.

Covers both vehicles' EKF errors (a few cm) and the scan's motion during a sweep."""

PARKING = (-5.0, -5.0, 0.0)
"""Where a fleet vehicle that drove its laps leaves the hall (outside the walls, the
next one 3 m further west): it must not block the route of the others."""


def without_vehicles(scan: Scan, sensor_world: np.ndarray,
                     footprints: Sequence[np.ndarray]) -> Scan:
    """Return ``scan`` with its readings on the world-frame ``footprints`` set to ``nan``.

    Each footprint is grown by :data:`FLEET_POSE_MARGIN`; ``sensor_world`` is the pose the
    scan was taken from. The scan itself is returned when nothing changes.
    """
    if not footprints:
        return scan
    areas = shapely.union_all([
        shapely.buffer(shapely.Polygon(footprint), FLEET_POSE_MARGIN) for footprint in footprints
    ])
    ranges = scan.ranges
    finite = np.isfinite(ranges)
    if not finite.any():
        return scan
    angles = scan.angle_min + scan.angle_increment * np.arange(ranges.size)
    heading = sensor_world[2] + angles[finite]
    xs = sensor_world[0] + ranges[finite] * np.cos(heading)
    ys = sensor_world[1] + ranges[finite] * np.sin(heading)
    on_vehicle = shapely.contains_xy(areas, xs, ys)
    if not on_vehicle.any():
        return scan
    masked = ranges.copy()
    masked[np.flatnonzero(finite)[on_vehicle]] = np.nan
    return dataclasses.replace(scan, ranges=masked)
