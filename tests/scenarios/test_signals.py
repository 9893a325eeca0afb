"""Closed output streams and the stop signals: one line (when stderr is open), the stated
status, no traceback, nothing written.

``check`` is the fastest command: it loads and validates a scenario, then prints its
summary to stdout. Each case starts it with stdout or stderr closed (``>&-``) or piped to
a reader that is already gone (``| head -0``), and reads the status from the process.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios.process.signals import (
    EXIT_BROKEN_STREAM,
    Stopped,
    exit_status,
    ignore_in_worker,
    stop_on_signals,
)

TIMEOUT_S = 120.0
"""Longest wait for one command (imports on a loaded machine)."""

COMMAND = [sys.executable, "-m", "scenarios", "check", "sim1"]


def _run(**streams) -> subprocess.CompletedProcess:
    return subprocess.run(COMMAND, timeout=TIMEOUT_S, **streams)


def _closing(descriptor: int):
    """Return a ``preexec_fn`` that closes ``descriptor`` in the child, as ``>&-`` does."""
    return lambda: os.close(descriptor)


def test_the_reference_command_succeeds_with_open_streams():
    done = _run(capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("sim1: valid")


def test_closed_stdout_ends_with_141_and_one_line():
    done = _run(stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                preexec_fn=_closing(1))
    assert done.returncode == EXIT_BROKEN_STREAM == 141
    assert done.stderr.splitlines() == [
        "error: stdout: is closed; stopped (what was not published yet is discarded, "
        "earlier results are left as they were)"]


def test_closed_stderr_ends_with_141_and_writes_nothing():
    done = _run(stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, preexec_fn=_closing(2))
    assert done.returncode == 141
    assert done.stdout == b""  # stopped before any work: nothing half-shown


def test_a_reader_gone_before_the_output_ends_with_141_and_one_line():
    reader, writer = os.pipe()
    os.close(reader)  # `| head -0`: nobody will read stdout
    try:
        done = _run(stdout=writer, stderr=subprocess.PIPE, text=True)
    finally:
        os.close(writer)
    assert done.returncode == 141, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.splitlines()[-1].startswith("error: stdout: is closed")
    assert "Exception ignored" not in done.stderr


def test_a_broken_stderr_pipe_ends_with_141_silently():
    reader, writer = os.pipe()
    os.close(reader)
    try:  # a bad scenario name: the error line goes to the broken stderr
        done = subprocess.run([*COMMAND[:-1], "nosuch"], stdout=subprocess.PIPE,
                              stderr=writer, timeout=TIMEOUT_S)
    finally:
        os.close(writer)
    assert done.returncode == 141
    assert done.stdout == b""


@pytest.mark.parametrize("number", [signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT])
def test_stop_signals_raise_stopped_and_give_128_plus_n(number):
    with stop_on_signals(), pytest.raises(KeyboardInterrupt) as stopped:
        signal.raise_signal(number)
    assert isinstance(stopped.value, Stopped)
    assert exit_status(stopped.value) == {signal.SIGTERM: 143, signal.SIGHUP: 129,
                                          signal.SIGQUIT: 131}[number]
    assert signal.getsignal(number) == signal.SIG_DFL


def test_an_ignored_signal_stays_ignored():
    # `nohup` starts a command with SIGHUP ignored: a hangup must not stop it.
    earlier = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with stop_on_signals():
            assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
            signal.raise_signal(signal.SIGHUP)  # ignored: no exception
    finally:
        signal.signal(signal.SIGHUP, earlier)


@pytest.mark.slow  # signals a subprocess
def test_a_worker_ignores_the_group_signals_and_obeys_sigterm():
    import multiprocessing

    context = multiprocessing.get_context("fork")
    ready = context.Event()

    def work() -> None:
        ignore_in_worker()
        ready.set()
        signal.pause()

    with stop_on_signals():  # the parent's handlers, which a fork inherits
        worker = context.Process(target=work)
        worker.start()
        assert ready.wait(TIMEOUT_S)
        for number in (signal.SIGINT, signal.SIGHUP, signal.SIGQUIT):
            os.kill(worker.pid, number)
        worker.join(timeout=1.0)
        assert worker.is_alive()  # every one ignored
        worker.terminate()  # SIGTERM, as a pool's terminate() sends
        worker.join(timeout=TIMEOUT_S)
    assert worker.exitcode == -signal.SIGTERM


@pytest.mark.slow  # signals a subprocess that runs laps
def test_sigquit_stops_a_run_with_131_and_keeps_the_old_result(tmp_path: Path):
    from scenarios.process.staging import write_result_marker
    from tests.scenarios.tiny_world import write_tiny

    out = tmp_path / "out"
    out.mkdir()
    write_result_marker(out, "run")
    (out / "metrics.json").write_text("{}")
    process = subprocess.Popen(
        [sys.executable, "-m", "scenarios", "run", str(write_tiny(tmp_path)), "--laps", "2",
         "--no-figures", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    for line in process.stderr:
        if "lap 1 of 2" in line:
            break
    process.send_signal(signal.SIGQUIT)
    err = process.stderr.read()
    assert process.wait(timeout=TIMEOUT_S) == 131, err
    assert err.strip().splitlines()[-1].startswith("interrupted")
    assert "Traceback" not in err
    assert (out / "metrics.json").read_text() == "{}"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["out", "tiny.toml",
                                                               "tiny_world.toml"]


class _SignalsWhenCollected:
    def __del__(self) -> None:
        signal.raise_signal(signal.SIGHUP)  # as when a signal lands in SQLAlchemy's __del__


def test_a_stop_swallowed_by_a_finalizer_is_raised_again_and_not_printed(capfd):
    from scenarios.process.signals import raise_if_stopped

    with stop_on_signals():
        _SignalsWhenCollected()  # collected at once: the handler raises inside __del__
        with pytest.raises(Stopped) as stopped:
            raise_if_stopped()
    assert stopped.value.signal_number == signal.SIGHUP
    assert capfd.readouterr().err == ""  # no "Exception ignored in ..." traceback
    raise_if_stopped()  # outside the block: forgotten
