"""Segment maps published as the vehicle drives: what is sent, its size, no effect on the run."""

import numpy as np
import pytest

from scenarios.bench.runner import run_scenario
from scenarios.bench.sharing import SegmentPublisher
from scenarios.bench.testbench import Testbench
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario


@pytest.mark.slow
def test_publisher_sends_each_segment_map_once_per_pass_and_changes_nothing():
    spec = load_scenario("pal1", overrides=["laps=1"])
    publisher = SegmentPublisher()
    with Testbench(spec) as bench:
        bench.add_observer(publisher)
        shared = bench.run()
        final_maps = {name: {entry.id: entry.status for entry in local_map}
                      for name, local_map in bench.local_maps.items()}
    plain = run_scenario(spec)
    np.testing.assert_array_equal(np.asarray(shared.true_poses), np.asarray(plain.true_poses))
    assert summarize(plain).get("sharing") is None

    names = [segment.name for segment in shared.segments]
    traffic = publisher.store.traffic_arrays()
    # One pass over three segments: each published once, in path order.
    assert traffic["segment"].tolist() == [0, 1, 2]
    for index, name in enumerate(names):
        message = publisher.store.fetch(index)
        assert {entry.id: entry.status for entry in message.entries} == final_maps[name]
    metrics = summarize(shared)["sharing"]
    assert metrics["messages"] == 3
    assert metrics["bytes"] == int(traffic["bytes"].sum())
    assert metrics["grid_ratio_min"] >= 10.0
