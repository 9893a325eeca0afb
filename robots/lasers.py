"""Laser range finder specifications: the Sick LMS100 and the Sick S300 safety laser.

A ``LaserSpec`` describes a 2D scanner the way its data sheet does: field of view,
angular resolution, scan rate, valid range interval and error figures. It is pure data
(no PyBullet); ``sim.laser.RaycastLaser`` turns it into ray casts, and the onboard stack
uses ``angles()`` and the intensity threshold to find the reflective landmark posts.

Intensities in this project are remission values on a ``[0, 1]`` scale (diffuse
reflectance of the hit surface as seen by the scanner): walls and boxes read low, the
retro-reflective landmark posts read high, and ``POST_INTENSITY_THRESHOLD`` separates them.

Examples
--------
>>> LMS100.num_beams, S300.num_beams
(541, 541)
>>> round(LMS100.angle_min, 4), round(float(LMS100.angles()[-1]), 4)
(-2.3562, 2.3562)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from semistatic.errors import MEMORY, SpecError
from semistatic.types import MAX_BEAMS
from semistatic.validation import bounds, check_fields

__all__ = [
    "LMS100",
    "POST_INTENSITY_THRESHOLD",
    "S300",
    "LaserSpec",
]

# Remission (intensity) above which a return is taken to come from a retro-reflective
# landmark post. Posts are specified at 0.95 and every other surface at <= 0.5, so with
# an intensity noise of a few hundredths this threshold sits many sigmas from both.
POST_INTENSITY_THRESHOLD = 0.7

# Slack when counting how many whole angular steps fit in the field of view, so that
# 270 deg / 0.5 deg gives 540 steps despite floating-point rounding.
_BEAM_COUNT_SLACK = 1e-9

MAX_RANGE_SIGMA = 10.0
"""Largest range noise (m): a data-sheet figure (<= 0.03 m) times a scenario's noise factor
(up to 100)."""


@dataclass(frozen=True)
class LaserSpec:
    """A planar laser scanner as its data sheet describes it.

    Parameters
    ----------
    name
        Human-readable model name.
    fov
        Field of view (aperture angle) in radians, centred on the sensor's x axis.
    angular_resolution
        Angle between neighbouring beams, radians.
    rate_hz
        Scans per second.
    range_min, range_max
        Valid range interval in metres; returns outside it are reported as ``inf``.
    range_sigma
        Statistical (random, per-reading) range error, 1-sigma, metres.
    range_bias_max
        Systematic range error bound, metres: each laser instance draws one bias
        uniformly in ``[-range_bias_max, range_bias_max]`` and adds it to every reading.
    intensity_sigma
        1-sigma noise added to the remission of the hit surface.
    dropout_prob
        Probability that a beam returns nothing (reported as ``inf``).
    multiple_sampling
        Consecutive scans an object must interrupt a safety field before the field
        triggers (a safety scanner's multiple sampling; 2 is Sick's minimum). The
        scanner's response time is this many scan periods
        (:func:`robots.stopping.response_time`).
    general_supplement
        Supplement for general measurement errors added to a protective field's length
        and to each side of its width (m; Sick's ``Z_G``).
    reflector_supplement, reflector_range
        Supplement for reflection-related measurement errors (m; Sick's ``Z_R``), added
        like ``general_supplement`` when a retroreflector is within ``reflector_range``
        (m) of the protective field's boundary.

    Examples
    --------
    >>> spec = LaserSpec(name="toy", fov=math.radians(90), angular_resolution=math.radians(45),
    ...                  rate_hz=10.0, range_min=0.1, range_max=5.0, range_sigma=0.01,
    ...                  range_bias_max=0.0, intensity_sigma=0.0, dropout_prob=0.0)
    >>> spec.num_beams
    3
    >>> spec.angles().round(4)
    array([-0.7854,  0.    ,  0.7854])
    >>> LaserSpec(**{**vars(spec), "fov": 270.0})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: fov: must be > 0.0 and <= 6.28..., got 270.0 \
(radians: math.radians(270) for a 270 deg scanner)
    """

    # Bounds span real 2D scanners (safety scanners to 100 m+ surveying-grade lidars).
    name: str
    fov: float = field(
        metadata=bounds(
            gt=0.0, le=2.0 * math.pi, fix="radians: math.radians(270) for a 270 deg scanner"
        )
    )
    angular_resolution: float = field(
        metadata=bounds(ge=math.radians(0.01), le=math.radians(45.0),
                        fix="radians: math.radians(0.5) for 0.5 deg")
    )
    rate_hz: float = field(metadata=bounds(gt=0.0, le=200.0, fix="scans per second, e.g. 25"))
    range_min: float = field(metadata=bounds(ge=0.0, le=10.0, fix="metres, e.g. 0.05"))
    range_max: float = field(metadata=bounds(gt=0.0, le=500.0, fix="metres, e.g. 20"))
    range_sigma: float = field(
        metadata=bounds(ge=0.0, le=MAX_RANGE_SIGMA, fix="metres, 1-sigma, e.g. 0.012")
    )
    range_bias_max: float = field(metadata=bounds(ge=0.0, le=1.0, fix="metres, e.g. 0.03"))
    intensity_sigma: float = field(
        metadata=bounds(ge=0.0, le=1.0, fix="on the [0, 1] remission scale, e.g. 0.02")
    )
    dropout_prob: float = field(metadata=bounds(ge=0.0, lt=1.0, fix="a probability, e.g. 0"))
    multiple_sampling: int = field(default=2, metadata=bounds(ge=1, le=16, fix="scans, e.g. 2"))
    general_supplement: float = field(default=0.1, metadata=bounds(ge=0.0, le=1.0,
                                                                   fix="metres, e.g. 0.1"))
    reflector_supplement: float = field(default=0.2, metadata=bounds(ge=0.0, le=1.0,
                                                                     fix="metres, e.g. 0.2"))
    reflector_range: float = field(default=1.0, metadata=bounds(ge=0.0, le=10.0,
                                                                fix="metres, e.g. 1.0"))

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.name:
            raise SpecError(MEMORY, "name", "must be a non-empty string, e.g. 'Sick LMS100'")
        if self.angular_resolution > self.fov:
            raise SpecError(
                MEMORY,
                "angular_resolution",
                f"must not exceed fov ({self.fov} rad), got {self.angular_resolution}",
            )
        if self.range_min >= self.range_max:
            raise SpecError(
                MEMORY,
                "range_min",
                f"must be < range_max ({self.range_max} m), got {self.range_min}",
            )
        if self.num_beams > MAX_BEAMS:  # a Scan refuses more: check, not the run, says so
            raise SpecError(
                MEMORY,
                "angular_resolution",
                f"gives {self.num_beams} beams over the fov, more than the limit of "
                f"{MAX_BEAMS} a scan may have; use a coarser resolution",
            )

    @property
    def num_beams(self) -> int:
        """Return the number of beams in one scan (both edges of the field of view included)."""
        return math.floor(self.fov / self.angular_resolution + _BEAM_COUNT_SLACK) + 1

    @property
    def angle_min(self) -> float:
        """Return the angle of the first (rightmost) beam, ``-fov / 2``, in radians."""
        return -0.5 * self.fov

    @property
    def period(self) -> float:
        """Return the time between two scans, ``1 / rate_hz``, in seconds."""
        return 1.0 / self.rate_hz

    def angles(self) -> np.ndarray:
        """Return the ``(num_beams,)`` beam angles in the sensor frame, counter-clockwise.

        Examples
        --------
        >>> a = LMS100.angles()
        >>> a.shape, round(float(a[1] - a[0]), 6)
        ((541,), 0.008727)
        """
        return self.angle_min + self.angular_resolution * np.arange(self.num_beams, dtype=float)


LMS100 = LaserSpec(
    name="Sick LMS100",
    fov=math.radians(270.0),
    angular_resolution=math.radians(0.5),
    rate_hz=50.0,
    range_min=0.5,
    range_max=20.0,
    range_sigma=0.012,
    range_bias_max=0.030,
    intensity_sigma=0.02,
    dropout_prob=0.0,
)
"""Sick LMS100 (LMS100-10000), the Pioneer 3DX's laser in the paper.

Data sheet (SICK "LMS100/111/120 Laser Measurement Systems", operating instructions,
technical data): aperture angle 270 deg; angular resolution 0.25 deg / 0.5 deg
(0.5 deg used, 541 beams); scanning frequency 25 Hz / 50 Hz (50 Hz used, 0.5 deg goes
with 50 Hz); operating range 0.5 m to 20 m; statistical error (1 sigma) +-12 mm;
systematic error +-30 mm. The data sheet gives no intensity noise figure: 0.02 on the
``[0, 1]`` remission scale is our choice, and dropouts are off by default. The LMS100 is
no safety scanner; where it guards a vehicle (the Pioneer) we give it a safety
scanner's settings: multiple sampling 2 and Sick's S300 supplements (100 mm general,
200 mm near reflectors within 1 m).
"""

S300 = LaserSpec(
    name="Sick S300",
    fov=math.radians(270.0),
    angular_resolution=math.radians(0.5),
    rate_hz=12.5,
    range_min=0.05,
    range_max=8.0,
    range_sigma=0.03,
    range_bias_max=0.0,
    intensity_sigma=0.02,
    dropout_prob=0.0,
)
"""Sick S300 safety laser scanner, mounted low on the ``lgv`` preset.

Data sheet (SICK "S300 Safety laser scanner", operating instructions, technical data):
scanning angle 270 deg; angular resolution 0.5 deg (541 measured values per scan);
scan time 80 ms, hence 12.5 Hz; protective field range up to 2 m (Medium Range) or 3 m
(Long Range); warning field range up to 8 m, which we take as ``range_max`` because the
safety fields and the mapper only use returns inside the warning field. The S300 data
sheet specifies field tolerances rather than a range noise: 0.03 m (1 sigma) is our
choice, inside the 100 mm general measurement-error supplement the manual asks to add
to protective fields; no systematic bias, no intensity output on the real device
(0.02 remission noise is ours so the scan carries comparable intensities), minimum
range 0.05 m is ours (the scanner has no blind zone specification beyond its housing).
Safety settings from the operating instructions: multiple sampling 2 (its minimum, with
the 80 ms basic response time), general supplement ``Z_G`` 100 mm, reflector supplement
``Z_R`` 200 mm with retroreflectors closer than 1 m to the protective field.
"""
