import gzip
import math
import re
from pathlib import Path

import numpy as np
import pytest

from semistatic.logs.carmen import (
    DEFAULT_FLASER_MAX_RANGE,
    LogFormatError,
    ReadStats,
    flaser_angles,
    infer_no_return,
    read_carmen,
)

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"

# The table of /work/shared/data/README.md.
REAL_LOGS = [
    ("intel-corrected.log.gz", 910, 180, math.radians(1.0), 81.83),
    ("aces-corrected.log.gz", 440, 180, math.radians(1.0), 50.0),
    ("freiburg-079-corrected.log.gz", 4791, 360, math.radians(0.5), 81.91),
    ("csail-robotlaser1-corrected.log.gz", 686, 361, 0.008727, 80.0),
]


def flaser_line(ranges, pose=(1.0, 2.0, 0.5), stamp=10.0):
    values = " ".join(str(r) for r in ranges)
    x, y, theta = pose
    return f"FLASER {len(ranges)} {values} {x} {y} {theta} {x} {y} {theta} {stamp} host {stamp}\n"


def robotlaser1_line(ranges, remissions=(), pose=(3.0, -1.0, 3.0), stamp=7.0):
    values = " ".join(str(r) for r in ranges)
    rem = " ".join(str(r) for r in remissions)
    x, y, theta = pose
    return (
        f"ROBOTLASER1 0 -1.5 3.0 0.01 20.0 0.01 0 {len(ranges)} {values} {len(remissions)} {rem} "
        f"{x} {y} {theta} 0 0 0 0.1 0.0 0.5 0.3 1.0 {stamp} host {stamp}\n"
    )


def write(tmp_path, text, name="run.log"):
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD = [1.0, 2.0, 3.0, 4.0]


@pytest.mark.parametrize(("name", "count", "beams", "increment", "range_max"), REAL_LOGS)
def test_real_logs_parse_with_the_readme_counts(name, count, beams, increment, range_max):
    path = DATA / name
    if not path.is_file():
        pytest.skip(f"real CARMEN logs not found at {DATA} (expected beside the repository)")
    stats = ReadStats()
    scans = list(read_carmen(path, stats=stats))
    assert len(scans) == count
    assert stats.scans == count
    assert stats.malformed == 0
    assert {len(s) for s in scans} == {beams}
    first = scans[0]
    assert first.angle_min == pytest.approx(-math.pi / 2, abs=1e-6)
    assert first.angle_increment == pytest.approx(increment, abs=1e-9)
    assert first.range_max == pytest.approx(range_max)
    ranges = np.concatenate([s.ranges for s in scans])
    # The no-return sentinel became inf, nothing at or above the limit is left.
    assert np.isinf(ranges).any()
    assert np.nanmax(ranges[np.isfinite(ranges)]) < range_max
    poses = np.array([s.pose for s in scans])
    assert np.isfinite(poses).all()
    assert np.all(np.abs(poses[:, 2]) <= math.pi)
    # The robot moves: these are real runs, not a parked sensor.
    assert np.ptp(poses[:, 0]) > 5.0


def test_flaser_record_fields(tmp_path):
    path = write(tmp_path, "# c\nPARAM a 1 h 0\nODOM 0 0 0 0 0 0 1 h 1\n" + flaser_line(GOOD))
    (scan,) = read_carmen(path, max_range=3.5)
    np.testing.assert_array_equal(scan.ranges, [1.0, 2.0, 3.0, np.inf])
    np.testing.assert_array_equal(scan.pose, [1.0, 2.0, 0.5])
    assert scan.stamp == 10.0
    assert scan.range_max == 3.5
    assert scan.intensities is None


def test_flaser_angle_convention():
    assert flaser_angles(180) == pytest.approx((-math.pi / 2, math.pi / 180))
    assert flaser_angles(181) == pytest.approx((-math.pi / 2, math.pi / 180))
    assert flaser_angles(360) == pytest.approx((-math.pi / 2, math.pi / 360))
    assert flaser_angles(401) == pytest.approx((-math.radians(50), math.radians(0.25)))
    assert flaser_angles(100) == pytest.approx((-math.pi / 2, math.pi / 99))
    with pytest.raises(ValueError, match="beam_count"):
        flaser_angles(1)


def test_pose_heading_is_wrapped(tmp_path):
    path = write(tmp_path, flaser_line(GOOD, pose=(0.0, 0.0, 4.0)))
    (scan,) = read_carmen(path)
    assert scan.pose[2] == pytest.approx(4.0 - 2 * math.pi)


def test_robotlaser1_record_fields(tmp_path):
    text = robotlaser1_line([1.0, 25.0, 2.0], remissions=[0.1, 0.2, 0.9])
    (scan,) = read_carmen(write(tmp_path, text))
    assert scan.angle_min == -1.5
    assert scan.angle_increment == 0.01
    assert scan.range_max == 20.0
    np.testing.assert_array_equal(scan.ranges, [1.0, np.inf, 2.0])
    np.testing.assert_array_equal(scan.intensities, [0.1, 0.2, 0.9])
    np.testing.assert_allclose(scan.pose, [3.0, -1.0, 3.0])
    assert scan.stamp == 7.0


def test_robotlaser1_user_max_range_takes_the_smaller(tmp_path):
    (scan,) = read_carmen(write(tmp_path, robotlaser1_line([1.0, 5.0, 2.0])), max_range=4.0)
    np.testing.assert_array_equal(scan.ranges, [1.0, np.inf, 2.0])
    assert scan.range_max == 4.0
    assert scan.intensities is None


def test_gzip_and_plain_give_the_same_scans(tmp_path):
    text = flaser_line(GOOD) + "ODOM 0 0 0 0 0 0 1 h 1\n" + flaser_line([5.0, 6.0, 7.0, 8.0])
    plain = write(tmp_path, text)
    packed = tmp_path / "run.log.gz"
    with gzip.open(packed, "wt") as stream:
        stream.write(text)
    a, b = list(read_carmen(plain)), list(read_carmen(packed))
    assert len(a) == len(b) == 2
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.ranges, y.ranges)
        np.testing.assert_array_equal(x.pose, y.pose)


def test_no_return_is_inferred_from_the_repeated_maximum(tmp_path):
    lines = [flaser_line([1.0, 50.0, 50.0, 49.9]) for _ in range(3)]
    path = write(tmp_path, "".join(lines))
    assert infer_no_return(path) == 50.0
    scans = list(read_carmen(path))
    np.testing.assert_array_equal(scans[0].ranges, [1.0, np.inf, np.inf, 49.9])


def test_unrepeated_maximum_is_a_reading_and_the_default_limit_applies(tmp_path):
    path = write(tmp_path, flaser_line([1.0, 30.0, 85.0, 2.0]))
    assert infer_no_return(path) is None
    (scan,) = read_carmen(path)
    assert scan.range_max == DEFAULT_FLASER_MAX_RANGE
    np.testing.assert_array_equal(scan.ranges, [1.0, 30.0, np.inf, 2.0])


BAD_LINES = {
    "truncated": ("FLASER 4 1.0 2.0 3.0\n", "truncated record"),
    "wrong_beam_count": (flaser_line(GOOD).replace("FLASER 4", "FLASER 5"), "wrong beam count"),
    "extra_fields": (flaser_line(GOOD).replace("FLASER 4", "FLASER 3"), "wrong beam count"),
    "non_numeric_range": (flaser_line([1.0, "abc", 3.0, 4.0]), "non-numeric field 'abc'"),
    "non_numeric_pose": (flaser_line(GOOD, pose=(1.0, "y?", 0.0)), "non-numeric field 'y?'"),
    "non_integer_count": (flaser_line(GOOD).replace("FLASER 4", "FLASER four"), "integer"),
    "robotlaser1_truncated": (robotlaser1_line(GOOD)[:60] + "\n", "ROBOTLASER1: truncated"),
    "robotlaser1_bad_count": (
        robotlaser1_line(GOOD).replace(" 0 4 ", " 0 6 ", 1),
        "ROBOTLASER1: remission count must be an integer, got '-1.0' (is the beam count right?)",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_LINES))
def test_malformed_line_names_file_and_line(tmp_path, case):
    bad, what = BAD_LINES[case]
    path = write(tmp_path, "# header\n" + flaser_line(GOOD) + "ODOM 1 2 3 0 0 0 1 h 1\n" + bad)
    scans = read_carmen(path, max_range=80.0)
    first = next(scans)  # streaming: the good record comes out before the bad one is read
    np.testing.assert_array_equal(first.ranges, GOOD)
    with pytest.raises(LogFormatError) as error:
        next(scans)
    assert str(error.value).startswith(f"{path}:4: ")
    assert what in str(error.value)
    assert isinstance(error.value, ValueError)


def test_wrong_beam_count_mid_file_reports_its_line(tmp_path):
    lines = [flaser_line(GOOD)] * 6
    lines[4] = flaser_line([1.0, 2.0, 3.0])[:-1] + " 9.9\n"  # 3 beams declared, 4 present
    path = write(tmp_path, "".join(lines))
    with pytest.raises(LogFormatError, match=r":5: FLASER: wrong beam count"):
        list(read_carmen(path))


def test_empty_file_is_a_clear_error(tmp_path):
    path = write(tmp_path, "")
    with pytest.raises(LogFormatError, match="no laser records"):
        list(read_carmen(path))


def test_file_without_laser_records_is_a_clear_error(tmp_path):
    path = write(tmp_path, "# only odometry\nODOM 0 0 0 0 0 0 1 h 1\n")
    with pytest.raises(LogFormatError, match=re.escape(f"{path}: no laser records")):
        list(read_carmen(path))


def test_missing_file_fails_at_the_call(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.log"):
        read_carmen(tmp_path / "nope.log")


def test_bad_max_range_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="max_range must be > 0"):
        read_carmen(write(tmp_path, flaser_line(GOOD)), max_range=0.0)


def test_truncated_gzip_is_a_format_error(tmp_path):
    text = "".join(flaser_line([float(i), 2.0, 3.0, 4.0]) for i in range(2000))
    packed = gzip.compress(text.encode())
    path = tmp_path / "cut.log.gz"
    path.write_bytes(packed[: len(packed) // 2])
    with pytest.raises(LogFormatError, match=r"cut\.log\.gz"):
        list(read_carmen(path, max_range=80.0))


def test_lenient_mode_skips_and_counts(tmp_path):
    lines = [
        flaser_line(GOOD),
        "FLASER 4 1.0\n",
        flaser_line([1.0, "x", 3.0, 4.0]),
        "NEFF 12.3\n",
        flaser_line([9.0, 8.0, 7.0, 6.0]),
        robotlaser1_line(GOOD).replace(" 0 4 ", " 0 2 ", 1),
    ]
    path = write(tmp_path, "".join(lines))
    stats = ReadStats()
    scans = list(read_carmen(path, lenient=True, stats=stats, max_range=80.0))
    assert [s.ranges[0] for s in scans] == [1.0, 9.0]
    assert stats.scans == 2
    assert stats.malformed == 3
    assert stats.lines == 6
    assert [m.split(": ")[0] for m in stats.messages] == [f"{path}:2", f"{path}:3", f"{path}:6"]


def test_lenient_mode_with_only_bad_records_still_fails(tmp_path):
    path = write(tmp_path, "FLASER 4 1.0\nFLASER x\n")
    with pytest.raises(LogFormatError, match=r"no laser records .*2 malformed skipped"):
        list(read_carmen(path, lenient=True))


def test_unknown_messages_are_skipped(tmp_path):
    text = "RAWLASER1 1 2 3\nFLASERX 4 1 2 3\nTRUEPOS 1 2 3\n" + flaser_line(GOOD)
    assert len(list(read_carmen(write(tmp_path, text)))) == 1
