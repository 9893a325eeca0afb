"""The follower on the array code paths of ``SplinePath``: the reference for its fast paths.

``ChainedFormFollower`` queries the path one float at a time, which ``SplinePath`` answers
with pure-Python transcriptions of its array code for poses and curvatures (projections
of one point or many run through one compiled kernel). ``ArrayPathFollower`` makes the
same queries through the array code (one-row projections, 0-d poses and curvatures,
numpy's ``wrap_angle``), as the follower did before the fast paths existed. Tests require
the two to command the same, bit for bit; ``benchmarks/test_bench_navigation.py`` times both.
"""

from __future__ import annotations

import math

import numpy as np

from robots.follower import ChainedFormFollower, FollowerParams
from robots.path import SplinePath
from semistatic.frames import wrap_angle


class ArrayCurvaturePath(SplinePath):
    """A ``SplinePath`` whose ``curvature`` always takes the array code path."""

    def curvature(self, s):
        """Return the curvature at ``s`` computed on a 0-d array."""
        return super().curvature(np.array(s, dtype=float))


class ArrayPathFollower(ChainedFormFollower):
    """A ``ChainedFormFollower`` whose path queries all take the array code paths."""

    def __init__(self, knots, params: FollowerParams | None = None) -> None:
        super().__init__(ArrayCurvaturePath(knots), params)

    def _track(self, x: float, y: float) -> float:
        return float(
            self.path.project(
                np.array([[x, y]]), s_hint=self.progress, window=self.params.projection_window
            )[0]
        )

    def _reference(self, s: float) -> tuple[float, float, float, float]:
        x_ref, y_ref, theta_ref = self.path.pose(np.array(s))
        return x_ref, y_ref, theta_ref, self.path.curvature(s)

    @staticmethod
    def _offset(x, y, theta, x_ref, y_ref, theta_ref) -> tuple[float, float, float]:
        # numpy scalars (the reference's pose components) and numpy's wrap_angle.
        dx, dy = x - x_ref, y - y_ref
        c, s_theta = math.cos(theta), math.sin(theta)
        xe = c * dx + s_theta * dy
        ye = -s_theta * dx + c * dy
        return xe, ye, float(wrap_angle(np.asarray(theta - theta_ref)))
