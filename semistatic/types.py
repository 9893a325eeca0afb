"""Data types shared by every package: the laser scan.

``Scan`` mirrors ROS ``sensor_msgs/LaserScan`` plus the pose of the sensor that took it.
It lives here, in a module with no simulator dependency, so that the mapper
(``semistatic``), the navigation stack (``robots``), the simulator (``sim``) and the log
readers all speak the same type.

Examples
--------
>>> import numpy as np
>>> scan = Scan(ranges=[1.0, np.inf, 2.0], angle_min=-0.5, angle_increment=0.5, range_max=10.0)
>>> scan.valid_mask()
array([ True, False,  True])
>>> scan.points()[scan.valid_mask()].round(3)
array([[ 0.878, -0.479],
       [ 1.755,  0.959]])
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import transform_points

__all__ = ["MAX_BEAMS", "Scan", "beam_angles", "beam_directions"]


@functools.lru_cache(maxsize=32)
def beam_angles(count: int, angle_min: float, angle_increment: float) -> np.ndarray:
    """Return the ``count`` beam angles ``angle_min + i * angle_increment`` (rad, read-only).

    Computed once per scan geometry and shared, so hot loops over the scans of one scanner
    do not redo it; the values are bitwise those of :meth:`Scan.angles`.

    Examples
    --------
    >>> beam_angles(3, -0.5, 0.5)
    array([-0.5,  0. ,  0.5])
    >>> beam_angles(3, -0.5, 0.5) is beam_angles(3, -0.5, 0.5)
    True
    """
    angles = angle_min + angle_increment * np.arange(count)
    angles.flags.writeable = False
    return angles


@functools.lru_cache(maxsize=32)
def beam_directions(
    count: int, angle_min: float, angle_increment: float
) -> tuple[np.ndarray, np.ndarray]:
    """Return the cosines and sines of :func:`beam_angles` (read-only, cached likewise).

    Examples
    --------
    >>> cos, sin = beam_directions(2, 0.0, np.pi / 2)
    >>> cos.round(12), sin.round(12)
    (array([1., 0.]), array([0., 1.]))
    """
    angles = beam_angles(count, angle_min, angle_increment)
    directions = np.cos(angles), np.sin(angles)
    for array in directions:
        array.flags.writeable = False
    return directions


MAX_BEAMS = 8192
"""Most beams a scan may have. Real 2D lasers have a few thousand at most (a SICK LMS511
at 1/6 deg over 190 deg: 1141, a nanoScan3: 1650, a 360 deg scanner at 0.125 deg: 2880;
the logs we evaluate 180-361, the simulated S300 541); the mapper's cost grows faster
than the beam count, and 100,000 beams asked for 49.6 GiB."""


@dataclass(frozen=True, eq=False)
class Scan:
    """One 2D laser scan, ROS ``LaserScan``-like, in SI units.

    Parameters
    ----------
    ranges
        ``(N,)`` ranges in metres, beam ``i`` at ``angle_min + i * angle_increment``
        (counter-clockwise, sensor frame). ``inf`` (or ``nan``) means no return.
    angle_min, angle_increment
        Beam angles in radians.
    range_min, range_max
        Valid range interval; readings outside it are invalid.
    intensities
        Optional ``(N,)`` remission values (reflective posts read high).
    stamp
        Acquisition time in seconds.
    pose
        ``(x, y, theta)`` of the sensor in the world (or map) frame when the scan was taken.
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float = 0.0
    range_max: float = float("inf")
    intensities: np.ndarray | None = None
    stamp: float = 0.0
    pose: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        ranges = np.array(self.ranges, dtype=np.float64).reshape(-1)
        if ranges.size > MAX_BEAMS:
            raise ValueError(f"Scan: {ranges.size} beams, more than the limit of {MAX_BEAMS} "
                             "(real 2D lasers have a few thousand at most)")
        ranges.flags.writeable = False
        object.__setattr__(self, "ranges", ranges)
        if self.intensities is not None:
            intensities = np.array(self.intensities, dtype=np.float64).reshape(-1)
            if intensities.shape != ranges.shape:
                raise ValueError(
                    f"Scan: intensities has {intensities.size} values but ranges has "
                    f"{ranges.size}; pass one intensity per beam or intensities=None"
                )
            intensities.flags.writeable = False
            object.__setattr__(self, "intensities", intensities)
        pose = np.array(self.pose, dtype=np.float64).reshape(-1)
        if pose.shape != (3,):
            raise ValueError(f"Scan: pose must be (x, y, theta), got shape {pose.shape}")
        pose.flags.writeable = False
        object.__setattr__(self, "pose", pose)
        for name in ("angle_min", "angle_increment", "range_min", "range_max", "stamp"):
            object.__setattr__(self, name, float(getattr(self, name)))
        if not self.angle_increment > 0.0:
            raise ValueError(
                f"Scan: angle_increment must be > 0 (counter-clockwise beams), "
                f"got {self.angle_increment}"
            )
        if not 0.0 <= self.range_min < self.range_max:
            raise ValueError(
                f"Scan: need 0 <= range_min < range_max, got {self.range_min}, {self.range_max}"
            )

    def __len__(self) -> int:
        return int(self.ranges.size)

    def angles(self) -> np.ndarray:
        """Return the beam angles in the sensor frame, radians."""
        return self.angle_min + self.angle_increment * np.arange(self.ranges.size)

    def valid_mask(self) -> np.ndarray:
        """Return which readings are finite and inside ``[range_min, range_max]``."""
        r = self.ranges
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max)

    def points(self) -> np.ndarray:
        """Return ``(N, 2)`` end points in the sensor frame; invalid beams give ``nan`` rows."""
        r = np.where(self.valid_mask(), self.ranges, np.nan)
        a = self.angles()
        return np.column_stack([r * np.cos(a), r * np.sin(a)])

    def world_points(self, pose: ArrayLike | None = None) -> np.ndarray:
        """Return ``(N, 2)`` end points in the world frame (``nan`` rows for invalid beams).

        Uses ``pose`` when given (e.g. an EKF estimate), else the scan's own pose.
        """
        return transform_points(self.pose if pose is None else pose, self.points())
