"""2D rigid-body frames: poses ``(x, y, theta)`` in REP-103 convention.

A pose is a length-3 float array ``(x, y, theta)``: the position of a child frame in its
parent frame and its heading, counter-clockwise from the parent's x axis, wrapped to
``(-pi, pi]``. Functions here are pure and take anything array-like.

Examples
--------
>>> import numpy as np
>>> robot = np.array([1.0, 2.0, np.pi / 2])
>>> transform_points(robot, [[1.0, 0.0]])  # a point 1 m ahead of the robot
array([[1., 3.]])
>>> compose(robot, inverse(robot))
array([0., 0., 0.])
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "between",
    "compose",
    "inverse",
    "transform_points",
    "untransform_points",
    "wrap_angle",
    "wrap_angle_compiled",
]


_TWO_PI = 2.0 * math.pi


def wrap_angle(angle: ArrayLike) -> np.ndarray | float:
    """Wrap angles to ``(-pi, pi]``.

    Examples
    --------
    >>> float(wrap_angle(3 * np.pi / 2))
    -1.5707963267948966
    >>> float(wrap_angle(-np.pi))
    3.141592653589793
    >>> wrap_angle(math.nextafter(math.pi, 4.0))  # rounds onto -pi; the interval is (-pi, pi]
    3.141592653589793
    """
    if type(angle) is float:
        # Hot loops call this on plain floats; Python's % rounds exactly like np.mod,
        # without the array round trip (a tested equivalence).
        wrapped = math.pi - (math.pi - angle) % _TWO_PI
        return math.pi if wrapped == -math.pi else wrapped
    wrapped = np.pi - np.mod(np.pi - np.asarray(angle, dtype=float), 2.0 * np.pi)
    # Rounding can land exactly on -pi (just above pi, say): the interval is (-pi, pi].
    wrapped = np.where(wrapped == -np.pi, np.pi, wrapped)
    return float(wrapped) if wrapped.ndim == 0 else wrapped


@numba.njit(cache=True)
def wrap_angle_compiled(angle: float) -> float:
    """Wrap one angle to ``(-pi, pi]`` inside compiled (numba) kernels, as :func:`wrap_angle`.

    Examples
    --------
    >>> wrap_angle_compiled(3 * math.pi / 2)
    -1.5707963267948966
    >>> wrap_angle_compiled(-math.pi)
    3.141592653589793
    """
    wrapped = math.pi - (math.pi - angle) % (2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def compose(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Return ``a ⊕ b``: pose ``b`` (given in frame ``a``) expressed in ``a``'s parent.

    Examples
    --------
    >>> compose([1.0, 0.0, np.pi / 2], [1.0, 0.0, 0.0]).round(12)
    array([1.        , 1.        , 1.57079633])
    """
    # Python floats: a pose is three numbers, for which numpy's per-call cost dominates.
    ax, ay, at = _floats(a)
    bx, by, bt = _floats(b)
    c, s = math.cos(at), math.sin(at)
    return np.array([ax + c * bx - s * by, ay + s * bx + c * by, wrap_angle(at + bt)])


def inverse(a: ArrayLike) -> np.ndarray:
    """Return ``⊖a``, the parent frame seen from pose ``a``.

    Examples
    --------
    >>> inverse([1.0, 0.0, 0.0])
    array([-1.,  0.,  0.])
    """
    x, y, theta = _floats(a)
    c, s = math.cos(theta), math.sin(theta)
    return np.array([-c * x - s * y, s * x - c * y, wrap_angle(-theta)])


def _floats(pose: ArrayLike) -> list[float]:
    """Return a pose's ``(x, y, theta)`` as Python floats."""
    return np.asarray(pose, dtype=float).reshape(3).tolist()


def between(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Return ``⊖a ⊕ b``: pose ``b`` expressed in frame ``a`` (both given in one parent).

    This is the odometry increment from ``a`` to ``b``.

    Examples
    --------
    >>> between([1.0, 1.0, np.pi / 2], [1.0, 2.0, np.pi / 2]).round(12)
    array([1., 0., 0.])
    """
    return compose(inverse(a), b)


def transform_points(pose: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Map ``(N, 2)`` points from the frame of ``pose`` into its parent frame.

    Examples
    --------
    >>> transform_points([0.0, 0.0, np.pi], [[1.0, 0.0], [0.0, 1.0]]).round(12)
    array([[-1.,  0.],
           [-0., -1.]])
    """
    pose = np.asarray(pose, dtype=float)
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rotation = np.array([[c, -s], [s, c]])
    return pts @ rotation.T + pose[:2]


def untransform_points(pose: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Map ``(N, 2)`` points from the parent frame into the frame of ``pose``.

    Examples
    --------
    >>> untransform_points([1.0, 0.0, np.pi / 2], [[1.0, 1.0]]).round(12)
    array([[1., 0.]])
    """
    pose = np.asarray(pose, dtype=float)
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rotation = np.array([[c, -s], [s, c]])
    return (pts - pose[:2]) @ rotation
