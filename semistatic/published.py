"""PLE's published extraction accuracy on real logs, to compare ours against.

Schaefer, Büscher, Vertens, Luft, Burgard, "A Maximum Likelihood Approach to Extract
Polylines from 2-D Laser Range Scans", IROS 2018, Fig. 4a. The per-log figures are the
data behind that figure, published with the paper's code (github.com/acschaefer/ple,
``matlab/output/eval.mat``, array ``rmse`` of shape (2, 260, 6, 5): real/simulated scan,
scan, algorithm {VVL, PLE, PLE+, IEF, SAM, VB}, J in {10, 20, 30, 40, 50}); 20 real scans
per log in alphabetical file order, averaged per log. They are reference data, not
results of this code: RMSE along each ray (the metric of :mod:`semistatic.evaluation`)
at J vertices per scan, and the coverage f published with them.

:func:`published_rmse` reads a curve at our vertex count: linearly interpolated between
the published J, the J = 50 figure where we store more vertices (so that we compare
against their best figure), the J = 10 figure below.

Examples
--------
>>> published_log("intel-corrected")
'intel'
>>> round(100 * published_rmse("intel", 50.0), 2)  # PLE+ at J = 50, in cm
0.77
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "PLE_PUBLISHED",
    "PLE_VERTEX_COUNTS",
    "PublishedCurve",
    "published_log",
    "published_rmse",
]

PLE_VERTEX_COUNTS = (10, 20, 30, 40, 50)
"""The vertex counts J per scan at which PLE's evaluation was run."""


@dataclass(frozen=True)
class PublishedCurve:
    """One log's published figures at :data:`PLE_VERTEX_COUNTS` (RMSE in metres).

    Examples
    --------
    >>> PLE_PUBLISHED["aces"].ple_plus[0]
    0.0727
    """

    ple_plus: tuple[float, ...]
    ple: tuple[float, ...]
    coverage: tuple[float, ...]

    def __post_init__(self) -> None:
        for name in ("ple_plus", "ple", "coverage"):
            values = getattr(self, name)
            if len(values) != len(PLE_VERTEX_COUNTS):
                raise ValueError(
                    f"PublishedCurve: {name} needs {len(PLE_VERTEX_COUNTS)} values, "
                    f"got {len(values)}"
                )


# Per log: PLE+'s RMSE (cm), PLE's RMSE (cm), coverage f, at J = 10, 20, 30, 40, 50.
_PUBLISHED_CM = {
    "intel": ((7.01, 4.43, 2.16, 1.30, 0.77), (9.66, 6.31, 3.03, 1.71, 0.98),
              (0.861, 0.961, 0.981, 0.986, 0.986)),
    "aces": ((7.27, 5.47, 3.87, 2.67, 1.95), (11.24, 7.59, 5.23, 3.38, 2.40),
             (0.808, 0.928, 0.959, 0.963, 0.963)),
    "freiburg-079": ((10.04, 8.07, 6.13, 4.54, 3.25), (13.55, 11.05, 8.64, 6.30, 4.43),
                     (0.800, 0.930, 0.972, 0.990, 0.994)),
    "csail": ((7.45, 6.16, 4.99, 4.04, 3.20), (10.18, 8.20, 6.36, 5.08, 4.02),
              (0.819, 0.905, 0.937, 0.954, 0.965)),
}

PLE_PUBLISHED: dict[str, PublishedCurve] = {
    log: PublishedCurve(
        ple_plus=tuple(round(value / 100.0, 6) for value in plus),
        ple=tuple(round(value / 100.0, 6) for value in ple),
        coverage=coverage,
    )
    for log, (plus, ple, coverage) in _PUBLISHED_CM.items()
}
"""PLE's and PLE+'s ray-wise RMSE (m) and coverage per log (Schaefer et al. 2018)."""


def published_log(name: str) -> str | None:
    """Return the key of :data:`PLE_PUBLISHED` that the log ``name`` is, or None.

    ``name`` is a log's file name without its suffixes; CARMEN's distribution names them
    ``<log>-corrected``, ``csail-robotlaser1-corrected`` for csail.

    Examples
    --------
    >>> published_log("freiburg-079-corrected"), published_log("room")
    ('freiburg-079', None)
    """
    lowered = name.lower()
    for key in PLE_PUBLISHED:
        if lowered == key or lowered.startswith(f"{key}-"):
            return key
    return None


def published_rmse(log: str, vertices_per_scan: float, method: str = "PLE+") -> float:
    """Return the published RMSE (m) of ``method`` on ``log`` at ``vertices_per_scan``.

    Parameters
    ----------
    log
        A key of :data:`PLE_PUBLISHED`.
    vertices_per_scan
        Our vertex count, ``> 0``; interpolated linearly between the published J, the
        end figures beyond them.
    method
        ``"PLE+"`` or ``"PLE"``.

    Examples
    --------
    >>> round(100 * published_rmse("aces", 25.0), 2)  # halfway between J = 20 and 30
    4.67
    >>> round(100 * published_rmse("aces", 25.0, "PLE"), 2)
    6.41
    """
    if log not in PLE_PUBLISHED:
        raise ValueError(f"published_rmse: unknown log {log!r}; choose from {list(PLE_PUBLISHED)}")
    curves = {"PLE+": PLE_PUBLISHED[log].ple_plus, "PLE": PLE_PUBLISHED[log].ple}
    if method not in curves:
        raise ValueError(f"published_rmse: method must be 'PLE+' or 'PLE', got {method!r}")
    if not vertices_per_scan > 0.0:
        raise ValueError(
            f"published_rmse: vertices_per_scan must be > 0, got {vertices_per_scan!r}"
        )
    return float(np.interp(vertices_per_scan, PLE_VERTEX_COUNTS, curves[method]))
