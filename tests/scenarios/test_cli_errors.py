"""Every bad input ends the same way: exit 2, one ``error:`` line naming the file and key or
the option, nothing written, and no PyBullet started (issue 12's failure classes)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from scenarios.spec.load import bundled_scenarios
from sim.client import SimClient
from tests.scenarios.cli_helpers import assert_one_error_line, run_cli
from tests.scenarios.tiny_world import TINY_SCENARIO, TINY_WORLD, write_tiny


@pytest.fixture
def no_simulation(monkeypatch):
    """Fail the test if anything starts PyBullet or runs a scenario."""

    def refuse(*_args, **_kwargs):
        raise AssertionError("PyBullet started before the input was validated")

    monkeypatch.setattr(SimClient, "__init__", refuse)


FORKS: list[int] = []
os.register_at_fork(before=lambda: FORKS.append(os.getpid()))
"""Every fork of this process (a worker pool's or the kernel compilation's), as it happens."""


def _files(folder: Path) -> set[Path]:
    return {path for path in folder.rglob("*")}


def _expect_error(capsys, folder: Path, *args, fragments=()) -> str:
    """Run the CLI, check exit 2, one error line with ``fragments``, nothing new in folder."""
    before = _files(folder)
    status, out, err = run_cli(capsys, *args)
    assert status == 2, (out, err)
    assert_one_error_line(err, *fragments)
    assert _files(folder) == before
    return err


def _tiny_with_world(folder: Path, old: str, new: str) -> Path:
    assert old in TINY_WORLD
    path = write_tiny(folder)
    (folder / "tiny_world.toml").write_text(TINY_WORLD.replace(old, new, 1))
    return path


# --- 1. lap 1 is checked; 7. values have physical bounds ---------------------------------

@pytest.mark.parametrize(
    ("old", "new", "fragments"),
    [
        ("pose = [2.6, -1.0, 0.0]", "pose = [2.6, -1.4, 0.0]",
         ["tiny_world.toml", "boxes[0]", "lap 1", "overlaps walls[0]"]),
        ("pose = [2.6, -1.0, 0.0]", "pose = [0.0, 0.0, 0.0]",
         ["tiny_world.toml", "boxes[0]", "lap 1", "swept robot footprint overlaps"]),
        ("{ x = -2.0, y = -1.39 }, { x = 0.0, y = -1.39 }, { x = 2.0, y = -1.39 },\n"
         "    { x = 4.0, y = -1.39 }, { x = 6.0, y = -1.39 },\n"
         "    { x = -1.0, y = 1.39 }, { x = 1.0, y = 1.39 }, { x = 3.0, y = 1.39 }, "
         "{ x = 5.0, y = 1.39 },\n    { x = -2.39, y = 0.3 }, { x = 6.39, y = -0.3 },",
         "{ x = 0.0, y = -1.39 }, { x = 2.0, y = -1.39 },",
         ["tiny_world.toml", "posts", "lap 1", "fewer than 3 posts"]),
        ("speed = 0.4", "speed = 1e9", ["tiny_world.toml", "path.speed", "<= 2.0"]),
        ("{ x = 6.0, y = -1.39 }", "{ x = 6.0e7, y = -1.39 }",
         ["tiny_world.toml", "posts[4].x", "<= 1000.0"]),
    ],
    ids=["box-in-wall", "box-on-start", "two-posts", "speed-1e9", "far-post"],
)
def test_bad_worlds_are_rejected_before_pybullet(capsys, tmp_path, no_simulation, old, new,
                                                 fragments):
    scenario = _tiny_with_world(tmp_path, old, new)
    _expect_error(capsys, tmp_path, "run", scenario, "--out", tmp_path / "out",
                  fragments=fragments)
    _expect_error(capsys, tmp_path, "check", scenario, fragments=fragments)


def test_a_world_without_posts_is_rejected(capsys, tmp_path, no_simulation):
    text = TINY_WORLD[: TINY_WORLD.index("posts = [")] + TINY_WORLD[TINY_WORLD.index("[path]"):]
    scenario = write_tiny(tmp_path)
    (tmp_path / "tiny_world.toml").write_text(text)
    _expect_error(capsys, tmp_path, "run", scenario, "--out", tmp_path / "out",
                  fragments=["posts", "lap 1", "the worst 0"])


# --- 6. errors name what the user typed; 9. names never become paths outside ------------

@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["run", "sim1", "--laps", "0"], ["error: --laps: laps: must be >= 1"]),
        (["run", "sim1", "--seed", "-1"], ["error: --seed: seed: must be >= 0"]),
        (["run", "sim1", "--set", "laps=0"], ["error: --set: laps: must be >= 1"]),
        (["check", "sim1", "--laps", "5000"], ["error: --laps: laps: must be >= 1 and <= 1000"]),
        (["run", "sim1", "--set", "path=1"], ["--set", "path", "unknown key"]),
        (["run", "sim1", "--set", "name=../../etc"], ["--set", "name", "not a usable name"]),
        (["table", "--jobs", "0"], ["error: --jobs: jobs: must be >= 1"]),
        (["replay", "x.log", "--max-range", "-1"], ["error: --max-range: max_range: must be > 0"]),
        (["replay", "x.log", "--every", "0"], ["error: --every: every: must be >= 1"]),
        (["replay", "x.log", "--set", "mapper.gate=abc"],
         ["error: --set: mapper.gate: expected a number, got a string 'abc'"]),
    ],
)
def test_option_errors_name_the_option(capsys, tmp_path, monkeypatch, no_simulation, args,
                                      fragments):
    monkeypatch.chdir(tmp_path)
    _expect_error(capsys, tmp_path, *args, fragments=fragments)


def test_scenario_name_cannot_leave_the_results_folder(capsys, tmp_path, no_simulation):
    scenario = write_tiny(tmp_path, scenario='name = "../escape"\n' + TINY_SCENARIO)
    _expect_error(capsys, tmp_path, "run", scenario,
                  fragments=[str(scenario), "name", "not a usable name"])


def test_box_names_are_names_not_paths(capsys, tmp_path, no_simulation):
    scenario = _tiny_with_world(tmp_path, 'name = "carton"', 'name = "../../carton"')
    _expect_error(capsys, tmp_path, "check", scenario,
                  fragments=["tiny_world.toml", "boxes[0].name", "not a usable name"])


def test_a_directory_given_as_scenario_says_so(capsys, tmp_path, no_simulation):
    _expect_error(capsys, tmp_path, "run", tmp_path,
                  fragments=[str(tmp_path), "is a directory", "scenario .toml"])


# --- input robustness: one key per --set, printable names, --jobs, nesting ---------------

@pytest.mark.parametrize(
    ("text", "shown"),
    [("seed=3\nlaps=7", "a line break ('\\n')"), ("seed=3\rlaps=7", "a line break ('\\r')")],
    ids=["newline", "cr"],
)
def test_set_takes_one_key_on_one_line(capsys, tmp_path, no_simulation, text, shown):
    err = _expect_error(capsys, tmp_path, "check", "sim1", "--set", text,
                        fragments=[f"error: --set: {text!r}: holds {shown}; one --set sets "
                                   "one KEY=VALUE on one line: give each key its own --set"])
    assert "\r" not in err


def test_a_world_name_with_an_escape_sequence_is_refused_escaped(capsys, tmp_path,
                                                                 no_simulation):
    scenario = _tiny_with_world(tmp_path, 'name = "tiny"', 'name = "\\u001b[31mred"')
    err = _expect_error(capsys, tmp_path, "check", scenario,
                        fragments=["tiny_world.toml: name: '\\x1b[31mred' holds the "
                                   "unprintable character '\\x1b' at position 0"])
    assert "\x1b" not in err


def test_an_escape_sequence_in_a_file_name_is_printed_escaped(capsys, tmp_path, no_simulation):
    # The error names the file as typed; the one line still holds no raw ESC.
    err = _expect_error(capsys, tmp_path, "check", tmp_path / "\x1b[31mnone.toml",
                        fragments=["\\x1b[31mnone.toml: <file>: no such file"])
    assert "\x1b" not in err


def _jobs_limit() -> int:
    """4 per CPU this process may run on, as ``nproc`` counts them."""
    return 4 * len(os.sched_getaffinity(0))


@pytest.mark.parametrize(
    "command",
    [["table"], ["tune", "sim1", "--grid", "mapper.gate=0.1,0.2"], ["campaign", "sim1"],
     ["falsify", "sim1", "--vary", "safety.slowdown=uniform(0.3, 0.6)"]],
    ids=["table", "tune", "campaign", "falsify"],
)
def test_jobs_above_4_per_cpu_are_refused_before_any_process(capsys, tmp_path, no_simulation,
                                                             command):
    limit = _jobs_limit()
    forks = len(FORKS)
    _expect_error(capsys, tmp_path, *command, "--jobs", limit + 1, "--out", tmp_path / "out",
                  fragments=[f"error: --jobs: jobs: must be >= 1 and <= {limit}, got "
                             f"{limit + 1} (4 per CPU of the {limit // 4} this process may use)"])
    assert len(FORKS) == forks  # neither a worker pool nor the kernel compilation forked
    _expect_error(capsys, tmp_path, *command, "--jobs", 100_000, "--out", tmp_path / "out",
                  fragments=["--jobs", f"<= {limit}, got 100000"])
    assert len(FORKS) == forks


def test_a_world_nested_100000_deep_is_one_line(capsys, tmp_path, no_simulation):
    scenario = write_tiny(tmp_path)
    nested = "deep = " + "[" * 100_000 + "]" * 100_000 + "\n"
    (tmp_path / "tiny_world.toml").write_text(TINY_WORLD + nested)
    line = TINY_WORLD.count("\n") + 1
    _expect_error(capsys, tmp_path, "check", scenario,
                  fragments=[f"{scenario}: world: {tmp_path / 'tiny_world.toml'}: arrays and "
                             f"tables nest deeper than 64 levels (at line {line})"])
    (tmp_path / "tiny_world.toml").write_text(TINY_WORLD)
    scenario.write_text(scenario.read_text() + nested)
    _expect_error(capsys, tmp_path, "check", scenario,
                  fragments=[f"{scenario}: <file>: arrays and tables nest deeper than 64 levels"])
    _expect_error(capsys, tmp_path, "check", "sim1", "--set", "people=" + "[" * 100_000,
                  fragments=["error: --set: people: arrays and tables nest deeper than 64"])


def test_manifests_nested_100000_deep_are_one_line(capsys, tmp_path, no_simulation):
    nested = "[" * 100_000 + "]" * 100_000
    recording = tmp_path / "recording"
    recording.mkdir()
    (recording / "manifest.json").write_text(nested)
    _expect_error(capsys, tmp_path, "tune", "sim1", "--grid", "mapper.gate=0.1,0.2",
                  "--recording", recording, "--out", tmp_path / "out",
                  fragments=["error: --recording: manifest.json: arrays and tables nest deeper "
                             "than 64 levels (at line 1)"])
    campaign = tmp_path / "campaign"
    campaign.mkdir()
    (campaign / "manifest.json").write_text('{"kind": ' + nested + "}")
    (campaign / "runs.parquet").write_bytes(b"")
    _expect_error(capsys, tmp_path, "compare", campaign, campaign,
                  fragments=[f"error: BASELINE: {campaign / 'manifest.json'}: arrays and tables "
                             "nest deeper than 64 levels (at line 1)"])


# --- 2. outputs are checked before the work ----------------------------------------------

def _output_cases(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    a_file = tmp_path / "a_file"
    a_file.write_text("not a directory")
    stranger = tmp_path / "stranger"
    stranger.mkdir()
    (stranger / "notes.txt").write_text("someone's work")
    return {
        "file": (a_file, "exists and is not a directory"),
        "under-a-file": (a_file / "out", "is a file, not a directory"),
        "impossible": (Path("/proc/semistatic-results"), "cannot create it"),
        "foreign": (stranger, "not a semistatic result"),
    }


@pytest.mark.parametrize("case", ["file", "under-a-file", "impossible", "foreign"])
@pytest.mark.parametrize(
    "command",
    [["run", "sim1"], ["table"], ["tune", "sim1", "--grid", "mapper.gate=0.1,0.2"],
     ["replay", "LOG"], ["check", "sim1"]],
    ids=["run", "table", "tune", "replay", "check"],
)
def test_bad_output_locations_fail_before_any_work(capsys, tmp_path, no_simulation, command,
                                                   case):
    out, fragment = _output_cases(tmp_path)[case]
    log = tmp_path / "x.log"
    log.write_text("FLASER 2 1.0 1.0 0 0 0 0 0 0 1.0 host 1.0\n")
    args = [str(log) if arg == "LOG" else arg for arg in command]
    _expect_error(capsys, tmp_path, *args, "--out", out, fragments=["--out", str(out), fragment])


@pytest.mark.parametrize(
    ("bag", "fragment"),
    [("a_file/bag", "does not exist"), ("/proc/semistatic-bag", "cannot create it")],
)
def test_bad_bag_locations_fail_before_the_run(capsys, tmp_path, no_simulation, bag, fragment):
    (tmp_path / "a_file").write_text("x")
    bag_path = bag if bag.startswith("/") else tmp_path / bag
    _expect_error(capsys, tmp_path, "run", "sim1", "--out", tmp_path / "out", "--bag", bag_path,
                  fragments=["--bag", fragment])


def test_gui_without_a_display_says_so(capsys, tmp_path, no_simulation, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    _expect_error(capsys, tmp_path, "run", "sim1", "--gui", "--out", tmp_path / "out",
                  fragments=["--gui", "DISPLAY", "run without --gui"])


# --- 5. unusual log data -----------------------------------------------------------------

def _flaser(ranges: str, pose: str, stamp: float) -> str:
    return f"FLASER 180 {ranges} {pose} {pose} {stamp} test {stamp}"


def test_replay_of_a_log_with_only_nan_ranges(capsys, tmp_path):
    lines = [_flaser(" ".join(["nan"] * 180), f"{0.1 * k:.1f} 0 0", float(k)) for k in range(30)]
    log = tmp_path / "nan.log"
    log.write_text("\n".join(lines) + "\n")
    _expect_error(capsys, tmp_path, "replay", log, "--out", tmp_path / "out",
                  fragments=[str(log), "no polyline in any of its 30 scans"])


def test_replay_of_a_nan_pose_names_file_and_line(capsys, tmp_path, no_simulation):
    lines = [_flaser(" ".join(["1.0"] * 180), "nan 0 0" if k == 4 else f"{0.1 * k:.1f} 0 0",
                     float(k)) for k in range(10)]
    log = tmp_path / "pose.log"
    log.write_text("\n".join(lines) + "\n")
    _expect_error(capsys, tmp_path, "replay", log, "--out", tmp_path / "out",
                  fragments=[f"{log}:5", "pose", "must be finite"])


def test_replay_of_a_corrupt_bag_is_one_line(capsys, tmp_path, no_simulation):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: [\n")
    _expect_error(capsys, tmp_path, "replay", bag, "--out", tmp_path / "out",
                  fragments=[str(bag), "cannot open as a ROS bag"])


# --- semistatic check and --version ------------------------------------------------------

@pytest.mark.parametrize("name", bundled_scenarios())
def test_check_accepts_every_bundled_scenario(capsys, no_simulation, name):
    status, out, err = run_cli(capsys, "check", name)
    assert (status, err) == (0, "")
    assert out.startswith(f"{name}: valid (")
    assert "boxes per lap: [" in out


def test_version(capsys):
    with pytest.raises(SystemExit) as stop:
        run_cli(capsys, "--version")
    assert stop.value.code == 0
    assert capsys.readouterr().out.startswith("semistatic ")
