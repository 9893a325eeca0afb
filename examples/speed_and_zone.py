"""An observer that records the robot's speed and safety zone at every tick, and plots them.

Observers are how an experiment watches a run without touching the robot: any object
with some of ``on_tick(bench)``, ``on_scan(bench, record)``, ``on_lap_start(bench,
lap)`` and ``on_lap_end(bench, lap_log)``. This one keeps the true forward speed, the
EKF's position uncertainty and the zone (free, warning, protective) at every physics
tick, and draws them over time with the zones shaded.

Run it::

    python examples/speed_and_zone.py [--scenario pal3b] [--laps 1] [--out speed_and_zone.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from scenarios import Observer, Testbench, load_scenario

ZONE_COLOURS = {"warning": "tab:orange", "protective": "tab:red"}


class SpeedAndZone(Observer):
    """Keep time, forward speed, position sigma and zone of every physics tick."""

    def __init__(self) -> None:
        self.time: list[float] = []
        self.speed: list[float] = []
        self.sigma: list[float] = []
        self.zone: list[str] = []
        self.lap_starts: list[float] = []

    def on_lap_start(self, bench, lap: int) -> None:
        """Note when a lap starts (the robot was carried back to the start)."""
        self.lap_starts.append(bench.sim_time)

    def on_tick(self, bench) -> None:
        """Record one tick."""
        self.time.append(bench.sim_time)
        self.speed.append(float(bench.true_twist[0]))
        self.sigma.append(float(np.sqrt(np.linalg.eigvalsh(bench.ekf_covariance[:2, :2])[-1])))
        self.zone.append(bench.zone)

    def plot(self, path: Path, title: str) -> Path:
        """Draw speed and sigma over time with the warning/protective periods shaded."""
        time, zone = np.array(self.time), np.array(self.zone)
        fig = Figure(figsize=(10.0, 5.0), layout="constrained")
        speed_axis, sigma_axis = fig.subplots(2, 1, sharex=True)
        speed_axis.plot(time, self.speed, color="black", lw=0.8)
        for name, colour in ZONE_COLOURS.items():
            speed_axis.fill_between(time, 0.0, 1.0, where=zone == name, color=colour,
                                    alpha=0.3, transform=speed_axis.get_xaxis_transform(),
                                    label=name, lw=0)
        for start in self.lap_starts:
            for axis in (speed_axis, sigma_axis):
                axis.axvline(start, color="tab:purple", ls=":", lw=1.0)
        speed_axis.set_ylabel("forward speed [m/s]")
        speed_axis.legend(loc="upper right", fontsize=8)
        sigma_axis.plot(time, np.array(self.sigma) * 1000.0, color="tab:blue", lw=0.8)
        sigma_axis.set_yscale("log")  # from the triangulated start (cm) to mm in seconds
        sigma_axis.set_ylabel("EKF position σ [mm]")
        sigma_axis.set_xlabel("time [s]")
        fig.suptitle(title)
        fig.savefig(path, dpi=100)
        return path


def record(spec) -> tuple[SpeedAndZone, object]:
    """Run ``spec`` with a :class:`SpeedAndZone` observer; return it and the run's log."""
    recorder = SpeedAndZone()
    with Testbench(spec) as bench:
        bench.add_observer(recorder)
        log = bench.run()
    return recorder, log


def main(argv: list[str] | None = None) -> int:
    """Run the scenario with the observer and write the figure."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="pal3b")
    parser.add_argument("--laps", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("speed_and_zone.png"))
    args = parser.parse_args(argv)
    spec = load_scenario(args.scenario, overrides=[f"laps={args.laps}"])
    recorder, log = record(spec)
    shares = {name: recorder.zone.count(name) / len(recorder.zone) for name in
              ("free", "warning", "protective")}
    print(f"{len(recorder.time)} ticks over {recorder.time[-1]:.1f} s; "
          + ", ".join(f"{name} {share:.0%}" for name, share in shares.items())
          + f"; stops {sum(lap.stops for lap in log.laps)}")
    print(f"figure: {recorder.plot(args.out, f'{spec.name}: speed and safety zone per tick')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
