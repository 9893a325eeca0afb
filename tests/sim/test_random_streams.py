"""Per-component random streams: independent by name, repeatable by seed."""

import numpy as np
import pytest

from sim.random_streams import RandomStreams


def test_a_component_stream_does_not_depend_on_the_others():
    alone = RandomStreams(7).generator("laser/safety").standard_normal(1000)
    streams = RandomStreams(7)
    # Another component created first and drawing heavily: the laser's numbers stay.
    streams.generator("encoders").standard_normal(10_000)
    streams.generator("laser/localization").uniform(size=5)
    np.testing.assert_array_equal(streams.generator("laser/safety").standard_normal(1000), alone)


def test_streams_differ_between_components_and_seeds():
    draws = {
        (seed, name): RandomStreams(seed).generator(name).standard_normal(64)
        for seed in (0, 1)
        for name in ("encoders", "laser/safety", "person/walker")
    }
    values = list(draws.values())
    for i, first in enumerate(values):
        for second in values[i + 1 :]:
            # Independent streams: no shared values, correlation near zero.
            assert not np.any(first == second)
            assert abs(np.corrcoef(first, second)[0, 1]) < 0.5


@pytest.mark.parametrize("seed", [-1, 1.5, True])
def test_a_bad_seed_is_refused(seed):
    with pytest.raises(ValueError, match="seed"):
        RandomStreams(seed)
