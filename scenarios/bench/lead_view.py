"""The bench seen as its first vehicle: the read-only properties of a VehicleView.

:class:`LeadVehicleView` gives :class:`~scenarios.bench.testbench.Testbench` the state an
observer reads (:class:`~scenarios.bench.observer.VehicleView`), each a property that
reads the same name of the first vehicle of the bench's ``fleet``.

Examples
--------
>>> from types import SimpleNamespace
>>> class Bench(LeadVehicleView):
...     fleet = [SimpleNamespace(name="robot", lap=2, zone="free")]
>>> bench = Bench()
>>> bench.name, bench.lap, bench.zone
('robot', 2, 'free')
"""

from __future__ import annotations

import numpy as np

__all__ = ["LeadVehicleView"]


def _of_lead(name: str, doc: str) -> property:
    """Return a read-only property reading ``name`` of the bench's first vehicle."""
    return property(lambda bench: getattr(bench.fleet[0], name), doc=doc)


class LeadVehicleView:
    """The :class:`~scenarios.bench.observer.VehicleView` of a bench's first vehicle.

    A mixin for a class with a ``fleet``, a list of
    :class:`~scenarios.bench.vehicle.Vehicle` (the first one leads).
    """

    name = _of_lead("name", "The first vehicle's name.")
    segment = _of_lead("segment", "The path segment the first vehicle is on.")
    lap_log = _of_lead("lap_log", "The first vehicle's current lap log.")
    true_pose = _of_lead("true_pose", "The first vehicle's true pose (x, y, theta); for scoring.")
    true_twist = _of_lead("true_twist", "The first vehicle's true (v_forward, v_left, omega).")
    ekf_pose = _of_lead("ekf_pose", "The first vehicle's EKF pose estimate (x, y, theta).")
    ekf_covariance = _of_lead("ekf_covariance", "The first vehicle's (3, 3) EKF covariance.")
    local_maps = _of_lead("local_maps", "The first vehicle's local map of every segment.")
    zone = _of_lead("zone", "The first vehicle's safety zone: free, warning or protective.")
    speed_scale = _of_lead("speed_scale", "The first vehicle's speed factor (1 free, 0 stop).")
    policy = _of_lead("policy", "The first vehicle's field policy (each vehicle has its own).")
    lap = _of_lead("lap", "The current lap, from 1 (the last lap once the run is done).")
    world = _of_lead("world", "The simulated world (boxes as they stand now).")
    person_positions = _of_lead("person_positions", "Where the people stand now (or None).")
    layout_revision = _of_lead("layout_revision", "Changes whenever a box moves.")
    robot = _of_lead("robot", "The first vehicle's preset (footprint, lasers, wheels).")

    def vehicle_outlines(self) -> list[np.ndarray]:
        """Return the true footprints of the fleet's vehicles (for scoring)."""
        return self.fleet[0].vehicle_outlines()
