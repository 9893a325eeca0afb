"""Replay on a synthetic log whose second pass is logged with a known pose offset.

The scans are ray cast from the true poses with CARMEN's 180 one-degree beams; the log
records the true pose on the first pass and an offset pose on the second, the way a SLAM
back end can place a revisit a few centimetres off.
"""

import dataclasses
import gzip
import itertools
import json
import math

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.logs.real_log import ReplayOptions, replay_log
from semistatic.alignment import AlignmentParams
from semistatic.types import Scan
from tests.semistatic.synthetic import box, raycast, scene, wall

ROOM = scene(
    wall((-5.0, -3.5), (5.0, -3.5)),
    wall((5.0, -3.5), (5.0, 3.5)),
    wall((5.0, 3.5), (-5.0, 3.5)),
    wall((-5.0, 3.5), (-5.0, -3.5)),
    box((0.0, 0.0), 2.0, 1.2),
    box((3.8, 2.4), 0.6, 0.6, yaw=0.4),
    box((-3.9, -2.5), 0.8, 0.5),
)
ANGLES = np.radians(np.arange(-90.0, 90.0, 1.0))
NO_RETURN = 81.83
OFFSET = np.array([0.05, -0.03, math.radians(0.4)])
OPTIONS = ReplayOptions(tile_size=4.0, revisit_gap=5.0)


def loop_poses(step=0.25):
    corners = np.array([[-3.0, -2.2], [3.0, -2.2], [3.0, 2.2], [-3.0, 2.2], [-3.0, -2.2]])
    poses = []
    for start, end in itertools.pairwise(corners):
        heading = math.atan2(*(end - start)[::-1])
        count = round(float(np.hypot(*(end - start))) / step)
        for k in range(count):
            x, y = start + (end - start) * k / count
            poses.append((x, y, heading))
    return np.array(poses)


def synthetic_log(offset=OFFSET, *, seed=0, noise=0.005):
    """Return two laps of scans; the second lap's logged poses are off by ``offset``."""
    rng = np.random.default_rng(seed)
    scans = []
    poses = loop_poses()
    for lap in range(2):
        for k, pose in enumerate(poses):
            ranges = raycast(ROOM, pose, ANGLES) + rng.normal(0.0, noise, ANGLES.size)
            logged = pose + (np.asarray(offset) if lap else 0.0)
            scans.append(Scan(ranges=np.where(np.isfinite(ranges), ranges, NO_RETURN),
                              angle_min=ANGLES[0], angle_increment=math.radians(1.0),
                              range_max=NO_RETURN - 0.01, stamp=lap * 100.0 + k, pose=logged))
    return scans


@pytest.fixture(scope="module")
def aligned_and_raw():
    scans = synthetic_log()
    aligned = replay_log(scans, OPTIONS)
    raw = replay_log(scans, dataclasses.replace(OPTIONS, align=False))
    return aligned.summary(), raw.summary()


def test_alignment_recovers_the_offset_of_the_second_pass(aligned_and_raw):
    aligned, _ = aligned_and_raw
    alignment = aligned["alignment"]
    assert aligned["revisit_scans"] > 20
    assert alignment["attempted"] == aligned["revisit_scans"]
    assert alignment["accepted"] >= 0.8 * alignment["attempted"]
    # Corrections are the offset, whatever the scan.
    assert alignment["translation_cm"]["median"] == pytest.approx(
        100 * np.hypot(*OFFSET[:2]), abs=0.5
    )
    assert alignment["rotation_deg"]["median"] == pytest.approx(math.degrees(OFFSET[2]), abs=0.1)
    assert alignment["rms_after_cm"]["median"] < alignment["rms_before_cm"]["median"]


def test_aligned_revisits_are_consistent_and_the_raw_figure_is_kept(aligned_and_raw):
    aligned, raw = aligned_and_raw
    at_log_pose = aligned["alignment"]["table1_cm_log_pose"]
    assert at_log_pose == raw["table1_cm"]  # the same association at the logged poses
    assert raw["table1_cm"]["mean"]["avg"] > 4.0  # a 5.8 cm, 0.4 deg offset shows
    assert aligned["table1_cm"]["mean"]["avg"] < 2.0
    assert aligned["table1_cm"]["polylines"] >= raw["table1_cm"]["polylines"]


def test_alignment_leaves_extraction_and_maps_alone(aligned_and_raw):
    aligned, raw = aligned_and_raw
    assert aligned["extraction"] == raw["extraction"]
    assert aligned["map_polylines"] == raw["map_polylines"]
    assert aligned["params"]["align"] is True
    assert raw["params"]["align"] is False
    assert raw["alignment"] is None
    assert raw["performance"]["alignment_ms_median"] is None


def test_consistent_log_is_not_made_to_look_better():
    # Logged poses already right: the corrections are small (the reference is a 3 cm
    # Douglas-Peucker polyline map, not the truth) and Table 1 does not shrink.
    summary = replay_log(synthetic_log(offset=(0.0, 0.0, 0.0), seed=1), OPTIONS).summary()
    alignment = summary["alignment"]
    assert alignment["translation_cm"]["median"] < 1.0
    assert alignment["rotation_deg"]["median"] < 0.1
    assert summary["table1_cm"]["mean"]["avg"] == pytest.approx(
        alignment["table1_cm_log_pose"]["mean"]["avg"], abs=0.1
    )


def test_rejected_alignments_keep_the_logged_pose():
    options = dataclasses.replace(OPTIONS, alignment=AlignmentParams(min_points=100_000))
    summary = replay_log(synthetic_log(seed=2), options).summary()
    alignment = summary["alignment"]
    assert alignment["accepted"] == 0
    assert alignment["rejected"] == {"too few points": alignment["attempted"]}
    assert alignment["translation_cm"]["median"] is None
    assert summary["table1_cm"] == alignment["table1_cm_log_pose"]


def test_corrections_beyond_the_bound_are_refused():
    options = dataclasses.replace(OPTIONS, alignment=AlignmentParams(max_translation=0.03))
    alignment = replay_log(synthetic_log(seed=2), options).summary()["alignment"]
    refused = alignment["rejected"].get("translation beyond max_translation", 0)
    assert refused >= 0.8 * alignment["attempted"]  # the offset is 5.8 cm


def test_same_log_same_summary():
    scans = synthetic_log(seed=3)
    first, second = replay_log(scans, OPTIONS).summary(), replay_log(scans, OPTIONS).summary()
    first.pop("performance")
    second.pop("performance")
    assert first == second


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"align": "yes"}, "ReplayOptions.align"),
        ({"alignment": {"max_distance": 0.2}}, "ReplayOptions.alignment"),
        ({"every": 0}, "ReplayOptions.every"),
        ({"tile_size": 0.0}, "ReplayOptions.tile_size"),
        ({"revisit_gap": -1.0}, "ReplayOptions.revisit_gap"),
    ],
)
def test_options_are_validated(changes, message):
    with pytest.raises(ValueError, match=message):
        ReplayOptions(**changes)


def write_carmen(scans, path):
    lines = []
    for scan in scans:
        values = " ".join(f"{r:.3f}" for r in scan.ranges)
        pose = " ".join(f"{v:.6f}" for v in scan.pose)
        lines.append(f"FLASER {len(scan.ranges)} {values} {pose} {pose} {scan.stamp:.1f} "
                     f"test {scan.stamp:.1f}")
    with gzip.open(path, "wt") as stream:
        stream.write("\n".join(lines) + "\n")


@pytest.mark.parametrize("flag", ["--align", "--no-align", None])
def test_cli_align_flag(capsys, tmp_path, flag):
    log = tmp_path / "offset.log.gz"
    write_carmen(synthetic_log(seed=4), log)
    out = tmp_path / "replay"
    args = ["replay", str(log), "--out", str(out), "--tile", "4", "--no-figures"]
    status = main(args + ([flag] if flag else []))
    stdout = capsys.readouterr().out
    assert status == 0
    metrics = json.loads((out / "metrics.json").read_text())
    aligned = flag != "--no-align"  # aligning is the default
    assert metrics["params"]["align"] is aligned
    assert ("at the logged poses" in stdout) is aligned
    assert (metrics["alignment"] is not None) is aligned


@pytest.mark.parametrize("flag", ["--auto-noise", "--no-auto-noise"])
def test_cli_auto_noise_flag(capsys, tmp_path, flag):
    log = tmp_path / "offset.log.gz"
    write_carmen(synthetic_log(seed=4), log)
    out = tmp_path / "replay"
    args = ["replay", str(log), "--out", str(out), "--tile", "4", "--no-figures"]
    assert main(args + ([flag] if flag else [])) == 0
    assert "range noise" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["params"]["auto_noise"] is (flag == "--auto-noise")
    assert (metrics["noise"]["rule"] is not None) is (flag == "--auto-noise")
