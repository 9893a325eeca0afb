"""Helpers shared by the command-line tests: run ``semistatic`` in-process, check its errors."""

from __future__ import annotations

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
