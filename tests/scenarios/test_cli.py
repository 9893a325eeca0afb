"""The command line contract: exit status 2 and one error line on bad input, nothing written."""

import gzip
import json

import numpy as np
import pytest

from tests.scenarios.cli_helpers import assert_one_error_line, run_cli
from tests.scenarios.tiny_world import write_tiny


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["run", "no/such/file.toml"], ["no/such/file.toml", "no such file"]),
        (["run", "sim3"], ["sim3", "did you mean"]),
        (["run", "sim1", "--laps", "-1"], ["laps", "must be >= 1"]),
        (["run", "sim1", "--set", "mapper.gte=0.2"], ["--set", "mapper.gte", "'gate'"]),
        (["run", "sim1", "--set", "polcy=adaptive"], ["--set", "polcy", "'policy'"]),
        (["run", "sim1", "--set", "laps"], ["--set", "KEY=VALUE"]),
        (["run", "sim1", "--set", "policy=greedy"], ["policy", "conservative, adaptive"]),
    ],
)
def test_bad_run_input_exits_2_and_writes_nothing(capsys, tmp_path, args, fragments):
    out = tmp_path / "out"
    status, _, err = run_cli(capsys, *args, "--out", out)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert not out.exists()


def test_not_toml_and_unknown_key_name_the_file(capsys, tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text("laps = [1, \n")
    status, _, err = run_cli(capsys, "run", broken, "--out", tmp_path / "a")
    assert status == 2
    assert_one_error_line(err, "broken.toml", "not valid TOML")

    typo = write_tiny(tmp_path, scenario='world = "tiny_world.toml"\nlapz = 2\n')
    status, _, err = run_cli(capsys, "run", typo, "--out", tmp_path / "b")
    assert status == 2
    assert_one_error_line(err, str(typo), "lapz", "did you mean 'laps'")
    assert not (tmp_path / "a").exists()
    assert not (tmp_path / "b").exists()


def test_replay_bad_logs_exit_2(capsys, tmp_path):
    status, _, err = run_cli(capsys, "replay", tmp_path / "missing.log")
    assert status == 2
    assert_one_error_line(err, "missing.log")

    bad = tmp_path / "bad.log"
    bad.write_text("FLASER 3 1.0 oops 1.0 0 0 0 0 0 0 1.0 host 1.0\n")
    status, _, err = run_cli(capsys, "replay", bad, "--out", tmp_path / "r")
    assert status == 2
    assert_one_error_line(err, "bad.log:1")
    assert not (tmp_path / "r").exists()

    status, _, err = run_cli(capsys, "replay", bad, "--set", "mapper.gat=0.1")
    assert status == 2
    assert_one_error_line(err, "mapper.gat", "'gate'")


def test_replay_writes_its_outputs(capsys, tmp_path):
    # A robot driving along a corridor and back: two passes over the same walls.
    angles = np.radians(np.arange(-90.0, 90.0, 1.0))
    lines = []
    xs = [*np.arange(0.0, 3.0, 0.1), *np.arange(3.0, 0.0, -0.1)]
    for k, x in enumerate(xs):
        theta = 0.0 if k < 30 else np.pi
        heading = angles + theta
        with np.errstate(divide="ignore"):
            to_left = np.where(np.sin(heading) > 1e-9, (1.0) / np.sin(heading), np.inf)
            to_right = np.where(np.sin(heading) < -1e-9, (-1.0) / np.sin(heading), np.inf)
        ranges = np.minimum(np.minimum(to_left, to_right), 81.83)
        values = " ".join(f"{r:.3f}" for r in ranges)
        pose = f"{x:.3f} 0.0 {theta:.6f}"
        lines.append(f"FLASER {len(ranges)} {values} {pose} {pose} {k * 30.0:.1f} test {k:.1f}")
    log = tmp_path / "corridor.log.gz"
    with gzip.open(log, "wt") as stream:
        stream.write("\n".join(lines) + "\n")
    out = tmp_path / "replay"
    status, stdout, err = run_cli(capsys, "replay", log, "--out", out, "--tile", "2")
    assert status == 0, err
    assert "revisit consistency" in stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["scans"] == len(xs)
    assert metrics["revisit_scans"] > 0
    assert metrics["table1_cm"]["mean"]["avg"] < 5.0
    assert (out / "figures" / "replay_map.png").stat().st_size > 5000
    assert (out / "table1.csv").read_text().startswith("environment,")
