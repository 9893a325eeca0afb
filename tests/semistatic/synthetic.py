"""Tiny pure-numpy scene builder and laser ray caster for the mapper tests.

A scene is an ``(S, 2, 2)`` array of line segments (start, end) in the world frame.
:func:`cast_scan` returns the ``Scan`` a 2D laser at a given sensor pose would read,
optionally with Gaussian range noise from an explicit ``numpy.random.Generator``.
"""

from __future__ import annotations

import math

import numpy as np

from semistatic.frames import untransform_points
from semistatic.types import Scan

FIELD_OF_VIEW = math.radians(270.0)
INCREMENT = math.radians(0.5)
BEAMS = 541


def wall(start: tuple[float, float], end: tuple[float, float]) -> np.ndarray:
    """Return a ``(1, 2, 2)`` scene with one wall segment."""
    return np.array([[start, end]], dtype=float)


def box(center: tuple[float, float], length: float, width: float, yaw: float = 0.0) -> np.ndarray:
    """Return the ``(4, 2, 2)`` edges of a rectangle, corners counter-clockwise."""
    c, s = math.cos(yaw), math.sin(yaw)
    half = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]], dtype=float) * [length / 2, width / 2]
    corners = half @ np.array([[c, s], [-s, c]]) + np.asarray(center, dtype=float)
    return np.stack((corners, np.roll(corners, -1, axis=0)), axis=1)


def box_corners(
    center: tuple[float, float], length: float, width: float, yaw: float = 0.0
) -> np.ndarray:
    """Return the ``(4, 2)`` corners of :func:`box` (counter-clockwise)."""
    return box(center, length, width, yaw)[:, 0]


def scene(*parts: np.ndarray) -> np.ndarray:
    """Return the segments of several parts as one ``(S, 2, 2)`` array."""
    if not parts:
        return np.empty((0, 2, 2))
    return np.concatenate([np.asarray(part, dtype=float).reshape(-1, 2, 2) for part in parts])


def raycast(segments: np.ndarray, pose: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Return the exact range to the nearest segment along each beam (``inf``: none)."""
    segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    if segments.shape[0] == 0:
        return np.full(angles.size, np.inf)
    start = untransform_points(pose, segments[:, 0])
    edge = untransform_points(pose, segments[:, 1]) - start
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
    denominator = dx * edge[:, 1] - dy * edge[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        along_beam = (start[:, 0] * edge[:, 1] - start[:, 1] * edge[:, 0]) / denominator
        along_edge = (start[:, 0] * dy - start[:, 1] * dx) / denominator
    hit = (np.abs(denominator) > 1e-12) & (along_beam > 0) & (along_edge >= 0) & (along_edge <= 1)
    return np.where(hit, along_beam, np.inf).min(axis=1)


def cast_scan(
    segments: np.ndarray,
    pose: tuple[float, float, float] | np.ndarray,
    *,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
    stamp: float = 0.0,
    range_max: float = 20.0,
    beams: int = BEAMS,
) -> Scan:
    """Return the 270 deg, 0.5 deg scan of ``segments`` from sensor ``pose`` (world frame).

    Beams that hit nothing, or hit beyond ``range_max``, read ``inf``.
    """
    pose = np.asarray(pose, dtype=float)
    increment = FIELD_OF_VIEW / (beams - 1)
    angle_min = -FIELD_OF_VIEW / 2
    angles = angle_min + increment * np.arange(beams)
    ranges = raycast(segments, pose, angles)
    if noise > 0.0:
        if rng is None:
            raise ValueError("cast_scan: pass rng=np.random.default_rng(seed) to add noise")
        ranges = ranges + rng.normal(0.0, noise, beams)
    ranges = np.where(ranges > range_max, np.inf, ranges)
    return Scan(
        ranges=ranges,
        angle_min=angle_min,
        angle_increment=increment,
        range_max=range_max,
        stamp=stamp,
        pose=pose,
    )
