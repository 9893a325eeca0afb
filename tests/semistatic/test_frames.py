import math

import numpy as np

from semistatic.frames import between, compose, inverse, wrap_angle


def test_float_path_of_wrap_angle_is_the_array_path_to_the_last_bit():
    angles = np.random.default_rng(0).normal(0.0, 10.0, 2000)
    specials = [0.0, -0.0, math.pi, -math.pi, 2 * math.pi, -2 * math.pi, 3 * math.pi, 1e-300]
    values = [*angles.tolist(), *specials, math.nextafter(math.pi, 4.0), 1e6 + 0.5]
    array_path = wrap_angle(np.array(values))
    for value, expected in zip(values, array_path, strict=True):
        result = wrap_angle(value)
        assert type(result) is float
        assert result == expected
        assert -math.pi < result <= math.pi


def test_compose_inverse_and_between_agree():
    a, b = np.array([1.0, -2.0, 3.0]), np.array([0.5, 0.25, -2.5])
    np.testing.assert_allclose(compose(a, inverse(a)), 0.0, atol=1e-12)
    np.testing.assert_allclose(compose(a, between(a, b)), b, atol=1e-12)
