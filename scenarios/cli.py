"""The ``semistatic`` command line (its contract: the design page, docs/design.md).

The commands (:mod:`scenarios.commands`) register their parsers (``add_parser(s)``) and
run (``main_*``); this module assembles the parser, compiles the mapper's kernels ahead of
a command that runs them (:func:`semistatic.kernel_cache.warm_kernel_cache`), and turns
errors into exit statuses: bad input (a missing or malformed file, an unknown key, an
out-of-range value, an option out of range, an output directory that cannot be created)
ends with status 2 and one line ``error: <file or option>: <key>: <what is wrong>``,
before any work starts and before anything is written; a full disk or a refused
permission while writing also ends with status 2 and one ``error:`` line (the previous
result whole); a run whose lap cannot complete exits with 1; Ctrl-C exits with 130 and
one line, SIGTERM, SIGHUP and SIGQUIT with 128 + N and the same line
(:mod:`scenarios.process.signals`); a closed stdout or stderr ends the command with 141
(one line on stderr when stderr is still open), no traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.metadata
import os
import sys
from collections.abc import Sequence

from scenarios.commands import campaign, compare, evaluate, falsify, replay, run, tune
from scenarios.process.errors import EXIT_BAD_INPUT, InputError, check_jobs, write_failure
from scenarios.process.signals import (
    EXIT_BROKEN_STREAM,
    broken_stream,
    exit_status,
    silence_streams,
    stop_on_signals,
    stream_problem,
)
from semistatic.errors import SpecError, caused_by_interrupt

__all__ = ["console_main", "main"]

COMPILING_COMMANDS = ("run", "table", "tune", "replay", "evaluate", "campaign", "falsify")
"""Commands that run the mapper: its kernels are compiled (on every core) before them."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="semistatic",
        description="Semi-static object detection with polygonal maps: a PyBullet testbench.",
    )
    parser.add_argument("--version", action="version",
                        version=f"%(prog)s {importlib.metadata.version('semistatic')}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    run.add_parsers(commands)
    replay.add_parser(commands)
    tune.add_parser(commands)
    evaluate.add_parser(commands)
    campaign.add_parser(commands)
    compare.add_parser(commands)
    falsify.add_parser(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``semistatic`` command line; return the exit status.

    Examples
    --------
    >>> main(["check", "pal1"])  # doctest: +ELLIPSIS
    pal1: valid (...pal1.toml)
    ...
    0
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(argv)
    args.argv = argv  # the command as given, for the manifests that record it
    handlers = {"check": run.main_check, "run": run.main_run, "table": run.main_table,
                "replay": replay.main_replay, "tune": tune.main_tune,
                "evaluate": evaluate.main_evaluate, "campaign": campaign.main_campaign,
                "compare": compare.main_compare, "falsify": falsify.main_falsify}
    try:
        with stop_on_signals():
            return _run_command(args, handlers)
    except KeyboardInterrupt as interrupt:  # Ctrl-C, or a stop signal (signals.Stopped)
        return _interrupted(exit_status(interrupt))
    except SystemError as error:
        # Ctrl-C while numba unpickles a cached kernel reaches us as a SystemError
        # ("returned a result with an exception set") caused by the KeyboardInterrupt.
        if not caused_by_interrupt(error):
            raise
        cause = error
        while not isinstance(cause, KeyboardInterrupt):
            cause = cause.__cause__ or cause.__context__
        return _interrupted(exit_status(cause))
    except (OSError, ValueError, AttributeError) as error:
        if not broken_stream(error):
            raise
        return _broken_stream()


def _run_command(args: argparse.Namespace, handlers: dict) -> int:
    if stream_problem() is not None:
        return _broken_stream()  # before any work: nothing it shows could be read
    try:
        if getattr(args, "jobs", None) is not None:
            # Now, before the kernel compilation below forks workers of its own: a --jobs
            # out of range must not start a process before it is refused.
            check_jobs(args.jobs)
        if args.command in COMPILING_COMMANDS:
            from semistatic.kernel_cache import warm_kernel_cache

            # numba's set-up and the kernels its cache lacks (the first run after an
            # installation or an upgrade), on every core: start-up, not the run's time.
            warm_kernel_cache()
        return handlers[args.command](args)
    except (SpecError, InputError) as error:
        print("error: " + _one_line(str(error)), file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:
        # A full disk or a refused permission while writing (staging is removed on the
        # way out of stage_and_publish); any other OSError (a broken stdout's EPIPE
        # among them, handled by main) is a fault to see whole.
        line = write_failure(error)
        if line is None:
            raise
        print("error: " + _one_line(line), file=sys.stderr)
        return EXIT_BAD_INPUT


def _interrupted(status: int) -> int:
    try:
        print("interrupted; earlier results are left as they were", file=sys.stderr)
    except (OSError, ValueError, AttributeError):
        return _broken_stream()
    return status


def _broken_stream() -> int:
    problem = stream_problem() or "stdout"
    if problem != "stderr":
        # BrokenPipeError too: stderr may be the pipe that broke; then nothing is shown.
        with contextlib.suppress(OSError, ValueError, AttributeError):
            print(f"error: {problem}: is closed; stopped (what was not published yet is "
                  "discarded, earlier results are left as they were)", file=sys.stderr)
    silence_streams()
    return EXIT_BROKEN_STREAM


def _one_line(message: str) -> str:
    r"""Return ``message`` as one line of printable text.

    Whatever a library (or a file name, or an option's value) put into the message: a
    run of whitespace becomes one space, and a control character that is left (an ESC
    that would recolour the terminal) is shown escaped.

    Examples
    --------
    >>> _one_line("w.toml: name:\n  bad \x1b[31mred")
    'w.toml: name: bad \\x1b[31mred'
    """
    text = " ".join(message.split())
    return "".join(char if char.isprintable() else char.encode("unicode_escape").decode()
                   for char in text)


def console_main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the ``semistatic`` command: :func:`main`, then exit with its status.

    After Ctrl-C, a stop signal or a closed stream the interpreter's own teardown is
    skipped (``os._exit``, once the output is flushed and every result staged or cleaned
    up by :func:`main`): an interrupt that lands while numba loads or compiles a kernel
    can leave a half-built llvmlite object
    whose destructor then frees memory twice at exit (seen as "free(): double free
    detected" after the one ``interrupted`` line).

    Examples
    --------
    >>> try:
    ...     console_main(["check", "pal1"])  # doctest: +ELLIPSIS
    ... except SystemExit as done:
    ...     print("exit status", done.code)
    pal1: valid (...pal1.toml)
    ...
    exit status 0
    """
    status = main(argv)
    if status > 128:  # 128 + N: stopped by signal N, or by a closed stream (SIGPIPE's)
        with contextlib.suppress(OSError, ValueError, AttributeError):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(status)
    sys.exit(status)
