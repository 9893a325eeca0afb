"""``docs/scenario-format.md`` is generated from the specs and must be current."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from scenarios.spec.format import NOT_IN_FILES, SECTIONS, field_rows, render

DOC = Path(__file__).resolve().parents[2] / "docs" / "scenario-format.md"


def test_the_page_is_current():
    assert DOC.read_text() == render(), (
        "docs/scenario-format.md is stale: python -m scenarios.spec.format "
        "docs/scenario-format.md"
    )


@pytest.mark.parametrize(("title", "cls"), SECTIONS, ids=[cls.__name__ for _, cls in SECTIONS])
def test_every_key_is_listed_with_a_meaning(title, cls):
    keys = [name for name, *_ in field_rows(cls)]
    fields = [field.name for field in dataclasses.fields(cls)
              if field.init and field.name not in NOT_IN_FILES]
    assert keys == fields
    assert all(row[-1] for row in field_rows(cls))


def test_an_undocumented_key_is_an_error():
    @dataclasses.dataclass(frozen=True)
    class Spec:
        """A spec.

        Parameters
        ----------
        known
            Documented (m).
        """

        known: float = 1.0
        unknown: float = 2.0

    with pytest.raises(ValueError, match=r"Spec\.unknown has no entry"):
        field_rows(Spec)
