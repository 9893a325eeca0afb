"""Record a simulated run as a ROS 2 bag that RViz 2 or Foxglove can open.

``semistatic run SCENARIO --bag DIR`` passes a :class:`BagRecorder` to
:func:`~scenarios.bench.runner.run_scenario` as its ``on_scan`` observer. The recorder keeps one
:class:`~semistatic.logs.rosbag.BagFrame` per safety-laser scan; after the run
:func:`write_run_bag` writes them with
:func:`~semistatic.logs.rosbag.write_ros2_bag` (atomically: ``DIR`` appears only when the
bag is whole). The topics (:data:`BAG_TOPICS`):

- ``/scan`` ``sensor_msgs/LaserScan``: the safety laser, frame ``laser`` (ranges and
  intensities as float32, the message type's precision);
- ``/odom`` ``nav_msgs/Odometry``: wheel odometry alone, restarted from the triangulated
  pose at each lap start (it drifts within a lap);
- ``/ekf/odom`` ``nav_msgs/Odometry``: the EKF pose with its x, y, yaw covariance;
- ``/tf`` ``map -> base_link`` from the EKF pose and ``/tf_static``
  ``base_link -> laser`` from the preset's safety-laser mount;
- ``/semistatic/polylines`` ``visualization_msgs/MarkerArray``: the current segment's
  local map after each scan, world frame, one LINE_STRIP per polyline.

Frames are collected in memory during the run (about 10 kB per scan of 541 beams) and
written after it: the runner pushes records while the writer pulls frames, and joining
the two without a thread would mean writing the bag inside the physics loop.

Examples
--------
>>> import tempfile, pathlib
>>> import numpy as np
>>> from robots.presets import get_preset
>>> from semistatic.logs.rosbag import read_bag
>>> from semistatic.types import Scan
>>> recorder = BagRecorder()
>>> for k in range(3):
...     scan = Scan(ranges=[1.0, 2.0, 1.5], angle_min=-0.5, angle_increment=0.5,
...                 range_max=10.0, stamp=0.08 * (k + 1))
...     pose = np.array([0.1 * k, 0.0, 0.0])
...     recorder(ScanRecord(lap=1, segment="corridor", scan=scan, odom_pose=pose,
...                         ekf_pose=pose, ekf_covariance=np.eye(3) * 1e-4,
...                         polylines=(np.array([[0.0, 1.0], [2.0, 1.0]]),)))
>>> folder = tempfile.TemporaryDirectory()
>>> bag = write_run_bag(pathlib.Path(folder.name) / "run", recorder.frames,
...                     get_preset("pioneer3dx"))
>>> [s.pose.round(3).tolist() for s in read_bag(bag)]
[[0.12, 0.0, 0.0], [0.22, 0.0, 0.0], [0.32, 0.0, 0.0]]
>>> folder.cleanup()
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Literal

from robots.presets import UGVSpec
from scenarios.bench.records import ScanRecord
from scenarios.process.staging import check_writable_parent
from semistatic.logs.rosbag import (
    EKF_TOPIC,
    MARKER_TOPIC,
    ODOM_TOPIC,
    SCAN_TOPIC,
    STORAGES,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    BagFrame,
    write_ros2_bag,
)

__all__ = [
    "BAG_STORAGES",
    "BAG_TOPICS",
    "BagRecorder",
    "bag_frame",
    "check_new_bag_path",
    "write_run_bag",
]

BAG_STORAGES = tuple(STORAGES)
"""Storage plugins ``--bag-storage`` accepts: ``sqlite3`` (ROS 2 Humble's default), ``mcap``."""

BAG_TOPICS = (SCAN_TOPIC, ODOM_TOPIC, EKF_TOPIC, TF_TOPIC, TF_STATIC_TOPIC, MARKER_TOPIC)
"""The topics of a run bag, in the order the summary lists them."""


def bag_frame(record: ScanRecord) -> BagFrame:
    """Return the bag frame of one scan record (the scan's true pose is not stored).

    Examples
    --------
    >>> import numpy as np
    >>> from semistatic.types import Scan
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=1.0)
    >>> record = ScanRecord(lap=1, segment="a", scan=scan, odom_pose=np.zeros(3),
    ...                     ekf_pose=np.ones(3), ekf_covariance=np.eye(3))
    >>> bag_frame(record).ekf_pose
    array([1., 1., 1.])
    """
    return BagFrame(
        scan=record.scan,
        odom_pose=record.odom_pose,
        ekf_pose=record.ekf_pose,
        polylines=record.polylines,
        ekf_covariance=record.ekf_covariance,
    )


class BagRecorder:
    """Collect the bag frames of a run; pass it as ``run_scenario(..., on_scan=recorder)``.

    Attributes
    ----------
    frames
        One :class:`~semistatic.logs.rosbag.BagFrame` per safety-laser scan, in time order.

    Examples
    --------
    >>> import numpy as np
    >>> from semistatic.types import Scan
    >>> recorder = BagRecorder()
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=1.0)
    >>> recorder(ScanRecord(lap=1, segment="a", scan=scan, odom_pose=np.zeros(3),
    ...                     ekf_pose=np.zeros(3), ekf_covariance=np.eye(3)))
    >>> len(recorder.frames)
    1
    """

    def __init__(self) -> None:
        self.frames: list[BagFrame] = []

    def __call__(self, record: ScanRecord) -> None:
        """Convert ``record`` to a frame now, so the run's later state cannot change it."""
        self.frames.append(bag_frame(record))


def check_new_bag_path(path: str | os.PathLike[str], *, out: Path | None = None) -> Path:
    """Return ``path`` if a run bag can be created there, else raise ``ValueError``.

    Called before a run starts, so that a bad ``--bag`` costs nothing. The bag directory
    must not exist, its parent must (or be ``out``, the run's output directory, which
    is written first), and it must neither be ``out`` nor contain it.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> check_new_bag_path(folder / "run").name
    'run'
    >>> check_new_bag_path(folder)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: ...: --bag: exists already; choose a new directory name or remove the old bag
    >>> folder.rmdir()
    """
    path = Path(path)
    if path.exists():
        raise ValueError(
            f"{path}: --bag: exists already; choose a new directory name or remove the old bag"
        )
    if out is not None:
        bag, results = path.resolve(), out.resolve()
        if bag == results or bag in results.parents:
            raise ValueError(
                f"{path}: --bag: is the --out directory or contains it ({out}); "
                "give the bag its own directory, e.g. --bag OUT/bag"
            )
        if bag.parent == results:
            return path
    if not path.parent.is_dir():
        raise ValueError(
            f"{path}: --bag: the parent directory {path.parent} does not exist; create it "
            "first (the bag directory itself must not exist)"
        )
    check_writable_parent(path, option="--bag")
    return path


def write_run_bag(
    path: str | os.PathLike[str],
    frames: Iterable[BagFrame],
    robot: UGVSpec,
    *,
    storage: Literal["sqlite3", "mcap"] = "sqlite3",
) -> Path:
    """Write a run's frames to a new ROS 2 bag directory, atomically; return its path.

    The laser sits at ``robot``'s safety-laser mount (``/tf_static``), the laser whose
    scans the runner records.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from robots.presets import get_preset
    >>> from semistatic.types import Scan
    >>> folder = tempfile.TemporaryDirectory()
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=1.0)
    >>> frame = BagFrame(scan=scan, odom_pose=(0, 0, 0), ekf_pose=(0, 0, 0))
    >>> bag = write_run_bag(pathlib.Path(folder.name) / "run", [frame], get_preset("lgv"),
    ...                     storage="mcap")
    >>> sorted(p.suffix for p in bag.iterdir())
    ['.mcap', '.yaml']
    >>> folder.cleanup()
    """
    return write_ros2_bag(
        path, frames, laser_offset=robot.safety_laser.pose2d(), storage=storage
    )
