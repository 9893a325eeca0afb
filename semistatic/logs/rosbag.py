"""Read laser scans from ROS 1 / ROS 2 bags and write mapper runs as ROS 2 bags.

Both directions use the pure-Python ``rosbags`` library, so no ROS installation is needed.

Reading (:func:`read_bag`)
    ``sensor_msgs/LaserScan`` messages become :class:`~semistatic.types.Scan` objects.
    The pose of each scan comes from a ``nav_msgs/Odometry`` topic, matched in time:
    the odometry poses are linearly interpolated at the scan's header stamp (the heading
    along the shorter arc). A scan before the first or after the last odometry message
    takes the nearest pose; a scan whose nearest odometry message is more than
    ``max_pose_gap`` seconds away is skipped (counted in :class:`BagStats`). The
    odometry pose is the pose of its ``child_frame_id`` (the robot base); when
    ``/tf_static`` links that frame to the scan's ``frame_id`` the mounting offset is
    composed in, otherwise the laser is taken to sit at the base origin (with a warning).
    Header stamps of zero fall back to the bag's receive time.

Writing (:func:`write_ros2_bag`)
    One :class:`BagFrame` per scan: the scan on ``/scan`` (frame ``laser``), the
    odometry and the EKF poses as ``nav_msgs/Odometry`` on ``/odom`` and ``/ekf/odom``
    (frame ``map``, child ``base_link``; the EKF covariance, when given, fills the x,
    y and yaw entries), the transform tree ``map -> base_link`` on ``/tf`` from the EKF
    pose (the pose the mapper works with) and ``base_link -> laser`` once on
    ``/tf_static`` (transient-local) from ``laser_offset``, and the polylines as
    ``visualization_msgs/MarkerArray`` LINE_STRIP markers on ``/semistatic/polylines``
    (a DELETEALL first, so each message replaces the previous map). RViz 2 (fixed frame
    ``map``) and Foxglove open the result. The scan's own ``pose`` is not stored: reading
    the bag back with ``odom_topic=EKF_TOPIC`` gives ``compose(ekf_pose, laser_offset)``.

Examples
--------
>>> import tempfile, pathlib
>>> folder = tempfile.TemporaryDirectory()
>>> scan = Scan(ranges=[1.0, 2.0, 1.5], angle_min=-0.5, angle_increment=0.5,
...             range_max=10.0, stamp=1.0, pose=(1.0, 0.0, 0.0))
>>> frame = BagFrame(scan=scan, odom_pose=(1.0, 0.0, 0.0), ekf_pose=(1.0, 0.0, 0.0),
...                  polylines=[np.array([[0.0, 1.0], [2.0, 1.0]])])
>>> bag = write_ros2_bag(pathlib.Path(folder.name) / "run", [frame])
>>> [s.ranges for s in read_bag(bag, odom_topic=EKF_TOPIC)]
[array([1. , 2. , 1.5])]
>>> folder.cleanup()
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import warnings
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from semistatic.frames import compose, wrap_angle
from semistatic.types import Scan

__all__ = [
    "EKF_TOPIC",
    "MARKER_TOPIC",
    "ODOM_TOPIC",
    "SCAN_TOPIC",
    "TF_TOPIC",
    "BagError",
    "BagFrame",
    "BagStats",
    "read_bag",
    "write_ros2_bag",
]

SCAN_TOPIC = "/scan"
ODOM_TOPIC = "/odom"
EKF_TOPIC = "/ekf/odom"
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
MARKER_TOPIC = "/semistatic/polylines"
MAP_FRAME = "map"
BASE_FRAME = "base_link"
LASER_FRAME = "laser"

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"

# A scan further than this (s) from any odometry message gets no pose and is skipped:
# a few odometry periods at the usual 10-50 Hz.
DEFAULT_MAX_POSE_GAP = 0.25
NANOSECONDS = 1_000_000_000
# LINE_STRIP width in metres and colour (RGBA): thin orange lines read well over scans.
MARKER_LINE_WIDTH = 0.03
MARKER_COLOR = (1.0, 0.55, 0.0, 1.0)
# Odometry covariance is 6x6 over (x, y, z, roll, pitch, yaw); the planar entries.
PLANAR_COVARIANCE_INDICES = (0, 1, 5)
STORAGES = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
LATCHED = Qos(
    QosHistory.KEEP_LAST,
    1,
    QosReliability.RELIABLE,
    QosDurability.TRANSIENT_LOCAL,
    QosTime(0, 0),
    QosTime(0, 0),
    QosLiveliness.AUTOMATIC,
    QosTime(0, 0),
    False,
)
# The frame tree walk gives up after this many static hops (guards against cycles).
MAX_TF_HOPS = 16


class BagError(ValueError):
    """Raise when a bag cannot be read as scans; the message names the bag and the topic.

    Examples
    --------
    >>> isinstance(BagError("run.bag: no sensor_msgs/LaserScan topic"), ValueError)
    True
    """


@dataclass
class BagStats:
    """Count what :func:`read_bag` yielded and skipped; filled in while streaming.

    Attributes
    ----------
    scans
        Scans yielded.
    without_pose
        Scans skipped because no odometry message was within ``max_pose_gap``.

    Examples
    --------
    >>> BagStats()
    BagStats(scans=0, without_pose=0)
    """

    scans: int = 0
    without_pose: int = 0


@dataclass(frozen=True, eq=False)
class BagFrame:
    """One scan of a mapper run, with what RViz or Foxglove should show beside it.

    Parameters
    ----------
    scan
        The laser scan; its ``stamp`` (s, >= 0) stamps every message of the frame.
        It is shown at the EKF pose composed with the writer's ``laser_offset``.
    odom_pose, ekf_pose
        ``(x, y, theta)`` of the robot from wheel odometry and from the EKF, map frame.
    polylines
        Map polylines in the world frame, each an ``(N, 2)`` array with ``N >= 2``.
    ekf_covariance
        Optional ``(3, 3)`` covariance of the EKF pose over ``(x, y, theta)``.

    Examples
    --------
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1)
    >>> frame = BagFrame(scan=scan, odom_pose=(0, 0, 0), ekf_pose=(0, 0, 0),
    ...                  polylines=[[[0, 0], [1, 0]]])
    >>> frame.polylines[0].shape
    (2, 2)
    """

    scan: Scan
    odom_pose: np.ndarray
    ekf_pose: np.ndarray
    polylines: Sequence[np.ndarray] = field(default_factory=tuple)
    ekf_covariance: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.scan, Scan):
            raise TypeError(f"BagFrame.scan must be a Scan, got {type(self.scan).__name__}")
        if not (math.isfinite(self.scan.stamp) and self.scan.stamp >= 0):
            raise ValueError(
                f"BagFrame.scan.stamp must be a finite time >= 0 s (got {self.scan.stamp}): "
                "bag timestamps are unsigned nanoseconds"
            )
        for name in ("odom_pose", "ekf_pose"):
            pose = np.array(getattr(self, name), dtype=np.float64).reshape(-1)
            if pose.shape != (3,) or not np.isfinite(pose).all():
                raise ValueError(f"BagFrame.{name} must be a finite (x, y, theta), got {pose}")
            object.__setattr__(self, name, pose)
        polylines = []
        for index, line in enumerate(self.polylines):
            points = np.array(line, dtype=np.float64)
            if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
                raise ValueError(
                    f"BagFrame.polylines[{index}] must be an (N, 2) array with N >= 2, "
                    f"got shape {points.shape}"
                )
            polylines.append(points)
        object.__setattr__(self, "polylines", tuple(polylines))
        if self.ekf_covariance is not None:
            covariance = np.array(self.ekf_covariance, dtype=np.float64)
            if covariance.shape != (3, 3):
                raise ValueError(
                    f"BagFrame.ekf_covariance must be (3, 3) over (x, y, theta), "
                    f"got shape {covariance.shape}"
                )
            object.__setattr__(self, "ekf_covariance", covariance)


def write_ros2_bag(
    path: str | os.PathLike[str],
    frames: Iterable[BagFrame],
    *,
    laser_offset: ArrayLike = (0.0, 0.0, 0.0),
    storage: Literal["sqlite3", "mcap"] = "sqlite3",
) -> Path:
    """Write mapper frames to a new ROS 2 bag directory, atomically.

    The bag is written into a temporary directory beside ``path`` and renamed into
    place when complete, so ``path`` either does not exist or holds a whole bag.

    Parameters
    ----------
    path
        The bag directory to create; it must not exist.
    frames
        :class:`BagFrame` objects in time order (any iterable; streamed).
    laser_offset
        ``(x, y, theta)`` of the laser in the robot base frame (``/tf_static``).
    storage
        ``"sqlite3"`` (``.db3``, the ROS 2 Humble default) or ``"mcap"``.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = tempfile.TemporaryDirectory()
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=2.5)
    >>> frame = BagFrame(scan=scan, odom_pose=(0, 0, 0), ekf_pose=(0, 0, 0))
    >>> bag = write_ros2_bag(pathlib.Path(folder.name) / "run", [frame])
    >>> sorted(p.name for p in bag.iterdir())
    ['metadata.yaml', 'run.db3']
    >>> folder.cleanup()
    """
    path = Path(path)
    if storage not in STORAGES:
        raise ValueError(
            f"write_ros2_bag: storage must be one of {sorted(STORAGES)}, got {storage!r}"
        )
    if path.exists():
        raise FileExistsError(f"{path}: exists already; choose a new bag path or remove it")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"{path.parent}: no such directory for the bag")
    offset = np.array(laser_offset, dtype=np.float64).reshape(-1)
    if offset.shape != (3,) or not np.isfinite(offset).all():
        raise ValueError(
            f"write_ros2_bag: laser_offset must be a finite (x, y, theta), got {offset}"
        )
    staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    try:
        # The storage file is named after the bag directory, so stage under the final name.
        staged = staging / path.name
        _write_frames(staged, frames, offset, STORAGES[storage])
        staged.rename(path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return path


def read_bag(
    path: str | os.PathLike[str],
    *,
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    max_pose_gap: float = DEFAULT_MAX_POSE_GAP,
    stats: BagStats | None = None,
) -> Iterator[Scan]:
    """Yield the laser scans of a ROS 1 or ROS 2 bag with poses from odometry.

    Parameters
    ----------
    path
        A ROS 1 ``.bag`` file or a ROS 2 bag directory (sqlite3 or mcap).
    scan_topic
        The ``sensor_msgs/LaserScan`` topic; None: the bag's only one.
    odom_topic
        The ``nav_msgs/Odometry`` topic giving the pose; None: ``/odom`` when present,
        else the bag's only one.
    max_pose_gap
        Skip scans whose nearest odometry message is further away than this (s).
    stats
        Optional :class:`BagStats` updated as the scans stream out.

    Yields
    ------
    Scan
        Ranges (float32 in the bag, as float64), angles (beams reordered to be
        counter-clockwise when the bag's increment is negative), ``range_min`` and
        ``range_max``, intensities when present, the header stamp (s) and the laser pose
        in the odometry frame (see the module docstring for the time matching).

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    BagError
        At the call when a topic is missing or ambiguous; while iterating when a
        message is not a valid scan.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = tempfile.TemporaryDirectory()
    >>> scans = [Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.25, stamp=t,
    ...               pose=(t, 0.0, 0.0)) for t in (1.0, 2.0)]
    >>> frames = [BagFrame(scan=s, odom_pose=s.pose, ekf_pose=s.pose) for s in scans]
    >>> bag = write_ros2_bag(pathlib.Path(folder.name) / "run", frames)
    >>> [s.pose.tolist() for s in read_bag(bag)]
    [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
    >>> folder.cleanup()
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such bag (a ROS 1 .bag file or a ROS 2 directory)")
    if not max_pose_gap >= 0:
        raise ValueError(f"read_bag: max_pose_gap must be >= 0 s, got {max_pose_gap}")
    with _open_reader(path) as reader:
        scan_topic = _pick_topic(path, reader, LASER_SCAN, scan_topic, None, "scan_topic")
        odom_topic = _pick_topic(path, reader, ODOMETRY, odom_topic, ODOM_TOPIC, "odom_topic")
        trajectory = _read_trajectory(path, reader, odom_topic)
        scan_frame = _first_frame_id(reader, scan_topic)
        offset = _static_offset(reader, trajectory.child_frame, scan_frame)
    if offset is None:
        warnings.warn(
            f"{path}: /tf_static does not link {trajectory.child_frame!r} (from {odom_topic}) "
            f"to the laser frame {scan_frame!r}; taking the laser at the base origin",
            UserWarning,
            stacklevel=2,
        )
        offset = np.zeros(3)
    stats = BagStats() if stats is None else stats
    return _scan_stream(path, scan_topic, trajectory, offset, max_pose_gap, stats)


# ----------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class _Trajectory:
    stamps: np.ndarray  # (M,) seconds, sorted
    poses: np.ndarray  # (M, 3), heading unwrapped for interpolation
    child_frame: str

    def pose_at(self, stamp: float, max_gap: float) -> np.ndarray | None:
        stamps = self.stamps
        after = int(np.searchsorted(stamps, stamp))
        nearest = min(
            (abs(stamps[i] - stamp) for i in (after - 1, after) if 0 <= i < len(stamps)),
            default=math.inf,
        )
        if nearest > max_gap:
            return None
        pose = np.array([np.interp(stamp, stamps, self.poses[:, k]) for k in range(3)])
        pose[2] = wrap_angle(pose[2])
        return pose


@contextmanager
def _open_reader(path: Path) -> Iterator[AnyReader]:
    try:
        # Bags without embedded definitions (old ROS 2 sqlite3) need a default type store.
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError) as error:
        # rosbags' YAML errors span several lines; one line reads better in a terminal.
        reason = " ".join(str(error).split())
        raise BagError(f"{path}: cannot open as a ROS bag ({reason})") from error
    try:
        yield reader
    finally:
        reader.close()


def _pick_topic(
    path: Path,
    reader: AnyReader,
    msgtype: str,
    wanted: str | None,
    preferred: str | None,
    argument: str,
) -> str:
    topics = sorted(name for name, info in reader.topics.items() if info.msgtype == msgtype)
    kind = msgtype.replace("/msg/", "/")
    if wanted is not None:
        if wanted not in topics:
            raise BagError(
                f"{path}: {argument}={wanted!r} is not a {kind} topic of this bag; "
                f"its {kind} topics: {topics or 'none'}"
            )
        return wanted
    if preferred in topics:
        return preferred
    if len(topics) == 1:
        return topics[0]
    if not topics:
        raise BagError(f"{path}: no {kind} topic in this bag (topics: {sorted(reader.topics)})")
    raise BagError(f"{path}: several {kind} topics {topics}; pass {argument}=one of them")


def _stamp_seconds(header: Any, bag_time_ns: int) -> float:
    stamp = header.stamp
    if stamp.sec == 0 and stamp.nanosec == 0:
        return bag_time_ns / NANOSECONDS
    return stamp.sec + stamp.nanosec / NANOSECONDS


def _yaw(quaternion: Any) -> float:
    q = quaternion
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _frame_name(frame_id: str) -> str:
    return frame_id.lstrip("/")  # ROS 1 bags often write "/base_link"


def _read_trajectory(path: Path, reader: AnyReader, topic: str) -> _Trajectory:
    connections = [c for c in reader.connections if c.topic == topic]
    stamps, poses, child = [], [], ""
    for connection, bag_time, raw in reader.messages(connections=connections):
        message = reader.deserialize(raw, connection.msgtype)
        pose = message.pose.pose
        stamps.append(_stamp_seconds(message.header, bag_time))
        poses.append((pose.position.x, pose.position.y, _yaw(pose.orientation)))
        child = child or _frame_name(message.child_frame_id)
    if not stamps:
        raise BagError(f"{path}: odometry topic {topic} has no messages")
    order = np.argsort(stamps, kind="stable")
    poses_array = np.array(poses, dtype=np.float64)[order]
    # Unwrapped so that interpolating between 179 deg and -179 deg passes through 180.
    poses_array[:, 2] = np.unwrap(poses_array[:, 2])
    return _Trajectory(np.array(stamps, dtype=np.float64)[order], poses_array, child)


def _first_frame_id(reader: AnyReader, topic: str) -> str:
    connections = [c for c in reader.connections if c.topic == topic]
    for connection, _, raw in reader.messages(connections=connections):
        return _frame_name(reader.deserialize(raw, connection.msgtype).header.frame_id)
    return ""


def _static_offset(reader: AnyReader, base_frame: str, laser_frame: str) -> np.ndarray | None:
    """Return the laser pose in the base frame from ``/tf_static``, or None if unlinked."""
    if laser_frame == base_frame:
        return np.zeros(3)
    parents: dict[str, tuple[str, np.ndarray]] = {}
    connections = [
        c for c in reader.connections if c.topic == TF_STATIC_TOPIC and c.msgtype == TF_MESSAGE
    ]
    if connections:
        for connection, _, raw in reader.messages(connections=connections):
            for transform in reader.deserialize(raw, connection.msgtype).transforms:
                t = transform.transform
                pose = np.array([t.translation.x, t.translation.y, _yaw(t.rotation)])
                parents[_frame_name(transform.child_frame_id)] = (
                    _frame_name(transform.header.frame_id),
                    pose,
                )
    offset = np.zeros(3)
    frame = laser_frame
    for _ in range(MAX_TF_HOPS):
        if frame not in parents:
            return None
        parent, pose = parents[frame]
        offset = compose(pose, offset)
        if parent == base_frame:
            return offset
        frame = parent
    return None


def _scan_stream(
    path: Path,
    topic: str,
    trajectory: _Trajectory,
    offset: np.ndarray,
    max_pose_gap: float,
    stats: BagStats,
) -> Iterator[Scan]:
    with _open_reader(path) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        for connection, bag_time, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            stamp = _stamp_seconds(message.header, bag_time)
            base_pose = trajectory.pose_at(stamp, max_pose_gap)
            if base_pose is None:
                stats.without_pose += 1
                continue
            try:
                scan = _to_scan(message, stamp, compose(base_pose, offset))
            except ValueError as error:
                raise BagError(f"{path}: {topic} message at t={stamp:.6f} s: {error}") from None
            stats.scans += 1
            yield scan


def _to_scan(message: Any, stamp: float, pose: np.ndarray) -> Scan:
    ranges = np.asarray(message.ranges, dtype=np.float64)
    intensities = np.asarray(message.intensities, dtype=np.float64)
    angle_min = float(message.angle_min)
    increment = float(message.angle_increment)
    if increment < 0:
        # A clockwise scanner (e.g. mounted upside down): reverse into CCW order.
        angle_min += increment * (len(ranges) - 1)
        increment = -increment
        ranges = ranges[::-1]
        intensities = intensities[::-1]
    return Scan(
        ranges=ranges,
        angle_min=angle_min,
        angle_increment=increment,
        range_min=float(message.range_min),
        range_max=float(message.range_max),
        intensities=intensities if intensities.size == ranges.size and ranges.size else None,
        stamp=stamp,
        pose=pose,
    )


# ----------------------------------------------------------------------------- writing


class _Ros2Messages:
    """Build the ROS 2 Humble messages of one frame from a type store."""

    def __init__(self) -> None:
        self.store = get_typestore(Stores.ROS2_HUMBLE)
        self.types = self.store.types

    def serialize(self, message: Any) -> bytes:
        return bytes(self.store.serialize_cdr(message, message.__msgtype__))

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        time = self.types["builtin_interfaces/msg/Time"](
            sec=stamp_ns // NANOSECONDS, nanosec=stamp_ns % NANOSECONDS
        )
        return self.types["std_msgs/msg/Header"](stamp=time, frame_id=frame_id)

    def quaternion(self, yaw: float) -> Any:
        return self.types["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0)
        )

    def point(self, x: float, y: float) -> Any:
        return self.types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0)

    def pose(self, pose: np.ndarray) -> Any:
        return self.types["geometry_msgs/msg/Pose"](
            position=self.point(pose[0], pose[1]), orientation=self.quaternion(pose[2])
        )

    def laser_scan(self, scan: Scan, stamp_ns: int) -> Any:
        ranges = np.asarray(scan.ranges, dtype=np.float32)
        intensities = (
            np.zeros(0, dtype=np.float32)
            if scan.intensities is None
            else np.asarray(scan.intensities, dtype=np.float32)
        )
        return self.types[LASER_SCAN](
            header=self.header(stamp_ns, LASER_FRAME),
            angle_min=scan.angle_min,
            angle_max=scan.angle_min + scan.angle_increment * max(len(scan) - 1, 0),
            angle_increment=scan.angle_increment,
            time_increment=0.0,
            scan_time=0.0,
            range_min=scan.range_min,
            range_max=scan.range_max,
            ranges=ranges,
            intensities=intensities,
        )

    def odometry(self, pose: np.ndarray, covariance: np.ndarray | None, stamp_ns: int) -> Any:
        pose_covariance = np.zeros(36)
        if covariance is not None:
            rows = np.array(PLANAR_COVARIANCE_INDICES)
            full = np.zeros((6, 6))
            full[np.ix_(rows, rows)] = covariance
            pose_covariance = full.reshape(-1)
        vector = self.types["geometry_msgs/msg/Vector3"]
        twist = self.types["geometry_msgs/msg/Twist"](
            linear=vector(x=0.0, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0)
        )
        return self.types[ODOMETRY](
            header=self.header(stamp_ns, MAP_FRAME),
            child_frame_id=BASE_FRAME,
            pose=self.types["geometry_msgs/msg/PoseWithCovariance"](
                pose=self.pose(pose), covariance=pose_covariance
            ),
            twist=self.types["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.zeros(36)
            ),
        )

    def transform(self, parent: str, child: str, pose: np.ndarray, stamp_ns: int) -> Any:
        transform = self.types["geometry_msgs/msg/Transform"](
            translation=self.types["geometry_msgs/msg/Vector3"](
                x=float(pose[0]), y=float(pose[1]), z=0.0
            ),
            rotation=self.quaternion(pose[2]),
        )
        stamped = self.types["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp_ns, parent),
            child_frame_id=child,
            transform=transform,
        )
        return self.types[TF_MESSAGE](transforms=[stamped])

    def marker(self, stamp_ns: int, index: int, points: np.ndarray, action: int) -> Any:
        marker_type = self.types["visualization_msgs/msg/Marker"]
        r, g, b, a = MARKER_COLOR
        return marker_type(
            header=self.header(stamp_ns, MAP_FRAME),
            ns="polylines",
            id=index,
            type=marker_type.LINE_STRIP,
            action=action,
            pose=self.pose(np.zeros(3)),
            scale=self.types["geometry_msgs/msg/Vector3"](x=MARKER_LINE_WIDTH, y=0.0, z=0.0),
            color=self.types["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a),
            lifetime=self.types["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
            frame_locked=False,
            points=[self.point(x, y) for x, y in points],
            colors=[],
            texture_resource="",
            texture=self.types["sensor_msgs/msg/CompressedImage"](
                header=self.header(stamp_ns, ""), format="", data=np.zeros(0, dtype=np.uint8)
            ),
            uv_coordinates=[],
            text="",
            mesh_resource="",
            mesh_file=self.types["visualization_msgs/msg/MeshFile"](
                filename="", data=np.zeros(0, dtype=np.uint8)
            ),
            mesh_use_embedded_materials=False,
        )

    def marker_array(self, polylines: Sequence[np.ndarray], stamp_ns: int) -> Any:
        marker_type = self.types["visualization_msgs/msg/Marker"]
        # DELETEALL first: every message then carries the whole current map.
        markers = [self.marker(stamp_ns, 0, np.zeros((0, 2)), marker_type.DELETEALL)]
        markers += [
            self.marker(stamp_ns, index, points, marker_type.ADD)
            for index, points in enumerate(polylines)
        ]
        return self.types[MARKER_ARRAY](markers=markers)


def _write_frames(
    path: Path, frames: Iterable[BagFrame], laser_offset: np.ndarray, storage: StoragePlugin
) -> None:
    build = _Ros2Messages()
    with Writer(path, version=Writer.VERSION_LATEST, storage_plugin=storage) as writer:
        topics = {
            SCAN_TOPIC: LASER_SCAN,
            ODOM_TOPIC: ODOMETRY,
            EKF_TOPIC: ODOMETRY,
            TF_TOPIC: TF_MESSAGE,
            MARKER_TOPIC: MARKER_ARRAY,
        }
        connection = {
            topic: writer.add_connection(topic, msgtype, typestore=build.store)
            for topic, msgtype in topics.items()
        }
        # Late-joining subscribers (RViz started after `ros2 bag play`) need the static
        # transform latched, as robot_state_publisher offers it.
        connection[TF_STATIC_TOPIC] = writer.add_connection(
            TF_STATIC_TOPIC, TF_MESSAGE, typestore=build.store, offered_qos_profiles=[LATCHED]
        )
        for index, frame in enumerate(frames):
            if not isinstance(frame, BagFrame):
                raise TypeError(
                    f"write_ros2_bag: frames[{index}] must be a BagFrame, "
                    f"got {type(frame).__name__}"
                )
            stamp_ns = round(frame.scan.stamp * NANOSECONDS)
            if index == 0:
                static = build.transform(BASE_FRAME, LASER_FRAME, laser_offset, stamp_ns)
                writer.write(connection[TF_STATIC_TOPIC], stamp_ns, build.serialize(static))
            messages = {
                SCAN_TOPIC: build.laser_scan(frame.scan, stamp_ns),
                ODOM_TOPIC: build.odometry(frame.odom_pose, None, stamp_ns),
                EKF_TOPIC: build.odometry(frame.ekf_pose, frame.ekf_covariance, stamp_ns),
                TF_TOPIC: build.transform(MAP_FRAME, BASE_FRAME, frame.ekf_pose, stamp_ns),
                MARKER_TOPIC: build.marker_array(frame.polylines, stamp_ns),
            }
            for topic, message in messages.items():
                writer.write(connection[topic], stamp_ns, build.serialize(message))
