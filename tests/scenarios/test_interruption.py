"""Ctrl-C (SIGINT), SIGTERM, SIGHUP and SIGKILL in run, table, tune and replay: the
command stops promptly with one line and exit 128 + N (130 for SIGINT), no process
outlives it, an earlier good result is left intact and no staging directory survives the
next command on the same directory. A search (``tune --param``) stopped by any of them
resumes: the same command again finishes the study with every grid point exactly once.

Each command runs in a subprocess with stderr piped, so it prints progress lines; the
signal is sent once its progress line (or its worker processes) shows it is working,
never after a fixed sleep. Timeouts are generous: the machine may be loaded.
"""

from __future__ import annotations

import gzip
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from scenarios.process.staging import write_result_marker
from tests.scenarios.tiny_world import write_tiny

pytestmark = pytest.mark.slow

START_TIMEOUT_S = 120.0
"""Longest wait for a command to show it is working (imports and loads on a busy machine)."""

STOP_TIMEOUT_S = 20.0
"""Longest wait for a command to stop after the signal."""

BUSY_CPU_S = 0.5
"""CPU time (s) after which a worker is surely inside a run, not waiting for one."""

WORKERS_STOP_S = 3.0
"""Longest wait for the workers to stop once their parent stopped: shorter than one of
their runs (5 laps of the tiny world, 2 of a bundled scenario), so waiting for them to
finish their run would fail."""


def _children(pid: int) -> set[int]:
    """Return the ids of the live processes whose parent is ``pid`` (Linux /proc)."""
    found = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if int(fields[1]) == pid and fields[0] != "Z":
            found.add(int(entry.name))
    return found


def _descendants(pid: int) -> set[int]:
    """Return the ids of the live descendants of ``pid`` (children, theirs, ...)."""
    found, todo = set(), [pid]
    while todo:
        children = _children(todo.pop())
        todo.extend(children - found)
        found |= children
    return found


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


RAY_STOP_S = 15.0
"""Longest wait for Ray's processes to stop once the driver stopped: its agents notice
the raylet's end by polling (measured: all gone within 8 s of a SIGKILLed driver)."""


def _corridor_log(path: Path, passes: int) -> Path:
    """Write a CARMEN log of a robot driving a 3 m corridor back and forth."""
    angles = np.radians(np.arange(-90.0, 90.0, 1.0))
    lines, stamp = [], 0.0
    for index in range(passes):
        xs = np.arange(0.0, 3.0, 0.1) if index % 2 == 0 else np.arange(3.0, 0.0, -0.1)
        theta = 0.0 if index % 2 == 0 else np.pi
        heading = angles + theta
        with np.errstate(divide="ignore"):
            left = np.where(np.sin(heading) > 1e-9, 1.0 / np.sin(heading), np.inf)
            right = np.where(np.sin(heading) < -1e-9, -1.0 / np.sin(heading), np.inf)
        values = " ".join(f"{r:.3f}" for r in np.minimum(np.minimum(left, right), 81.83))
        for x in xs:
            stamp += 1.0
            pose = f"{x:.3f} 0.0 {theta:.6f}"
            lines.append(f"FLASER 180 {values} {pose} {pose} {stamp:.1f} test {stamp:.1f}")
    with gzip.open(path, "wt") as stream:
        stream.write("\n".join(lines) + "\n")
    return path


def _previous_result(out: Path) -> str:
    """Make ``out`` an earlier good result; return the text that must survive."""
    out.mkdir()
    write_result_marker(out, "run")
    text = json.dumps({"earlier": "good result"})
    (out / "metrics.json").write_text(text)
    return text


def _command(kind: str, tmp_path: Path, out: Path) -> tuple[list[str], str | None, int]:
    """Return (arguments, progress marker or None, workers to wait for) of one command."""
    scenario = write_tiny(tmp_path)
    if kind == "run":
        return ["run", str(scenario), "--laps", "2", "--no-figures"], "lap 1 of 2", 0
    if kind == "table":
        return ["table", "--laps", "2", "--jobs", "2", "--no-figures"], None, 2
    if kind == "tune":
        return (["tune", str(scenario), "--laps", "5", "--jobs", "2", "--no-figures",
                 "--grid", "mapper.gate=0.08,0.12,0.16"], None, 2)
    log = _corridor_log(tmp_path / "corridor.log.gz", passes=200)
    return ["replay", str(log), "--no-figures", "--tile", "2"], "replay corridor: 500 scans", 0


def _interruptible() -> None:
    # A command started from a terminal receives Ctrl-C; a test suite started in the
    # background (`nohup make test &`) passes SIGINT on ignored, and Python would then never
    # install its KeyboardInterrupt handler in the child. Restore what a terminal gives.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(args: list[str], out: Path, cwd: Path) -> subprocess.Popen:
    # stdout goes to a file: workers writing into a closed pipe would die of SIGPIPE and
    # hide whether they stop with their parent on their own.
    with open(cwd / "stdout.txt", "w") as stdout:
        return subprocess.Popen(
            [sys.executable, "-m", "scenarios", *args, "--out", str(out)],
            cwd=cwd, stdout=stdout, stderr=subprocess.PIPE, text=True,
            preexec_fn=_interruptible,
        )


def _wait_until_working(process: subprocess.Popen, marker: str | None, workers: int) -> set[int]:
    """Wait for ``marker`` on stderr or for ``workers`` child processes; return the children."""
    deadline = time.monotonic() + START_TIMEOUT_S
    if marker is not None:
        for line in process.stderr:
            if marker in line:
                return _children(process.pid)
            assert time.monotonic() < deadline, f"no {marker!r} in time"
        pytest.fail(f"the command ended before printing {marker!r}")
    # Busy workers: each has spent CPU time in its run (an idle, just-forked worker would
    # stop at its parent's death anyway, reading the closed task queue).
    while len(children := _children(process.pid)) < workers or min(
        _cpu_seconds(pid) for pid in children
    ) < BUSY_CPU_S:
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "the workers did not start in time"
        time.sleep(0.05)
    return children


def _cpu_seconds(pid: int) -> float:
    """Return the user + system CPU time (s) process ``pid`` has used (0 once gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return 0.0
    fields = stat[stat.rindex(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _wait_stopped(process: subprocess.Popen, workers: set[int],
                  allowed_s: float = WORKERS_STOP_S) -> None:
    """Wait for ``process`` to end, then for ``workers`` within ``allowed_s``.

    ``wait`` rather than ``communicate``: reading stderr to its end would also wait for
    the workers, which hold it open, and hide how long they outlived their parent.
    """
    try:
        process.wait(timeout=STOP_TIMEOUT_S)
    finally:
        process.kill()
    deadline = time.monotonic() + allowed_s
    while any(_alive(pid) for pid in workers):
        assert time.monotonic() < deadline, f"processes outlived their parent: {workers}"
        time.sleep(0.05)


def _leftovers(folder: Path) -> list[str]:
    return sorted(path.name for path in folder.iterdir() if ".staging-" in path.name
                  or ".previous-" in path.name)


def _interrupted(tmp_path: Path, kind: str, signal_number: int) -> tuple[Path, str, str, int]:
    """Start ``kind`` over an earlier result, signal it while it works, wait for the end.

    Returns the output directory, the earlier result's text, stderr and the exit status.
    """
    out = tmp_path / "results"
    old = _previous_result(out)
    args, marker, workers = _command(kind, tmp_path, out)
    process = _start(args, out, tmp_path)
    children = _wait_until_working(process, marker, workers)
    process.send_signal(signal_number)
    _wait_stopped(process, children)
    return out, old, process.stderr.read(), process.returncode


STOPPING = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]
"""Signals that stop a command with one line (SIGQUIT is handled alike: test_signals.py)."""


@pytest.mark.parametrize("signal_number", STOPPING, ids=lambda number: number.name)
@pytest.mark.parametrize("kind", ["run", "table", "tune", "replay"])
def test_a_signal_stops_promptly_with_one_line_and_keeps_the_old_result(
        tmp_path, kind, signal_number):
    out, old, err, status = _interrupted(tmp_path, kind, signal_number)
    assert status == 128 + signal_number, err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("interrupted")
    assert (out / "metrics.json").read_text() == old
    assert _leftovers(tmp_path) == []
    _next_command_succeeds(tmp_path, out, old)


@pytest.mark.parametrize("kind", ["run", "table", "tune", "replay"])
def test_sigkill_leaves_no_process_and_the_next_command_cleans_up(tmp_path, kind):
    out, old, _, _ = _interrupted(tmp_path, kind, signal.SIGKILL)
    assert (out / "metrics.json").read_text() == old
    # A staging directory a killed run left behind (it may have been killed mid-write).
    (tmp_path / f".results.staging-{_dead_pid()}-x").mkdir()
    _next_command_succeeds(tmp_path, out, old)


def _next_command_succeeds(tmp_path: Path, out: Path, old: str) -> None:
    """Check that a command on ``out`` succeeds, leaves no staging and the old result."""
    check = subprocess.run(
        [sys.executable, "-m", "scenarios", "check", "sim1", "--out", str(out)],
        cwd=tmp_path, capture_output=True, text=True, timeout=START_TIMEOUT_S,
    )
    assert check.returncode == 0, check.stderr
    assert _leftovers(tmp_path) == []
    assert (out / "metrics.json").read_text() == old


def _dead_pid() -> int:
    """Return a process id that no running process has."""
    pid = os.getpid() + 100_000
    while _alive(pid):
        pid += 1
    return pid


SEARCH = ["tune", "--param", "mapper.gate=0.05:0.2", "--sampler", "grid", "--grid-points",
          "4", "--laps", "2", "--jobs", "2", "--no-figures"]
"""A four-trial grid search on the tiny world: each trial is one short run."""

GRID = [0.05, 0.1, 0.15, 0.2]
"""The grid's values of mapper.gate (4 points from 0.05 to 0.2)."""


def _trials(out: Path) -> list[tuple[str, float]]:
    """Return (state, mapper.gate) of every trial of the study in ``out`` (hand-read SQL)."""
    import sqlite3

    with sqlite3.connect(out / "study.db") as database:
        rows = database.execute(
            "SELECT trials.state, trial_params.param_value FROM trials JOIN trial_params"
            " ON trial_params.trial_id = trials.trial_id ORDER BY trials.number").fetchall()
    return [(state, round(value, 9)) for state, value in rows]


@pytest.mark.parametrize("signal_number", [*STOPPING, signal.SIGKILL],
                         ids=lambda number: number.name)
@pytest.mark.parametrize("backend", ["pool", "ray"])
def test_a_stopped_search_resumes_with_every_trial_once(tmp_path, backend, signal_number):
    if backend == "ray":
        pytest.importorskip("ray")
    scenario = write_tiny(tmp_path)
    out = tmp_path / "search"
    args = [*SEARCH[:1], str(scenario), *SEARCH[1:], "--backend", backend]
    process = _start(args, out, tmp_path)
    _wait_until_working(process, "1/4 trials done", 0)
    # Every process the command made: the pool's workers, or Ray's GCS server, raylet,
    # dashboard and runtime-env agents (children of the raylet) and workers.
    family = _descendants(process.pid)
    process.send_signal(signal_number)
    _wait_stopped(process, family, RAY_STOP_S if backend == "ray" else WORKERS_STOP_S)
    err = process.stderr.read()
    if signal_number != signal.SIGKILL:
        assert process.returncode == 128 + signal_number, err
        assert "Traceback" not in err
    assert _leftovers(tmp_path) == []
    assert any(state == "COMPLETE" for state, _ in _trials(out))
    started = time.monotonic()
    resumed = subprocess.run(
        [sys.executable, "-m", "scenarios", *args, "--out", str(out)],
        cwd=tmp_path, capture_output=True, text=True, timeout=START_TIMEOUT_S * 2)
    assert resumed.returncode == 0, resumed.stderr
    complete = sorted(value for state, value in _trials(out) if state == "COMPLETE")
    assert complete == GRID, _trials(out)
    print(f"resumed in {time.monotonic() - started:.1f} s")
