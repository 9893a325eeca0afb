"""The path by scipy alone: the independent reference for ``robots.path`` and the follower.

scipy's ``CubicSpline`` through the knots, parameterised by cumulative chord length (the
curve ``robots.path`` documents), its arc length by adaptive quadrature
(``scipy.integrate.quad``) and the inverse ``s -> t`` by root finding (``brentq``). It
shares nothing with ``SplinePath``'s arc-length table, Hermite inverse or compiled
kernels; it is slow (milliseconds per query) and obviously correct.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from scipy.integrate import quad
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq, minimize_scalar


class ScipyPath:
    """The path by scipy alone: ``r(t)``, ``S(t)`` by quadrature and ``t(s)`` by brentq."""

    def __init__(self, knots, bc_type):
        knots = np.asarray(knots, dtype=float)
        self.knot_t = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(knots, axis=0).T))])
        self.spline = CubicSpline(self.knot_t, knots, axis=0, bc_type=bc_type)
        self.velocity = self.spline.derivative()
        self.acceleration = self.spline.derivative(2)
        pieces = [self._integral(t0, t1) for t0, t1 in itertools.pairwise(self.knot_t)]
        self.knot_s = np.concatenate([[0.0], np.cumsum(pieces)])
        self.length = float(self.knot_s[-1])

    def _integral(self, t0, t1):
        """Return the arc length from ``t0`` to ``t1`` (adaptive quadrature of ``|r'(t)|``)."""
        value, _ = quad(lambda t: np.hypot(*self.velocity(t)), t0, t1, epsabs=1e-13, epsrel=1e-13)
        return value

    def t(self, s):
        """Return the spline parameter at arc length ``s`` (clamped to the path)."""
        s = min(max(s, 0.0), self.length)
        piece = min(np.searchsorted(self.knot_s, s, side="right") - 1, self.knot_t.size - 2)
        t0, t1 = self.knot_t[piece], self.knot_t[piece + 1]
        if s - self.knot_s[piece] <= 0.0:
            return t0
        return brentq(lambda t: self.knot_s[piece] + self._integral(t0, t) - s, t0, t1, xtol=1e-14)

    def point(self, s):
        """Return the curve point at arc length ``s``."""
        return self.spline(self.t(s))

    def frame(self, s):
        """Return the point, heading and curvature at ``s`` (one inversion of ``S(t)``)."""
        t = self.t(s)
        (dx, dy), (ddx, ddy) = self.velocity(t), self.acceleration(t)
        return self.spline(t), math.atan2(dy, dx), (dx * ddy - dy * ddx) / math.hypot(dx, dy) ** 3

    def s(self, t):
        """Return the arc length at the spline parameter ``t``."""
        piece = min(np.searchsorted(self.knot_t, t, side="right") - 1, self.knot_t.size - 2)
        return self.knot_s[piece] + self._integral(self.knot_t[piece], t)

    def closest(self, point, low, high):
        """Return the arc length in ``[low, high]`` of the curve point closest to ``point``.

        A dense grid in ``t`` picks the basin, a bounded scalar minimisation refines it.
        """
        t_low, t_high = self.t(low), self.t(high)
        grid = np.linspace(t_low, t_high, 2001)
        gaps = np.linalg.norm(self.spline(grid) - point, axis=1)
        k = int(np.argmin(gaps))
        best = minimize_scalar(
            lambda t: np.linalg.norm(self.spline(t) - point),
            bounds=(grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]),
            method="bounded",
            options={"xatol": 1e-12},
        )
        return self.s(best.x if best.fun < gaps[k] else grid[k])
