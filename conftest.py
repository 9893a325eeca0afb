"""Test-suite set-up shared by the tests and the packages' doctests."""

import pytest

from semistatic.kernel_cache import warm_kernel_cache


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels():
    """Compile the mapper's kernels ahead of the tests, on every core, once per session.

    A library call never compiles ahead (``Testbench.reset`` starts no process); the
    command line and this suite ask for it.
    """
    warm_kernel_cache()
