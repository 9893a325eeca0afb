"""Try your own safety-field policy beside the two bundled ones.

The paper leaves the use of the local maps to "the developers of the navigation
system". A policy decides, at every safety scan, which laser readings count against
the warning and the protective field (:mod:`scenarios.bench.policies`). This one, *short
warning*, keeps the protective field whole and lets the warning field count only the
readings closer than ``reach`` metres ahead: a shorter braking zone, at the price of
less warning. Whatever a policy answers, readings in the vehicle's stop envelope
always count: the robot still stops for a person.

Run it::

    python examples/custom_field_policy.py [--scenario pal1] [--laps 2] [--reach 0.8]
"""

from __future__ import annotations

import argparse

from scenarios import FieldPolicy, FieldReadings, FieldView, Testbench, load_scenario
from scenarios.results.outputs import summarize


class ShortWarning(FieldPolicy):
    """Count warning-field readings only up to ``reach`` metres ahead of the robot."""

    def __init__(self, reach: float) -> None:
        self.reach = reach
        self.name = f"short-warning-{reach:g}m"

    def counted_readings(self, view: FieldView) -> FieldReadings:
        """Return the readings nearer than ``reach`` for the warning field, all for the other."""
        return FieldReadings(warning=view.points[:, 0] <= self.reach, protective=None)


def compare(spec, policies) -> dict[str, dict]:
    """Run ``spec`` once per policy (name or object); return each run's safety metrics."""
    results = {}
    for policy in policies:
        with Testbench(spec, policy=policy) as bench:
            metrics = summarize(bench.run())
        results[metrics["policy"]] = metrics["safety"]
    return results


def main(argv: list[str] | None = None) -> int:
    """Run the scenario under three policies and print lap times and safety events."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="pal1")
    parser.add_argument("--laps", type=int, default=2)
    parser.add_argument("--reach", type=float, default=0.8)
    args = parser.parse_args(argv)
    spec = load_scenario(args.scenario, overrides=[f"laps={args.laps}"])
    results = compare(spec, ["conservative", "adaptive", ShortWarning(args.reach)])
    print(f"{'policy':<22} {'lap times s':<24} {'slowdowns':>9} {'stops':>5} {'collisions':>10}")
    for name, safety in results.items():
        times = " ".join(f"{t:.1f}" for t in safety["lap_time_s"])
        print(f"{name:<22} {times:<24} {safety['slowdowns']:>9} {safety['stops']:>5} "
              f"{safety['collisions']:>10}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
