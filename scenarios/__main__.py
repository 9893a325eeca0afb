"""``python -m scenarios``: the ``semistatic`` command line, as the installed script runs it."""

from scenarios.cli import console_main

console_main()
