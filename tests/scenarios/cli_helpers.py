"""Helpers shared by the command-line tests: run ``semistatic`` in-process, check its errors."""

from __future__ import annotations

import os
import signal
import subprocess
import time

from scenarios.cli import main


def run_cli(capsys, *args):
    """Run ``semistatic ARGS`` and return ``(exit status, stdout, stderr)``."""
    status = main([str(arg) for arg in args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def assert_one_error_line(err, *fragments):
    """Assert that ``err`` is one ``error:`` line holding every fragment."""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ")
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def kill_after_line(command, cwd, marker, timeout):
    """Start ``command``; SIGKILL it once a line of its stderr holds ``marker``.

    Fails the test when no such line comes within ``timeout`` seconds.
    """
    process = subprocess.Popen(command, cwd=cwd, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + timeout
    for line in process.stderr:
        if marker in line:
            break
        assert time.monotonic() < deadline, f"no {marker!r} within {timeout} s"
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
