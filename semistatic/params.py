"""Every threshold of the polyline mapper, in one frozen dataclass.

Defaults are chosen for a Sick LMS100 / S300 class scanner (0.5 deg resolution,
~1-3 cm range noise) in indoor hallways, following the paper and ``docs/design.md``.

Examples
--------
>>> params = MapperParams()
>>> params.gate
0.12
>>> MapperParams(gate=-1.0)  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
semistatic.errors.SpecError: <memory>: gate: must be > 0.0 and <= 5.0, got -1.0 (m, the ...
>>> params.replace(gate=0.2).gate
0.2
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Literal

from semistatic.errors import MEMORY, SpecError
from semistatic.validation import bounds, check_fields, unlimited

__all__ = ["HAUSDORFF_RESTRICTIONS", "VERTEX_PLACEMENTS", "MapperParams"]

HAUSDORFF_RESTRICTIONS = ("vertex", "projection")
VERTEX_PLACEMENTS = ("fitted", "raw")


@dataclass(frozen=True)
class MapperParams:
    """Thresholds of extraction, association, merge, join and the object life cycle.

    Extraction (paper Sec. 3.1, docs/design.md#detail-1 to #detail-3)

    outlier_removal
        Delete statistical outliers (the paper's filter, docs/design.md#detail-1). Off by
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
        Range noise sigma_r (m) added as ``3 sigma_r`` to the breakpoint distance. A
        scenario that leaves it out gets its robot's safety laser's range noise
        (:func:`semistatic.noise.spec_noise_params`); replay at least the log's measured
        noise.
    min_points
        Intervals with fewer valid points are dropped. Two by default: small clusters
        (chair and table legs) are real objects; the life cycle decides whether they are
        confirmed.
    epsilon
        Douglas-Peucker tolerance (m), also used to re-simplify after merge/join. The
        default is 2.5 times the range noise of the Sick LMS100 (1.2 cm); a scenario that
        leaves it out gets 2.5 times its robot's safety laser's range noise (the S300's
        3 cm: 7.5 cm; :func:`semistatic.noise.spec_noise_params`), replay three times
        the log's measured noise (:func:`semistatic.noise.noise_epsilon`).
    vertex_placement
        ``"fitted"`` (default): total-least-squares edges, vertices at the intersections
        of adjacent fitted lines and on the end readings' beams
        (:mod:`semistatic.fitting`). ``"raw"``: the paper's reading, vertices on raw
        readings.
    max_range
        Readings beyond this (m) are ignored by the mapper (``inf``: the scan's own limit).

    Association and map (Sec. 3.2-4, docs/design.md#detail-4 to #detail-10)

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
    free_space_cut
        Cut the parts of an observed map polyline that the scan reads through, beyond
        ``visibility_margin`` (:func:`semistatic.visibility.visibility`): a box
        pushed along its own face leaves no stale face in the map. On by default.
    """

    # extraction
    outlier_removal: bool = False
    # alpha < sqrt(2k) is needed to remove anything (extraction.py)
    outlier_k: int = field(
        default=4, metadata=bounds(ge=1, le=50, fix="readings, half width of the window")
    )
    outlier_alpha: float = field(
        default=2.5, metadata=bounds(gt=0.0, le=100.0, fix="window standard deviations")
    )
    breakpoint_lambda: float = field(
        default=math.radians(10.0),
        metadata=bounds(gt=0.0, lt=round(math.pi / 2, 4),
                        fix="rad, 10-20 deg (0.17-0.35 rad) is typical"),
    )
    breakpoint_sigma_r: float = field(
        default=0.012, metadata=bounds(ge=0.0, le=1.0, fix="m, the scanner's range noise")
    )
    min_points: int = field(
        default=2, metadata=bounds(ge=2, le=1000, fix="a polyline needs at least two points")
    )
    epsilon: float = field(
        default=0.03, metadata=bounds(gt=0.0, le=1.0, fix="m, the Douglas-Peucker tolerance")
    )
    vertex_placement: Literal["fitted", "raw"] = "fitted"
    # A laser reaches at most 100 m; in code, inf keeps the scan's own limit.
    max_range: float = field(
        default=math.inf,
        metadata={**bounds(gt=0.0, le=100.0, fix="m"),
                  **unlimited()},
    )
    # association and map; a tolerance beyond 1 m or a gate beyond 5 m maps nothing real
    gate: float = field(
        default=0.12,
        metadata=bounds(gt=0.0, le=5.0,
                        fix="m, the restricted Hausdorff gate; the paper's is slightly "
                            "above 0.10"),
    )
    hausdorff_restriction: Literal["vertex", "projection"] = "vertex"
    miss_limit: int = field(
        default=5, metadata=bounds(ge=1, le=1000, fix="visible misses before deletion")
    )
    visibility_margin: float = field(
        default=0.15, metadata=bounds(ge=0.0, le=10.0, fix="m, occlusion tolerance")
    )
    free_space_cut: bool = True

    def __post_init__(self) -> None:
        check_fields(self)
        for name, choices in (("vertex_placement", VERTEX_PLACEMENTS),
                              ("hausdorff_restriction", HAUSDORFF_RESTRICTIONS)):
            if getattr(self, name) not in choices:
                raise SpecError(
                    MEMORY, name,
                    f"must be one of {', '.join(choices)}, got {getattr(self, name)!r}",
                )

    def replace(self, **changes: object) -> MapperParams:
        """Return a copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)
