"""Test-suite set-up shared by the tests and the packages' doctests.

Doctests cannot carry a marker, so the few whose examples run a bundled scenario's closed
loop (seconds to tens of seconds each) are marked ``slow`` here by name:
``make test`` leaves them out, ``make test-all`` (and CI) runs them. A renamed one
is caught by tests/test_slow_doctests.py.
"""

from __future__ import annotations

import pytest

from semistatic.kernel_cache import warm_kernel_cache

# Measured with --durations (warm cache, one core): 21, 13, 10, 8, 5, 4 and 3 s.
CLOSED_LOOP_DOCTESTS = {
    "scenarios.bench.testbench.Testbench.run_lap",
    "scenarios.bench.testbench.Testbench.run",
    "scenarios.bench.testbench.Testbench",
    "scenarios.bench.sharing",
    "scenarios.bench.runner.run_scenario",
    "scenarios.bench.saved_state",
    "scenarios.bench.saved_state.SavedStates.save_state",
    "scenarios.tuning.warm",
    "scenarios.results.emergence",
    "scenarios.results.stopping",
}


def pytest_configure(config: pytest.Config) -> None:
    """Compile the mapper's kernels ahead of the tests, on every core, once per session.

    A library call never compiles ahead (``Testbench.reset`` starts no process); the
    command line and this suite ask for it. Under pytest-xdist (``make test``) the
    controller compiles before it starts the workers, which then load them from the cache.
    """
    warm_kernel_cache()


@pytest.hookimpl(tryfirst=True)  # before -m deselects by marker
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark the closed-loop doctests ``slow``."""
    for item in items:
        if isinstance(item, pytest.DoctestItem) and item.name in CLOSED_LOOP_DOCTESTS:
            item.add_marker(pytest.mark.slow)
