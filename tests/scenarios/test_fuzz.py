"""Property-based fuzzing of the scenario and world files (hypothesis).

Mutants of the bundled files (keys dropped, duplicated into lists, retyped, set to
extreme or non-finite numbers, strings where tables go) are validated with
``semistatic check``: each is either accepted or rejected with exit status 2 and one
``error:`` line, never a traceback. ``make test`` validates ``VALIDATE_EXAMPLES`` mutants,
derandomised so CI is reproducible. The ``fuzz`` profile (``make fuzz``, marker ``fuzz``)
also runs each accepted mutant for one short lap: it must finish (exit 0), or fail with a
clear line (exit 1 for a lap that cannot complete, 2 for bad input), never crash.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import tomllib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scenarios.cli import main
from scenarios.spec.load import DATA_DIR as SCENARIO_DIR
from scenarios.spec.load import paper_scenarios
from worlds.load import DATA_DIR as WORLD_DIR

VALIDATE_EXAMPLES = 300
"""Mutants validated in ``make test`` (the acceptance asks for at least 300 in 60 s)."""

RUN_EXAMPLES = 200
"""Mutants validated and, when accepted, run for one lap in the ``fuzz`` profile."""

RUN_LAP_TIMEOUT_S = 60.0
"""``lap_timeout`` of the fuzz profile's runs: a bundled lap takes 25-60 simulated s."""

EXTREMES = (0, -1, 1, 2**63, -(2**63), 1e-300, 1e308, -1e308, 1e9, -1e9, 0.5,
            math.nan, math.inf, -math.inf)
"""Numbers that break code which forgot a bound: zero, signs, huge, tiny, non-finite."""

OTHER_TYPES = ("text", "", True, [], [1, 2], {}, {"x": 1}, "../../escape")


def _toml(value: Any) -> str:
    """Return ``value`` as a TOML value (inline tables), non-finite floats included."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(item) for item in value) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml(v)}" for k, v in value.items()) + "}"


def _document(table: dict[str, Any]) -> str:
    return "".join(f"{json.dumps(key)} = {_toml(value)}\n" for key, value in table.items())


def _places(value: Any, path: tuple = ()) -> list[tuple]:
    """Return the path (keys and indices) of every value inside ``value``."""
    places = [path] if path else []
    if isinstance(value, dict):
        for key, item in value.items():
            places += _places(item, (*path, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            places += _places(item, (*path, index))
    return places


def _container(document: Any, path: tuple) -> Any:
    for step in path[:-1]:
        document = document[step]
    return document


@st.composite
def mutants(draw) -> tuple[str, dict, dict]:
    """Draw a bundled scenario and its world with one to three mutations in either."""
    name = draw(st.sampled_from(paper_scenarios()))
    scenario = tomllib.loads((SCENARIO_DIR / f"{name}.toml").read_text())
    world = tomllib.loads((WORLD_DIR / f"{scenario['world']}.toml").read_text())
    scenario["world"] = "world.toml"
    scenario.setdefault("name", name)
    for _ in range(draw(st.integers(1, 3))):
        target = draw(st.sampled_from([scenario, world]))
        places = _places(target)
        if not places:
            continue
        path = draw(st.sampled_from(places))
        parent, key = _container(target, path), path[-1]
        action = draw(st.sampled_from(["drop", "duplicate", "retype", "number", "table"]))
        if action == "drop":
            del parent[key]
        elif action == "duplicate" and isinstance(parent, list):
            parent.insert(key, copy.deepcopy(parent[key]))
        elif action == "duplicate":
            other = draw(st.sampled_from(places))
            parent[key] = copy.deepcopy(_container(target, other)[other[-1]])
        elif action == "retype":
            # A copy: a later mutation may change it in place, and the module's own lists
            # and tables must stay as they are for the next example.
            parent[key] = copy.deepcopy(draw(st.sampled_from(OTHER_TYPES)))
        elif action == "number":
            parent[key] = draw(st.sampled_from(EXTREMES) | st.floats() | st.integers())
        else:
            parent[key] = draw(st.sampled_from(["a string", 3, [1.0, 2.0]]))
    return name, scenario, world


def _write(folder: Path, scenario: dict, world: dict) -> Path:
    """Write the mutant's world and scenario files; return the scenario's path."""
    (folder / "world.toml").write_text(_document(world))
    path = folder / "scenario.toml"
    path.write_text(_document(scenario))
    return path


def _cli(*args: object) -> tuple[int, str]:
    """Run ``semistatic ARGS`` in-process; return the exit status and stderr."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        status = main([str(arg) for arg in args])
    return status, err.getvalue()


def _assert_clean_rejection(status: int, err: str) -> None:
    lines = err.strip().splitlines()
    assert status == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err


@pytest.mark.slow
@settings(max_examples=VALIDATE_EXAMPLES, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(mutant=mutants())
def test_every_mutant_is_accepted_or_rejected_in_one_line(tmp_path, mutant):
    status, err = _cli("check", _write(tmp_path, *mutant[1:]))
    if status != 0:
        _assert_clean_rejection(status, err)


@pytest.mark.fuzz
@settings(max_examples=RUN_EXAMPLES, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(mutant=mutants())
def test_accepted_mutants_run_a_short_lap_or_fail_clearly(tmp_path, mutant):
    path = _write(tmp_path, *mutant[1:])
    status, err = _cli("check", path)
    if status != 0:
        _assert_clean_rejection(status, err)
        return
    status, err = _cli("run", path, "--laps", 1, "--no-figures", "--set",
                       f"lap_timeout={RUN_LAP_TIMEOUT_S}", "--out", tmp_path / "out")
    assert "Traceback" not in err
    if status == 1:
        assert [line for line in err.splitlines() if line.startswith("run failed: lap 1")], err
    elif status == 2:
        _assert_clean_rejection(status, err)
    else:
        assert status == 0, err
