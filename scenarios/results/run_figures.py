"""The figures of a run's output directory: ``DIR/figures/*.png``.

Written by :func:`~scenarios.results.outputs.write_outputs` with the rest of the directory;
:func:`write_figures` draws the map (paper Fig. 4), the EKF corrections (Fig. 5), the
tangent histograms of an associated pair (Fig. 2), the map-sharing traffic, the detection
scores and the events per lap, whose inputs :func:`run_events` gathers from a vehicle's log.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from scenarios.bench.policies import policy_name
from scenarios.bench.records import RunLog
from scenarios.results.figures import (
    plot_detection_scores,
    plot_ekf_corrections,
    plot_polygonal_map,
    plot_run_events,
    plot_sharing_traffic,
    plot_tangent_histograms,
)
from scenarios.results.figures.events import lap_speeds
from scenarios.results.figures.style import run_title

__all__ = ["run_events", "write_figures"]


def _last_lap(log: RunLog) -> slice:
    return slice(log.laps[-1].first_tick if log.laps else 0, None)


def run_events(log: RunLog) -> dict[str, Any]:
    """Return the inputs of the events figure (:func:`plot_run_events`) from a vehicle's log.

    ``laps``: each lap's log as a dict; ``speeds``: each lap's true speed from its
    recorded poses (:func:`lap_speeds`); ``events``: the safety record's protective stops
    and infractions, and every polyline of the local maps after a lap first seen during
    that lap (objects mapped and removed within the lap are not in those maps), each at
    its time since its lap's start.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> from scenarios.bench.records import LapLog
    >>> lap = LapLog(lap=1, start_time=10.0, duration_s=5.0)
    >>> feature = {"properties": {"segment": "aisle", "id": 4, "first_seen": 12.5}}
    >>> log = SimpleNamespace(laps=[lap], stamps=[10.0, 11.0, 12.0],
    ...                       true_poses=[[0, 0, 0], [0.5, 0, 0], [1.0, 0, 0]],
    ...                       safety_record=None,
    ...                       maps_after_lap=[{"aisle": {"features": [feature]}}])
    >>> inputs = run_events(log)
    >>> inputs["events"], inputs["speeds"][1][1].tolist()
    ([{'lap': 1, 't': 2.5, 'kind': 'new_object', 'label': 'aisle#4'}], [0.5, 0.5])
    """
    laps = log.laps
    ends = [lap.first_tick for lap in laps[1:]] + [len(log.stamps)]
    speeds = {}
    for lap, end in zip(laps, ends, strict=True):
        stamps = np.asarray(log.stamps[lap.first_tick:end], dtype=float) - lap.start_time
        if stamps.size > 1:
            speeds[lap.lap] = lap_speeds(stamps, log.true_poses[lap.first_tick:end])
    starts = {lap.lap: lap.start_time for lap in laps}
    events: list[dict[str, Any]] = []
    record = log.safety_record
    if record is not None:
        events += [{"lap": stop["lap"], "t": stop["t"] - starts[stop["lap"]], "kind": "stop",
                    "label": stop.get("object") or ""}
                   for stop in record.protective_stops if stop["lap"] in starts]
        events += [{"lap": item["lap"], "t": item["t"] - starts[item["lap"]],
                    "kind": "infraction", "label": item["kind"].replace("_", " ")}
                   for item in record.infractions if item["lap"] in starts]
    for lap, maps in zip(laps, log.maps_after_lap, strict=False):
        for collection in maps.values():
            for feature in collection["features"]:
                properties = feature["properties"]
                seen = properties.get("first_seen")
                if seen is not None and lap.start_time <= seen <= lap.start_time + lap.duration_s:
                    events.append({"lap": lap.lap, "t": seen - lap.start_time,
                                   "kind": "new_object",
                                   "label": f"{properties['segment']}#{properties['id']}"})
    rows = [{"lap": lap.lap, "duration_s": lap.duration_s, "completed": lap.completed,
             "stops": lap.stops, "stopped_time_s": lap.stopped_time_s,
             "slowdowns": lap.slowdowns, "slowed_time_s": lap.slowed_time_s,
             "detection": lap.detection,
             "false_objects_from_people": lap.false_objects_from_people,
             "latencies": lap.latencies} for lap in laps]
    return {"laps": rows, "speeds": speeds, "events": events}


def write_figures(log: RunLog, folder: Path) -> None:
    """Write the figures of a run into ``folder`` (created; it must not exist).

    Every figure's title starts with the run's scenario, policy, seed and laps
    (:func:`~scenarios.results.figures.style.run_title`). A fleet's figures show its
    first vehicle, except the map, which draws every vehicle's last lap.
    """
    folder.mkdir()
    spec = log.spec
    heading = run_title(spec.name, policy_name(spec.policy), spec.seed, spec.laps)
    final = log.maps_after_lap[-1] if log.maps_after_lap else {}
    polylines = [
        {"points": np.asarray(f["geometry"]["coordinates"], dtype=float).reshape(-1, 2),
         **{k: f["properties"][k] for k in ("segment", "status", "id")}}
        for collection in final.values()
        for f in collection["features"]
        if f["geometry"] is not None
    ]
    truth = log.truth_after_lap[-1] if log.truth_after_lap else None
    # A fleet's per-vehicle figures show its first vehicle (its metrics cover them all).
    lead = next(iter(log.vehicles.values())) if log.vehicles else log
    if log.vehicles:
        plot_polygonal_map(
            log.world, polylines, folder / "polygonal_map.png", truth_outlines=truth,
            trajectories={
                vehicle: np.asarray(each.true_poses[_last_lap(each)]).reshape(-1, 3)
                for vehicle, each in log.vehicles.items()
            },
            title=f"{heading}\n{next(iter(log.vehicles))}'s local maps after lap "
                  f"{len(lead.laps)}, every vehicle's last lap",
        )
    else:
        last_lap = _last_lap(log)
        plot_polygonal_map(
            log.world, polylines, folder / "polygonal_map.png", truth_outlines=truth,
            trajectory=np.asarray(log.true_poses[last_lap]).reshape(-1, 3),
            estimate=np.asarray(log.estimated_poses[last_lap]).reshape(-1, 3),
            title=f"{heading}\nsemi-static local maps after lap {len(log.laps)} "
                  "(paper Fig. 4)",
        )
    history = lead.ekf_history
    if len(history.get("stamp", ())):
        plot_ekf_corrections(
            history["stamp"], history["correction"], history["sigma"],
            folder / "ekf_corrections.png", title=f"{heading}\nEKF corrections (paper Fig. 5)",
            reinitialized=history["reinitialized"],
        )
    if log.sharing is not None and log.sharing["messages"]:
        sharing = log.sharing
        plot_sharing_traffic(
            sharing["stamp"], sharing["message_bytes"], sharing["message_grid_bytes"],
            folder / "sharing_bytes.png", title=f"{heading}\nsegment maps published",
        )
    if log.example_pair is not None:
        plot_tangent_histograms(
            *log.example_pair, folder / "tangent_histograms.png",
            title=f"{heading}\nan associated pair, reference (top) and scan (paper Fig. 2)",
        )
    if lead.laps:
        plot_detection_scores(
            [{"lap": lap.lap, **lap.detection,
              "false_objects_from_people": lap.false_objects_from_people}
             for lap in lead.laps],
            folder / "detection_scores.png",
            title=f"{heading}\nsemi-static object detection per lap",
        )
        vehicle = f" ({next(iter(log.vehicles))})" if log.vehicles else ""
        plot_run_events(**run_events(lead), path=folder / "events.png",
                        title=f"{heading}\nevents per lap{vehicle}")
