"""Publishing segment maps to a fleet map store as a vehicle drives (an observer).

When the vehicle leaves a path segment, :class:`SegmentPublisher` encodes that segment's
local map (:mod:`semistatic.fleet`) and puts it into its :class:`FleetMapStore`; the run's
log then holds the traffic (``RunLog.sharing``): messages, their encoded bytes and the
bytes of the same segments' safety areas as 5 cm occupancy grids, the paper's
bandwidth claim measured. A scenario turns it on with ``sharing = true``.

Examples
--------
>>> from scenarios.spec.load import load_scenario
>>> from scenarios.bench.testbench import Testbench
>>> spec = load_scenario("pal1", overrides=["laps=1"])
>>> with Testbench(spec) as bench:
...     bench.add_observer(SegmentPublisher())
...     log = bench.run()
>>> log.sharing["messages"], log.sharing["grid_bytes"] > 10 * log.sharing["bytes"]
(3, True)
"""

from __future__ import annotations

from scenarios.bench.observer import Observer, VehicleView
from semistatic.fleet import FleetMapStore

__all__ = ["SegmentPublisher"]


class SegmentPublisher(Observer):
    """Observer: publish each segment's local map to ``store`` when the vehicle leaves it.

    Parameters
    ----------
    store
        The fleet map store (a new one when omitted).
    sender
        The publishing vehicle's index.
    segment_names
        The fleet's segment names in path order (a message names a segment by its place
        there); default: the vehicle's segments.

    Notes
    -----
    The last segment of the last lap is published when the run ends. The traffic totals
    and per-message arrays go to ``vehicle.log.sharing`` at every lap end.

    Examples
    --------
    >>> SegmentPublisher().store.totals()
    {'messages': 0, 'bytes': 0, 'grid_bytes': 0}
    """

    def __init__(self, store: FleetMapStore | None = None, sender: int = 0,
                 segment_names: list[str] | None = None) -> None:
        self.store = FleetMapStore() if store is None else store
        self.sender = int(sender)
        self.segment_names = segment_names
        self._segment: str | None = None
        self._entered = 0.0

    def on_scan(self, vehicle: VehicleView, record) -> None:
        """Publish the segment the vehicle just left (when the scan is in a new one)."""
        if record.segment != self._segment:
            if self._segment is not None:
                self._publish(vehicle, record.scan.stamp)
            self._segment = record.segment
            self._entered = record.scan.stamp

    def on_lap_end(self, vehicle: VehicleView, lap_log) -> None:
        """Copy the traffic into ``bench.log.sharing``; publish the last segment at the end."""
        if lap_log.lap == vehicle.log.spec.laps and self._segment is not None:
            self._publish(vehicle, vehicle.sim_time)
            self._segment = None
        traffic = self.store.traffic_arrays()
        vehicle.log.sharing = {
            **self.store.totals(),
            "stamp": traffic["stamp"].tolist(),
            "message_bytes": traffic["bytes"].tolist(),
            "message_grid_bytes": traffic["grid_bytes"].tolist(),
        }

    def _publish(self, vehicle: VehicleView, stamp: float) -> None:
        names = self.segment_names or [segment.name for segment in vehicle.segments]
        index = names.index(self._segment)
        self.store.publish(index, self.sender, vehicle.local_maps[self._segment], stamp=stamp,
                           since=self._entered)
