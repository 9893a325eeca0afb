"""Differential-drive UGV descriptions: body, wheels, encoders, laser mounts, footprint.

A ``UGVSpec`` describes a two-wheel differential-drive vehicle with passive casters the
way its data sheet does. It is pure data (no PyBullet): ``robots.urdf`` turns it into a
URDF, ``sim.ugv.SimUGV`` drives that URDF on wheel motors and ``sim.encoders`` turns the
wheel angles into odometry.

Frames follow REP-103/REP-120: ``base_link`` lies on the floor, below the midpoint of the
drive-wheel axle (the vehicle's centre of rotation), x forward, y left, z up. Laser
mounts, casters, the body box and the footprint are given in ``base_link``.

Two presets:

``PIONEER3DX``
    The paper's robot (MobileRobots Pioneer 3-DX with one Sick LMS100 on top that serves
    both as safety and as localization laser).
``LGV``
    An industrial laser-guided vehicle: a low Sick S300 safety scanner in the front and a
    Sick LMS100 for landmark localization on a mast at about 2 m.

Examples
--------
>>> spec = get_preset("pioneer3dx")
>>> spec.encoder_ticks_per_rev, round(spec.max_speed, 3)
(19150, 1.2)
>>> left, right = spec.wheel_speeds(0.5, 0.0)
>>> round(float(left), 4), round(float(right), 4)
(5.1282, 5.1282)
>>> spec.safety_laser is spec.localization_laser
True
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from robots.lasers import LMS100, S300, LaserSpec
from semistatic.errors import MEMORY, SpecError
from semistatic.validation import bounds, check_fields

__all__ = [
    "LGV",
    "PIONEER3DX",
    "PRESETS",
    "LaserMount",
    "UGVSpec",
    "get_preset",
]

Point = tuple[float, float]

# Bounds a real wheeled vehicle respects, from a 2 kg lab robot to a 50 t heavy-load AGV.
MAX_VEHICLE_EXTENT = 20.0
"""Largest distance (m) of any body part, caster, mount or footprint vertex from the axle
midpoint: the longest automated guided vehicles are about 15 m long."""

_IN_VEHICLE = bounds(
    ge=-MAX_VEHICLE_EXTENT, le=MAX_VEHICLE_EXTENT, fix="metres in base_link, x forward, y left"
)


def _polygon_signed_area(vertices: np.ndarray) -> float:
    """Shoelace area, positive for a counter-clockwise polygon."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


@dataclass(frozen=True)
class LaserMount:
    """The pose of a planar laser scanner in ``base_link``.

    Parameters
    ----------
    laser
        The scanner's data-sheet description.
    x, y, z
        Position of the scan centre (the point the beams start from) in ``base_link``,
        metres. ``z`` is the height of the scan plane above the floor.
    yaw
        Heading of the scanner's x axis (its middle beam) in ``base_link``, radians,
        in ``(-pi, pi]``.

    Examples
    --------
    >>> mount = LaserMount(LMS100, x=0.1, y=0.0, z=0.3)
    >>> mount.pose2d()
    array([0.1, 0. , 0. ])
    >>> LaserMount(LMS100, x=0.1, y=0.0, z=-0.3)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: z: must be > 0.0 and <= 10.0, got -0.3 \
(metres: height of the scan plane above the floor)
    """

    laser: LaserSpec
    x: float = field(metadata=_IN_VEHICLE)
    y: float = field(metadata=_IN_VEHICLE)
    z: float = field(
        metadata=bounds(gt=0.0, le=10.0, fix="metres: height of the scan plane above the floor")
    )
    yaw: float = field(
        default=0.0,
        metadata=bounds(gt=-math.pi, le=math.pi, fix="wrap it with semistatic.frames.wrap_angle"),
    )

    def __post_init__(self) -> None:
        if not isinstance(self.laser, LaserSpec):
            raise TypeError(
                f"LaserMount.laser must be a robots.lasers.LaserSpec, got {type(self.laser)}"
            )
        check_fields(self)

    def pose2d(self) -> np.ndarray:
        """Return the planar mount pose ``(x, y, yaw)`` in ``base_link``.

        This is the sensor-to-base transform the EKF and the safety fields need.

        Examples
        --------
        >>> LaserMount(S300, x=0.6, y=0.0, z=0.15, yaw=0.0).pose2d()
        array([0.6, 0. , 0. ])
        """
        return np.array([self.x, self.y, self.yaw], dtype=float)


@dataclass(frozen=True)
class UGVSpec:
    """A differential-drive vehicle with passive casters, in SI units.

    Parameters
    ----------
    name
        Preset name (lower case, used by ``get_preset`` and scenario files).
    body_length, body_width
        Extent of the body box along x and y (m).
    body_height
        Height of the top of the body above the floor (m), as data sheets give it.
    ground_clearance
        Height of the bottom of the body box above the floor (m).
    body_x_offset
        x of the body box centre in ``base_link`` (m): positive when the drive axle sits
        behind the middle of the body.
    body_mass
        Mass of the body without drive wheels and casters, kg.
    wheel_radius, wheel_width, wheel_mass
        Drive wheel (tyre) radius (m), width (m) and mass (kg).
    wheel_separation
        Track: distance between the mid-planes of the two drive wheels (m).
    max_wheel_torque
        Torque limit of each wheel motor at the wheel (after the gearbox), N m. In the
        simulation this is the only limit on acceleration.
    max_wheel_speed
        Speed limit of each wheel, rad/s; ``command`` scales requests down to it.
    caster_radius, caster_mass
        Radius (m) of the passive ball casters and mass (kg) of each.
    caster_positions
        ``(x, y)`` of each caster's floor contact in ``base_link``. With the two drive
        wheels they must support the body: along x the centre of mass has to lie
        strictly between the axle (x = 0) and the farthest casters.
    encoder_ticks_per_rev
        Encoder counts per WHEEL revolution (motor encoder lines times gear ratio).
    encoder_slip_sigma
        Odometry noise: the relative 1-sigma error of one wheel's travelled distance
        over 1 m. The error variance grows linearly with distance, ``sigma**2 * |d| *
        1 m`` (Siegwart & Nourbakhsh's ``k |Δs|`` model with ``k = sigma**2 * 1 m``), so
        it does not depend on how often the odometry is sampled.
    safety_laser, localization_laser
        Where the scanners sit. The same ``LaserMount`` object for a robot whose single
        scanner serves both roles.
    footprint
        Outline of the vehicle in ``base_link`` as counter-clockwise ``(x, y)`` vertices.

    Examples
    --------
    >>> spec = PIONEER3DX
    >>> round(spec.total_mass, 2), round(spec.max_omega, 2)
    (9.0, 7.27)
    >>> PIONEER3DX.replace(wheel_radius=0.0)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: wheel_radius: must be > 0.0 and <= 2.0, got 0.0 \
(metres, tyre radius, e.g. 0.0975)
    """

    name: str
    body_length: float = field(metadata=bounds(gt=0.0, le=MAX_VEHICLE_EXTENT, fix="metres"))
    body_width: float = field(metadata=bounds(gt=0.0, le=MAX_VEHICLE_EXTENT, fix="metres"))
    body_height: float = field(
        metadata=bounds(gt=0.0, le=5.0, fix="metres: height of the body top above the floor")
    )
    ground_clearance: float = field(metadata=bounds(ge=0.0, le=5.0, fix="metres"))
    body_x_offset: float = field(metadata=_IN_VEHICLE)
    body_mass: float = field(metadata=bounds(gt=0.0, le=50000.0, fix="kg"))
    wheel_radius: float = field(
        metadata=bounds(gt=0.0, le=2.0, fix="metres, tyre radius, e.g. 0.0975")
    )
    wheel_separation: float = field(
        metadata=bounds(gt=0.0, le=MAX_VEHICLE_EXTENT, fix="metres between wheel mid-planes")
    )
    wheel_width: float = field(metadata=bounds(gt=0.0, le=1.0, fix="metres"))
    wheel_mass: float = field(metadata=bounds(gt=0.0, le=2000.0, fix="kg"))
    max_wheel_torque: float = field(
        metadata=bounds(gt=0.0, le=100000.0, fix="N m at the wheel, after the gearbox")
    )
    max_wheel_speed: float = field(
        metadata=bounds(gt=0.0, le=500.0, fix="rad/s: top speed / wheel_radius")
    )
    caster_radius: float = field(metadata=bounds(gt=0.0, le=1.0, fix="metres"))
    caster_mass: float = field(metadata=bounds(gt=0.0, le=500.0, fix="kg"))
    caster_positions: tuple[Point, ...] = field(metadata=_IN_VEHICLE)
    encoder_ticks_per_rev: int = field(
        metadata=bounds(ge=1, le=2**31 - 1, fix="counts per wheel revolution")
    )
    encoder_slip_sigma: float = field(
        metadata=bounds(
            ge=0.0, le=1.0, fix="relative 1-sigma error over 1 m; 0 for quantised-only odometry"
        )
    )
    safety_laser: LaserMount
    localization_laser: LaserMount
    footprint: tuple[Point, ...] = field(metadata=_IN_VEHICLE)

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.name or self.name != self.name.lower():
            raise SpecError(
                MEMORY, "name", f"must be a non-empty lower-case string, got {self.name!r}"
            )
        if self.ground_clearance >= self.body_height:
            raise SpecError(
                MEMORY,
                "ground_clearance",
                f"must be < body_height ({self.body_height} m), got {self.ground_clearance}: "
                "body_height is the height of the body top above the floor, not the box height",
            )
        if self.wheel_separation <= self.wheel_width:
            raise SpecError(
                MEMORY,
                "wheel_separation",
                f"must exceed wheel_width ({self.wheel_width} m), got {self.wheel_separation}: "
                "the track is measured between the wheel mid-planes",
            )
        for name in ("safety_laser", "localization_laser"):
            if not isinstance(getattr(self, name), LaserMount):
                raise TypeError(f"UGVSpec.{name} must be a LaserMount")
        self._validate_casters()
        self._validate_footprint()

    def _validate_casters(self) -> None:
        if not self.caster_positions:
            raise SpecError(MEMORY, "caster_positions", "needs at least one (x, y) caster")
        # The wheels touch the floor on the axle line (x = 0); a body carried by them and
        # the casters is statically stable only if the centre of mass lies strictly
        # between the axle and the farthest casters on each side it leans to.
        com_x = self.centre_of_mass_x
        caster_xs = [x for x, _ in self.caster_positions]
        if not min(*caster_xs, 0.0) < com_x < max(*caster_xs, 0.0):
            raise SpecError(
                MEMORY,
                "caster_positions",
                f"the centre of mass (x={com_x:.3f} m) must lie strictly between the axle "
                f"(x=0) and the casters (x={caster_xs}); move a caster past it or change "
                "body_x_offset",
            )

    def _validate_footprint(self) -> None:
        if len(self.footprint) < 3:
            raise SpecError(
                MEMORY, "footprint", f"needs at least 3 (x, y) vertices, got {len(self.footprint)}"
            )
        if _polygon_signed_area(np.asarray(self.footprint)) <= 0.0:
            raise SpecError(
                MEMORY,
                "footprint",
                "must be counter-clockwise with non-zero area; reverse the vertex order",
            )

    @property
    def total_mass(self) -> float:
        """Return the mass of body, drive wheels and casters, kg."""
        casters = len(self.caster_positions) * self.caster_mass
        return self.body_mass + 2.0 * self.wheel_mass + casters

    @property
    def centre_of_mass_x(self) -> float:
        """Return the x of the vehicle's centre of mass in ``base_link``, metres."""
        caster_x = sum(x for x, _ in self.caster_positions) * self.caster_mass
        return (self.body_mass * self.body_x_offset + caster_x) / self.total_mass

    @property
    def max_speed(self) -> float:
        """Return the top straight-line speed allowed by the wheel speed limit, m/s."""
        return self.max_wheel_speed * self.wheel_radius

    @property
    def max_omega(self) -> float:
        """Return the top turn-on-the-spot rate allowed by the wheel speed limit, rad/s."""
        return 2.0 * self.max_speed / self.wheel_separation

    @property
    def metres_per_tick(self) -> float:
        """Return the wheel travel per encoder count, metres."""
        return 2.0 * math.pi * self.wheel_radius / self.encoder_ticks_per_rev

    def wheel_speeds(self, v: ArrayLike, omega: ArrayLike) -> tuple[Any, Any]:
        """Return the wheel angular speeds ``(left, right)`` in rad/s for a body twist.

        Parameters
        ----------
        v
            Forward speed of ``base_link`` (m/s).
        omega
            Yaw rate (rad/s), counter-clockwise positive.

        Examples
        --------
        >>> left, right = PIONEER3DX.wheel_speeds(0.0, 1.0)  # turn left on the spot
        >>> round(float(left), 4), round(float(right), 4)
        (-1.6923, 1.6923)
        """
        v = np.asarray(v, dtype=float)
        omega = np.asarray(omega, dtype=float)
        half_track = 0.5 * self.wheel_separation
        left = (v - omega * half_track) / self.wheel_radius
        right = (v + omega * half_track) / self.wheel_radius
        return left[()], right[()]

    def twist_from_wheel_speeds(self, left: ArrayLike, right: ArrayLike) -> tuple[Any, Any]:
        """Return the body twist ``(v, omega)`` for wheel angular speeds in rad/s.

        The inverse of ``wheel_speeds``; it also maps wheel angle increments (rad) to the
        travelled distance and heading change of an exact no-slip drive.

        Examples
        --------
        >>> v, omega = PIONEER3DX.twist_from_wheel_speeds(*PIONEER3DX.wheel_speeds(0.4, -0.3))
        >>> round(float(v), 12), round(float(omega), 12)
        (0.4, -0.3)
        """
        left = np.asarray(left, dtype=float) * self.wheel_radius
        right = np.asarray(right, dtype=float) * self.wheel_radius
        v = 0.5 * (left + right)
        omega = (right - left) / self.wheel_separation
        return v[()], omega[()]

    def replace(self, **changes: Any) -> UGVSpec:
        """Return a copy with some fields changed (validated again).

        Examples
        --------
        >>> PIONEER3DX.replace(max_wheel_torque=0.05).max_wheel_torque
        0.05
        """
        return replace(self, **changes)


def _box_footprint(length: float, width: float, x_offset: float) -> tuple[Point, ...]:
    """Counter-clockwise rectangle of ``length`` x ``width`` centred at ``(x_offset, 0)``."""
    front, rear = x_offset + 0.5 * length, x_offset - 0.5 * length
    half = 0.5 * width
    return ((front, -half), (front, half), (rear, half), (rear, -half))


_PIONEER_LMS100 = LaserMount(LMS100, x=0.12, y=0.0, z=0.35, yaw=0.0)

PIONEER3DX = UGVSpec(
    name="pioneer3dx",
    body_length=0.455,
    body_width=0.381,
    body_height=0.237,
    ground_clearance=0.06,
    body_x_offset=-0.045,
    body_mass=7.8,
    wheel_radius=0.0975,
    wheel_separation=0.33,
    wheel_width=0.047,
    wheel_mass=0.5,
    max_wheel_torque=1.0,
    max_wheel_speed=1.2 / 0.0975,
    caster_radius=0.04,
    caster_mass=0.2,
    caster_positions=((-0.2, 0.0),),
    encoder_ticks_per_rev=500 * 383 // 10,
    encoder_slip_sigma=0.0005,
    safety_laser=_PIONEER_LMS100,
    localization_laser=_PIONEER_LMS100,
    footprint=_box_footprint(0.455, 0.381, -0.045),
)
"""MobileRobots (Adept) Pioneer 3-DX with a Sick LMS100: the robot of the paper's real tests.

Figures and where they come from:

- Body 455 mm long, 381 mm wide, 237 mm high; robot weight about 9 kg; two 195 mm drive
  wheels and a rear caster; top speed 1.2 m/s: Pioneer 3-DX data sheet (MobileRobots /
  Adept MobileRobots) and the Pioneer 3 Operations Manual (MobileRobots 2006-2007).
- Encoders: 500 ticks per motor revolution and a 38.3:1 gearbox, hence
  500 * 38.3 = 19150 counts per wheel revolution (Pioneer 3 Operations Manual).
- Tyre width 47 mm and track 0.33 m: the overall width (381 mm) minus one tyre width,
  the value commonly used for P3-DX kinematics; the data sheet gives no track figure.
- Drive axle 45 mm ahead of the body centre and the caster 0.2 m behind the axle, as in
  the ROS ``p2os``/``amr-ros-config`` P3-DX descriptions (chassis at x = -0.045).
- Our estimates, not data-sheet figures: ground clearance 60 mm, the 9 kg split into a
  7.8 kg body, 0.5 kg per wheel and a 0.2 kg caster, caster radius 40 mm, wheel torque
  limit 1 N m (peak acceleration ~2 m/s^2, far below the ~7 m/s^2 the tyres can
  transmit at friction 1 with ~80 % of the weight on them, so a step command never
  makes them slip), odometry noise
  0.05 % per sqrt(m) per wheel.
- LMS100 on the top plate, 0.12 m ahead of the axle with its scan plane at 0.35 m: our
  placement (the paper does not give it); the one scanner is both safety and
  localization laser, as on the paper's robot.
"""

_LGV_S300 = LaserMount(S300, x=0.62, y=0.0, z=0.15, yaw=0.0)
_LGV_LMS100 = LaserMount(LMS100, x=0.0, y=0.0, z=2.0, yaw=0.0)

LGV = UGVSpec(
    name="lgv",
    body_length=1.2,
    body_width=0.8,
    body_height=0.45,
    ground_clearance=0.05,
    body_x_offset=0.0,
    body_mass=180.0,
    wheel_radius=0.125,
    wheel_separation=0.6,
    wheel_width=0.08,
    wheel_mass=8.0,
    max_wheel_torque=15.0,
    max_wheel_speed=1.5 / 0.125,
    caster_radius=0.05,
    caster_mass=2.0,
    caster_positions=((0.45, 0.0), (-0.45, 0.0)),
    encoder_ticks_per_rev=4096 * 20,
    encoder_slip_sigma=0.0005,
    safety_laser=_LGV_S300,
    localization_laser=_LGV_LMS100,
    footprint=(
        (0.6, -0.4),
        (0.67, -0.1),
        (0.67, 0.1),
        (0.6, 0.4),
        (-0.6, 0.4),
        (-0.6, -0.4),
    ),
)
"""A compact industrial laser-guided vehicle (LGV) with centre drive.

A representative vehicle, not a specific product: the magnitudes follow compact
differential-drive AGVs' published data (e.g. a MiR100: 890 x 580 mm, 67 kg, 1.5 m/s,
Sick S300 safety scanners) scaled to a 1.2 x 0.8 m pallet-size body as in the paper's
industrial setting.

- Body 1.2 x 0.8 m, 0.45 m high, 50 mm ground clearance, 180 kg body (200 kg in all);
  drive axle in the middle with 250 mm polyurethane drive wheels on a 0.6 m track and a
  ball caster 0.45 m ahead and behind: our choices.
- Top speed 1.5 m/s (wheel limit 12 rad/s); wheel torque limit 15 N m, peak acceleration
  ~1.1 m/s^2, far below the tyres' friction limit: our choices.
- Encoders: 1024-line quadrature encoder (4096 counts per motor revolution) behind a 20:1
  gearbox, 81920 counts per wheel revolution: typical traction drive, our choice.
- Sick S300 safety scanner at the front, 0.62 m ahead of the axle (in a bracket just ahead
  of the 0.6 m body front) with its scan plane 0.15 m above the floor: SICK's S300
  operating instructions ask for a low scan plane on vehicles (at most ~200 mm so that
  a lying person's legs are detected). The footprint includes the scanner bracket.
- Sick LMS100 localization scanner on a mast above the axle at 2.0 m, clear of people and
  boxes, seeing the reflective posts: the usual LGV layout the paper describes.
"""

PRESETS: dict[str, UGVSpec] = {spec.name: spec for spec in (PIONEER3DX, LGV)}
"""Registered presets by name."""


def get_preset(name: str) -> UGVSpec:
    """Return the preset called ``name`` (case-insensitive).

    Examples
    --------
    >>> get_preset("LGV").wheel_radius
    0.125
    >>> get_preset("pionner3dx")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    KeyError: "unknown robot preset 'pionner3dx'; did you mean 'pioneer3dx'? ..."
    """
    key = name.strip().lower()
    if key in PRESETS:
        return PRESETS[key]
    close = difflib.get_close_matches(key, PRESETS, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    known = ", ".join(sorted(PRESETS))
    raise KeyError(f"unknown robot preset {name!r}{hint} (known: {known})")
