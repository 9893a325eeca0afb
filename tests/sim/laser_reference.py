"""``RaycastLaser.cast`` and ``scan`` as first written: the reference for the leaner ones.

The laser's own Python around ``rayTestBatch`` now works in place on floats and clips with
``maximum``/``minimum``; ``ReferenceLaser`` keeps the original array code (``numpy.clip``,
``numpy.where`` for the intensities, the ``engine_timer`` context manager). Tests require
both to return the same scans bit for bit from the same random stream;
``benchmarks/test_bench_navigation.py`` times both.
"""

from __future__ import annotations

import time

import numpy as np

from semistatic.frames import wrap_angle
from semistatic.types import Scan
from sim.laser import _HIT_BODY, _HIT_FRACTION, LASER_RAY_MASK, RaycastLaser


class ReferenceLaser(RaycastLaser):
    """A ``RaycastLaser`` running the original ``cast`` and ``scan``."""

    def cast(self, sensor_pose_xyz_yaw):
        """Cast every beam once: the original code."""
        x, y, z, yaw = (float(v) for v in np.asarray(sensor_pose_xyz_yaw, dtype=float))
        cos_yaw, sin_yaw = np.cos(yaw), np.sin(yaw)
        dir_x = cos_yaw * self._cos - sin_yaw * self._sin
        dir_y = sin_yaw * self._cos + cos_yaw * self._sin
        length = self.spec.range_max
        self._from[:] = (x, y, z)
        self._to[:, 0] = x + length * dir_x
        self._to[:, 1] = y + length * dir_y
        self._to[:, 2] = z
        start = time.perf_counter()
        with self.sim.engine_timer():
            results = self._ray_test_batch(
                self._from,
                self._to,
                numThreads=self.num_threads,
                collisionFilterMask=LASER_RAY_MASK,
            )
        self.last_raycast_s = time.perf_counter() - start
        count = len(results)
        body_ids = np.fromiter(map(_HIT_BODY, results), dtype=np.int64, count=count)
        fractions = np.fromiter(map(_HIT_FRACTION, results), dtype=float, count=count)
        ranges = np.where(body_ids >= 0, fractions * length, np.inf)
        return ranges, body_ids

    def scan(self, sensor_pose_xyz_yaw, stamp=0.0):
        """Take one scan: the original code."""
        pose = np.asarray(sensor_pose_xyz_yaw, dtype=float)
        true_ranges, body_ids = self.cast(pose)
        hit = body_ids >= 0
        remission = self.world.remission_of(body_ids)
        spec = self.spec
        if self.noise_free:
            ranges, intensities = true_ranges, remission
        else:
            count = spec.num_beams
            range_noise = self.rng.normal(0.0, spec.range_sigma, count)
            intensity_noise = self.rng.normal(0.0, spec.intensity_sigma, count)
            dropped = self.rng.random(count) < spec.dropout_prob
            measured = np.clip(true_ranges + self.bias + range_noise, 0.0, spec.range_max)
            hit = hit & ~dropped
            ranges = np.where(hit, measured, np.inf)
            intensities = np.where(hit, np.maximum(remission + intensity_noise, 0.0), 0.0)
        return Scan(
            ranges=ranges,
            angle_min=spec.angle_min,
            angle_increment=spec.angular_resolution,
            range_min=spec.range_min,
            range_max=spec.range_max,
            intensities=intensities,
            stamp=stamp,
            pose=(pose[0], pose[1], wrap_angle(pose[3])),
        )
