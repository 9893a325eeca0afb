"""Path segments as the runner uses them: arc-length span, frame, fields, safety area.

Each path segment of a world has its own safety fields (switched as the robot enters it,
as on a real Sick scanner) and its own local map, stored in a frame anchored at the
segment start (paper Sec. 3, docs/design.md#detail-9). The local map keeps only polylines
that meet the segment's *safety area*: the union of the warning field swept along the
segment.

Examples
--------
>>> from worlds import load_world
>>> world = load_world("pal1")
>>> segments = path_segments(world)
>>> [segment.name for segment in segments]
['niches', 'side_corridor', 'east']
>>> segments[0].start_s, round(segments[-1].end_s, 2)
(0.0, 11.02)
>>> segment_index(segments, 6.0)
1
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from robots.path import SplinePath
from robots.safety import FieldSet
from semistatic.frames import transform_points, untransform_points
from worlds.checks import build_spline
from worlds.spec import WorldSpec

__all__ = ["SWEEP_STEP", "PathSegment", "path_segments", "segment_index", "swept_area"]

SWEEP_STEP = 0.05
"""Arc-length step (m) at which a field is placed along the path to sweep the safety area."""


@dataclass(frozen=True, eq=False)
class PathSegment:
    """One path segment: its span ``[start_s, end_s)`` along the path and its geometry.

    ``origin`` is the path pose at ``start_s`` (the local map's frame); ``safety_area``
    is the swept warning field in that frame, ``safety_area_world`` the same in the world.
    """

    index: int
    name: str
    start_s: float
    end_s: float
    origin: np.ndarray
    fields: FieldSet
    safety_area: shapely.Geometry
    safety_area_world: shapely.Geometry


def swept_area(
    path: SplinePath, polygon: np.ndarray, start_s: float, end_s: float, step: float = SWEEP_STEP
) -> shapely.Geometry:
    """Return the union of ``polygon`` (robot frame) placed at path poses in ``[start_s, end_s]``.

    Examples
    --------
    >>> path = SplinePath([(0.0, 0.0), (2.0, 0.0)])
    >>> square = np.array([[0.0, -0.5], [1.0, -0.5], [1.0, 0.5], [0.0, 0.5]])
    >>> round(swept_area(path, square, 0.0, 2.0).area, 3)  # a 3 m x 1 m strip
    3.0
    """
    count = max(2, int(np.ceil((end_s - start_s) / step)) + 1)
    poses = path.pose(np.linspace(start_s, end_s, count))
    # The polygons made in one call (one by one, their constructor's checks cost more than
    # placing them).
    placed = shapely.polygons(np.stack([transform_points(pose, polygon) for pose in poses]))
    return shapely.union_all(placed)


def path_segments(world: WorldSpec, path: SplinePath | None = None) -> tuple[PathSegment, ...]:
    """Return the segments of ``world``'s path with their frames, fields and safety areas."""
    path = build_spline(world.path) if path is None else path
    segments = []
    for index, spec in enumerate(world.path.segments):
        start_s = float(path.knot_s[spec.start_knot])
        end_s = float(path.knot_s[spec.end_knot])
        origin = path.pose(start_s)
        warning = np.asarray(spec.warning, dtype=float)
        area_world = swept_area(path, warning, start_s, end_s)
        area_local = shapely.transform(area_world, lambda xy, o=origin: untransform_points(o, xy))
        segments.append(
            PathSegment(
                index=index,
                name=spec.name,
                start_s=start_s,
                end_s=end_s,
                origin=origin,
                fields=FieldSet(warning, np.asarray(spec.protective, dtype=float), name=spec.name),
                safety_area=area_local,
                safety_area_world=area_world,
            )
        )
    return tuple(segments)


def segment_index(segments: Sequence[PathSegment], s: float) -> int:
    """Return the index of the segment containing arc length ``s`` (clamped to the ends)."""
    for segment in segments:
        if s < segment.end_s:
            return segment.index
    return segments[-1].index
