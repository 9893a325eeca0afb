"""Record a simulated run as a ROS 2 bag that RViz 2 or Foxglove can open.

``semistatic run SCENARIO --bag DIR`` adds a :class:`BagRecorder` to
:func:`~scenarios.bench.runner.run_scenario` as an observer. The recorder keeps one
:class:`~semistatic.logs.rosbag.BagFrame` per safety-laser scan; after the run
:func:`write_run_bag` writes them with
:func:`~semistatic.logs.rosbag.write_ros2_bag` (atomically: ``DIR`` appears only when the
bag is whole). Frames follow REP-105 (``map -> odom -> base_link -> laser``); every
message is stamped with its scan's simulated time. The topics (:data:`BAG_TOPICS`):

- ``/clock`` ``rosgraph_msgs/Clock``: the simulated time of each scan, for
  ``ros2 bag play --clock`` and ``use_sim_time`` nodes;
- ``/scan`` ``sensor_msgs/LaserScan``: the safety laser, frame ``laser`` (ranges and
  intensities as float32, the message type's precision); ``scan_time`` is the time
  between the bench's safety scans (``1 / rates.safety_hz``), ``time_increment`` 0
  because the simulated laser casts all its beams at one instant from one pose;
- ``/odom`` ``nav_msgs/Odometry``: wheel odometry alone, frame ``odom``, child
  ``base_link``; restarted from the triangulated pose at each lap start (it drifts
  within a lap);
- ``/ekf/odom`` ``nav_msgs/Odometry``: the EKF pose with its x, y, yaw covariance,
  frame ``map``;
- ``/tf`` ``map -> odom`` (the EKF's correction of odometry) and ``odom -> base_link``
  (odometry), so that ``map -> base_link`` is the EKF pose; ``/tf_static``
  ``base_link -> laser`` from the preset's safety-laser mount;
- ``/semistatic/polylines`` ``visualization_msgs/MarkerArray``: the current segment's
  local map after each scan, world frame, one LINE_STRIP per polyline in the colour of
  its status (:data:`~semistatic.colours.STATUS_COLOURS`; the marker namespace is the
  status);
- ``/semistatic/fields/warning``, ``/semistatic/fields/protective``,
  ``/semistatic/fields/minimum`` ``geometry_msgs/PolygonStamped``: the safety fields the
  scan was judged against, frame ``base_link``;
- ``/semistatic/people`` and ``/semistatic/boxes`` ``visualization_msgs/MarkerArray``:
  the people (a CYLINDER each) and the semi-static boxes (a CUBE each) where they truly
  are, frame ``map``.

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
>>> frames = []
>>> for k in range(3):
...     scan = Scan(ranges=[1.0, 2.0, 1.5], angle_min=-0.5, angle_increment=0.5,
...                 range_max=10.0, stamp=0.08 * (k + 1))
...     pose = np.array([0.1 * k, 0.0, 0.0])
...     frames.append(bag_frame(ScanRecord(
...         lap=1, segment="corridor", scan=scan, odom_pose=pose, ekf_pose=pose,
...         ekf_covariance=np.eye(3) * 1e-4, polylines=(np.array([[0.0, 1.0], [2.0, 1.0]]),),
...         polyline_status=("new",))))
>>> folder = tempfile.TemporaryDirectory()
>>> bag = write_run_bag(pathlib.Path(folder.name) / "run", frames, get_preset("pioneer3dx"))
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
from scenarios.bench.observer import Observer, VehicleView
from scenarios.bench.records import ScanRecord
from scenarios.process.staging import check_writable_parent
from semistatic.logs.rosbag import (
    BOX_TOPIC,
    CLOCK_TOPIC,
    EKF_TOPIC,
    FIELD_NAMES,
    FIELD_TOPICS,
    MARKER_TOPIC,
    ODOM_TOPIC,
    PEOPLE_TOPIC,
    SCAN_TOPIC,
    STORAGES,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    BagBox,
    BagFrame,
    BagPerson,
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

BAG_TOPICS = (
    CLOCK_TOPIC, SCAN_TOPIC, ODOM_TOPIC, EKF_TOPIC, TF_TOPIC, TF_STATIC_TOPIC, MARKER_TOPIC,
    *(FIELD_TOPICS[name] for name in FIELD_NAMES), PEOPLE_TOPIC, BOX_TOPIC,
)
"""The topics of a run bag, in the order the summary lists them."""


def bag_frame(record: ScanRecord, vehicle: VehicleView | None = None, *,
              boxes: tuple[BagBox, ...] | None = None) -> BagFrame:
    """Return the bag frame of one scan record (the scan's true pose is not stored).

    The record gives the scan, the poses, the map polylines with their statuses and the
    safety fields (when it carries them). ``vehicle``, the view the record came with,
    gives the people where they stand now, the boxes (``boxes`` when given, e.g. cached
    per layout) and the scan time, the bench's safety-scan period
    ``1 / rates.safety_hz``. The beams' ``time_increment`` stays 0: the simulated laser
    casts all of them at one instant from one pose, and a non-zero value would make
    RViz 2 and SLAM front ends de-skew scans that have no skew.

    Examples
    --------
    >>> import numpy as np
    >>> from semistatic.types import Scan
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=1.0)
    >>> record = ScanRecord(lap=1, segment="a", scan=scan, odom_pose=np.zeros(3),
    ...                     ekf_pose=np.ones(3), ekf_covariance=np.eye(3))
    >>> frame = bag_frame(record)
    >>> frame.ekf_pose, frame.fields, frame.people, frame.scan_time
    (array([1., 1., 1.]), None, None, 0.0)
    """
    fields = None
    if record.fields is not None:
        fields = {name: getattr(record.fields, name) for name in FIELD_NAMES}
    people, scan_time = None, 0.0
    if vehicle is not None:
        bodies = {person.name: person for person in vehicle.world.people}
        people = tuple(
            BagPerson(name, position, radius=bodies[name].radius, height=bodies[name].height)
            for name, position in vehicle.person_positions.items() if position is not None
        )
        if boxes is None:
            boxes = _world_boxes(vehicle)
        scan_time = 1.0 / vehicle.spec.rates.safety_hz
    return BagFrame(
        scan=record.scan,
        odom_pose=record.odom_pose,
        ekf_pose=record.ekf_pose,
        polylines=record.polylines,
        ekf_covariance=record.ekf_covariance,
        polyline_status=record.polyline_status,
        fields=fields,
        people=people,
        boxes=boxes,
        scan_time=scan_time,
    )


def _world_boxes(vehicle: VehicleView) -> tuple[BagBox, ...]:
    """Return the boxes of ``vehicle``'s world as they stand now, for the bag's markers."""
    return tuple(BagBox(box.name, pose=box.pose, size=box.size) for box in vehicle.world.boxes)


class BagRecorder(Observer):
    """Collect the bag frames of a run; add it as ``run_scenario(..., observers=[recorder])``.

    It asks for the map polylines and the safety fields of every scan
    (``wants_polylines``), and reads the people and boxes from the vehicle.

    Attributes
    ----------
    frames
        One :class:`~semistatic.logs.rosbag.BagFrame` per safety-laser scan, in time order.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> import numpy as np
    >>> from scenarios.spec.scenario import Rates
    >>> from semistatic.types import Scan
    >>> from worlds.spec import BoxSpec, PersonSpec
    >>> world = SimpleNamespace(
    ...     boxes=(BoxSpec("carton", size=(0.5, 0.4, 0.6), pose=(2.6, -1.0, 0.0)),),
    ...     people=(PersonSpec("walker", waypoints=[(5.0, 1.0)]),))
    >>> vehicle = SimpleNamespace(world=world, layout_revision=0,
    ...                           person_positions={"walker": np.array([5.0, 1.0])},
    ...                           spec=SimpleNamespace(rates=Rates(safety_hz=12.5)))
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=1.0)
    >>> recorder = BagRecorder()
    >>> recorder.on_scan(vehicle, ScanRecord(lap=1, segment="a", scan=scan,
    ...     odom_pose=np.zeros(3), ekf_pose=np.zeros(3), ekf_covariance=np.eye(3)))
    >>> frame, = recorder.frames
    >>> frame.people[0].position, frame.boxes[0].name, frame.scan_time
    (array([5., 1.]), 'carton', 0.08)
    """

    wants_polylines = True

    def __init__(self) -> None:
        self.frames: list[BagFrame] = []
        self._boxes: tuple[int, tuple[BagBox, ...]] | None = None

    def on_scan(self, vehicle: VehicleView, record: ScanRecord) -> None:
        """Convert ``record`` to a frame now, so the run's later state cannot change it."""
        # Boxes move only between layouts: one tuple per layout, shared by its frames.
        revision = vehicle.layout_revision
        if self._boxes is None or self._boxes[0] != revision:
            self._boxes = (revision, _world_boxes(vehicle))
        self.frames.append(bag_frame(record, vehicle, boxes=self._boxes[1]))


def check_new_bag_path(path: str | os.PathLike[str], *, out: Path | None = None) -> Path:
    """Return ``path`` if a run bag can be created there, else raise ``ValueError``.

    Called before a run starts, so that a bad ``--bag`` costs nothing. The bag directory
    must not exist and its parent must, unless it lies directly in ``out``, the run's
    output directory (written first, replacing a previous result and its bag whole). That
    it neither is ``out`` nor holds it is every command's overlap check
    (:func:`scenarios.process.output_paths.check_output_paths`).

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
    if out is not None and path.resolve().parent == out.resolve():
        return path  # lands in the new result, which replaces the old one (and its bag) whole
    if path.exists():
        raise ValueError(
            f"{path}: --bag: exists already; choose a new directory name or remove the old bag"
        )
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
