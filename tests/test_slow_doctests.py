"""The closed-loop doctests that ``conftest.py`` marks slow by name exist under that name.

``make test`` leaves them out by name; a doctest renamed or moved without updating the
list would quietly run in the fast suite again (tens of seconds each).
"""

from __future__ import annotations

import doctest
import importlib
import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]


def slow_doctest_names() -> list[str]:
    spec = importlib.util.spec_from_file_location("_root_conftest", ROOT / "conftest.py")
    conftest = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conftest)
    return sorted(conftest.CLOSED_LOOP_DOCTESTS)


def module_of(name: str) -> ModuleType:
    """Return the longest importable prefix of a dotted doctest name."""
    parts = name.split(".")
    for end in range(len(parts), 0, -1):
        prefix = ".".join(parts[:end])
        try:
            return importlib.import_module(prefix)
        except ModuleNotFoundError as error:
            if not prefix.startswith(error.name or "?"):
                raise  # a module that exists failed to import
    raise AssertionError(f"{name}: no module")


@pytest.mark.parametrize("name", slow_doctest_names())
def test_every_name_marked_slow_is_a_doctest_pytest_collects(name):
    module = module_of(name)
    # The names pytest's doctest items carry: the module's name, then the qualified name.
    found = {test.name for test in doctest.DocTestFinder().find(module, module.__name__)
             if test.examples}
    assert name in found
