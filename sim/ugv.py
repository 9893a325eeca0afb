"""The UGV as a PyBullet multibody driven by its two wheel motors.

``SimUGV`` loads the URDF of a ``UGVSpec`` into a ``SimClient`` and moves only through
physics: the two wheel joints run under PyBullet's ``VELOCITY_CONTROL`` with the motor
torque limit as maximum force, the tyres grip the floor by Coulomb friction and the
ball casters slide without friction. Nothing sets the body's pose while driving;
``reset`` teleports the robot between laps, as an operator would carry it back.

Poses are those of ``base_link`` (on the floor, below the drive-axle midpoint), not of
the body's centre of mass that PyBullet reports: the conversion uses the inertial frame
offset PyBullet read from the URDF.

Examples
--------
>>> from robots.presets import PIONEER3DX
>>> from sim.client import SimClient
>>> with SimClient() as sim:
...     floor = add_floor(sim)
...     robot = SimUGV(sim, PIONEER3DX, pose=(1.0, 2.0, 0.5))
...     _ = robot.command(0.5, 0.0)
...     sim.step(240)
...     robot.true_pose().round(1)
array([1.4, 2.2, 0.5])
"""

from __future__ import annotations

import math
import tempfile
import time

import numpy as np
from numpy.typing import ArrayLike

from robots.presets import LaserMount, UGVSpec
from robots.urdf import CASTER_LATERAL_FRICTION, WHEEL_LATERAL_FRICTION, write_urdf
from semistatic.frames import wrap_angle
from sim.client import SimClient

__all__ = ["FLOOR_LATERAL_FRICTION", "SimUGV", "add_floor"]

FLOOR_LATERAL_FRICTION = 1.0
"""Friction of the floor; PyBullet multiplies it with the tyre's, so 1 keeps the tyre's."""

# Drop height when spawning or teleporting: the wheels start just above the floor
# instead of inside it, so the contact solver does not kick the robot up.
_SPAWN_DROP = 1e-3


def add_floor(sim: SimClient, lateral_friction: float = FLOOR_LATERAL_FRICTION) -> int:
    """Create an infinite static floor plane at z = 0 and return its body id.

    The world builder makes its own floor; this one is for tests and bare drives.

    Examples
    --------
    >>> from sim.client import SimClient
    >>> with SimClient() as sim:
    ...     add_floor(sim) >= 0
    True
    """
    bullet = sim.bullet
    shape = bullet.createCollisionShape(bullet.GEOM_PLANE)
    floor = bullet.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape)
    bullet.changeDynamics(
        floor, -1, lateralFriction=lateral_friction, rollingFriction=0.0, spinningFriction=0.0
    )
    return int(floor)


def _rotation(quaternion) -> np.ndarray:
    """3x3 rotation matrix of a PyBullet ``(x, y, z, w)`` quaternion."""
    x, y, z, w = quaternion
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


class SimUGV:
    """A differential-drive UGV simulated by PyBullet.

    Parameters
    ----------
    sim
        The simulation to load the robot into.
    spec
        The vehicle description (``robots.presets``).
    pose
        Initial ``(x, y, theta)`` of ``base_link`` in the world.

    Attributes
    ----------
    body_id
        PyBullet body unique id of the robot.
    spec
        The vehicle description.

    Examples
    --------
    >>> from robots.presets import PIONEER3DX
    >>> from sim.client import SimClient
    >>> with SimClient() as sim:
    ...     _ = add_floor(sim)
    ...     robot = SimUGV(sim, PIONEER3DX)
    ...     _ = robot.command(0.0, 1.0)  # turn left on the spot
    ...     sim.step(240)
    ...     round(float(robot.true_twist()[2]), 2)
    1.0
    """

    def __init__(self, sim: SimClient, spec: UGVSpec, pose: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        self.sim = sim
        self.spec = spec
        bullet = sim.bullet
        self._bullet = bullet
        start = self._checked_pose(pose)
        with tempfile.TemporaryDirectory(prefix="semistatic-urdf-") as tmp:
            path = write_urdf(spec, tmp)
            # Inertias from the URDF (the flag), not recomputed from collision shapes.
            self.body_id = int(
                bullet.loadURDF(
                    str(path),
                    basePosition=(start[0], start[1], _SPAWN_DROP),
                    baseOrientation=bullet.getQuaternionFromEuler((0.0, 0.0, start[2])),
                    flags=bullet.URDF_USE_INERTIA_FROM_FILE | bullet.URDF_USE_IMPLICIT_CYLINDER,
                )
            )
        joints = {}
        links = {}
        for index in range(bullet.getNumJoints(self.body_id)):
            info = bullet.getJointInfo(self.body_id, index)
            joints[info[1].decode()] = index
            links[info[12].decode()] = index
        self.link_indices: dict[str, int] = links
        self.wheel_joints = (joints["left_wheel_joint"], joints["right_wheel_joint"])
        # PyBullet tracks the base by its centre of mass; keep the offset to base_link.
        dynamics = bullet.getDynamicsInfo(self.body_id, -1)
        self._com_in_base = np.asarray(dynamics[3], dtype=float)
        self._configure_dynamics()
        # Bound once (BulletClient builds a new partial on every attribute access) with the
        # constant arguments of the per-tick calls: these run at the control rate.
        self._base_position_and_orientation = bullet.getBasePositionAndOrientation
        self._joint_states = bullet.getJointStates
        self._motor_control_array = bullet.setJointMotorControlArray
        self._velocity_control = bullet.VELOCITY_CONTROL
        self._wheel_joint_list = list(self.wheel_joints)
        self._wheel_forces = [spec.max_wheel_torque, spec.max_wheel_torque]
        self._half_track = 0.5 * spec.wheel_separation
        self._wheel_targets = np.zeros(2)
        self.set_wheel_speeds(0.0, 0.0)

    @staticmethod
    def _checked_pose(pose: ArrayLike) -> np.ndarray:
        pose = np.asarray(pose, dtype=float).reshape(-1)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            raise ValueError(f"SimUGV: pose must be a finite (x, y, theta), got {pose.tolist()}")
        return pose

    def _configure_dynamics(self) -> None:
        bullet, body = self._bullet, self.body_id
        # No artificial drag: PyBullet's default damping (0.04) would act as a hidden
        # brake; the motors and contacts alone decide how the robot moves.
        bullet.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0)
        for joint in self.wheel_joints:
            bullet.changeDynamics(
                body,
                joint,
                lateralFriction=WHEEL_LATERAL_FRICTION,
                rollingFriction=0.0,
                spinningFriction=0.0,
                linearDamping=0.0,
                angularDamping=0.0,
                jointDamping=0.0,
            )
        for name, link in self.link_indices.items():
            if name.startswith("caster_"):
                bullet.changeDynamics(
                    body,
                    link,
                    lateralFriction=CASTER_LATERAL_FRICTION,
                    rollingFriction=0.0,
                    spinningFriction=0.0,
                )

    @property
    def wheel_targets(self) -> np.ndarray:
        """Return the wheel speed targets ``(left, right)`` last sent to the motors, rad/s."""
        return self._wheel_targets.copy()

    def set_wheel_speeds(self, left: float, right: float) -> np.ndarray:
        """Command the wheel motors' target speeds in rad/s; return what was applied.

        Each target is clipped to ``spec.max_wheel_speed``; the motors reach it only as
        fast as ``spec.max_wheel_torque`` and the tyres' grip allow.

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     SimUGV(sim, PIONEER3DX).set_wheel_speeds(100.0, -1.0).round(2)
        array([12.31, -1.  ])
        """
        limit = self.spec.max_wheel_speed
        # min/max on floats clip exactly like numpy.clip (an infinite speed becomes the
        # limit, nan stays nan and is refused), at a fraction of the cost.
        targets = [min(max(float(left), -limit), limit), min(max(float(right), -limit), limit)]
        if not (math.isfinite(targets[0]) and math.isfinite(targets[1])):
            raise ValueError(f"SimUGV.set_wheel_speeds: speeds must be finite, got {left}, {right}")
        self._wheel_targets = np.array(targets)
        start = time.perf_counter()
        self._motor_control_array(
            self.body_id,
            self._wheel_joint_list,
            self._velocity_control,
            targetVelocities=targets,
            forces=self._wheel_forces,
        )
        self.sim.engine_time_s += time.perf_counter() - start
        return np.array(targets)

    def command(self, v: float, omega: float) -> np.ndarray:
        """Drive with forward speed ``v`` (m/s) and yaw rate ``omega`` (rad/s).

        When a wheel would exceed its speed limit both wheel speeds are scaled down by
        the same factor, which keeps the commanded curvature (the path) and slows down
        along it. Returns the wheel speed targets applied, rad/s.

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     robot = SimUGV(sim, PIONEER3DX)
        ...     left, right = robot.command(5.0, 5.0)  # far beyond the limits
        ...     round(float(right), 2), round(float(left / right), 4)
        (12.31, 0.7167)
        """
        # UGVSpec.wheel_speeds on floats: the same IEEE operations without numpy's overhead.
        v, omega = float(v), float(omega)
        radius = self.spec.wheel_radius
        left = (v - omega * self._half_track) / radius
        right = (v + omega * self._half_track) / radius
        if not (math.isfinite(left) and math.isfinite(right)):
            raise ValueError(f"SimUGV.command: v and omega must be finite, got {v}, {omega}")
        peak = max(abs(left), abs(right))
        limit = self.spec.max_wheel_speed
        if peak > limit:
            factor = limit / peak
            left, right = left * factor, right * factor
        return self.set_wheel_speeds(left, right)

    def stop(self) -> None:
        """Command zero wheel speed (the motors brake with their torque limit).

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     robot = SimUGV(sim, PIONEER3DX)
        ...     _ = robot.command(0.5, 0.0)
        ...     robot.stop()
        ...     robot.wheel_targets
        array([0., 0.])
        """
        self.set_wheel_speeds(0.0, 0.0)

    def _base_state(self) -> tuple[np.ndarray, np.ndarray]:
        """World position of ``base_link`` and the base rotation matrix."""
        # Engine time, inline (the engine_timer context manager costs more than the call).
        start = time.perf_counter()
        com, quaternion = self._base_position_and_orientation(self.body_id)
        self.sim.engine_time_s += time.perf_counter() - start
        rotation = _rotation(quaternion)
        # numpy's (BLAS) matrix-vector product, not a Python sum: they round differently.
        return np.array(com) - rotation @ self._com_in_base, rotation

    def true_pose(self) -> np.ndarray:
        """Return the ground-truth ``(x, y, theta)`` of ``base_link`` in the world.

        Examples
        --------
        >>> from robots.presets import LGV
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     SimUGV(sim, LGV, pose=(3.0, -1.0, np.pi)).true_pose().round(6).tolist()
        [3.0, -1.0, 3.141593]
        """
        position, rotation = self._base_state()
        theta = float(np.arctan2(rotation[1, 0], rotation[0, 0]))  # numpy's atan2 (not math's)
        x, y, _ = position.tolist()
        return np.array([x, y, wrap_angle(theta)])

    def true_twist(self) -> np.ndarray:
        """Return the ground-truth twist ``(v_forward, v_left, omega)`` of ``base_link``.

        Velocities in m/s along the robot's own x and y axes, yaw rate in rad/s.

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     _ = add_floor(sim)
        ...     robot = SimUGV(sim, PIONEER3DX, pose=(0.0, 0.0, 1.0))
        ...     _ = robot.command(0.4, 0.0)
        ...     sim.step(240)
        ...     v_forward, v_left, omega = robot.true_twist()  # robot frame, any heading
        ...     round(float(v_forward), 3), abs(round(float(v_left), 3))
        (0.4, 0.0)
        """
        position, rotation = self._base_state()
        com = position + rotation @ self._com_in_base
        linear, angular = self._bullet.getBaseVelocity(self.body_id)
        linear = np.asarray(linear, dtype=float)
        angular = np.asarray(angular, dtype=float)
        # Rigid body: the base_link origin moves with v_com + w x (p_base - p_com).
        velocity = linear + np.cross(angular, position - com)
        forward, left = rotation[:2, 0], rotation[:2, 1]
        return np.array([velocity[:2] @ forward, velocity[:2] @ left, angular[2]])

    def wheel_angles(self) -> np.ndarray:
        """Return the wheel joint angles ``(left, right)`` in radians (not wrapped).

        Positive rotation drives the robot forward; the angles accumulate over turns,
        which is what an incremental encoder counts.

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     _ = add_floor(sim)
        ...     robot = SimUGV(sim, PIONEER3DX)
        ...     _ = robot.set_wheel_speeds(2.0, 2.0)
        ...     sim.step(240)
        ...     robot.wheel_angles().round(1)  # about 2 rad/s for 1 s, less the start-up
        array([1.9, 1.9])
        """
        start = time.perf_counter()
        (left, *_), (right, *_) = self._joint_states(self.body_id, self._wheel_joint_list)
        self.sim.engine_time_s += time.perf_counter() - start
        return np.array([left, right])

    def wheel_velocities(self) -> np.ndarray:
        """Return the wheel joint speeds ``(left, right)`` in rad/s.

        Examples
        --------
        >>> from robots.presets import LGV
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     _ = add_floor(sim)
        ...     robot = SimUGV(sim, LGV)
        ...     _ = robot.set_wheel_speeds(-1.0, 1.0)
        ...     sim.step(240)
        ...     robot.wheel_velocities().round(3)
        array([-1.,  1.])
        """
        states = self._bullet.getJointStates(self.body_id, list(self.wheel_joints))
        return np.array([states[0][1], states[1][1]], dtype=float)

    def sensor_pose(self, mount: LaserMount) -> np.ndarray:
        """Return the world pose ``(x, y, z, yaw)`` of a laser mounted at ``mount``.

        The position follows the body's full 3D attitude (a pitching body moves the
        scanner); the yaw is the robot's heading plus the mount's yaw.

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     _ = add_floor(sim)
        ...     robot = SimUGV(sim, PIONEER3DX, pose=(1.0, 0.0, np.pi / 2))
        ...     sim.step(48)
        ...     robot.sensor_pose(PIONEER3DX.safety_laser).round(2)
        array([1.  , 0.12, 0.35, 1.57])
        """
        position, rotation = self._base_state()
        world = position + rotation @ np.array([mount.x, mount.y, mount.z])
        yaw = float(np.arctan2(rotation[1, 0], rotation[0, 0])) + mount.yaw
        return np.array([*world.tolist(), wrap_angle(yaw)])

    def reset(self, pose: ArrayLike) -> None:
        """Teleport ``base_link`` to ``pose`` = ``(x, y, theta)`` at rest, motors stopped.

        Used between laps. Wheel angles are kept (encoders do not jump), all velocities
        are zeroed and the wheel targets set to 0.

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> from sim.client import SimClient
        >>> with SimClient() as sim:
        ...     _ = add_floor(sim)
        ...     robot = SimUGV(sim, PIONEER3DX)
        ...     _ = robot.command(1.0, 0.5)
        ...     sim.step(240)
        ...     robot.reset((0.0, 0.0, 0.0))
        ...     sim.step(24)
        ...     bool(np.allclose(robot.true_pose(), 0, atol=1e-3)), robot.wheel_targets
        (True, array([0., 0.]))
        """
        pose = self._checked_pose(pose)
        bullet = self._bullet
        quaternion = bullet.getQuaternionFromEuler((0.0, 0.0, pose[2]))
        base = np.array([pose[0], pose[1], _SPAWN_DROP])
        com = base + _rotation(quaternion) @ self._com_in_base
        bullet.resetBasePositionAndOrientation(self.body_id, com.tolist(), quaternion)
        bullet.resetBaseVelocity(self.body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
        for joint, angle in zip(self.wheel_joints, self.wheel_angles(), strict=True):
            bullet.resetJointState(self.body_id, joint, float(angle), targetVelocity=0.0)
        self.stop()
