"""Path following with the chained-form controller of Morin & Samson (paper eq. 6).

The UGV tracks the fixed spline path at a nominal speed ``u1r`` with the control law

    u1 = u1r - K1 |u1r| xe
    u2 = u2r - K2 u1r ye - K3 |u1r| tan(theta_e)

where ``u1`` is the forward speed ``v``, ``u2`` the yaw rate ``omega``, ``u2r = kappa(s)
u1r`` the feed-forward that keeps a robot on the path, and the paper's gains are
``K1 = 3``, ``K2 = 1.5 1/m^2``, ``K3 = 1.5 1/m``.

Errors and why these signs converge
-----------------------------------
The reference pose ``(xr, yr, theta_r)`` is the path pose at the progress ``s``, the
closest path point to the robot (a local projection around the previous progress, so the
reference waits for the robot when the safety fields stop it). The errors are the robot's
offset from the reference, expressed in the ROBOT frame as the paper says::

    [xe, ye] = R(theta)^T [x - xr, y - yr],   theta_e = wrap(theta - theta_r)

With ``p`` the robot position, ``pr`` the reference and ``d/dt R(theta)^T = -omega J
R(theta)^T`` (``J`` the 90 degree rotation) the error dynamics of a unicycle following a
reference that moves at ``(u1r, u2r)`` are

    xe' = u1 - u1r cos(theta_e) + omega ye
    ye' = u1r sin(theta_e) - omega xe
    theta_e' = u2 - u2r

Linearised about zero error (``xe, ye, theta_e`` small, ``u1 ~ u1r``) and inserting eq. 6:

    xe' = -K1 |u1r| xe
    ye'' = u1r theta_e' = -K2 u1r^2 ye - K3 |u1r| ye'

The first is a stable first-order lag. (With the reference at the projection rather than
running ahead at ``u1r``, ``xe = ye tan(theta_e)`` is second order, so the ``K1`` term only
trims the speed, and the lateral equations are the same to first order.) The second has
the characteristic polynomial
``l^2 + K3 |u1r| l + K2 u1r^2``, Hurwitz for any ``K2, K3 > 0`` and ``u1r != 0``, in either
driving direction: the origin is locally exponentially stable. A positive ``ye`` (robot
left of the path) thus commands ``u2 < 0`` (turn right), a positive ``theta_e`` (pointing
left of the path) likewise. Since all gains multiply ``|u1r|``, the response is fixed in
DISTANCE travelled: per metre the lateral error obeys ``l^2 + K3 l + K2 = 0``, for the
paper's gains ``l = -0.75 +- 0.97i``, damping 0.61, an envelope shrinking by ``e`` every
1.33 m, whatever the speed. Beyond the linearisation, eq. 6 is to first order the
chained-form law ``z3' = -K2 z1' z2 - K3 |z1'| z3`` with ``z2 = ye``, ``z3 = tan(theta_e)``
whose Lyapunov function ``V = K2 z2^2 / 2 + z3^2 / 2`` has ``V' = -K3 |z1'| z3^2 <= 0``
(Morin & Samson 2008), which is why the ``tan`` appears.

``tan`` diverges at ``theta_e = +-pi/2``; we clip ``theta_e`` to ``MAX_HEADING_ERROR`` before
taking it, which keeps the sign (turn toward the path) and a bounded command.

Examples
--------
>>> from robots.path import SplinePath
>>> follower = ChainedFormFollower(SplinePath([(0.0, 0.0), (5.0, 0.0)]))
>>> v, omega = follower.command([0.0, 0.1, 0.0], dt=0.02)
>>> round(v, 3), round(omega, 3)
(0.01, -0.06)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from robots.path import SplinePath
from semistatic.frames import wrap_angle
from semistatic.validation import bounds, check_fields, unlimited

__all__ = ["ChainedFormFollower", "FollowerParams"]

# Heading errors beyond this (rad) are clipped before tan(): tan(pi/2) is infinite and
# beyond it the sign flips, which would steer away from the path.
MAX_HEADING_ERROR = math.radians(80.0)


def _limit(default: float, *, le: float, unit: str) -> Any:
    """Return a limit field: ``> 0`` and at most ``le``, or ``math.inf`` to switch it off."""
    return field(
        default=default,
        metadata={**bounds(gt=0.0, le=le, fix=f"{unit}; math.inf disables it"), **unlimited()},
    )


@dataclass(frozen=True)
class FollowerParams:
    """Gains and limits of the chained-form path follower.

    Parameters
    ----------
    speed
        Nominal forward speed ``u1r`` along the path, m/s (> 0).
    k1, k2, k3
        Gains of eq. (6): ``k1`` (1/m) on the along-track error, ``k2`` (1/m^2) on the
        lateral error, ``k3`` (1/m) on ``tan`` of the heading error. Paper: 3, 1.5, 1.5.
    max_speed, max_angular_speed
        Limits on ``|v|`` (m/s) and ``|omega|`` (rad/s). When either is exceeded both
        are scaled by the same factor, so the robot stays on the commanded arc.
    max_acceleration, max_deceleration
        Limits on how fast ``|v|`` may grow and shrink (m/s^2). Braking, including a
        safety stop, uses ``max_deceleration``; near the goal the reference speed
        follows ``sqrt(2 max_deceleration * remaining)`` so the robot stops on the end.
    max_angular_acceleration
        Limit on ``|d omega / dt|`` (rad/s^2).
    goal_tolerance
        The path is done when the progress is within this distance (m) of its end.
    projection_window
        Half-width (m) of the arc-length window searched for the progress around the
        previous one; larger than the distance travelled in one control tick.

    Notes
    -----
    Any limit may be ``math.inf`` (no limit).

    Examples
    --------
    >>> FollowerParams(speed=0.3).k1
    3.0
    >>> FollowerParams(k2=-1.0)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: k2: must be > 0.0 and <= 100.0, got -1.0 \
(1/m^2, lateral-error gain; paper uses 1.5)
    >>> FollowerParams(max_speed=math.inf).max_speed
    inf
    """

    # Bounds cover wheeled vehicles up to road speed (20 m/s); a limit of math.inf is off.
    speed: float = field(
        default=0.4, metadata=bounds(gt=0.0, le=20.0, fix="m/s, nominal forward speed")
    )
    k1: float = field(
        default=3.0, metadata=bounds(gt=0.0, le=100.0, fix="1/m, along-track gain; paper uses 3")
    )
    k2: float = field(
        default=1.5,
        metadata=bounds(gt=0.0, le=100.0, fix="1/m^2, lateral-error gain; paper uses 1.5"),
    )
    k3: float = field(
        default=1.5,
        metadata=bounds(gt=0.0, le=100.0, fix="1/m, heading-error gain; paper uses 1.5"),
    )
    max_speed: float = _limit(1.0, le=20.0, unit="m/s")
    max_angular_speed: float = _limit(1.5, le=20.0, unit="rad/s")
    max_acceleration: float = _limit(0.5, le=20.0, unit="m/s^2")
    max_deceleration: float = _limit(1.0, le=20.0, unit="m/s^2")
    max_angular_acceleration: float = _limit(3.0, le=100.0, unit="rad/s^2")
    goal_tolerance: float = field(default=0.05, metadata=bounds(gt=0.0, le=10.0, fix="m"))
    projection_window: float = field(
        default=1.0,
        metadata=bounds(gt=0.0, le=100.0, fix="m, exceed the distance of one control tick"),
    )

    def __post_init__(self) -> None:
        check_fields(self)


class ChainedFormFollower:
    """Follow a ``SplinePath`` with eq. (6), tracking the progress by projection.

    Parameters
    ----------
    path
        The path to follow, from ``s = 0`` to its end.
    params
        Gains and limits; defaults are the paper's gains.

    Attributes
    ----------
    progress : float
        Arc length of the current reference (the projection of the last pose).
    done : bool
        True once the progress came within ``goal_tolerance`` of the path end. On a
        closed path the follower keeps driving (the end is the next lap's start) until
        :meth:`reset` starts the next lap.

    Examples
    --------
    >>> from robots.path import SplinePath
    >>> follower = ChainedFormFollower(SplinePath([(0.0, 0.0), (1.0, 0.0)]))
    >>> pose, dt = np.zeros(3), 0.02
    >>> for _ in range(500):
    ...     v, omega = follower.command(pose, dt)
    ...     pose = pose + dt * np.array([v * np.cos(pose[2]), v * np.sin(pose[2]), omega])
    >>> follower.done, round(float(pose[0]), 2)
    (True, 1.0)
    """

    def __init__(self, path: SplinePath, params: FollowerParams | None = None) -> None:
        self.path = path
        self.params = FollowerParams() if params is None else params
        self.reset()

    def reset(self, s: float = 0.0, *, keep_speed: bool = False) -> None:
        """Start over from progress ``s`` (default the path start), standing still.

        ``keep_speed`` keeps the last command for the acceleration limits: the next lap
        of a closed path, entered at speed.

        Examples
        --------
        >>> from robots.path import SplinePath
        >>> follower = ChainedFormFollower(SplinePath([(0.0, 0.0), (1.0, 0.0)]))
        >>> follower.reset(0.5)
        >>> follower.progress, follower.done
        (0.5, False)
        """
        self.progress = float(np.clip(s, 0.0, self.path.length))
        self.done = False
        if not keep_speed:
            self._last_command = (0.0, 0.0)

    def errors(self, pose: ArrayLike) -> tuple[float, float, float]:
        """Return ``(xe, ye, theta_e)``: the robot's offset from its reference, robot frame.

        The reference is the path pose at the projection of ``pose`` (searched around the
        current progress); this does not advance the progress.

        Examples
        --------
        >>> from robots.path import SplinePath
        >>> follower = ChainedFormFollower(SplinePath([(0.0, 0.0), (2.0, 0.0)]))
        >>> [round(float(e), 3) for e in follower.errors([0.5, 0.2, 0.1])]
        [0.02, 0.199, 0.1]
        """
        x, y, theta = np.asarray(pose, dtype=float)[:3].tolist()
        x_ref, y_ref, theta_ref, _ = self.path.frame(self._project(x, y))
        return _offset(x, y, theta, x_ref, y_ref, theta_ref)

    def _project(self, x: float, y: float) -> float:
        """Return the progress at ``(x, y)``: the projection searched around the current one."""
        return self.path.project(
            (x, y), s_hint=self.progress, window=self.params.projection_window
        )

    def command(self, pose: ArrayLike, dt: float, speed_scale: float = 1.0) -> tuple[float, float]:
        """Advance the progress to ``pose`` and return the wheel-base command ``(v, omega)``.

        Parameters
        ----------
        pose
            ``(x, y, theta)`` estimate of the robot in the world frame (e.g. the EKF's).
        dt
            Control period in s (> 0), for the acceleration limits.
        speed_scale
            Factor in ``[0, 1]`` on the nominal speed from the safety fields: 1 clear,
            e.g. 0.5 in the warning field, 0 in the protective field (brake to a stop).

        Returns
        -------
        tuple of float
            Forward speed ``v`` (m/s) and yaw rate ``omega`` (rad/s), limited.

        Examples
        --------
        >>> from robots.path import SplinePath
        >>> follower = ChainedFormFollower(SplinePath([(0.0, 0.0), (5.0, 0.0)]))
        >>> follower.command([0.0, 0.0, 0.0], dt=0.02, speed_scale=0.0)
        (0.0, 0.0)
        """
        if not dt > 0.0:
            raise ValueError(f"ChainedFormFollower.command: dt must be > 0 s, got {dt}")
        if not 0.0 <= speed_scale <= 1.0:
            raise ValueError(
                f"ChainedFormFollower.command: speed_scale must be in [0, 1], got {speed_scale}"
            )
        x, y, theta = np.asarray(pose, dtype=float)[:3].tolist()
        params = self.params
        self.progress = self._project(x, y)
        remaining = self.path.length - self.progress
        if remaining <= params.goal_tolerance:
            self.done = True
        closed = self.path.closed
        if self.done and not closed:
            return self._limit(0.0, 0.0, dt)

        u1r = params.speed * speed_scale
        if not closed:
            # Brake profile: never faster than the speed from which the robot can still
            # stop at the path end with max_deceleration. A closed path has no end.
            u1r = min(u1r, math.sqrt(2.0 * params.max_deceleration * remaining))
        x_ref, y_ref, theta_ref, curvature = self.path.frame(self.progress)
        u2r = curvature * u1r
        xe, ye, theta_e = _offset(x, y, theta, x_ref, y_ref, theta_ref)
        theta_e = min(max(theta_e, -MAX_HEADING_ERROR), MAX_HEADING_ERROR)
        v = u1r - params.k1 * abs(u1r) * xe
        omega = u2r - params.k2 * u1r * ye - params.k3 * abs(u1r) * math.tan(theta_e)
        return self._limit(v, omega, dt)

    def _limit(self, v: float, omega: float, dt: float) -> tuple[float, float]:
        """Apply speed limits (keeping the arc), then acceleration limits; remember it."""
        params = self.params
        scale = 1.0
        if abs(v) > params.max_speed:
            scale = params.max_speed / abs(v)
        if abs(omega) * scale > params.max_angular_speed:
            scale = params.max_angular_speed / abs(omega)
        v, omega = v * scale, omega * scale

        last_v, last_omega = self._last_command
        # Speeding up (same direction, larger magnitude) vs braking.
        speeding_up = abs(v) > abs(last_v) and v * last_v >= 0.0
        step = (params.max_acceleration if speeding_up else params.max_deceleration) * dt
        v = min(max(v, last_v - step), last_v + step)
        angular_step = params.max_angular_acceleration * dt
        omega = min(max(omega, last_omega - angular_step), last_omega + angular_step)
        self._last_command = (float(v), float(omega))
        return self._last_command


def _offset(
    x: float, y: float, theta: float, x_ref: float, y_ref: float, theta_ref: float
) -> tuple[float, float, float]:
    """Return ``(xe, ye, theta_e)``: the pose's offset from the reference, robot frame."""
    dx, dy = x - x_ref, y - y_ref
    c, s_theta = math.cos(theta), math.sin(theta)
    xe = c * dx + s_theta * dy
    ye = -s_theta * dx + c * dy
    return xe, ye, wrap_angle(theta - theta_ref)
