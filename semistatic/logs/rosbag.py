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
    One :class:`BagFrame` per scan, every message stamped with the scan's stamp, the
    frames as REP-105 names them (``map -> odom -> base_link -> laser``):

    - ``/clock`` ``rosgraph_msgs/Clock``: the stamp, so that ``ros2 bag play --clock``
      gives ``use_sim_time`` nodes the simulation's clock;
    - ``/scan`` ``sensor_msgs/LaserScan``, frame ``laser``, with the frame's
      ``scan_time`` (0: unknown) and ``time_increment`` (0: all beams at one instant,
      or unknown);
    - ``/odom`` ``nav_msgs/Odometry``: the wheel-odometry pose, frame ``odom``, child
      ``base_link``;
    - ``/ekf/odom`` ``nav_msgs/Odometry``: the EKF pose, frame ``map``, child
      ``base_link`` (the EKF covariance, when given, fills the x, y and yaw entries);
    - ``/tf``: ``map -> odom`` (``ekf_pose ⊕ ⊖odom_pose``, the odometry's drift as the
      EKF sees it) and ``odom -> base_link`` (``odom_pose``), so that ``map ->
      base_link`` is the EKF pose, the pose the mapper works with; ``/tf_static``:
      ``base_link -> laser`` once (transient-local) from ``laser_offset``;
    - ``/semistatic/polylines`` ``visualization_msgs/MarkerArray``: one LINE_STRIP per
      map polyline, frame ``map``, in its status's colour
      (:data:`~semistatic.colours.STATUS_COLOURS`, namespace the status);
    - ``/semistatic/fields/warning``, ``.../protective``, ``.../minimum``
      ``geometry_msgs/PolygonStamped``, frame ``base_link``: the safety fields the scan
      was judged against, for frames that carry them;
    - ``/semistatic/people`` and ``/semistatic/boxes`` ``visualization_msgs/MarkerArray``,
      frame ``map``: a CYLINDER per person and a CUBE per box, where they truly are, for
      frames that carry them.

    Each MarkerArray starts with a DELETEALL, so each message replaces the previous
    one. A topic whose data no frame carries is not created. RViz 2 (fixed frame
    ``map``) and Foxglove open the result. The scan's own ``pose`` is not stored:
    reading the bag back with ``odom_topic=EKF_TOPIC`` gives
    ``compose(ekf_pose, laser_offset)``.

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
from collections.abc import Iterable, Iterator, Mapping, Sequence
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

from semistatic.colours import (
    BOX_COLOUR,
    PERSON_COLOUR,
    POLYLINE_COLOUR,
    STATUS_COLOURS,
    Colour,
)
from semistatic.errors import SpecError
from semistatic.frames import compose, inverse, wrap_angle
from semistatic.inputs import check_regular_file
from semistatic.types import Scan

__all__ = [
    "BOX_TOPIC",
    "CLOCK_TOPIC",
    "EKF_TOPIC",
    "FIELD_NAMES",
    "FIELD_TOPICS",
    "MARKER_TOPIC",
    "ODOM_TOPIC",
    "PEOPLE_TOPIC",
    "SCAN_TOPIC",
    "TF_STATIC_TOPIC",
    "TF_TOPIC",
    "BagBox",
    "BagError",
    "BagFrame",
    "BagPerson",
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
CLOCK_TOPIC = "/clock"
FIELD_NAMES = ("warning", "protective", "minimum")
"""The safety fields a :class:`BagFrame` may carry, in the order their topics are listed."""
FIELD_TOPICS = {name: f"/semistatic/fields/{name}" for name in FIELD_NAMES}
PEOPLE_TOPIC = "/semistatic/people"
BOX_TOPIC = "/semistatic/boxes"
MAP_FRAME = "map"
ODOM_FRAME = "odom"
BASE_FRAME = "base_link"
LASER_FRAME = "laser"

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
POLYGON_STAMPED = "geometry_msgs/msg/PolygonStamped"
CLOCK = "rosgraph_msgs/msg/Clock"

# A scan further than this (s) from any odometry message gets no pose and is skipped:
# a few odometry periods at the usual 10-50 Hz.
DEFAULT_MAX_POSE_GAP = 0.25
NANOSECONDS = 1_000_000_000
# LINE_STRIP width in metres: thin lines read well over the scan's points.
MARKER_LINE_WIDTH = 0.03
# Boxes and people are drawn half transparent: the scan points on their faces stay visible.
SOLID_ALPHA = 0.5
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
MAX_BAG_BYTES = 64 << 30
"""Largest ROS 1 bag file: bags are streamed message by message, so this only refuses
what no recording of a 2D laser reaches (a day of 40 Hz 1081-beam scans is ~15 GB)."""


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


def _finite_vector(owner: str, value: ArrayLike, length: int, what: str) -> np.ndarray:
    vector = np.array(value, dtype=np.float64).reshape(-1)
    if vector.shape != (length,) or not np.isfinite(vector).all():
        raise ValueError(f"{owner} must be a finite {what}, got {vector}")
    return vector


def _positive(owner: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{owner} must be a finite length > 0 m, got {value}")
    return value


@dataclass(frozen=True, eq=False)
class BagBox:
    """A box as it truly stands in the world, for the ``/semistatic/boxes`` markers.

    Parameters
    ----------
    name
        The box's name.
    pose
        ``(x, y, yaw)`` of the box centre on the floor, map frame (m, m, rad).
    size
        ``(sx, sy, sz)`` edges of the box (m, each > 0).

    Examples
    --------
    >>> BagBox("carton", pose=(2.6, -1.0, 0.0), size=(0.5, 0.4, 0.6)).size
    array([0.5, 0.4, 0.6])
    """

    name: str
    pose: np.ndarray
    size: np.ndarray

    def __post_init__(self) -> None:
        owner = f"BagBox {self.name!r}"
        object.__setattr__(self, "pose", _finite_vector(f"{owner}.pose", self.pose, 3,
                                                        "(x, y, yaw)"))
        size = _finite_vector(f"{owner}.size", self.size, 3, "(sx, sy, sz)")
        for edge in size:
            _positive(f"{owner}.size", edge)
        object.__setattr__(self, "size", size)


@dataclass(frozen=True, eq=False)
class BagPerson:
    """A person where they truly stand, for the ``/semistatic/people`` markers.

    Parameters
    ----------
    name
        The person's name.
    position
        ``(x, y)`` of the body's centre on the floor, map frame (m).
    radius, height
        The body cylinder (m, each > 0).

    Examples
    --------
    >>> BagPerson("walker", position=(1.0, 2.0), radius=0.25, height=1.75).position
    array([1., 2.])
    """

    name: str
    position: np.ndarray
    radius: float = 0.25
    height: float = 1.75

    def __post_init__(self) -> None:
        owner = f"BagPerson {self.name!r}"
        object.__setattr__(self, "position", _finite_vector(f"{owner}.position",
                                                            self.position, 2, "(x, y)"))
        object.__setattr__(self, "radius", _positive(f"{owner}.radius", self.radius))
        object.__setattr__(self, "height", _positive(f"{owner}.height", self.height))


@dataclass(frozen=True, eq=False)
class BagFrame:
    """One scan of a mapper run, with what RViz or Foxglove should show beside it.

    Parameters
    ----------
    scan
        The laser scan; its ``stamp`` (s, >= 0) stamps every message of the frame.
        It is shown at the EKF pose composed with the writer's ``laser_offset``.
    odom_pose, ekf_pose
        ``(x, y, theta)`` of the robot from wheel odometry and from the EKF. The EKF
        pose is in the map frame; the odometry pose in the ``odom`` frame, whose origin
        is the map's (odometry is integrated in map coordinates; the two drift apart).
    polylines
        Map polylines in the world frame, each an ``(N, 2)`` array with ``N >= 2``.
    ekf_covariance
        Optional ``(3, 3)`` covariance of the EKF pose over ``(x, y, theta)``.
    polyline_status
        The life-cycle status of each polyline (``new``, ``confirmed`` or ``blank``), in
        the order of ``polylines``; empty: not known (drawn in
        :data:`~semistatic.colours.POLYLINE_COLOUR`).
    fields
        The safety fields the scan was judged against, robot frame (x ahead, y left):
        ``{"warning": (N, 2), "protective": (N, 2), "minimum": (M, 2)}`` (``M`` may be 0:
        no minimum field); None: none (a replayed real log).
    people, boxes
        The people (:class:`BagPerson`) and boxes (:class:`BagBox`) in the scene, where
        they truly are; None: not known (no markers written).
    scan_time
        The time between two scans of this laser (s); 0: unknown.
    time_increment
        The time between two beams of the scan (s); 0: all beams at one instant, or
        unknown. The beams of one scan fit into one scan time.

    Examples
    --------
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1)
    >>> frame = BagFrame(scan=scan, odom_pose=(0, 0, 0), ekf_pose=(0, 0, 0),
    ...                  polylines=[[[0, 0], [1, 0]]], polyline_status=["new"])
    >>> frame.polylines[0].shape, frame.polyline_status
    ((2, 2), ('new',))
    """

    scan: Scan
    odom_pose: np.ndarray
    ekf_pose: np.ndarray
    polylines: Sequence[np.ndarray] = field(default_factory=tuple)
    ekf_covariance: np.ndarray | None = None
    polyline_status: Sequence[str] = field(default_factory=tuple)
    fields: Mapping[str, ArrayLike] | None = None
    people: Sequence[BagPerson] | None = None
    boxes: Sequence[BagBox] | None = None
    scan_time: float = 0.0
    time_increment: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.scan, Scan):
            raise TypeError(f"BagFrame.scan must be a Scan, got {type(self.scan).__name__}")
        if not (math.isfinite(self.scan.stamp) and self.scan.stamp >= 0):
            raise ValueError(
                f"BagFrame.scan.stamp must be a finite time >= 0 s (got {self.scan.stamp}): "
                "bag timestamps are unsigned nanoseconds"
            )
        for name in ("odom_pose", "ekf_pose"):
            object.__setattr__(self, name, _finite_vector(f"BagFrame.{name}",
                                                          getattr(self, name), 3,
                                                          "(x, y, theta)"))
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
        self._check_status()
        self._check_fields()
        for name, kind in (("people", BagPerson), ("boxes", BagBox)):
            items = getattr(self, name)
            if items is None:
                continue
            items = tuple(items)
            for index, item in enumerate(items):
                if not isinstance(item, kind):
                    raise TypeError(f"BagFrame.{name}[{index}] must be a {kind.__name__}, "
                                    f"got {type(item).__name__}")
            object.__setattr__(self, name, items)
        self._check_timing()

    def _check_status(self) -> None:
        status = tuple(self.polyline_status)
        if status and len(status) != len(self.polylines):
            raise ValueError(
                f"BagFrame.polyline_status must give one status per polyline "
                f"({len(self.polylines)}), got {len(status)}"
            )
        unknown = sorted(set(status) - set(STATUS_COLOURS))
        if unknown:
            raise ValueError(f"BagFrame.polyline_status: unknown status {unknown}; "
                             f"one of {sorted(STATUS_COLOURS)}")
        object.__setattr__(self, "polyline_status", status)

    def _check_fields(self) -> None:
        if self.fields is None:
            return
        if sorted(self.fields) != sorted(FIELD_NAMES):
            raise ValueError(f"BagFrame.fields must have the keys {list(FIELD_NAMES)}, "
                             f"got {sorted(self.fields)}")
        fields = {}
        for name in FIELD_NAMES:
            polygon = np.array(self.fields[name], dtype=np.float64).reshape(-1, 2)
            if 0 < len(polygon) < 3 or not np.isfinite(polygon).all():
                raise ValueError(f"BagFrame.fields[{name!r}] must be a finite (N, 2) polygon "
                                 f"with N >= 3 (or N = 0: none), got shape {polygon.shape}")
            fields[name] = polygon
        object.__setattr__(self, "fields", fields)

    def _check_timing(self) -> None:
        for name in ("scan_time", "time_increment"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"BagFrame.{name} must be a finite time >= 0 s "
                                 f"(0: unknown), got {value}")
            object.__setattr__(self, name, value)
        sweep = self.time_increment * max(len(self.scan) - 1, 0)
        if self.scan_time > 0.0 and sweep > self.scan_time:
            raise ValueError(
                f"BagFrame.time_increment: {len(self.scan)} beams {self.time_increment} s "
                f"apart take {sweep} s, longer than the scan time {self.scan_time} s"
            )


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
    if not path.is_dir():  # a FIFO or a device would block or never end
        try:
            check_regular_file(path, limit=MAX_BAG_BYTES, what="ROS bag")
        except SpecError as error:
            raise BagError(str(error)) from None
    if not max_pose_gap >= 0:
        raise ValueError(f"read_bag: max_pose_gap must be >= 0 s, got {max_pose_gap}")
    with _open_reader(path) as reader:
        scan_topic = _pick_topic(path, reader, LASER_SCAN, scan_topic, None, "scan_topic")
        odom_topic = _pick_topic(path, reader, ODOMETRY, odom_topic, ODOM_TOPIC, "odom_topic")
        trajectory = _read_trajectory(path, reader, odom_topic)
        scan_frame = _first_frame_id(path, reader, scan_topic)
        offset = _static_offset(path, reader, trajectory.child_frame, scan_frame)
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


def _messages(path: Path, reader: AnyReader, topic: str) -> Iterator[tuple[Any, int, Any]]:
    """Yield ``(connection, bag_time, message)`` of ``topic``, deserialized.

    A corrupt bag (bytes flipped in an MCAP chunk, a garbage message in a db3) fails
    inside rosbags with whatever its decoder raises (struct.error, IndexError,
    UnicodeDecodeError, a decompressor's error...): that third-party boundary is the one
    place any of them becomes one :class:`BagError` naming the file and the topic.
    """
    connections = [c for c in reader.connections if c.topic == topic]
    stream = reader.messages(connections=connections)
    while True:
        try:
            connection, bag_time, raw = next(stream)
            message = reader.deserialize(raw, connection.msgtype)
        except StopIteration:
            return
        except Exception as error:  # see above: rosbags' decoders raise anything
            reason = " ".join(str(error).split()) or type(error).__name__
            raise BagError(f"{path}: {topic}: corrupt message ({reason}); is the bag "
                           "complete?") from None
        yield connection, bag_time, message


def _read_trajectory(path: Path, reader: AnyReader, topic: str) -> _Trajectory:
    stamps, poses, child = [], [], ""
    for _, bag_time, message in _messages(path, reader, topic):
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


def _first_frame_id(path: Path, reader: AnyReader, topic: str) -> str:
    for _, _, message in _messages(path, reader, topic):
        return _frame_name(message.header.frame_id)
    return ""


def _static_offset(path: Path, reader: AnyReader, base_frame: str,
                   laser_frame: str) -> np.ndarray | None:
    """Return the laser pose in the base frame from ``/tf_static``, or None if unlinked."""
    if laser_frame == base_frame:
        return np.zeros(3)
    parents: dict[str, tuple[str, np.ndarray]] = {}
    if any(c.topic == TF_STATIC_TOPIC and c.msgtype == TF_MESSAGE for c in reader.connections):
        for _, _, message in _messages(path, reader, TF_STATIC_TOPIC):
            for transform in message.transforms:
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
        for _, bag_time, message in _messages(path, reader, topic):
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

    def point(self, x: float, y: float, z: float = 0.0) -> Any:
        return self.types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))

    def pose(self, pose: np.ndarray, z: float = 0.0) -> Any:
        return self.types["geometry_msgs/msg/Pose"](
            position=self.point(pose[0], pose[1], z), orientation=self.quaternion(pose[2])
        )

    def clock(self, stamp_ns: int) -> Any:
        return self.types[CLOCK](clock=self.header(stamp_ns, "").stamp)

    def laser_scan(self, frame: BagFrame, stamp_ns: int) -> Any:
        scan = frame.scan
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
            time_increment=frame.time_increment,
            scan_time=frame.scan_time,
            range_min=scan.range_min,
            range_max=scan.range_max,
            ranges=ranges,
            intensities=intensities,
        )

    def odometry(self, pose: np.ndarray, covariance: np.ndarray | None, stamp_ns: int,
                 frame_id: str) -> Any:
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
            header=self.header(stamp_ns, frame_id),
            child_frame_id=BASE_FRAME,
            pose=self.types["geometry_msgs/msg/PoseWithCovariance"](
                pose=self.pose(pose), covariance=pose_covariance
            ),
            twist=self.types["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.zeros(36)
            ),
        )

    def transforms(self, links: Sequence[tuple[str, str, np.ndarray]], stamp_ns: int) -> Any:
        """Return a TFMessage of ``(parent, child, pose)`` links, all at ``stamp_ns``."""
        stamped = [
            self.types["geometry_msgs/msg/TransformStamped"](
                header=self.header(stamp_ns, parent),
                child_frame_id=child,
                transform=self.types["geometry_msgs/msg/Transform"](
                    translation=self.types["geometry_msgs/msg/Vector3"](
                        x=float(pose[0]), y=float(pose[1]), z=0.0
                    ),
                    rotation=self.quaternion(pose[2]),
                ),
            )
            for parent, child, pose in links
        ]
        return self.types[TF_MESSAGE](transforms=stamped)

    def polygon(self, points: np.ndarray, stamp_ns: int) -> Any:
        point32 = self.types["geometry_msgs/msg/Point32"]
        return self.types[POLYGON_STAMPED](
            header=self.header(stamp_ns, BASE_FRAME),
            polygon=self.types["geometry_msgs/msg/Polygon"](
                points=[point32(x=float(x), y=float(y), z=0.0) for x, y in points]
            ),
        )

    def marker(
        self,
        stamp_ns: int,
        *,
        ns: str,
        index: int,
        kind: str,
        action: str = "ADD",
        pose: ArrayLike = (0.0, 0.0, 0.0),
        z: float = 0.0,
        scale: tuple[float, float, float] = (0.0, 0.0, 0.0),
        colour: Colour = (0.0, 0.0, 0.0),
        alpha: float = 1.0,
        points: Sequence[ArrayLike] = (),
    ) -> Any:
        marker_type = self.types["visualization_msgs/msg/Marker"]
        vector = self.types["geometry_msgs/msg/Vector3"]
        r, g, b = colour
        return marker_type(
            header=self.header(stamp_ns, MAP_FRAME),
            ns=ns,
            id=index,
            type=getattr(marker_type, kind),
            action=getattr(marker_type, action),
            pose=self.pose(pose, z),
            scale=vector(x=float(scale[0]), y=float(scale[1]), z=float(scale[2])),
            color=self.types["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=alpha),
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

    def marker_array(self, markers: list[Any], stamp_ns: int) -> Any:
        # DELETEALL first: every message then carries the whole current picture.
        clear = self.marker(stamp_ns, ns="", index=0, kind="ARROW", action="DELETEALL")
        return self.types[MARKER_ARRAY](markers=[clear, *markers])

    def polylines(self, frame: BagFrame, stamp_ns: int) -> Any:
        status = frame.polyline_status or (None,) * len(frame.polylines)
        markers = [
            self.marker(
                stamp_ns, ns=state or "polylines", index=index, kind="LINE_STRIP",
                scale=(MARKER_LINE_WIDTH, 0.0, 0.0),
                colour=POLYLINE_COLOUR if state is None else STATUS_COLOURS[state],
                points=points,
            )
            for index, (points, state) in enumerate(zip(frame.polylines, status, strict=True))
        ]
        return self.marker_array(markers, stamp_ns)

    def people(self, people: Sequence[BagPerson], stamp_ns: int) -> Any:
        # A CYLINDER's pose is its centre and its scale the bounding box: lift it by half.
        markers = [
            self.marker(
                stamp_ns, ns="people", index=index, kind="CYLINDER",
                pose=np.array([*person.position, 0.0]), z=person.height / 2.0,
                scale=(2.0 * person.radius, 2.0 * person.radius, person.height),
                colour=PERSON_COLOUR, alpha=SOLID_ALPHA,
            )
            for index, person in enumerate(people)
        ]
        return self.marker_array(markers, stamp_ns)

    def boxes(self, boxes: Sequence[BagBox], stamp_ns: int) -> Any:
        markers = [
            self.marker(
                stamp_ns, ns="boxes", index=index, kind="CUBE", pose=box.pose,
                z=box.size[2] / 2.0, scale=tuple(box.size), colour=BOX_COLOUR,
                alpha=SOLID_ALPHA,
            )
            for index, box in enumerate(boxes)
        ]
        return self.marker_array(markers, stamp_ns)


def _write_frames(
    path: Path, frames: Iterable[BagFrame], laser_offset: np.ndarray, storage: StoragePlugin
) -> None:
    build = _Ros2Messages()
    with Writer(path, version=Writer.VERSION_LATEST, storage_plugin=storage) as writer:
        connections: dict[str, Any] = {}

        def connect(topic: str, msgtype: str, **qos: Any) -> None:
            connections[topic] = writer.add_connection(topic, msgtype, typestore=build.store,
                                                       **qos)

        def write(topic: str, msgtype: str, message: Any, stamp_ns: int) -> None:
            # The optional topics are created on first use: one no frame has data for is
            # left out (a replayed log has no safety fields, no people and no boxes).
            if topic not in connections:
                connect(topic, msgtype)
            writer.write(connections[topic], stamp_ns, build.serialize(message))

        for topic, msgtype in (
            (CLOCK_TOPIC, CLOCK),
            (SCAN_TOPIC, LASER_SCAN),
            (ODOM_TOPIC, ODOMETRY),
            (EKF_TOPIC, ODOMETRY),
            (TF_TOPIC, TF_MESSAGE),
            (MARKER_TOPIC, MARKER_ARRAY),
        ):
            connect(topic, msgtype)
        # Late-joining subscribers (RViz started after `ros2 bag play`) need the static
        # transform latched, as robot_state_publisher offers it.
        connect(TF_STATIC_TOPIC, TF_MESSAGE, offered_qos_profiles=[LATCHED])

        for index, frame in enumerate(frames):
            if not isinstance(frame, BagFrame):
                raise TypeError(
                    f"write_ros2_bag: frames[{index}] must be a BagFrame, "
                    f"got {type(frame).__name__}"
                )
            stamp_ns = round(frame.scan.stamp * NANOSECONDS)
            if index == 0:
                static = build.transforms([(BASE_FRAME, LASER_FRAME, laser_offset)], stamp_ns)
                write(TF_STATIC_TOPIC, TF_MESSAGE, static, stamp_ns)
            # map -> odom is what the EKF corrects of odometry: composed with odom ->
            # base_link (the odometry pose) it gives the EKF pose, map -> base_link.
            drift = compose(frame.ekf_pose, inverse(frame.odom_pose))
            links = [(MAP_FRAME, ODOM_FRAME, drift), (ODOM_FRAME, BASE_FRAME, frame.odom_pose)]
            write(CLOCK_TOPIC, CLOCK, build.clock(stamp_ns), stamp_ns)
            write(SCAN_TOPIC, LASER_SCAN, build.laser_scan(frame, stamp_ns), stamp_ns)
            write(ODOM_TOPIC, ODOMETRY,
                  build.odometry(frame.odom_pose, None, stamp_ns, ODOM_FRAME), stamp_ns)
            write(EKF_TOPIC, ODOMETRY,
                  build.odometry(frame.ekf_pose, frame.ekf_covariance, stamp_ns, MAP_FRAME),
                  stamp_ns)
            write(TF_TOPIC, TF_MESSAGE, build.transforms(links, stamp_ns), stamp_ns)
            write(MARKER_TOPIC, MARKER_ARRAY, build.polylines(frame, stamp_ns), stamp_ns)
            if frame.fields is not None:
                for name in FIELD_NAMES:
                    write(FIELD_TOPICS[name], POLYGON_STAMPED,
                          build.polygon(frame.fields[name], stamp_ns), stamp_ns)
            if frame.people is not None:
                write(PEOPLE_TOPIC, MARKER_ARRAY, build.people(frame.people, stamp_ns),
                      stamp_ns)
            if frame.boxes is not None:
                write(BOX_TOPIC, MARKER_ARRAY, build.boxes(frame.boxes, stamp_ns), stamp_ns)
