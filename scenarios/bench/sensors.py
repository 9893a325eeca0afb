"""A vehicle's sensors: wheel encoders and its localization and safety lasers.

Each noisy sensor draws from its own random stream, spawned from the scenario seed by
name (:mod:`sim.random_streams`); a fleet vehicle's names carry its index, the first
vehicle keeps a single robot's names, so adding vehicles never changes its noise. The
scenario's ``noise`` factors scale the encoders' slip and the lasers' range noise. A
robot whose two roles share one laser (the Pioneer's LMS100) scans once for both.

Examples
--------
>>> stream_prefix(0), stream_prefix(2)
('', 'vehicles/2/')
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from robots.landmarks import LandmarkObservation, detect_landmarks
from robots.presets import UGVSpec
from scenarios.bench.scene import Scene
from scenarios.spec.starts import landmark_noise
from semistatic.types import Scan
from sim.encoders import WheelEncoders
from sim.laser import RaycastLaser, vehicle_laser_group
from sim.ugv import SimUGV

__all__ = ["VehicleSensors", "stream_prefix"]


def stream_prefix(index: int) -> str:
    """Return the random-stream name prefix of fleet vehicle ``index``."""
    return "" if index == 0 else f"vehicles/{index}/"


class VehicleSensors:
    """The encoders and lasers on one vehicle's body.

    Parameters
    ----------
    scene
        The bench's shared state (physics client, world, random streams, noise factors).
    index
        The vehicle's place in the fleet (its streams and laser group).
    robot
        The vehicle's description (lasers, mounts, encoder slip).
    body
        The simulated body the sensors ride on (its own rays are ignored).
    raycast_timer
        Called with each scan's ray-cast time (s).
    """

    def __init__(self, scene: Scene, index: int, robot: UGVSpec, body: SimUGV,
                 raycast_timer: Callable[[float], None]) -> None:
        noise, streams, prefix = scene.spec.noise, scene.streams, stream_prefix(index)
        self.body = body
        self._raycast_timer = raycast_timer
        self._sim = scene.sim
        self.encoders = WheelEncoders(
            robot.replace(encoder_slip_sigma=robot.encoder_slip_sigma * noise.odometry),
            streams.generator(prefix + "encoders"))
        group = vehicle_laser_group(index)

        def laser(mount, name: str) -> RaycastLaser:
            noisy = dataclasses.replace(mount.laser,
                                        range_sigma=mount.laser.range_sigma * noise.range)
            return RaycastLaser(scene.sim, noisy, scene.world, streams.generator(prefix + name),
                                ignore_body_ids=(body.body_id,), ignore_group=group)

        self.localization_mount = robot.localization_laser
        self.safety_mount = robot.safety_laser
        self.localization_laser = laser(robot.localization_laser, "laser/localization")
        self.shared_laser = robot.safety_laser is robot.localization_laser
        self.safety_laser = (self.localization_laser if self.shared_laser
                             else laser(robot.safety_laser, "laser/safety"))
        # The safety mount's (x, y, yaw), read at every safety scan: built once, read-only.
        self.safety_mount_pose = robot.safety_laser.pose2d()
        self.safety_mount_pose.flags.writeable = False
        posts = scene.world.posts
        self.post_radius = posts[0].radius if posts else 0.04

    def localization_scan(self) -> Scan:
        """Return a scan of the localization laser now."""
        return self._scan(self.localization_laser, self.localization_mount)

    def safety_scan(self, localization_scan: Scan | None) -> Scan:
        """Return a scan of the safety laser now (the localization scan if they share one)."""
        if self.shared_laser and localization_scan is not None:
            return localization_scan
        return self._scan(self.safety_laser, self.safety_mount)

    def landmarks(self, scan: Scan) -> list[LandmarkObservation]:
        """Return the reflective-post landmarks of a localization scan."""
        range_sigma, bearing_sigma = landmark_noise(self.localization_mount.laser)
        return detect_landmarks(scan, post_radius=self.post_radius, range_sigma=range_sigma,
                                bearing_sigma=bearing_sigma)

    def odometry(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the odometry increment since the last read and its covariance."""
        return self.encoders.read(self.body.wheel_angles())

    def _scan(self, laser: RaycastLaser, mount) -> Scan:
        scan = laser.scan(self.body.sensor_pose(mount), stamp=self._sim.sim_time)
        self._raycast_timer(laser.last_raycast_s)
        return scan
