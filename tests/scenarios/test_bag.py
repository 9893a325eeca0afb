"""A simulated run written as a ROS 2 bag reads back identically and replays (issue 6)."""

import json

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from scenarios.bench.runner import run_scenario
from scenarios.cli import main
from scenarios.commands.run import BAG_STORAGE_CHOICES
from scenarios.logs.bag import (
    BAG_STORAGES,
    BAG_TOPICS,
    bag_frame,
    check_new_bag_path,
    write_run_bag,
)
from scenarios.process.output_paths import check_output_paths
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario
from semistatic.errors import SpecError
from semistatic.frames import compose, inverse
from semistatic.local_map import LocalMap
from semistatic.logs.rosbag import EKF_TOPIC, MARKER_TOPIC, read_bag
from tests.scenarios.cli_helpers import assert_one_error_line, run_cli
from tests.scenarios.tiny_world import write_tiny

POSE_TOLERANCE = 1e-9  # yaw travels as a quaternion: a few ulp of round trip
STAMP_TOLERANCE = 1e-9  # stamps travel as integer nanoseconds
ODOMETRY_DRIFT_BOUND = 0.03  # m: wheel odometry over the tiny 3.5 m path stays this close


def without_performance(metrics):
    return {key: value for key, value in metrics.items() if key != "performance"}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """One lap of the tiny scenario: through the CLI with --bag, and directly with an observer.

    Same seed, so the direct run's records must be what the CLI wrote into its bag.
    """
    folder = tmp_path_factory.mktemp("bag")
    scenario = write_tiny(folder)
    bag, out = folder / "run_bag", folder / "out"
    status = main(
        ["run", str(scenario), "--laps", "1", "--out", str(out), "--bag", str(bag),
         "--no-figures"]
    )
    assert status == 0
    spec = load_scenario(scenario, overrides=["laps=1"])
    records = []
    log = run_scenario(spec, on_scan=records.append)
    return {"folder": folder, "bag": bag, "out": out, "spec": spec, "log": log,
            "records": records}


def test_observer_sees_every_safety_scan_once_in_time_order(recorded):
    log, records = recorded["log"], recorded["records"]
    assert len(records) == sum(lap.safety_scans for lap in log.laps) > 100
    stamps = np.array([record.scan.stamp for record in records])
    assert np.all(np.diff(stamps) > 0)
    assert {record.lap for record in records} == {1}
    assert {record.segment for record in records} <= {seg.name for seg in log.segments}
    assert all(record.ekf_covariance.shape == (3, 3) for record in records)


def test_observer_sees_the_local_map_grow_to_the_box(recorded):
    records, log = recorded["records"], recorded["log"]
    assert len(records[0].polylines) >= 1  # a wall is in view from the start
    final = records[-1]
    lap_map = log.maps_after_lap[0][final.segment]
    # The last record carries the segment's map as the lap left it (world frame).
    coordinates = [np.array(f["geometry"]["coordinates"]) for f in lap_map["features"]]
    assert len(final.polylines) == len(coordinates)
    for mine, theirs in zip(final.polylines, coordinates, strict=True):
        np.testing.assert_allclose(mine, theirs, atol=1e-6)


def test_observer_does_not_change_the_run_and_costs_nothing_without_it(recorded, monkeypatch):
    calls = []
    world_polylines = LocalMap.world_polylines

    def counted(self):
        calls.append(self.segment)
        return world_polylines(self)

    monkeypatch.setattr(LocalMap, "world_polylines", counted)
    plain = run_scenario(recorded["spec"])
    # Without an observer the map is only read at the lap's end (scoring), never per scan.
    assert len(calls) <= len(plain.segments) * len(plain.laps)
    observed = recorded["log"]
    assert without_performance(summarize(plain)) == without_performance(summarize(observed))
    assert plain.maps_after_lap == observed.maps_after_lap
    np.testing.assert_array_equal(np.array(plain.estimated_poses),
                                  np.array(observed.estimated_poses))


def test_odometry_drifts_apart_from_the_ekf_but_stays_near_the_truth(recorded):
    records, log = recorded["records"], recorded["log"]
    mount = log.robot.safety_laser.pose2d()
    odom = np.array([record.odom_pose for record in records])
    ekf = np.array([record.ekf_pose for record in records])
    truth = np.array([compose(record.scan.pose, inverse(mount)) for record in records])
    odom_error = np.hypot(*(odom - truth)[:, :2].T)
    ekf_error = np.hypot(*(ekf - truth)[:, :2].T)
    assert odom_error.max() < ODOMETRY_DRIFT_BOUND
    # Odometry is integrated on its own: uncorrected, it ends further off than the EKF.
    assert odom_error[-20:].mean() > ekf_error[-20:].mean()
    assert np.abs(odom - ekf).max() > 1e-3


def test_cli_bag_reads_back_with_identical_scans_and_odometry_poses(recorded):
    records, log = recorded["records"], recorded["log"]
    mount = log.robot.safety_laser.pose2d()
    scans = list(read_bag(recorded["bag"]))  # /odom by default: wheel odometry
    assert len(scans) == len(records)
    for read, record in zip(scans, records, strict=True):
        written = record.scan
        # LaserScan carries float32: ranges come back as the float32 of ours, bit for bit.
        np.testing.assert_array_equal(read.ranges, written.ranges.astype(np.float32))
        np.testing.assert_array_equal(read.intensities, written.intensities.astype(np.float32))
        assert read.stamp == pytest.approx(written.stamp, abs=STAMP_TOLERANCE)
        assert read.angle_increment == pytest.approx(written.angle_increment, rel=1e-6)
        np.testing.assert_allclose(read.pose, compose(record.odom_pose, mount),
                                   atol=POSE_TOLERANCE)


def test_cli_bag_reads_back_the_ekf_poses(recorded):
    records, log = recorded["records"], recorded["log"]
    mount = log.robot.safety_laser.pose2d()
    scans = list(read_bag(recorded["bag"], odom_topic=EKF_TOPIC))
    assert [s.stamp for s in scans] == pytest.approx([r.scan.stamp for r in records],
                                                      abs=STAMP_TOLERANCE)
    for read, record in zip(scans, records, strict=True):
        np.testing.assert_allclose(read.pose, compose(record.ekf_pose, mount),
                                   atol=POSE_TOLERANCE)


def test_cli_bag_has_every_topic_the_ekf_covariance_and_the_polylines(recorded):
    records = recorded["records"]
    with AnyReader([recorded["bag"]]) as reader:
        assert set(reader.topics) == set(BAG_TOPICS)
        assert reader.topics[MARKER_TOPIC].msgtype == "visualization_msgs/msg/MarkerArray"
        connections = [c for c in reader.connections if c.topic in (MARKER_TOPIC, EKF_TOPIC)]
        markers, ekf = [], []
        for connection, _, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            (markers if connection.topic == MARKER_TOPIC else ekf).append(message)
    assert len(markers) == len(ekf) == len(records)
    for message, odometry, record in zip(markers, ekf, records, strict=True):
        first, *lines = message.markers
        assert first.action == first.DELETEALL  # each message replaces the whole map
        assert all(line.type == line.LINE_STRIP and line.header.frame_id == "map"
                   for line in lines)
        got = [np.array([[p.x, p.y] for p in line.points]) for line in lines]
        assert len(got) == len(record.polylines)
        for mine, theirs in zip(record.polylines, got, strict=True):
            np.testing.assert_array_equal(theirs, mine)  # geometry_msgs/Point is float64
        covariance = np.array(odometry.pose.covariance).reshape(6, 6)[np.ix_([0, 1, 5], [0, 1, 5])]
        np.testing.assert_array_equal(covariance, record.ekf_covariance)


def test_cli_prints_the_bag_and_writes_the_outputs_too(recorded):
    assert (recorded["out"] / "metrics.json").is_file()
    assert sorted(p.suffix for p in recorded["bag"].iterdir()) == [".db3", ".yaml"]
    # No staging folder is left beside the bag or the outputs.
    assert sorted(p.name for p in recorded["folder"].iterdir()) == [
        "out", "run_bag", "tiny.toml", "tiny_world.toml"
    ]


def test_semistatic_replay_runs_on_the_bag(capsys, recorded, tmp_path):
    out = tmp_path / "replay"
    status, printed, err = run_cli(capsys, "replay", recorded["bag"], "--out", out,
                                   "--no-figures")
    assert status == 0, err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["scans"] == len(recorded["records"])
    assert metrics["map_polylines"] >= 2  # the corridor walls at least
    assert f"results in {out}" in printed


def test_mcap_bag_reads_back_the_same_scans(recorded, tmp_path):
    records, log = recorded["records"], recorded["log"]
    frames = [bag_frame(record) for record in records[:20]]
    bag = write_run_bag(tmp_path / "run", frames, log.robot, storage="mcap")
    assert [p.suffix for p in bag.iterdir() if p.suffix != ".yaml"] == [".mcap"]
    scans = list(read_bag(bag))
    assert len(scans) == 20
    for read, record in zip(scans, records[:20], strict=True):
        np.testing.assert_array_equal(read.ranges, record.scan.ranges.astype(np.float32))


def test_failed_write_leaves_no_bag_and_no_staging(recorded, tmp_path):
    records, log = recorded["records"], recorded["log"]

    def frames_then_failure():
        yield bag_frame(records[0])
        yield bag_frame(records[1])
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        write_run_bag(tmp_path / "run", frames_then_failure(), log.robot)
    assert list(tmp_path.iterdir()) == []


def test_cli_storage_choices_match_the_writer():
    assert BAG_STORAGE_CHOICES == BAG_STORAGES


@pytest.mark.parametrize(
    ("bag_name", "fragments"),
    [
        ("existing", ["existing", "--bag", "exists already", "choose a new directory"]),
        ("no/parent/bag", ["no/parent/bag", "--bag", "parent directory", "does not exist"]),
        # Every command's overlap check (scenarios.process.output_paths) answers first.
        ("out", ["out", "--bag", "is --out", "replaced as a whole"]),
    ],
)
def test_bad_bag_path_exits_2_before_the_run(capsys, tmp_path, bag_name, fragments):
    scenario = write_tiny(tmp_path)
    (tmp_path / "existing").mkdir()
    out = tmp_path / "out"
    status, printed, err = run_cli(capsys, "run", scenario, "--laps", "1", "--out", out,
                                   "--bag", tmp_path / bag_name)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert printed == ""
    assert not out.exists()
    assert list((tmp_path / "existing").iterdir()) == []


def test_bag_may_go_inside_the_output_directory_not_around_it(tmp_path):
    out = tmp_path / "results"
    assert check_new_bag_path(out / "bag", out=out) == out / "bag"  # out is written first
    with pytest.raises(SpecError, match=r"--out: .*: is inside --bag"):
        check_output_paths({"--out": tmp_path / "outer" / "results",
                            "--bag": tmp_path / "outer"}, into_result=["--bag"])
    with pytest.raises(ValueError, match="does not exist"):
        check_new_bag_path(out / "deeper" / "bag", out=out)
