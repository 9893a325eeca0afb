"""The shared spec validation layer: a bound's fix, unlimited limits, file/code parity."""

import math
from dataclasses import dataclass, field

import pytest

from semistatic.errors import MEMORY, SpecError
from semistatic.validation import bounds, check_fields, from_table, unlimited


@dataclass(frozen=True)
class Drive:
    """A toy spec: one bounded number with a fix and one limit that may be switched off."""

    radius: float = field(default=0.1, metadata=bounds(gt=0.0, le=2.0, fix="metres, e.g. 0.1"))
    top_speed: float = field(default=1.0, metadata={**bounds(gt=0.0, le=20.0), **unlimited()})

    def __post_init__(self):
        check_fields(self)


@pytest.mark.parametrize(
    ("changes", "key", "message"),
    [
        ({"radius": 3.0}, "radius", "must be > 0.0 and <= 2.0, got 3.0 (metres, e.g. 0.1)"),
        ({"top_speed": 25.0}, "top_speed", "must be > 0.0 and <= 20.0, got 25.0"),
        ({"top_speed": -math.inf}, "top_speed", "must be a finite number, got -inf"),
        ({"top_speed": math.nan}, "top_speed", "must be a finite number, got nan"),
    ],
)
def test_code_and_file_give_the_same_message(changes, key, message):
    with pytest.raises(SpecError) as in_code:
        Drive(**changes)
    assert (in_code.value.file, in_code.value.key, in_code.value.message) == (MEMORY, key, message)
    with pytest.raises(SpecError) as from_file:
        from_table(Drive, changes, file="drive.toml", key="drive")
    assert str(from_file.value) == f"drive.toml: drive.{key}: {message}"


def test_an_unlimited_field_takes_plus_inf_only_in_code():
    assert Drive(top_speed=math.inf).top_speed == math.inf
    assert type(Drive(top_speed=2).top_speed) is float
    # A file never switches a limit off: inf in TOML stays an error there.
    with pytest.raises(SpecError, match="finite"):
        from_table(Drive, {"top_speed": math.inf}, file="drive.toml")
