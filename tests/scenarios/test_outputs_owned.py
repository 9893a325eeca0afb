"""Outputs that are provably ours (issue 29, item 1).

A directory is replaced only when it carries the marker our commands write; every path a
command writes is resolved and checked against the others before any work; a full disk
or a refused permission is one ``error:`` line with the previous result whole.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import scenarios.commands.run as run_command
from scenarios.process.output_paths import check_output_paths, sqlite_path
from scenarios.process.staging import (
    RESULT_MARKER,
    is_result_dir,
    stage_and_publish,
    write_result_marker,
)
from semistatic.errors import SpecError
from sim.client import SimClient
from tests.scenarios.cli_helpers import assert_one_error_line, run_cli
from tests.scenarios.tiny_world import write_tiny

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def no_simulation(monkeypatch):
    """Fail the test if anything starts PyBullet: every case here is refused before."""

    def refuse(*_args, **_kwargs):
        raise AssertionError("PyBullet started before the outputs were checked")

    monkeypatch.setattr(SimClient, "__init__", refuse)


def _snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every path under ``folder`` (relative) with its bytes (``None`` for a directory)."""
    return {str(path.relative_to(folder)): None if path.is_dir() else path.read_bytes()
            for path in sorted(folder.rglob("*"))}


def _users_folder(folder: Path) -> Path:
    folder.mkdir()
    (folder / "notes.md").write_text("# my notes\n")
    (folder / "data.csv").write_text("a,b\n1,2\n")
    (folder / "metrics.json").write_text('{"mine": true}\n')
    return folder


def _previous_result(folder: Path, command: str = "run") -> Path:
    folder.mkdir()
    write_result_marker(folder, command)
    (folder / "metrics.json").write_text('{"earlier": "good result"}\n')
    return folder


def _expect_refused(capsys, tmp_path, *args, fragments):
    """Exit 2, one error line with ``fragments``, nothing under ``tmp_path`` changed."""
    before = _snapshot(tmp_path)
    status, out, err = run_cli(capsys, *args)
    assert status == 2, (out, err)
    assert_one_error_line(err, *fragments)
    assert "Traceback" not in err
    assert _snapshot(tmp_path) == before  # user files byte-identical, no staging left


# --- a result is what carries our marker ---------------------------------------------------

@pytest.mark.parametrize("command", [["run"], ["check"], ["table"]], ids=lambda c: c[0])
def test_a_folder_of_the_users_with_a_metrics_json_is_refused_not_replaced(
    capsys, tmp_path, no_simulation, command
):
    scenario = write_tiny(tmp_path)
    folder = _users_folder(tmp_path / "mine")
    args = [*command, scenario] if command[0] != "table" else command
    _expect_refused(capsys, tmp_path, *args, "--out", folder,
                    fragments=["--out", str(folder), "not a semistatic result"])


GENUINE_ID = "0123456789abcdef0123456789abcdef"
FAKE_MARKERS = {
    "empty": "",
    "old-text": "written by semistatic; replaced as a whole\n",
    "no-id": '{"semistatic": 1, "command": "run"}',
    "short-id": '{"semistatic": 1, "command": "run", "id": "abc"}',
    "extra-key": json.dumps({"semistatic": 1, "command": "run", "id": GENUINE_ID, "x": 1}),
    "bool-format": json.dumps({"semistatic": True, "command": "run", "id": GENUINE_ID}),
    "other-format": json.dumps({"semistatic": 2, "command": "run", "id": GENUINE_ID}),
    "list": json.dumps([1, "run", GENUINE_ID]),
    "nested": "[" * 100_000 + "]" * 100_000,
    "too-large": json.dumps({"semistatic": 1, "command": "run", "id": GENUINE_ID}) + " " * 5000,
}


@pytest.mark.parametrize("content", FAKE_MARKERS.values(), ids=FAKE_MARKERS.keys())
def test_a_marker_file_that_is_not_our_document_does_not_make_a_result(
    capsys, tmp_path, no_simulation, content
):
    folder = _users_folder(tmp_path / "mine")
    (folder / RESULT_MARKER).write_text(content)
    assert not is_result_dir(folder)
    _expect_refused(capsys, tmp_path, "run", write_tiny(tmp_path), "--out", folder,
                    fragments=["--out", "not a semistatic result"])


def test_a_marker_that_is_a_symlink_or_a_directory_is_not_ours(tmp_path):
    genuine = _previous_result(tmp_path / "genuine")
    linked = _users_folder(tmp_path / "linked")
    (linked / RESULT_MARKER).symlink_to(genuine / RESULT_MARKER)
    as_folder = _users_folder(tmp_path / "as-folder")
    (as_folder / RESULT_MARKER).mkdir()
    assert is_result_dir(genuine)
    assert not is_result_dir(linked)
    assert not is_result_dir(as_folder)


def test_a_genuine_result_is_replaced_whole_with_a_new_random_id(tmp_path):
    out = tmp_path / "out"
    stage_and_publish(out, lambda staging: (staging / "a.txt").write_text("1"), command="run")
    first = json.loads((out / RESULT_MARKER).read_text())
    stage_and_publish(out, lambda staging: (staging / "b.txt").write_text("2"), command="tune")
    second = json.loads((out / RESULT_MARKER).read_text())
    assert sorted(path.name for path in out.iterdir()) == [RESULT_MARKER, "b.txt"]
    assert (first["semistatic"], first["command"], second["command"]) == (1, "run", "tune")
    assert all(len(marker["id"]) == 32 and int(marker["id"], 16) >= 0
               for marker in (first, second))
    assert first["id"] != second["id"]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["out"]  # no staging left


def test_a_symlink_to_a_result_is_published_through(tmp_path):
    target = _previous_result(tmp_path / "target")
    link = tmp_path / "link"
    link.symlink_to(target)
    stage_and_publish(link, lambda staging: (staging / "new.txt").write_text("new"),
                      command="run")
    assert link.is_symlink()
    assert link.resolve() == target
    assert sorted(path.name for path in target.iterdir()) == [RESULT_MARKER, "new.txt"]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["link", "target"]


# --- every written path checked against the others -----------------------------------------

def test_tune_storage_inside_the_replaced_out_is_refused_untouched(capsys, tmp_path,
                                                                    no_simulation):
    out = _previous_result(tmp_path / "out", command="tune")
    (out / "mine.db").write_bytes(b"a study of four finished trials")
    _expect_refused(capsys, tmp_path, "tune", write_tiny(tmp_path), "--laps", "1",
                    "--param", "mapper.gate=0.05:0.3", "--trials", "2", "--no-figures",
                    "--storage", f"sqlite:///{out / 'mine.db'}", "--out", out,
                    fragments=["--storage", str(out / "mine.db"), "is inside --out",
                               "study would be deleted"])


def test_tune_keeps_its_own_study_inside_out_and_nothing_else():
    out = Path("/tmp/out")
    check_output_paths({"--out": out, "--storage": out / "study.db"},
                       storages=["--storage"], managed=[out / "study.db"])
    with pytest.raises(SpecError, match="study would be deleted"):
        check_output_paths({"--out": out, "--storage": out / "sub" / "study.db"},
                           storages=["--storage"], managed=[out / "study.db"])


@pytest.mark.parametrize(("url", "path"), [
    ("sqlite:////abs/s.db", Path("/abs/s.db")), ("sqlite:///rel/s.db", Path("rel/s.db")),
    ("sqlite:///s.db?timeout=5", Path("s.db")), ("sqlite://", None),
    ("sqlite:///:memory:", None), ("mysql://u@h/db", None), (None, None),
])
def test_sqlite_path_names_the_file_of_a_sqlite_url_only(url, path):
    assert sqlite_path(url) == path


@pytest.mark.parametrize("where", [".", "..", "sub/../."])
def test_out_that_is_or_holds_the_current_directory_is_refused(capsys, tmp_path, monkeypatch,
                                                               no_simulation, where):
    scenario = write_tiny(tmp_path)
    result = _previous_result(tmp_path / "result")
    (result / "sub").mkdir()
    monkeypatch.chdir(result / "sub" if where == ".." else result)
    _expect_refused(capsys, tmp_path, "run", scenario, "--out", where,
                    fragments=["--out", "current directory"])


def test_out_holding_the_scenario_file_is_refused(capsys, tmp_path, no_simulation):
    result = _previous_result(tmp_path / "result")
    scenario = write_tiny(result)
    _expect_refused(capsys, tmp_path, "run", scenario, "--out", result,
                    fragments=["--out", "holds the scenario file", str(scenario)])


def test_record_at_the_out_directory_through_a_symlink_is_refused(capsys, tmp_path,
                                                                  no_simulation):
    result = _previous_result(tmp_path / "result")
    link = tmp_path / "link"
    link.symlink_to(result)
    for out, record in ((result, result), (link, result), (result, tmp_path / "x" / ".." /
                                                           "result")):
        _expect_refused(capsys, tmp_path, "run", write_tiny(tmp_path), "--out", out,
                        "--record", record,
                        fragments=["--record", "is --out", "replaced as a whole"])


def test_record_inside_out_or_out_inside_record_is_refused(capsys, tmp_path, no_simulation):
    scenario = write_tiny(tmp_path)
    out = tmp_path / "out"
    _expect_refused(capsys, tmp_path, "run", scenario, "--out", out, "--record", out / "rec",
                    fragments=["--record", f"is inside --out {out}", "replaced as a whole"])
    _expect_refused(capsys, tmp_path, "run", scenario, "--out", out / "run", "--record", out,
                    fragments=["--out", f"is inside --record {out}"])


def test_bag_and_record_at_one_place_are_refused(capsys, tmp_path, no_simulation):
    place = tmp_path / "place"
    _expect_refused(capsys, tmp_path, "run", write_tiny(tmp_path), "--out", tmp_path / "out",
                    "--bag", place, "--record", tmp_path / "." / "place",
                    fragments=["--record", "is --bag", "give each its own path"])


def test_a_bag_may_go_into_the_new_result():
    check_output_paths({"--out": "/tmp/o", "--bag": "/tmp/o/bag"}, into_result=["--bag"])
    with pytest.raises(SpecError, match="--bag: /tmp/o: is --out /tmp/o"):
        check_output_paths({"--out": "/tmp/o", "--bag": "/tmp/o"}, into_result=["--bag"])


def test_compare_reports_at_one_place_or_at_an_input_are_refused(capsys, tmp_path):
    baseline, candidate = tmp_path / "a", tmp_path / "b"
    report = tmp_path / "report.md"
    _expect_refused(capsys, tmp_path, "compare", baseline, candidate, "--junit", report,
                    "--markdown", tmp_path / "." / "report.md",
                    fragments=["--markdown", "is --junit", "give each its own path"])
    baseline.mkdir()
    (baseline / "summary.json").write_text("{}")
    with pytest.raises(SpecError, match="is the BASELINE the command reads"):
        check_output_paths({"--junit": baseline / "summary.json"}, replaced=None,
                           inputs={"BASELINE": [baseline / "summary.json"]})


# --- a full disk or a refused permission ----------------------------------------------------

@pytest.mark.parametrize("number", [errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EPERM,
                                    errno.EROFS])
def test_a_write_failure_is_one_line_and_the_previous_result_stays_whole(
    capsys, tmp_path, monkeypatch, number
):
    out = _previous_result(tmp_path / "out")
    before = _snapshot(tmp_path)

    def failing_run(args):
        def fill(staging: Path) -> None:
            target = staging / "metrics.json"
            with target.open("wb") as stream:
                stream.write(b'{"half": ')
            # What the kernel answers when the disk fills (or the mount is read-only).
            raise OSError(number, os.strerror(number), str(target))

        stage_and_publish(args.out, fill, command="run")
        return 0

    monkeypatch.setattr(run_command, "main_run", failing_run)
    status, _, err = run_cli(capsys, "run", "anything", "--out", out)
    assert status == 2
    assert_one_error_line(err, "metrics.json", os.strerror(number),
                          "earlier results are left as they were")
    assert _snapshot(tmp_path) == before


def test_other_os_errors_are_not_swallowed(capsys, tmp_path, monkeypatch):
    def broken_run(_args):
        raise OSError(errno.EIO, os.strerror(errno.EIO), "/dev/sdz")

    monkeypatch.setattr(run_command, "main_run", broken_run)
    with pytest.raises(OSError, match="Input/output error"):
        run_cli(capsys, "run", "anything", "--out", tmp_path / "out")


def _mount_tmpfs(folder: Path, size: str) -> None:
    folder.mkdir()
    attempt = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs",
                              str(folder)], capture_output=True, text=True)
    if attempt.returncode != 0:
        pytest.skip(f"a tmpfs cannot be mounted here (needs root): {attempt.stderr.strip()}")


def _write_until_full(path: Path) -> None:
    with path.open("wb") as filler:
        while True:
            filler.write(b"\0" * 4096)
            filler.flush()


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("mount") is None, reason="no mount command")
def test_a_real_full_disk_during_a_run_is_one_line_and_the_previous_result_stays(tmp_path):
    disk = tmp_path / "disk"
    _mount_tmpfs(disk, "256k")
    try:
        out = _previous_result(disk / "out")
        before = _snapshot(disk)
        # Fill the disk but for a few kB: the run's maps and metrics do not fit.
        with pytest.raises(OSError, match="No space left") as full:
            _write_until_full(disk / "filler")
        assert full.value.errno == errno.ENOSPC
        # Truncating frees pages and never allocates: a few kB left for the run.
        os.truncate(disk / "filler", (disk / "filler").stat().st_size - 8192)
        before["filler"] = (disk / "filler").read_bytes()
        environment = {**os.environ, "PYTHONPATH": str(ROOT)}
        finished = subprocess.run(
            [sys.executable, "-m", "scenarios", "run", str(write_tiny(tmp_path)), "--laps",
             "1", "--no-figures", "--out", str(out)],
            cwd=tmp_path, env=environment, capture_output=True, text=True, timeout=600,
        )
        assert finished.returncode == 2, finished.stderr
        assert_one_error_line(finished.stderr.strip().splitlines()[-1],
                              f"error: {out}: No space left on device",
                              "earlier results are left")
        assert "Traceback" not in finished.stderr
        assert _snapshot(disk) == before  # the previous result whole, no staging left
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def test_a_swap_that_fails_halfway_puts_the_previous_result_back(tmp_path, monkeypatch):
    out = _previous_result(tmp_path / "out")
    before = _snapshot(tmp_path)
    rename = os.rename

    def full_at_the_swap(source, target):
        if ".staging-" in Path(source).name:  # the new result into place: the disk says no
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(target))
        rename(source, target)

    monkeypatch.setattr(os, "rename", full_at_the_swap)
    with pytest.raises(OSError, match="No space left"):
        stage_and_publish(out, lambda staging: (staging / "new.txt").write_text("new"),
                          command="run")
    assert _snapshot(tmp_path) == before


def test_a_bag_in_the_previous_result_does_not_block_the_next_run(tmp_path):
    from scenarios.logs.bag import check_new_bag_path

    out = _previous_result(tmp_path / "out")
    (out / "bag").mkdir()  # the previous run's bag: replaced with the result
    assert check_new_bag_path(out / "bag", out=out) == out / "bag"
    with pytest.raises(ValueError, match="exists already"):
        check_new_bag_path(out / "bag")
