"""A 2D laser scanner simulated with one PyBullet ``rayTestBatch`` per scan.

``RaycastLaser`` casts the beams of a ``robots.lasers.LaserSpec`` horizontally from the
sensor pose, turns hit fractions into ranges and hit body ids into intensities (the
remission of the hit body, via ``SimWorld.remission_of``), and adds the data sheet's
errors: Gaussian statistical noise on every reading, a systematic bias drawn once per
laser instance, intensity noise and optional beam dropouts.

Range semantics follow ROS ``sensor_msgs/LaserScan``:

- no surface within ``range_max`` (or a dropped beam) reads ``inf``;
- a noisy reading that lands above ``range_max`` is clipped to ``range_max`` (the surface
  is really there);
- a reading below ``range_min`` is kept as measured (never negative): ``Scan.valid_mask``
  discards it, like a ROS consumer would, and nothing closer is hidden by starting the
  rays late (a ray starting inside a box would see through it).

The robot never sees itself: its bodies are put in their own collision filter group
(``exclude_from_lasers``) that every laser's ray mask leaves out; they still collide with
everything as before.

Examples
--------
>>> import numpy as np
>>> from robots.lasers import LMS100
>>> from sim.client import SimClient
>>> from sim.world_builder import SimWorld
>>> from worlds.spec import PathSpec, SegmentSpec, WallSpec, WorldSpec
>>> field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
>>> path = PathSpec([(0.0, 0.0), (1.0, 0.0)], [SegmentSpec("a", 0, 1, field, field)])
>>> spec = WorldSpec(name="wall", walls=(WallSpec((3.0, -5.0), (3.0, 5.0)),), posts=(),
...                  boxes=(), people=(), path=path)
>>> with SimClient() as sim:
...     laser = RaycastLaser(sim, LMS100, SimWorld(sim, spec), np.random.default_rng(0),
...                          noise_free=True)
...     scan = laser.scan((0.0, 0.0, 0.3, 0.0), stamp=0.0)
>>> round(float(scan.ranges[270]), 4), bool(np.isinf(scan.ranges[0]))
(2.95, True)
"""

from __future__ import annotations

import math
import time
from operator import itemgetter

import numpy as np
from numpy.typing import ArrayLike

from robots.lasers import LaserSpec
from semistatic.frames import wrap_angle
from semistatic.types import Scan

__all__ = [
    "LASER_IGNORE_GROUP",
    "LASER_RAY_MASK",
    "MAX_VEHICLES",
    "RaycastLaser",
    "exclude_from_lasers",
    "vehicle_laser_group",
]

LASER_IGNORE_GROUP = 1 << 10
"""Collision filter group of bodies lasers do not see (the robot's own links).

Bullet's predefined groups use bits 0-5, so bit 10 is free for us."""

LASER_RAY_MASK = ~LASER_IGNORE_GROUP
"""``collisionFilterMask`` of every ray: hits bodies whose group shares a bit with it."""

# Everything (Bullet's AllFilter): an excluded body keeps colliding with all groups.
_COLLIDE_WITH_ALL = -1

# Fields of one rayTestBatch hit tuple: (objectUniqueId, linkIndex, hit fraction, ...).
_HIT_BODY = itemgetter(0)
_HIT_FRACTION = itemgetter(2)


def exclude_from_lasers(sim, body_id: int, group: int = LASER_IGNORE_GROUP) -> None:
    """Hide every link of ``body_id`` from the rays of mask ``~group``; collisions are unchanged.

    Sets the body's collision filter group to ``group`` (default ``LASER_IGNORE_GROUP``,
    hidden from every ``RaycastLaser`` with the default mask) and its mask to all bits,
    so it still collides with every other body (Bullet collides two bodies when each
    one's group meets the other's mask) while the rays' mask leaves it out. Vehicles of a
    fleet each take a group of their own (:func:`vehicle_laser_group`): a laser then
    misses its own vehicle and sees the others.

    Examples
    --------
    >>> from sim.client import SimClient
    >>> with SimClient() as sim:
    ...     b = sim.bullet
    ...     body = b.createMultiBody(1.0, b.createCollisionShape(b.GEOM_SPHERE, radius=0.2),
    ...                              -1, [1.0, 0.0, 0.2])
    ...     ray = ([[0, 0, 0.2]], [[2, 0, 0.2]])
    ...     before = b.rayTestBatch(*ray, collisionFilterMask=LASER_RAY_MASK)
    ...     exclude_from_lasers(sim, body)
    ...     after = b.rayTestBatch(*ray, collisionFilterMask=LASER_RAY_MASK)
    >>> before[0][0] == body, after[0][0]
    (True, -1)
    """
    bullet = sim.bullet
    for link in range(-1, bullet.getNumJoints(body_id)):
        bullet.setCollisionFilterGroupMask(body_id, link, group, _COLLIDE_WITH_ALL)


MAX_VEHICLES = 16
"""Vehicles that can each have a laser group of their own (bits 10-25)."""


def vehicle_laser_group(index: int) -> int:
    """Return the collision filter group of vehicle ``index``'s body (0: ``LASER_IGNORE_GROUP``).

    Examples
    --------
    >>> vehicle_laser_group(0) == LASER_IGNORE_GROUP, vehicle_laser_group(1) == 1 << 11
    (True, True)
    >>> bool(~vehicle_laser_group(1) & vehicle_laser_group(0))  # vehicle 1's rays see vehicle 0
    True
    """
    if not 0 <= index < MAX_VEHICLES:
        raise ValueError(f"vehicle_laser_group: index must be in [0, {MAX_VEHICLES}), got {index}")
    return LASER_IGNORE_GROUP << index


class RaycastLaser:
    """A laser scanner of ``spec`` that casts real rays into the world ``world``.

    Parameters
    ----------
    sim
        The ``sim.client.SimClient``; the wall time of every ray cast is added to its
        ``engine_time_s``.
    spec
        The scanner's data sheet figures.
    world
        The ``sim.world_builder.SimWorld`` whose bodies give remissions.
    rng
        Source of every random draw (bias at construction, noise and dropouts per scan).
    num_threads
        Threads for ``rayTestBatch`` (0: all available, as in pybullet).
    ignore_body_ids
        Bodies this laser must not see (the robot carrying it); passed to
        ``exclude_from_lasers`` with ``ignore_group``.
    ignore_group
        Collision filter group of those bodies; this laser's rays leave that group out
        (default ``LASER_IGNORE_GROUP``: hidden from every laser with the default group).
    noise_free
        When true, ranges and intensities are exact (no bias, noise or dropout) and
        ``rng`` is never used.

    Attributes
    ----------
    bias
        The systematic range error of this instance, metres.
    last_raycast_s
        Wall time of the last ``rayTestBatch`` call, seconds.
    """

    def __init__(
        self,
        sim,
        spec: LaserSpec,
        world,
        rng: np.random.Generator,
        *,
        num_threads: int = 0,
        ignore_body_ids: tuple[int, ...] = (),
        noise_free: bool = False,
        ignore_group: int = LASER_IGNORE_GROUP,
    ) -> None:
        if num_threads < 0:
            raise ValueError(f"RaycastLaser: num_threads must be >= 0 (0 = all), got {num_threads}")
        self.sim = sim
        self.spec = spec
        self.world = world
        self.rng = rng
        self.num_threads = int(num_threads)
        self.noise_free = bool(noise_free)
        for body in ignore_body_ids:
            exclude_from_lasers(sim, body, ignore_group)
        self.ray_mask = ~int(ignore_group)
        self.bias = (
            0.0 if noise_free else float(rng.uniform(-spec.range_bias_max, spec.range_bias_max))
        )
        self._angles = spec.angles()
        self._cos = np.cos(self._angles)
        self._sin = np.sin(self._angles)
        self._ray_test_batch = sim.bullet.rayTestBatch  # bound once (BulletClient re-wraps)
        self._from = np.empty((spec.num_beams, 3))
        self._to = np.empty((spec.num_beams, 3))
        self.last_raycast_s = 0.0

    def cast(self, sensor_pose_xyz_yaw: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Cast every beam once and return the exact ``(ranges, body_ids)``.

        ``ranges`` is ``inf`` and ``body_ids`` is ``-1`` where a beam hits nothing within
        ``range_max``. No noise; ``scan`` builds on the same hits.
        """
        body_ids, distances = self.hits(sensor_pose_xyz_yaw)
        return np.where(body_ids >= 0, distances, np.inf), body_ids

    def hits(self, sensor_pose_xyz_yaw: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Cast every beam once; return its hit body id (-1: none) and ``fraction * range_max``.

        The one ray cast behind :meth:`cast` and :meth:`scan`: a beam that hits nothing
        reads ``range_max`` here (``cast`` turns it into ``inf``, ``scan`` drops it).

        Examples
        --------
        >>> from robots.lasers import LMS100
        >>> from sim.client import SimClient
        >>> from sim.world_builder import SimWorld
        >>> from worlds.load import load_world
        >>> with SimClient() as sim:  # sim1's hall; beam 270 looks straight ahead
        ...     world = SimWorld(sim, load_world("sim1"))
        ...     laser = RaycastLaser(sim, LMS100, world, np.random.default_rng(0))
        ...     body_ids, distances = laser.hits((1.0, 0.0, 0.3, 0.0))
        ...     ahead = world.name_of(int(body_ids[270])), round(float(distances[270]), 2)
        ...     body_ids, distances = laser.hits((1.0, 0.0, 5.0, 0.0))  # above the walls
        >>> ahead, int(body_ids.max()), float(distances.min())
        (('post_10', 8.85), -1, 20.0)
        """
        x, y, z, yaw = np.asarray(sensor_pose_xyz_yaw, dtype=float).tolist()
        # math's cos and sin are numpy's to the last bit (both call the C library).
        cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
        # world-frame beam directions: rotate the precomputed sensor-frame unit vectors
        dir_x = cos_yaw * self._cos
        dir_x -= sin_yaw * self._sin
        dir_y = sin_yaw * self._cos
        dir_y += cos_yaw * self._sin
        length = self.spec.range_max
        self._from[:] = (x, y, z)
        dir_x *= length
        dir_y *= length
        np.add(x, dir_x, out=self._to[:, 0])
        np.add(y, dir_y, out=self._to[:, 1])
        self._to[:, 2] = z
        # One clock for both figures (the engine_timer context manager costs a few us).
        start = time.perf_counter()
        try:
            results = self._ray_test_batch(
                self._from,
                self._to,
                numThreads=self.num_threads,
                collisionFilterMask=self.ray_mask,
            )
        finally:
            self.last_raycast_s = time.perf_counter() - start
            self.sim.engine_time_s += self.last_raycast_s
        count = len(results)
        # map(itemgetter) stays in C: no Python frame per beam, unlike a generator.
        body_ids = np.fromiter(map(_HIT_BODY, results), dtype=np.int64, count=count)
        distances = np.fromiter(map(_HIT_FRACTION, results), dtype=float, count=count)
        distances *= length
        return body_ids, distances

    def scan(self, sensor_pose_xyz_yaw: ArrayLike, stamp: float = 0.0) -> Scan:
        """Take one scan from ``sensor_pose_xyz_yaw`` = (x, y, z, yaw) in the world.

        The returned ``Scan.pose`` is the true sensor (x, y, yaw): ground truth, not an
        estimate.
        """
        pose = np.asarray(sensor_pose_xyz_yaw, dtype=float)
        values = pose.tolist() if pose.shape == (4,) else [math.nan]
        if not all(math.isfinite(v) for v in values):
            raise ValueError(
                f"RaycastLaser.scan: sensor pose must be 4 finite numbers (x, y, z, yaw), "
                f"got {pose!r}"
            )
        body_ids, distances = self.hits(values)
        hit = body_ids >= 0
        remission = self.world.remission_of(body_ids)
        spec = self.spec
        if self.noise_free:
            ranges = np.where(hit, distances, np.inf)
            intensities = remission
        else:
            # draw the same amount of noise every scan so the stream never depends on hits
            count = spec.num_beams
            range_noise = self.rng.normal(0.0, spec.range_sigma, count)
            intensity_noise = self.rng.normal(0.0, spec.intensity_sigma, count)
            dropped = self.rng.random(count) < spec.dropout_prob
            # numpy.clip, as maximum then minimum (clip's Python wrapper costs more than both).
            # A missed beam's distance is range_max, not inf: where() below drops it anyway.
            measured = distances
            measured += self.bias
            measured += range_noise
            np.maximum(measured, 0.0, out=measured)
            np.minimum(measured, spec.range_max, out=measured)
            hit &= ~dropped
            ranges = np.where(hit, measured, np.inf)
            intensities = remission
            intensities += intensity_noise
            np.maximum(intensities, 0.0, out=intensities)
            # Zero where nothing was hit: times 0 or 1, exact on these finite values >= 0,
            # and cheaper than indexing with the inverted mask.
            intensities *= hit
        return Scan(
            ranges=ranges,
            angle_min=spec.angle_min,
            angle_increment=spec.angular_resolution,
            range_min=spec.range_min,
            range_max=spec.range_max,
            intensities=intensities,
            stamp=stamp,
            pose=(values[0], values[1], wrap_angle(values[3])),
        )
