"""A run bag as readers that are not ours see it: rosbags and MCAP's own ROS 2 decoder.

Nothing here reads the bag with the project's reader: ``rosbags.highlevel.AnyReader`` and
``mcap.reader`` + ``mcap_ros2.decoder`` decode it, and every value is checked against an
independent reference: the world's TOML numbers and the scenario's segments, the
palette, the laser's data sheet, hand-composed frames.
"""

import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from robots.presets import get_preset
from scenarios.cli import main
from scenarios.spec.layout import scenario_world
from scenarios.spec.load import load_scenario
from scenarios.spec.segments import path_segments
from semistatic.colours import BOX_COLOUR, PERSON_COLOUR, STATUS_COLOURS
from semistatic.logs.rosbag import BagBox, BagFrame, BagPerson, write_ros2_bag
from semistatic.types import Scan
from tests.scenarios.tiny_world import TINY_WORLD

FLOAT32 = 1e-6  # Point32 and LaserScan's float fields: float32 of a few metres
POSE = 1e-9  # float64 poses, yaw through a quaternion: a few ulp
STAMP = 1e-9  # stamps travel as integer nanoseconds
SOLID_ALPHA = 0.5  # boxes and people are drawn half transparent (the writer's choice)
FIELD_TOPICS = {name: f"/semistatic/fields/{name}" for name in ("warning", "protective",
                                                                 "minimum")}
MARKER_TOPICS = ("/semistatic/polylines", "/semistatic/people", "/semistatic/boxes")
DELETEALL, ADD = 3, 0  # visualization_msgs/Marker actions
CUBE, CYLINDER, LINE_STRIP = 1, 3, 4  # ... and types

# S300 data sheet (robots/lasers.py cites it): 80 ms scan time, 0.5 deg between beams;
# the mirror turns once per scan, so neighbouring beams are 0.5/360 of a scan apart.
S300_SCAN_TIME = 0.08
S300_TIME_INCREMENT = 0.08 * 0.5 / 360.0


# ------------------------------------------------------------------ independent readers


def read_with_rosbags(bag: Path) -> dict[str, list]:
    """Return ``{topic: [(log time ns, message), ...]}`` decoded by rosbags."""
    topics: dict[str, list] = {}
    with AnyReader([bag]) as reader:
        for connection, stamp, raw in reader.messages():
            topics.setdefault(connection.topic, []).append(
                (stamp, reader.deserialize(raw, connection.msgtype)))
        types = {name: info.msgtype for name, info in reader.topics.items()}
    topics["types"] = types
    return topics


def read_with_mcap(bag: Path) -> dict[str, list]:
    """Return ``{topic: [(log time ns, message), ...]}`` decoded by mcap-ros2-support."""
    (path,) = bag.glob("*.mcap")
    topics: dict[str, list] = {}
    types = {}
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            topics.setdefault(channel.topic, []).append((message.log_time, decoded))
            types[channel.topic] = schema.name
    topics["types"] = types
    return topics


READERS = {"rosbags": read_with_rosbags, "mcap": read_with_mcap}


def yaw(q) -> float:
    """Heading of a quaternion about z (REP-103: counter-clockwise from x)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def planar(transform) -> np.ndarray:
    t = transform.transform
    return np.array([t.translation.x, t.translation.y, yaw(t.rotation)])


def chain(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose ``b`` given in frame ``a``, expressed in ``a``'s parent (by hand)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    heading = math.atan2(math.sin(a[2] + b[2]), math.cos(a[2] + b[2]))
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], heading])


def seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def odometry_pose(message) -> np.ndarray:
    pose = message.pose.pose
    return np.array([pose.position.x, pose.position.y, yaw(pose.orientation)])


def polygon(message) -> np.ndarray:
    return np.array([[p.x, p.y] for p in message.polygon.points]).reshape(-1, 2)


def rgba(marker) -> tuple:
    c = marker.color
    return (c.r, c.g, c.b, c.a)


def drawn(message) -> list:
    """The markers a MarkerArray adds, after checking it first clears the previous ones."""
    first, *markers = message.markers
    assert first.action == DELETEALL
    assert all(marker.action == ADD and marker.header.frame_id == "map" for marker in markers)
    return markers


def assert_close_colour(marker, colour, alpha):
    np.testing.assert_allclose(rgba(marker), (*colour, alpha), atol=FLOAT32)


def assert_frames_chain_to_the_ekf(topics):
    """/tf is map -> odom -> base_link composing to /ekf/odom; /odom is in odom (REP-105)."""
    ekf = {stamp: message for stamp, message in topics["/ekf/odom"]}
    odom = {stamp: message for stamp, message in topics["/odom"]}
    assert len(topics["/tf"]) == len(ekf) == len(odom)
    for stamp, message in topics["/tf"]:
        to_odom, to_base = message.transforms
        assert (to_odom.header.frame_id, to_odom.child_frame_id) == ("map", "odom")
        assert (to_base.header.frame_id, to_base.child_frame_id) == ("odom", "base_link")
        assert seconds(to_odom.header.stamp) == pytest.approx(stamp * 1e-9, abs=STAMP)
        composed = chain(planar(to_odom), planar(to_base))
        assert ekf[stamp].header.frame_id == "map"
        np.testing.assert_allclose(composed, odometry_pose(ekf[stamp]), atol=POSE)
        assert (odom[stamp].header.frame_id, odom[stamp].child_frame_id) == ("odom",
                                                                            "base_link")
        np.testing.assert_allclose(planar(to_base), odometry_pose(odom[stamp]), atol=POSE)
    ((_, static),) = topics["/tf_static"]
    ((link),) = static.transforms
    assert (link.header.frame_id, link.child_frame_id) == ("base_link", "laser")


def assert_clock_is_the_scan_stamps(topics):
    clock = [seconds(message.clock) for _, message in topics["/clock"]]
    scans = [seconds(message.header.stamp) for _, message in topics["/scan"]]
    assert clock == scans
    assert np.all(np.diff(clock) > 0)


def assert_polylines_in_their_status_colours(topics) -> list[str]:
    """Every polyline marker is drawn in its status's colour; return the statuses seen."""
    seen = []
    for _, message in topics["/semistatic/polylines"]:
        for marker in drawn(message):
            assert marker.type == LINE_STRIP
            assert marker.ns in STATUS_COLOURS
            assert_close_colour(marker, STATUS_COLOURS[marker.ns], 1.0)
            seen.append(marker.ns)
    return seen


# ------------------------------------------------------------------ hand-built frames


def hand_frames(count=3):
    """Frames whose every value is chosen here; the odometry drifts off the EKF pose."""
    warning = [[0.2, -0.9], [1.4, -0.9], [1.4, 0.9], [0.2, 0.9]]
    protective = [[0.2, -0.6], [0.8, -0.6], [0.8, 0.6], [0.2, 0.6]]
    minimum = [[-0.4, -0.3], [0.5, -0.3], [0.5, 0.3], [-0.4, 0.3]]
    frames = []
    for k in range(count):
        scan = Scan(ranges=[1.0, 1.5, 2.0, 2.5, 3.0], angle_min=-0.5, angle_increment=0.25,
                    range_max=8.0, stamp=10.0 + S300_SCAN_TIME * k)
        frames.append(BagFrame(
            scan=scan,
            odom_pose=(0.1 * k, 0.02 * k, 3.1 + 0.03 * k),  # crosses pi: yaw wraps
            ekf_pose=(0.1 * k + 0.05, -0.01, 3.1 + 0.02 * k),
            polylines=[[[0, 1], [2, 1]], [[0, -1], [2, -1], [2, -2]], [[3, 0], [3, 1]]],
            polyline_status=["new", "confirmed", "blank"],
            fields={"warning": warning, "protective": protective, "minimum": minimum},
            people=[BagPerson("standing", position=(3.0, 1.0), radius=0.25, height=1.75)],
            boxes=[BagBox("carton", pose=(2.6, -1.0, 0.3), size=(0.5, 0.4, 0.6))],
            scan_time=S300_SCAN_TIME,
            time_increment=S300_TIME_INCREMENT,
        ))
    return frames, warning, protective, minimum


@pytest.mark.parametrize(("storage", "reader"),
                         [("sqlite3", "rosbags"), ("mcap", "rosbags"), ("mcap", "mcap")])
def test_hand_built_frames_read_back_by_other_readers(tmp_path, storage, reader):
    frames, warning, protective, minimum = hand_frames()
    bag = write_ros2_bag(tmp_path / "run", frames, laser_offset=(0.12, 0.0, 0.0),
                         storage=storage)
    topics = READERS[reader](bag)
    types = topics["types"]
    assert types["/clock"] == "rosgraph_msgs/msg/Clock"
    assert {types[topic] for topic in FIELD_TOPICS.values()} == {
        "geometry_msgs/msg/PolygonStamped"}
    assert {types[topic] for topic in MARKER_TOPICS} == {"visualization_msgs/msg/MarkerArray"}

    assert_frames_chain_to_the_ekf(topics)
    assert_clock_is_the_scan_stamps(topics)
    assert [seconds(m.clock) for _, m in topics["/clock"]] == pytest.approx(
        [10.0, 10.08, 10.16], abs=STAMP)
    for _, scan in topics["/scan"]:
        assert scan.scan_time == pytest.approx(S300_SCAN_TIME, rel=FLOAT32)
        assert scan.time_increment == pytest.approx(S300_TIME_INCREMENT, rel=FLOAT32)
        assert scan.time_increment * (len(scan.ranges) - 1) <= scan.scan_time
    for name, expected in (("warning", warning), ("protective", protective),
                           ("minimum", minimum)):
        messages = topics[FIELD_TOPICS[name]]
        assert len(messages) == len(frames)
        for _, message in messages:
            assert message.header.frame_id == "base_link"
            np.testing.assert_allclose(polygon(message), expected, atol=FLOAT32)

    assert assert_polylines_in_their_status_colours(topics) == ["new", "confirmed",
                                                               "blank"] * len(frames)
    for _, message in topics["/semistatic/people"]:
        (person,) = drawn(message)
        assert person.type == CYLINDER
        p = person.pose.position
        assert (p.x, p.y, p.z) == pytest.approx((3.0, 1.0, 1.75 / 2))
        assert (person.scale.x, person.scale.y, person.scale.z) == pytest.approx((0.5, 0.5,
                                                                                   1.75))
        assert_close_colour(person, PERSON_COLOUR, SOLID_ALPHA)
    for _, message in topics["/semistatic/boxes"]:
        (box,) = drawn(message)
        assert box.type == CUBE
        p = box.pose.position
        assert (p.x, p.y, p.z, yaw(box.pose.orientation)) == pytest.approx((2.6, -1.0, 0.3,
                                                                             0.3))
        assert (box.scale.x, box.scale.y, box.scale.z) == pytest.approx((0.5, 0.4, 0.6))
        assert_close_colour(box, BOX_COLOUR, SOLID_ALPHA)


def test_frames_without_fields_people_or_boxes_leave_those_topics_out(tmp_path):
    # A replayed real log knows none of them, nor its laser's timing (0: unknown).
    scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=1.0)
    frame = BagFrame(scan=scan, odom_pose=(0, 0, 0), ekf_pose=(0, 0, 0),
                     polylines=[[[0, 0], [1, 0]]])
    topics = read_with_rosbags(write_ros2_bag(tmp_path / "run", [frame]))
    assert sorted(topics["types"]) == ["/clock", "/ekf/odom", "/odom", "/scan",
                                       "/semistatic/polylines", "/tf", "/tf_static"]
    ((_, scan_message),) = topics["/scan"]
    assert (scan_message.scan_time, scan_message.time_increment) == (0.0, 0.0)
    ((_, markers),) = topics["/semistatic/polylines"]
    (line,) = drawn(markers)
    # Without a status a polyline is drawn in none of the status colours.
    assert line.ns == "polylines"
    assert rgba(line)[:3] not in [pytest.approx(c) for c in STATUS_COLOURS.values()]


@pytest.mark.parametrize(("change", "message"), [
    ({"polyline_status": ["new", "new"]}, "one status per polyline"),
    ({"polyline_status": ["stale"]}, "unknown status"),
    ({"fields": {"warning": np.zeros((4, 2))}}, "must have the keys"),
    ({"fields": {"warning": [[0, 0], [1, 0]], "protective": [], "minimum": []}},
     "N >= 3"),
    ({"scan_time": -0.08}, "scan_time must be a finite time >= 0"),
    ({"scan_time": 0.08, "time_increment": 0.05}, "longer than the scan time"),
    ({"people": [(1.0, 2.0)]}, r"people\[0\] must be a BagPerson"),
])
def test_bag_frame_rejects_inconsistent_extras(change, message):
    scan = Scan(ranges=[1.0, 2.0, 3.0], angle_min=0.0, angle_increment=0.1, stamp=1.0)
    arguments = {"scan": scan, "odom_pose": (0, 0, 0), "ekf_pose": (0, 0, 0),
                 "polylines": [[[0, 0], [1, 0]]], **change}
    with pytest.raises((ValueError, TypeError), match=message):
        BagFrame(**arguments)


def test_box_and_person_reject_impossible_sizes():
    with pytest.raises(ValueError, match="size must be a finite length > 0"):
        BagBox("flat", pose=(0, 0, 0), size=(0.5, 0.0, 0.6))
    with pytest.raises(ValueError, match="radius must be a finite length > 0"):
        BagPerson("ghost", position=(0, 0), radius=-0.1)


# ------------------------------------------------------------------ a tiny closed-loop run

# The tiny corridor with a person standing still beyond the path's end (clear of every
# field) and the fixed minimum field: its closed form is the protective field's first
# 0.15 m, x in [0.18, 0.33], y in [-0.65, 0.65] (tiny_world.py's corridor fields).
BYSTANDER = """
[[people]]
name = "bystander"
waypoints = [[5.5, 1.0]]
radius = 0.25
"""
TINY_RUN = """
world = "tiny_world.toml"
laps = 2
seed = 3

[mapper]
hausdorff_restriction = "projection"

[safety]
minimum_field = "fixed"
"""
TINY_WARNING = [[0.18, -0.9], [1.4, -0.9], [1.4, 0.9], [0.18, 0.9]]
TINY_PROTECTIVE = [[0.18, -0.65], [0.78, -0.65], [0.78, 0.65], [0.18, 0.65]]
TINY_MINIMUM = shapely.box(0.18, -0.65, 0.18 + 0.15, 0.65)


@pytest.fixture(scope="module")
def tiny_bag(tmp_path_factory):
    folder = tmp_path_factory.mktemp("readers")
    (folder / "tiny_world.toml").write_text(TINY_WORLD + BYSTANDER)
    scenario = folder / "tiny.toml"
    scenario.write_text(TINY_RUN)
    bag = folder / "bag"
    status = main(["run", str(scenario), "--out", str(folder / "out"), "--bag", str(bag),
                   "--bag-storage", "mcap", "--no-figures"])
    assert status == 0
    return {"bag": bag, "spec": load_scenario(scenario)}


@pytest.mark.parametrize("reader", ["rosbags", "mcap"])
def test_tiny_run_bag_as_other_readers_see_it(tiny_bag, reader):
    topics = READERS[reader](tiny_bag["bag"])
    spec = tiny_bag["spec"]
    world = scenario_world(spec)
    (segment,) = path_segments(world)
    scans = len(topics["/scan"])
    assert scans > 300  # two laps of 3.5 m at 0.4 m/s, 12.5 scans a second

    assert_frames_chain_to_the_ekf(topics)
    assert_clock_is_the_scan_stamps(topics)
    # The odometry drifts off the EKF: map -> odom is no identity.
    drift = np.array([planar(m.transforms[0]) for _, m in topics["/tf"]])
    assert np.abs(drift).max() > 1e-4

    # The fields as the corridor segment defines them, in the robot frame, every scan.
    for name, expected in (("warning", TINY_WARNING), ("protective", TINY_PROTECTIVE)):
        messages = topics[FIELD_TOPICS[name]]
        assert len(messages) == scans
        for _, message in messages:
            assert message.header.frame_id == "base_link"
            np.testing.assert_allclose(polygon(message), expected, atol=FLOAT32)
            np.testing.assert_allclose(polygon(message), getattr(segment.fields, name),
                                       atol=FLOAT32)
    for _, message in topics[FIELD_TOPICS["minimum"]]:
        outline = shapely.Polygon(polygon(message))
        assert shapely.symmetric_difference(outline, TINY_MINIMUM).area < 1e-6

    # The map: nothing is confirmed at the first scan; the second lap confirms what the
    # first mapped, drawn green.
    first, last = topics["/semistatic/polylines"][0][1], topics["/semistatic/polylines"][-1][1]
    assert {m.ns for m in drawn(first)} <= {"new"}
    confirmed = [m for m in drawn(last) if m.ns == "confirmed"]
    assert confirmed
    for marker in confirmed:
        assert_close_colour(marker, (0.0, 0.65, 0.0), 1.0)  # green
    assert "confirmed" in assert_polylines_in_their_status_colours(topics)

    # The laser: the bench's safety scans are 1/12.5 s apart (rates.safety_hz), the
    # spacing of the stamps; the simulated beams are cast at one instant.
    assert spec.rates.safety_hz == 12.5
    stamps = np.array([seconds(m.header.stamp) for _, m in topics["/scan"]])
    spacing = np.diff(stamps)
    within_laps = spacing[spacing < 0.5]
    assert within_laps.mean() == pytest.approx(0.08, abs=1.0 / 240)  # one physics step
    laser = get_preset(spec.robot).safety_laser.laser
    for _, scan in topics["/scan"]:
        assert scan.scan_time == pytest.approx(0.08, rel=FLOAT32)
        assert scan.time_increment == 0.0
        assert len(scan.ranges) == laser.num_beams == 541  # 270 deg at 0.5 deg
        assert scan.time_increment * (len(scan.ranges) - 1) <= scan.scan_time

    # The bystander where the world puts them, the carton as the TOML gives it.
    assert len(topics["/semistatic/people"]) == scans
    for _, message in topics["/semistatic/people"]:
        (person,) = drawn(message)
        assert person.type == CYLINDER
        p = person.pose.position
        assert (p.x, p.y) == pytest.approx((5.5, 1.0))
        assert person.scale.x == pytest.approx(2 * 0.25)
        assert_close_colour(person, PERSON_COLOUR, SOLID_ALPHA)
    (carton,) = world.boxes
    for _, message in topics["/semistatic/boxes"]:
        (box,) = drawn(message)
        assert box.type == CUBE
        p = box.pose.position
        assert (p.x, p.y, yaw(box.pose.orientation)) == pytest.approx((2.6, -1.0, 0.0))
        assert (box.scale.x, box.scale.y, box.scale.z) == pytest.approx((0.5, 0.4, 0.6))
        assert (p.x, p.y) == pytest.approx(carton.pose[:2])


# ------------------------------------------------------------------ sim1, end to end


@pytest.mark.slow
def test_sim1_bag_from_the_cli_as_mcap_sees_it(tmp_path):
    bag = tmp_path / "bag"
    status = main(["run", "sim1", "--laps", "2", "--out", str(tmp_path / "out"),
                   "--bag", str(bag), "--bag-storage", "mcap", "--no-figures"])
    assert status == 0
    topics = read_with_mcap(bag)
    spec = load_scenario("sim1", overrides=["laps=2"])
    world = scenario_world(spec)
    segments = path_segments(world)

    assert_frames_chain_to_the_ekf(topics)
    assert_clock_is_the_scan_stamps(topics)
    # Each scan is judged against the fields of the segment it is on: the first one's at
    # the start, every segment's on the way.
    for name in ("warning", "protective"):
        options = [np.asarray(getattr(s.fields, name)) for s in segments]
        shown = [polygon(message) for _, message in topics[FIELD_TOPICS[name]]]
        np.testing.assert_allclose(shown[0], options[0], atol=FLOAT32)
        matches = [[len(p) == len(o) and np.allclose(p, o, atol=FLOAT32) for o in options]
                   for p in shown]
        assert all(any(row) for row in matches)
        assert np.any(matches, axis=0).all()
    # The standard minimum field: behind the vehicle it is the footprint grown by the
    # general supplement Z_G (0.1 m: the S300 settings the LMS100 is given), at any speed.
    robot = get_preset(spec.robot)
    rear = np.asarray(robot.footprint)[:, 0].min() - 0.1
    for _, message in topics[FIELD_TOPICS["minimum"]]:
        assert polygon(message)[:, 0].min() == pytest.approx(rear, abs=1e-5)

    seen = assert_polylines_in_their_status_colours(topics)
    assert "confirmed" in seen
    last = topics["/semistatic/polylines"][-1][1]
    assert any(m.ns == "confirmed" for m in drawn(last))
    # sim1 has no people; its three boxes stand as the world file puts them (laps 1-2).
    assert all(drawn(message) == [] for _, message in topics["/semistatic/people"])
    expected = sorted((*b.pose[:2], *b.size) for b in world.boxes)
    assert len(expected) == 3
    for _, message in topics["/semistatic/boxes"][:: 50]:
        got = sorted((m.pose.position.x, m.pose.position.y, m.scale.x, m.scale.y, m.scale.z)
                     for m in drawn(message))
        np.testing.assert_allclose(got, expected, atol=1e-12)
    for _, scan in topics["/scan"]:
        assert scan.scan_time == pytest.approx(1.0 / spec.rates.safety_hz, rel=FLOAT32)
        assert scan.time_increment * (len(scan.ranges) - 1) <= scan.scan_time
