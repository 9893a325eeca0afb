"""Corrupt bags and hopeless logs: one error naming the file (and the topic), never a crash.

A genuine small ROS 2 bag (``write_ros2_bag``) is damaged: a garbage message in its db3,
bytes flipped inside its MCAP (hypothesis, derandomised). Reading it yields scans or
raises :class:`BagError` naming the bag; any other exception fails. ``evaluate`` on a log
whose ranges are all ``inf`` is one ``error:`` line, exit 2, nothing printed before it.
"""

from __future__ import annotations

import os
import sqlite3
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scenarios.cli import main
from semistatic.logs.rosbag import SCAN_TOPIC, BagError, read_bag, write_ros2_bag
from tests.semistatic.test_logs_rosbag import LASER_OFFSET, synthetic_frames


def _bag(folder: Path, storage: str) -> Path:
    return write_ros2_bag(folder / "run", synthetic_frames(np.random.default_rng(0)),
                          laser_offset=LASER_OFFSET, storage=storage)


def _read_all(bag: Path) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a damaged /tf_static: base pose
        return len(list(read_bag(bag)))


def test_a_garbage_scan_message_in_a_db3_names_the_bag_and_the_topic(tmp_path):
    bag = _bag(tmp_path, "sqlite3")
    assert _read_all(bag) == 6  # the genuine bag reads whole
    database = next(bag.glob("*.db3"))
    with sqlite3.connect(database) as db:
        (topic,) = db.execute("SELECT id FROM topics WHERE name = ?", (SCAN_TOPIC,)).fetchone()
        db.execute("UPDATE messages SET data = ? WHERE id = (SELECT min(id) FROM messages "
                   "WHERE topic_id = ?)", (b"\x00\xff\x13garbage", topic))
    db.close()
    with pytest.raises(BagError, match=f"{bag}: {SCAN_TOPIC}: corrupt message"):
        _read_all(bag)


def test_a_fifo_given_as_a_bag_is_refused_without_being_opened(tmp_path):
    fifo = tmp_path / "run.bag"
    os.mkfifo(fifo)
    with pytest.raises(BagError, match=r"is a FIFO \(named pipe\), expected a regular ROS bag"):
        read_bag(fifo)


@pytest.fixture(scope="module")
def mcap_bytes(tmp_path_factory) -> bytes:
    bag = _bag(tmp_path_factory.mktemp("mcap"), "mcap")
    return next(bag.glob("*.mcap")).read_bytes()


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_bytes_flipped_inside_an_mcap_are_a_bag_error_or_harmless(tmp_path_factory,
                                                                   mcap_bytes, data):
    raw = bytearray(mcap_bytes)
    for position in data.draw(st.sets(st.integers(0, len(raw) - 1), min_size=1, max_size=8)):
        raw[position] ^= data.draw(st.integers(1, 255))
    folder = tmp_path_factory.mktemp("flipped")
    bag = _bag(folder, "mcap")
    next(bag.glob("*.mcap")).write_bytes(bytes(raw))
    line, scans = None, 0
    try:
        scans = _read_all(bag)
    except BagError as error:  # any other exception fails the test
        line = str(error)
    if line is None:
        assert scans <= 6  # a flip in padding or a value: read, never more scans
    else:
        assert line.startswith(str(bag)), line
        assert "\n" not in line, line


def test_evaluate_on_a_log_of_only_inf_ranges_is_one_error_line(tmp_path, capsys):
    log = tmp_path / "inf.log"
    # 80.0 repeats on every beam: the no-return value, so every range becomes inf.
    log.write_text("".join(f"FLASER 4 80 80 80 80 0 0 0 0 0 0 {t} host {t}\n"
                           for t in range(20)))
    assert main(["evaluate", str(log), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (f"error: {log}: <file>: no valid range in any of its 4 scans (all "
                            "NaN, inf or beyond the maximum range); nothing to evaluate\n")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["inf.log"]
