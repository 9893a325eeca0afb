"""Turn a run log into the output directory of docs/design.md (a contract, extend only).

::

    DIR/metrics.json          machine-readable results
    DIR/table1.csv            the Table 1 row of this run, in cm
    DIR/maps/lap_NN.geojson   the local maps after lap NN, world frame
    DIR/figures/*.png         Fig. 4 map, Fig. 5 EKF corrections, Fig. 2 tangent histograms, ...

The figures are drawn by :mod:`scenarios.results.run_figures`.

Nothing is half-written: every file is first written to a staging folder beside ``DIR``,
which then replaces ``DIR`` as a whole (:mod:`scenarios.process.staging`).
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.bench.ground_truth import detection_scores
from scenarios.bench.policies import policy_name
from scenarios.bench.records import LapLog, RunLog
from scenarios.bench.safety_record import merged_record
from scenarios.process.staging import stage_and_publish
from scenarios.results.figures import plot_lap_times
from scenarios.results.figures.style import run_title
from scenarios.results.metrics import ekf_correction_metrics, localization_metrics, table1_cm
from scenarios.results.run_figures import write_figures
from scenarios.spec.field_sizing import field_checks
from scenarios.spec.pieces import piece_sightings
from scenarios.spec.scenario import POLICIES

__all__ = [
    "PAPER_TABLE1",
    "TABLE1_COLUMNS",
    "csv_text",
    "detection_metrics",
    "failed_laps",
    "json_text",
    "policy_comparison",
    "safety_kpis",
    "stage_and_publish",
    "summarize",
    "table1_rows",
    "write_outputs",
]

TABLE1_COLUMNS = ("environment", "mean_avg", "mean_min", "mean_max", "std_avg", "std_min",
                  "std_max")

PAPER_TABLE1 = {
    "sim1": (4.71, 2.19, 6.62, 1.89, 1.25, 2.69),
    "sim2": (4.46, 1.20, 12.37, 2.13, 0.91, 5.14),
    "pal1": (2.46, 1.78, 2.86, 1.09, 0.99, 1.16),
    "pal3a": (3.99, 2.14, 5.94, 1.68, 0.70, 3.18),
    "pal3b": (4.55, 2.88, 6.86, 1.72, 1.21, 3.45),
}
"""The paper's Table 1 (cm): mean avg/min/max, std avg/min/max per environment."""


def _median_ms(seconds: list[float]) -> float | None:
    return round(float(np.median(seconds)) * 1e3, 4) if seconds else None


def detection_metrics(laps: Sequence[LapLog]) -> dict[str, Any]:
    """Return the ``detection`` section of ``metrics.json`` from the scored lap logs.

    Examples
    --------
    >>> lap = LapLog(lap=1, start_time=0.0, detection={"tp": 3, "fp": 1, "fn": 0})
    >>> detection_metrics([lap])["precision"]
    0.75
    """
    totals = [lap.detection for lap in laps]
    overall = detection_scores(
        sum(d["tp"] for d in totals), sum(d["fp"] for d in totals), sum(d["fn"] for d in totals)
    )
    return {
        "precision": overall["precision"],
        "recall": overall["recall"],
        "f1": overall["f1"],
        "false_objects_from_people": sum(lap.false_objects_from_people for lap in laps),
        **({"false_objects_from_vehicles": sum(lap.false_objects_from_vehicles or 0
                                               for lap in laps)}
           if any(lap.false_objects_from_vehicles is not None for lap in laps) else {}),
        "per_lap": [{"lap": lap.lap, **lap.detection} for lap in laps],
        "latency_scans": {
            f"lap_{lap.lap:02d}/{name}": value
            for lap in laps
            for name, value in lap.latencies.items()
        },
    }


def summarize(log: RunLog) -> dict[str, Any]:
    """Return the ``metrics.json`` content of a run (docs/design.md keys, and more)."""
    spec = log.spec
    laps = log.laps
    localization = localization_metrics(log.true_poses, log.estimated_poses, log.covariances)
    history = log.ekf_history
    if len(history.get("stamp", ())):
        # Fig. 5's figures: lap-start re-localisations are jumps, not corrections.
        localization["ekf_corrections"] = ekf_correction_metrics(
            history["correction"], history["sigma"], history["reinitialized"]
        )
    wall, engine = log.wall_time_s, log.engine_time_s
    extra = {}
    if log.sharing is not None:
        sharing = log.sharing
        extra["sharing"] = {
            "messages": sharing["messages"],
            "bytes": sharing["bytes"],
            "grid_bytes": sharing["grid_bytes"],
            # Per message, the 5 cm grid of its segment over its encoded size.
            "grid_ratio_min": min(
                (grid / size for grid, size in zip(sharing["message_grid_bytes"],
                                                   sharing["message_bytes"], strict=True)),
                default=None,
            ),
        }
    return {
        "scenario": spec.name,
        "seed": spec.seed,
        "laps": spec.laps,
        "world": log.world.name,
        "robot": log.robot.name,
        "policy": policy_name(spec.policy),
        "table1_cm": table1_cm(log.table1_distances),
        "detection": detection_metrics(laps),
        "localization": localization,
        "safety": {
            "collisions": sum(lap.collisions for lap in laps),
            "stops": sum(lap.stops for lap in laps),
            "slowdowns": sum(lap.slowdowns for lap in laps),
            "stops_per_lap": [lap.stops for lap in laps],
            "lap_time_s": [round(lap.duration_s, 4) for lap in laps],
            "total_time_s": round(sum(lap.duration_s for lap in laps), 4),
            "stopped_time_s": [round(lap.stopped_time_s, 4) for lap in laps],
            "slowed_time_s": [round(lap.slowed_time_s, 4) for lap in laps],
            "laps_completed": sum(lap.completed for lap in laps),
            "failed_laps": failed_laps(log),
            **safety_kpis(log),
        },
        "performance": {
            "sim_time_s": round(log.sim_time_s, 3),
            "wall_time_s": round(wall, 3),
            "engine_time_s": round(engine, 3),
            "real_time_factor": round(log.sim_time_s / wall, 3) if wall else None,
            "wall_over_engine": round(wall / engine, 3) if engine else None,
            "mapper_ms_median": _median_ms(log.mapper_seconds),
            "raycast_ms_median": _median_ms(log.raycast_seconds),
            "safety_scans": len(log.mapper_seconds),
        },
        **extra,
        # Only a run with seeded faults says so: a fault-free run's metrics stay as they were.
        **({"faults": spec.faults.active()} if spec.faults.active() else {}),
        **({"vehicles": {name: summarize(vehicle) for name, vehicle in log.vehicles.items()}}
           if log.vehicles else {}),
    }


def safety_kpis(log: RunLog) -> dict[str, Any]:
    """Return the run's safety figures (:mod:`scenarios.bench.safety_record`) and field margins.

    A fleet's figures are its vehicles' together; ``field_margins_m`` is each segment's
    protective field against the standard's formula for the first vehicle
    (:mod:`scenarios.spec.field_sizing`), ``test_pieces`` every test piece against every
    vehicle's safety laser (:mod:`scenarios.spec.pieces`).
    """
    records = [log.safety_record] if log.safety_record is not None else [
        vehicle.safety_record for vehicle in log.vehicles.values()
        if vehicle.safety_record is not None]
    kpis = merged_record(records).as_metrics() if records else {}
    checks = field_checks(log.spec, log.world, log.robot)
    return {
        **kpis,
        "near_miss_distance_m": log.spec.safety.near_miss_distance,
        "field_margins_m": {check.segment: check.as_metrics() for check in checks},
        "test_pieces": [sighting.as_metrics()
                        for sighting in piece_sightings(log.spec, log.world, log.robot)],
    }


def failed_laps(log: RunLog) -> list[dict[str, Any]]:
    """Return ``{"lap", "reason"}`` for every lap that did not reach the end of the path.

    The runner ends a lap at the end of the path or when ``lap_timeout`` simulated
    seconds have passed (the robot stopped for good, lost or stuck); a lap that never
    started (the run ended early) counts as failed too.
    """
    spec = log.spec
    failed = [
        {"lap": lap.lap,
         "reason": f"did not reach the end of the path within lap_timeout = "
                   f"{spec.lap_timeout:g} s ({lap.stops} stops, {lap.collisions} collisions)"}
        for lap in log.laps if not lap.completed
    ]
    failed += [{"lap": lap, "reason": "never ran"}
               for lap in range(len(log.laps) + 1, spec.laps + 1)]
    return failed


COMPARED_KEYS = ("lap_time_s", "stops", "slowdowns", "stops_per_lap", "min_separation_m",
                 "min_ttc_s")
"""The ``safety`` keys ``policy_comparison`` keeps of every policy."""


def policy_comparison(summaries: Mapping[str, Mapping[str, Any]]) -> dict:
    """Return every policy's lap times and safety figures and what each saves.

    ``summaries`` maps each field policy run on the same scenario and seed (at least
    ``conservative``) to its summary. Per policy: :data:`COMPARED_KEYS`, the count of each
    kind of infraction and ``saved_percent``, the total time it saves against the
    conservative policy; ``total_time_saved_s`` / ``_percent`` are the adaptive policy's.

    Examples
    --------
    >>> def run(laps, stops=0):
    ...     return {"safety": {"lap_time_s": laps, "total_time_s": sum(laps), "stops": stops,
    ...                        "slowdowns": 0, "stops_per_lap": [stops], "infractions": [],
    ...                        "min_separation_m": {"person": 0.5}, "min_ttc_s": None}}
    >>> both = policy_comparison({"conservative": run([40.0]), "adaptive": run([30.0])})
    >>> both["adaptive"]["saved_percent"], both["total_time_saved_s"]
    (25.0, 10.0)
    """
    base = summaries["conservative"]["safety"]["total_time_s"]
    compared: dict[str, Any] = {}
    for policy, summary in summaries.items():
        safety = summary["safety"]
        kinds = [item["kind"] for item in safety["infractions"]]
        total = safety["total_time_s"]
        compared[policy] = {key: safety[key] for key in COMPARED_KEYS} | {
            "infractions": {kind: kinds.count(kind) for kind in sorted(set(kinds))},
            "saved_percent": round(100.0 * (base - total) / base, 3) if base else None,
        }
    if "adaptive" in summaries:
        new = summaries["adaptive"]["safety"]["total_time_s"]
        compared["total_time_saved_s"] = round(base - new, 4)
        compared["total_time_saved_percent"] = compared["adaptive"]["saved_percent"]
    return compared


def sharing_comparison(on: Mapping[str, Any], off: Mapping[str, Any]) -> dict:
    """Return every vehicle's lap times with sharing on and off and the share saved per lap.

    ``saved_percent`` is ``100 (off - on) / off`` per lap: positive where sharing made
    the lap faster.

    Examples
    --------
    >>> on = {"vehicles": {"a": {"safety": {"lap_time_s": [10.0, 9.0]}}}}
    >>> off = {"vehicles": {"a": {"safety": {"lap_time_s": [10.0, 10.0]}}}}
    >>> sharing_comparison(on, off)
    {'a': {'on': [10.0, 9.0], 'off': [10.0, 10.0], 'saved_percent': [0.0, 10.0]}}
    """
    result = {}
    for name, vehicle in on.get("vehicles", {}).items():
        times_on = vehicle["safety"]["lap_time_s"]
        times_off = off["vehicles"][name]["safety"]["lap_time_s"]
        result[name] = {
            "on": times_on,
            "off": times_off,
            "saved_percent": [round(100.0 * (b - a) / b, 3) if b else None
                              for a, b in zip(times_on, times_off, strict=False)],
        }
    return result


def table1_rows(name: str, table: Mapping[str, Any]) -> list[list[Any]]:
    """Return the CSV rows (header first) of one run's Table 1 (cm)."""
    row = [name]
    for stat in ("mean", "std"):
        row += [table[stat][key] for key in ("avg", "min", "max")]
    return [list(TABLE1_COLUMNS), row]


def csv_text(rows: list[list[Any]]) -> str:
    """Return ``rows`` as CSV text (``None`` as an empty cell)."""
    buffer = io.StringIO()
    cleaned = [["" if value is None else value for value in row] for row in rows]
    csv.writer(buffer, lineterminator="\n").writerows(cleaned)
    return buffer.getvalue()


def _map_collection(maps: Mapping[str, dict]) -> dict:
    features = [feature for collection in maps.values() for feature in collection["features"]]
    segments = {name: collection["properties"] for name, collection in maps.items()}
    return {"type": "FeatureCollection", "properties": {"segments": segments},
            "features": features}


def json_text(data: Any) -> str:
    """Return ``data`` as indented JSON text (NaN refused: it is not JSON)."""
    return json.dumps(data, indent=2, allow_nan=False) + "\n"


def _write_maps(folder: Path, maps_after_lap: Sequence[Mapping[str, dict]]) -> None:
    folder.mkdir()
    for lap, maps in enumerate(maps_after_lap, start=1):
        (folder / f"lap_{lap:02d}.geojson").write_text(json_text(_map_collection(maps)))


def write_outputs(
    log: RunLog,
    out_dir: str | os.PathLike[str],
    *,
    figures: bool = True,
    comparison: Mapping[str, Mapping[str, Any]] | None = None,
    sharing_off: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Write the run's output directory and return the metrics written.

    ``comparison`` maps the other field policies run on the same scenario and seed to
    their summaries; it adds ``policy_comparison`` to the metrics and
    ``figures/lap_times.png``. ``sharing_off``
    is the summary of the same fleet run with sharing off; it adds
    ``sharing_comparison`` and ``figures/lap_times_sharing.png``.
    """
    metrics = summarize(log)
    if sharing_off is not None:
        metrics["sharing_comparison"] = sharing_comparison(metrics, sharing_off)
    if comparison is not None:
        runs = {policy_name(log.spec.policy): metrics, **comparison}
        metrics["policy_comparison"] = policy_comparison(
            {policy: runs[policy] for policy in POLICIES if policy in runs})

    def fill(staging: Path) -> None:
        (staging / "metrics.json").write_text(json_text(metrics))
        rows = table1_rows(log.spec.name, metrics["table1_cm"])
        (staging / "table1.csv").write_text(csv_text(rows))
        _write_maps(staging / "maps", log.maps_after_lap)
        # A fleet: maps/ holds the first vehicle's, maps/NAME/ every vehicle's own.
        for vehicle, each in log.vehicles.items():
            _write_maps(staging / "maps" / vehicle, each.maps_after_lap)
        if figures:
            write_figures(log, staging / "figures")
            heading = run_title(log.spec.name, policy_name(log.spec.policy), log.spec.seed,
                                log.spec.laps)
            if comparison is not None:
                times = metrics["policy_comparison"]
                policies = [p for p in POLICIES if p in times]
                plot_lap_times(
                    {p: times[p]["lap_time_s"] for p in policies},
                    staging / "figures" / "lap_times.png",
                    stops={p: times[p]["stops_per_lap"] for p in policies},
                    title=f"{heading}\nlap times by field policy: {', '.join(policies)} "
                          "(same seed)",
                )
            if sharing_off is not None:
                change = metrics["sharing_comparison"]
                plot_lap_times(
                    {f"{name}, {state}": change[name][key]
                     for name in change for state, key in (("sharing", "on"),
                                                           ("no sharing", "off"))},
                    staging / "figures" / "lap_times_sharing.png",
                    title=f"{heading}\nlap times per vehicle, sharing on and off (same seed)",
                )

    stage_and_publish(Path(out_dir), fill, command="run")
    return metrics
