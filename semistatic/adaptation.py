"""Safety-field adaptation around known semi-static objects (paper Sec. 4).

The paper's proposal: once a semi-static object is in the local map of a path segment,
"reduce one or both the safety areas ... so that no obstacle lies inside" them, so the
next vehicle is not slowed or stopped by an object that is already known. We shrink a
field by cutting out a ``margin``-wide band around every known object polyline; the
vehicle's stop envelope stays whole whatever the policy (:mod:`scenarios.bench.policies`), so
anything that enters it (a person stepping out from behind a known box) still stops it.

For occupancy, cutting a band out of the polygon is the same as not counting the
readings that fall inside the band, which is what :func:`explained_readings` computes
(cheap: one vectorised point-to-segment distance).

Examples
--------
>>> import numpy as np
>>> wall_of_box = np.array([[1.0, -1.0], [1.0, 1.0]])  # a known box face 1 m ahead
>>> readings = np.array([[1.01, 0.0], [0.6, 0.0]])    # one on the box, one in front of it
>>> explained_readings(readings, [wall_of_box], margin=0.05)
array([ True, False])
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "distance_to_polylines",
    "explained_readings",
]


def _segments(polylines: Sequence[ArrayLike]) -> tuple[np.ndarray, np.ndarray]:
    """Return the start points and edge vectors of every edge (a lone vertex: zero edge)."""
    starts, edges = [], []
    for polyline in polylines:
        pts = np.asarray(polyline, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            continue
        if len(pts) == 1:
            pts = np.vstack([pts, pts])
        starts.append(pts[:-1])
        edges.append(np.diff(pts, axis=0))
    if not starts:
        return np.empty((0, 2)), np.empty((0, 2))
    return np.vstack(starts), np.vstack(edges)


def distance_to_polylines(points: ArrayLike, polylines: Sequence[ArrayLike]) -> np.ndarray:
    """Return each point's Euclidean distance to the nearest edge of any polyline.

    ``inf`` for every point when there are no polylines.

    Examples
    --------
    >>> distance_to_polylines([[0.0, 1.0], [3.0, 0.0]], [[[0.0, 0.0], [2.0, 0.0]]])
    array([1., 1.])
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    starts, edges = _segments(polylines)
    if len(starts) == 0 or len(pts) == 0:
        return np.full(len(pts), np.inf)
    rel = pts[:, None, :] - starts[None, :, :]
    length2 = np.einsum("ij,ij->i", edges, edges)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.einsum("nsj,sj->ns", rel, edges) / length2
    t = np.clip(np.nan_to_num(t, nan=0.0), 0.0, 1.0)
    closest = starts[None, :, :] + t[:, :, None] * edges[None, :, :]
    return np.sqrt(((pts[:, None, :] - closest) ** 2).sum(axis=2)).min(axis=1)


def explained_readings(
    points: ArrayLike, known_objects: Sequence[ArrayLike], margin: float
) -> np.ndarray:
    """Return which readings lie within ``margin`` of a known semi-static object.

    ``points`` and ``known_objects`` must be in the same frame. NaN points (no return)
    are never explained.

    Examples
    --------
    >>> explained_readings([[1.02, 0.5], [0.7, 0.0], [np.nan, np.nan]],
    ...                    [[[1.0, -1.0], [1.0, 1.0]]], margin=0.05)
    array([ True, False, False])
    """
    if not margin > 0:
        raise ValueError(f"explained_readings: margin must be > 0 m (got {margin})")
    distance = distance_to_polylines(points, known_objects)
    with np.errstate(invalid="ignore"):
        return distance <= margin
