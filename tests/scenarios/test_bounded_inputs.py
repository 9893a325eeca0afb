"""Hostile inputs are refused before allocation: one line, exit 2, within ~2x the memory.

Each case runs the real command in a subprocess and reads the child's peak resident set
from ``os.wait4``; the reference is the peak of ``check`` on the largest bundled world's
scenario (warehouse), which the hostile cases must stay within twice of. Unit tests of the
limits themselves (the reader, the counts, the grid) are fast and unmarked.
"""

from __future__ import annotations

import gzip
import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios.tuning.params import MAX_GRID_POINTS, MAX_GRID_TRIALS, grid_size, parse_params
from semistatic.errors import SpecError
from semistatic.inputs import (
    MAX_LOG_BYTES,
    MAX_SPEC_BYTES,
    bounded_lines,
    check_regular_file,
    open_bounded,
)
from semistatic.logs.carmen import LogFormatError, read_carmen
from semistatic.types import MAX_BEAMS
from tests.scenarios.tiny_world import TINY_WORLD, write_tiny
from worlds.load import world_from_toml
from worlds.spec import MAX_ITEMS, MAX_VERTICES

REPO = Path(__file__).resolve().parents[2]
SEMISTATIC = [sys.executable, "-m", "scenarios"]
TIMEOUT_S = 300  # generous: the machine is shared; a FIFO that blocked would hit it


def _flaser(beams: int) -> str:
    ranges = " ".join(["1"] * beams)
    return f"FLASER {beams} {ranges} 0 0 0 0 0 0 1.0 host 1.0\n"


def _world_with(lines: str) -> str:
    return TINY_WORLD + "\n" + lines


def _boxes(count: int) -> str:
    return "".join(f'[[boxes]]\nname = "b{i}"\nsize = [0.1, 0.1, 0.1]\npose = [{i * 0.2}, 5, 0]\n'
                   for i in range(count))


# --- fast: the limits, each against a hand-made case ------------------------------------

def test_a_fifo_is_refused_without_being_opened(tmp_path):
    fifo = tmp_path / "world.toml"
    os.mkfifo(fifo)
    # Opening a FIFO for reading would block this test for ever: the check must not open.
    with pytest.raises(SpecError, match=r"is a FIFO \(named pipe\), expected a regular"):
        check_regular_file(fifo, limit=MAX_SPEC_BYTES, what=".toml file")


@pytest.mark.parametrize(("path", "kind"), [("/dev/zero", "a character device"),
                                            ("/", "a directory")])
def test_devices_and_directories_are_not_files(path, kind):
    with pytest.raises(SpecError, match=f"is {kind}, expected a regular log"):
        check_regular_file(path, limit=MAX_LOG_BYTES, what="log")


def test_a_sparse_file_over_the_limit_is_refused_by_its_size(tmp_path):
    huge = tmp_path / "huge.toml"
    with open(huge, "wb") as stream:
        stream.truncate(MAX_SPEC_BYTES + 1)
    with pytest.raises(SpecError, match=r"is 1\.0 MiB, more than the limit of 1\.0 MiB"):
        check_regular_file(huge, limit=MAX_SPEC_BYTES, what=".toml file")


@pytest.mark.parametrize("compress", [gzip.compress, __import__("bz2").compress,
                                      __import__("lzma").compress])
def test_decompression_stops_at_the_limit(tmp_path, compress):
    exact, bomb = tmp_path / "exact.log", tmp_path / "bomb.log"
    exact.write_bytes(compress(bytes(4000)))
    bomb.write_bytes(compress(bytes(4001)))
    with open_bounded(exact, limit=4000, what="log") as stream:
        assert stream.read() == bytes(4000)  # up to the limit it reads
    with open_bounded(bomb, limit=4000, what="log") as stream, \
            pytest.raises(SpecError, match="decompresses to more than the limit of 4000"):
        stream.read()


def test_a_line_without_a_break_is_refused_at_the_line_limit():
    stream = io.BufferedReader(io.BytesIO(b"ab\n" + b"x" * 100))
    lines = bounded_lines(stream, file="x.log", limit=50)
    assert next(lines) == "ab\n"
    with pytest.raises(SpecError, match=r"x\.log: line 2: longer than 50 bytes"):
        next(lines)


def test_a_scan_of_more_beams_than_a_laser_has_is_refused_with_its_line(tmp_path):
    log = tmp_path / "wide.log"
    log.write_text(_flaser(2) + _flaser(MAX_BEAMS + 1))
    scans = read_carmen(log, max_range=80.0)
    assert len(next(scans)) == 2
    with pytest.raises(LogFormatError, match=f"wide.log:2: FLASER: {MAX_BEAMS + 1} beams, "
                       f"more than the limit of {MAX_BEAMS}"):
        next(scans)


def test_box_and_knot_counts_are_limited_before_the_layout_checks(tmp_path):
    import tomllib

    table = tomllib.loads(_world_with(_boxes(MAX_ITEMS + 1)))
    with pytest.raises(SpecError, match=f"w.toml: boxes: has {MAX_ITEMS + 2} entries, more "
                       f"than the limit of {MAX_ITEMS}"):
        world_from_toml(table, file="w.toml")
    table = tomllib.loads(TINY_WORLD)
    table["path"]["knots"] = [[0.01 * i, 0.0] for i in range(MAX_VERTICES + 1)]
    with pytest.raises(SpecError, match=f"path.knots: has {MAX_VERTICES + 1} entries"):
        world_from_toml(table, file="w.toml")


def test_grid_points_and_grid_size_are_limited_before_allocation():
    gate = parse_params(["mapper.gate=0.1:0.2"])
    assert grid_size(gate, MAX_GRID_POINTS) == MAX_GRID_POINTS
    with pytest.raises(SpecError, match=f"--grid-points: grid_points: must be <= "
                       f"{MAX_GRID_POINTS} .*got 100000000"):
        grid_size(gate, 100_000_000)
    # 1000^2 combinations: each range is allowed, the grid is not.
    two = parse_params(["mapper.gate=0.1:0.2", "mapper.outlier_alpha=0.01:0.1"])
    with pytest.raises(SpecError, match=f"1000000 points, more than the limit of "
                       f"{MAX_GRID_TRIALS} trials"):
        grid_size(two, MAX_GRID_POINTS)


# --- slow: each hostile case through the command, its peak memory measured ----------------

def _peak(args: list[str], cwd: Path) -> tuple[int, str, int]:
    """Run ``semistatic args`` in a fresh measuring interpreter: (status, stderr, KiB)."""
    measure = (
        "import os, subprocess, sys, resource\n"
        "child = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, "
        f"stderr=subprocess.PIPE, timeout={TIMEOUT_S})\n"
        "sys.stderr.buffer.write(child.stderr)\n"
        "peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss\n"
        "print(child.returncode, peak)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run([sys.executable, "-c", measure, *SEMISTATIC, *args], cwd=cwd,
                          env=env, capture_output=True, timeout=TIMEOUT_S + 60, check=False)
    if done.returncode != 0:
        pytest.fail(f"semistatic {' '.join(args)}: {done.stderr.decode()[-2000:]}")
    status, peak = map(int, done.stdout.split())
    return status, done.stderr.decode(), peak


def _hostile_cases(folder: Path) -> dict[str, tuple[list[str], str]]:
    """Build every hostile input in ``folder``: name -> (arguments, expected fragment)."""
    write_tiny(folder)
    os.mkfifo(folder / "fifo.toml")
    os.mkfifo(folder / "fifo.log")
    with open(folder / "huge.toml", "wb") as stream:
        stream.truncate(4 << 30)  # 4 GiB, sparse: costs no disk
    with open(folder / "huge.log", "wb") as stream:
        stream.truncate(4 << 30)
    # Gzip bombs of 512 MiB, compressed to ~0.5 MB, written in chunks: zeros (one endless
    # line) and 1 KiB comment lines (every line short, the whole too long).
    comments = (b"#" * 1023 + b"\n") * 1024
    for name, chunk in (("bomb.log.gz", bytes(1 << 20)), ("lines.log.gz", comments)):
        with gzip.open(folder / name, "wb", compresslevel=1) as stream:
            for _ in range(512):
                stream.write(chunk)
    (folder / "wide.log").write_text(_flaser(100_000))
    for name, body in (("boxes.toml", _boxes(100_000)), ("boxes_1001.toml", _boxes(1001))):
        (folder / name).write_text(_world_with(body))
    knots = ", ".join(f"[{0.001 * i:.3f}, 0.0]" for i in range(10**6))
    (folder / "knots.toml").write_text(
        TINY_WORLD.replace("knots = [[0.0, 0.0], [1.75, 0.0], [3.5, 0.0]]", f"knots = [{knots}]"))
    for world in ("boxes", "boxes_1001", "knots", "fifo", "huge"):
        (folder / f"on_{world}.toml").write_text(
            (folder / "tiny.toml").read_text().replace("tiny_world.toml", f"{world}.toml"))
    recording = folder / "rec"
    recording.mkdir()
    os.mkfifo(recording / "manifest.json")
    return {
        "fifo scenario": (["check", "fifo.toml"], "is a FIFO"),
        "fifo world": (["check", "on_fifo.toml"], "is a FIFO"),
        "fifo log": (["evaluate", "fifo.log"], "is a FIFO"),
        "fifo manifest": (["tune", "tiny.toml", "--recording", "rec", "--param",
                           "mapper.gate=0.1:0.2", "--trials", "1", "--out", "t"], "is a FIFO"),
        "/dev/zero scenario": (["check", "/dev/zero"], "is a character device"),
        "/dev/zero log": (["evaluate", "/dev/zero"], "is a character device"),
        "4 GiB scenario": (["check", "huge.toml"], "more than the limit of 1.0 MiB"),
        "4 GiB world": (["check", "on_huge.toml"], "more than the limit of 1.0 MiB"),
        "4 GiB log": (["evaluate", "huge.log"], "more than the limit of 64.0 MiB"),
        "gzip bomb of zeros": (["evaluate", "bomb.log.gz"], "line 1: longer than 262144"),
        "gzip bomb of lines": (["evaluate", "lines.log.gz"],
                               "decompresses to more than the limit of 64.0 MiB"),
        "100k beams": (["evaluate", "wide.log"], "more than the limit of 8192"),
        "10^5 boxes": (["check", "on_boxes.toml"], "more than the limit of 1.0 MiB"),
        "1001 boxes": (["check", "on_boxes_1001.toml"], "more than the limit of 1000"),
        "10^6 knots": (["check", "on_knots.toml"], "more than the limit of 1.0 MiB"),
        "--grid-points 1e8": (["tune", "tiny.toml", "--sampler", "grid", "--grid-points",
                               "100000000", "--param", "mapper.gate=0.1:0.2", "--out", "t"],
                              "--grid-points: grid_points: must be <= 1000"),
    }


@pytest.mark.slow
def test_every_hostile_input_is_refused_in_one_line_within_twice_the_memory(tmp_path):
    # The reference: check of the largest bundled world's scenario, which must pass.
    status, stderr, reference = _peak(["check", "warehouse"], tmp_path)
    assert status == 0, stderr
    cases = _hostile_cases(tmp_path)
    before = sorted(path.name for path in tmp_path.iterdir())
    peaks = {}
    for name, (args, fragment) in cases.items():
        status, stderr, peak = _peak(args, tmp_path)
        lines = stderr.strip().splitlines()
        assert status == 2, (name, stderr)
        assert len(lines) == 1, (name, stderr)
        assert lines[0].startswith("error: "), (name, stderr)
        assert "Traceback" not in stderr, (name, stderr)
        assert fragment in lines[0], (name, lines[0])
        peaks[name] = peak
        assert peak <= 2 * reference, (name, peak, reference)
    # Nothing written: no result, staging or study beside the inputs.
    assert sorted(path.name for path in tmp_path.iterdir()) == before
    assert sorted(path.name for path in (tmp_path / "rec").iterdir()) == ["manifest.json"]
    print(f"peak RSS KiB: reference {reference}, hostile {peaks}")


def test_a_laser_with_more_beams_than_a_scan_may_have_is_refused_by_its_spec():
    import dataclasses
    import math

    from robots.lasers import LMS100

    # 360 deg at 0.01 deg: 36,001 beams; check must refuse what a Scan would refuse mid-run.
    with pytest.raises(SpecError, match=f"gives 36001 beams over the fov, more than the limit "
                       f"of {MAX_BEAMS}"):
        dataclasses.replace(LMS100, fov=math.radians(360), angular_resolution=math.radians(0.01))
    assert LMS100.num_beams == 541 <= MAX_BEAMS
