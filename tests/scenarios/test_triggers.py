"""People's triggers: when a distance or meet trigger fires, held triggers, fire ticks."""

from types import SimpleNamespace

import numpy as np
import pytest

from robots.path import SplinePath
from scenarios.bench.triggers import PersonTriggers
from worlds.spec import PersonSpec

# A straight path east; the person crosses it at x = 6 walking north (2 m to the path).
PATH = SplinePath([(0.0, 0.0), (5.0, 0.0), (10.0, 0.0)])
FOOTPRINT = [(-0.2, -0.3), (0.5, -0.3), (0.5, 0.3), (-0.2, 0.3)]  # front 0.5 m ahead
PROGRESS = np.arange(40) * 0.25  # m, exact in binary: tick k at k/4 m


def vehicle(progress=0.0):
    return SimpleNamespace(name="agv", path=PATH, robot=SimpleNamespace(footprint=FOOTPRINT),
                           follower=SimpleNamespace(progress=progress,
                                                    params=SimpleNamespace(speed=1.0)),
                           done=False, waiting=False)


def person(**fields):
    return PersonSpec("ann", waypoints=((6.0, -2.0), (6.0, 2.0)), speed=1.0,
                      **{"trigger": "distance", **fields})


def test_a_distance_trigger_fires_when_the_front_is_that_far_from_the_crossing():
    # 6 - (p + 0.5) <= 2 from p = 3.5 m on: tick 14; tick 14 idle (NaN) moves it to 15.
    triggers = PersonTriggers([person(trigger_distance=2.0)], [vehicle()])
    assert triggers.fire_ticks(PROGRESS, lap=1) == {"ann": 14}
    idle = PROGRESS.copy()
    idle[14] = np.nan
    assert triggers.fire_ticks(idle, lap=1) == {"ann": 15}
    assert triggers.fire_ticks(PROGRESS[:14], lap=1) == {"ann": None}


def test_a_meet_trigger_leaves_when_walk_and_drive_take_as_long():
    # meet_at 0.5: the path's point; the walk takes 2 s, the drive (6 - 0.5 - p) / 1 m/s:
    # p >= 3.5 (tick 14). meet_at 1.0: 0.3 m further up the leg, 2.3 s: p >= 3.2 (tick 13).
    middle, left = (person(trigger="meet", meet_at=at) for at in (0.5, 1.0))
    assert PersonTriggers([middle], [vehicle()]).fire_ticks(PROGRESS, 1) == {"ann": 14}
    assert PersonTriggers([left], [vehicle()]).fire_ticks(PROGRESS, 1) == {"ann": 13}


def test_fire_ticks_agree_with_update_tick_by_tick():
    for spec in (person(trigger_distance=1.3), person(trigger="meet", meet_at=0.2)):
        car = vehicle()
        triggers = PersonTriggers([spec], [car])
        [expected] = triggers.fire_ticks(PROGRESS, lap=1).values()
        for tick, progress in enumerate(PROGRESS):
            car.follower.progress = progress
            if triggers.update(t=tick * 0.1, lap_start=0.0, lap=1)["ann"] is not None:
                break
        assert tick == expected


def test_people_of_other_laps_and_spent_triggers_do_not_fire():
    late = PersonTriggers([person(laps=(3,))], [vehicle()])
    assert late.fire_ticks(PROGRESS, lap=2) == {"ann": None}
    assert late.fire_ticks(PROGRESS, lap=3) == {"ann": 14}
    once = PersonTriggers([person(per_lap=False)], [vehicle()])
    once.fired["ann"] = 12.0  # fired in an earlier lap; does not re-arm
    assert once.fire_ticks(PROGRESS, lap=2) == {"ann": None}


def test_a_held_trigger_does_not_fire_until_the_people_are_replaced():
    car = vehicle(progress=9.0)  # far past the emergence point
    triggers = PersonTriggers([person()], [car])
    triggers.hold(["ann"])
    assert triggers.update(t=1.0, lap_start=0.0, lap=1) == {"ann": None}
    triggers.replace_people([person()])
    assert triggers.held == frozenset()
    assert triggers.update(t=2.0, lap_start=0.0, lap=1) == {"ann": 2.0}
    with pytest.raises(ValueError, match=r"no triggered person named \['bob'\]"):
        triggers.hold(["bob"])
