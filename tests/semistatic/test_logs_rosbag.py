import math

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from semistatic.frames import compose, wrap_angle
from semistatic.logs.rosbag import (
    EKF_TOPIC,
    MARKER_TOPIC,
    ODOM_TOPIC,
    SCAN_TOPIC,
    BagError,
    BagFrame,
    BagStats,
    read_bag,
    write_ros2_bag,
)
from semistatic.types import Scan

LASER_OFFSET = np.array([0.2, -0.05, 0.1])
FLOAT32_ANGLE = 1e-6  # angles travel as float32 in LaserScan


def synthetic_frames(rng, count=6):
    frames = []
    for k in range(count):
        beams = 40
        # Multiples of 1/256 m are exact in float32, so ranges must come back bit-identical.
        ranges = np.round(rng.uniform(0.5, 8.0, beams) * 256) / 256
        ranges[rng.integers(0, beams, 3)] = np.inf
        intensities = None if k % 2 else np.round(rng.uniform(0, 1000, beams))
        odom = np.array([0.1 * k, 0.02 * k, wrap_angle(3.0 + 0.1 * k)])
        ekf = odom + rng.normal(0, 0.01, 3)
        ekf[2] = wrap_angle(ekf[2])
        scan = Scan(
            ranges=ranges,
            angle_min=-1.5,
            angle_increment=0.075,
            range_min=0.05,
            range_max=10.0,
            intensities=intensities,
            stamp=100.0 + 0.08 * k,
            pose=compose(ekf, LASER_OFFSET),
        )
        polylines = [rng.uniform(-5, 5, (n, 2)) for n in (2, 5)][: 1 + k % 2]
        frames.append(
            BagFrame(
                scan=scan,
                odom_pose=odom,
                ekf_pose=ekf,
                polylines=polylines,
                ekf_covariance=np.diag([0.01, 0.02, 0.003]),
            )
        )
    return frames


def assert_same_scan(read, written, pose):
    np.testing.assert_array_equal(read.ranges, written.ranges)
    assert read.angle_min == pytest.approx(written.angle_min, abs=FLOAT32_ANGLE)
    assert read.angle_increment == pytest.approx(written.angle_increment, abs=FLOAT32_ANGLE)
    assert read.range_min == pytest.approx(written.range_min, rel=1e-7)
    assert read.range_max == pytest.approx(written.range_max, rel=1e-7)
    assert read.stamp == pytest.approx(written.stamp, abs=1e-9)
    if written.intensities is None:
        assert read.intensities is None
    else:
        np.testing.assert_array_equal(read.intensities, written.intensities)
    np.testing.assert_allclose(read.pose, pose, atol=1e-9)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_ros2_round_trip_gives_back_scans_and_poses(tmp_path, storage):
    frames = synthetic_frames(np.random.default_rng(7))
    bag = write_ros2_bag(tmp_path / "run", frames, laser_offset=LASER_OFFSET, storage=storage)
    assert bag == tmp_path / "run"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging left behind

    ekf_scans = list(read_bag(bag, odom_topic=EKF_TOPIC))
    assert len(ekf_scans) == len(frames)
    for read, frame in zip(ekf_scans, frames, strict=True):
        # Written at the EKF pose with the laser offset: exactly the frame's scan pose.
        assert_same_scan(read, frame.scan, frame.scan.pose)

    stats = BagStats()
    odom_scans = list(read_bag(bag, stats=stats))  # /odom is the default pose source
    assert stats.scans == len(frames)
    assert stats.without_pose == 0
    for read, frame in zip(odom_scans, frames, strict=True):
        assert_same_scan(read, frame.scan, compose(frame.odom_pose, LASER_OFFSET))


def test_ros2_bag_carries_markers_covariance_and_tf(tmp_path):
    frames = synthetic_frames(np.random.default_rng(3), count=3)
    bag = write_ros2_bag(tmp_path / "run", frames, laser_offset=LASER_OFFSET)
    with AnyReader([bag]) as reader:
        topics = reader.topics
        assert topics[SCAN_TOPIC].msgtype == "sensor_msgs/msg/LaserScan"
        assert topics[ODOM_TOPIC].msgtype == "nav_msgs/msg/Odometry"
        assert topics[EKF_TOPIC].msgtype == "nav_msgs/msg/Odometry"
        assert topics[MARKER_TOPIC].msgtype == "visualization_msgs/msg/MarkerArray"
        assert topics["/tf"].msgcount == 3
        assert topics["/tf_static"].msgcount == 1
        markers, covariances = [], []
        for connection, _, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            if connection.topic == MARKER_TOPIC:
                markers.append(message.markers)
            elif connection.topic == EKF_TOPIC:
                covariances.append(message.pose.covariance.reshape(6, 6))
            elif connection.topic == "/tf":
                # REP-105: the EKF's correction map -> odom, then odometry odom -> base_link.
                assert [(t.header.frame_id, t.child_frame_id) for t in message.transforms] == [
                    ("map", "odom"),
                    ("odom", "base_link"),
                ]
    assert len(markers) == 3
    for message, frame in zip(markers, frames, strict=True):
        assert message[0].action == 3  # DELETEALL, then one LINE_STRIP per polyline
        strips = message[1:]
        assert [m.type for m in strips] == [4] * len(frame.polylines)
        for marker, line in zip(strips, frame.polylines, strict=True):
            points = np.array([[p.x, p.y] for p in marker.points])
            np.testing.assert_array_equal(points, line)
            assert marker.header.frame_id == "map"
    np.testing.assert_allclose(np.diag(covariances[0])[[0, 1, 5]], [0.01, 0.02, 0.003])
    assert np.diag(covariances[0])[[2, 3, 4]].tolist() == [0.0, 0.0, 0.0]


def test_write_refuses_an_existing_path(tmp_path):
    (tmp_path / "run").mkdir()
    with pytest.raises(FileExistsError, match="exists already"):
        write_ros2_bag(tmp_path / "run", synthetic_frames(np.random.default_rng(0), 1))


def test_failed_write_leaves_nothing_behind(tmp_path):
    frames = synthetic_frames(np.random.default_rng(0), 3)

    def broken():
        yield frames[0]
        yield frames[1]
        raise RuntimeError("simulation crashed")

    with pytest.raises(RuntimeError, match="crashed"):
        write_ros2_bag(tmp_path / "run", broken())
    assert list(tmp_path.iterdir()) == []


def test_write_rejects_a_non_frame(tmp_path):
    with pytest.raises(TypeError, match=r"frames\[0\] must be a BagFrame"):
        write_ros2_bag(tmp_path / "run", ["scan"])
    assert list(tmp_path.iterdir()) == []


def test_bag_frame_validation():
    scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=1.0)
    with pytest.raises(ValueError, match=r"polylines\[0\] must be an \(N, 2\)"):
        BagFrame(scan=scan, odom_pose=(0, 0, 0), ekf_pose=(0, 0, 0), polylines=[[[0, 0]]])
    with pytest.raises(ValueError, match="ekf_pose must be a finite"):
        BagFrame(scan=scan, odom_pose=(0, 0, 0), ekf_pose=(0, np.nan, 0))
    with pytest.raises(ValueError, match=r"ekf_covariance must be \(3, 3\)"):
        BagFrame(scan=scan, odom_pose=(0, 0, 0), ekf_pose=(0, 0, 0), ekf_covariance=np.eye(2))
    negative = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=-1.0)
    with pytest.raises(ValueError, match="stamp must be a finite time >= 0"):
        BagFrame(scan=negative, odom_pose=(0, 0, 0), ekf_pose=(0, 0, 0))


# --------------------------------------------------------------------------- ROS 1

ROS1 = get_typestore(Stores.ROS1_NOETIC)
# The noetic store has no tf2_msgs; its definition is one line.
ROS1.register(
    get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
)


def ros1_header(stamp, frame_id, seq=0):
    time = ROS1.types["builtin_interfaces/msg/Time"](
        sec=math.floor(stamp), nanosec=round((stamp - math.floor(stamp)) * 1e9)
    )
    return ROS1.types["std_msgs/msg/Header"](seq=seq, stamp=time, frame_id=frame_id)


def ros1_quaternion(yaw):
    return ROS1.types["geometry_msgs/msg/Quaternion"](
        x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
    )


def ros1_laser_scan(stamp, ranges, angle_min, increment, frame="/laser"):
    return ROS1.types["sensor_msgs/msg/LaserScan"](
        header=ros1_header(stamp, frame),
        angle_min=angle_min,
        angle_max=angle_min + increment * (len(ranges) - 1),
        angle_increment=increment,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.1,
        range_max=30.0,
        ranges=np.asarray(ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )


def ros1_odometry(stamp, pose):
    t = ROS1.types
    vector = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return t["nav_msgs/msg/Odometry"](
        header=ros1_header(stamp, "/odom"),
        child_frame_id="/base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=pose[0], y=pose[1], z=0.0),
                orientation=ros1_quaternion(pose[2]),
            ),
            covariance=np.zeros(36),
        ),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](linear=vector, angular=vector),
            covariance=np.zeros(36),
        ),
    )


def ros1_static_tf(stamp, parent, child, pose):
    t = ROS1.types
    stamped = t["geometry_msgs/msg/TransformStamped"](
        header=ros1_header(stamp, parent),
        child_frame_id=child,
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=pose[0], y=pose[1], z=0.0),
            rotation=ros1_quaternion(pose[2]),
        ),
    )
    return t["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def robot_pose(t):
    """Drive at 0.5 m/s while turning at 1 rad/s: the heading crosses +-pi."""
    return np.array([0.5 * t, 0.1 * t, wrap_angle(2.5 + 1.0 * t)])


def write_ros1_bag(path, *, scans, odometry, static=(), extra_scan_topic=False, clockwise=False):
    with Ros1Writer(path) as writer:
        topics = {
            "/base_scan": "sensor_msgs/msg/LaserScan",
            "/odom": "nav_msgs/msg/Odometry",
            "/tf_static": "tf2_msgs/msg/TFMessage",
        }
        if extra_scan_topic:
            topics["/rear_scan"] = "sensor_msgs/msg/LaserScan"
        connection = {
            topic: writer.add_connection(topic, msgtype, typestore=ROS1)
            for topic, msgtype in topics.items()
        }
        messages = [(t, "/odom", ros1_odometry(t, robot_pose(t))) for t in odometry]
        messages += [(0.0, "/tf_static", ros1_static_tf(0.0, *link)) for link in static]
        for t, ranges in scans:
            if clockwise:
                laser = ros1_laser_scan(t, ranges[::-1], 1.0, -0.5)
            else:
                laser = ros1_laser_scan(t, ranges, -1.0, 0.5)
            messages.append((t, "/base_scan", laser))
        for t, topic, message in sorted(messages, key=lambda m: m[0]):
            data = ROS1.serialize_ros1(message, message.__msgtype__)
            writer.write(connection[topic], round(t * 1e9) + 1, data)
    return path


SCANS = [(t, [1.0, 2.0, 3.0, 4.0, 5.0]) for t in (1.05, 1.5, 2.02, 2.97, 3.5)]
ODOMETRY = [1.0 + 0.1 * k for k in range(26)]  # 10 Hz from 1.0 to 3.5 s
MOUNT = [
    ("/base_link", "laser_mount", (0.1, 0.0, 0.0)),
    ("laser_mount", "/laser", (0.0, 0.05, 0.3)),
]


def test_ros1_bag_reads_into_scans_with_interpolated_poses(tmp_path):
    bag = write_ros1_bag(tmp_path / "run.bag", scans=SCANS, odometry=ODOMETRY, static=MOUNT)
    scans = list(read_bag(bag))
    assert len(scans) == len(SCANS)
    offset = compose((0.1, 0.0, 0.0), (0.0, 0.05, 0.3))
    for scan, (t, ranges) in zip(scans, SCANS, strict=True):
        np.testing.assert_array_equal(scan.ranges, ranges)
        assert scan.stamp == pytest.approx(t, abs=1e-9)
        assert scan.angle_min == -1.0
        assert scan.angle_increment == 0.5
        assert (scan.range_min, scan.range_max) == (pytest.approx(0.1), 30.0)
        # Linear interpolation between 10 Hz samples of a smooth motion: the position is
        # exact (linear in t), the heading too (constant turn rate, shorter arc across pi).
        expected = compose(robot_pose(t), offset)
        np.testing.assert_allclose(scan.pose[:2], expected[:2], atol=1e-9)
        assert wrap_angle(scan.pose[2] - expected[2]) == pytest.approx(0.0, abs=1e-9)


def test_clockwise_scans_are_reordered_counter_clockwise(tmp_path):
    bag = write_ros1_bag(
        tmp_path / "run.bag", scans=SCANS[:1], odometry=ODOMETRY, static=MOUNT, clockwise=True
    )
    (scan,) = read_bag(bag)
    np.testing.assert_array_equal(scan.ranges, SCANS[0][1])
    assert scan.angle_min == pytest.approx(-1.0)
    assert scan.angle_increment == pytest.approx(0.5)


def test_scans_far_from_odometry_are_skipped_and_counted(tmp_path):
    scans = [(0.2, [1.0, 2.0]), (1.1, [1.0, 2.0]), (3.6, [1.0, 2.0]), (9.0, [1.0, 2.0])]
    bag = write_ros1_bag(tmp_path / "run.bag", scans=scans, odometry=ODOMETRY, static=MOUNT)
    stats = BagStats()
    read = list(read_bag(bag, stats=stats))
    # 0.2 s and 9.0 s are more than 0.25 s from odometry; 3.6 s takes the last pose.
    assert [s.stamp for s in read] == [pytest.approx(1.1), pytest.approx(3.6)]
    assert (stats.scans, stats.without_pose) == (2, 2)
    offset = compose((0.1, 0.0, 0.0), (0.0, 0.05, 0.3))
    np.testing.assert_allclose(read[1].pose, compose(robot_pose(3.5), offset), atol=1e-9)


def test_missing_static_link_warns_and_uses_the_base_pose(tmp_path):
    bag = write_ros1_bag(tmp_path / "run.bag", scans=SCANS[:1], odometry=ODOMETRY)
    with pytest.warns(UserWarning, match="does not link 'base_link'"):
        (scan,) = read_bag(bag)
    np.testing.assert_allclose(scan.pose, robot_pose(SCANS[0][0]), atol=1e-9)


def test_ambiguous_or_unknown_topics_are_errors(tmp_path):
    bag = write_ros1_bag(
        tmp_path / "run.bag", scans=SCANS, odometry=ODOMETRY, static=MOUNT, extra_scan_topic=True
    )
    with pytest.raises(BagError, match=r"several sensor_msgs/LaserScan topics .*scan_topic="):
        read_bag(bag)
    with pytest.raises(BagError, match=r"scan_topic='/nope' is not a sensor_msgs/LaserScan"):
        read_bag(bag, scan_topic="/nope")
    assert len(list(read_bag(bag, scan_topic="/base_scan"))) == len(SCANS)


def test_bag_without_odometry_is_an_error(tmp_path):
    bag = write_ros1_bag(tmp_path / "run.bag", scans=SCANS, odometry=[])
    with pytest.raises(BagError, match="odometry topic /odom has no messages"):
        read_bag(bag)


def test_missing_and_garbage_paths(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such bag"):
        read_bag(tmp_path / "nope.bag")
    garbage = tmp_path / "garbage.bag"
    garbage.write_bytes(b"not a bag at all")
    with pytest.raises(BagError, match="cannot open as a ROS bag"):
        read_bag(garbage)
