"""One independent random stream per simulated component, all from the scenario seed.

A run's noise comes from one :class:`numpy.random.SeedSequence` built from the seed;
each component (a laser, the wheel encoders, a person, a user's script) draws from its
own child sequence, keyed by the component's *name* rather than by the order in which
components were created. Adding a sensor, or drawing more numbers in one component,
therefore leaves every other component's noise unchanged (docs/design.md, conventions),
and the same seed gives the same streams.

Examples
--------
>>> streams = RandomStreams(0)
>>> first = streams.generator("encoders").standard_normal(2)
>>> again = RandomStreams(0).generator("encoders").standard_normal(2)
>>> bool((first == again).all())
True
>>> other = streams.generator("laser/safety").standard_normal(2)
>>> bool((first == other).any())
False
"""

from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["RandomStreams", "component_key"]


def component_key(name: str) -> int:
    """Return the 64-bit spawn key of component ``name`` (stable across runs and machines).

    Examples
    --------
    >>> component_key("encoders") == component_key("encoders")
    True
    >>> component_key("encoders") != component_key("laser/safety")
    True
    """
    digest = hashlib.blake2b(name.encode("utf-8"), digest_size=8).digest()
    return int.from_bytes(digest, "little")


class RandomStreams:
    """The random streams of one run: ``generator(name)`` for each component.

    Parameters
    ----------
    seed
        The scenario seed (an integer >= 0).

    Notes
    -----
    A component's generator is the child of ``SeedSequence(seed)`` with spawn key
    ``(component_key(name),)``; asking twice for the same name gives two generators
    that repeat the same numbers, so ask once per component.

    Examples
    --------
    >>> streams = RandomStreams(3)
    >>> streams.seed_sequence.entropy
    3
    >>> isinstance(streams.generator("encoders"), np.random.Generator)
    True
    """

    def __init__(self, seed: int) -> None:
        if isinstance(seed, bool) or int(seed) != seed or seed < 0:
            raise ValueError(f"RandomStreams: seed must be an integer >= 0, got {seed!r}")
        self.seed_sequence = np.random.SeedSequence(int(seed))

    def sequence(self, name: str) -> np.random.SeedSequence:
        """Return the seed sequence of component ``name``.

        Examples
        --------
        >>> RandomStreams(0).sequence("encoders").spawn_key == (component_key("encoders"),)
        True
        """
        return np.random.SeedSequence(
            self.seed_sequence.entropy, spawn_key=(component_key(name),)
        )

    def generator(self, name: str) -> np.random.Generator:
        """Return a fresh generator on component ``name``'s stream."""
        return np.random.default_rng(self.sequence(name))
