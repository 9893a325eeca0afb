"""Where a Rerun recording puts things, and the pieces the recorder builds them with.

The timeline (:data:`TIMELINE`), the entity roots (:data:`MAP_ROOT`, :data:`SERIES_ROOT`,
:data:`EVENTS_ROOT`), the time series of each vehicle (:data:`SERIES`) and the viewer's
default layout (:func:`blueprint`); the per-scan rows buffered and sent in columns
(:class:`Column`), what is remembered of a vehicle between scans (:class:`VehicleTrack`)
and the small geometry logged (:func:`transform`, :func:`closed`,
:func:`person_separation`). :class:`~scenarios.logs.rrd.RerunRecorder` uses them.

Examples
--------
>>> closed([[0, 0], [1, 0], [1, 1]]).tolist()
[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0]]
>>> transform([1.0, 2.0, 0.0])["translation"]
[[1.0, 2.0, 0.0]]
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import shapely

from scenarios.bench.observer import VehicleView
from semistatic.frames import transform_points

__all__ = [
    "EVENTS_ROOT",
    "MAP_ROOT",
    "SERIES",
    "SERIES_ROOT",
    "TIMELINE",
    "VECTOR_SIZE",
    "Column",
    "VehicleTrack",
    "blueprint",
    "closed",
    "person_separation",
    "transform",
]

TIMELINE = "sim_time"
"""The timeline: simulated seconds since the run started (a replay: the log's stamps)."""

MAP_ROOT = "/map"
"""The top-down map in the world frame: the world, then ``/map/VEHICLE/...``."""

SERIES_ROOT = "/series"
"""The time series: ``/series/KEY/VEHICLE``."""

EVENTS_ROOT = "/events"
"""The events as a text log: ``/events/VEHICLE``."""

SERIES = {
    "speed": "speed (m/s)",
    "speed_scale": "speed scale (1 free, 0 stopped)",
    "zone": "zone (0 free, 1 warning, 2 protective)",
    "separation": "separation from the nearest person (m)",
    "ekf_sigma_xy": "EKF position sigma (m, major axis)",
    "ekf_sigma_theta": "EKF heading sigma (rad)",
}
"""The time series of each vehicle: ``/series/KEY/VEHICLE``, one plot per key."""


VECTOR_SIZE = {"positions": 2, "translation": 3, "quaternion": 4}
"""Numbers per instance of the components :class:`Column` sends as one ``(N, d)`` array."""


class Column:
    """The buffered per-scan rows of one entity: each a few components of N instances."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.times: list[float] = []
        self.rows: list[dict[str, Any]] = []

    def add(self, stamp: float, components: dict[str, Any]) -> None:
        """Buffer one scan's components (every row of an entity has the same keys)."""
        self.times.append(stamp)
        self.rows.append(components)

    def send(self, rr: Any, stream: Any) -> None:
        """Send the buffered rows to ``stream`` in one ``send_columns`` call and forget them."""
        if not self.times:
            return
        first = self.rows[0]
        archetype = (rr.Transform3D if "translation" in first else
                     rr.Scalars if "scalars" in first else
                     rr.LineStrips2D if "strips" in first else rr.Points2D)
        lengths = [len(row[next(iter(row))]) for row in self.rows]
        columns = {}
        for key in first:
            values = [row[key] for row in self.rows]
            if key in VECTOR_SIZE:  # (N, d) numbers: one array
                columns[key] = np.concatenate(
                    [np.asarray(value, dtype=float).reshape(len(value), VECTOR_SIZE[key])
                     for value in values])
            else:  # one item per instance (strips, colours, radii, labels, scalars)
                columns[key] = [item for value in values for item in value]
        stream.send_columns(
            self.path, indexes=[rr.TimeColumn(TIMELINE, duration=self.times)],
            columns=archetype.columns(**columns).partition(lengths))
        self.times, self.rows = [], []


class VehicleTrack:
    """What the recorder remembers of one vehicle between scans."""

    def __init__(self) -> None:
        self.started = False
        self.true: list[np.ndarray] = []
        self.ekf: list[np.ndarray] = []
        self.trail_at = -math.inf
        self.zone = "clear"
        self.fields: np.ndarray | None = None
        self.infractions = 0
        self.map_counts: dict[str, dict[str, int]] = {}

    def start_lap(self) -> None:
        """Forget the trajectories of the lap before."""
        self.true, self.ekf, self.trail_at = [], [], -math.inf

    def add(self, true_pose: np.ndarray, ekf_pose: np.ndarray) -> None:
        """Add one scan's true and EKF positions to the lap's trajectories."""
        self.true.append(true_pose[:2].copy())
        self.ekf.append(ekf_pose[:2].copy())


def transform(pose: np.ndarray) -> dict[str, list]:
    """Return the Transform3D components that place a child frame at ``(x, y, theta)``."""
    x, y, theta = (float(value) for value in pose)
    return {"translation": [[x, y, 0.0]],
            "quaternion": [[0.0, 0.0, math.sin(theta / 2.0), math.cos(theta / 2.0)]]}


def closed(points: np.ndarray) -> np.ndarray:
    """Return a polygon's ``(N, 2)`` vertices with the first repeated at the end."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    return np.vstack([points, points[:1]]) if len(points) > 2 else points


def person_separation(vehicle: VehicleView, true_pose: np.ndarray) -> float | None:
    """Return the distance (m) from the true footprint to the nearest person's body."""
    people = [xy for xy in vehicle.person_positions.values() if xy is not None]
    if not people:
        return None
    radius = {person.name: person.radius for person in vehicle.world.people}
    outline = shapely.Polygon(transform_points(true_pose,
                                               np.asarray(vehicle.robot.footprint, float)))
    names = [name for name, xy in vehicle.person_positions.items() if xy is not None]
    distances = shapely.distance(outline, shapely.points(np.array(people, dtype=float)))
    gaps = distances - np.array([radius.get(name, 0.25) for name in names])
    return float(max(gaps.min(), 0.0))


def blueprint() -> Any:
    """Return the default layout: the top-down map beside the time series and events."""
    import rerun.blueprint as rrb

    plots = [rrb.TimeSeriesView(origin=f"{SERIES_ROOT}/{key}", name=title)
             for key, title in SERIES.items()]
    return rrb.Blueprint(
        rrb.Horizontal(
            # From the root, so that the y flip logged at /map applies to what it shows.
            rrb.Spatial2DView(origin="/", contents=f"{MAP_ROOT}/**", name="map (top-down)"),
            rrb.Vertical(
                rrb.Grid(*plots, grid_columns=2),
                rrb.TextLogView(origin=EVENTS_ROOT, name="events"),
                row_shares=[3, 2],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
