"""Every threshold of the polyline mapper, in one frozen dataclass.

Defaults are chosen for a Sick LMS100 / S300 class scanner (0.5 deg resolution,
~1-3 cm range noise) in indoor hallways, following the paper and ``DESIGN.md``.

Examples
--------
>>> params = MapperParams()
>>> params.gate
0.12
>>> MapperParams(gate=-1.0)  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
ValueError: MapperParams.gate must be > 0 (got -1.0): the restricted Hausdorff gate ...
>>> params.replace(gate=0.2).gate
0.2
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

__all__ = ["HAUSDORFF_RESTRICTIONS", "VERTEX_PLACEMENTS", "MapperParams"]

HAUSDORFF_RESTRICTIONS = ("vertex", "projection")
VERTEX_PLACEMENTS = ("fitted", "raw")


@dataclass(frozen=True)
class MapperParams:
    """Thresholds of extraction, association, merge, join and the object life cycle.

    Extraction (paper Sec. 3.1, DESIGN.md details 1-3)

    outlier_removal
        Delete statistical outliers (the paper's filter, DESIGN.md detail 1). Off by
        default: on real scans the readings it deletes are real returns (through a gap,
        off a thin object), and once deleted a polyline may cross their rays. Kept, an
        isolated reading breaks the polyline around it and forms no polyline of its own.
    outlier_k
        Half window: statistics over the ``2k+1`` valid ranges centred on each reading.
    outlier_alpha
        A reading is an outlier when ``|r_i - mu_i| > alpha * sigma_i``.
    breakpoint_lambda
        Adaptive breakpoint angle lambda (rad), Borges & Aldon 2004; 10-20 deg typical.
    breakpoint_sigma_r
        Range noise sigma_r (m) added as ``3 sigma_r`` to the breakpoint distance.
    min_points
        Intervals with fewer valid points are dropped. Two by default: small clusters
        (chair and table legs) are real objects; the life cycle decides whether they are
        confirmed.
    epsilon
        Douglas-Peucker tolerance (m), also used to re-simplify after merge/join. The
        default is 2.5 times the range noise of the Sick LMS100 (1.2 cm) that the bundled
        scenarios simulate; replay sets it to three times the log's measured noise
        (:func:`semistatic.noise.noise_epsilon`).
    vertex_placement
        ``"fitted"`` (default): total-least-squares edges, vertices at the intersections
        of adjacent fitted lines and on the end readings' beams
        (:mod:`semistatic.fitting`). ``"raw"``: the paper's reading, vertices on raw
        readings.
    max_range
        Readings beyond this (m) are ignored by the mapper (``inf``: the scan's own limit).

    Association and map (Sec. 3.2-4, DESIGN.md details 4-10)

    gate
        Restricted Hausdorff validation gate (m): "slightly above 10 cm".
    hausdorff_restriction
        ``"vertex"`` (the paper's, default) or ``"projection"`` (continuous cut).
    miss_limit
        k: a map polyline is deleted after this many misses while it should have been
        visible.
    visibility_margin
        A map point counts as occluded when the scan reads more than this (m) shorter
        along its bearing.
    """

    # extraction
    outlier_removal: bool = False
    outlier_k: int = 4  # alpha < sqrt(2k) is needed to remove anything (extraction.py)
    outlier_alpha: float = 2.5
    breakpoint_lambda: float = math.radians(10.0)
    breakpoint_sigma_r: float = 0.012
    min_points: int = 2
    epsilon: float = 0.03
    vertex_placement: Literal["fitted", "raw"] = "fitted"
    max_range: float = math.inf
    # association and map
    gate: float = 0.12
    hausdorff_restriction: Literal["vertex", "projection"] = "vertex"
    miss_limit: int = 5
    visibility_margin: float = 0.15

    def __post_init__(self) -> None:
        def fail(name: str, rule: str, hint: str) -> None:
            value = getattr(self, name)
            raise ValueError(f"MapperParams.{name} must be {rule} (got {value!r}): {hint}")

        if not isinstance(self.outlier_removal, bool):
            fail("outlier_removal", "True or False", "the paper's statistical outlier removal")
        if not (isinstance(self.outlier_k, int) and self.outlier_k >= 1):
            fail("outlier_k", "an integer >= 1", "half width of the outlier window")
        if not self.outlier_alpha > 0:
            fail("outlier_alpha", "> 0", "outlier threshold in window standard deviations")
        if not 0 < self.breakpoint_lambda < math.pi / 2:
            fail("breakpoint_lambda", "in (0, pi/2) rad", "10-20 deg (0.17-0.35 rad) is typical")
        if not self.breakpoint_sigma_r >= 0:
            fail("breakpoint_sigma_r", ">= 0", "the scanner's range noise in metres")
        if not (isinstance(self.min_points, int) and self.min_points >= 2):
            fail("min_points", "an integer >= 2", "a polyline needs at least two points")
        if not self.epsilon > 0:
            fail("epsilon", "> 0", "the Douglas-Peucker tolerance in metres, e.g. 0.03")
        if self.vertex_placement not in VERTEX_PLACEMENTS:
            fail("vertex_placement", f"one of {VERTEX_PLACEMENTS}", "see DESIGN.md detail 3")
        if not self.max_range > 0:
            fail("max_range", "> 0", "metres, or inf to keep the scan's own limit")
        if not self.gate > 0:
            fail(
                "gate", "> 0",
                "the restricted Hausdorff gate in metres, the paper uses slightly above 0.10",
            )
        if self.hausdorff_restriction not in HAUSDORFF_RESTRICTIONS:
            fail("hausdorff_restriction", f"one of {HAUSDORFF_RESTRICTIONS}", "see DESIGN.md 5")
        if not (isinstance(self.miss_limit, int) and self.miss_limit >= 1):
            fail("miss_limit", "an integer >= 1", "visible misses before a polyline is deleted")
        if not self.visibility_margin >= 0:
            fail("visibility_margin", ">= 0", "occlusion tolerance in metres")

    def replace(self, **changes: object) -> MapperParams:
        """Return a copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)
