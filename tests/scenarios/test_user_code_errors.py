"""User code gets named errors: a policy's or observer's wrong answer names the class, the
hook and what was expected, where the answer is used (issue 29, item 8).

Before, a mask of the wrong length gave a raw ``IndexError``, a tuple an
``AttributeError``, and an integer mask was silently taken as fancy indexing.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from scenarios.bench.observer import Observer, require_observer
from scenarios.bench.policies import (
    FieldPolicy,
    FieldReadings,
    checked_readings,
    checked_speed_cap,
)
from scenarios.bench.testbench import Testbench
from scenarios.spec.load import load_scenario
from tests.scenarios.tiny_world import write_tiny

COUNT = 541  # readings in a scan: the masks must have one entry each


class MyPolicy(FieldPolicy):
    name = "mine"

    def __init__(self, readings=None, cap=None):
        self.readings = readings
        self.cap = cap

    def counted_readings(self, view):
        return self.readings(len(view.points)) if callable(self.readings) else self.readings

    def speed_cap(self, view):
        return self.cap


NAMED = r"policy MyPolicy \('mine'\)"

WRONG_READINGS = [
    ((True, False), "counted_readings returned a tuple; expected FieldReadings"),
    ([True] * COUNT, "counted_readings returned a list; expected FieldReadings"),
    (np.ones(COUNT, dtype=bool), "counted_readings returned a bool array of shape"),
    (FieldReadings(warning=np.ones(COUNT - 1, dtype=bool)),
     r"warning = a bool array of shape \(540,\); expected None or a boolean numpy array of "
     r"shape \(541,\)"),
    (FieldReadings(protective=np.arange(COUNT)),
     r"protective = a int64 array of shape \(541,\); expected None or a boolean"),
    (FieldReadings(warning=np.ones(COUNT)), r"warning = a float64 array"),
    (FieldReadings(warning=(True,) * COUNT), "warning = a tuple; expected None"),
    (FieldReadings(warning=np.ones((COUNT, 1), dtype=bool)), r"shape \(541, 1\)"),
]


@pytest.mark.parametrize(("answer", "message"), WRONG_READINGS)
def test_wrong_readings_name_policy_hook_and_expectation(answer, message):
    with pytest.raises(TypeError, match=f"^{NAMED}.*{message}"):
        checked_readings(MyPolicy(), answer, COUNT)


def test_right_readings_pass_unchanged():
    mask = np.zeros(COUNT, dtype=bool)
    answer = FieldReadings(warning=mask, protective=None)
    assert checked_readings(MyPolicy(), answer, COUNT) is answer
    assert checked_readings(MyPolicy(), None, COUNT) is None


@pytest.mark.parametrize(("cap", "error", "message"), [
    ((0.5,), TypeError, "returned a tuple"),
    ("0.5", TypeError, "returned a str"),
    (True, TypeError, "returned a bool"),
    (np.array([0.5]), TypeError, r"returned a float64 array of shape \(1,\)"),
    (1.5, ValueError, "returned 1.5"),
    (-0.1, ValueError, "returned -0.1"),
    (float("nan"), ValueError, "returned nan"),
])
def test_wrong_speed_cap_is_named(cap, error, message):
    with pytest.raises(error, match=f"^{NAMED}.speed_cap {message}; expected None or a "
                                    r"number in \[0, 1\]"):
        checked_speed_cap(MyPolicy(), cap)


@given(st.floats(min_value=0.0, max_value=1.0) | st.integers(min_value=0, max_value=1))
def test_any_cap_in_range_passes(cap):
    assert checked_speed_cap(MyPolicy(), cap) == float(cap)


@pytest.mark.parametrize(("flag", "value"), [("wants_polylines", "yes"),
                                             ("every_vehicle", 1), ("wants_polylines", None)])
def test_observer_flags_must_be_booleans(flag, value):
    class MyObserver(Observer):
        pass

    setattr(MyObserver, flag, value)
    with pytest.raises(TypeError, match=f"^observer MyObserver.{flag} is .*; expected True or "
                                        "False"):
        require_observer(MyObserver())


def test_observer_hook_that_is_no_method_is_named():
    class MyObserver(Observer):
        on_scan = None

    with pytest.raises(TypeError, match=r"^observer MyObserver.on_scan is NoneType, not a "
                                        r"method; expected def on_scan\(self, vehicle, ...\)"):
        require_observer(MyObserver())


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return load_scenario(write_tiny(tmp_path_factory.mktemp("tiny")), overrides=["laps=1"])


def _first_scans(bench: Testbench, ticks: int = 60) -> None:
    for _ in range(ticks):  # a few safety scans (the laser runs at a tenth of physics)
        bench.step()


@pytest.mark.parametrize(("policy", "error", "message"), [
    (MyPolicy(readings=lambda n: np.ones(n, dtype=int)), TypeError,
     r"counted_readings returned a int64 array"),
    (MyPolicy(readings=lambda n: FieldReadings(warning=np.ones(n + 3, dtype=bool))), TypeError,
     r"counted_readings returned warning = a bool array of shape \(\d+,\); expected None"),
    (MyPolicy(cap=(0.2,)), TypeError, "speed_cap returned a tuple"),
], ids=["int-array", "wrong-length", "tuple-cap"])
def test_the_bench_names_a_wrong_answer_where_it_is_used(tiny, policy, error, message):
    with Testbench(tiny, policy=policy) as bench:
        bench.reset(seed=0)
        with pytest.raises(error, match=f"^{NAMED}.{message}"):
            _first_scans(bench)


def test_a_right_answer_still_runs(tiny):
    """Masks that count every reading and a cap of 1: the same run as no policy answer."""
    everything = MyPolicy(readings=lambda n: FieldReadings(np.ones(n, dtype=bool),
                                                           np.ones(n, dtype=bool)), cap=1.0)
    with Testbench(tiny, policy=everything) as bench:
        bench.reset(seed=0)
        _first_scans(bench)
        assert bench.lap == 1
        assert bench.zone in ("free", "warning", "protective")
