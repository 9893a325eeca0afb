"""semistatic: semi-static object detection with polygonal local maps.

The paper's contribution as a pure numpy/scipy/shapely library that runs on any 2D laser
scan, simulated or real: polyline extraction, tangent-space similarity, the restricted
Hausdorff distance, ordered association, merge, join, per-segment local maps with the
semi-static object life cycle, and safety-field adaptation. No simulator imports here.

Examples
--------
>>> import numpy as np
>>> from semistatic import Scan, extract_polylines
>>> angles = np.radians(np.arange(-45.0, 45.5, 0.5))
>>> scan = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0],
...             angle_increment=np.radians(0.5), range_max=20.0)
>>> [len(polyline) for polyline in extract_polylines(scan)]  # a flat wall: two vertices
[2]
"""

from semistatic.alignment import Alignment, AlignmentParams, align_points
from semistatic.association import associate
from semistatic.cache_healing import heal_kernels
from semistatic.extraction import douglas_peucker, extract_polylines
from semistatic.hausdorff import hausdorff, restrict, restricted_hausdorff
from semistatic.join import merge_group, overlapping_groups
from semistatic.local_map import LocalMap
from semistatic.mapper import MapPolyline, PolylineMap, UpdateReport
from semistatic.merge import merge
from semistatic.params import MapperParams
from semistatic.polyline import PackedPolylines, Polyline, as_polyline, as_polylines
from semistatic.similarity import similarity, tangent_function
from semistatic.types import Scan

__all__ = [
    "Alignment",
    "AlignmentParams",
    "LocalMap",
    "MapPolyline",
    "MapperParams",
    "PackedPolylines",
    "Polyline",
    "PolylineMap",
    "Scan",
    "UpdateReport",
    "align_points",
    "as_polyline",
    "as_polylines",
    "associate",
    "douglas_peucker",
    "extract_polylines",
    "hausdorff",
    "merge",
    "merge_group",
    "overlapping_groups",
    "restrict",
    "restricted_hausdorff",
    "similarity",
    "tangent_function",
]

# A damaged numba cache file of a kernel is deleted and the kernel compiled again,
# instead of failing every run (semistatic/cache_healing.py): before any kernel runs.
heal_kernels("semistatic")
