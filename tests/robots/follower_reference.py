"""The follower on the array code paths of ``SplinePath``: the reference for its fast paths.

``ChainedFormFollower`` queries the path one float at a time, which ``SplinePath`` answers
with pure-Python transcriptions of its array code. ``ArrayPathFollower`` makes the same
queries through the array code (one-row projections, 0-d poses and curvatures, numpy's
``wrap_angle``), as the follower did before the fast paths existed. Tests require the
two to command the same, bit for bit; ``benchmarks/test_bench_navigation.py`` times both.
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

    def _project(self, pose: np.ndarray) -> float:
        return float(
            self.path.project(
                pose[None, :2], s_hint=self.progress, window=self.params.projection_window
            )[0]
        )

    def _errors(self, pose: np.ndarray, s: float) -> tuple[float, float, float]:
        reference = self.path.pose(np.array(s))
        dx, dy = pose[0] - reference[0], pose[1] - reference[1]
        c, s_theta = math.cos(pose[2]), math.sin(pose[2])
        xe = c * dx + s_theta * dy
        ye = -s_theta * dx + c * dy
        return xe, ye, float(wrap_angle(pose[2] - reference[2]))
