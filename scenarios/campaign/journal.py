"""The journal of a campaign: one line per finished run, so a stopped campaign resumes.

Each finished run is appended to ``DIR/runs.jsonl`` as one JSON line and flushed to the
disk (``fsync``) before the next one is counted: after a SIGKILL, the journal holds every
run that finished, and at worst one half-written last line, which reading skips (that
run is simply run again). Re-running the same command reads the journal and runs only
what is missing, so no run is ever recorded twice.

Examples
--------
>>> import tempfile
>>> path = Path(tempfile.mkdtemp()) / "runs.jsonl"
>>> with Journal(path) as journal:
...     journal.append("pal1 adaptive sample=0 seed=0", {"detection": {"f1": 1.0}}, None)
>>> sorted(read_journal(path))
['pal1 adaptive sample=0 seed=0']
>>> _ = path.open("a").write('{"run": "half-writ')  # a SIGKILL in mid-line
>>> len(read_journal(path))
1
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from semistatic.errors import SpecError
from semistatic.validation import loads_json

__all__ = ["JOURNAL_FILE", "Journal", "JournalEntry", "read_journal"]

JOURNAL_FILE = "runs.jsonl"

JournalEntry = tuple[dict[str, Any] | None, str | None]
"""A finished run's metrics (``metrics.json`` content), or the error it raised."""


def read_journal(path: Path) -> dict[str, JournalEntry]:
    """Return ``{run: (metrics, error)}`` of every complete line of the journal at ``path``.

    A line that is not a complete JSON object of a run (the last one, cut by a kill) is
    skipped; a run given twice keeps its first line.
    """
    entries: dict[str, JournalEntry] = {}
    if not path.exists():
        return entries
    with path.open("rb") as lines:
        for line in lines:
            try:
                entry = loads_json(line.decode(), file=str(path))
            except (json.JSONDecodeError, UnicodeDecodeError, SpecError):
                continue
            if isinstance(entry, dict) and isinstance(entry.get("run"), str):
                entries.setdefault(entry["run"], (entry.get("metrics"), entry.get("error")))
    return entries


class Journal:
    """Append finished runs to the journal at ``path``, each on the disk before returning."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __enter__(self) -> Journal:
        self._file = self.path.open("ab")
        # A line cut by a kill must not swallow the next run's line: start a fresh line.
        if self._file.tell() and not self.path.read_bytes().endswith(b"\n"):
            self._file.write(b"\n")
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self._file.close()

    def append(self, run: str, metrics: dict[str, Any] | None, error: str | None) -> None:
        """Record run ``run`` as finished: its metrics, or the error it raised."""
        line = json.dumps({"run": run, "error": error, "metrics": metrics},
                          allow_nan=True, separators=(",", ":"))
        self._file.write(line.encode() + b"\n")
        self._file.flush()
        os.fsync(self._file.fileno())
