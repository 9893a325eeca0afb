"""Assert that building a spec in code fails the way a file would: ``<memory>: key: ...``."""

import contextlib
import re

import pytest

from semistatic.errors import MEMORY, SpecError


@contextlib.contextmanager
def raises_spec_error(key: str, message: str):
    """Expect a :class:`SpecError` from code (file ``<memory>``) at ``key``.

    ``message`` is a regular expression searched in the error's message (the text after
    ``<memory>: key: ``).
    """
    with pytest.raises(SpecError) as caught:
        yield caught
    error = caught.value
    assert (error.file, error.key) == (MEMORY, key), str(error)
    assert re.search(message, error.message), str(error)
    assert str(error) == f"{MEMORY}: {key}: {error.message}"
