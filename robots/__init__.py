"""The industrial UGV as it exists before the paper: description and onboard stack.

Descriptions (presets, lasers, URDF) and the navigation stack (reflective-post landmarks,
three-object triangulation, EKF localizer, cubic-spline path, chained-form follower,
warning/protective safety fields). Pure numpy/scipy/filterpy: no PyBullet.
"""

from robots.ekf import EKFLocalizer, EKFParams, EKFRecord
from robots.follower import ChainedFormFollower, FollowerParams
from robots.landmarks import LandmarkObservation, associate_landmarks, detect_landmarks
from robots.lasers import LMS100, POST_INTENSITY_THRESHOLD, S300, LaserSpec
from robots.path import SplinePath
from robots.presets import LGV, PIONEER3DX, PRESETS, LaserMount, UGVSpec, get_preset
from robots.safety import (
    FieldSet,
    FieldState,
    SafetyPolicy,
    SafetySupervisor,
    field_occupancy,
    scan_points_in_robot_frame,
)
from robots.triangulation import TriangulationError, triangulate
from semistatic.cache_healing import heal_kernels

__all__ = [
    "LGV",
    "LMS100",
    "PIONEER3DX",
    "POST_INTENSITY_THRESHOLD",
    "PRESETS",
    "S300",
    "ChainedFormFollower",
    "EKFLocalizer",
    "EKFParams",
    "EKFRecord",
    "FieldSet",
    "FieldState",
    "FollowerParams",
    "LandmarkObservation",
    "LaserMount",
    "LaserSpec",
    "SafetyPolicy",
    "SafetySupervisor",
    "SplinePath",
    "TriangulationError",
    "UGVSpec",
    "associate_landmarks",
    "detect_landmarks",
    "field_occupancy",
    "get_preset",
    "scan_points_in_robot_frame",
    "triangulate",
]

# A damaged numba cache file of a kernel is deleted and the kernel compiled again,
# instead of failing every run (semistatic/cache_healing.py): before any kernel runs.
heal_kernels("robots")
